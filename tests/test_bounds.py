"""Intervals at a physical bound and the claims guard's side (issue 26 follow-ups): a
time constant, a delay, a drag, an inertia scale cannot be negative; an interval that
reaches past the bound is cut there wherever it is shown, and a claim whose interval
excludes the null only where the parameter cannot be is held back as not physical."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omavctl.cli.fit import _interval_text
from omavctl.diagnose.claim_text import not_pinned_text
from omavctl.diagnose.claims import beyond_bound, excludes_null
from omavctl.diagnose.estimate_text import estimate_sentence
from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.intervals import Z95, interval95, pinned_down, unpinned_words
from omavctl.learn.model_file import _effects_from_json
from omavctl.report.diagnosis import _interval_note

# the Crazyflie hover window's motor lag (docs/intervals.md): 9.4 +- 18.5 ms
LAG = EffectEstimate("motor_lag", {"T_m": np.array([0.0094])}, {"T_m": np.array([0.0185])})


def test_a_lag_interval_is_cut_at_zero_and_its_standard_error_kept():
    ((lo, hi),) = LAG.interval95()["T_m"]
    assert lo == 0.0 and hi == 0.0094 + Z95 * 0.0185
    assert LAG.stderr["T_m"].tolist() == [0.0185]
    assert LAG.pinned()["T_m"].tolist() == [False]  # it holds 0: no lag
    # an estimate below its bound keeps its interval (it is not physical, and says so)
    below = interval95(np.array([-0.00136]), np.array([0.00068]), 0.0)
    assert below.tolist() == [[-0.00136 - Z95 * 0.00068, -0.00136 + Z95 * 0.00068]]
    # a parameter of either sign (a CoM offset) is never cut
    assert interval95(np.array([0.001]), np.array([0.01]), None)[0, 0] < 0


def test_every_place_that_shows_the_interval_shows_the_cut_one():
    js = LAG.to_json()
    assert js["T_m_ci95"] == [[0.0, 0.0094 + Z95 * 0.0185]] and js["T_m_stderr"] == [0.0185]
    # the model file holds P and P_stderr and derives the interval again on reading
    (read,) = _effects_from_json({"motor_lag": js}, Path("m.npz"), 2).values()
    assert read.interval95()["T_m"].tolist() == LAG.interval95()["T_m"].tolist()
    ci = js["T_m_ci95"][0]
    assert _interval_text(ci, False, ("motor_lag", "T_m", 0)) == (
        "[0, 0.0457] (cut at T_m ≥ 0): cannot be pinned down from this flight"
    )
    entry = {"name": "motor_lag", "estimate": js, "units": {"T_m": "s"}}
    assert "T_m = 0.0094 s (95 %: 0 to 0.0457, cut at T_m ≥ 0, cannot be pinned down" in (
        estimate_sentence(entry)
    )
    assert _interval_note(js, "T_m", 0, "motor_lag") == (
        " [0, 0.046] (cut at T_m ≥ 0): cannot be pinned down from this flight"
    )


def test_an_inertia_scale_interval_is_cut_at_zero_and_keeps_its_side():
    est = EffectEstimate(
        "inertia_error", {"scale": np.array([0.3, 1.0, 8.0])}, {"scale": np.array([0.2, 0.01, 1.0])}
    )
    iv = est.interval95()["scale"]
    assert iv[0, 0] == 0.0 and iv[1, 0] > 0.0 and iv[2, 0] > 0.0
    # scale 0 to 0.69 excludes 1 (no inertia error) on the physical side
    assert excludes_null("inertia_error", est.to_json(), {"x"})


def test_a_negative_delay_is_not_physical_and_not_a_claim():
    """tau_d = -1.36 ms (95 %: -2.70 to -0.03) excluded 0 and passed the old guard."""
    est = {"tau_d": [-0.00136], "tau_d_ci95": [[-0.00270, -0.00003]]}
    assert not excludes_null("command_delay", est, None)
    assert beyond_bound("command_delay", est, None) == ["tau_d"]
    assert excludes_null("command_delay", {"tau_d_ci95": [[0.00003, 0.0027]]}, None)
    assert pinned_down("command_delay", "tau_d", np.array([[-0.0027, -0.00003]])).tolist() == [
        False
    ]
    assert unpinned_words("command_delay", "tau_d", (-0.0027, -0.00003)).startswith(
        "not physical: tau_d cannot be below 0"
    )
    # a drag whose x interval lies below 0 and whose y interval holds 0: no claim;
    # one claimed on y alone says nothing of x
    drag = {"D_ci95": [[-0.3, -0.1], [-0.1, 0.2], [0.1, 0.3]]}
    assert not excludes_null("rotational_drag", drag, {"x", "y"})
    assert beyond_bound("rotational_drag", drag, {"x", "y"}) == ["D_x"]
    assert beyond_bound("rotational_drag", drag, {"y"}) == []
    assert excludes_null("rotational_drag", drag, None)  # z: 0.1 to 0.3
    # an effect of either sign (a CoM offset) excludes its null on both sides
    assert excludes_null("com_offset", {"r_ci95": [[-0.02, -0.01]] * 3}, None)


def test_a_claim_held_back_as_not_physical_says_so():
    diag = {
        "not_pinned": [
            {
                "name": "command_delay",
                "units": {"tau_d": "s"},
                "estimate": {
                    "tau_d": [-0.00136],
                    "tau_d_ci95": [[-0.0027, -0.00003]],
                    "tau_d_pinned": [False],
                },
                "axes": None,
                "not_physical": ["tau_d"],
            }
        ]
    }
    text = not_pinned_text(diag)
    assert text.startswith(
        " Not claimed: command_delay, which is not physical here: the 95 % interval of "
        "tau_d lies wholly below its physical bound 0"
    )
    assert "tau_d = -0.00136 s (95 %: -0.0027 to -3e-05, not physical" in text
