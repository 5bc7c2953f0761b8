"""plan --objective effects: flights that pin down and separate named physical effects."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.linalg import cho_solve, cholesky
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.logs import align
from omavctl.planning.effects_objective import (
    EffectsPrior,
    effects_from_evaluation,
    information_gain,
    max_cross_correlation,
)
from omavctl.planning.gp import GPAxes
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.trajectory import write_trajectory
from omavctl.sim.truth import truth_from_tree

runner = CliRunner()
EFFECTS = "rotational_drag,command_delay"
TRUTH = {
    "seed": 1,
    "effects": {"rotational_drag": {"D": [0.05, 0.05, 0.03]}, "command_delay": {"tau_d": 0.03}},
}


@pytest.fixture(scope="module")
def setup(tmp_path_factory, vehicle):
    """An 8 s figure-8 and a model with drag and delay fitted on one flight of it."""
    tmp = tmp_path_factory.mktemp("plan-effects")
    task = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.5)
    task_path = tmp / "task.csv"
    write_trajectory(task_path, task)
    flight = align(simulate(task, vehicle, truth_from_tree(TRUTH, vehicle), seed=1).log)
    fitted = fit_model([flight], vehicle, effects=EFFECTS.split(","), points=40, restarts=0)
    model_path = tmp / "model.npz"
    save_model(model_path, fitted.model)
    return tmp, task_path, model_path, fitted.model


def _gp(rng, n: int, d: int) -> GPAxes:
    return GPAxes(
        inputs=rng.standard_normal((n, d)),
        targets=rng.standard_normal((n, 3)),
        mean=np.zeros(3),
        signal_variance=np.array([0.5, 0.2, 0.0]),  # axis z: GP switched off
        length_scales=rng.uniform(0.8, 2.0, (3, d)),
        noise_variance=np.array([0.01, 0.02, 0.03]),
    )


def test_information_gain_is_the_gls_information_of_old_and_new_points_together():
    rng = np.random.default_rng(0)
    n, m, d, p = 30, 7, 4, 3
    gp = _gp(rng, n, d)
    x_old = rng.standard_normal((n, 3, p))
    picks = rng.standard_normal((2, m, d))
    x_new = rng.standard_normal((2, m, 3, p))
    gain = information_gain(gp, x_old, picks, x_new)
    for b in range(2):
        z = np.concatenate([gp.inputs, picks[b]])
        x = np.concatenate([x_old, x_new[b]])
        full, old = np.zeros((p, p)), np.zeros((p, p))
        for a in range(3):
            for zz, xx, out in ((z, x, full), (gp.inputs, x_old, old)):
                k = gp.kernel(a, zz, zz) + gp.noise_variance[a] * np.eye(len(zz))
                out += xx[:, a].T @ cho_solve((cholesky(k, lower=True), True), xx[:, a])
        np.testing.assert_allclose(gain[b], full - old, rtol=1e-8, atol=1e-8)


def test_cross_correlation_ignores_parameters_of_the_same_effect():
    cov = np.array([[1.0, 0.9, 0.0], [0.9, 1.0, 0.5], [0.0, 0.5, 1.0]])
    info = np.linalg.inv(cov)
    assert max_cross_correlation(info, np.array([0, 0, 1])) == pytest.approx(0.5)
    assert max_cross_correlation(info, np.array([0, 0, 0])) == 0.0


def test_the_prior_information_reproduces_the_drag_standard_errors_fit_wrote(setup):
    *_, model = setup
    prior = EffectsPrior.from_model(model, GPAxes.from_model(model), ["rotational_drag"])
    se = prior.standard_errors(prior.information)
    # the same GLS as fit's joint estimate; fit's cross-validation adjusts the noise and
    # signal variances afterwards, which moves them by a few tens of percent at most.
    # fit then widens its errors for autocorrelated residuals (docs/intervals.md): the
    # planner's white GLS errors are at most those, equal where the prior decides (D_z)
    fit_se = model.effects["rotational_drag"].stderr["D"]
    assert np.all(se <= 1.3 * fit_se), (se, fit_se)
    np.testing.assert_allclose(se[2], fit_se[2], rtol=0.3)


def test_cli_effects_plan_scores_both_objectives_and_is_deterministic(setup):
    """On a 4 s figure-8 (three plans; the 8 s task doubled their simulation): the
    checks are equalities and orderings the GLS guarantees, not margins."""
    tmp, _, model_path, _ = setup
    task_path = tmp / "task-4s.csv"
    write_trajectory(task_path, fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=4.0, ramp=1.5))
    outs = []
    for name in ("a", "b"):
        out, scores = tmp / f"{name}.csv", tmp / f"{name}-scores.csv"
        args = ["plan", "--task", str(task_path), "--model", str(model_path), "--out", str(out)]
        args += ["--candidates", "4", "--sims", "2", "--test-points", "80", "--points", "10"]
        args += ["--objective", "effects", "--effects", EFFECTS, "--seed", "3"]
        result = runner.invoke(app, [*args, "--scores", str(scores), "--json", "-q"])
        assert result.exit_code == 0, result.output
        outs.append((out.read_bytes(), scores.read_bytes(), json.loads(result.stdout)))
    assert outs[0][:2] == outs[1][:2]
    # --json carries the warnings the terminal prints (a script must see them too)
    html = tmp / "a.html"
    shown = runner.invoke(app, [*args, "--report", str(html)])
    assert shown.exit_code == 0, shown.output
    # its "vs task" is of the standard errors, not of the -log det cost (a new user read
    # "cost -76.21, -77.9 % against flying the task itself (-52.09)")
    page = html.read_text()
    assert "its standard errors" in page and "std error vs task (- better)" in page
    printed = [
        ln.removeprefix("warning: ")
        for ln in shown.output.splitlines()
        if ln.startswith("warning: ")
    ]
    assert outs[0][2]["warnings"] == printed
    lines = outs[0][1].decode().splitlines()
    header = lines[0].split(",")
    rows = [dict(zip(header, line.split(","), strict=True)) for line in lines[1:]]
    feasible = [r for r in rows if r["feasible"] == "true"]
    assert feasible
    for r in feasible:  # both objectives for every candidate; the effects one ranks
        assert float(r["variance_cost"]) > 0 and r["cost"] == r["effects_cost"]
        assert 0 < float(r["effects_rel_se"]) and 0 <= float(r["effects_max_correlation"]) <= 1
    # --json carries the same numbers per candidate as the scores CSV
    for r, c in zip(rows, outs[0][2]["candidates"], strict=True):
        for column in ("variance_cost", "effects_cost", "effects_rel_se"):
            assert (c[column] is None) == (r[column] == "")
            if c[column] is not None:
                assert abs(c[column] - float(r[column])) <= 1e-8 * max(1.0, abs(c[column]))
        reason = (c["reason"] or "").replace(",", ";")
        assert c["feasible"] == (r["feasible"] == "true") and reason == r["reason"]
    best = min(feasible, key=lambda r: float(r["effects_cost"]))
    summary = outs[0][2]["effects"]
    assert outs[0][2]["best"] == int(best["candidate"])
    assert summary["names"] == EFFECTS.split(",")
    assert len(summary["stderr_before"]) == len(summary["stderr_after"]) == 4
    # fit's own standard errors beside the planner's (theta is the parameter for both)
    model = setup[3]
    stored = [
        *model.effects["rotational_drag"].stderr["D"],
        *model.effects["command_delay"].stderr["tau_d"],
    ]
    assert summary["stderr_fit"] == pytest.approx([float(v) for v in stored], rel=1e-12)
    # what the lines show: the planner's times the factors (effects_forecast), never
    # above what is shown now (a flight adds information)
    factor = summary["forecast_factor"]
    now = [
        f if f is not None else b
        for f, b in zip(summary["stderr_fit"], summary["stderr_before"], strict=True)
    ]
    after = zip(summary["stderr_after"], now, strict=True)
    assert summary["stderr_after_forecast"] == pytest.approx(
        [min(v * factor, n) for v, n in after], rel=1e-12
    )
    task = zip(summary["stderr_task"], summary["autocorrelation_factor"], now, strict=True)
    assert summary["stderr_task_forecast"] == pytest.approx(
        [min(v * f, n) for v, f, n in task], rel=1e-12
    )
    # the planned flight adds information: no standard error grows
    assert all(
        a <= b * (1 + 1e-9)
        for a, b in zip(summary["stderr_after"], summary["stderr_before"], strict=True)
    )


def test_variance_plan_also_reports_the_effects_numbers(setup):
    tmp, task_path, model_path, _ = setup
    out, scores = tmp / "v.csv", tmp / "v-scores.csv"
    args = ["plan", "--task", str(task_path), "--model", str(model_path), "--out", str(out)]
    args += ["--candidates", "3", "--sims", "2", "--test-points", "80", "--points", "10"]
    result = runner.invoke(app, [*args, "--scores", str(scores)])
    assert result.exit_code == 0, result.output
    # "now" is fit's own standard error (its 1-D search for the delay), never the
    # planner's white linearisation, which a new user found 6-8x smaller than fit's
    text = " ".join(result.output.split())
    tau_d = float(setup[3].effects["command_delay"].stderr["tau_d"][0])
    assert f"± {tau_d:.3g} s now (fit's)" in text
    # the forecast after the flight carries the one factor (docs/plan-effects.md)
    assert re.search(r"after the flight \(planner's ×[0-9.]+(, no better than now)?\)", text)
    # the rotors' thrust spread stays whatever is flown: the forecast, under it, said
    # nothing of it, so a new user read 'r_x ± 0.000946 after the flight' beside fit's
    # interval of ± 0.0043 m (± 0.0019 of it the spread)
    spread = float(setup[3].effects["rotational_drag"].systematic["D"][0])
    assert spread > 0
    assert (
        f"± {spread:.3g} spread beside each: the rotors' thrust spread as the fit flight passes"
        in text
    )
    lines = scores.read_text().splitlines()
    header = lines[0].split(",")
    for line in lines[1:]:
        r = dict(zip(header, line.split(","), strict=True))
        if r["feasible"] == "true":
            assert r["cost"] == r["variance_cost"] and float(r["effects_cost"]) < 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--effects", "wind"], "unknown effect 'wind'"),
        (["--effects", "gyro_bias"], "cannot be identified"),
        (["--objective", "entropy"], "unknown --objective 'entropy'"),
    ],
)
def test_bad_effects_options_fail_in_one_line(setup, extra, message):
    tmp, task_path, model_path, _ = setup
    args = ["plan", "--task", str(task_path), "--model", str(model_path)]
    args += ["--out", str(tmp / "x.csv"), "--candidates", "1", "--sims", "1", "-q"]
    if extra[0] == "--effects":
        extra = ["--objective", "effects", *extra]
    result = runner.invoke(app, [*args, *extra])
    text = result.output.strip()
    assert result.exit_code == 2 and "Traceback" not in text, text
    assert len(text.splitlines()) == 1 and message in text, text


def test_effects_named_by_an_evaluation(tmp_path):
    path = tmp_path / "eval.json"
    diagnosis = {
        "missing": ["rotational_drag"],
        "missing_effects": [
            {"name": "rotational_drag", "ambiguous_with": ["command_delay"]},
            {"name": "com_offset", "ambiguous_with": ["inertia_error"]},
        ],
    }
    path.write_text(json.dumps({"diagnosis": diagnosis}))
    assert effects_from_evaluation(path) == ("rotational_drag", "command_delay")
    path.write_text("{}")
    result = runner.invoke(
        app,
        [
            "plan",
            "--task",
            str(path),
            "--model",
            str(path),
            "--out",
            str(tmp_path / "o.csv"),
            "--evaluation",
            str(path),
            "-q",
        ],
    )
    assert result.exit_code == 2 and "diagnosis" in result.output


def test_an_effects_flight_pins_hidden_drag_and_delay_down_better_than_the_others(tmp_path):
    """The benchmark (benchmarks/bench_effects_plan.py) on a shorter flight: the
    standard errors fit reports after the effects plan's flight are well below those
    after flying the task again and below those after the variance plan's flight, and
    its estimates are near the truth."""
    from benchmarks.bench_effects_plan import omavctl_in_process, run_case

    # the commands in this process (the benchmark starts a process per command: 11 here)
    # the refits on two logs keep 100 points each (200 in all, the one-log default; fit
    # keeps each log's own points since session 16, and 400 doubled this test's time)
    r = run_case(
        tmp_path, seed=1, duration=12.0, candidates=12, sims=2, run=omavctl_in_process, points=100
    )
    print({k: round(r[k]["rel_se_gmean"], 3) for k in ("first", "effects", "variance", "task")})
    print({k: round(r[k]["max_rel_error"], 3) for k in ("first", "effects", "variance", "task")})
    assert r["se_ratio_vs_task"] >= 1.5
    assert r["se_ratio_vs_variance"] >= 1.1
    # on 12 s flights the effective delay (30 ms + the actuators' lags) and D are
    # within 40 %; flying the task again leaves D_z off by a factor of several
    assert r["effects"]["max_rel_error"] < 0.4
    assert r["effects"]["max_rel_error"] < r["task"]["max_rel_error"] / 3


def test_a_weak_correlation_is_not_called_inseparable():
    from omavctl.planning.effects_forecast import correlation_remark

    assert correlation_remark(0.5, 0.3) == ""
    assert (
        correlation_remark(0.04, 0.06) == " (a little more correlated after it, still told apart)"
    )
    assert correlation_remark(0.4, 0.8) == (
        " (the flight correlates them more: it does not tell them apart)"
    )
    assert correlation_remark(0.762, 0.757) == " (still too correlated after it to tell them apart)"


def test_the_headline_does_not_promise_to_pin_down_what_it_correlates_more():
    """'is expected to pin down com_offset, rotor_interference ... (the flight correlates
    them more: it does not tell them apart)' read as a contradiction to a new user."""
    from types import SimpleNamespace

    from omavctl.planning.effects_forecast import _headline

    result = SimpleNamespace(best=3, objective="variance")
    rel = {"now": 0.031, "after_forecast": 0.022, "task_forecast": 0.028}
    worse = {"before": 0.65, "after": 0.79, "task": 0.57}
    line = _headline(result, ["com_offset", "rotor_interference"], rel, worse)
    assert "is expected to narrow com_offset, rotor_interference" in line
    assert "does not tell them apart" in line and "pin down" not in line
    better = {"before": 0.79, "after": 0.5, "task": 0.7}
    line = _headline(result, ["com_offset", "rotor_interference"], rel, better)
    assert "is expected to separate and pin down com_offset" in line
    assert "is expected to pin down com_offset:" in _headline(result, ["com_offset"], rel, worse)
    # fit's relative standard error now and the forecasts of it, as the lines below say
    assert "(geometric mean, fit's and its forecasts) 0.031 now, 0.022 after it, 0.028" in line
    assert "not pinned down" not in line and "forecast to narrow" not in line


