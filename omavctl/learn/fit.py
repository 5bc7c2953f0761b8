"""``omavctl fit``: learn the residual model from flight logs.

Pipeline (each step a function; :func:`fit_model` runs them in order):

1. :func:`read_flights` reads and aligns every log on the controller-rate grid
   (optionally restricted to a time window; a note when the body rate was
   logged slower than the grid).
2. :func:`omavctl.learn.signal.residual_samples` differentiates the body rate with
   the Savitzky-Golay filter per valid segment (dropping ``window // 2``
   samples at every segment edge and segments shorter than the window) and
   subtracts the nominal model, commands filtered like the derivative.
3. :func:`estimate_effects` fits the named physical effects by least squares on
   their registry regressors (standard errors from the residual variance) and
   subtracts them.
4. :func:`select_points` picks the GP training points by k-medoids on the
   normalised inputs (squared Euclidean distance); ``--prior`` adds the prior
   model's training points.
5. :func:`fit_hyperparameters` maximises the marginal likelihood of one GP per
   axis (scikit-learn, squared-exponential ARD kernel plus white noise, restarts).
6. The result is a :class:`omavctl.learn.model.ResidualGP`; :func:`omavctl.learn.model.save_model`
   writes it.

A vehicle whose torque command is normalised (``command_units.torque:
normalised``) always gets ``inertia_error``: its ``scale`` is then the inverse
of the per-axis command gain (:func:`torque_gain`), its regressor ``I^-1 tau``
(no gyroscopic term), and its joint-fit prior is centred on and scaled to the
least-squares gain (:func:`effect_prior`).

Defaults and how they were chosen: ``docs/fit.md``.
"""

from __future__ import annotations

import hashlib
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from omavctl import __version__
from omavctl.base.errors import ConfigError, LogError, ModelError
from omavctl.learn.control_loss import out_of_control
from omavctl.learn.effect_search import SearchResult, gls_search, search_effects
from omavctl.learn.model import EffectEstimate, ResidualGP, check_vehicle, load_model
from omavctl.learn.signal import (
    DEFAULT_FEATURES,
    DEFAULT_SG_ORDER,
    DEFAULT_SG_WINDOW,
    FEATURES,
    ResidualSamples,
    SavitzkyGolay,
    feature_names,
    residual_samples,
)
from omavctl.learn.validation import (
    BLOCK_SECONDS,
    FOLDS,
    KEEP_RATIO,
    TARGET_COVERAGE,
    cholesky_of_k,
    cross_validate,
    fold_of,
)
from omavctl.logs.types import FlightLog
from omavctl.physics.effects import EFFECTS, get_effect
from omavctl.vehicle import NORMALISED, Vehicle, default_vehicle

__all__ = [
    "DEFAULT_POINTS",
    "DEFAULT_RESTARTS",
    "GAIN_EFFECT",
    "GAIN_PRIOR_FACTOR",
    "KMEDOIDS_MAX_DIRECT",
    "KMEDOIDS_SUBSAMPLE",
    "PRIOR_STD",
    "RATE_TOLERANCE",
    "AxisFit",
    "EffectFit",
    "FitResult",
    "FitSummary",
    "LogSummary",
    "body_rate_rate",
    "effect_prior",
    "effect_unit",
    "estimate_effects",
    "fit_hyperparameters",
    "fit_model",
    "read_flights",
    "select_points",
    "sha256_of",
    "torque_gain",
    "upsampling_note",
]

#: Training points selected from the new logs (the paper used 20-100 per flight).
DEFAULT_POINTS = 200
#: Restarts of the marginal-likelihood optimiser per axis (besides the first run).
DEFAULT_RESTARTS = 3
#: Above this many samples k-medoids runs on seeded subsamples (CLARA-style):
#: the n x n float64 distance matrix of 3000 samples is 72 MB.
KMEDOIDS_MAX_DIRECT = 3000
#: Size of each subsample, and how many subsamples are tried.
KMEDOIDS_SUBSAMPLE = 2000
KMEDOIDS_DRAWS = 3
#: Roles fit needs from every log.
REQUIRED_ROLES = ("body_rate", "force_command", "torque_command")
#: The effect that estimates the gain of a normalised torque command.
GAIN_EFFECT = "inertia_error"
#: A body rate logged below this fraction of the grid rate is noted as upsampled
#: (the tolerance absorbs jitter in the median step).
RATE_TOLERANCE = 0.95

Progress = Callable[[str, float], None]


# ------------------------------------------------------------------ results
@dataclass
class LogSummary:
    """What one log contributed: grid samples, samples used, and what was dropped."""

    path: Path
    samples: int
    used: int
    in_gaps: int
    edge_dropped: int
    short_dropped: int
    notes: list[str] = field(default_factory=list)


@dataclass
class EffectFit:
    """Least-squares estimate of the stacked effect parameters.

    theta (p,), cov (p, p); estimates by effect name; residual_std (3,) per axis
    after subtracting the effects; explained (3,) fraction of residual variance
    the effects explain per axis.
    """

    theta: np.ndarray
    cov: np.ndarray
    estimates: dict[str, EffectEstimate]
    residual_std: np.ndarray
    explained: np.ndarray


@dataclass
class AxisFit:
    """Fitted GP of one axis: hyperparameters (physical units) and training fit.

    signal_std and noise_std in rad/s^2; length_scales (d,) in normalised input
    units; r2 and rmse of the model (effects + GP) on every sample of the new
    logs; rmse_nominal: RMS of the residual without any model.
    """

    signal_std: float
    noise_std: float
    length_scales: np.ndarray
    log_marginal_likelihood: float
    r2: float = float("nan")
    rmse: float = float("nan")
    rmse_nominal: float = float("nan")
    #: blocked cross-validation (:mod:`omavctl.learn.validation`): whether the GP stays
    #: on, held-out RMSE of the GP and of physics only (rad/s^2), held-out
    #: 2-sigma coverage before calibration and the factor on the std after it
    gp_on: bool = True
    cv_rmse_gp: float = float("nan")
    cv_rmse_physics: float = float("nan")
    cv_coverage: float = float("nan")
    std_factor: float = 1.0
    latent_factor: float = 1.0


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


