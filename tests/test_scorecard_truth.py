"""The scorecard's apparent truth (benchmarks/scorecard_truth.py): the default
imperfections' part of a fitted parameter, derived by hand on constructed cases, and
the rescoring of small records with it."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import scorecard_score as sc
from benchmarks import scorecard_truth as st
from benchmarks.scorecard import table
from omavctl.physics.allocation import Allocation
from omavctl.vehicle import load_vehicle


def test_spread_is_the_one_the_plant_draws_from_the_truth_seed():
    from omavctl.sim import plant
    from omavctl.sim.trajectory import Trajectory

    vehicle = load_vehicle(None)
    truth, _ = st.plant_truth({"seed": 123456})
    ref = Trajectory(np.column_stack([np.linspace(0.0, 0.1, 11), np.zeros((11, 18))]))
    rates = plant._Rates.of(1000.0, 100.0, 100.0, 200.0, 0.1)
    flight = plant._Flight(ref, vehicle, truth, None, np.random.default_rng(0), rates)
    assert np.array_equal(flight.act.spread, st.spread_factors(123456, truth.thrust_spread))
    assert not np.allclose(st.spread_factors(1), st.spread_factors(2))


def test_a_spread_on_two_rotors_moves_the_centre_of_thrust_by_hand():
    """At hover (tilts 0, every rotor m g / 12) a factor 1 + a on arm 0's top rotor and
    1 - a on arm 1's adds the force a T e_z at p_0 and -a T e_z at p_1: the torque
    (p_0 - p_1) x a T e_z, which r x m g e_z explains with r = a (p_0 - p_1) / 12 in
    x and y; r_z is not seen at hover (0)."""
    vehicle = load_vehicle(None)
    geom = st.hover_geometry(vehicle)
    assert np.allclose(geom.tilt, 0.0, atol=1e-9)
    assert np.allclose(geom.thrust, vehicle.mass * vehicle.gravity / 12.0)
    a = 0.04
    spread = np.ones(12)
    spread[0], spread[2] = 1.0 + a, 1.0 - a  # top rotors of arms 0 and 1
    p = Allocation(vehicle).arm_position
    expected = a * (p[0] - p[1]) / 12.0
    r = st.linear_shift(geom, ["com_offset"], spread, 0.0, 0.0, vehicle)["com_offset"]["r"]
    assert r[0] == pytest.approx(expected[0], abs=1e-12)
    assert r[1] == pytest.approx(expected[1], abs=1e-12)
    assert r[2] == pytest.approx(0.0, abs=1e-12)
    assert np.hypot(*r[:2]) > 1e-3  # millimetres: the size the scorecard's misses had
    # the interference's regressor is not excited at hover (tilts 0): its shift stays 0
    both = st.linear_shift(geom, ["com_offset", "rotor_interference"], spread, 0.25, 0.04, vehicle)
    assert both["rotor_interference"] == {"rotor_rotor": [0.0], "rotor_arm": [0.0]}
    assert both["com_offset"]["r"] == pytest.approx(r, abs=1e-12)
    # no spread, no interference: nothing to add
    zero = st.linear_shift(geom, ["com_offset"], np.ones(12), 0.0, 0.0, vehicle)
    assert np.allclose(zero["com_offset"]["r"], 0.0)


def test_timing_apparent_values():
    assert st.timing_lead(None) == 0.0
    assert st.timing_lead(100.0) == 0.0
    assert st.timing_lead(1000.0) == pytest.approx(0.0045)
    slow, _ = st.plant_truth({"seed": 1, "effects": {"command_delay": {"tau_d": 0.05}}})
    delay = {"command_delay": {"tau_d": 0.05}}
    fast, _ = st.plant_truth({"seed": 1, "effects": delay, "timing": {"controller_rate_hz": 1000}})
    # the default 5 ms motor lag is a 5 ms delay; with motor_lag fitted beside, it is its own
    alone = st.timing_truth("command_delay", slow, ["command_delay"])
    assert alone == {"tau_d": [pytest.approx(0.055)]}
    assert st.timing_truth("command_delay", slow, ["motor_lag"]) == {"tau_d": [pytest.approx(0.05)]}
    assert st.timing_truth("command_delay", fast, []) == {"tau_d": [pytest.approx(0.0505)]}
    assert st.timing_truth("motor_lag", fast, []) == {"T_m": [pytest.approx(0.0005)]}
    assert st.timing_truth("rotational_drag", slow, []) is None


def _com_record(hidden_r, estimate, half, seed=77, fits_effects=("com_offset",)):
    truth = {"seed": seed, "effects": {"com_offset": {"r": hidden_r}} if hidden_r else {}}
    values = {"r": list(estimate)}
    ci = {"r": [[e - half, e + half] for e in estimate]}
    effects = {"com_offset": {"values": values, "ci95": ci}}
    for name in fits_effects:
        if name != "com_offset":
            effects[name] = {"values": {}, "ci95": {}}
    rnd = {
        "missing": [],
        "candidates": [],
        "model_effects": [],
        "rmse_physics": {"x": 1.0, "y": 1.0, "z": 1.0},
        "rmse_model": {"x": 0.5, "y": 0.5, "z": 0.5},
        "coverage": {"x": 0.95, "y": 0.95, "z": 0.95},
        "coverage_inside": {"x": 0.95, "y": 0.95, "z": 0.95},
        "claim_floor": 0.1,
    }
    return {
        "split": "tune2",
        "index": 3,
        "hidden": {"com_offset": {"r": hidden_r}} if hidden_r else {},
        "truth": truth,
        "rounds": [rnd],
        "fits": [{"command": "fit", "effects": effects}],
        "size_ratio": 2.0,
        "error": None,
        "seconds": 1.0,
        "timing": "100Hz",
        "flights": [
            {"role": "fit", "family": "fig8", "format": "csv"},
            {"role": "held", "family": "chirp", "format": "csv"},
        ],
    }


def test_rescoring_a_record_against_the_apparent_truth():
    """A CoM offset of 1 mm hidden on a vehicle whose spread adds millimetres: an
    estimate at hidden + the spread's offset with a 0.1 mm interval misses the hidden
    value and holds the apparent truth; one at the hidden value misses the apparent."""
    hidden = [0.001, 0.0, 0.0]
    probe = _com_record(hidden, hidden, 1e-4)
    app = st.apparent_truth(probe)
    shift = app["fit"]["shifts"]["com_offset"]["com_offset"]["r"]
    assert app["fit"]["method"] == "hover" and np.hypot(*shift[:2]) > 3e-4
    seen = [h + s for h, s in zip(hidden, shift, strict=True)]
    rec = _com_record(hidden, seen, 1e-4)
    j = sc.judge(rec, app)
    assert j["param_covered"] == [False, False, True]
    assert j["param_covered_apparent"] == [True, True, True]
    assert sc.judge(rec)["param_covered_apparent"] is None  # no apparent truth: no row
    wrong = sc.judge(_com_record(hidden, hidden, 1e-4), app)
    assert wrong["param_covered_apparent"] == [False, False, True]
    # the table shows the apparent rows only when given the apparent truth
    lines = table([rec], {"tune2:3": app})
    row = "| apparent truth inside the reported 95 % interval | >= 85 % | 3/3 = 100 %"
    assert any(line.startswith(row) for line in lines)
    assert not any("apparent" in line for line in table([rec]))


def _none_record(claims):
    rec = _com_record(None, [0.0, 0.0, 0.0], 1e-4)
    rnd = rec["rounds"][0]
    rnd["missing"] = [name for name, _ in claims]
    rnd["candidates"] = [{"name": name, "parameters": params} for name, params in claims]
    return rec


def test_none_draw_claims_that_are_the_defaults_look_alikes():
    probe = _none_record([])
    app = st.apparent_truth(probe)
    r = app["held"]["shifts"]["com_offset"]["com_offset"]["r"]
    spread_com = {"r": r, "r_ci95": [[v - 2e-4, v + 2e-4] for v in r]}
    delay_5ms = {"tau_d": [0.0052], "tau_d_ci95": [[0.0045, 0.0059]]}
    delay_20ms = {"tau_d": [0.02], "tau_d_ci95": [[0.018, 0.022]]}
    far_com = {"r": [0.01, 0.0, 0.0], "r_ci95": [[0.009, 0.011], [-1e-4, 1e-4], [-1e-4, 1e-4]]}
    inertia = {"scale": [1.1, 1.0, 1.0], "scale_ci95": [[1.05, 1.15], [0.9, 1.1], [0.9, 1.1]]}
    ok = _none_record([("com_offset", spread_com), ("command_delay", delay_5ms)])
    assert sc.judge(ok, app)["none_lookalike"] is True
    assert sc.judge(ok, app)["none_silent"] is False  # the strict row still counts them
    assert sc.judge(_none_record([("rotor_interference", {})]), app)["none_lookalike"] is True
    for bad in (("command_delay", delay_20ms), ("com_offset", far_com), ("inertia_error", inertia)):
        assert sc.judge(_none_record([bad]), app)["none_lookalike"] is False, bad[0]


def test_a_look_alike_named_after_also_is_judged_on_its_estimate_as_fit_makes_it():
    """report26 draw 42 (steps -> wobble, nothing hidden): com_offset named after "Also:",
    so the verdict quotes no estimate of it; the ranking's fit of it alone to the model's
    remaining error gave r_y -0.0095 (95 %: -0.0113 to -0.0077) for an apparent -0.0044,
    and the draw counted as a claim that is no default's look-alike. Its estimate as the
    fit command makes it (claim_estimates), -0.0044, is what is judged now."""
    probe = _none_record([])
    app = st.apparent_truth(probe)
    r = app["held"]["shifts"]["com_offset"]["com_offset"]["r"]
    alone = {"r": [v + 0.005 for v in r], "r_ci95": [[v + 0.004, v + 0.006] for v in r]}
    rec = _none_record([("com_offset", alone)])
    assert sc.judge(rec, app)["none_lookalike"] is False  # the ranking's fit alone
    as_fit = {"r": r, "r_ci95": [[v - 2e-4, v + 2e-4] for v in r]}
    rec["rounds"][0]["claim_estimates"] = {"com_offset": as_fit}
    assert sc.judge(rec, app)["none_lookalike"] is True
    off = {"r": [v + 0.005 for v in r], "r_ci95": [[v + 0.004, v + 0.006] for v in r]}
    rec["rounds"][0]["claim_estimates"] = {"com_offset": off}
    assert sc.judge(rec, app)["none_lookalike"] is False
    # a learned claim's estimate (its ``learned`` entry, as fit would) is recorded too
    from benchmarks.scorecard_draws import claim_estimates

    diag = {
        "claim_estimates": {},
        "learned_claims": ["com_offset"],
        "learned": [{"name": "com_offset", "estimate": as_fit}, {"name": "motor_lag"}],
    }
    assert claim_estimates(diag) == {"com_offset": as_fit}


def test_the_verdicts_quoted_estimate_is_read_per_component():
    verdict = (
        "Missing: com_offset — it explains 35 % of the model's remaining error. Estimated on "
        "this flight as fit would: r_y = 0.000918 m (95 %: 0.00067 to 0.00117); r_z = "
        "0.000412 m (95 %: -0.00156 to 0.00239, cannot be pinned down from this flight). "
        "r_x not claimed: the effect explains under 5 % of the x error here. Also: "
        "rotor_interference (the fit command adds them together: estimated 0.3 (95 %: 0.1 to 0.5)"
    )
    rec = _none_record([("com_offset", {})])
    rec["rounds"][0]["verdict"] = ["axis x: something else", verdict]
    assert sc.quoted_interval(rec, "com_offset", "r_y") == (0.00067, 0.00117)
    assert sc.quoted_interval(rec, "com_offset", "r_z") == (-0.00156, 0.00239)
    assert sc.quoted_interval(rec, "com_offset", "r_x") is None
    assert sc.quoted_interval(rec, "rotor_interference", "rotor_rotor") is None


def test_the_documented_rescoring_is_what_the_kept_records_give():
    """docs/scorecard.md's apparent-truth rows are what report3's and report2's records
    and their kept apparent truths give (a scorer change shows in the doc)."""
    import json
    from pathlib import Path

    from benchmarks.scorecard import read_records

    root = Path(__file__).resolve().parent.parent
    doc = (root / "docs" / "scorecard.md").read_text()
    section = doc[doc.index("## 2026-11-26: the apparent truth") :]
    for split in ("report3", "report2"):
        folder = root / "benchmarks" / "scorecard-runs" / f"{split}-2026-11-26"
        records = [r for r in read_records([folder / f"{split}.jsonl"]) if not r["error"]]
        apparent = json.loads((folder / f"{split}.apparent.json").read_text())
        judged = [sc.judge(r, apparent[f"{r['split']}:{r['index']}"]) for r in records]
        for key in ("param_covered", "param_covered_apparent", "none_lookalike"):
            k, n = sc.tally(judged, key)
            assert f"{k}/{n} = {100 * k / n:.0f} %" in section, (split, key)