def test_the_headline_says_a_forecast_above_the_value_is_not_pinned_down():
    """'is expected to pin down rotor_interference: relative standard error ... 2.92 now,
    2.26 after it, 2.54 after flying the task again' (a new user: an error above the
    value is not pinned down); and where flying the task again is forecast to do better,
    the headline says so."""
    from types import SimpleNamespace

    from omavctl.planning.effects_forecast import _headline

    result = SimpleNamespace(best=0, objective="variance")
    rel = {"now": 2.92, "after_forecast": 2.26, "task_forecast": 2.54}
    corr = {"before": 0.5, "after": 0.4, "task": 0.5}
    line = _headline(result, ["rotor_interference"], rel, corr)
    assert "is expected to narrow rotor_interference:" in line
    assert line.endswith(
        "2.54 after flying the task again (not pinned down after it: the standard error "
        "stays above the size it is relative to, the value or, where that is small or not "
        "fitted, the effect's typical size)"
    )
    line = _headline(result, ["rotor_interference"], {**rel, "task_forecast": 2.0}, corr)
    assert line.endswith("(flying the task again is forecast to narrow it more)")
    line = _headline(result, ["com_offset", "rotor_interference"], rel, corr)
    assert "is expected to separate and narrow com_offset, rotor_interference" in line
    # 0.76 now, 0.76 after it (a new user's effects plan): neither a fall as printed nor
    # a pair told apart, so no "separate"
    same = {"before": 0.762, "after": 0.757, "task": 0.77}
    line = _headline(result, ["com_offset", "rotor_interference"], rel, same)
    assert "is expected to narrow com_offset, rotor_interference" in line
    assert line.endswith("(still too correlated after it to tell them apart)")


