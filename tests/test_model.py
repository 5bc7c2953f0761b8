"""Model artifact: numpy predictions, file round trip, refusals, controller use; the SG rule."""

from __future__ import annotations

import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import savgol_filter
from typer.testing import CliRunner

from omavctl.base.errors import ModelError
from omavctl.cli import app
from omavctl.learn.effects_band import beyond_weight, parameter_variance
from omavctl.learn.model import SCHEMA, EffectEstimate, ResidualGP
from omavctl.learn.model_file import load_model, save_model
from omavctl.learn.signal import SavitzkyGolay, feature_names, usable_segments
from omavctl.physics.controller import Controller, ControllerState
from omavctl.physics.effects import get_effect
from tests.conftest import rebuilt

runner = CliRunner()


def make_model(
    vehicle, features: str = "wrench", effects: bool = False, n: int = 40, seed: int = 0
):
    """A small model with known hyperparameters on synthetic data."""
    rng = np.random.default_rng(seed)
    d = 6 if features == "wrench" else 9
    z = rng.normal(size=(n, d)) * np.r_[2.0, 2.0, 1.0, 3.0, 3.0, 1.0, 0.5, 0.5, 0.5][:d]
    z[:, 2] += 9.81
    y = np.column_stack([np.sin(z[:, 3]), 0.5 * np.cos(z[:, 4]) * z[:, 0], 0.2 * z[:, 5]])
    y += 0.01 * rng.normal(size=y.shape)
    est = {}
    if effects:
        est["rotational_drag"] = EffectEstimate(
            "rotational_drag", {"D": np.array([0.03, 0.02, 0.01])}, {"D": np.full(3, 1e-3)}
        )
    return ResidualGP(
        vehicle=vehicle,
        features=features,
        input_names=feature_names(features),
        inputs=z,
        targets=y,
        input_mean=z.mean(0),
        input_scale=z.std(0),
        target_mean=y.mean(0),
        signal_variance=np.array([0.5, 0.3, 0.2]),
        length_scales=np.linspace(0.8, 3.0, 3 * d).reshape(3, d),
        noise_variance=np.array([1e-4, 2e-4, 3e-4]),
        effects=est,
        provenance={"seed": seed, "sources": [{"name": "synthetic", "sha256": None}]},
    )


