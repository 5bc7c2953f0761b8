"""Planner numerics: rank-updated posterior variance, pathwise samples, deviations."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.physics.rigid_body import euler_rates
from omavctl.planning.candidates import (
    coefficient_names,
    deviated_references,
    sample_coefficients,
)
from omavctl.planning.fused import FusedSamples
from omavctl.planning.gp import GPAxes, PathwiseSamples, posterior_variance_with_data, se_kernel
from omavctl.sim.tasks import fig8


def _gp(n=60, d=6, seed=0) -> GPAxes:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, d))
    y = np.column_stack([np.sin(x[:, 0]), np.cos(x[:, 1]) * x[:, -1], 0.3 * x[:, 0] * x[:, 1]])
    return GPAxes(
        inputs=x,
        targets=y + 0.05 * rng.normal(size=y.shape),
        mean=np.array([0.1, -0.2, 0.0]),
        signal_variance=np.array([1.0, 0.5, 2.0]),
        length_scales=rng.uniform(0.8, 3.0, size=(3, d)),
        noise_variance=np.array([0.01, 0.02, 0.005]),
    )


def _direct_variance(gp: GPAxes, extra: np.ndarray, test: np.ndarray) -> np.ndarray:
    """Posterior variance (S, 3) with training inputs Z u extra, by a fresh solve."""
    z = np.concatenate([gp.inputs, extra])
    out = np.empty((test.shape[0], 3))
    for a in range(3):
        k = gp.kernel(a, z, z) + gp.noise_variance[a] * np.eye(z.shape[0])
        ks = gp.kernel(a, z, test)
        out[:, a] = gp.signal_variance[a] - np.einsum("ns,ns->s", ks, np.linalg.solve(k, ks))
    return out


def test_rank_update_equals_direct_recomputation():
    gp = _gp()
    rng = np.random.default_rng(1)
    new = rng.normal(size=(5, 12, 6))
    test = rng.normal(size=(40, 6))
    fast = posterior_variance_with_data(gp, new, test, chunk=2)
    for b in range(5):
        np.testing.assert_allclose(fast[b], _direct_variance(gp, new[b], test), atol=1e-8)


def test_more_data_near_the_test_points_lowers_variance_more():
    gp = _gp()
    rng = np.random.default_rng(2)
    test = rng.normal(size=(50, 6)) * 0.3 + 4.0  # far from the training data
    near = test[:20][None] + 0.05 * rng.normal(size=(1, 20, 6))
    far = rng.normal(size=(1, 20, 6)) - 4.0
    v = posterior_variance_with_data(gp, np.concatenate([near, far]), test).mean(axis=(1, 2))
    prior = gp.posterior_variance(test).mean()
    assert v[0] < 0.5 * prior and v[1] > 0.95 * prior


def test_posterior_mean_and_variance_match_a_direct_solve():
    gp = _gp()
    test = np.random.default_rng(3).normal(size=(30, 6))
    np.testing.assert_allclose(
        gp.posterior_variance(test), _direct_variance(gp, np.empty((0, 6)), test), atol=1e-10
    )
    a = 1
    k = gp.kernel(a, gp.inputs, gp.inputs) + gp.noise_variance[a] * np.eye(gp.n)
    direct = gp.mean[a] + gp.kernel(a, test, gp.inputs) @ np.linalg.solve(
        k, gp.targets[:, a] - gp.mean[a]
    )
    np.testing.assert_allclose(gp.posterior_mean(test)[:, a], direct, atol=1e-10)


def test_pathwise_samples_have_the_posterior_moments():
    gp = _gp(n=30, d=2, seed=4)
    samples = PathwiseSamples(gp, 3000, np.random.default_rng(5), n_features=2000)
    test = np.random.default_rng(6).normal(size=(8, 2))
    draws = np.stack([samples.evaluate(test, np.full(8, m))[0] for m in range(3000)])
    _, mean = samples.evaluate(test, np.zeros(8, dtype=int))
    np.testing.assert_allclose(mean, gp.posterior_mean(test), atol=1e-12)
    np.testing.assert_allclose(draws.mean(axis=0), gp.posterior_mean(test), atol=0.08)
    np.testing.assert_allclose(draws.var(axis=0), gp.posterior_variance(test), atol=0.06, rtol=0.2)


def test_one_sample_is_one_consistent_function():
    gp = _gp(n=20, d=2, seed=7)
    samples = PathwiseSamples(gp, 4, np.random.default_rng(8))
    z = np.random.default_rng(9).normal(size=(10, 2))
    first, _ = samples.evaluate(z, np.full(10, 2))
    again, _ = samples.evaluate(z[::-1], np.full(10, 2))
    np.testing.assert_allclose(first, again[::-1], atol=1e-12)
    other, _ = samples.evaluate(z, np.full(10, 3))
    assert not np.allclose(first, other)


def test_se_kernel_matches_broadcast_formula():
    rng = np.random.default_rng(10)
    a, b, ell = rng.normal(size=(5, 3)), rng.normal(size=(7, 3)), np.array([0.5, 1.0, 2.0])
    direct = 1.7 * np.exp(-0.5 * (((a[:, None] - b[None]) / ell) ** 2).sum(-1))
    np.testing.assert_allclose(se_kernel(a, b, ell, 1.7), direct, atol=1e-12)


def test_deviated_references_are_consistent_and_vanish_at_the_ends():
    task = fig8(duration=8, ramp=1.5)
    rng = np.random.default_rng(11)
    coeffs = sample_coefficients(rng, 4, 2, 0.1, 2.0, 1.0)
    assert coeffs.shape == (4, 3, 2, 2) and len(coefficient_names(2)) == 12
    refs = deviated_references(task, coeffs)
    assert refs.shape == (4, *task.data.shape)
    dt = task.dt
    for ref in refs:
        eta, omega, domega = ref[:, 4:7], ref[:, 10:13], ref[:, 16:19]
        fd_eta = np.gradient(eta, dt, axis=0)[2:-2]
        np.testing.assert_allclose(euler_rates(eta, omega)[2:-2], fd_eta, atol=5e-4)
        # central differences at 100 Hz err by dt^2/6 * third derivative (~0.03 at 2 Hz)
        np.testing.assert_allclose(np.gradient(omega, dt, axis=0)[2:-2], domega[2:-2], atol=3e-2)
        np.testing.assert_allclose(ref[[0, -1]], task.data[[0, -1]], atol=1e-12)
        assert not np.allclose(ref[:, 4:7], task.euler)
    # zero magnitudes give back the task
    coeffs[..., 1] = 0.0
    np.testing.assert_allclose(deviated_references(task, coeffs)[0], task.data, atol=1e-12)


@pytest.mark.parametrize("amplitude", [0.5, 2.0])
def test_deviation_acceleration_has_the_sampled_magnitude(amplitude):
    task = fig8(roll_deg=0.0, pitch_deg=0.0, duration=20, ramp=2)
    coeffs = np.zeros((1, 3, 2, 2))
    coeffs[0, 0, 0] = [1.0, amplitude]  # 1 Hz on x
    coeffs[0, :, :, 0] = np.maximum(coeffs[0, :, :, 0], 0.5)
    ref = deviated_references(task, coeffs)[0]
    middle = (task.t > 5) & (task.t < 15)
    assert np.abs(ref[middle, 16]).max() == pytest.approx(amplitude, rel=0.01)


@pytest.mark.parametrize("noise", [0.01, 1e-4])
def test_fused_float32_samples_agree_with_the_float64_evaluation(noise):
    """float32 error stays below 1e-5 of the summed term magnitudes (exponents carry
    rounding of the squared norms), and far below the sample itself."""
    gp = _gp(n=80, seed=12)
    gp = GPAxes(
        gp.inputs, gp.targets, gp.mean, gp.signal_variance, gp.length_scales, np.full(3, noise)
    )
    samples = PathwiseSamples(gp, 4, np.random.default_rng(13))
    fused = FusedSamples(samples, chunk=64)
    z = gp.inputs[np.arange(150) % gp.n] + 0.3 * np.random.default_rng(14).normal(size=(150, 6))
    for m in range(4):
        sample, mean = samples.evaluate(z, np.full(150, m))
        out = fused.evaluate(z.T, m)
        assert out.dtype == np.float64 and out.shape == (6, 150)
        for a in range(3):
            k = gp.kernel(a, z, gp.inputs)
            feat = np.abs(samples.features(a, z)) @ np.abs(samples.w[a, m])
            size_s = np.abs(k) @ np.abs(samples.v[a, m]) + feat + abs(gp.mean[a])
            size_m = np.abs(k) @ np.abs(gp.alpha[a]) + abs(gp.mean[a])
            assert np.all(np.abs(out[a] - sample[:, a]) <= 1e-5 * size_s)
            assert np.all(np.abs(out[3 + a] - mean[:, a]) <= 1e-5 * size_m)
        assert np.abs(out[:3].T - sample).max() < 1e-3 * np.abs(sample).max()


def test_fused_answer_does_not_depend_on_how_the_batch_is_split():
    """Bit for bit: plan's results must not depend on --jobs (the blocks are padded to
    one width and a piece given its offset in the batch puts every column where the
    whole batch does, so BLAS computes every column with the same kernel and place)."""
    gp = _gp(n=50, seed=17)
    fused = FusedSamples(PathwiseSamples(gp, 2, np.random.default_rng(18)), chunk=128)
    z = np.random.default_rng(19).normal(size=(6, 301))
    fused.set_batch(301)
    whole = fused.evaluate(z, 1)
    cuts = ((0, 37), (37, 200), (200, 301))
    parts = [fused.evaluate(z[:, lo:hi], 1, offset=lo) for lo, hi in cuts]
    np.testing.assert_array_equal(np.concatenate(parts, axis=1), whole)
    fused.set_batch(5)
    assert fused.width == 64
    with pytest.raises(ValueError, match="multiple of 64"):
        FusedSamples(PathwiseSamples(gp, 1, np.random.default_rng(0)), chunk=100)


def test_fused_samples_without_signal_on_an_axis_give_the_constant():
    gp = _gp(n=30, seed=15)
    gp = GPAxes(
        gp.inputs,
        gp.targets,
        gp.mean,
        np.array([1.0, 0.0, 2.0]),
        gp.length_scales,
        gp.noise_variance,
    )
    fused = FusedSamples(PathwiseSamples(gp, 2, np.random.default_rng(16)))
    out = fused.evaluate(np.random.default_rng(17).normal(size=(6, 20)), 1)
    np.testing.assert_array_equal(out[1], gp.mean[1])
    np.testing.assert_array_equal(out[4], gp.mean[1])