def test_the_planned_flights_forecast_carries_the_linear_effects_median_factor():
    """make bench-effects, seed 1 (a drag and a 30 ms delay, figure-8 first flight): fit's
    standard error over the planner's was 4.92, 4.25 for D_x, D_y, 1.02 for D_z (left at
    its prior: the planner's 0.078 is the prior's) and 37 for tau_d (its interval allowed
    213 ms for a lag's form). Each parameter's own factor made the planned flight's
    forecasts 0.07-15x off what fit then gave; the task's held (0.86-1.15x)."""
    from omavctl.planning.effects_forecast import forecast_factors

    before = np.array([0.0532, 0.0310, 0.0781, 0.00580])
    fit_se = np.array([0.2617, 0.1315, 0.0798, 0.2147])
    prior = np.array([0.1, 0.1, 0.1, 0.05])
    searched = np.array([False, False, False, True])
    own, factor = forecast_factors(before, fit_se, prior, searched)
    assert own == pytest.approx(fit_se / before)
    assert factor == pytest.approx(np.median([0.2617 / 0.0532, 0.1315 / 0.0310]))
    # D_z at its prior and the delay's search are left out; with only the delay, its own
    only_delay = forecast_factors(before[3:], fit_se[3:], prior[3:], searched[3:])
    assert only_delay[1] == pytest.approx(0.2147 / 0.0058)
    # fit without a standard error: factor 1, never below 1
    none = forecast_factors(before, np.full(4, np.nan), prior, searched)
    assert none[0].tolist() == [1.0] * 4 and none[1] == 1.0
    one = forecast_factors(np.array([0.1]), np.array([0.05]), np.array([1.0]), np.array([False]))
    assert one[1] == 1.0  # fit's below the planner's: at least 1


