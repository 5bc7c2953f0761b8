"""Intervals at a physical bound and the claims guard's side (issue 26 follow-ups): a
time constant, a delay, a drag, an inertia scale cannot be negative; an interval that
reaches past the bound is cut there wherever it is shown, and a claim whose interval
excludes the null only where the parameter cannot be is held back as not physical."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omavctl.cli.fit import _interval_text
from omavctl.diagnose.claim_text import not_pinned_text
from omavctl.diagnose.claims import beyond_bound, excludes_null
from omavctl.diagnose.estimate_text import estimate_sentence
from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.intervals import (
    Z95,
    interval95,
    physical_side,
    pinned_down,
    unpinned_words,
)
from omavctl.learn.model_file import _effects_from_json
from omavctl.report.params import _interval_note

# the Crazyflie hover window's motor lag (docs/intervals.md): 9.4 +- 18.5 ms
LAG = EffectEstimate("motor_lag", {"T_m": np.array([0.0094])}, {"T_m": np.array([0.0185])})


def test_a_lag_interval_is_cut_at_zero_and_its_standard_error_kept():
    ((lo, hi),) = LAG.interval95()["T_m"]
    assert lo == 0.0 and hi == 0.0094 + Z95 * 0.0185
    assert LAG.stderr["T_m"].tolist() == [0.0185]
    assert LAG.pinned()["T_m"].tolist() == [False]  # it holds 0: no lag
    # an interval wholly below its bound keeps its ends (it is not physical, and says so)
    below = interval95(np.array([-0.00136]), np.array([0.00068]), 0.0)
    assert below.tolist() == [[-0.00136 - Z95 * 0.00068, -0.00136 + Z95 * 0.00068]]
    # one rule on every axis: an estimate below the bound whose interval reaches past it
    # is cut too (Betaflight +battery_sag: scale_x -7.9 +- 54 was [-115, 98.8] beside
    # scale_z's [0, 8.31])
    scales = interval95(np.array([-7.9, 2.5]), np.array([54.0, 2.96]), 0.0)
    assert scales[:, 0].tolist() == [0.0, 0.0]
    assert scales[:, 1].tolist() == [-7.9 + Z95 * 54.0, 2.5 + Z95 * 2.96]
    # the estimate then lies outside its interval, and the words say so (the Crazyflie's
    # tau_d = -0.617 ms, 95 %: 0 to 0.637 ms); an interval cut at the bound reads
    # 'below' its high end, not '0 to 0.000637', which read as a delay pinned near 0
    # (eyes6), and where the bound is the effect's absence it says so
    delay = {"tau_d": [-0.000617], "tau_d_ci95": [[0.0, 0.000637]], "tau_d_pinned": [False]}
    entry = {"name": "command_delay", "estimate": delay, "units": {"tau_d": "s"}}
    assert (
        "tau_d = -0.000617 s (95 %: below 0.000637 s, cut at tau_d ≥ 0, not told from absent; "
        "the estimate is below it, cannot be pinned down from this flight)"
    ) in (estimate_sentence(entry))
    assert _interval_note(delay, "tau_d", 0, "command_delay").startswith(
        " [below 0.000637] (cut at tau_d ≥ 0, not told from absent; the estimate is below it): "
    )
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
        "[below 0.0457] (cut at T_m ≥ 0, not told from absent): cannot be pinned down from "
        "this flight"
    )
    entry = {"name": "motor_lag", "estimate": js, "units": {"T_m": "s"}}
    assert "T_m = 0.0094 s (95 %: below 0.0457 s, cut at T_m ≥ 0, not told from absent, cannot" in (
        estimate_sentence(entry)
    )
    assert _interval_note(js, "T_m", 0, "motor_lag") == (
        " [below 0.0457] (cut at T_m ≥ 0, not told from absent): cannot be pinned down from "
        "this flight"
    )


def test_an_inertia_scale_interval_is_made_on_its_gain():
    """The scale is estimated linearly in its gain 1/scale: the interval is the gain's,
    mapped back. Betaflight's scale_x -7.9 +- 52 (gain -0.126 +- 0.83) was [0, 98.8]
    once cut at 0, which excluded gains below 0.0101 that the data cannot rule out."""
    scale = np.array([0.3, 1.0, 8.0, -7.912, -2.0])
    se = np.array([0.2, 0.01, 1.0, 52.0, 0.1])
    est = EffectEstimate("inertia_error", {"scale": scale}, {"scale": se})
    iv = est.interval95()["scale"]
    gain, gain_se = 1.0 / scale, se / scale**2
    lo, hi = gain - Z95 * gain_se, gain + Z95 * gain_se
    # gain 3.33 +- 2.22 reaches 0: the scale has no upper end, and 1 is inside
    assert iv[0, 0] == pytest.approx(1.0 / hi[0]) and iv[0, 1] == np.inf
    assert iv[1].tolist() == pytest.approx([1.0 / hi[1], 1.0 / lo[1]])  # [0.981, 1.02]
    assert iv[2].tolist() == pytest.approx([6.43, 10.59], abs=0.01)
    assert iv[3, 0] == pytest.approx(1.0 / hi[3]) and iv[3, 0] > 0.6 and iv[3, 1] == np.inf
    # a gain wholly below 0 maps to negative scales, kept whole: not physical
    assert iv[4].tolist() == pytest.approx([1.0 / hi[4], 1.0 / lo[4]])
    assert physical_side("inertia_error", "scale", iv).tolist() == [True] * 4 + [False]
    js = est.to_json()
    assert js["scale_ci95"][0][1] is None and js["scale_ci95"][2][0] == pytest.approx(
        6.43, abs=0.01
    )
    # 1.05 gain standard errors from 1 is no inertia error; 8 +- 1 is one, on x alone
    only_x = EffectEstimate("inertia_error", {"scale": scale[:3]}, {"scale": se[:3]}).to_json()
    assert not excludes_null("inertia_error", only_x, {"x"})
    assert excludes_null("inertia_error", only_x, {"z"})


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
    assert "tau_d = -0.00136 s (95 %: -0.0027 to -3e-05 s, not physical" in text


def test_a_torque_gain_interval_is_its_scale_interval_inverted():
    """One parameter, one interval (px4tools, normalised commands): scale_x 8.2 +- 22,
    95 % [0, 51.9], was printed beside gain_x = 1/scale_x 0.12 +- 0.33, [0, 0.77]: the
    first allowed gain >= 0.019 only, the second scale >= 1.3 only. Both are the gain's
    interval now (the scale's made on it), and a negative gain's says it lies below."""
    import io
    from types import SimpleNamespace

    from rich.console import Console

    from omavctl.cli.fit import _effects_table, gain_interval

    assert gain_interval(0.0, 51.9) == (1 / 51.9, float("inf"))  # an older file's cut scale
    assert gain_interval(0.663, float("inf")) == (0.0, 1 / 0.663)
    assert gain_interval(0.5, 2.0) == (0.5, 2.0)
    assert gain_interval(-4.0, -2.0) == (-0.5, -0.25)  # not physical: stays on its side
    scale = np.array([8.2, 1.25, 0.5])
    se = np.array([22.0, 0.05, 0.02])
    summary = SimpleNamespace(
        effects={"inertia_error": EffectEstimate("inertia_error", {"scale": scale}, {"scale": se})},
        command_units={"torque": "normalised", "force": "N"},
        torque_gain=1.0 / scale,
        torque_gain_stderr=se / scale**2,
        logs=["px4.csv"],
    )

    def rows() -> dict[str, str]:
        con = Console(width=300, record=True, file=io.StringIO())
        con.print(_effects_table(summary))
        lines = con.export_text().splitlines()
        return {ln.split("│")[2].strip(): ln for ln in lines if "│" in ln}

    shown = rows()
    g_hi = 1 / 8.2 + Z95 * 22.0 / 8.2**2  # the gain 0.122 +- 0.327 holds 0
    assert f"[{1 / g_hi:.3g}, ∞): cannot be pinned down from this flight" in shown["scale_x"]
    assert (
        f"[0, {g_hi:.3g}] (cut at gain ≥ 0): cannot be pinned down" in shown["gain_x = 1/scale_x"]
    )
    g, g_se = 1 / 1.25, 0.05 / 1.25**2
    assert f"[{g - Z95 * g_se:.3g}, {g + Z95 * g_se:.3g}]" in shown["gain_y = 1/scale_y"]
    assert "cannot" not in shown["gain_y = 1/scale_y"]
    # Betaflight: gain_x -0.126 +- 0.82 was printed beside [0.0106, inf) while the note
    # said the gain is within 2 standard errors of 0
    summary.effects["inertia_error"] = EffectEstimate(
        "inertia_error", {"scale": np.array([-7.9, 1.25, 0.5])}, {"scale": se}
    )
    summary.torque_gain = 1.0 / np.array([-7.9, 1.25, 0.5])
    g_hi = -1 / 7.9 + Z95 * 22.0 / 7.9**2
    assert (
        f"[0, {g_hi:.3g}] (cut at gain ≥ 0) (the estimate is below it): cannot be pinned down"
        in rows()["gain_x = 1/scale_x"]
    )
    assert "below it" not in rows()["gain_y = 1/scale_y"]


def test_a_component_the_flight_does_not_excite_is_not_quoted():
    """A quadrotor's com_offset r_z (only a force along x or y shows it): the verdict
    quoted 'r_z = 0 (95 %: -0.098 to 0.098, cannot be pinned down ...)', the prior's,
    while fit said 'not excited by these logs'."""
    est = {
        "r": [-3.98e-05, 3.31e-06, 0.0],
        "r_ci95": [[-0.0015, 0.00142], [-0.00185, 0.00186], [-0.098, 0.098]],
        "r_pinned": [False, False, False],
    }
    entry = {
        "name": "com_offset",
        "estimate": est,
        "units": {"r": "m"},
        "parameters": {"excited": [True, True, False]},
    }
    text = estimate_sentence(entry)
    assert "r_x = -3.98e-05 m" in text and "r_y = 3.31e-06 m" in text
    assert "r_z" not in text and "0.098" not in text
    del entry["parameters"]  # without the ranking's excitation, as before
    assert "r_z = 0 m (95 %: -0.098 to 0.098" in estimate_sentence(entry)


def test_an_inertia_scale_whose_gain_is_not_told_from_zero_is_no_estimate():
    """A Crazyflie's hover logs: scale_x 82 +- 1400 with only 'within 2 standard errors
    of 1' said, and a model that predicted almost no roll."""
    from types import SimpleNamespace

    from omavctl.learn.fit_notes import effect_notes

    est = EffectEstimate(
        "inertia_error",
        {"scale": np.array([82.05, 1.2, 0.9])},
        {"scale": np.array([1400.0, 0.05, 0.2])},
    )
    notes = effect_notes(SimpleNamespace(estimates={"inertia_error": est}))
    (no_torque,) = [n for n in notes if "does not show the torque" in n]
    assert no_torque.startswith(
        "inertia_error: on x the measured angular acceleration does not show the torque "
        "(1/scale_x = 0.012 ± 0.21, within 2 standard errors of 0): scale_x 82 is no estimate"
    )
    # near 1 as its interval says, on the gain 1/scale: x's gain 0.012 +- 0.21 is 4.7
    # standard errors from 1 (its interval excludes it); z's 1.11 +- 0.25 is not
    assert "inertia_error: scale_z within 2 standard errors of 1" in " ".join(notes)
    # session 34's Crazyflie fit: scale_x 8.56 +- 8.6, interval [2.88, inf), was also
    # "within 2 standard errors of 1"
    est.values["scale"][0], est.stderr["scale"][0] = 8.563, 8.6
    notes = effect_notes(SimpleNamespace(estimates={"inertia_error": est}))
    assert not [n for n in notes if "scale_x" in n and "standard errors of 1" in n]
    assert [n for n in notes if "scale_z within 2 standard errors of 1" in n]


def test_the_report_shows_an_unbounded_scale_by_its_low_end():
    """The report's parameter table read an inertia scale with a null high end (its gain
    not told from 0) as '[unbounded]'."""
    params = {"scale": [-7.9], "scale_ci95": [[0.663, None]], "scale_pinned": [False]}
    assert _interval_note(params, "scale", 0, "inertia_error") == (
        " [0.663, ∞): cannot be pinned down from this flight"
    )


def test_fits_table_gives_a_lag_in_ms_beside_its_seconds():
    """A new user compared fit's table, 'T_m 0.06375 ± 0.0097' (s), with its note,
    '63.8 ± 9.7 ms': the table now gives both."""
    import io
    from types import SimpleNamespace

    from rich.console import Console

    from omavctl.cli.fit import _effects_table

    lag = EffectEstimate("motor_lag", {"T_m": np.array([0.06375])}, {"T_m": np.array([0.0097])})
    summary = SimpleNamespace(
        effects={"motor_lag": lag}, command_units={}, torque_gain=None, torque_gain_stderr=None,
        logs=["a.csv"],
    )  # fmt: skip
    con = Console(width=300, record=True, file=io.StringIO())
    con.print(_effects_table(summary))
    assert "0.06375 ± 0.0097 = 63.8 ± 9.7 ms" in con.export_text()


def test_fits_table_says_these_flights_for_a_fit_on_several():
    """A new user's fit on two flights: 'cannot be pinned down from this flight'."""
    import io
    from types import SimpleNamespace

    from rich.console import Console

    from omavctl.cli.fit import _effects_table

    lag = EffectEstimate("motor_lag", {"T_m": np.array([0.01])}, {"T_m": np.array([0.02])})
    for logs, words in (
        (["a.csv"], "from this flight"),
        (["a.csv", "b.csv"], "from these flights"),
    ):
        summary = SimpleNamespace(effects={"motor_lag": lag}, command_units={}, torque_gain=None,
                                  torque_gain_stderr=None, logs=logs)  # fmt: skip
        con = Console(width=300, record=True, file=io.StringIO())
        con.print(_effects_table(summary))
        assert f"not told from absent): cannot be pinned down {words}" in con.export_text()


def test_an_estimate_outside_its_own_interval_is_said_to_be():
    """Betaflight: `scale_x │ -7.912 ± 52 │ [0.663, ∞)` with no word on it, while the
    gain row beside it said "(the estimate is below it)"."""
    inf = float("inf")
    which = ("inertia_error", "scale", 0)
    assert _interval_text((0.663, inf), True, which, -7.912) == (
        "[0.663, ∞) (the estimate is below it)"
    )
    assert (
        _interval_text((0.663, 1.2), True, which, 1.5) == "[0.663, 1.2] (the estimate is above it)"
    )
    assert _interval_text((0.663, 1.2), True, which, 1.0) == "[0.663, 1.2]"
    # an interval cut at its bound says it once, after the cut
    assert (
        _interval_text((0.0, 0.000637), True, ("command_delay", "tau_d", 0), -0.000617).count(
            "the estimate is below it"
        )
        == 1
    )
