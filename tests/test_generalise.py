"""A model is judged on flights it has not seen (benchmarks/generalise.py, pinned).

Fit on one trajectory, evaluate on another, both directions: a figure-8 and a
multi-sine wobble (different shapes, yaw, frequencies), with the default plant
imperfections, a controller at the log rate (commands held) or ten times
faster (sampled), and hidden effects. The full model (effects + GP) must never
be worse than its physics alone, and its 2-sigma band must be honest where it
is (docs/generalisation.md lists every case, including those still outside the
0.85-0.99 band).
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.generalise import fly_pair, run_direction

#: (hidden effect, controller timing) pairs pinned here; both directions each
CASES = [
    ("none", "100Hz-held"),
    ("none", "1kHz-sampled"),
    ("rotational_drag", "100Hz-held"),
    ("command_delay", "100Hz-held"),
]
#: cases whose coverage is pinned to the 0.85-1.0 band as well: all of them since the
#: band grows beyond the training inputs (rotational_drag at 100 Hz, fitted on the
#: figure-8, x: 0.84 before, 0.96 with it; docs/generalisation.md)
CALIBRATED = set(CASES)


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("generalise")
    out = {}
    for case, timing in CASES:
        logs = fly_pair(tmp, case, timing)
        for fit_on in logs:
            # the metrics alone: the tests below read the ratio and the coverage, which
            # the diagnosis and the horizons table do not change (8 x 8 CPU s less)
            out[(case, timing, fit_on)] = run_direction(
                tmp, logs, fit_on, case, timing, diagnose=False
            )
    return out


@pytest.mark.parametrize(("case", "timing"), CASES)
@pytest.mark.parametrize("fit_on", ["fig8", "wobble"])
def test_the_gp_never_makes_a_new_flight_worse(outcomes, case, timing, fit_on):
    o = outcomes[(case, timing, fit_on)]
    print(case, timing, fit_on, "ratio", o.ratio.round(2), "coverage", o.coverage.round(2))
    assert np.all(o.ratio <= 1.05)


@pytest.mark.parametrize(("case", "timing"), sorted(CALIBRATED))
@pytest.mark.parametrize("fit_on", ["fig8", "wobble"])
def test_the_band_covers_a_new_flight(outcomes, case, timing, fit_on):
    o = outcomes[(case, timing, fit_on)]
    assert np.all(o.coverage >= 0.85), o.coverage


def test_a_clean_flight_of_an_ideal_plant_switches_the_gp_off(tmp_path):
    """Noise only: the GP has nothing to learn and says so (mean 0, variance the
    residual's mean square: the log's own derivative noise)."""
    from omavctl.learn.fit import fit_model
    from omavctl.logs import align
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import default_vehicle

    vehicle = default_vehicle()
    ref = fig8(roll_deg=20, pitch_deg=20, period=5.0, duration=12.0, ramp=2.0)
    log = align(simulate(ref, vehicle, truth_from_tree({"ideal": True}, vehicle), seed=0).log)
    result = fit_model([log], points=80, restarts=0)
    floor = np.array(result.model.provenance["gp"]["noise_floor"])
    assert np.all((floor > 0.02) & (floor < 0.04))  # 0.003 rad/s gyro noise x SG gain
    assert not result.model.gp_enabled.any()
    assert sum("GP switched off" in n for n in result.summary.notes) == 3
    std = np.sqrt(result.model.noise_variance)
    assert np.all(np.abs(std / floor - 1) < 0.2)


@pytest.mark.parametrize("timing", [{}, {"controller_rate_hz": 1000}])
def test_clean_flights_claim_nothing(tmp_path, timing):
    """Ideal actuators, sensor noise only, a controller at the log rate (commands
    held) or ten times faster (sampled: a sub-period lead the held-command model
    does not know): fit on a figure-8, evaluate on a wobble. Nothing is missing,
    nothing is claimed as learned."""
    from omavctl.diagnose.evaluate import evaluate
    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model
    from omavctl.logs import write_log
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8, wobble
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import default_vehicle

    vehicle = default_vehicle()
    truth = truth_from_tree({"ideal": True, "timing": timing}, vehicle)
    fit_log, eval_log = tmp_path / "fit.csv", tmp_path / "eval.bag"
    write_log(fit_log, simulate(fig8(20, 20, 5.0, 12.0), vehicle, truth, seed=1).log)
    write_log(eval_log, simulate(wobble(25, duration=12.0), vehicle, truth, seed=2).log)
    model = tmp_path / "m.npz"
    save_model(model, fit_model([fit_log], vehicle, points=80, restarts=0).model)
    tree = evaluate([model], [eval_log], horizons=()).tree  # the horizons are not read
    diag = tree["diagnosis"]
    assert diag["missing"] == [] and diag["fit_command"] is None
    # nothing worth a test flight at the log rate; at 1 kHz the commands lead the held
    # model by a sub-period (real timing, 1.3x the noise, not claimed): only a delay
    # may be suggested for a test
    assert diag["below_noise"] in ((None,) if not timing else (None, "command_delay"))
    assert not any(e["missing"] for e in diag["learned"])
    assert not [f for f in tree["flags"] if f["code"] == "worse_than_physics"]


def test_the_band_grows_where_a_flight_leaves_the_training_inputs(tmp_path):
    """Hidden inertia error, fit on the figure-8, evaluate on the wobble: nearly all of
    the wobble lies beyond the figure-8's inputs. The band that grows beyond them
    (``beyond_scale``) covers the errors there; the same model without that growth
    does not, and the verdict then says the model extrapolates. The other way round
    the flight stays inside."""
    from omavctl.diagnose.evaluate import evaluate
    from omavctl.diagnose.verdict import verdict
    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model

    logs = fly_pair(tmp_path, "inertia_error", "100Hz-held")
    models = {
        fit_on: fit_model([logs[fit_on]], points=100, restarts=1).model
        for fit_on in ("fig8", "wobble")
    }

    def envelope(model, log):
        path = tmp_path / "m.npz"
        save_model(path, model)
        # the envelope line reads the envelope and its flags alone: neither the diagnosis
        # nor the horizons table changes them (3 x 8 CPU s less without)
        tree = evaluate([path], [log], with_diagnosis=False, horizons=()).tree
        return tree["envelope"], [ln.text for ln in verdict(tree) if ln.key == "envelope"]

    fig8_model = models["fig8"]
    assert np.all(fig8_model.beyond_scale >= 0.5)
    env, lines = envelope(fig8_model, logs["wobble"])
    print(env)
    assert env["outside_fraction"] > 0.5 and "(I^-1 tau)x" in env["beyond"]
    assert env["coverage_outside"]["x"] >= 0.8 and env["coverage_outside"]["z"] >= 0.8
    assert len(lines) == 1 and lines[0].endswith("its band still covers the errors there.")
    # the band of a plain SE GP, as before: no growth beyond the training inputs (neither
    # the GP's nor the band's with the torque and the reach, omavctl/learn/band.py)
    fig8_model.beyond_scale = np.zeros(3)
    fig8_model.torque_growth, fig8_model.range_growth = np.zeros(3), np.zeros(3)
    env, lines = envelope(fig8_model, logs["wobble"])
    assert env["coverage_outside"]["x"] < 0.8 < env["coverage_inside"]["x"]
    assert len(lines) == 1 and "the model extrapolates" in lines[0]
    env, lines = envelope(models["wobble"], logs["fig8"])
    assert env["outside_fraction"] < 0.25 and lines == []


@pytest.mark.parametrize("seed", [2, 5])
def test_a_first_model_fit_on_steps_covers_a_figure_8_that_tilts_beyond_them(tmp_path, seed):
    """Nothing hidden but the simulator's own imperfections, which the first model's GP
    holds: fit on attitude steps of 15 degrees, judged on a figure-8 of 25 degrees in
    roll and pitch. The rotors' interference grows faster beyond the steps' tilts than
    the band's growth of 4x the training targets' RMS per training range allowed (the
    scorecard's own-fig8 draws: x 0.57-0.83); at 8x (``RANGE_GROWTH``) it covers, and
    the band inside the fit inputs is the same."""
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.learn.band import RANGE_GROWTH, growth_variance
    from omavctl.learn.fit import fit_model
    from omavctl.logs import write_log
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8, steps
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import default_vehicle

    vehicle = default_vehicle()
    truth = truth_from_tree({"seed": seed}, vehicle)
    write_log(tmp_path / "fit.csv", simulate(steps(15, seed=seed), vehicle, truth, seed=seed).log)
    wide = fig8(roll_deg=25, pitch_deg=25, period=5.5, duration=12.0, ramp=1.0)
    write_log(tmp_path / "held.csv", simulate(wide, vehicle, truth, seed=seed + 1).log)
    model = fit_model([tmp_path / "fit.csv"], vehicle, points=80, restarts=0).model
    held = _read_log(tmp_path / "held.csv", model.vehicle, *_grid(model), None)[0]

    def coverage() -> np.ndarray:
        mean, var = model.predict_samples(held, noise=True)
        return np.mean(np.abs(held.residual - mean) <= 2.0 * np.sqrt(var), axis=0)

    assert RANGE_GROWTH == 8.0
    now = coverage()
    assert np.all(now >= 0.85), now
    wide_band = model.predict_samples(held, noise=True)[1]
    model.range_growth = model.range_growth / 2.0  # the growth of sessions 31-32
    before = coverage()
    assert before[0] < 0.85 <= now[0], (before, now)
    # only samples beyond the fit inputs gain; the fit flight's own keep their band
    assert np.all(model.predict_samples(held, noise=True)[1] <= wide_band)
    assert np.all(growth_variance(model, model.inputs) == 0.0)
