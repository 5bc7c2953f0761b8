"""``omavctl fit``: learn the residual model from flight logs.

Pipeline (each step a function; :func:`fit_model` runs them in order):

1. :func:`omavctl.learn.flights.read_flights` reads and aligns every log on the
   controller-rate grid (optionally restricted to a time window; a note when
   the body rate was logged slower than the grid).
2. :func:`omavctl.learn.signal.residual_samples` differentiates the body rate with
   the Savitzky-Golay filter per valid segment (dropping ``window // 2``
   samples at every segment edge and segments shorter than the window) and
   subtracts the nominal model, commands filtered like the derivative
   (:func:`omavctl.learn.flights.read_samples`).
3. :func:`omavctl.learn.effect_fit.estimate_effects` fits the named physical
   effects by least squares on their registry regressors (standard errors robust
   to autocorrelated residuals, :mod:`omavctl.learn.intervals`) and subtracts
   them; effects nonlinear in their parameter are found by a 1-D search first
   (:func:`omavctl.learn.fit_steps.first_pass`).
4. :func:`omavctl.learn.points.select_points` picks the GP training points by
   k-medoids on the normalised inputs (squared Euclidean distance); ``--prior``
   adds the prior model's training points (:func:`omavctl.learn.fit_steps.training_set`).
5. :func:`omavctl.learn.hyperparameters.fit_hyperparameters` maximises the
   marginal likelihood of one GP per axis (scikit-learn, squared-exponential
   ARD kernel plus white noise, restarts); the effects are then estimated
   jointly with the GP and the GP validated on held-out time blocks
   (:mod:`omavctl.learn.fit_steps`).
6. The result is a :class:`omavctl.learn.model.ResidualGP`;
   :func:`omavctl.learn.model_file.save_model` writes it.

A vehicle whose torque command is normalised (``command_units.torque:
normalised``) always gets ``inertia_error``: its ``scale`` is then the inverse
of the per-axis command gain (:func:`omavctl.learn.effect_fit.torque_gain`), its
regressor ``I^-1 tau`` (no gyroscopic term), and its joint-fit prior is centred
on and scaled to the least-squares gain (:func:`omavctl.learn.effect_fit.effect_prior`).

Defaults and how they were chosen: ``docs/fit.md``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from omavctl.learn.band import RANGE_GROWTH, TORQUE_GROWTH
from omavctl.learn.effect_fit import (
    GAIN_EFFECT,
    EffectFit,
    check_available,
    merged_estimates,
    torque_gain,
)
from omavctl.learn.fit_notes import actuator_notes, search_notes, unit_notes
from omavctl.learn.fit_steps import (
    FitOptions,
    GPFit,
    Residuals,
    TrainingSet,
    first_pass,
    fit_options,
    gp_hyperparameters,
    joint_step,
    training_set,
    validation_step,
)
from omavctl.learn.flights import LogSummary, read_samples
from omavctl.learn.hyperparameters import DEFAULT_RESTARTS, AxisFit
from omavctl.learn.imu_lever import lever_provenance
from omavctl.learn.mean_shrink import MEAN_SHRINK
from omavctl.learn.model import EffectEstimate, ResidualGP
from omavctl.learn.provenance import fit_provenance
from omavctl.learn.rollout_check import rollout_verdict
from omavctl.learn.rollout_walk import walk_gain
from omavctl.learn.signal import (
    DEFAULT_FEATURES,
    DEFAULT_SG_ORDER,
    DEFAULT_SG_WINDOW,
    ResidualSamples,
    feature_names,
)
from omavctl.learn.spread_band import spread_basis
from omavctl.logs.types import FlightLog
from omavctl.physics.effects import get_effect
from omavctl.vehicle import NORMALISED, Vehicle, default_vehicle

__all__ = [
    "DEFAULT_POINTS",
    "DEFAULT_RESTARTS",
    "FitResult",
    "FitSummary",
    "fit_model",
]

#: Training points selected from the new logs (the paper used 20-100 per flight).
DEFAULT_POINTS = 200

Progress = Callable[[str, float], None]


# ------------------------------------------------------------------ results
@dataclass
class FitSummary:
    """Everything the CLI prints after a fit."""

    logs: list[LogSummary]
    samples: int
    points_new: int
    points_prior: int
    features: str
    input_names: tuple[str, ...]
    sg_window: int
    sg_order: int
    kmedoids: str
    axes: list[AxisFit]
    effects: dict[str, EffectEstimate]
    timings: dict[str, float]
    notes: list[str] = field(default_factory=list)
    #: Units of the logged commands (the vehicle's ``command_units``).
    command_units: dict[str, str] = field(default_factory=lambda: {"torque": "N m", "force": "N"})
    #: Effects added because the vehicle requires them (``inertia_error`` for a
    #: normalised torque command), not named by the user.
    added_effects: tuple[str, ...] = ()
    #: Per-axis gain (3,) of a normalised torque command and its standard error
    #: (3,): torque [N m with the assumed inertia] = gain x command. None for SI.
    torque_gain: np.ndarray | None = None
    torque_gain_stderr: np.ndarray | None = None

    @property
    def points(self) -> int:
        return self.points_new + self.points_prior

    @property
    def torque_normalised(self) -> bool:
        return self.command_units.get("torque") == NORMALISED


@dataclass
class FitResult:
    """The fitted model and a summary of how it was obtained."""

    model: ResidualGP
    summary: FitSummary


# ---------------------------------------------------------------- pipeline
def fit_model(
    logs: Sequence[str | Path | FlightLog],
    vehicle: Vehicle | None = None,
    effects: Sequence[str] | None = None,
    points: int = DEFAULT_POINTS,
    prior: ResidualGP | str | Path | None = None,
    sg_window: int = DEFAULT_SG_WINDOW,
    sg_order: int = DEFAULT_SG_ORDER,
    features: str = DEFAULT_FEATURES,
    seed: int = 0,
    restarts: int = DEFAULT_RESTARTS,
    progress: Progress | None = None,
    time_window: tuple[float | None, float | None] | None = None,
) -> FitResult:
    """Fit effects and the residual GP from flight logs (see module docstring).

    Args:
        logs: log paths (any format ``read_vehicle_log`` reads) or aligned FlightLogs.
        vehicle: the vehicle (mass, inertia, topics, column map, frame, command
            units, controller rate); default omav.
        effects: registry effect names to estimate; None: ``vehicle.effects``.
            With a normalised torque command ``inertia_error`` is added when
            not named (it estimates the command gain; noted in the summary).
        points: training points selected from the new logs.
        prior: a model (or its path) whose training points are kept (augmented).
        sg_window, sg_order: Savitzky-Golay window (odd, samples) and order.
        features: GP inputs: "wrench" (6-D scaled commanded wrench), "+rate" adds
            body rates, "+dtorque" the torque command's rate of change
            (default :data:`omavctl.learn.signal.DEFAULT_FEATURES`, 12-D).
        seed: seeds subsampling and optimiser restarts; same inputs and seed,
            same model.
        restarts: extra optimiser starts per axis.
        progress: called with (stage description, fraction done in [0, 1]).
        time_window: ``(start, end)`` in s from each log's start (``None`` = open
            end; :func:`omavctl.logs.parse_time_window` parses ``START:END``):
            only samples with ``start <= t < end`` are used.

    Raises:
        LogError: unreadable logs, missing roles, NaNs, too few usable samples.
        ConfigError: invalid options. ModelError: an unusable prior.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    report = _reporter(progress)
    vehicle = vehicle if vehicle is not None else default_vehicle()
    sg = (sg_window, sg_order)
    opts = fit_options(
        logs, vehicle, effects, points, prior, sg, features, seed, restarts, time_window
    )
    report("reading logs", 0.0)
    with _timed(timings, "read"):
        original, summaries = read_samples(logs, vehicle, opts.sg, time_window, points, report)
    check_available(original, opts.names)
    with _timed(timings, "effects"):
        report("estimating effects", 0.0)
        res = first_pass(original, opts.names)
    with _timed(timings, "kmedoids"):
        report("selecting training points (k-medoids)", 0.0)
        train = training_set(opts, res)
    with _timed(timings, "gp"):
        report("fitting GP hyperparameters", 0.0)
        gp = gp_hyperparameters(opts, original, res, train)
    eff, notes = joint_step(opts, res, train, gp)
    validation_step(res, train, gp, eff)
    gain, notes = _gain(vehicle, opts.added, eff, notes, opts.names)
    model = _model(opts, res, train, gp, eff, gain, sum(s.n for s in original))
    if any(get_effect(name).measured_state for name in model.effects):
        # which lever arm the measured force was taken less of (files before: unknown)
        levers = [(s.path.name, s.lever) for s in original]
        model.provenance["imu_lever"] = lever_provenance(levers)
    with _timed(timings, "rollouts"):  # the GP mean on held-out rollouts
        _rollout_check(model, original, train, notes)
    with _timed(timings, "evaluate"):
        _training_fit(model, original, gp.axes)
    confirmed: set[str] = set()  # lags and delays the actuators' feedback shows
    notes = actuator_notes(res.found, original, vehicle, confirmed) + notes
    timings["total"] = time.perf_counter() - t_start
    report("done", 1.0)
    summary = _summary(opts, summaries, res, train, gp, eff, gain, notes, timings, confirmed)
    return FitResult(model, summary)


