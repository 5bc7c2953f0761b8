"""plan's tilt margin: candidates are held to the task's largest tilt plus --tilt-margin."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.learn.model_file import save_model
from omavctl.planning.candidates import deviated_references
from omavctl.planning.planner import PlanSettings, plan, task_tilt_deg, tilt_limit
from omavctl.sim.tasks import fig8
from omavctl.sim.trajectory import write_trajectory

runner = CliRunner()


@pytest.fixture(scope="module")
def setup(tmp_path_factory, fig8_fitted):
    """A 20 deg figure-8 task and a model fitted on one flight of it (tests/conftest.py),
    both as files."""
    tmp = tmp_path_factory.mktemp("plan-tilt")
    task, model = fig8_fitted
    write_trajectory(tmp / "task.csv", task)
    save_model(tmp / "model.npz", model)
    return tmp, task, model


def test_the_limit_is_the_task_tilt_plus_the_margin_unless_max_tilt_is_lower():
    task = fig8(roll_deg=26, pitch_deg=20, duration=8.0, ramp=1.0)
    assert task_tilt_deg(task) == pytest.approx(26.0, abs=0.05)
    assert tilt_limit(task, PlanSettings()) == pytest.approx(36.0, abs=0.05)
    assert tilt_limit(task, PlanSettings(tilt_margin_deg=4.0)) == pytest.approx(30.0, abs=0.05)
    assert tilt_limit(task, PlanSettings(max_tilt_deg=31.0)) == 31.0
    assert tilt_limit(task, PlanSettings(tilt_margin_deg=90.0)) == 80.0
    assert tilt_limit(task, PlanSettings(objective="effects")) == 80.0
    effects = PlanSettings(objective="effects", tilt_margin_deg=5.0)
    assert tilt_limit(task, effects) == pytest.approx(31.0, abs=0.05)


def test_the_margin_rejects_exactly_the_candidates_that_tilt_beyond_it(setup):
    """Same candidates and posterior samples: with the margin, the candidates feasible
    without it that tilt beyond the task's 20 deg + 4 are rejected for the attitude
    limit, and none that stays well within it is. On a 4 s figure-8 (the 8 s task doubled
    the simulation): 5 dropped, 7 kept, kept tilts up to 23.75 deg, dropped from 24.47
    (the 8 s task: 8, 4, 22.69, 24.23; limits 27 and 21)."""
    _, _, model = setup
    task = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=4.0, ramp=1.5)
    base = dict(candidates=12, sims=2, test_points=100, points=15, amplitude=2.0, seed=3)
    free = plan(model, task, PlanSettings(**base, tilt_margin_deg=90.0))
    capped = plan(model, task, PlanSettings(**base, tilt_margin_deg=4.0))
    assert free.max_tilt_deg == 80.0 and capped.max_tilt_deg == pytest.approx(24.0, abs=0.05)
    assert capped.tilt_by_margin and not free.tilt_by_margin
    np.testing.assert_array_equal(free.coefficients, capped.coefficients)
    refs = deviated_references(task, free.coefficients)
    tilt = np.rad2deg(np.abs(refs[..., 4:6])).max(axis=(1, 2))
    dropped = free.feasible & ~capped.feasible
    assert dropped.any() and capped.feasible.any()  # the margin bites on this pool
    assert all("attitude limit" in capped.reason[k] for k in np.flatnonzero(dropped))
    assert np.all(tilt[capped.feasible] < 24.0 + 3.0)  # simulated tilt tracks the reference
    assert not np.any(dropped & (tilt < 24.0 - 3.0))
    assert not (capped.feasible & ~free.feasible).any()


def test_cli_states_the_limit_and_refuses_a_bad_margin(setup):
    tmp, _, _ = setup
    args = ["plan", "--task", str(tmp / "task.csv"), "--model", str(tmp / "model.npz")]
    args += ["--candidates", "4", "--sims", "1", "--test-points", "50", "--jobs", "1"]
    done = runner.invoke(app, [*args, "--out", str(tmp / "p.csv"), "--tilt-margin", "6"])
    assert done.exit_code == 0, done.output
    assert "attitude limit: |roll|, |pitch| <= 26 deg in simulation (the task tilts to 20; " in (
        done.output
    )
    js = runner.invoke(app, [*args, "--out", str(tmp / "q.csv"), "--json", "-q"])
    assert js.exit_code == 0, js.output
    assert json.loads(js.stdout)["max_tilt_deg"] == pytest.approx(30.0, abs=0.05)
    bad = runner.invoke(app, [*args, "--out", str(tmp / "r.csv"), "--tilt-margin", "-1"])
    assert bad.exit_code == 2
    assert "--tilt-margin must be in [0, 90] deg, got -1" in bad.output


def test_no_feasible_candidate_for_the_margin_says_how_to_raise_it(setup):
    """The one candidate of seed 0 tilts beyond 20 + 10 deg: the error line names the
    margin and the limit it gave."""
    tmp, _, _ = setup
    args = ["plan", "--task", str(tmp / "task.csv"), "--model", str(tmp / "model.npz")]
    args += ["--candidates", "1", "--sims", "1", "--points", "5", "--out", str(tmp / "n.csv")]
    done = runner.invoke(app, [*args, "-q"])
    assert done.exit_code == 2 and len(done.output.strip().splitlines()) == 1
    assert "(1 candidates: 1 attitude limit)" in done.output
    assert done.output.strip().endswith(
        ": lower --amplitude or --max-freq (or raise --tilt-margin: the attitude limit was "
        "30 deg, the task's largest tilt plus the margin)"
    )