def test_forecasts_for_effects_no_fit_calibrates_are_called_lower_bounds():
    """A new user planned for com_offset with a model that held no fitted effect: the
    lines said '± 0.000491 after the flight (planner's ×1)' and fit then gave ±0.0014:
    with nothing fitted, the factor is no calibration, and the lines say so."""
    from omavctl.planning.effects_forecast import _parameter_lines
    from omavctl.planning.effects_objective import EffectsPrior

    prior = EffectsPrior(("com_offset",), np.zeros(3), np.full(3, 0.01), np.eye(3))
    before, none = np.full(3, 7e-4), np.full(3, np.nan)
    forecasts = (np.full(3, 5e-4), np.full(3, 6.6e-4))
    lines = _parameter_lines(prior, before, none, forecasts, (np.ones(3), 1.0))
    assert lines[0].startswith("  com_offset.r_x: not in the model (prior ± 0.0007 m)")
    assert lines[-1].startswith("  (forecasts: the planner's white linearisation, ×1, uncalibrated")
    assert lines[-1].endswith("read them as lower bounds)")
    fitted = EffectsPrior(("com_offset",), np.full(3, 0.01), np.full(3, 0.01), np.eye(3),
                          fitted=("com_offset",), fit_stderr=np.full(3, 2e-3))  # fmt: skip
    lines = _parameter_lines(fitted, before, np.full(3, 2e-3), forecasts, (np.ones(3) * 3, 3.0))
    assert lines[-1].startswith("  (forecasts of fit's standard errors")
    # a forecast held at the standard error now says so: a new user multiplied the
    # planner's 1.76e-05 by the printed x2.8 and did not get the printed 4.81e-05
    capped = (np.array([True, False, False]), np.zeros(3, bool))
    lines = _parameter_lines(
        fitted, before, np.full(3, 2e-3), forecasts, (np.ones(3) * 3, 3.0), capped
    )
    assert (
        "after the flight (planner's ×3, no better than now), ± 0.00066 after the task (×3)"
        in (lines[0])
    )
    assert "no better than now" not in lines[1]


def test_an_evaluation_that_names_nothing_missing_is_said_not_silently_replaced(setup):
    """A new user planned with --objective effects --evaluation E, E naming nothing
    missing: the plan went on for the model's own effects with no word ('notes: []')."""
    tmp, task_path, model_path, _ = setup
    ev = tmp / "nothing.json"
    ev.write_text(json.dumps({"diagnosis": {"missing": [], "missing_effects": []}}))
    args = ["plan", "--task", str(task_path), "--model", str(model_path)]
    args += ["--out", str(tmp / "n.csv"), "--objective", "effects", "--evaluation", str(ev)]
    args += ["--candidates", "3", "--sims", "2", "--test-points", "80", "--points", "10"]
    result = runner.invoke(app, [*args, "--json"])
    assert result.exit_code == 0, result.output
    notes = json.loads(result.stdout)["notes"]
    assert notes[0] == (
        f"{ev} names no effect missing: the plan is for the model's own fitted effects "
        "(name others with --effects)"
    )
