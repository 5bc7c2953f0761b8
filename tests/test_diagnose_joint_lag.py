"""A claim beside a motor lag judged against the lag's exact form profiled over its time
constant (omavctl/diagnose/joint_lag.py; issue 26, docs/scorecard.md session 14): a lag
estimated short leaves a loss of gain that an inertia scale absorbs; the exact lag at
its best time constant leaves nothing to it, while a real gain error beside the lag stays."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from omavctl.diagnose.claim_text import not_pinned_text
from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.joint_lag import beside_lag, lag_profile
from omavctl.physics.actuator_effects import first_order_lag

DT = 0.01  # a 100 Hz controller
FLOOR = 0.05
TRUE_LAG = 0.12


class _Samples:
    """Held-out samples of a commanded angular acceleration ``u`` (n, 3) held at 100 Hz:
    the motor lag's exact form, and the first-order regressors of a gain (``inertia_error``
    as a loss of the commanded acceleration) and of a look-alike that is not excited."""

    def __init__(self, u: np.ndarray) -> None:
        self.u = u
        eye = np.eye(3)[None]
        self.regressors = {
            "inertia_error": -u[:, :, None] * eye,
            "com_offset": np.zeros((u.shape[0], 3, 3)),
            "rotor_interference": np.zeros((u.shape[0], 3, 2)),
            "command_delay": -np.gradient(u, DT, axis=0)[:, :, None],
            "motor_lag": np.zeros((u.shape[0], 3, 1)),  # (its exact form is profiled)
        }

    def exact(self, name: str, value: float) -> np.ndarray:
        assert name == "motor_lag"
        return first_order_lag(self.u, value, DT) - self.u


def _flight(gain: float, seed: int = 0) -> tuple[_Samples, np.ndarray]:
    """Steps of the commanded acceleration (rad/s^2) every 0.3-1 s for 20 s; the
    physics-only error of a 120 ms motor lag and a loss of ``gain`` x the command (the
    scale's first-order regressor), with noise 10x under the floor."""
    rng = np.random.default_rng(seed)
    n = 2000
    edges = np.cumsum(rng.integers(30, 100, size=60))
    level = rng.normal(0.0, 3.0, size=(edges.size + 1, 3))
    u = level[np.searchsorted(edges, np.arange(n), side="right")]
    s = _Samples(u)
    lagged = first_order_lag(u, TRUE_LAG, DT)
    physics = lagged - (1.0 + gain) * u + rng.normal(0.0, FLOOR / 10, size=(n, 3))
    return s, physics


def test_the_lags_exact_form_leaves_nothing_to_an_inertia_scale_the_vehicle_lacks():
    s, physics = _flight(gain=0.0)
    model = SimpleNamespace(effects={})
    prof = lag_profile([s], model, physics, "motor_lag", "inertia_error", ["com_offset"])  # type: ignore[arg-type]
    assert prof.value == pytest.approx(TRUE_LAG, abs=0.002)
    assert prof.share < 0.05
    assert prof.part < FLOOR
    # a lag held at 60 ms (as a first-order regressor estimates it short) leaves a gain loss
    # the scale takes: that is what the profile over the time constant removes
    short = physics - s.exact("motor_lag", 0.06)
    x = s.regressors["inertia_error"].reshape(-1, 3)
    coef, *_ = np.linalg.lstsq(x, short.reshape(-1), rcond=None)
    assert np.all(coef > 0.05)  # about 10 % of the command lost: a scale near 1.1


def test_a_real_gain_error_beside_the_lag_is_kept():
    s, physics = _flight(gain=0.2)
    model = SimpleNamespace(effects={})
    prof = lag_profile([s], model, physics, "motor_lag", "inertia_error", ["com_offset"])  # type: ignore[arg-type]
    assert prof.value_with == pytest.approx(TRUE_LAG, abs=0.005)
    assert prof.share > 0.5
    assert prof.part > 10 * FLOOR


def _guard(names: list[str]) -> Guarded:
    return Guarded(kept=list(names), estimates={n: {"name": n} for n in names})


@pytest.mark.parametrize(
    "gain, kept", [(0.0, ["motor_lag"]), (0.2, ["motor_lag", "inertia_error"])]
)
def test_beside_lag_holds_back_only_the_claim_the_lag_leaves_nothing_to(gain, kept):
    s, physics = _flight(gain)
    model = SimpleNamespace(effects={})
    guarded = _guard(["motor_lag", "inertia_error"])
    out = beside_lag([s], model, physics, guarded, FLOOR, _guard)  # type: ignore[arg-type]
    assert out.kept == kept
    held = [h["name"] for h in out.held_back]
    assert held == ([] if gain else ["inertia_error"])
    if not gain:
        text = not_pinned_text({"not_pinned": out.held_back})
        assert "Not claimed: inertia_error, which this flight does not tell from motor_lag:" in text
        assert "Fit motor_lag first; judge inertia_error on the next flight." in text


def test_no_lag_claimed_leaves_the_claims_as_they_are():
    s, physics = _flight(gain=0.0)
    guarded = _guard(["inertia_error"])
    out = beside_lag([s], SimpleNamespace(effects={}), physics, guarded, FLOOR, _guard)  # type: ignore[arg-type]
    assert out is guarded


def test_a_delay_claimed_without_a_lag_gives_way_to_the_lag_that_leaves_it_nothing():
    s, physics = _flight(gain=0.0)  # a 120 ms motor lag, no delay
    guarded = _guard(["com_offset", "command_delay"])
    out = beside_lag([s], SimpleNamespace(effects={}), physics, guarded, FLOOR, _guard)  # type: ignore[arg-type]
    assert out.kept == ["com_offset", "motor_lag"]
    (held,) = out.held_back
    assert held["name"] == "command_delay"
    assert held["beside_lag"]["claimed_instead"] is True
    assert held["beside_lag"]["share"] < 0.15
    text = not_pinned_text({"not_pinned": out.held_back})
    assert "motor_lag, which every rotorcraft's motors have, is claimed in its place." in text
    # the guard holding the lag back too: neither is claimed
    refuse = lambda names: _guard([n for n in names if n != "motor_lag"])  # noqa: E731
    out = beside_lag([s], SimpleNamespace(effects={}), physics, guarded, FLOOR, refuse)  # type: ignore[arg-type]
    assert out.kept == ["com_offset"]
    assert out.held_back[0]["beside_lag"]["claimed_instead"] is False


def _drag_flight(drag: float, gain: float = 0.0) -> tuple[_Samples, np.ndarray]:
    """:func:`_flight`'s 120 ms lag with a rate damping ``drag`` (1/s: the drag torque
    over the inertia) instead of a gain loss, or beside one; the samples also hold the
    damping's first-order regressor (``rotational_drag``: minus the body rate, the
    integral of the measured acceleration)."""
    s, physics = _flight(gain)
    rate = np.cumsum(physics + s.u, axis=0) * DT
    rate -= rate.mean(axis=0)
    s.regressors["rotational_drag"] = -rate[:, :, None] * np.eye(3)[None]
    return s, physics - drag * rate


def test_a_drag_beside_the_lag_takes_the_place_of_the_inertia_scale_that_stood_in_for_it():
    s, physics = _drag_flight(drag=3.0)
    model = SimpleNamespace(effects={})
    inertia = lag_profile([s], model, physics, "motor_lag", "inertia_error", ["com_offset"])  # type: ignore[arg-type]
    drag = lag_profile([s], model, physics, "motor_lag", "rotational_drag", ["com_offset"])  # type: ignore[arg-type]
    assert drag.share > 0.9 > inertia.share
    assert drag.value_with == pytest.approx(TRUE_LAG, abs=0.005)
    assert drag.values["D"] == pytest.approx([3.0] * 3, rel=0.02)
    out = beside_lag([s], model, physics, _guard(["motor_lag", "inertia_error"]), FLOOR, _guard)  # type: ignore[arg-type]
    assert out.kept == ["motor_lag", "rotational_drag"]
    (held,) = out.held_back
    assert held["name"] == "inertia_error"
    assert held["beside_lag"]["rival"]["name"] == "rotational_drag"
    text = not_pinned_text({"not_pinned": out.held_back})
    assert text.endswith(
        "; rotational_drag, in its place, removes 100 % of what is left with motor_lag at "
        "120.0 ms (fitted so: D = 3, 3, 3), is claimed instead."
    )
    # the verdict's "Also:" says where the drag came from
    from omavctl.diagnose.joint_text import named_later

    diag = {"missing": out.kept, "joint_steps": [{"name": "motor_lag"}], "not_pinned": [held]}
    assert named_later(diag)["rotational_drag"] == (
        "beside the lag",
        "rotational_drag: in the place of inertia_error, beside motor_lag's exact form",
    )
    # a real gain error beside the lag and no damping: the scale stays, no rival
    s, physics = _drag_flight(drag=0.0, gain=0.2)
    out = beside_lag([s], model, physics, _guard(["motor_lag", "inertia_error"]), FLOOR, _guard)  # type: ignore[arg-type]
    assert out.kept == ["motor_lag", "inertia_error"] and out.held_back == []


def test_a_rival_held_back_too_is_not_claimed_instead_and_is_said_once():
    """A new user's Crazyflie window: "Not claimed: drag_moment ..." (h = 0.0224 m), then
    inertia_error's "drag_moment, in its place, removes 59 % ... is claimed instead",
    then "Not claimed: drag_moment" again (h = 0.0248 m): the guard run again after the
    swap held the rival back a second time. Each effect is held back once (its last
    entry), and a rival held back is not said to be claimed."""
    from omavctl.diagnose.joint_lag import _merged

    s, physics = _drag_flight(drag=3.0)
    model = SimpleNamespace(effects={})

    def guard(names):  # the rival, once claimed, is held back as not pinned down
        out = _guard([n for n in names if n != "rotational_drag"])
        if "rotational_drag" in names:
            out.held_back = [{"name": "rotational_drag", "estimate": {"D": [2.9, 2.9, 2.9]}}]
        return out

    first = guard(["motor_lag", "inertia_error"])
    first.held_back = [{"name": "rotational_drag", "estimate": {"D": [1.0, 1.0, 1.0]}}]
    out = beside_lag([s], model, physics, first, FLOOR, guard)  # type: ignore[arg-type]
    assert [h["name"] for h in out.held_back] == ["inertia_error", "rotational_drag"]
    assert out.held_back[-1]["estimate"]["D"] == [2.9, 2.9, 2.9]  # the later estimate
    text = not_pinned_text({"not_pinned": out.held_back})
    assert "is claimed instead" not in text
    assert (
        "; rotational_drag removes 100 % of what is left with motor_lag at 120.0 ms (fitted "
        "so: D = 3, 3, 3) and would take its place, but cannot be pinned down either (said "
        "below)." in text
    )
    assert text.count("Not claimed: rotational_drag") == 1
    assert text.index("Not claimed: inertia_error") < text.index("Not claimed: rotational_drag")
    assert _merged([{"name": "a", "k": 1}], [{"name": "b"}], [{"name": "a", "k": 2}]) == [
        {"name": "b"},
        {"name": "a", "k": 2},
    ]