# ------------------------------------------------------------------- steps
def read_flights(
    logs: Sequence[str | Path | FlightLog],
    vehicle: Vehicle,
    time_window: tuple[float | None, float | None] | None = None,
) -> list[FlightLog]:
    """Read and align every log on the controller-rate grid (``read_vehicle_log``:
    the vehicle's topics, column map and frame; ground and idle time excluded;
    only ``start <= t < end`` s from each log's start with ``time_window``).

    A log whose body rate was recorded below the grid rate gets a note (its grid
    samples are interpolated, see :func:`upsampling_note`). Already aligned
    :class:`FlightLog` objects are passed through (the window still applies).
    Raises LogError for an unreadable log, one lacking the body rate or the
    wrench command, or an empty window.
    """
    from omavctl.logs import read_vehicle_log, restrict_window

    out = []
    for item in logs:
        if isinstance(item, FlightLog):
            flight = item if time_window is None else restrict_window(item, time_window)
        else:
            flight = read_vehicle_log(
                item,
                vehicle,
                rate=vehicle.gains.rate_hz,
                required=REQUIRED_ROLES,
                time_window=time_window,
            )
        note = upsampling_note(flight, vehicle)
        if note is not None:
            flight = replace(flight, notes=[*flight.notes, note])
        out.append(flight)
    return out


def body_rate_rate(flight: FlightLog, vehicle: Vehicle) -> float | None:
    """Median rate (Hz) at which the log recorded the body rate, if the reader saw it.

    The source is the ``body_rate`` column group of a CSV or the vehicle's
    ``imu`` topic of a bag (:attr:`FlightLog.topics`).
    """
    names = {"body_rate", vehicle.topics.get("imu", "")}
    rates = [info.rate for info in flight.topics if info.name in names and info.rate > 0]
    return min(rates) if rates else None


def upsampling_note(flight: FlightLog, vehicle: Vehicle) -> str | None:
    """A note when the body rate was logged below the grid rate, else None.

    Below :data:`RATE_TOLERANCE` x the grid rate the aligned body rate is
    mostly linear interpolation between logged samples: the Savitzky-Golay
    derivative then differentiates the interpolant (piecewise constant slopes),
    the window spans fewer real samples than it says, and the residual's noise
    level is not the one the defaults were chosen for (docs/fit.md).
    """
    rate = body_rate_rate(flight, vehicle)
    grid = flight.rate
    if rate is None or rate >= RATE_TOLERANCE * grid:
        return None
    return (
        f"body rate logged at {rate:.1f} Hz (median step), below the {grid:g} Hz grid "
        f"(controller.rate_hz): {1 - rate / grid:.0%} of the grid samples are interpolated "
        "between logged samples and the Savitzky-Golay derivative sees the interpolation; "
        f"set controller.rate_hz to at most {math.floor(rate):d} Hz in the vehicle YAML to "
        "fit at the log's own rate"
    )


def estimate_effects(samples: Sequence[ResidualSamples], effects: Sequence[str]) -> EffectFit:
    """Least squares of the residual on the stacked held regressors of ``effects``.

    ``residual ~= sum_e X_e theta_e`` over every axis and sample (3n equations);
    covariance ``s^2 (X^T X)^+`` with ``s^2`` the residual variance (the samples
    are autocorrelated by the filter, so these standard errors are optimistic).
    """
    residual = np.concatenate([s.residual for s in samples])
    n = residual.shape[0]
    sizes = [get_effect(name).n_theta for name in effects]
    p = sum(sizes)
    if p == 0:
        std = residual.std(axis=0)
        return EffectFit(np.empty(0), np.empty((0, 0)), {}, std, np.zeros(3))
    x = np.concatenate(
        [np.concatenate([s.regressors[name] for s in samples]) for name in effects], axis=-1
    )  # (n, 3, p)
    a = x.reshape(3 * n, p)
    b = residual.reshape(3 * n)
    theta, *_ = np.linalg.lstsq(a, b, rcond=None)
    fitted = (x @ theta).reshape(n, 3)
    rest = residual - fitted
    dof = max(3 * n - p, 1)
    s2 = float(np.sum(rest**2) / dof)
    cov = s2 * np.linalg.pinv(a.T @ a)
    estimates: dict[str, EffectEstimate] = {}
    i = 0
    for name, size in zip(effects, sizes, strict=True):
        effect = get_effect(name)
        params = effect.to_parameters(theta[i : i + size], cov[i : i + size, i : i + size])
        estimates[name] = EffectEstimate(
            name, {k: v for k, (v, _) in params.items()}, {k: se for k, (_, se) in params.items()}
        )
        i += size
    var = residual.var(axis=0)
    explained = np.where(var > 0, 1.0 - rest.var(axis=0) / np.where(var > 0, var, 1.0), 0.0)
    return EffectFit(theta, cov, estimates, rest.std(axis=0), explained)


def _sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances (n, m) between rows of a (n, d) and b (m, d)."""
    d2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.maximum(d2, 0.0)


def _kmedoids(x: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Indices (k,) of k-medoids of x (n, d), squared Euclidean (:mod:`omavctl.learn.kmedoids`)."""
    from omavctl.learn.kmedoids import kmedoids

    return kmedoids(x, k, seed)


def _cost(x: np.ndarray, medoids: np.ndarray, chunk: int = 20000) -> float:
    """Sum over samples of the squared distance to the nearest medoid, in chunks (n x k)."""
    total = 0.0
    for start in range(0, x.shape[0], chunk):
        total += float(_sq_dist(x[start : start + chunk], medoids).min(axis=1).sum())
    return total


