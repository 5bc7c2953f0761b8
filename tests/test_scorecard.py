"""The scorecard's scoring (benchmarks/scorecard_score.py) on synthetic records, its
draws' determinism and split, and the re-analysis from JSON lines."""

from __future__ import annotations

import copy
import json
import math

import pytest
from scipy.stats import binomtest

from benchmarks import scorecard_score as sc
from benchmarks.scorecard import analyse, read_records, table
from benchmarks.scorecard_draws import SPLITS, draw_spec, hidden_parameters
from omavctl.physics.effects import EFFECTS


def _round(missing=(), ambiguous=None, effects=(), physics=None, model=None, cover=None):
    ambiguous = ambiguous or {}
    physics = physics or {"x": 1.0, "y": 1.0, "z": 1.0}
    return {
        "missing": list(missing),
        "candidates": [{"name": n, "ambiguous_with": ambiguous.get(n, [])} for n in missing],
        "model_effects": list(effects),
        "rmse_physics": physics,
        "rmse_model": model or {a: 0.5 * v for a, v in physics.items()},
        "coverage": cover or {"x": 0.95, "y": 0.95, "z": 0.95},
        "coverage_inside": {"x": 0.95, "y": 0.97, "z": 0.999},
        "claim_floor": 0.1,
    }


def _record(hidden, rounds, fits=(), size_ratio=2.0):
    return {
        "split": "tune",
        "index": 0,
        "hidden": hidden,
        "rounds": rounds,
        "fits": list(fits),
        "size_ratio": size_ratio,
        "error": None,
        "seconds": 100.0,
        "timing": "100Hz",
        "flights": [{"family": "chirp", "format": "ros1"}, {"family": "fig8", "format": "csv"}],
    }


DRAG = {"rotational_drag": {"D": [0.05, 0.04, 0.03]}}


def test_wilson_interval_matches_scipy():
    for k, n in [(0, 10), (3, 10), (10, 10), (26, 32), (1, 200)]:
        lo, hi = sc.wilson(k, n)
        ref = binomtest(k, n).proportion_ci(method="wilson")
        assert lo == pytest.approx(ref.low, abs=1e-12)
        assert hi == pytest.approx(ref.high, abs=1e-12)
    assert sc.wilson(0, 0) == (0.0, 1.0)
    # 26/32 (the first-answer rate) is 0.65-0.91
    lo, hi = sc.wilson(26, 32)
    assert (round(lo, 2), round(hi, 2)) == (0.65, 0.91)


def test_naming_the_hidden_effect_first_is_right():
    rec = _record(DRAG, [_round(missing=["rotational_drag"])])
    assert sc.first_answer_right(rec)
    assert not sc.first_answer_right(_record(DRAG, [_round()]))  # missed it


def test_ambiguous_set_holding_the_truth_counts_as_right():
    amb = {"inertia_error": ["rotational_drag"]}
    rec = _record(DRAG, [_round(missing=["inertia_error"], ambiguous=amb)])
    assert sc.first_answer_right(rec)
    # the same name without the look-alike in its set is wrong and invented
    rec = _record(DRAG, [_round(missing=["inertia_error"])])
    assert not sc.first_answer_right(rec)


def test_claim_on_a_none_draw_counts_as_invented():
    rec = _record({}, [_round(missing=["command_delay"]), _round(effects=["command_delay"])])
    assert not sc.first_answer_right(rec)
    assert sc.ends_invented(rec)
    assert sc.judge(rec)["invented"] is True
    clean = _record({}, [_round()])
    assert sc.first_answer_right(clean) and not sc.ends_invented(clean)


def test_naming_a_documented_default_imperfection_is_not_invented():
    for name in ("rotor_interference", "com_offset", "servo_lag", "motor_lag"):
        rec = _record({}, [_round(missing=[name]), _round(effects=[name])])
        assert sc.first_answer_right(rec), name
        assert not sc.ends_invented(rec), name
    # but a hidden drag answered only with a default imperfection is not right
    rec = _record(DRAG, [_round(missing=["rotor_interference"])])
    assert not sc.first_answer_right(rec)


def test_physics_fall_and_worse_axes():
    first = _round(physics={"x": 3.0, "y": 4.0, "z": 0.0})  # RSS 5
    last = _round(
        physics={"x": 1.2, "y": 1.6, "z": 0.0},  # RSS 2: fell 60 %
        model={"x": 1.0, "y": 1.7, "z": 0.0},  # y 1.06x physics-only
    )
    rec = _record(DRAG, [first, last])
    assert sc.physics_fall(rec) == pytest.approx(0.6)
    assert sc.worse_axes(last) == ["y"]
    j = sc.judge(rec)
    assert j["fall"] is True and j["worse"] is True
    # a none draw has no fall to judge
    assert sc.judge(_record({}, [first]))["fall"] is None


