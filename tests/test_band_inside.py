"""The 2-sigma band on a held-out flight: sharp inside the fit flight's inputs, never
overconfident beyond them (issue 26: coverage >= 0.85 on every axis, <= 0.99 on the
samples inside the fit inputs; wider than needed beyond them is accepted).

The default plant without a hidden effect; the well-specified model is
``fit --effects rotor_interference`` (the plant's own interference, what the diagnosis
names), 100 points, 1 restart. docs/intervals.md, "The model's band inside the fit
flight's inputs", has the decomposition that found the cause: the noise floor from the
held-out error of time blocks *and* input ends (0.75 x their MSE), counted on top of a
band already calibrated on the time blocks. That floor now applies beyond the fit inputs
only, where the band also grows with the torque and the reach beyond them
(:mod:`omavctl.learn.band`; tests/test_model.py pins those terms, tests/test_never_hurts.py
and tests/test_generalise.py their coverage on flights that leave the fit inputs).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omavctl.learn.fit import fit_model
from omavctl.logs import write_log
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8, wobble
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle

#: flights (16 s, 100 Hz controller, default plant): trajectory and simulator seed
FLIGHTS = {
    "wobble": (lambda: wobble(amplitude_deg=25, bandwidth=0.8, duration=16.0, ramp=2.0), 12),
    # a gentler figure-8: inside the wobble's inputs
    "fig8-small": (
        lambda: fig8(roll_deg=15, pitch_deg=15, period=6.0, duration=16.0, ramp=2.0),
        22,
    ),
}


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("band")
    vehicle = default_vehicle()
    truth = truth_from_tree({"effects": {}}, vehicle)
    out = {}
    for name, (make, seed) in FLIGHTS.items():
        out[name] = tmp / f"{name}.csv"
        write_log(out[name], simulate(make(), vehicle, truth, seed=seed).log)
    return out


def _judge(model, log: Path) -> dict:
    """Coverage, coverage inside the fit inputs, outside share and ratio to physics of
    ``model`` on ``log``, as ``evaluate`` computes them (without its diagnosis)."""
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.diagnose.metrics import training_envelope

    rate, sg = _grid(model)
    samples, *_ = _read_log(log, model.vehicle, rate, sg, None)
    mean, var = model.predict_samples(samples, noise=True)
    err = samples.residual - mean
    physics = samples.residual - model.effects_samples(samples)
    z = samples.inputs(model.features)
    env = training_envelope(model.inputs, z, list(model.input_names), err, np.sqrt(var))
    return {
        "coverage": np.mean(np.abs(err) <= 2.0 * np.sqrt(var), axis=0),
        "inside": np.array([env["coverage_inside"][a] for a in "xyz"], dtype=float),
        "outside": env["outside_fraction"],
        "ratio": np.sqrt(np.mean(err**2, axis=0) / np.mean(physics**2, axis=0)),
    }


def test_inside_the_fit_inputs_the_band_is_sharp(logs):
    """Fitted on the wobble, judged on a gentler figure-8 that stays inside its inputs:
    the band covers 0.85-0.99 on every axis (measured 0.926 / 0.950 / 0.968; with one
    factor inside, before session 21's band that follows the GP's distance from its
    data, 0.971 / 0.982 / 0.981). With the held-out noise floor everywhere, as before,
    z covered 0.999."""
    model = fit_model(
        [logs["wobble"]], points=100, restarts=1, effects=["rotor_interference"]
    ).model
    assert np.all(model.band_noise <= model.noise_variance)
    assert np.any(model.band_noise < model.noise_variance)  # the floor binds somewhere
    now = _judge(model, logs["fig8-small"])
    print("now", now)
    assert now["outside"] < 0.05
    assert np.all(now["ratio"] <= 1.05), now["ratio"]
    assert np.all((now["inside"] >= 0.85) & (now["inside"] <= 0.99)), now["inside"]
    assert np.all((now["coverage"] >= 0.85) & (now["coverage"] <= 0.99)), now["coverage"]
    fitted = model.band_noise.copy()
    model.band_noise = model.noise_variance.copy()  # the floor counted inside too
    before = _judge(model, logs["fig8-small"])
    print("before", before)
    np.testing.assert_array_equal(before["ratio"], now["ratio"])  # the mean is the same
    assert np.all(before["inside"] >= now["inside"])
    assert before["inside"].max() > 0.99
    model.band_noise = fitted
