"""A lag or delay a smooth held-out flight cannot pin down, judged at its fit-flight
estimate on the held-out physics-only error beside the look-alikes (issue 26, "smooth";
omavctl/diagnose/held_beside.py)."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.diagnose.claim_text import learned_claim_text
from omavctl.diagnose.held_beside import held_timing_beside
from omavctl.diagnose.joint import MIN_SHARE
from tests.conftest import rebuilt
from tests.test_diagnose_joint import DT, FLOOR, _case
from tests.test_diagnose_steps import ALIKES, DELAY, _Held


def _absorbed(delay: float | None, lag: bool = False, seed: int = 11):
    """The fit flight's targets hold the look-alikes at 0.4 of their held-out size (what
    the GP absorbed on the steps) and the whole ``delay``; the held-out physics-only error
    holds both whole. ``lag``: a motor lag whose regressor is the delay's, up to 3 %."""
    alike = {"motor_lag": "command_delay"} if lag else None
    truth = {**ALIKES, "command_delay": None if delay is None else np.array([delay])}
    if lag:
        truth["motor_lag"] = None
    model, physics, regs, blocks = _case(truth, seed=seed, alike=alike)
    train = model.train_regressors
    targets = model.targets - 0.6 * sum(train[n] @ t for n, t in ALIKES.items())
    return rebuilt(model, targets=targets, train_regressors=train), physics, regs, blocks


def _held(name: str = "command_delay", **extra) -> dict:
    """The guard's held-back entry: its estimate on the held-out flight not pinned down."""
    est = {"tau_d": [0.04], "tau_d_ci95": [[0.0, 0.2]], "tau_d_pinned": [False]}
    return {"name": name, "units": {"tau_d": "s"}, "estimate": est, "axes": None, **extra}


def _claim(case, held):
    model, physics, regs, blocks = case
    return held_timing_beside(held, [_Held(regs)], model, physics, regs, blocks, (FLOOR, DT))


def test_a_delay_held_back_on_the_held_out_flight_is_claimed_at_its_fit_estimate():
    case = _absorbed(DELAY)
    found = _claim(case, [_held()])
    assert found is not None
    step, entry = found
    assert step.name == entry["name"] == "command_delay"
    assert step.theta == pytest.approx([DELAY], rel=0.1)  # the fit flight's estimate
    lo, hi = entry["fit_flight_ci95"]
    assert 0 < lo <= DELAY <= hi
    assert step.share >= MIN_SHARE and step.contribution_rms >= FLOOR
    assert step.ambiguous_with == entry["ambiguous_with"] == []


def test_no_delay_or_a_delay_held_back_for_another_reason_is_not_claimed_here():
    assert _claim(_absorbed(None), [_held()]) is None
    case = _absorbed(DELAY)
    assert _claim(case, [_held(beside_lag={"lag": "motor_lag"})]) is None  # joint_lag's
    pinned = _held()
    pinned["estimate"] = {**pinned["estimate"], "tau_d_pinned": [True]}
    assert _claim(case, [pinned]) is None  # not held back for its held-out estimate
    assert _claim(case, [_held("inertia_error")]) is None  # not a lag or delay
    assert _claim(case, []) is None


def test_a_lag_the_data_do_not_tell_from_it_is_named_ambiguous_and_the_text_says_so():
    found = _claim(_absorbed(DELAY, lag=True), [_held()])
    assert found is not None
    step, entry = found
    assert step.name == "command_delay" and entry["ambiguous_with"] == ["motor_lag"]
    diag = {"missing": [], "learned_claims": ["command_delay"], "learned_steps": [entry]}
    text = learned_claim_text(diag, "on the held-out flight")
    ms = 1e3 * entry["fit_flight_value"]
    assert (
        " This flight alone does not pin its value down; the fit flight shows it "
        f"({ms:.0f} ms, its 95 % interval excluding 0; the GP shrinks it, so fit --effects "
        "gives the value to trust), and at the training points' value it removes the share "
        "above beside the look-alikes. The data do not tell it from motor_lag: plan "
        "--objective effects "
        "designs a flight that does."
    ) in text