def test_parameters_against_stderr_or_a_real_interval():
    fit = {
        "effects": {"rotational_drag": {"D": [0.05, 0.03, 0.031], "D_stderr": [0.001, 0.001, None]}}
    }
    rec = _record(DRAG, [_round()], fits=[{"effects": {}}, fit])
    checks = {c.name: c for c in sc.param_checks(rec)}
    assert checks["D[0]"].within_tol and checks["D[0]"].covered  # 0.05 +- 0.00196
    assert not checks["D[1]"].within_tol and not checks["D[1]"].covered  # 0.03 for 0.04
    assert checks["D[2]"].within_tol and checks["D[2]"].interval is None  # no stderr
    assert not checks["D[2]"].covered
    # a real interval wins over the standard error, in either layout
    wide = copy.deepcopy(fit)
    wide["effects"]["rotational_drag"]["D_ci95"] = [[0.04, 0.06], [0.02, 0.045], [0.0, 0.1]]
    assert all(c.covered for c in sc.param_checks(_record(DRAG, [_round()], fits=[wide])))
    nested = {"T_s": [0.02], "T_s_stderr": [1e-4], "ci95": {"T_s": [0.019, 0.041]}}
    lag = _record(
        {"servo_lag": {"T_s": 0.04}}, [_round()], fits=[{"effects": {"servo_lag": nested}}]
    )
    (c,) = sc.param_checks(lag)
    assert c.covered and not c.within_tol and c.interval == (0.019, 0.041)


def test_parameters_in_fit_json_layout():
    # fit --json prints {"values": {P}, "stderr": {P}}; a later fit of the same effect wins
    first = {"com_offset": {"values": {"r": [0.1, 0.1, 0.1]}, "stderr": {"r": [1, 1, 1]}}}
    last = {
        "com_offset": {
            "values": {"r": [0.0205, -0.016, 0.0121]},
            "stderr": {"r": [0.0001, 0.0001, 0.0001]},
            "ci95": {"r": [[0.019, 0.022], [-0.017, -0.015], [0.011, 0.013]]},
        }
    }
    hidden = {"com_offset": {"r": [0.021, -0.0175, 0.012]}}
    rec = _record(hidden, [_round()], fits=[{"effects": first}, {"effects": last}])
    checks = sc.param_checks(rec)
    assert [c.estimate for c in checks] == [0.0205, -0.016, 0.0121]
    assert [c.covered for c in checks] == [True, False, True]  # the ci95, not +- 1.96 SE
    assert all(c.within_tol for c in checks)


def test_coverage_checks_and_size_bins():
    rec = _record(DRAG, [_round(cover={"x": 0.84, "y": 0.9, "z": 0.99})], size_ratio=0.5)
    low, inside = sc.coverage_checks(rec)
    assert low == [False, True, True] and inside == [True, True, False]
    assert sc.size_bin(rec) == "< 1x floor"
    assert sc.size_bin({**rec, "size_ratio": 3.0}) == "3-10x floor"
    assert sc.size_bin({**rec, "hidden": {}}) == "none"
    # two hidden effects: the larger one's size over the first evaluation's floor
    two = {**rec, "sizes": {"gyro_bias": 0.001, "com_offset": 1.79}}
    assert sc.size_ratio(two) == pytest.approx(17.9)
    assert sc.size_bin(two) == ">= 10x floor"


def test_tables_rebuild_from_json_lines(tmp_path, capsys):
    right = _record(DRAG, [_round(missing=["rotational_drag"])])
    wrong = {**_record({}, [_round(missing=["gyro_bias"])]), "index": 1}
    broken = {**_record(DRAG, []), "index": 2, "error": "omavctl fit: exit 2: error: x"}
    path = tmp_path / "tune.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in (right, wrong, broken)))
    records = read_records([path])
    assert len(records) == 3
    first = next(line for line in table(records) if line.startswith("| first answer"))
    assert "1/2 = 50 % [9, 91]" in first
    analyse([path], tmp_path / "t.md")
    text = (tmp_path / "t.md").read_text()
    assert "failed to run: 1" in text and "said gyro_bias" in text and "exit 2" in text