def _reporter(progress: Progress | None) -> Progress:
    """``progress``, or a function that does nothing when there is none."""

    def report(stage: str, fraction: float) -> None:
        if progress is not None:
            progress(stage, fraction)

    return report


@contextmanager
def _timed(timings: dict[str, float], key: str) -> Iterator[None]:
    """Record the wall time of the block in ``timings[key]`` (s)."""
    t0 = time.perf_counter()
    yield
    timings[key] = time.perf_counter() - t0


def _gain(
    vehicle: Vehicle,
    added: Sequence[str],
    eff: EffectFit,
    notes: list[str],
    names: Sequence[str] = (),
) -> tuple[tuple[np.ndarray, np.ndarray] | None, list[str]]:
    """The torque-command gain and its standard error (3,) each for a normalised torque
    command (else None), and the notes with what they say about the command units first."""
    if vehicle.torque_normalised and GAIN_EFFECT in eff.estimates:
        gain, gain_se = torque_gain(eff.estimates[GAIN_EFFECT])
        return (gain, gain_se), [*unit_notes(vehicle, added, gain, gain_se, names), *notes]
    if vehicle.force_normalised:
        return None, [*unit_notes(vehicle, added, None, None), *notes]
    return None, notes


def _effects(opts: FitOptions, res: Residuals, eff: EffectFit) -> dict[str, EffectEstimate]:
    """Every effect's estimate in the order the fit names them (searched and linear)."""
    return merged_estimates(opts.names, eff.estimates, res.found)


