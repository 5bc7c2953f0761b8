"""omavctl plan: informative references from a fitted model."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.learn.fit import fit_model
from omavctl.learn.model import SCHEMA_FITTED
from omavctl.learn.model_file import load_model, save_model
from omavctl.logs import align
from omavctl.planning.gp import GPAxes, PathwiseSamples, posterior_variance_with_data
from omavctl.planning.planner import PlanSettings, _test_points, plan
from omavctl.planning.rollout import rollout
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.trajectory import read_trajectory, write_trajectory
from omavctl.sim.truth import truth_from_tree
from tests.conftest import rebuilt

runner = CliRunner()


@pytest.fixture(scope="module")
def setup(tmp_path_factory, vehicle):
    """A task (8 s figure-8), a model fitted on one flight of it, both as files."""
    tmp = tmp_path_factory.mktemp("plan")
    task = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.5)
    task_path = tmp / "task.csv"
    write_trajectory(task_path, task)
    flight = align(simulate(task, vehicle, truth_from_tree({"seed": 1}, vehicle), seed=1).log)
    model = fit_model([flight], vehicle, points=40, restarts=0).model
    model_path = tmp / "model.npz"
    save_model(model_path, model)
    return tmp, task_path, model_path


def test_covering_the_task_region_scores_lower_than_staying_away(setup):
    _, task_path, model_path = setup
    model, task = load_model(model_path), read_trajectory(task_path)
    settings = PlanSettings(sims=2, test_points=200, points=20)
    rng = np.random.default_rng(0)
    gp = GPAxes.from_model(model)
    samples = PathwiseSamples(gp, settings.sims, rng)
    roll = rollout(model, samples, task.data[None], task.t, settings.sims)
    visited = roll.inputs.reshape(-1, gp.d)
    test = _test_points(visited, float(roll.gap.mean()), settings.test_points, rng)
    inside = visited[rng.choice(visited.shape[0], size=20, replace=False)]
    # the same points moved well outside the task region (3 std of every input)
    away = inside + 3.0 * np.sign(inside.mean(axis=0) + 1e-9)
    var = posterior_variance_with_data(gp, np.stack([inside, away]), test).mean(axis=(1, 2))
    prior = gp.posterior_variance(test).mean()
    assert var[0] < var[1] <= prior + 1e-12
    assert var[0] < 0.9 * prior


def test_the_planners_band_is_the_models_latent_band_without_its_noise(setup):
    """GPAxes.band_variance leaves out the band's noise on purpose (its docstring: the
    same for every candidate inside the fit inputs, no flight lowers it) and matches
    the model's latent variance without the mean's weighing, inside the training box
    and beyond it."""
    _, _, model_path = setup
    # the band's factor inside the fit inputs (band_scale, band_slope) set aside: the
    # noise left out is what this pins (tests/test_model.py pins the factor)
    model = rebuilt(
        load_model(model_path),
        mean_shrink=np.zeros(3),
        band_scale=np.ones(3),
        band_slope=np.zeros(3),
    )
    gp = GPAxes.from_model(model)
    centre = model.inputs.mean(axis=0)
    for spread in (1.0, 2.0):
        z = centre + spread * (model.inputs - centre)
        planner = gp.band_variance(model.normalise(z))
        np.testing.assert_allclose(planner, model.latent(z)[1], rtol=1e-8, atol=1e-14)
        measured = model.gp_predict(z, noise=True)[1]
        assert np.all(measured >= planner + model.band_noise - 1e-12)


def test_plan_scores_candidates_and_picks_the_lowest_cost(setup):
    _, task_path, model_path = setup
    model, task = load_model(model_path), read_trajectory(task_path)
    result = plan(model, task, PlanSettings(candidates=4, sims=2, test_points=100, points=15))
    assert result.coefficients.shape == (4, 3, 2, 2)
    feasible = result.feasible
    assert feasible.any()
    assert result.best == int(np.argmin(np.where(feasible, result.cost, np.inf)))
    assert np.all(result.cost[feasible] < result.prior_variance)
    best = result.best_trajectory()
    assert best.data.shape == task.data.shape
    np.testing.assert_allclose(best.data[[0, -1]], task.data[[0, -1]], atol=1e-9)


def test_cli_plan_is_deterministic_and_writes_scores(setup):
    tmp, task_path, model_path = setup
    outs = []
    for name in ("a", "b"):
        out, scores = tmp / f"{name}.csv", tmp / f"{name}-scores.csv"
        args = ["plan", "--task", str(task_path), "--model", str(model_path), "--out", str(out)]
        args += ["--candidates", "3", "--sims", "2", "--test-points", "80", "--points", "10"]
        result = runner.invoke(app, [*args, "--scores", str(scores), "--seed", "5", "-q"])
        assert result.exit_code == 0, result.output
        outs.append((out.read_bytes(), scores.read_bytes()))
    assert outs[0] == outs[1]
    header = outs[0][1].decode().splitlines()[0].split(",")
    assert header[0] == "candidate" and len(header) == 1 + 12 + 10
    assert header[-2:] == ["generation", "reference_sha256"]
    assert len(outs[0][1].decode().splitlines()) == 4
    read_trajectory(tmp / "a.csv")


def test_cli_plan_one_candidate_one_simulation(setup):
    tmp, task_path, model_path = setup
    out = tmp / "one.csv"
    args = ["plan", "--task", str(task_path), "--model", str(model_path), "--out", str(out)]
    # this one candidate tilts beyond the task's 20 deg + the default --tilt-margin 10
    # (tests/test_plan_tilt.py): the single-candidate path is tested without the margin
    one = ["--candidates", "1", "--sims", "1", "--points", "5", "--tilt-margin", "90", "-q"]
    result = runner.invoke(app, [*args, *one])
    assert result.exit_code == 0, result.output
    assert read_trajectory(out).data.shape[1] == 19


def _one_error_line(result) -> str:
    text = result.output.strip()
    assert result.exit_code == 2 and "Traceback" not in text
    assert len(text.splitlines()) == 1, text
    return text


def test_cli_plan_refuses_bad_inputs(setup, tmp_path):
    _, task_path, model_path = setup
    lines = task_path.read_text().splitlines()
    missing = tmp_path / "missing.csv"
    missing.write_text("\n".join(",".join(r.split(",")[:-1]) for r in lines) + "\n")
    nonuniform = tmp_path / "nonuniform.csv"
    rows = [r.split(",") for r in lines]
    rows[3][0] = str(float(rows[3][0]) + 0.004)
    nonuniform.write_text("\n".join(",".join(r) for r in rows) + "\n")
    other = tmp_path / "other.npz"
    with np.load(model_path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    name, version = SCHEMA_FITTED.rsplit("/", 1)  # the newest schema this omavctl reads
    newer = f"{name}/{int(version) + 1}"
    arrays["schema"] = np.array(newer)
    np.savez(other, **arrays)
    out = tmp_path / "out.csv"
    base = ["plan", "--out", str(out), "--candidates", "1", "--sims", "1"]
    r = runner.invoke(app, [*base, "--task", str(missing), "--model", str(model_path)])
    assert _one_error_line(r) == f"error: {missing}: missing columns: dwz"
    # a flight log given as the task listed all 18 columns as missing (a new user)
    log = tmp_path / "log.csv"
    log.write_text("t,body_rate_x,body_rate_y,body_rate_z\n0,0,0,0\n0.01,0,0,0\n")
    r = runner.invoke(app, [*base, "--task", str(log), "--model", str(model_path)])
    assert _one_error_line(r) == (
        f"error: {log}: a flight log (body_rate columns), not a trajectory: --task and "
        "--reference take the CSV that omavctl task writes (t, x, y, z, roll, pitch, yaw and "
        "their rates)"
    )
    assert not out.exists()
    r = runner.invoke(app, [*base, "--task", str(nonuniform), "--model", str(model_path)])
    assert _one_error_line(r).startswith(f"error: {nonuniform}: non-uniform time grid")
    r = runner.invoke(app, [*base, "--task", str(task_path), "--model", str(other)])
    assert _one_error_line(r) == (
        f"error: {other}: schema '{newer}' is newer than this omavctl supports ({SCHEMA_FITTED})"
    )
    assert not out.exists()


def test_no_feasible_candidate_says_which_limits_and_keeps_the_reasons(setup, tmp_path):
    """Deviations far too large for the servos: no reference is written, the one error
    line counts the candidates by the limit they broke, and the scores (every
    candidate's reason) are written for the user to look at."""
    _, task_path, model_path = setup
    out, scores = tmp_path / "ref.csv", tmp_path / "scores.csv"
    args = ["plan", "--task", str(task_path), "--model", str(model_path), "--out", str(out)]
    args += ["--amplitude", "30", "--candidates", "4", "--sims", "1", "--points", "5"]
    args += ["--tilt-margin", "90"]  # the limits of the vehicle, not of the task's region
    line = _one_error_line(runner.invoke(app, [*args, "--scores", str(scores), "-q"]))
    assert line.startswith(
        f"error: {task_path}: no feasible candidate for this task (4 candidates: "
    )
    assert line.endswith(
        f"; every candidate's reason is in {scores}: lower --amplitude or --max-freq"
    )
    assert not out.exists()
    with scores.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 and all(r["feasible"] == "false" and r["reason"] for r in rows)
    counted = re.search(r"\(4 candidates: (.*?)\)", line)
    assert counted is not None
    tally = {}
    for r in rows:
        for why in r["reason"].split("; "):
            tally[why] = tally.get(why, 0) + 1
    assert {w.split(" ", 1)[1]: int(w.split(" ", 1)[0]) for w in counted[1].split(", ")} == tally
    plain = _one_error_line(runner.invoke(app, [*args, "-q"]))
    assert plain.endswith(
        "; --scores FILE lists every candidate's reason: lower --amplitude or --max-freq"
    )


def test_plan_summary_names_the_planned_envelope_and_warns_of_a_long_yaw_turn():
    """A flight engineer sees where the planned reference goes beside the task, and is
    warned when it turns yaw (or rotates) far beyond it."""
    from types import SimpleNamespace

    from omavctl.planning.envelope import envelope, envelope_lines, envelope_warnings
    from omavctl.sim.tasks import yaw

    task = fig8(duration=8.0, ramp=1.0)
    gentle = SimpleNamespace(best=0, task=task, best_trajectory=lambda: task)
    lines = envelope_lines(gentle)
    assert len(lines) == 1 and lines[0].startswith("planned reference: |roll| <= ")
    turn = yaw(300, 4.0, duration=8.0)  # +-300 deg
    e = envelope(turn)
    assert 590 < e["yaw_range_deg"] <= 600 and e["max_abs_roll_deg"] < 1
    wild = SimpleNamespace(best=0, task=task, best_trajectory=lambda: turn)
    lines = envelope_lines(wild)
    warning = "warning: the planned reference turns yaw through"
    assert any(line.startswith(warning) for line in lines)
    # 164 deg for a task that turns none (a new user's plan): warned; 80 deg: not
    for amplitude, warned in ((82, True), (40, False)):
        turned = yaw(amplitude, 4.0, duration=8.0)
        plan = SimpleNamespace(best=0, task=task, best_trajectory=lambda t=turned: t)
        assert any(line.startswith(warning) for line in envelope_lines(plan)) is warned
    assert envelope_lines(SimpleNamespace(best=-1, task=task)) == []
    # tilting to 60 deg for a 26 deg task (a new user's effects plan went to 59/65 deg
    # and broke actuator limits in 92 steps where the task broke them in 20)
    task26 = fig8(roll_deg=26, pitch_deg=26, duration=8.0, ramp=1.0)
    steep = fig8(roll_deg=60, pitch_deg=20, duration=8.0, ramp=1.0)
    lines = envelope_lines(SimpleNamespace(best=0, task=task26, best_trajectory=lambda: steep))
    assert lines[1:] == [
        "warning: the planned reference tilts to 60 deg, 2.3x the task's 26: check the "
        "vehicle can fly it (actuator limits, flight area), or lower --amplitude or plan "
        "with --max-tilt 52 (candidates that tilt further are rejected)"
    ]
    assert envelope_warnings(SimpleNamespace(best=0, task=task26, best_trajectory=lambda: steep))[
        0
    ].startswith("the planned reference tilts to 60 deg")
    mild = fig8(roll_deg=40, pitch_deg=26, duration=8.0, ramp=1.0)  # below 45 deg: no warning
    assert (
        len(envelope_lines(SimpleNamespace(best=0, task=task26, best_trajectory=lambda: mild))) == 1
    )


def test_the_rejections_are_counted_per_reason():
    from types import SimpleNamespace

    from omavctl.planning.report import rejection_tally

    result = SimpleNamespace(reason=["", "tilt rate limit", "diverged, tilt rate limit", ""])
    assert rejection_tally(result) == "2 tilt rate limit, 1 diverged"


def test_no_candidate_better_than_the_task_is_a_warning_in_the_terminal_and_json():
    from types import SimpleNamespace

    from omavctl.planning.report import task_warning as _task_warning

    def result(costs, task_cost, generations):
        cost = np.array(costs)
        return SimpleNamespace(
            cost=cost,
            best=int(np.argmin(cost)),
            task_cost=task_cost,
            generation=np.array(generations),
            versus_task=lambda c: 100.0 * (c / task_cost - 1.0),
        )

    assert _task_warning(result([1.0, 0.9], 1.0, [0, 0])) is None
    assert _task_warning(result([1.2, 1.05], 1.0, [0, 0])) == (
        "no candidate is more informative than flying the task again (best +5.0% vs the "
        "task): fly the task, or try more --candidates or --search cem"
    )
    assert _task_warning(result([1.2, 1.05], 1.0, [0, 1])).endswith("try more --candidates")