def select_points(x: np.ndarray, k: int, seed: int = 0) -> tuple[np.ndarray, str]:
    """Pick k training points among the rows of x (n, d) (normalised inputs) by k-medoids.

    Squared Euclidean distance (as in the paper); the library call is
    :func:`omavctl.learn.kmedoids.kmedoids` (eager-swap PAM, seeded random start).
    Above :data:`KMEDOIDS_MAX_DIRECT` samples no n x n matrix is built: like
    CLARA, :data:`KMEDOIDS_DRAWS` seeded subsamples of
    ``max(KMEDOIDS_SUBSAMPLE, 4 k)`` samples (each holding the best medoids so
    far) are clustered and the medoids with the lowest cost over all samples
    kept. Returns sorted indices (k,) and a description of the method.
    """
    n = x.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"cannot select {k} points from {n} samples")
    if k == n:
        return np.arange(n), "all samples"
    if n <= KMEDOIDS_MAX_DIRECT:
        return np.sort(_kmedoids(x, k, seed)), f"k-medoids on all {n} samples"
    size = min(n, max(KMEDOIDS_SUBSAMPLE, 4 * k))
    rng = np.random.default_rng(seed)
    best: np.ndarray | None = None
    best_cost = np.inf
    for _ in range(KMEDOIDS_DRAWS):
        if best is None:
            sub = np.sort(rng.choice(n, size=size, replace=False))
        else:
            rest = np.setdiff1d(np.arange(n), best)
            sub = np.sort(np.concatenate([best, rng.choice(rest, size=size - k, replace=False)]))
        medoids = sub[_kmedoids(x[sub], k, seed)]
        cost = _cost(x, x[medoids])
        if cost < best_cost:
            best, best_cost = medoids, cost
    assert best is not None
    return np.sort(best), (
        f"k-medoids on {KMEDOIDS_DRAWS} seeded subsamples of {size} of {n} samples"
    )


#: Hyperparameter bounds, for inputs normalised to unit std and targets scaled to unit std.
_SIGNAL_BOUNDS = (1e-4, 1e3)
_LENGTH_BOUNDS = (1e-2, 5.0)
_NOISE_BOUNDS = (1e-6, 10.0)


