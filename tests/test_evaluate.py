"""evaluate: metrics, where the model fails, and the diagnosis of missing physics.

Each case flies a figure-8 (fit flight, wide CSV) and a different figure-8
(held-out flight: other amplitudes and period, ROS 1 bag) through the default
truth plant plus one hidden effect.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.diagnose.evalio import load_evaluation, write_evaluation
from omavctl.diagnose.evaluate import evaluate
from omavctl.diagnose.scoring import MIN_EXPLAINED
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs import read_vehicle_log, write_log
from omavctl.physics.effects import get_effect
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8, heave, yaw
from omavctl.sim.truth import truth_from_tree

runner = CliRunner()
DURATION = 16.0
#: The diagnosis of effects missing from a GP on the paper's inputs (the commanded
#: wrench): a GP with body-rate and command-rate inputs (the default) learns drag,
#: lags and delays itself, and the diagnosis shows them as learned
#: (test_a_gp_with_rate_inputs_learns_a_lag), not missing.
FEATURES = "wrench"

#: Flight pairs (fit flight, held-out flight): the held-out one is a different
#: trajectory in a different format (CSV -> ROS 1 bag) and leaves the fit
#: flight's envelope in what the effect acts on.
PAIRS = {
    # the paper's task, then a faster, larger figure-8
    "fig8": (
        lambda: fig8(duration=DURATION, ramp=2.0),
        lambda: fig8(roll_deg=20, pitch_deg=30, period=6.0, duration=DURATION, ramp=2.0),
    ),
    # collective thrust +-2.5 % then +-30 %, level (r x f without tilt)
    "heave": (
        lambda: heave(0.1, 4.0, duration=DURATION),
        lambda: heave(0.3, 2.0, duration=DURATION),
    ),
    # small attitudes (little tilt), slower then fast: torques 2.5-4x the fit flight's
    # (an 8 s period left the inertia scale at +-0.3..0.9 and its refit a matter of luck)
    "small-fig8": (
        lambda: fig8(roll_deg=6, pitch_deg=6, period=5.0, duration=DURATION, ramp=2.0),
        lambda: fig8(roll_deg=6, pitch_deg=6, period=2.5, duration=DURATION, ramp=2.0),
    ),
    # yaw by tilting the arms together, another period: lags are not functions
    # of the wrench once the period changes
    "yaw": (
        lambda: yaw(30, 4.0, duration=DURATION),
        lambda: yaw(20, 2.0, duration=DURATION),
    ),
}
#: case -> (flight pair, hidden effect or None, its parameters)
CASES = {
    "none": ("fig8", None, {}),
    "rotational_drag": ("fig8", "rotational_drag", {"D": [0.05, 0.05, 0.03]}),
    "motor_lag": ("fig8", "motor_lag", {"T_m": 0.05}),
    "none-heave": ("heave", None, {}),
    "com_offset": ("heave", "com_offset", {"r": [0.02, -0.015, 0.0]}),
    "none-small-fig8": ("small-fig8", None, {}),
    "inertia_error": ("small-fig8", "inertia_error", {"scale": [1.3, 1.3, 1.3]}),
    "none-yaw": ("yaw", None, {}),
    "servo_lag": ("yaw", "servo_lag", {"T_s": 0.08}),
}
#: ``evaluate`` without the horizons table (open-loop rollouts, about 1.2 CPU s on a
#: 16 s log) for the tests that read none of it; ``METRICS`` without the diagnosis too
#: (8 CPU s) for those that read only the metrics or the training-data flags, which
#: neither changes (evaluate's ``with_diagnosis``; the verdict's first line, a flag,
#: keeps the diagnosis beside it).
NO_HORIZONS = {"horizons": ()}
METRICS = {"with_diagnosis": False, "horizons": ()}
#: Training points per fit (fewer than fit's default 200, for speed). inertia_error,
#: like the GP a function of the wrench alone, needs the default: with 100 points
#: whether the diagnosis names it depended on which points k-medoids picked (fit
#: seeds 0-3 with rustpam: com_offset named for seed 0, inertia_error's refit
#: explained variance 0.02 for seed 1); with 200 all four seeds name it, refit
#: explained variance 0.40-0.59.
POINTS = {"inertia_error": 200}


def _flights(tmp, vehicle, case):
    pair, effect, params = CASES[case]
    truth = truth_from_tree({"seed": 1, "effects": {effect: params} if effect else {}}, vehicle)
    fit_task, eval_task = PAIRS[pair]
    fit_log, eval_log = tmp / f"{case}-fit.csv", tmp / f"{case}-eval.bag"
    write_log(fit_log, simulate(fit_task(), vehicle, truth, seed=1).log)
    write_log(eval_log, simulate(eval_task(), vehicle, truth, seed=2).log)
    return fit_log, eval_log


@pytest.fixture(scope="module")
def cases(tmp_path_factory, vehicle):
    tmp = tmp_path_factory.mktemp("evaluate")
    out = {}
    for case in CASES:
        fit_log, eval_log = _flights(tmp, vehicle, case)
        model = tmp / f"{case}.npz"
        points = POINTS.get(case, 100)
        save_model(
            model,
            fit_model([fit_log], vehicle, points=points, restarts=0, features=FEATURES).model,
        )
        out[case] = (fit_log, eval_log, model)
    return tmp, out


#: The cases whose held-out evaluation a test reads in full, horizons table too (the
#: JSON contract); the others' without it (``NO_HORIZONS``).
FULL = {"rotational_drag"}


@pytest.fixture(scope="module")
def heldout(cases):
    """case -> ``evaluate`` of its model on its held-out flight, computed once for
    every test that reads it (the horizons table changes neither the diagnosis, the
    metrics nor the flags): the effect test's "before", the JSON contract's second
    evaluation (compared with the CLI's, for determinism), the flag test's held-out
    log. About 9 CPU s each (the diagnosis)."""
    _, c = cases
    memo = {}

    def get(case):
        if case not in memo:
            _, eval_log, model = c[case]
            memo[case] = evaluate([model], [eval_log], **({} if case in FULL else NO_HORIZONS))
        return memo[case]

    return get


@pytest.mark.parametrize("case", ["none", "none-heave", "none-small-fig8", "none-yaw"])
def test_no_hidden_effect_nothing_is_missing(heldout, case):
    """The default plant's own imperfections (thrust spread, 5 ms lags, backlash)
    are real but small: nothing is called missing, except the registered effects
    that describe them, which the model lacks: its rotor interference (named on the
    figure-8, whose tilts excite it; not on the level heave) and the centre-of-mass
    offset that its 3 % thrust spread amounts to (named only by the joint selection,
    when estimated from the fit flight it lowers the held-out physics-only error)."""
    tree = heldout(case).tree
    missing = tree["diagnosis"]["missing"]
    assert set(missing) <= {"rotor_interference", "com_offset"}
    if case == "none-heave":
        assert "rotor_interference" not in missing
    joint = {s["name"] for s in tree["diagnosis"]["joint_steps"]}
    assert "com_offset" not in missing or "com_offset" in joint
    assert (tree["diagnosis"]["fit_command"] is None) == (missing == [])
    for entry in tree["diagnosis"]["missing_effects"]:
        if entry["name"] in ("rotor_interference", "com_offset"):
            continue
        assert not entry["missing"]
        assert not (
            entry["explained_variance"] >= MIN_EXPLAINED
            and entry["significant"]
            and entry["above_noise"]
        )


@pytest.mark.parametrize(
    "name", ["rotational_drag", "motor_lag", "com_offset", "inertia_error", "servo_lag"]
)
def test_missing_effect_is_named_and_adding_it_halves_the_error(cases, heldout, vehicle, name):
    tmp, c = cases
    fit_log, eval_log, _ = c[name]
    before = heldout(name).tree
    diag = before["diagnosis"]
    # claimed with what else the held-out flight confirms (the plant's own rotor
    # interference on the larger figure-8), all added by the one fit command
    assert name in diag["missing"]
    assert set(diag["missing"]) <= {name, "rotor_interference", "com_offset"}
    assert diag["missing_effects"][0]["name"] == name
    assert diag["missing_effects"][0]["refit_explained_variance"] > MIN_EXPLAINED
    words = shlex.split(diag["fit_command"])
    assert words[words.index("--effects") + 1].split(",") == diag["missing"]
    # the log's path, valid from the current directory (relative or absolute)
    assert any(Path(w).resolve() == fit_log.resolve() for w in words), words

    refit = tmp / f"{name}-refit.npz"
    save_model(
        refit,
        fit_model(
            [fit_log],
            vehicle,
            effects=[name],
            points=POINTS.get(name, 100),
            restarts=0,
            features=FEATURES,
        ).model,
    )
    after = evaluate([refit], [eval_log], **NO_HORIZONS).tree
    assert name not in after["diagnosis"]["missing"]

    # the axes the effect drives on the held-out flight: where its true
    # contribution is at least half of its largest (on the other axes it is
    # below the filter-noise floor of the measured acceleration)
    flight = read_vehicle_log(eval_log, vehicle)
    s = residual_samples(flight, vehicle, SavitzkyGolay(11, 2, 0.01), effects=[name])
    effect = get_effect(name)
    params = CASES[name][2]
    theta = effect.to_theta({k: np.asarray(v) for k, v in params.items()})
    true_rms = np.sqrt(((s.regressors[name] @ theta) ** 2).mean(axis=0))
    rmse0 = np.array([before["metrics"]["model"]["rmse"][a] for a in "xyz"])
    rmse1 = np.array([after["metrics"]["model"]["rmse"][a] for a in "xyz"])
    driven = true_rms >= 0.5 * true_rms.max()
    assert driven.any()
    print(name, "RMSE before", rmse0.round(3), "after", rmse1.round(3), "effect", true_rms.round(3))
    assert np.all(rmse1[driven] <= 0.5 * rmse0[driven])


def test_evaluation_json_contract_and_round_trip(cases, heldout, tmp_path):
    _, c = cases
    _, eval_log, model = c["rotational_drag"]
    out = tmp_path / "eval.json"
    result = runner.invoke(
        app, ["evaluate", str(eval_log), "--model", str(model), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    tree = json.loads(out.read_text())
    assert tree["schema"] == "omavctl.eval/1"
    for label in ("nominal", "effects", "model"):
        for metric in ("rmse", "mae", "r2", "mean_std", "coverage_2sigma", "nlpd"):
            assert set(tree["metrics"][label][metric]) == {"x", "y", "z"}
    m = tree["metrics"]
    assert all(m["model"]["rmse"][a] < m["nominal"]["rmse"][a] for a in "xyz")
    # R^2: the share of the nominal model's squared error removed (0 for the nominal)
    for a in "xyz":
        assert m["nominal"]["r2"][a] == pytest.approx(0.0, abs=1e-12)
        ratio = m["model"]["rmse"][a] / m["nominal"]["rmse"][a]
        assert m["model"]["r2"][a] == pytest.approx(1.0 - ratio**2, rel=1e-9)
    assert 0.5 < np.mean(list(m["model"]["coverage_2sigma"].values())) <= 1.0
    assert set(tree["tracking"]) == {"x", "y", "z", "mean"}
    seg = tree["worst_segments"][0]
    assert seg["end"] > seg["start"] and set(seg["rmse"]) == {"x", "y", "z"}
    assert {"fx/m", "wy", "pitch"} <= set(tree["binned"])
    top = tree["diagnosis"]["missing_effects"][0]
    assert {"name", "explained_variance", "parameters", "units"} <= set(top)
    assert top["units"] == {"D": "N m s^2"}
    tree2, series = load_evaluation(out)
    assert tree2 == tree and tree["series"]["file"] == "eval.series.npz"
    n = series["t"].size
    assert series["measured"].shape == (n, 3) and series["std_0"].shape == (n, 3)
    # computed in this process (by the effect test, when the module runs whole)
    write_evaluation(tmp_path / "again.json", heldout("rotational_drag"))
    again = json.loads((tmp_path / "again.json").read_text())
    assert again.pop("series") != tree.pop("series") and again == tree  # deterministic


def test_evaluating_on_the_fit_flight_is_flagged(cases, heldout, tmp_path):
    """The model's own training log (same file by sha256, overlapping time window) is
    not a held-out flight: flagged, in the verdict too; another log or a window after
    the fitted one is not."""
    from omavctl.diagnose.verdict import verdict

    _, c = cases
    fit_log, eval_log, model = c["none"]
    tree = evaluate([model], [fit_log], **NO_HORIZONS).tree
    flags = [f for f in tree["flags"] if f["code"] == "training_data"]
    message = (
        f"{fit_log.name}: the model was fitted on this log: its errors here are not those "
        "of a flight it has not seen"
    )
    assert flags == [{"code": "training_data", "axis": None, "value": None, "message": message}]
    assert verdict(tree)[0].key == "training" and verdict(tree)[0].text == message
    assert not [f for f in heldout("none").tree["flags"] if f["code"] == "training_data"]
    # fitted on 0-8 s: evaluated on 6-16 s it overlaps, on 8 s to the end it does not
    windowed = tmp_path / "window.npz"
    save_model(
        windowed,
        fit_model(
            [fit_log], points=60, restarts=0, features=FEATURES, time_window=(0.0, 8.0)
        ).model,
    )
    overlap = evaluate([windowed], [fit_log], time_window=(6.0, None), **METRICS).tree["flags"]
    assert [f["message"] for f in overlap if f["code"] == "training_data"] == [
        f"{fit_log.name}: the model was fitted on this log in an overlapping time window: its "
        "errors here are not those of a flight it has not seen"
    ]
    after = evaluate([windowed], [fit_log], time_window=(8.0, None), **METRICS).tree["flags"]
    assert not [f for f in after if f["code"] == "training_data"]
    # a model fitted on another log with this one's model as --prior holds its points too
    augmented = tmp_path / "augmented.npz"
    save_model(
        augmented,
        fit_model([eval_log], points=40, restarts=0, features=FEATURES, prior=model).model,
    )
    tree = evaluate([augmented], [fit_log], **METRICS).tree
    assert [f["message"] for f in tree["flags"] if f["code"] == "training_data"] == [message]


def test_two_models_are_compared_on_the_same_samples(cases):
    _, c = cases
    _, eval_log, model = c["motor_lag"]
    _, _, other = c["none"]
    tree = evaluate([model, other], [eval_log], **METRICS).tree
    assert len(tree["metrics_by_model"]) == 2
    assert tree["metrics_by_model"][0] == tree["metrics"]


def test_evaluate_refuses_unusable_input(cases, tmp_path):
    _, c = cases
    _, eval_log, model = c["none"]
    bad = tmp_path / "notes.csv"
    bad.write_text("t,body_rate_x\n0,1\n")
    out = tmp_path / "e.json"
    r = runner.invoke(app, ["evaluate", str(bad), "--model", str(model), "--out", str(out)])
    assert r.exit_code == 2 and "Traceback" not in r.output
    assert r.output.strip().startswith(f"error: {bad}: ")
    r = runner.invoke(
        app, ["evaluate", str(eval_log), "--model", str(tmp_path / "no.npz"), "--out", str(out)]
    )
    assert r.output.strip() == f"error: {tmp_path / 'no.npz'}: file not found"
    assert not out.exists()
