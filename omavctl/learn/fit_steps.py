"""The steps of ``fit`` between reading the logs and building the model.

:func:`omavctl.learn.fit.fit_model` runs them in order on one
:class:`FitOptions`: :func:`first_pass` (effects: 1-D searches, then least
squares), :func:`training_set` (k-medoids), :func:`gp_hyperparameters` (and the
searched effects once more jointly with the GP), :func:`joint_step` (effects
jointly with the GP) and :func:`validation_step` (blocked cross-validation).
The intermediate results are the small dataclasses :class:`Residuals`,
:class:`TrainingSet` and :class:`GPFit`; a step may update the fields of the
ones it is given, as the pipeline refines them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from omavctl.base.errors import ConfigError, ModelError
from omavctl.learn.effect_fit import (
    GAIN_EFFECT,
    EffectFit,
    effect_prior,
    estimate_effects,
    honest_covariance,
    joint_effects,
    refit_estimates,
    search_step,
    without_searched,
)
from omavctl.learn.effect_search import SearchResult, gls_search
from omavctl.learn.fit_notes import effect_notes
from omavctl.learn.flights import source_of, training_logs
from omavctl.learn.hyperparameters import (
    AxisFit,
    apply_validation,
    fit_hyperparameters,
    measurement_noise_std,
)
from omavctl.learn.model import ResidualGP
from omavctl.learn.model_file import check_vehicle, load_model
from omavctl.learn.points import normalisation, select_points, select_points_per_log
from omavctl.learn.signal import FEATURES, ResidualSamples, SavitzkyGolay, feature_names
from omavctl.logs.types import FlightLog
from omavctl.physics.effects import EFFECTS, get_effect
from omavctl.vehicle import Vehicle

__all__ = [
    "FitOptions",
    "GPFit",
    "Residuals",
    "TrainingSet",
    "first_pass",
    "fit_options",
    "gp_hyperparameters",
    "joint_step",
    "training_set",
    "validation_step",
]


@dataclass
class FitOptions:
    """The checked options of one fit.

    ``names``: every effect to estimate, in order (``added``: those the vehicle
    requires and the user did not name); ``prior_model`` and its provenance
    ``prior_source`` when the fit augments a prior model.
    """

    logs: Sequence[str | Path | FlightLog]
    vehicle: Vehicle
    names: list[str]
    added: tuple[str, ...]
    sg: SavitzkyGolay
    features: str
    points: int
    seed: int
    restarts: int
    time_window: tuple[float | None, float | None] | None
    prior_model: ResidualGP | None = None
    prior_source: dict[str, Any] | None = None


@dataclass
class Residuals:
    """The residual of the new logs as the GP sees it.

    samples: per log, with the searched effects' exact residual removed;
    found: the searched effects' estimates; linear: the effects estimated by
    least squares, first_pass their estimate; x_eff (N, 3, p) their regressors
    at every sample (None without linear effects); residual (N, 3) and targets
    (N, 3) = residual minus the first-pass linear effects, rad/s^2.
    """

    samples: list[ResidualSamples]
    found: dict[str, SearchResult]
    linear: list[str]
    first_pass: EffectFit
    x_eff: np.ndarray | None
    residual: np.ndarray
    targets: np.ndarray


@dataclass
class TrainingSet:
    """The GP training points: idx (k,) and method of the k-medoids selection among the
    N samples of the new logs with inputs_all (N, d); x (n, d), y (n, 3) and
    regressors (name -> (n, 3, p)) at the n = n_prior + k training points (the
    prior model's first)."""

    idx: np.ndarray
    method: str
    inputs_all: np.ndarray
    x: np.ndarray
    y: np.ndarray
    regressors: dict[str, np.ndarray]
    n_prior: int


@dataclass
class GPFit:
    """Per-axis GP hyperparameters and what they were fitted on.

    in_mean, in_scale (d,): input normalisation; z (n, d): normalised training
    inputs; floor (3,): noise floor, rad/s^2; axes: per-axis fits; t_mean,
    sv (3,), ls (3, d): target means, signal variances, length scales; nv (3,):
    noise variances, latent (3,) latent-variance factors and beyond (3,) weights
    on the variance beyond the training box (set by :func:`validation_step`);
    notes for the summary.
    """

    in_mean: np.ndarray
    in_scale: np.ndarray
    z: np.ndarray
    floor: np.ndarray
    axes: list[AxisFit]
    t_mean: np.ndarray
    sv: np.ndarray
    ls: np.ndarray
    notes: list[str]
    nv: np.ndarray = field(default_factory=lambda: np.zeros(3))
    latent: np.ndarray = field(default_factory=lambda: np.ones(3))
    beyond: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def noise_variances(self) -> np.ndarray:
        """Noise variances (3,) of the per-axis fits."""
        return np.array([a.noise_std**2 for a in self.axes])

    @property
    def band_noise(self) -> np.ndarray:
        """Noise variances (3,) of the band inside the fit flight's inputs: the
        calibrated noise before the held-out floor (``nv`` where there is none)."""
        band = np.array([a.band_noise_std**2 for a in self.axes])
        return np.where(np.isfinite(band), np.minimum(band, self.nv), self.nv)


# ---------------------------------------------------------------- options
def fit_options(
    logs: Sequence[str | Path | FlightLog],
    vehicle: Vehicle,
    effects: Sequence[str] | None,
    points: int,
    prior: ResidualGP | str | Path | None,
    sg_window_order: tuple[int, int],
    features: str,
    seed: int,
    restarts: int,
    time_window: tuple[float | None, float | None] | None,
) -> FitOptions:
    """Check ``fit_model``'s options and read the prior model (ConfigError, ModelError)."""
    if not logs:
        raise ConfigError("no logs given")
    if features not in FEATURES:
        raise ConfigError(f"unknown --features '{features}' (known: {', '.join(FEATURES)})")
    if points < 1:
        raise ConfigError(f"--points must be at least 1, got {points}")
    if restarts < 0:
        raise ConfigError(f"--restarts must be >= 0, got {restarts}")
    names, added = _effect_names(vehicle, effects)
    sg = SavitzkyGolay(*sg_window_order, 1.0 / vehicle.gains.rate_hz)
    opts = FitOptions(
        logs, vehicle, names, added, sg, features, points, seed, restarts, time_window
    )
    if prior is not None:
        opts.prior_model, opts.prior_source = _read_prior(prior, vehicle, features, names)
    return opts


def _effect_names(
    vehicle: Vehicle, effects: Sequence[str] | None
) -> tuple[list[str], tuple[str, ...]]:
    """The effects to estimate (registry names, each once) and those added for the vehicle:
    ``inertia_error`` (the command gain) for a normalised torque command."""
    names = list(vehicle.effects if effects is None else effects)
    for name in names:
        get_effect(name)
    if len(set(names)) != len(names):
        raise ConfigError(f"effect named twice in --effects: {', '.join(names)}")
    added: tuple[str, ...] = ()
    if vehicle.torque_normalised and GAIN_EFFECT not in names:
        names.append(GAIN_EFFECT)
        added = (GAIN_EFFECT,)
    return names, added


def _read_prior(
    prior: ResidualGP | str | Path, vehicle: Vehicle, features: str, names: Sequence[str]
) -> tuple[ResidualGP, dict[str, Any]]:
    """The prior model and its provenance; ModelError unless it was fitted for this
    vehicle with the same features and effects."""
    if isinstance(prior, ResidualGP):
        prior_model = prior
        prior_source: dict[str, Any] = {"name": "<in memory>", "sha256": None}
    else:
        prior_model = load_model(prior)
        prior_source = source_of(prior)
    ppath = None if isinstance(prior, ResidualGP) else prior
    # the logs whose points the prior holds, so that evaluate knows them as this
    # model's training data too
    prior_source["training"] = training_logs(prior_model.provenance)
    check_vehicle(prior_model, vehicle, ppath)
    if prior_model.features != features:
        raise ModelError(
            f"prior model uses --features {prior_model.features}, this fit {features}", ppath
        )
    if sorted(prior_model.effects) != sorted(names):
        raise ModelError(
            f"prior model was fitted with effects [{', '.join(sorted(prior_model.effects))}]"
            f", this fit with [{', '.join(sorted(names))}]: use the same --effects",
            ppath,
        )
    return prior_model, prior_source


# ------------------------------------------------------------------ steps
def _targets(
    samples: Sequence[ResidualSamples], x_eff: np.ndarray | None, theta: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Residual (N, 3) of every sample and the targets (N, 3): residual minus
    ``x_eff @ theta`` (the linear effects), or a copy of it without them."""
    residual = np.concatenate([s.residual for s in samples])
    targets = residual.copy()
    if x_eff is not None:
        targets -= x_eff @ theta
    return residual, targets


def first_pass(original: list[ResidualSamples], names: Sequence[str]) -> Residuals:
    """3. effects: those nonlinear in their parameter by an exact 1-D search, then
    the linear ones by least squares on what remains."""
    samples, found = search_step(original, names)
    linear = [nm for nm in names if nm not in found]
    eff = estimate_effects(samples, linear)
    x_eff = None
    if linear:
        x_eff = np.concatenate(
            [np.concatenate([s.regressors[nm] for s in samples]) for nm in linear], axis=-1
        )
    residual, targets = _targets(samples, x_eff, eff.theta)
    return Residuals(samples, found, linear, eff, x_eff, residual, targets)


def training_set(opts: FitOptions, res: Residuals) -> TrainingSet:
    """4. training points: k-medoids on the normalised inputs of every sample (with
    several logs, each log's own, :func:`select_points_per_log`), after the prior
    model's training points when there is one."""
    samples = res.samples
    inputs_all = np.concatenate([s.inputs(opts.features) for s in samples])
    if len(samples) > 1:  # several logs: each its own points (select_points_per_log)
        lengths = [s.n for s in samples]
        idx, kmethod = select_points_per_log(inputs_all, lengths, opts.points, opts.seed)
    else:
        mean_all, scale_all = normalisation(inputs_all)
        idx, kmethod = select_points((inputs_all - mean_all) / scale_all, opts.points, opts.seed)
    train_x = inputs_all[idx]
    train_y = res.targets[idx]
    # what the diagnosis may score as learned (Effect.diagnosed), and the fitted effects
    kept = [nm for nm, e in EFFECTS.items() if e.diagnosed or nm in opts.names]
    train_reg = {nm: np.concatenate([s.regressors[nm] for s in samples])[idx] for nm in kept}
    n_prior = 0
    prior_model = opts.prior_model
    if prior_model is not None:
        n_prior = prior_model.n_train
        train_x = np.concatenate([prior_model.inputs, train_x])
        train_y = np.concatenate([prior_model.targets, train_y])
        train_reg = {
            nm: np.concatenate([prior_model.train_regressors[nm], reg])
            for nm, reg in train_reg.items()
            if nm in prior_model.train_regressors
        }
    return TrainingSet(idx, kmethod, inputs_all, train_x, train_y, train_reg, n_prior)


def _optimise(
    opts: FitOptions, z: np.ndarray, targets: np.ndarray, floor: np.ndarray
) -> tuple[Any, ...]:
    """:func:`fit_hyperparameters` on normalised inputs z (n, d) and targets (n, 3)."""
    # one BLAS thread: the matrices are small (points x points) and threads
    # fighting over 2 cores made fit time swing 2x (profiled)
    with threadpool_limits(1):
        return fit_hyperparameters(
            z,
            targets,
            seed=opts.seed,
            restarts=opts.restarts,
            input_names=feature_names(opts.features),
            noise_floor=floor,
        )


def gp_hyperparameters(
    opts: FitOptions, original: list[ResidualSamples], res: Residuals, train: TrainingSet
) -> GPFit:
    """5. GP hyperparameters; lags and delays once more jointly with the GP
    (:func:`_refine_searched`, which updates ``res`` and ``train.y``)."""
    in_mean, in_scale = normalisation(train.x)
    z = (train.x - in_mean) / in_scale
    floor = measurement_noise_std(res.samples, opts.sg)
    gp = GPFit(in_mean, in_scale, z, floor, *_optimise(opts, z, train.y, floor))
    if res.found and opts.prior_model is None:
        _refine_searched(opts, original, res, train, gp)
    return gp


def _refine_searched(
    opts: FitOptions,
    original: list[ResidualSamples],
    res: Residuals,
    train: TrainingSet,
    gp: GPFit,
) -> None:
    """The searched effects by generalised least squares at the training points (linear
    effects profiled), twice: the first hyperparameters saw the residual of the first,
    biased search; the hyperparameters are re-fitted after the first pass."""
    p_mean, p_std = effect_prior(res.linear, res.first_pass, opts.vehicle)
    x_tr = (
        np.concatenate([train.regressors[nm] for nm in res.linear], axis=-1)
        if res.linear
        else np.zeros((train.x.shape[0], 3, 0))
    )
    for gls_pass in range(2):
        res.found = gls_search(
            original,
            train.idx,
            res.found,
            x_tr,
            (p_mean, p_std),
            gp.z,
            (gp.t_mean, gp.sv, gp.ls, gp.noise_variances),
        )
        res.samples = without_searched(original, res.found)
        res.residual, res.targets = _targets(res.samples, res.x_eff, res.first_pass.theta)
        train.y = res.targets[train.idx]
        if gls_pass == 0:
            gp.axes, gp.t_mean, gp.sv, gp.ls, gp.notes = _optimise(opts, gp.z, train.y, gp.floor)


def joint_step(
    opts: FitOptions, res: Residuals, train: TrainingSet, gp: GPFit
) -> tuple[EffectFit, list[str]]:
    """6. effects jointly with the GP (explicit basis functions, R&W 2.7); updates
    ``train.y``. Returns the estimates and the notes about them."""
    names, eff, vehicle = res.linear, res.first_pass, opts.vehicle
    if not names:
        return eff, effect_notes(eff, vehicle.torque_normalised)
    theta_used = np.tile(eff.theta, (train.x.shape[0], 1))
    if opts.prior_model is not None:
        theta_used[: train.n_prior] = np.concatenate(
            [opts.prior_model.effects[nm].theta for nm in names]
        )
    x_tr = np.concatenate([train.regressors[nm] for nm in names], axis=-1)
    y_raw = train.y + np.einsum("nap,np->na", x_tr, theta_used)
    p_mean, p_std = effect_prior(names, res.first_pass, vehicle)
    theta, cov = joint_effects(
        gp.z, y_raw, x_tr, gp.t_mean, gp.sv, gp.ls, gp.noise_variances, p_std, p_mean
    )
    train.y = y_raw - x_tr @ theta
    eff = refit_estimates(names, theta, honest_covariance(cov, res.first_pass), eff)
    notes = effect_notes(eff, vehicle.torque_normalised)
    notes.append(
        "effects estimated jointly with the GP (generalised least squares at the "
        "training points, hyperparameters from the first pass)"
    )
    return eff, notes


def validation_step(res: Residuals, train: TrainingSet, gp: GPFit, eff: EffectFit) -> None:
    """7. blocked cross-validation: switch the GP off where it does not help on
    held-out time blocks, widen its band to cover them (updates ``gp``)."""
    nv = gp.noise_variances
    targets_all = res.targets
    if res.linear:
        x_all = np.concatenate(
            [np.concatenate([s.regressors[nm] for s in res.samples]) for nm in res.linear],
            axis=-1,
        )
        targets_all = res.residual - x_all @ eff.theta
    gp.t_mean, gp.sv, gp.nv, gp.latent, gp.beyond, cv_notes = apply_validation(
        res.samples,
        train.inputs_all,
        targets_all,
        train.idx,
        train.x[: train.n_prior],
        train.y[: train.n_prior],
        (gp.in_mean, gp.in_scale),
        (gp.t_mean, gp.sv, gp.ls, nv),
        gp.axes,
    )
    gp.notes += cv_notes