def test_draws_are_deterministic_and_split():
    names = sorted(EFFECTS)
    assert draw_spec("tune", 3, names) == draw_spec("tune", 3, names)
    assert draw_spec("tune", 3, names) != draw_spec("tune", 4, names)
    held_back = SPLITS["report"]["held_back"]
    for i in range(20):
        tune, report = draw_spec("tune", i, names), draw_spec("report", i, names)
        fams = [f["family"] for f in tune["flights"]]
        assert held_back not in fams and fams[0] != fams[1]
        assert held_back in [f["family"] for f in report["flights"]]
        assert report["seed"] != tune["seed"]
        for spec in (tune, report):
            assert len(spec["hidden"]) <= 2 and set(spec["hidden"]) <= set(names)
    # every registered effect has a size to draw, every component non-zero
    for name in names:
        params = hidden_parameters(name, 0.5, __import__("numpy").random.default_rng(0))
        values = [v for p in params.values() for v in (p if isinstance(p, list) else [p])]
        assert all(math.isfinite(v) and v != 0 for v in values)


def _eval_output(missing, command, effects=()):
    """``evaluate --json`` as the CLI prints it (the keys the scorecard reads)."""
    axes = {"x": 0.2, "y": 0.3, "z": 0.1}
    return {
        "missing": list(missing),
        "fit_command": command,
        "rmse_nominal": axes,
        "models": [
            {"effects": list(effects), "rmse": axes, "rmse_effects": axes, "coverage_2sigma": axes}
        ],
        "flags": [],
        "verdict": [{"key": "missing", "text": "Missing: " + ", ".join(missing)}],
    }


def test_the_loop_follows_the_printed_fit_command_for_two_rounds(tmp_path, monkeypatch):
    """The loop runs fit, evaluate, then each printed fit command and evaluate again,
    at most twice, and reads each evaluation's file beside its --json object."""
    import benchmarks.scorecard_draws as draws

    calls = []
    replies = {
        "m0.npz": _eval_output(
            ["com_offset"], "omavctl fit fit.bag --effects com_offset --out 'm 1.npz'"
        ),
        "m 1.npz": _eval_output(
            ["servo_lag"],
            "omavctl fit fit.bag --effects com_offset,servo_lag --out m2.npz",
            ["com_offset"],
        ),
        "m2.npz": _eval_output(
            ["motor_lag"], "omavctl fit fit.bag --out m3.npz", ["com_offset", "servo_lag"]
        ),
    }

    def fake(args, cwd, log):
        calls.append(args)
        if args[0] == "fit":
            return {"effects": {"com_offset": {"values": {"r": [0.01, 0, 0]}}}}
        model = args[args.index("--model") + 1]
        doc = {
            "diagnosis": {
                "missing_effects": [
                    {"name": n, "ambiguous_with": []} for n in replies[model]["missing"]
                ],
                "method": {"min_contribution_rms": 0.09, "measurement_noise_std": 0.03},
            },
            "envelope": {"coverage_inside": {"x": 0.95, "y": 0.95, "z": 0.95}},
        }
        (cwd / args[args.index("--out") + 1]).write_text(json.dumps(doc))
        return replies[model]

    monkeypatch.setattr(draws, "omavctl", fake)
    spec = {"flights": [{"log": "fit.bag"}, {"log": "held.mcap"}]}
    rounds, fits = draws.loop(spec, tmp_path, [])
    assert [c[0] for c in calls] == ["fit", "evaluate"] * 3  # two rounds, not three
    assert calls[2][-2:] == ["--out", "m 1.npz"]  # the shell-quoted path kept whole
    assert [r["missing"] for r in rounds] == [["com_offset"], ["servo_lag"], ["motor_lag"]]
    assert rounds[1]["model_effects"] == ["com_offset"] and rounds[0]["claim_floor"] == 0.09
    assert fits[1]["command"].startswith("omavctl fit fit.bag --effects com_offset")
    # a printed command that is not an omavctl fit ends the draw as a failed step
    replies["m0.npz"] = _eval_output(["com_offset"], "echo fit --out x.npz")
    with pytest.raises(draws.StepFailed, match="not an omavctl fit"):
        draws.loop(spec, tmp_path, [])


def test_the_documented_baseline_rebuilds_from_its_records():
    """docs/scorecard.md's tables and failure list are what the committed records
    give: the baseline can be re-analysed, and a scoring change shows in the doc."""
    from pathlib import Path

    from benchmarks.scorecard import by_effect, failures

    root = Path(__file__).resolve().parent.parent
    records = read_records(sorted((root / "benchmarks" / "scorecard-baseline").glob("*.jsonl")))
    assert len(records) == 42
    doc = (root / "docs" / "scorecard.md").read_text()
    for split in ("tune", "report"):
        recs = [r for r in records if r["split"] == split]
        for line in [*table(recs), *by_effect(recs)]:
            assert line in doc, line
    for line in failures(records):
        assert line in doc, line