def _model(
    opts: FitOptions,
    res: Residuals,
    train: TrainingSet,
    gp: GPFit,
    eff: EffectFit,
    gain: tuple[np.ndarray, np.ndarray] | None,
    n_total: int,
) -> ResidualGP:
    """The fitted model, with its provenance and the rotors' spread at its training
    points (:mod:`omavctl.learn.spread_band`: the band on other flights)."""
    provenance = fit_provenance(opts, train.method, gp, eff, n_total, res.first_pass, gain)
    model = ResidualGP(
        vehicle=opts.vehicle,
        features=opts.features,
        input_names=feature_names(opts.features),
        inputs=train.x,
        targets=train.y,
        input_mean=gp.in_mean,
        input_scale=gp.in_scale,
        target_mean=gp.t_mean,
        signal_variance=gp.sv,
        length_scales=gp.ls,
        noise_variance=gp.nv,
        band_noise=gp.band_noise,
        band_scale=np.array([a.band_scale for a in gp.axes]),
        band_slope=np.array([a.band_slope for a in gp.axes]),
        torque_growth=np.full(3, TORQUE_GROWTH),
        range_growth=RANGE_GROWTH * np.std(train.y, axis=0),
        latent_scale=gp.latent,
        beyond_scale=gp.beyond,
        mean_shrink=MEAN_SHRINK * (gp.sv > 0),
        effects=_effects(opts, res, eff),
        provenance=provenance,
        train_regressors=train.regressors,
    )
    prior = opts.prior_model.spread if opts.prior_model is not None else None
    tolerance = opts.vehicle.thrust_tolerance
    effects = list(model.effects)
    model.spread = spread_basis(res.samples, train.idx, effects, tolerance, prior, train.n_prior)
    return model


