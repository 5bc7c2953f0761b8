"""How the residual a model leaves adds up over a rollout (omavctl.learn.rollout_walk),
and the horizon band beyond the fit flight's inputs.

A synthetic 20 s log at 100 Hz whose residual the model cannot predict (its GP
holds nothing): persistent on x (AR(1), correlation time 0.5 s), white on y,
white plus a constant on z. As white noise the band's random walk holds the y
error and misses the x and z ones over 0.5 s (the Betaflight smooth tune's axis
whose GP is off, docs/horizons.md); with the gain measured on another draw of
the log it holds all three.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omavctl.diagnose.horizons import GridSignals, horizon_table
from omavctl.learn.model import ResidualGP
from omavctl.learn.rollout_walk import walk_gain, walk_gain_at
from omavctl.learn.signal import ResidualSamples, feature_names
from omavctl.physics.open_loop import rollout
from tests.conftest import rebuilt

DT, N, RHO, BIAS = 0.01, 2000, 0.98, 0.5


def _residual(rng: np.random.Generator) -> np.ndarray:
    """(N, 3): x AR(1) of unit variance, y white N(0, 1), z N(BIAS, 0.5^2)."""
    r = rng.standard_normal((N, 3))
    for i in range(1, N):
        r[i, 0] = RHO * r[i - 1, 0] + np.sqrt(1.0 - RHO**2) * r[i, 0]
    r[:, 2] = BIAS + 0.5 * r[:, 2]
    return r


def _log(vehicle, seed: int, fx: float = 0.0) -> tuple[ResidualSamples, GridSignals]:
    """The log: fx/m = fx + N(0, 0.3^2); the body rate the rigid body's with the
    residual and a logged damping torque ``-I K omega`` (K = 2 /s: the rates stay small,
    so the gyroscopic coupling does not mix the axes; a rollout over the logged torque
    with the residual exactly has zero error)."""
    rng = np.random.default_rng(seed)
    r = _residual(rng)
    u = np.zeros((N, 6))
    u[:, 0] = fx + 0.3 * rng.standard_normal(N)
    omega, torque = np.zeros((N, 3)), np.zeros((N, 3))
    inertia, inv = vehicle.inertia, vehicle.inertia_inv
    for i in range(N - 1):
        torque[i] = -2.0 * inertia @ omega[i]
        step, _ = rollout(
            omega[i : i + 1], np.zeros((1, 3)), torque[None, i : i + 1], inertia, inv, DT,
            lambda k, w, i=i: r[i][None, :],
        )  # fmt: skip
        omega[i + 1] = step[0, 1]
    index, t, z3 = np.arange(N), np.arange(N) * DT, np.zeros((N, 3))
    s = ResidualSamples(Path(f"walk-{seed}"), index, t, omega, u, z3, z3, r)
    s.du = np.zeros_like(u)
    s.rate_noise = np.zeros(3)
    return s, GridSignals(body_rate=omega, torque=torque, attitude=None)


def _model(vehicle, signal: float = 1e-6) -> ResidualGP:
    """A GP on the wrench that holds nothing (targets 0, fx in [-1, 1]); its noise
    variance is the residual's mean square (what fit gives an axis whose GP is off)."""
    names = feature_names("wrench")
    d = len(names)
    inputs = np.zeros((40, d))
    inputs[:, 0] = np.linspace(-1.0, 1.0, 40)
    lengths = np.full((3, d), 100.0)
    lengths[:, 0] = 0.5
    return ResidualGP(
        vehicle=vehicle,
        features="wrench",
        input_names=tuple(names),
        inputs=inputs,
        targets=np.zeros((40, 3)),
        input_mean=np.zeros(d),
        input_scale=np.ones(d),
        target_mean=np.zeros(3),
        signal_variance=np.full(3, signal),
        length_scales=lengths,
        noise_variance=np.array([1.0, 1.0, BIAS**2 + 0.25]),
    )


def test_the_gain_measures_how_the_residual_adds_up(vehicle):
    model = _model(vehicle)
    fit_log, _ = _log(vehicle, seed=1)
    entry = walk_gain(model, [fit_log], np.empty(0, int), n_prior=model.n_train)
    g = walk_gain_at(entry, np.array([1, 50]))
    assert g[0].tolist() == pytest.approx([1.0, 1.0, 1.0], abs=0.02)
    # x: AR(1) with rho 0.98: 1 + 2 sum_{l<50} (1 - l/50) rho^l = 36.7 (20 s of a 0.5 s
    # correlation time: a sampling error of tens of %)
    assert g[1, 0] == pytest.approx(36.7, rel=0.35)
    assert g[1, 1] < 1.5  # white: a random walk
    # z: (k s^2 + k^2 mu^2) / (k (s^2 + mu^2)) = 25.5 at k = 50
    assert g[1, 2] == pytest.approx(25.5, rel=0.25)
    # without an entry (an older file): the random walk; beyond the longest stored
    # window: fully persistent (proportional to k)
    assert walk_gain_at(None, np.array([1, 50])).tolist() == [[1.0] * 3, [1.0] * 3]
    longest = entry["steps"][-1]
    far = walk_gain_at(entry, np.array([longest, 2 * longest]))
    assert far[1] == pytest.approx(2 * far[0])


def test_the_band_holds_a_persistent_residual_it_called_noise(vehicle):
    model = _model(vehicle)
    fit_log, _ = _log(vehicle, seed=1)
    held, grid = _log(vehicle, seed=2)
    model.provenance["rollout_walk"] = walk_gain(model, [fit_log], np.empty(0, int), 40)
    white = rebuilt(model)  # no entry: the random walk

    def coverage(m: ResidualGP) -> dict:
        rows = horizon_table([m], [held], [grid], 1.0 / DT, (0.01, 0.5))["table"]["model"]
        return rows[1]["coverage"]

    before, after = coverage(white), coverage(model)
    assert before["y"] >= 0.85 and before["x"] < 0.7 and before["z"] < 0.5
    assert min(after["x"], after["y"], after["z"]) >= 0.85


def test_a_rollout_beyond_the_fit_inputs_gets_a_wider_band(vehicle):
    # a GP that learned something, with the band's growth beyond the training box
    model = rebuilt(_model(vehicle, signal=1.0), beyond_scale=np.full(3, 0.5))
    inside, g_in = _log(vehicle, seed=3, fx=0.0)
    beyond, g_out = _log(vehicle, seed=3, fx=6.0)  # 6 input stds past the box's edge

    def half(s: ResidualSamples, g: GridSignals) -> list[dict]:
        rows = horizon_table([model], [s], [g], 1.0 / DT, (0.01, 0.1, 0.5))["table"]["model"]
        return [r["band_halfwidth"] for r in rows]

    for a_in, a_out in zip(half(inside, g_in), half(beyond, g_out), strict=True):
        for axis in "xyz":
            assert a_out[axis] > 1.5 * a_in[axis]
