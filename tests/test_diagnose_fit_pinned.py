"""A learned effect the held-out flight does not pin down, claimed on the fit flight's
estimate when that excludes its null and passes the large cut on held-out data
(issue 26; omavctl/diagnose/learned_fit_pinned.py)."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.diagnose.claim_text import learned_claim_text
from omavctl.diagnose.claims import LARGE_CUT, learned_claim
from omavctl.diagnose.joint import MIN_BLOCK_T
from omavctl.diagnose.learned_fit_pinned import fit_flight_pinned, learned_fit_pinned
from tests.test_diagnose_joint import FLOOR, _case

COM = np.array([0.06, -0.05, 0.04])


def _unpinned(name: str = "com_offset") -> dict:
    """A ranking entry whose held-out interval holds the null on every axis (the GP
    fitted to the held-out flight took the slowly varying torque)."""
    return {
        "name": name,
        "missing": True,
        "explained_variance": 0.8,
        "explained_variance_per_axis": {"x": 0.8, "y": 0.7, "z": 0.6},
        "units": {"r": "m"},
        "estimate": {"r_ci95": [[-0.05, 0.15], [-0.12, 0.02], [-0.03, 0.1]]},
    }


def test_an_offset_the_held_out_flight_cannot_pin_is_claimed_on_the_fit_flight():
    model, physics, regs, blocks = _case({"com_offset": COM, "inertia_error": None})
    pool = [_unpinned()]
    # held-out interval holds 0: the claim of the held-out estimate does not take it
    assert learned_claim(pool, [], model, physics, regs, blocks, FLOOR) is None
    found = learned_fit_pinned(pool, model, physics, regs, blocks, FLOOR)
    assert found is not None
    step, entry = found
    assert step.name == entry["name"] == "com_offset"
    assert step.share >= 0.9 > LARGE_CUT and step.block_t >= MIN_BLOCK_T
    assert entry["held_out_not_pinned"] is True
    assert entry["fit_flight"]["r"] == pytest.approx(COM, rel=0.15)
    diag = {"missing": [], "learned_claims": ["com_offset"],
            "learned_steps": [{**entry, **step.to_json()}]}  # fmt: skip
    text = learned_claim_text(diag, "on held-out data")
    x, y, z = entry["fit_flight"]["r"]
    assert (
        "This flight alone does not pin its value down; the fit flight does (least squares "
        f"at the model's training points: r_x {x:.3g} m, r_y {y:.3g} m, r_z {z:.3g} m;"
    ) in text
    assert "uneven" not in text  # its blocks' t is above 4: not claimed on the large cut
    assert "fit --effects gives the value and interval to trust" in text


def test_no_claim_without_the_offset_when_pinned_here_or_for_an_inertia_scale():
    model, physics, regs, blocks = _case({"com_offset": None, "inertia_error": None})
    assert fit_flight_pinned(model, "com_offset", None) is None
    assert learned_fit_pinned([_unpinned()], model, physics, regs, blocks, FLOOR) is None
    model, physics, regs, blocks = _case({"com_offset": COM, "servo_lag": None})
    pinned = {**_unpinned(), "estimate": {"r_ci95": [[0.05, 0.07], [-0.06, -0.04], [0.03, 0.05]]}}
    # pinned down on the held-out flight: learned_claim judges it, not this route
    assert learned_fit_pinned([pinned], model, physics, regs, blocks, FLOOR) is None
    # an inertia scale the fit flight pins down is no default look-alike: not this route
    # (own-fig8 7 and 22: a yaw scale of 1.25 the vehicle lacks)
    model, physics, regs, blocks = _case({"inertia_error": np.array([-0.2, -0.2, -0.2])})
    assert fit_flight_pinned(model, "inertia_error", None) is not None
    scale = {**_unpinned("inertia_error"), "units": {"scale": "1"},
             "estimate": {"scale_ci95": [[0.5, 1.5]] * 3}}  # fmt: skip
    assert learned_fit_pinned([scale], model, physics, regs, blocks, FLOOR) is None