def _rollout_check(
    model: ResidualGP, original: Sequence[ResidualSamples], train: TrainingSet, notes: list[str]
) -> None:
    """The GP mean's weight in open-loop rollouts (:mod:`omavctl.learn.rollout_check`),
    recorded in the model, its provenance (``rollout_check``) and the notes; and how
    the residual it leaves adds up over a rollout (``rollout_walk``,
    :mod:`omavctl.learn.rollout_walk`)."""
    verdict = rollout_verdict(model, original, train.idx, train.n_prior)
    model.rollout_gp = verdict.weights

    def axes(v: np.ndarray) -> dict[str, float | None]:
        return {a: float(x) if np.isfinite(x) else None for a, x in zip("xyz", v, strict=True)}

    model.provenance["rollout_check"] = {
        "weights": axes(verdict.weights),
        "error_gp": axes(verdict.error_gp),
        "error_effects": axes(verdict.error_effects),
        "change": axes(verdict.change),
        "stderr": axes(verdict.stderr),
        "chunks": verdict.chunks,
    }
    # how the residual the model leaves adds up over a rollout (the horizon band's walk)
    model.provenance["rollout_walk"] = walk_gain(model, original, train.idx, train.n_prior)
    notes += verdict.notes


def _training_fit(
    model: ResidualGP, original: Sequence[ResidualSamples], axes: list[AxisFit]
) -> None:
    """Training fit on every new sample: fills r2, rmse and rmse_nominal of ``axes``."""
    residual = np.concatenate([s.residual for s in original])
    pred = np.concatenate([model.predict_samples(s, variance=False)[0] for s in original])
    err = residual - pred
    var = residual.var(axis=0)
    for a, axis in enumerate(axes):
        axis.rmse = float(np.sqrt(np.mean(err[:, a] ** 2)))
        axis.rmse_nominal = float(np.sqrt(np.mean(residual[:, a] ** 2)))
        axis.r2 = float(1.0 - np.mean(err[:, a] ** 2) / var[a]) if var[a] > 0 else float("nan")


def _summary(
    opts: FitOptions,
    summaries: list[LogSummary],
    res: Residuals,
    train: TrainingSet,
    gp: GPFit,
    eff: EffectFit,
    gain: tuple[np.ndarray, np.ndarray] | None,
    notes: list[str],
    timings: dict[str, float],
    confirmed: set[str],
) -> FitSummary:
    """What the CLI prints after the fit; ``confirmed``: the lags and delays the
    actuators' feedback shows (:func:`~omavctl.learn.fit_notes.actuator_notes`)."""
    return FitSummary(
        logs=summaries,
        samples=sum(s.used for s in summaries),
        points_new=int(train.idx.size),
        points_prior=train.n_prior,
        features=opts.features,
        input_names=feature_names(opts.features),
        sg_window=opts.sg.window,
        sg_order=opts.sg.order,
        kmedoids=train.method,
        axes=gp.axes,
        effects=_effects(opts, res, eff),
        timings=timings,
        notes=search_notes(res.found, opts.vehicle.torque_normalised, confirmed) + notes + gp.notes,
        command_units=dict(opts.vehicle.command_units),
        added_effects=opts.added,
        torque_gain=None if gain is None else gain[0],
        torque_gain_stderr=None if gain is None else gain[1],
    )