# ------------------------------------------------------------------ numerics
def test_predictions_match_scikit_learn(vehicle):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    model = make_model(vehicle)
    rng = np.random.default_rng(1)
    u = model.inputs[:5] + 0.3 * rng.normal(size=(5, 6))
    mean, var = model.predict(u)
    _, var_noisy = model.predict(u, noise=True)
    assert mean.shape == var.shape == (5, 3)
    zn = model.normalise(model.inputs)
    for a in range(3):
        kernel = ConstantKernel(model.signal_variance[a], "fixed") * RBF(
            model.length_scales[a], "fixed"
        ) + WhiteKernel(model.noise_variance[a], "fixed")
        gpr = GaussianProcessRegressor(kernel, optimizer=None, alpha=0.0)
        gpr.fit(zn, model.targets[:, a] - model.target_mean[a])
        m, s = gpr.predict(model.normalise(u), return_std=True)
        np.testing.assert_allclose(mean[:, a], m + model.target_mean[a], rtol=1e-8, atol=1e-10)
        # sklearn's std includes the white-noise kernel
        np.testing.assert_allclose(var_noisy[:, a], s**2, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(var[:, a], s**2 - model.noise_variance[a], rtol=1e-6, atol=1e-10)
    np.testing.assert_allclose(model.mean(u), mean)


def test_batched_prediction_equals_row_by_row(vehicle):
    model = make_model(vehicle, features="wrench+rate", effects=True)
    rng = np.random.default_rng(2)
    u = rng.normal(size=(7, 6))
    omega = rng.normal(size=(7, 3))
    mean, var = model.predict(u, omega)
    for i in range(7):
        m, v = model.predict(u[i : i + 1], omega[i : i + 1])
        np.testing.assert_allclose(m[0], mean[i], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(v[0], var[i], rtol=1e-10, atol=1e-14)
    # the drag effect is part of the mean: -I^-1 D omega |omega|
    drag = -(np.array([0.03, 0.02, 0.01]) * omega * np.abs(omega)) @ vehicle.inertia_inv.T
    np.testing.assert_allclose(model.effects_mean(u, omega), drag, atol=1e-12)
    with pytest.raises(ValueError, match="pass omega"):
        model.mean(u)


def _with_targets(model, targets):
    """The same GP (inputs, hyperparameters) trained on other targets, mean fitted anew."""
    return rebuilt(
        model,
        targets=targets,
        target_mean=targets.mean(0),
        latent_scale=None,
        beyond_scale=None,
        effects=None,
    )


def test_smooth_is_the_gp_mean_of_other_targets_including_its_mean(vehicle):
    """smooth() must carry the target mean too: far from the data the GP keeps
    predicting it (what evaluate's diagnosis relies on to know what it absorbed)."""
    model = make_model(vehicle)
    rng = np.random.default_rng(3)
    values = 4.0 + rng.normal(size=(model.n_train, 3, 2))  # two columns with a large mean
    z = np.concatenate([model.inputs[:4] + 0.2, model.inputs[:2] + 100.0])  # near and far
    out = model.smooth(z, values)
    for j in range(2):
        expected = _with_targets(model, values[:, :, j]).gp_predict(z, variance=False)[0]
        np.testing.assert_allclose(out[:, :, j], expected, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(out[-1], values.mean(0), rtol=1e-8)  # far: the mean


def test_basis_estimate_recovers_an_effect_the_gp_was_fitted_without(vehicle):
    """Targets = smooth function + X theta: the joint estimate from the training
    points recovers theta (what evaluate predicts fit --effects would find)."""
    model = make_model(vehicle, n=80)
    rng = np.random.default_rng(4)
    x = rng.normal(size=(model.n_train, 3, 2))
    theta = np.array([0.7, -0.3])
    fitted = _with_targets(model, model.targets + x @ theta)
    est, cov = fitted.basis_estimate(x, np.array([10.0, 10.0]))
    np.testing.assert_allclose(est, theta, atol=0.05)
    assert np.all(np.sqrt(np.diag(cov)) < 0.05)


def test_controller_inverts_the_model(vehicle):
    model = make_model(vehicle, features="wrench+rate", effects=True)
    ctrl = Controller(vehicle, model)
    x = np.zeros((3, 12))
    x[:, 9:12] = [[0.5, -0.3, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.5, 0.2]]
    ref = np.zeros((3, 19))
    ref[:, 16:19] = [[1.0, -1.0, 0.5], [0.0, 2.0, 0.0], [0.3, 0.3, -0.3]]
    out = ctrl.step(ControllerState.zeros(3), x, ref, 0.01)
    achieved = out.u[:, 3:] + model.mean(out.u, x[:, 9:12])
    l_x = -np.cross(x[:, 9:12], x[:, 9:12] @ vehicle.inertia.T) @ vehicle.inertia_inv.T
    np.testing.assert_allclose(achieved + l_x, out.desired_angular, atol=1e-8)


# ----------------------------------------------------------------- the file
def test_round_trip_and_plain_numpy_load(vehicle, tmp_path):
    model = make_model(vehicle, features="wrench+rate", effects=True)
    path = tmp_path / "m.npz"
    save_model(path, model)
    with np.load(path, allow_pickle=False) as npz:
        assert str(npz["schema"]) == SCHEMA == "omavctl.model/2"
        assert npz["train_inputs"].shape == (40, 9) and npz["length_scales"].shape == (3, 9)
        effects = json.loads(str(npz["effects"]))
        ci = [[v - 1.959963984540054e-3, v + 1.959963984540054e-3] for v in (0.03, 0.02, 0.01)]
        assert effects.keys() == {"rotational_drag"}
        drag = effects["rotational_drag"]
        assert drag["D"] == [0.03, 0.02, 0.01] and drag["D_stderr"] == [0.001, 0.001, 0.001]
        np.testing.assert_allclose(drag["D_ci95"], ci, rtol=1e-12)
        assert drag["D_pinned"] == [True, True, True] and drag["stderr_method"] == "hac"
        assert json.loads(str(npz["vehicle"]))["mass"] == vehicle.mass
        assert all(not npz[k].dtype.hasobject for k in npz.files)
    back = load_model(path)
    for key, arr in model.to_arrays().items():
        assert np.array_equal(back.to_arrays()[key], arr), key
    u = np.random.default_rng(3).normal(size=(4, 6))
    omega = np.ones((4, 3))
    np.testing.assert_array_equal(back.predict(u, omega)[0], model.predict(u, omega)[0])
    # same model, same bytes; no wall-clock time inside
    save_model(tmp_path / "again.npz", back)
    assert (tmp_path / "again.npz").read_bytes() == path.read_bytes()
    with zipfile.ZipFile(path) as zf:
        assert {i.date_time for i in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}


def _rewrite(src: Path, dst: Path, **changes: np.ndarray) -> None:
    with np.load(src, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update(changes)
    np.savez(dst, **arrays)


def _refused(path: Path) -> str:
    with pytest.raises(ModelError) as err:
        load_model(path)
    assert err.value.path == path
    return str(err.value)


def test_newer_and_unknown_schemas_are_refused(vehicle, tmp_path):
    good = tmp_path / "good.npz"
    save_model(good, make_model(vehicle))
    newer = tmp_path / "newer.npz"
    _rewrite(good, newer, schema=np.array("omavctl.model/4"))
    assert _refused(newer) == (
        f"{newer}: schema 'omavctl.model/4' is newer than this omavctl supports (omavctl.model/3)"
    )
    other = tmp_path / "other.npz"
    _rewrite(good, other, schema=np.array("somebody.gp/1"))
    assert _refused(other) == (
        f"{other}: unknown schema 'somebody.gp/1' (this omavctl reads omavctl.model/1 to /3)"
    )


def test_version_1_file_is_read_with_its_white_standard_errors(vehicle, tmp_path):
    """A file written before the intervals (schema 1: values and white-residual
    standard errors only) loads; its errors are marked optimistic, its intervals
    derived from them, and writing it again gives a version 2 file that says so."""
    good = tmp_path / "good.npz"
    save_model(good, make_model(vehicle, effects=True))
    old = tmp_path / "old.npz"
    v1_effects = {"rotational_drag": {"D": [0.03, 0.0, 0.01], "D_stderr": [0.001, 0.02, 0.01]}}
    _rewrite(
        good, old, schema=np.array("omavctl.model/1"), effects=np.array(json.dumps(v1_effects))
    )
    est = load_model(old).effects["rotational_drag"]
    assert est.stderr_method == "white"
    # a drag is not negative: the intervals of 0 +- 0.04 and 0.01 +- 0.02 are cut at 0
    np.testing.assert_allclose(
        est.interval95()["D"], [[0.02804, 0.03196], [0.0, 0.0392], [0.0, 0.0296]],
        atol=1e-5,
    )  # fmt: skip
    # 0.03 +- 0.002 is pinned down; 0 +- 0.04 and 0.01 +- 0.02 hold the value of no drag
    assert est.pinned()["D"].tolist() == [True, False, False]
    again = tmp_path / "again.npz"
    save_model(again, load_model(old))
    with np.load(again, allow_pickle=False) as npz:
        assert str(npz["schema"]) == "omavctl.model/2"
        assert json.loads(str(npz["effects"]))["rotational_drag"]["stderr_method"] == "white"
    assert load_model(again).effects["rotational_drag"].stderr_method == "white"
    bad = tmp_path / "bad.npz"
    v2_bad = {"rotational_drag": {**v1_effects["rotational_drag"], "stderr_method": "guess"}}
    _rewrite(good, bad, effects=np.array(json.dumps(v2_bad)))
    assert _refused(bad) == (
        f"{bad}: effect 'rotational_drag': unknown stderr_method 'guess' (known: hac, white)"
    )
    bare = tmp_path / "bare.npz"
    np.savez(bare, x=np.zeros(3))
    assert _refused(bare) == f"{bare}: no 'schema' key: not an omavctl model"


def test_pickles_are_refused(vehicle, tmp_path):
    good = tmp_path / "good.npz"
    save_model(good, make_model(vehicle))
    inside = tmp_path / "inside.npz"
    _rewrite(good, inside, provenance=np.array([{"evil": 1}], dtype=object))
    assert _refused(inside) == f"{inside}: contains pickled data; refusing to load"
    whole = tmp_path / "whole.npz"
    whole.write_bytes(pickle.dumps({"schema": SCHEMA}))
    assert _refused(whole) == f"{whole}: contains pickled data; refusing to load"


def test_other_bad_files_are_one_clear_error(vehicle, tmp_path):
    assert _refused(tmp_path / "none.npz") == f"{tmp_path / 'none.npz'}: file not found"
    text = tmp_path / "text.npz"
    text.write_text("hello")
    assert "expected an .npz (zip) file" in _refused(text)
    good = tmp_path / "good.npz"
    save_model(good, make_model(vehicle))
    broken = tmp_path / "broken.npz"
    _rewrite(good, broken, length_scales=np.ones((3, 4)))
    assert "key 'length_scales' must be numbers of shape (3, 6)" in _refused(broken)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:-200])
    assert _refused(truncated) == (
        f"{truncated}: truncated or damaged: it begins as an .npz (zip) file but its end is "
        "missing (an interrupted copy or download?)"
    )


# ------------------------------------------------------------- simulate --model
def test_simulate_with_model_and_vehicle_mismatch(vehicle, tmp_path):
    from omavctl.sim.tasks import fig8
    from omavctl.sim.trajectory import write_trajectory

    ref = tmp_path / "ref.csv"
    write_trajectory(ref, fig8(roll_deg=10, pitch_deg=10, period=2.0, duration=2.0, ramp=1.0))
    model = tmp_path / "m.npz"
    save_model(model, make_model(vehicle, effects=True))
    out = tmp_path / "flight.csv"
    args = ["simulate", "-r", str(ref), "-o", str(out), "--model", str(model), "-q"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert out.exists()
    heavy = tmp_path / "heavy.yaml"
    heavy.write_text("mass: 5.0\n")
    out2 = tmp_path / "flight2.csv"
    result = runner.invoke(
        app,
        [
            "simulate",
            "-r",
            str(ref),
            "-o",
            str(out2),
            "--model",
            str(model),
            "--vehicle",
            str(heavy),
        ],
    )
    assert result.exit_code == 2
    assert result.output.startswith(f"error: {model}: model was fitted for a vehicle of mass 4 kg")
    assert not out2.exists()


# ------------------------------------------------------------------- signal
def test_hold_kernel_reproduces_the_derivative_of_held_accelerations():
    """The SG derivative of a rate driven by held accelerations equals the hold
    kernel applied to those accelerations (exactly, for any window and order)."""
    dt = 0.01
    rng = np.random.default_rng(4)
    acc = np.cumsum(rng.normal(size=(300, 2)), axis=0) * 0.1 + rng.normal(size=(300, 2))
    rate = np.concatenate([np.zeros((1, 2)), np.cumsum(acc[:-1] * dt, axis=0)])  # w_k at t_k
    for window, order in [(3, 2), (5, 2), (11, 2), (11, 3), (15, 4)]:
        sg = SavitzkyGolay(window, order, dt)
        g = sg.hold_kernel
        assert g.shape == (window - 1,) and g.sum() == pytest.approx(1.0)
        m = window // 2
        deriv = sg.derivative(rate)
        np.testing.assert_allclose(
            deriv[m:-m], savgol_filter(rate, window, order, deriv=1, delta=dt, axis=0)[m:-m]
        )
        np.testing.assert_allclose(deriv[m:-m], sg.hold(acc)[m:-m], atol=1e-9)
    np.testing.assert_allclose(SavitzkyGolay(3, 2, dt).hold_kernel, [0.5, 0.5])


def test_rate_noise_is_recovered_from_second_differences():
    from omavctl.learn.signal import rate_noise

    rng = np.random.default_rng(5)
    t = np.arange(6000) * 0.01
    motion = np.column_stack([np.sin(t), 0.5 * np.sin(2 * t), 0.1 * t])
    noise = np.array([0.003, 0.01, 0.001])
    rate = motion + noise * rng.normal(size=motion.shape)
    np.testing.assert_allclose(rate_noise(np.diff(rate, 2, axis=0)), noise, rtol=0.05)
    assert np.all(np.isnan(rate_noise(np.empty((0, 3)))))


def test_usable_segments_drop_edges_and_short_runs():
    kept, edge, short = usable_segments([(0, 100), (110, 115), (120, 131)], 11)
    assert kept == [(0, 100, 5, 95), (120, 131, 125, 126)]
    assert edge == 20 and short == 5


@pytest.mark.parametrize(("window", "order"), [(4, 2), (1, 0), (11, 11), (11, 0)])
def test_bad_filter_settings(window, order):
    from omavctl.base.errors import ConfigError

    with pytest.raises(ConfigError, match="--sg-"):
        SavitzkyGolay(window, order, 0.01)


@pytest.fixture(scope="module")
def drag_fit(vehicle, short_fig8):
    """A drag model (the default plant's imperfections leave the GP something to learn;
    40 points) and the residual samples of its own flight."""
    from omavctl.learn.fit import fit_model
    from omavctl.learn.signal import SavitzkyGolay, residual_samples
    from omavctl.logs import align
    from omavctl.sim.plant import simulate
    from omavctl.sim.truth import truth_from_tree

    truth = truth_from_tree({"effects": {"rotational_drag": {"D": [0.05] * 3}}}, vehicle)
    flight = align(simulate(short_fig8, vehicle, truth, seed=0).log)
    model = fit_model([flight], vehicle, effects=["rotational_drag"], points=40, restarts=0).model
    samples = residual_samples(
        flight, vehicle, SavitzkyGolay(11, 2, 0.01), effects=["rotational_drag"]
    )
    return model, samples


def _switched_off(model):
    """The same model with every axis' GP off (mean 0, constant variance)."""
    return rebuilt(
        model,
        target_mean=np.zeros(3),
        signal_variance=np.zeros(3),
        mean_shrink=np.zeros(3),
        train_regressors=model.train_regressors,
    )


def test_the_band_adds_the_parameter_uncertainty_of_a_gp_with_basis_functions(drag_fit):
    """With the GP off, the parameters' posterior is that of weighted least squares with
    the effect's prior, ``Sigma = (B^-1 + sum_a X_a^T X_a / sigma_a^2)^-1``, and the band
    gains ``x Sigma x^T`` on every sample: it grows with the regressor."""
    model, samples = drag_fit
    off = _switched_off(model)
    h = model.train_regressors["rotational_drag"]  # (m, 3, 3)
    prior = get_effect("rotational_drag").prior_std
    a_mat = np.eye(3) / prior**2 + sum(
        h[:, a, :].T @ h[:, a, :] / model.noise_variance[a] for a in range(3)
    )
    sigma = np.linalg.inv(a_mat)
    x = samples.regressors["rotational_drag"]  # (n, 3, 3)
    expected = np.einsum("nap,pq,naq->na", x, sigma, x)
    # inside the training points' box (beyond it the robust term takes over: below)
    box = beyond_weight(model.inputs, samples.inputs(model.features)) == 0
    assert box.mean() > 0.8
    term = off.effects_variance(samples)
    np.testing.assert_allclose(term[box], expected[box], rtol=1e-9, atol=1e-15)
    _, var = off.predict_samples(samples)
    _, gp_var = off.gp_predict(samples.inputs(off.features))
    assert var is not None and gp_var is not None
    np.testing.assert_allclose(var, gp_var + term, rtol=1e-12)
    size = np.where(box, np.abs(x).sum(axis=(1, 2)), np.nan)
    assert expected[np.nanargmax(size)].sum() > 100 * expected[np.nanargmin(size)].sum()


def test_the_gp_carries_back_most_of_a_parameter_error_inside_its_inputs(drag_fit):
    """A parameter error moves the GP's training targets too, and its mean carries that
    back where it has data (Rasmussen & Williams eq. 2.42: ``R = H* - K*^T K^-1 H``):
    on the fit flight itself the term is under half of ``x Sigma x^T``; on an axis
    whose GP is off it is all of it."""
    model, samples = drag_fit
    h = model.train_regressors["rotational_drag"]
    sigma = model.basis_covariance(h, np.full(3, get_effect("rotational_drag").prior_std))
    x = samples.regressors["rotational_drag"]
    box = beyond_weight(model.inputs, samples.inputs(model.features)) == 0
    full = np.einsum("nap,pq,naq->na", x, sigma, x)[box]
    term = parameter_variance(model, samples)[box]  # the effects' term, without the spread's
    on = model.gp_enabled
    assert on.any()
    print("term / x Sigma x^T per axis:", term.mean(axis=0) / full.mean(axis=0), "GP on:", on)
    assert np.all(term[:, on].mean(axis=0) < 0.5 * full[:, on].mean(axis=0))  # 0.014-0.027
    np.testing.assert_allclose(term[:, ~on], full[:, ~on], rtol=1e-9, atol=1e-15)


def test_beyond_the_training_inputs_the_term_is_at_least_the_robust_one(drag_fit):
    """Beyond a quarter of a training range outside the training inputs' box (where
    ``evaluate`` calls a sample outside) the parameter term ramps up to at least the
    effects' robust standard errors taken as independent, fully at half a range."""
    from dataclasses import replace

    train = np.array([[0.0, 0.0], [1.0, 2.0]])
    z = np.array([[0.5, 1.0], [1.2, 1.0], [1.0, 2.75], [1.0, 3.0], [-2.0, 0.0]])
    np.testing.assert_allclose(beyond_weight(train, z), [0.0, 0.0, 0.5, 1.0, 1.0])
    flat = np.array([[0.0, 3.0], [1.0, 3.0]])  # the second input never moved in training
    np.testing.assert_allclose(beyond_weight(flat, np.array([[0.5, 3.0], [0.5, 3.1]])), [0, 1])
    model, samples = drag_fit
    far = replace(samples, omega=4.0 * samples.omega)  # body rates 4x the fit flight's
    rho = beyond_weight(model.inputs, far.inputs(model.features))
    assert (rho == 1.0).mean() > 0.3
    old = _switched_off(model)
    old.train_regressors = {}
    robust = old.effects_variance(far)
    term = model.effects_variance(far)
    assert np.all(term[rho == 1.0] >= robust[rho == 1.0] * (1 - 1e-12))


def test_a_file_without_training_regressors_takes_the_parameters_as_independent(drag_fit):
    """Older files hold no regressors at the training points: the term is then
    ``sum_j (x_j se_j)^2`` (the GP absorbs nothing, the parameters are independent)."""
    model, samples = drag_fit
    old = _switched_off(model)
    old.train_regressors = {}
    se = model.effects["rotational_drag"].stderr["D"]
    assert np.all(se > 0)
    x = samples.regressors["rotational_drag"]
    expected = ((x * se[None, None, :]) ** 2).sum(axis=2)
    np.testing.assert_allclose(old.effects_variance(samples), expected, rtol=1e-9, atol=1e-15)


# ------------------------------------------------------- band beyond the training box
def test_the_band_grows_beyond_the_training_inputs_and_the_mean_does_not_move(vehicle):
    """Beyond the training inputs' box the variance grows by ``beyond_scale s^2 (e/l)^2``
    per input (e: the distance beyond the box, normalised units); inside it, and for
    a model without the key (files written before it), nothing changes."""
    from omavctl.learn.validation import beyond_envelope_variance

    model = make_model(vehicle)
    zn = model.normalise(model.inputs)
    lo, hi = zn.min(0), zn.max(0)
    inside = model.inputs[:5]
    mean0, var0 = model.gp_predict(inside, noise=True)
    model.beyond_scale = np.array([0.5, 1.0, 2.0])
    mean1, var1 = model.gp_predict(inside, noise=True)
    np.testing.assert_array_equal(mean0, mean1)
    np.testing.assert_array_equal(var0, var1)

    # one input 2 training stds beyond the box, the others at its centre
    far = np.tile(model.input_mean, (2, 1))
    far[:, 3] = model.input_mean[3] + model.input_scale[3] * (hi[3] + np.array([0.0, 2.0]))
    model.beyond_scale = np.zeros(3)
    mean_off, var_off = model.gp_predict(far)
    model.beyond_scale = np.array([0.5, 1.0, 2.0])
    mean_on, var_on = model.gp_predict(far)
    np.testing.assert_array_equal(mean_off, mean_on)
    np.testing.assert_allclose(var_on[0], var_off[0], rtol=1e-9)  # on the box's face
    expected = model.beyond_scale * model.signal_variance * (2.0 / model.length_scales[:, 3]) ** 2
    np.testing.assert_allclose(var_on[1] - var_off[1], expected, rtol=1e-9)
    np.testing.assert_allclose(
        beyond_envelope_variance(
            np.array([[lo[0] - 1.0, *zn[0, 1:]]]), lo, hi, 2.0, np.full(zn.shape[1], 0.5)
        ),
        [2.0 * 4.0],
    )


def _check_optional_key(path, tmp_path, key, saved, default, bad):
    """The model file at ``path`` reads ``key`` back as ``saved``; without the key (a
    file from before it) as ``default`` (None: not checked); with ``bad`` it is refused."""
    np.testing.assert_array_equal(getattr(load_model(path), key), saved)
    if default is not None:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files if k != key}
        old = tmp_path / "old.npz"
        np.savez(old, **arrays)
        np.testing.assert_array_equal(getattr(load_model(old), key), default)
    negative = tmp_path / "negative.npz"
    _rewrite(path, negative, **{key: bad})
    assert _refused(negative) == f"{negative}: key '{key}' must not be negative"


def test_beyond_scale_round_trips_and_is_checked(vehicle, tmp_path):
    model = make_model(vehicle)
    model.beyond_scale = np.array([0.5, 0.75, 1.5])
    good = tmp_path / "good.npz"
    save_model(good, model)
    _check_optional_key(
        good, tmp_path, "beyond_scale", [0.5, 0.75, 1.5], np.zeros(3), np.array([0.5, -1.0, 0.5])
    )


def test_the_band_noise_rises_to_the_floor_only_beyond_the_fit_inputs(vehicle, tmp_path):
    """``band_noise`` is the noise inside the training inputs' box and up to a quarter of
    a training range beyond it; from there the noise rises to ``noise_variance`` (fit's
    floor from the held-out error), fully at half a range. The mean never moves."""
    model = make_model(vehicle)
    band = np.array([0.5e-4, 1e-4, 3e-4])  # z equal: no floor on that axis
    model.band_noise = band.copy()
    lo, hi = model.inputs.min(0), model.inputs.max(0)
    span = hi - lo
    inside = model.inputs[:5]
    at = {f: np.where(np.arange(6) == 3, hi + f * span, inside[0]) for f in (0.2, 0.375, 0.6)}
    mean_in, var_in = model.gp_predict(inside, noise=True)
    _, latent = model.gp_predict(inside)
    np.testing.assert_allclose(var_in - latent, np.broadcast_to(band, (5, 3)), rtol=1e-12)
    for f, share in ((0.2, 0.0), (0.375, 0.5), (0.6, 1.0)):
        _, v = model.gp_predict(at[f][None, :], noise=True)
        _, lat = model.gp_predict(at[f][None, :])
        expect = band + share * (model.noise_variance - band)
        np.testing.assert_allclose(v[0] - lat[0], expect, rtol=1e-9)
    mean_before, _ = make_model(vehicle).gp_predict(inside, noise=True)
    np.testing.assert_array_equal(mean_in, mean_before)
    path = tmp_path / "m.npz"
    save_model(path, model)
    bad = np.array([1e-4, -1e-4, 1e-4])
    _check_optional_key(path, tmp_path, "band_noise", band, model.noise_variance, bad)


def test_the_band_inside_follows_the_gps_distance_from_its_data(vehicle, tmp_path):
    """Inside the fit inputs the band's latent variance and noise are multiplied by
    ``band_scale (1 + band_slope rho)``, ``rho`` the latent variance over its prior (at
    most 1; fit's blocked cross-validation sets both,
    :func:`omavctl.learn.validation.band_slope`); from half a training range beyond the
    box the band is as before; the mean and the latent band (horizons, planning) never
    move. Files without the keys read 1 and 0 (the band as it was)."""
    model = make_model(vehicle)
    lo, hi = model.inputs.min(0), model.inputs.max(0)
    far = np.where(np.arange(6) == 3, hi + 0.6 * (hi - lo), model.inputs[0])
    z = np.vstack([model.inputs[:4], 0.5 * (lo + hi), far])  # points, the box's centre, far
    mean0, var0 = model.gp_predict(z, noise=True)
    _, latent = model.gp_predict(z)
    a, beta = np.array([0.5, 1.0, 2.0]), np.array([10.0, 0.0, 3.0])
    model.band_scale, model.band_slope = a, beta
    mean1, var1 = model.gp_predict(z, noise=True)
    np.testing.assert_array_equal(mean1, mean0)
    np.testing.assert_array_equal(model.gp_predict(z)[1], latent)
    rho = np.minimum(latent / model.signal_variance, 1.0)
    assert rho[:4].max() < 0.01 and rho[4, 0] > 0.3  # at the data, and away from it (x)
    factor = a * (1.0 + beta * rho[:5])
    np.testing.assert_allclose(var1[:5], factor * (latent[:5] + model.band_noise), rtol=1e-12)
    np.testing.assert_allclose(var1[5], var0[5], rtol=1e-12)
    path = tmp_path / "m.npz"
    save_model(path, model)
    _check_optional_key(path, tmp_path, "band_slope", beta, np.zeros(3), -beta)
    np.testing.assert_array_equal(load_model(path).band_scale, a)
    zero = tmp_path / "zero.npz"
    _rewrite(path, zero, band_scale=np.array([0.5, 0.0, 2.0]))
    assert _refused(zero) == f"{zero}: key 'band_scale' must be positive"


def test_the_band_grows_with_the_torque_beyond_the_fit_flights(vehicle, tmp_path):
    """Beyond the fit flight's commanded angular accelerations the band gains
    ``(torque_growth ||e||)^2``, ``e`` how far each axis' ``I^-1 tau`` lies beyond the
    training range (issue 26: wider beyond the fit inputs is accepted, overconfident
    is not), fully from half a training range beyond the box; within a quarter range
    (inside, as ``evaluate`` counts it) and along other inputs, nothing; the mean
    never moves."""
    model = make_model(vehicle)
    lo, hi = model.inputs.min(0), model.inputs.max(0)
    span = hi - lo
    far = np.array([model.inputs[0]] * 5)
    far[1, 3] = hi[3] + 0.6 * span[3]  # (I^-1 tau)x beyond
    far[2, 3], far[2, 4] = lo[3] - 0.6 * span[3], hi[4] + 0.8 * span[4]  # x and y
    far[3, 0] = hi[0] + 5.0 * span[0]  # a force beyond: not a torque
    far[4, 3] = hi[3] + 0.2 * span[3]  # inside the fit inputs as evaluate counts them
    mean0, var0 = model.gp_predict(far, noise=True)
    growth = np.array([0.3, 0.3, 0.1])
    model.torque_growth = growth
    mean1, var1 = model.gp_predict(far, noise=True)
    np.testing.assert_array_equal(mean1, mean0)
    added = var1 - var0
    np.testing.assert_allclose(added[[0, 3, 4]], 0.0, atol=1e-15)
    np.testing.assert_allclose(added[1], (growth * 0.6 * span[3]) ** 2, rtol=1e-9)
    e2 = (0.6 * span[3]) ** 2 + (0.8 * span[4]) ** 2
    np.testing.assert_allclose(added[2], growth**2 * e2, rtol=1e-9)
    _, latent = model.gp_predict(far)  # the latent band (horizons, planning): unchanged
    model.torque_growth = np.zeros(3)
    np.testing.assert_array_equal(model.gp_predict(far)[1], latent)
    model.torque_growth = growth
    path = tmp_path / "m.npz"
    save_model(path, model)
    bad = np.array([0.3, -0.1, 0.3])
    _check_optional_key(path, tmp_path, "torque_growth", growth, np.zeros(3), bad)


def test_the_band_grows_with_the_reach_beyond_the_training_inputs(vehicle, tmp_path):
    """Beyond the training inputs' box in any input the band gains ``(range_growth
    reach)^2``, ``reach`` the largest excursion in training ranges (a thrust the fit
    flight never reached: issue 26's chirp -> figure-8), rising from a quarter to half a
    range beyond the box (as the floor from the held-out error); inside, nothing."""
    model = make_model(vehicle)
    lo, hi = model.inputs.min(0), model.inputs.max(0)
    span = hi - lo
    at = np.array([model.inputs[0]] * 4)
    at[1, 2] = hi[2] + 0.5 * span[2]  # the thrust half a range beyond
    at[2, 2], at[2, 0] = lo[2] - 0.2 * span[2], hi[0] + 1.5 * span[0]  # the largest counts
    at[3, 1] = hi[1] + 0.375 * span[1]  # halfway up the ramp: half the term
    _, var0 = model.gp_predict(at, noise=True)
    model.range_growth = np.array([0.4, 0.2, 0.1])
    _, var1 = model.gp_predict(at, noise=True)
    added = var1 - var0
    np.testing.assert_allclose(added[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(added[1], (model.range_growth * 0.5) ** 2, rtol=1e-9)
    np.testing.assert_allclose(added[2], (model.range_growth * 1.5) ** 2, rtol=1e-9)
    np.testing.assert_allclose(added[3], 0.5 * (model.range_growth * 0.375) ** 2, rtol=1e-9)
    path = tmp_path / "m.npz"
    save_model(path, model)
    bad = np.array([0.3, -0.1, 0.3])
    _check_optional_key(path, tmp_path, "range_growth", [0.4, 0.2, 0.1], None, bad)


def test_the_diagnosis_weighs_samples_by_the_band_without_its_growth(vehicle):
    """The band's growth beyond the fit inputs is room for an error the fit flight could
    not show, such as a missing effect; the diagnosis looks for that error and weighs
    samples by the band without it (``diagnose.diagnosis.weight_std``): inside the fit
    inputs the same std, beyond them the band's std less its growth."""
    from omavctl.diagnose.diagnosis import weight_std

    model = make_model(vehicle)
    model.range_growth = np.array([0.4, 0.2, 0.1])
    lo, hi = model.inputs.min(0), model.inputs.max(0)
    at = np.array([model.inputs[0]] * 2)
    at[1, 2] = hi[2] + 0.5 * (hi[2] - lo[2])  # the thrust half a range beyond
    _, var = model.gp_predict(at, noise=True)
    std = np.sqrt(var)
    weights = weight_std(model, at, std)
    np.testing.assert_allclose(weights[0], std[0], rtol=1e-12)
    np.testing.assert_allclose(weights[1] ** 2, var[1] - (model.range_growth * 0.5) ** 2)
    assert np.all(weights[1] < std[1])
    model.range_growth = np.zeros(3)  # no growth: the band itself
    np.testing.assert_allclose(weight_std(model, at, std), std)


def test_a_gp_mean_near_zero_still_carries_back_a_parameter_error(drag_fit):
    """The parameter term is R&W eq. 2.42's with the GP mean's carry-back in full, also
    where ``mean_shrink`` weighs the mean (its cost is the band's own ``((1 - w) m)^2``
    term): equal to the term of the same model with ``mean_shrink`` 0. Weighing the
    carry-back by the weight of the mean as it is (near 0 where that mean is near 0)
    made it several times larger inside the fit inputs (0.17 against 0.002 rad/s^2 RMS
    on a scorecard draw's x, docs/intervals.md)."""
    from omavctl.learn.mean_shrink import shrink_weight

    model, samples = drag_fit
    assert np.all(model.mean_shrink[model.gp_enabled] > 0)
    z = samples.inputs(model.features)
    box = beyond_weight(model.inputs, z) == 0
    term = parameter_variance(model, samples)[box]
    unweighed = parameter_variance(
        rebuilt(model, mean_shrink=np.zeros(3), train_regressors=model.train_regressors), samples
    )[box]
    np.testing.assert_allclose(term, unweighed, rtol=1e-9, atol=1e-15)
    h = model.train_regressors["rotational_drag"]
    sigma = model.basis_covariance(h, np.full(3, get_effect("rotational_drag").prior_std))
    mean, latent = model.latent(z)
    w = shrink_weight(mean, latent, model.mean_shrink)[box]
    r = samples.regressors["rotational_drag"][box] - w[:, :, None] * model.smooth(z, h)[box]
    weighed = np.einsum("nap,pq,naq->na", r, sigma, r)
    on = model.gp_enabled
    ratio = weighed[:, on].mean(axis=0) / term[:, on].mean(axis=0)
    print("weighed carry-back / the term, per axis with its GP on:", ratio)
    assert np.all(ratio > 3.0)
