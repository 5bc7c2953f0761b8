"""The horizon band's gyro noise, estimated at the samples the log recorded.

A gyro recorded at 83 Hz and interpolated onto the 100 Hz grid shares its noise
between neighbouring grid samples: estimated on the grid, the noise is about half
of the truth and the band at 0.01 s is too narrow. Estimated on the recorded
samples and carried through the interpolation weights, it is the truth within
20 % and the band at 0.01 s covers 85-99 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.diagnose.evaluate import evaluate
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.learn.recorded_noise import RecordedNoise, band_scale
from omavctl.logs import write_log
from omavctl.logs.types import RawSeries
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from tests.conftest import NO_NOISE

GYRO = 0.003  # rad/s, the simulator's default gyro noise
DRAG = {"rotational_drag": {"D": [0.05, 0.05, 0.03]}}


def test_the_difference_factor_is_the_variance_of_interpolated_white_noise():
    """Monte Carlo: white noise at jittered 83 Hz stamps, interpolated at 100 Hz."""
    rng = np.random.default_rng(0)
    stamps = np.cumsum(1 / 83 + 0.001 * rng.random(400))
    t = np.arange(0.05, stamps[-2], 0.01)
    left = np.searchsorted(stamps, t, side="right") - 1
    weight = (t - stamps[left]) / (stamps[left + 1] - stamps[left])
    rn = RecordedNoise(np.ones(3), left, weight, upsampled=True)
    noise = rng.standard_normal((4000, stamps.size))
    grid = np.stack([np.interp(t, stamps, row) for row in noise])
    p = np.arange(t.size - 10)
    for k in (0, 1, 3, 10):
        want = np.var(grid[:, p + k] - grid[:, p], axis=0)
        se = want * np.sqrt(2 / noise.shape[0])  # a sample variance's standard error
        assert np.all(np.abs(rn.difference_factor(p, p + k) - want) <= 5 * se + 1e-12), k
        assert rn.difference_factor(p, p + k).mean() == pytest.approx(want.mean(), rel=0.01)
    assert rn.difference_factor(p, p + 1).mean() < 1.0  # not the 2 of independent samples
    # a filter over the grid: the mean variance of its output
    h = np.array([-1.0, 0.5, 2.0, 0.5, -1.0])
    out = sum(c * grid[:, j : t.size - 4 + j] for j, c in enumerate(h))
    index = np.arange(t.size)
    assert rn.derivative_factor(h, index) == pytest.approx(np.var(out), rel=0.05)


def test_the_band_scale_is_the_std_of_normal_noise_and_larger_for_heavy_tails():
    rng = np.random.default_rng(1)
    normal = 0.002 * rng.standard_normal((20000, 3))
    assert band_scale(np.diff(normal, 2, axis=0)) == pytest.approx(np.full(3, 0.002), rel=0.05)
    heavy = 0.002 * rng.standard_t(3, (20000, 3))
    mad = 1.4826 * np.median(np.abs(heavy - np.median(heavy, axis=0)), axis=0)
    assert np.all(band_scale(np.diff(heavy, 2, axis=0)) > 1.2 * mad)
    assert np.all(np.isnan(band_scale(np.empty((0, 3)))))


@pytest.fixture(scope="module")
def slow_gyro(tmp_path_factory, vehicle):
    """A model fit on a 100 Hz flight, and a held-out flight whose gyro was recorded at
    83 Hz (noiseless rate, interpolated at jittered 83 Hz stamps, + known noise)."""
    tmp = tmp_path_factory.mktemp("slowgyro")
    truth = truth_from_tree({"seed": 1, "effects": DRAG}, vehicle)
    fit_log = tmp / "fit.csv"
    write_log(fit_log, simulate(fig8(duration=10.0, ramp=1.0), vehicle, truth, seed=1).log)
    model = tmp / "m.npz"
    save_model(model, fit_model([fit_log], vehicle, points=80, restarts=0).model)
    quiet = truth_from_tree({"seed": 1, "effects": DRAG, "noise": NO_NOISE}, vehicle)
    raw = simulate(fig8(duration=10.0, ramp=1.0), vehicle, quiet, seed=2).log
    rate = raw.series["body_rate"]
    rng = np.random.default_rng(7)
    stamps = np.cumsum(
        np.full(int(rate.stamps[-1] * 83), 1 / 83) + 2e-4 * rng.random(int(rate.stamps[-1] * 83))
    )
    stamps = stamps[stamps < rate.stamps[-1]]
    values = np.stack([np.interp(stamps, rate.stamps, rate.values[:, j]) for j in range(3)], 1)
    raw.series["body_rate"] = RawSeries(stamps, values + GYRO * rng.standard_normal(values.shape))
    held = tmp / "held-83hz.mcap"
    write_log(held, raw)
    return model, held


def test_the_band_at_one_step_covers_a_gyro_recorded_at_83_hz(slow_gyro):
    model, held = slow_gyro
    # the horizons table alone: the diagnosis does not change it
    h = evaluate([model], [held], horizon_stride=2, with_diagnosis=False).tree["horizons"]
    noise = h["rate_noise"][0]
    assert noise["recorded"] is True
    for a in "xyz":
        assert noise[a] == pytest.approx(GYRO, rel=0.2), noise
        # the grid's own estimate sees about half of it: the band it gave was too narrow
        assert noise["grid"][a] < 0.75 * GYRO, noise
    first = h["table"]["model"][0]
    assert first["steps"] == 1
    for a in "xyz":
        assert 0.85 <= first["coverage"][a] <= 0.99, first["coverage"]
    for row in h["table"]["model"]:
        assert min(row["coverage"][a] for a in "xyz") >= 0.85, row