def fit_hyperparameters(
    x: np.ndarray,
    y: np.ndarray,
    seed: int = 0,
    restarts: int = DEFAULT_RESTARTS,
    input_names: Sequence[str] | None = None,
    noise_floor: np.ndarray | None = None,
) -> tuple[list[AxisFit], np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Maximise the marginal likelihood of one GP per axis.

    x (n, d) normalised inputs; y (n, 3) targets (rad/s^2). scikit-learn's
    ``GaussianProcessRegressor`` with ``ConstantKernel * RBF(ones(d)) +
    WhiteKernel`` on targets centred and scaled per axis, ``restarts`` extra
    optimiser starts, ``random_state=seed``. ``noise_floor`` (3,) rad/s^2: the
    noise std is bounded below by it (the measurement's own noise: a GP must
    not explain noise as signal). Returns the per-axis fits, the target means
    (3,), signal variances (3,), length scales (3, d) and notes (hyperparameters
    at a bound).
    """
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    d = x.shape[1]
    input_names = list(input_names) if input_names is not None else [str(j) for j in range(d)]
    axes: list[AxisFit] = []
    means, sv, ls = np.zeros(3), np.zeros(3), np.ones((3, d))
    notes: list[str] = []
    for a, name in enumerate("xyz"):
        mu = float(y[:, a].mean())
        std = float(y[:, a].std())
        if not std > 1e-12:
            std = 1.0
        yn = (y[:, a] - mu) / std
        noise_bounds = _NOISE_BOUNDS
        if noise_floor is not None and np.isfinite(noise_floor[a]) and noise_floor[a] > 0:
            low = min(float(noise_floor[a] / std) ** 2, 0.5 * _NOISE_BOUNDS[1])
            noise_bounds = (max(low, _NOISE_BOUNDS[0]), _NOISE_BOUNDS[1])
        kernel = ConstantKernel(1.0, _SIGNAL_BOUNDS) * RBF(
            np.ones(d), _LENGTH_BOUNDS
        ) + WhiteKernel(max(0.1, 2 * noise_bounds[0]), noise_bounds)
        gpr = GaussianProcessRegressor(
            kernel=kernel, alpha=1e-10, n_restarts_optimizer=restarts, random_state=seed
        )
        with warnings.catch_warnings():
            # hyperparameters at a bound are reported below, in words
            warnings.simplefilter("ignore", ConvergenceWarning)
            gpr.fit(x, yn)
        k = gpr.kernel_
        c = float(k.k1.k1.constant_value)
        length = np.atleast_1d(np.asarray(k.k1.k2.length_scale, dtype=float))
        noise = float(k.k2.noise_level) + 1e-10
        flat = [input_names[j] for j in np.flatnonzero(length >= 0.99 * _LENGTH_BOUNDS[1])]
        if flat:
            notes.append(
                f"axis {name}: the residual varies little with {', '.join(flat)} "
                f"(length scale at its upper bound, {_LENGTH_BOUNDS[1]:g} input stds)"
            )
        sharp = [input_names[j] for j in np.flatnonzero(length <= 1.01 * _LENGTH_BOUNDS[0])]
        if sharp:
            notes.append(
                f"axis {name}: length scale of {', '.join(sharp)} at its lower bound: "
                "the GP may be fitting noise"
            )
        if k.k2.noise_level <= 1.01 * noise_bounds[0] and noise_bounds[0] == _NOISE_BOUNDS[0]:
            notes.append(
                f"axis {name}: noise variance at its lower bound: the GP interpolates its "
                "training points"
            )
        means[a], sv[a], ls[a] = mu, c * std**2, length
        axes.append(
            AxisFit(
                signal_std=float(np.sqrt(c) * std),
                noise_std=float(np.sqrt(noise) * std),
                length_scales=length,
                log_marginal_likelihood=float(gpr.log_marginal_likelihood_value_),
            )
        )
    return axes, means, sv, ls, notes


#: Prior standard deviation of each effect's estimation parameters in the joint
#: fit (each effect's ``prior_std``): wide for what is physically plausible, so
#: that a parameter the data do not excite stays near 0 instead of absorbing
#: whatever correlates with it.
PRIOR_STD = {name: effect.prior_std for name, effect in EFFECTS.items()}
#: With a normalised torque command, the joint-fit prior of ``inertia_error``'s
#: theta (= gain - 1) per axis is centred on the first-pass least-squares value
#: (gain_LS - 1) with std ``GAIN_PRIOR_FACTOR x |gain_LS|``: scaled to the gain,
#: so gains of 1e-3 .. 1e3 are held alike (``PRIOR_STD`` = 0.5 around gain 1
#: would pull a gain of 100 to a few and is meaningless for a gain of 1e-3).
#: The centre matters because the gain's regressor ``I^-1 tau`` is a GP input:
#: where the GP could explain the same linear trend the data do not decide
#: between them, and the prior keeps the least-squares (physical) gain instead
#: of an arbitrary split; where they do decide, a factor 3 lets the data move
#: the gain freely.
GAIN_PRIOR_FACTOR = 3.0
_GAIN_PRIOR_FLOOR = 1e-9


def effect_prior(
    names: Sequence[str], first_pass: EffectFit, vehicle: Vehicle
) -> tuple[np.ndarray, np.ndarray]:
    """Prior mean (p,) and std (p,) of the stacked theta of ``names`` in the joint fit.

    Mean 0 and std :data:`PRIOR_STD` per effect; for ``inertia_error`` of a
    vehicle with a normalised torque command, per axis mean ``theta_LS`` (the
    first-pass least-squares estimate in ``first_pass``) and std
    ``GAIN_PRIOR_FACTOR |1 + theta_LS|`` (:data:`GAIN_PRIOR_FACTOR`).
    """
    means, stds = [], []
    for name in names:
        std = np.full(get_effect(name).n_theta, get_effect(name).prior_std)
        mean = np.zeros_like(std)
        if name == GAIN_EFFECT and vehicle.torque_normalised and name in first_pass.estimates:
            theta = get_effect(name).to_theta(first_pass.estimates[name].values)
            mean = np.where(np.isfinite(theta), theta, 0.0)
            std = np.maximum(GAIN_PRIOR_FACTOR * np.abs(1.0 + mean), _GAIN_PRIOR_FLOOR)
        means.append(mean)
        stds.append(std)
    if not names:
        return np.empty(0), np.empty(0)
    return np.concatenate(means), np.concatenate(stds)


def torque_gain(estimate: EffectEstimate) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis gain (3,) of a normalised torque command and its standard error (3,)
    from the ``inertia_error`` estimate: ``gain = 1 / scale`` (= 1 + theta).

    ``torque = gain x command`` in N m *with the vehicle's assumed inertia*: what
    the log determines is ``gain / I`` (rad/s^2 per command unit).
    """
    scale = np.asarray(estimate.values["scale"], float)
    se = np.asarray(estimate.stderr["scale"], float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return 1.0 / scale, se / scale**2


#: Effects whose regressor is a lag of the commanded wrench: with a normalised
#: torque their time constant is estimated times the command gain.
_COMMAND_LAGS = ("servo_lag", "motor_lag")


def effect_unit(name: str, unit: str, command_units: Mapping[str, str]) -> str:
    """The unit of a parameter of effect ``name`` for display, given the command units.

    With a normalised torque command, ``N m`` becomes ``[torque unit]`` (as in
    the report); ``com_offset``'s ``r`` (a torque per force) becomes
    ``[torque unit]/N``, ``N m/[force unit]`` or ``[torque unit]/[force unit]``;
    the lags of effects that act through the commanded wrench (``servo_lag``,
    ``motor_lag``) come out multiplied by the unknown gain: ``s (x torque gain)``.
    """
    torque = command_units.get("torque") == NORMALISED
    force = command_units.get("force") == NORMALISED
    if name == "com_offset" and unit == "m" and (torque or force):
        num = "[torque unit]" if torque else "N m"
        return f"{num}/{'[force unit]' if force else 'N'}"
    if name in _COMMAND_LAGS and torque:
        return f"{unit} (x torque gain)"
    if torque:
        return unit.replace("N m", "[torque unit]")
    return unit


def joint_effects(
    z: np.ndarray,
    y: np.ndarray,
    x: np.ndarray,
    mean: np.ndarray,
    signal_variance: np.ndarray,
    length_scales: np.ndarray,
    noise_variance: np.ndarray,
    prior_std: np.ndarray,
    prior_mean: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Effect parameters as explicit basis functions of the per-axis GPs.

    z (n, d) normalised training inputs; y (n, 3) residual at them (effects not
    removed); x (n, 3, p) effect regressors there; GP hyperparameters per axis.
    With ``K_a = s_a^2 k(z, z) + sigma_a^2 I`` and a Gaussian prior N(0, diag
    prior_std^2) on theta::

        theta = (sum_a X_a^T K_a^-1 X_a + B^-1)^-1 sum_a X_a^T K_a^-1 (y_a - c_a)

    which credits to the effects only what the GP (a smooth function of the
    inputs) would not explain as well: the effects no longer absorb input-
    dependent residuals that merely correlate with their regressors. A prior
    mean ``m`` (p,) (default 0) adds ``B^-1 m`` to the right-hand sum. Returns
    theta (p,) and its posterior covariance (p, p).
    """
    from scipy.linalg import cho_solve

    p = x.shape[2]
    a_mat = np.diag(1.0 / prior_std**2)
    b_vec = np.zeros(p) if prior_mean is None else prior_mean / prior_std**2
    for a in range(3):
        c = cholesky_of_k(z, signal_variance[a], length_scales[a], noise_variance[a])
        a_mat += x[:, a, :].T @ cho_solve(c, x[:, a, :])
        b_vec += x[:, a, :].T @ cho_solve(c, y[:, a] - mean[a])
    cov = np.linalg.inv(a_mat)
    return cov @ b_vec, cov


def _estimates(
    names: Sequence[str], theta: np.ndarray, cov: np.ndarray, old: EffectFit
) -> EffectFit:
    """An :class:`EffectFit` with new parameters (explained variances kept from ``old``)."""
    estimates: dict[str, EffectEstimate] = {}
    i = 0
    for name in names:
        effect = get_effect(name)
        size = effect.n_theta
        params = effect.to_parameters(theta[i : i + size], cov[i : i + size, i : i + size])
        estimates[name] = EffectEstimate(
            name, {k: v for k, (v, _) in params.items()}, {k: se for k, (_, se) in params.items()}
        )
        i += size
    return EffectFit(theta, cov, estimates, old.residual_std, old.explained)


def sha256_of(path: Path) -> str:
    """sha256 of a file, or of a directory's files (relative names and contents, sorted)."""
    h = hashlib.sha256()
    if path.is_dir():
        for f in sorted(p for p in path.rglob("*") if p.is_file()):
            h.update(str(f.relative_to(path)).encode())
            h.update(b"\0")
            h.update(hashlib.sha256(f.read_bytes()).digest())
        return h.hexdigest()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _source(item: str | Path | FlightLog) -> dict[str, Any]:
    path = item.path if isinstance(item, FlightLog) else Path(item)
    digest = sha256_of(path) if path.exists() else None
    # the path as given and absolute: evaluate prints the fit command that refits
    # with another effect from the same logs, with paths valid where it runs
    return {
        "name": path.name,
        "path": str(path),
        "abspath": str(path.resolve()),
        "sha256": digest,
    }


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

    def report(stage: str, fraction: float) -> None:
        if progress is not None:
            progress(stage, fraction)

    vehicle = vehicle if vehicle is not None else default_vehicle()
    if not logs:
        raise ConfigError("no logs given")
    if features not in FEATURES:
        raise ConfigError(f"unknown --features '{features}' (known: {', '.join(FEATURES)})")
    if points < 1:
        raise ConfigError(f"--points must be at least 1, got {points}")
    if restarts < 0:
        raise ConfigError(f"--restarts must be >= 0, got {restarts}")
    names = list(vehicle.effects if effects is None else effects)
    for name in names:
        get_effect(name)
    if len(set(names)) != len(names):
        raise ConfigError(f"effect named twice in --effects: {', '.join(names)}")
    added: tuple[str, ...] = ()
    if vehicle.torque_normalised and GAIN_EFFECT not in names:
        names.append(GAIN_EFFECT)
        added = (GAIN_EFFECT,)
    sg = SavitzkyGolay(sg_window, sg_order, 1.0 / vehicle.gains.rate_hz)

    prior_model: ResidualGP | None = None
    prior_source: dict[str, Any] | None = None
    if prior is not None:
        if isinstance(prior, ResidualGP):
            prior_model = prior
            prior_source = {"name": "<in memory>", "sha256": None}
        else:
            prior_model = load_model(prior)
            prior_source = _source(prior)
        ppath = None if isinstance(prior, ResidualGP) else prior
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

    # 1-2. read, align, differentiate, residual
    report("reading logs", 0.0)
    t0 = time.perf_counter()
    flights: list[FlightLog] = []
    samples: list[ResidualSamples] = []
    summaries: list[LogSummary] = []
    for i, item in enumerate(logs):
        flight = read_flights([item], vehicle, time_window)[0]
        flights.append(flight)
        # every registered effect's regressor: the fitted ones are estimated, all are
        # stored at the training points for evaluate's diagnosis
        s = residual_samples(flight, vehicle, sg, tuple(EFFECTS))
        loss = out_of_control(s.t, s.omega, s.omega_dot, vehicle, s.residual)
        if loss.any:
            s = s.select(~loss.mask)
            flight = replace(
                flight,
                notes=[
                    *flight.notes,
                    *(
                        f"{a:.2f}-{b:.2f} s out of control ({why}): not used"
                        for a, b, why in loss.spans
                    ),
                ],
            )
        if s.n == 0:
            longest = max((b - a for a, b in flight.segments), default=0)
            raise LogError(
                f"no usable samples: --sg-window {sg.window} needs a valid segment of at "
                f"least {sg.window} samples, the longest has {longest}",
                flight.path,
            )
        arrays = [s.residual, s.u, s.omega, *s.regressors.values()]
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise LogError("non-finite values in the residual or the wrench command", flight.path)
        samples.append(s)
        summaries.append(
            LogSummary(
                flight.path,
                s.total,
                s.n,
                s.in_gaps,
                s.edge_dropped,
                s.short_dropped,
                list(flight.notes),
            )
        )
        report("reading logs", (i + 1) / len(logs))
    timings["read"] = time.perf_counter() - t0
    n_total = sum(s.n for s in samples)
    if n_total < points:
        where = flights[0].path if len(flights) == 1 else None
        raise LogError(
            f"too few samples for --points {points}: {n_total} usable "
            f"sample{'s' if n_total != 1 else ''} after dropping gaps and filter edges",
            where,
        )

    # 3. effects: those nonlinear in their parameter by an exact 1-D search, then
    # the linear ones by least squares on what remains
    t0 = time.perf_counter()
    report("estimating effects", 0.0)
    all_names = list(names)
    original = samples
    samples, found = _search_step(samples, names)
    names = [nm for nm in names if nm not in found]
    eff = estimate_effects(samples, names)
    residual = np.concatenate([s.residual for s in samples])
    targets_all = residual.copy()
    if names:
        x_eff = np.concatenate(
            [np.concatenate([s.regressors[nm] for s in samples]) for nm in names], axis=-1
        )
        targets_all -= x_eff @ eff.theta
    timings["effects"] = time.perf_counter() - t0
    first_pass = eff
    notes = _effect_notes(eff, vehicle.torque_normalised)

    # 4. training points
    t0 = time.perf_counter()
    report("selecting training points (k-medoids)", 0.0)
    inputs_all = np.concatenate([s.inputs(features) for s in samples])
    mean_all, scale_all = _normalisation(inputs_all)
    idx, kmethod = select_points((inputs_all - mean_all) / scale_all, points, seed)
    train_x = inputs_all[idx]
    train_y = targets_all[idx]
    train_reg = {nm: np.concatenate([s.regressors[nm] for s in samples])[idx] for nm in EFFECTS}
    n_prior = 0
    if prior_model is not None:
        n_prior = prior_model.n_train
        train_x = np.concatenate([prior_model.inputs, train_x])
        train_y = np.concatenate([prior_model.targets, train_y])
        train_reg = {
            nm: np.concatenate([prior_model.train_regressors[nm], reg])
            for nm, reg in train_reg.items()
            if nm in prior_model.train_regressors
        }
    timings["kmedoids"] = time.perf_counter() - t0

    # 5. GP hyperparameters; lags and delays once more jointly with the GP
    # (generalised least squares at the training points, linear effects profiled),
    # twice: the first hyperparameters saw the residual of the first, biased search
    t0 = time.perf_counter()
    report("fitting GP hyperparameters", 0.0)
    in_mean, in_scale = _normalisation(train_x)
    floor = measurement_noise_std(samples, sg)
    refine = bool(found) and prior_model is None
    p_mean, p_std = effect_prior(names, first_pass, vehicle)
    x_tr = (
        np.concatenate([train_reg[nm] for nm in names], axis=-1)
        if names
        else np.zeros((train_x.shape[0], 3, 0))
    )

    def hyperparameters(targets: np.ndarray) -> tuple[Any, ...]:
        # one BLAS thread: the matrices are small (points x points) and threads
        # fighting over 2 cores made fit time swing 2x (profiled)
        with threadpool_limits(1):
            return fit_hyperparameters(
                (train_x - in_mean) / in_scale,
                targets,
                seed=seed,
                restarts=restarts,
                input_names=feature_names(features),
                noise_floor=floor,
            )

    axes, t_mean, sv, ls, gp_notes = hyperparameters(train_y)
    for gls_pass in range(2 if refine else 0):
        found = gls_search(
            original,
            idx,
            found,
            x_tr,
            (p_mean, p_std),
            (train_x - in_mean) / in_scale,
            (t_mean, sv, ls, np.array([a.noise_std**2 for a in axes])),
        )
        samples = _without_searched(original, found)
        residual = np.concatenate([s.residual for s in samples])
        targets_all = residual.copy()
        if names:
            targets_all -= x_eff @ first_pass.theta
        train_y = targets_all[idx]
        if gls_pass == 0:
            axes, t_mean, sv, ls, gp_notes = hyperparameters(train_y)
    timings["gp"] = time.perf_counter() - t0

    # 6. effects jointly with the GP (explicit basis functions, R&W 2.7)
    if names:
        theta_used = np.tile(eff.theta, (train_x.shape[0], 1))
        if prior_model is not None:
            theta_used[:n_prior] = np.concatenate(
                [get_effect(nm).to_theta(prior_model.effects[nm].values) for nm in names]
            )
        x_tr = np.concatenate([train_reg[nm] for nm in names], axis=-1)
        y_raw = train_y + np.einsum("nap,np->na", x_tr, theta_used)
        p_mean, p_std = effect_prior(names, first_pass, vehicle)
        theta, cov = joint_effects(
            (train_x - in_mean) / in_scale,
            y_raw,
            x_tr,
            t_mean,
            sv,
            ls,
            np.array([a.noise_std**2 for a in axes]),
            p_std,
            p_mean,
        )
        train_y = y_raw - x_tr @ theta
        eff = _estimates(names, theta, cov, eff)
        notes = _effect_notes(eff, vehicle.torque_normalised)
        notes.append(
            "effects estimated jointly with the GP (generalised least squares at the "
            "training points, hyperparameters from the first pass)"
        )

    # 7. blocked cross-validation: switch the GP off where it does not help on
    # held-out time blocks, widen its band to cover them
    nv = np.array([a.noise_std**2 for a in axes])
    if names:
        x_all = np.concatenate(
            [np.concatenate([s.regressors[nm] for s in samples]) for nm in names], axis=-1
        )
        targets_all = residual - x_all @ eff.theta
    t_mean, sv, nv, latent_scale, cv_notes = _validate(
        samples,
        inputs_all,
        targets_all,
        idx,
        train_x[:n_prior],
        train_y[:n_prior],
        (in_mean, in_scale),
        (t_mean, sv, ls, nv),
        axes,
    )
    gp_notes += cv_notes

    gain: np.ndarray | None = None
    gain_se: np.ndarray | None = None
    if vehicle.torque_normalised and GAIN_EFFECT in eff.estimates:
        gain, gain_se = torque_gain(eff.estimates[GAIN_EFFECT])
        notes = [*_unit_notes(vehicle, added, gain, gain_se), *notes]
    elif vehicle.force_normalised:
        notes = [*_unit_notes(vehicle, added, None, None), *notes]

    provenance = {
        "omavctl_version": __version__,
        "sources": [_source(item) for item in logs],
        "prior": prior_source,
        "grid_rate_hz": vehicle.gains.rate_hz,
        "savitzky_golay": {
            "window": sg.window,
            "order": sg.order,
            "command_alignment": "hold kernel matching the derivative (docs/fit.md)",
        },
        "kmedoids": {
            "points": points,
            "metric": "sqeuclidean",
            "method": "eager-swap PAM, seeded random start (omavctl.learn.kmedoids)",
            "selection": kmethod,
            "max_direct": KMEDOIDS_MAX_DIRECT,
        },
        "gp": {
            "kernel": "ConstantKernel * RBF(ARD) + WhiteKernel on normalised inputs",
            "restarts": restarts,
            "log_marginal_likelihood": [a.log_marginal_likelihood for a in axes],
            "noise_floor": [float(f) for f in floor],
            "validation": {
                "method": f"blocked cross-validation, {BLOCK_SECONDS:g} s blocks in {FOLDS} "
                "folds; GP off where its held-out MSE is not below "
                f"{KEEP_RATIO:g} x physics-only; std widened to {TARGET_COVERAGE:.0%} "
                "held-out 2-sigma coverage",
                "gp_on": [a.gp_on for a in axes],
                "rmse_gp": [a.cv_rmse_gp for a in axes],
                "rmse_physics": [a.cv_rmse_physics for a in axes],
                "coverage": [a.cv_coverage for a in axes],
                "std_factor": [a.std_factor for a in axes],
                "latent_factor": [a.latent_factor for a in axes],
            },
        },
        "effects_explained_variance": [float(v) for v in eff.explained],
        "samples": n_total,
        "seed": seed,
        "time_window": None if time_window is None else list(time_window),
        # evaluate's suggested refit command passes it as --vehicle
        "vehicle_path": vehicle.source if Path(vehicle.source).is_file() else None,
        "vehicle_abspath": (
            str(Path(vehicle.source).resolve()) if Path(vehicle.source).is_file() else None
        ),
        "command_units": dict(vehicle.command_units),
    }
    if gain is not None and gain_se is not None:
        ls_gain, ls_se = torque_gain(first_pass.estimates[GAIN_EFFECT])
        provenance["torque_gain"] = {
            "effect": GAIN_EFFECT,
            "values": [float(g) for g in gain],
            "stderr": [float(g) for g in gain_se],
            "first_pass_least_squares": [float(g) for g in ls_gain],
            "first_pass_stderr": [float(g) for g in ls_se],
            "prior": f"theta = gain - 1 ~ N(gain_LS - 1, ({GAIN_PRIOR_FACTOR:g} gain_LS)^2) "
            "per axis, gain_LS the first-pass least-squares gain",
        }
    model = ResidualGP(
        vehicle=vehicle,
        features=features,
        input_names=feature_names(features),
        inputs=train_x,
        targets=train_y,
        input_mean=in_mean,
        input_scale=in_scale,
        target_mean=t_mean,
        signal_variance=sv,
        length_scales=ls,
        noise_variance=nv,
        latent_scale=latent_scale,
        effects=_merged(all_names, eff.estimates, found),
        provenance=provenance,
        train_regressors=train_reg,
    )

    # training fit on every new sample
    t0 = time.perf_counter()
    residual = np.concatenate([s.residual for s in original])
    pred = np.concatenate([model.predict_samples(s, variance=False)[0] for s in original])
    err = residual - pred
    var = residual.var(axis=0)
    for a, axis in enumerate(axes):
        axis.rmse = float(np.sqrt(np.mean(err[:, a] ** 2)))
        axis.rmse_nominal = float(np.sqrt(np.mean(residual[:, a] ** 2)))
        axis.r2 = float(1.0 - np.mean(err[:, a] ** 2) / var[a]) if var[a] > 0 else float("nan")
    timings["evaluate"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    report("done", 1.0)

    summary = FitSummary(
        logs=summaries,
        samples=n_total,
        points_new=points,
        points_prior=n_prior,
        features=features,
        input_names=feature_names(features),
        sg_window=sg.window,
        sg_order=sg.order,
        kmedoids=kmethod,
        axes=axes,
        effects=_merged(all_names, eff.estimates, found),
        timings=timings,
        notes=_search_notes(found) + notes + gp_notes,
        command_units=dict(vehicle.command_units),
        added_effects=added,
        torque_gain=gain,
        torque_gain_stderr=gain_se,
    )
    return FitResult(model, summary)


def _unit_notes(
    vehicle: Vehicle,
    added: Sequence[str],
    gain: np.ndarray | None,
    gain_se: np.ndarray | None,
) -> list[str]:
    """What the summary says about normalised commands and the fitted gain."""
    notes = []
    if added:
        notes.append(
            f"torque command is normalised (command_units.torque): {', '.join(added)} added "
            "to estimate its per-axis gain (torque = gain x command)"
        )
    if gain is not None and gain_se is not None:
        diag = np.diag(vehicle.inertia)
        shown = ", ".join(
            f"{a} {g:.4g} ± {e:.2g} ({g / i:.4g} rad/s^2 per unit)"
            for a, g, e, i in zip("xyz", gain, gain_se, diag, strict=True)
        )
        notes.append(
            f"torque command gain (N m per command unit with the assumed inertia; the log "
            f"determines only gain / inertia): {shown}"
        )
        bad = [a for a, g in zip("xyz", gain, strict=True) if not (np.isfinite(g) and g > 0)]
        if bad:
            notes.append(
                f"torque command gain not positive on axis {', '.join(bad)}: check the sign "
                "of the torque columns and the frame (FLU/FRD) in the vehicle YAML"
            )
        notes.append(
            "torque units are unknown: parameters in N m are shown in [torque unit] "
            "(relative to the assumed inertia)"
        )
    if vehicle.force_normalised:
        notes.append(
            "force command is normalised (command_units.force): the GP inputs f/m are a "
            "scaled thrust feature, not an acceleration in m/s^2"
        )
    return notes


def _effect_notes(eff: EffectFit, torque_normalised: bool = False) -> list[str]:
    """Warnings about effect parameters the logs do not determine.

    With ``torque_normalised`` ``inertia_error`` is the command gain: the
    warning is about a gain within two standard errors of zero.
    """
    notes = []
    for name, est in eff.estimates.items():
        effect = get_effect(name)
        if name == GAIN_EFFECT and torque_normalised:
            gain, se = torque_gain(est)
            axes = [a for a, g, e in zip("xyz", gain, se, strict=True) if not abs(g) >= 2 * e]
            if axes:
                notes.append(
                    f"torque command gain on axis {', '.join(axes)} within 2 standard errors "
                    "of zero: the logs barely excite it (or the GP explains the same trend)"
                )
            continue
        if not effect.identifiable:
            notes.append(
                f"{name} is not identifiable from angular accelerations (see its docs): "
                "its estimate is unreliable"
            )
            continue
        for p in effect.parameters:
            weak = np.flatnonzero(np.abs(est.values[p.name]) < 2.0 * est.stderr[p.name])
            if weak.size:
                which = ", ".join(f"{p.name}[{i}]" for i in weak)
                notes.append(
                    f"{name}: {which} within 2 standard errors of zero: the logs barely excite "
                    "it or the effect is absent"
                )
    return notes


def _search_step(
    samples: list[ResidualSamples], names: Sequence[str]
) -> tuple[list[ResidualSamples], dict[str, SearchResult]]:
    """Estimate the effects of ``names`` that need a 1-D search (:mod:`omavctl.learn.effect_search`)
    and return the samples with their exact residual removed, and the estimates."""
    searched = [nm for nm in names if get_effect(nm).search is not None]
    if not searched:
        return samples, {}
    linear = [nm for nm in names if nm not in searched]
    found = search_effects(samples, searched, linear)
    return _without_searched(samples, found), found


def _without_searched(
    samples: Sequence[ResidualSamples], found: Mapping[str, SearchResult]
) -> list[ResidualSamples]:
    """The samples with the exact residual of every searched effect removed."""
    out = []
    for s in samples:
        rest = s.residual.copy()
        for nm, r in found.items():
            rest -= s.exact(nm, r.value)
        out.append(replace(s, residual=rest))
    return out


def _merged(
    names: Sequence[str], linear: Mapping[str, EffectEstimate], found: Mapping[str, SearchResult]
) -> dict[str, EffectEstimate]:
    """Every effect's estimate in the order of ``names``."""
    out: dict[str, EffectEstimate] = {}
    for nm in names:
        if nm in found:
            p = get_effect(nm).parameters[0].name
            r = found[nm]
            out[nm] = EffectEstimate(nm, {p: np.array([r.value])}, {p: np.array([r.stderr])})
        else:
            out[nm] = linear[nm]
    return out


def _search_notes(found: Mapping[str, SearchResult]) -> list[str]:
    """What the summary says about effects estimated by a 1-D search."""
    notes = []
    for r in found.values():
        p = get_effect(r.name).parameters[0]
        notes.append(
            f"{r.name}: {p.name} = {r.value * 1e3:.1f} ± {r.stderr * 1e3:.1f} ms "
            "(exact form, 1-D search jointly with the GP and the linear effects)"
        )
        if r.at_bound:
            lo, hi = get_effect(r.name).search  # type: ignore[misc]
            notes.append(
                f"{r.name}: {p.name} at the edge of its search interval "
                f"({lo * 1e3:g} to {hi * 1e3:g} ms): the logs do not determine it, or "
                "the effect is absent"
            )
    return notes


def measurement_noise_std(samples: Sequence[ResidualSamples], sg: SavitzkyGolay) -> np.ndarray:
    """Noise std (3,) rad/s^2 of the measured angular acceleration per axis.

    The body-rate white noise of each log (:attr:`ResidualSamples.rate_noise`,
    from second differences) through the derivative filter's noise gain, median
    over logs; NaN where no log tells.
    """
    rates = np.array([s.rate_noise for s in samples], dtype=float)
    if not np.isfinite(rates).any():
        return np.full(3, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN axis stays NaN
        return np.asarray(np.nanmedian(rates, axis=0) * sg.noise_gain, dtype=float)


def _validate(
    samples: Sequence[ResidualSamples],
    inputs_all: np.ndarray,
    targets_all: np.ndarray,
    idx: np.ndarray,
    prior_x: np.ndarray,
    prior_y: np.ndarray,
    norm: tuple[np.ndarray, np.ndarray],
    hyper: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    axes: list[AxisFit],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Blocked cross-validation (:func:`omavctl.learn.validation.cross_validate`) applied.

    Returns the target means, signal and noise variances after switching off
    the axes whose GP does not help (mean 0, signal variance 0, noise variance
    the residual's mean square) and calibrating the others; fills the
    validation fields of ``axes``; notes for the summary.
    """
    in_mean, in_scale = norm
    t_mean, sv, ls, nv = (np.array(h, dtype=float) for h in hyper)
    t = np.concatenate([s.t for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    fold = fold_of(t, log_id)
    notes: list[str] = []
    latent = np.ones(3)
    if np.unique(fold).size < 2:
        notes.append("too short for blocked cross-validation: the GP is kept as fitted")
        return t_mean, sv, nv, latent, notes
    verdicts = cross_validate(
        (inputs_all - in_mean) / in_scale,
        targets_all,
        fold,
        idx,
        (prior_x - in_mean) / in_scale,
        prior_y,
        t_mean,
        sv,
        ls,
        nv,
    )
    for a, (name, v) in enumerate(zip("xyz", verdicts, strict=True)):
        ax = axes[a]
        ax.gp_on, ax.std_factor, ax.cv_coverage = v.keep, v.std_factor, v.coverage
        ax.cv_rmse_gp, ax.cv_rmse_physics = math.sqrt(v.mse_gp), math.sqrt(v.mse_physics)
        latent[a] = v.latent_factor**2
        if not v.keep:
            t_mean[a], sv[a], nv[a] = 0.0, 0.0, v.off_variance * v.std_factor**2
            notes.append(
                f"axis {name}: GP switched off: on held-out time blocks it predicts "
                f"{ax.cv_rmse_gp:.3g} rad/s^2 RMS error against {ax.cv_rmse_physics:.3g} for "
                "physics only (mean 0, variance the residual's)"
            )
        else:
            sv[a] *= v.std_factor**2
            nv[a] *= v.std_factor**2
        ax.signal_std, ax.noise_std = math.sqrt(sv[a]), math.sqrt(nv[a])
        ax.latent_factor = v.latent_factor
        if v.std_factor > 1.0:
            notes.append(
                f"axis {name}: predictive std widened x{v.std_factor:.2f} to cover "
                f"{TARGET_COVERAGE:.0%} of held-out time blocks (was {v.coverage:.0%})"
            )
        if v.latent_factor > 1.0:
            notes.append(
                f"axis {name}: extrapolation uncertainty widened x{v.latent_factor:.2f} "
                "(held-out regions of input space)"
            )
    return t_mean, sv, nv, latent, notes


def _normalisation(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column mean (d,) and scale (d,) of x (n, d); a constant column gets scale 1."""
    mean = x.mean(axis=0)
    std = x.std(axis=0)
    scale = np.where(std > 1e-9 * np.maximum(1.0, np.abs(mean)), std, 1.0)
    return mean, scale
