"""fit's check of the GP mean on held-out rollouts (omavctl.learn.rollout_check).

A synthetic log whose residual is a fast function g of an input (white in
time) plus white noise. The model's GP holds g on x; on z it holds g plus a
constant bias. One step ahead both GPs help (g is most of the residual); over
0.5 s g averages out while the bias accumulates, so the biased GP hurts. The
check keeps the GP mean in rollouts on x and leaves it out on z; the horizon
table of another draw of the same log then has the full model within 1.05x
physics + effects at 0.5 s on every axis, where the GP used as in one-step
predictions was above it on z (the old behaviour).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omavctl.base.errors import ModelError
from omavctl.diagnose.horizons import GridSignals, horizon_table
from omavctl.learn.model import ResidualGP
from omavctl.learn.model_file import load_model, save_model
from omavctl.learn.rollout_check import rollout_verdict
from omavctl.learn.signal import ResidualSamples, feature_names
from omavctl.physics.open_loop import rollout
from tests.conftest import rebuilt

DT, N, BIAS = 0.01, 2000, 0.4


def _g(fx: np.ndarray) -> np.ndarray:
    return 2.0 * np.sin(1.3 * fx)


def _log(vehicle, seed: int) -> tuple[ResidualSamples, GridSignals]:
    """20 s at 100 Hz: fx/m white N(0, 1), torque 0; the residual on x and z is
    g(fx/m) + N(0, 0.5^2), on y N(0, 0.5^2); the body rate integrates the rigid body
    with it (so a rollout with the residual exactly has zero error)."""
    rng = np.random.default_rng(seed)
    u = np.zeros((N, 6))
    u[:, 0] = rng.standard_normal(N)
    r = 0.5 * rng.standard_normal((N, 3))
    r[:, 0] += _g(u[:, 0])
    r[:, 2] += _g(u[:, 0])
    torque = np.zeros((1, N - 1, 3))
    omega, _ = rollout(
        np.zeros((1, 3)),
        np.zeros((1, 3)),
        torque,
        vehicle.inertia,
        vehicle.inertia_inv,
        DT,
        lambda k, w: r[k][None, :],
    )
    omega = omega[0]
    index, t, z3 = np.arange(N), np.arange(N) * DT, np.zeros((N, 3))
    s = ResidualSamples(
        Path(f"synthetic-{seed}"), index, t, omega, u, z3, z3, r, du=np.zeros_like(u)
    )
    s.rate_noise = np.zeros(3)
    return s, GridSignals(body_rate=omega, torque=np.zeros((N, 3)), attitude=None)


def _model(vehicle) -> ResidualGP:
    """GP on the wrench: x holds g(fx/m), y nothing, z g(fx/m) + BIAS."""
    names = feature_names("wrench")
    d = len(names)
    fx = np.linspace(-3.5, 3.5, 60)
    inputs = np.zeros((fx.size, d))
    inputs[:, 0] = fx
    targets = np.stack([_g(fx), np.zeros_like(fx), _g(fx) + BIAS], axis=1)
    lengths = np.full((3, d), 100.0)
    lengths[:, 0] = 0.5
    return ResidualGP(
        vehicle=vehicle,
        features="wrench",
        input_names=tuple(names),
        inputs=inputs,
        targets=targets,
        input_mean=np.zeros(d),
        input_scale=np.ones(d),
        target_mean=np.array([0.0, 0.0, BIAS]),
        signal_variance=np.full(3, 4.0),
        length_scales=lengths,
        noise_variance=np.full(3, 0.25),
    )


def test_a_biased_gp_that_helps_one_step_is_left_out_of_rollouts(vehicle):
    model = _model(vehicle)
    fit_log, _ = _log(vehicle, seed=1)
    verdict = rollout_verdict(model, [fit_log], np.empty(0, int), n_prior=model.n_train)
    assert verdict.chunks >= 30
    # x: g alone lowers the held-out 0.5 s error by far more than its standard error
    assert verdict.weights[0] == 1.0
    assert verdict.change[0] < -5 * verdict.stderr[0]
    assert verdict.error_gp[0] < 0.6 * verdict.error_effects[0]
    # z: the bias (0.4 rad/s^2, 0.2 rad/s over 0.5 s) outweighs g's averaged-out help
    assert verdict.weights[2] == 0.0
    assert verdict.error_gp[2] > 1.5 * verdict.error_effects[2]
    assert any(n.startswith("axis z: the GP mean is left out") for n in verdict.notes)


def test_the_full_model_no_longer_loses_at_half_a_second(vehicle):
    model = _model(vehicle)
    fit_log, _ = _log(vehicle, seed=1)
    held, grid = _log(vehicle, seed=2)
    verdict = rollout_verdict(model, [fit_log], np.empty(0, int), n_prior=model.n_train)
    checked = rebuilt(model, rollout_gp=verdict.weights)

    def horizons(m: ResidualGP) -> dict:
        return horizon_table([m], [held], [grid], 1.0 / DT, (0.01, 0.5))

    before, after = horizons(model), horizons(checked)
    old, new = before["table"], after["table"]
    # the findings say so: the old table finds the GP winning early and losing late on z,
    # the new one that its rollouts leave the GP mean out on z
    found_before = {(f["code"], f["axis"]) for f in before["findings"]}
    found_after = {(f["code"], f["axis"]) for f in after["findings"]}
    assert {("gp_hurts_long", "z"), ("gp_worse_long", "z")} <= found_before
    assert ("gp_left_out", "z") in found_after and ("gp_left_out", "x") not in found_after
    assert not {("gp_hurts_long", "z"), ("gp_worse_long", "z")} & found_after
    # the old behaviour: the GP lowers z's one-step error and raises its 0.5 s error
    assert old["model"][0]["rate_error"]["z"] < 0.7 * old["effects"][0]["rate_error"]["z"]
    assert old["model"][1]["rate_error"]["z"] > 1.5 * old["effects"][1]["rate_error"]["z"]
    for axis in "xyz":
        assert new["model"][1]["rate_error"][axis] <= 1.05 * new["effects"][1]["rate_error"][axis]
    # x keeps what the GP gives at both horizons
    assert new["model"][1]["rate_error"]["x"] < 0.6 * new["effects"][1]["rate_error"]["x"]
    assert new["model"][0]["rate_error"]["x"] == pytest.approx(
        old["model"][0]["rate_error"]["x"], rel=1e-4
    )  # z couples into x only through the gyroscopic term
    # the band adds the GP mean the rollout leaves out: it still covers z
    assert new["model"][1]["coverage"]["z"] >= 0.85


def test_the_rollout_weight_is_kept_in_the_model_file(vehicle, tmp_path):
    path = tmp_path / "m.npz"
    save_model(path, rebuilt(_model(vehicle), rollout_gp=np.array([1.0, 1.0, 0.0])))
    assert load_model(path).rollout_gp.tolist() == [1.0, 1.0, 0.0]
    arrays = dict(np.load(path, allow_pickle=False))
    arrays["rollout_gp"] = np.array([1.0, 2.0, 0.0])
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ModelError, match="key 'rollout_gp' must be between 0 and 1"):
        load_model(tmp_path / "bad.npz")
    del arrays["rollout_gp"]  # a file written before the check: the mean as in one step
    np.savez(tmp_path / "old.npz", **arrays)
    assert load_model(tmp_path / "old.npz").rollout_gp.tolist() == [1.0, 1.0, 1.0]
