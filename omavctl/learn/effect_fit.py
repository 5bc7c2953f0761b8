"""Effect estimation for ``fit``: least squares, the joint fit with the GP, 1-D searches.

* :func:`estimate_effects`: ordinary least squares of the residual on the
  stacked held regressors of the linear effects (the first pass).
* :func:`search_step`: effects nonlinear in their parameter (lags, delay) by an
  exact 1-D search (:mod:`omavctl.learn.effect_search`), removed from the samples.
* :func:`joint_effects`: the effects as explicit basis functions of the per-axis
  GPs (generalised least squares at the training points), with the prior of
  :func:`effect_prior`.

A vehicle whose torque command is normalised always gets :data:`GAIN_EFFECT`:
its ``scale`` is the inverse of the per-axis command gain (:func:`torque_gain`)
and its joint-fit prior is centred on and scaled to the least-squares gain.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from omavctl.base.errors import LogError
from omavctl.learn.effect_search import SearchResult, search_effects
from omavctl.learn.estimate import GAIN_EFFECT, GAIN_PRIOR_FACTOR
from omavctl.learn.intervals import hac_covariance, segment_ids
from omavctl.learn.model import EffectEstimate
from omavctl.learn.physical import TORQUE_EFFECTS, PhysicalMap, physical_map, to_physical
from omavctl.learn.signal import ResidualSamples
from omavctl.learn.spread import spread_covariance
from omavctl.learn.validation import cholesky_of_k
from omavctl.physics.effects import EFFECTS, get_effect
from omavctl.vehicle import Vehicle

__all__ = [
    "GAIN_EFFECT",
    "GAIN_PRIOR_FACTOR",
    "PRIOR_STD",
    "EffectFit",
    "check_available",
    "effect_prior",
    "estimate_effects",
    "honest_covariance",
    "joint_effects",
    "merged_estimates",
    "refit_estimates",
    "search_step",
    "torque_gain",
    "without_searched",
]


@dataclass
class EffectFit:
    """Least-squares estimate of the stacked effect parameters.

    theta (p,), cov (p, p) (HAC: autocorrelated residuals); estimates by effect
    name; residual_std (3,) per axis after subtracting the effects; explained (3,)
    fraction of residual variance the effects explain per axis; cov_white (p, p)
    the white-residual covariance ``s^2 (A^T A)^+`` (None when not computed);
    physical: how the torque effects' parameters are put in physical units beside
    an inertia scale (:mod:`omavctl.learn.physical`; None: they already are).
    ``theta`` and ``cov`` stay the additive model's, which the model predicts with.
    cov_spread (p, p): the systematic covariance of the rotors' thrust spread
    (:func:`omavctl.learn.spread.spread_covariance`; None: not computed), reported in
    the estimates' intervals, never in what the model predicts with.
    """

    theta: np.ndarray
    cov: np.ndarray
    estimates: dict[str, EffectEstimate]
    residual_std: np.ndarray
    explained: np.ndarray
    cov_white: np.ndarray | None = None
    physical: PhysicalMap | None = None
    cov_spread: np.ndarray | None = None

    @property
    def inflation(self) -> np.ndarray:
        """Variance inflation (p,) of the autocorrelated residuals: diag(cov) over
        diag(cov_white), at least 1 (ones without cov_white)."""
        if self.cov_white is None:
            return np.ones(self.theta.size)
        white = np.diag(self.cov_white)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(white > 0, np.diag(self.cov) / white, 1.0)
        return np.maximum(np.nan_to_num(ratio, nan=1.0, posinf=1.0), 1.0)


def check_available(samples: Sequence[ResidualSamples], effects: Sequence[str]) -> None:
    """Refuse effects a log lacks the signals for (a motor-level effect on a log whose
    wrench was not mixed from motor outputs, ``battery_sag`` without a voltage).

    Raises:
        LogError: one line naming the log, the effect and what it needs.
    """
    for s in samples:
        for ctx, _ in s.contexts[:1]:
            for name in effects:
                why = get_effect(name).unavailable(ctx)
                if why is not None:
                    raise LogError(why, s.path)


def estimate_effects(samples: Sequence[ResidualSamples], effects: Sequence[str]) -> EffectFit:
    """Least squares of the residual on the stacked held regressors of ``effects``.

    ``residual ~= sum_e X_e theta_e`` over every axis and sample (3n equations);
    covariance by the Newey-West sandwich over contiguous samples
    (:func:`omavctl.learn.intervals.hac_covariance`: the samples are
    autocorrelated by the filter and by what no effect explains, and
    ``s^2 (X^T X)^+``, kept as ``cov_white``, would be optimistic).
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
    cov, cov_white = hac_covariance(x, rest, segment_ids(samples))
    ctx = next((c for s in samples for c, _ in s.contexts), None)
    phys = physical_map(x, effects, bool(ctx is not None and ctx.torque_normalised))
    var = residual.var(axis=0)
    explained = np.where(var > 0, 1.0 - rest.var(axis=0) / np.where(var > 0, var, 1.0), 0.0)
    spread = spread_covariance(samples, x, effects)
    estimates = _estimates(effects, theta, cov, phys, spread)
    return EffectFit(theta, cov, estimates, rest.std(axis=0), explained, cov_white, phys, spread)


def _estimates(
    names: Sequence[str],
    theta: np.ndarray,
    cov: np.ndarray,
    phys: PhysicalMap | None,
    spread: np.ndarray | None = None,
) -> dict[str, EffectEstimate]:
    """Each effect's estimate from the stacked theta (p,) and covariance (p, p) of the
    additive model; beside an inertia scale (``phys``) the torque effects' parameters
    in physical units, their additive coefficients kept as ``fitted``
    (:mod:`omavctl.learn.physical`); with ``spread`` (p, p) their systematic parts."""
    theta_p, cov_p = to_physical(theta, cov, phys)
    spread_p = None if spread is None else to_physical(theta, spread, phys)[1]
    moved = phys is not None and theta_p is not theta
    estimates: dict[str, EffectEstimate] = {}
    i = 0
    for name in names:
        effect = get_effect(name)
        size = effect.n_theta
        block = slice(i, i + size)
        params = effect.to_parameters(theta_p[block], cov_p[block, block])
        fitted = theta[block].copy() if moved and name in TORQUE_EFFECTS else None
        systematic = None
        if spread_p is not None:
            sys_params = effect.to_parameters(theta_p[block], spread_p[block, block])
            systematic = {k: np.nan_to_num(se) for k, (_, se) in sys_params.items()}
        estimates[name] = EffectEstimate(
            name,
            {k: v for k, (v, _) in params.items()},
            {k: se for k, (_, se) in params.items()},
            fitted=fitted,
            systematic=systematic,
        )
        i += size
    return estimates


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
#: the gain freely (``GAIN_PRIOR_FACTOR``, defined in :mod:`omavctl.learn.estimate`
#: for the model's band too).
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


def honest_covariance(cov_joint: np.ndarray, first_pass: EffectFit) -> np.ndarray:
    """The joint fit's posterior covariance (p, p) made honest about autocorrelation.

    The joint posterior accounts for what the GP could absorb (confounding) but
    treats the training points' misfit as white; each parameter's variance is
    multiplied by the first pass's inflation (HAC over white,
    :attr:`EffectFit.inflation`) and raised to at least the first pass's HAC
    variance, correlations kept.
    """
    if cov_joint.size == 0:
        return cov_joint
    var = np.diag(cov_joint)
    target = np.maximum(var * first_pass.inflation, np.diag(first_pass.cov))
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(var > 0, np.sqrt(target / var), 1.0)
    factor = np.nan_to_num(factor, nan=1.0, posinf=1.0)
    return np.asarray(cov_joint * np.outer(factor, factor))


def refit_estimates(
    names: Sequence[str], theta: np.ndarray, cov: np.ndarray, old: EffectFit
) -> EffectFit:
    """An :class:`EffectFit` with new parameters (explained variances and the physical
    map kept from ``old``)."""
    estimates = _estimates(names, theta, cov, old.physical, old.cov_spread)
    return EffectFit(
        theta, cov, estimates, old.residual_std, old.explained, None, old.physical, old.cov_spread
    )


def search_step(
    samples: list[ResidualSamples], names: Sequence[str]
) -> tuple[list[ResidualSamples], dict[str, SearchResult]]:
    """Estimate the effects of ``names`` that need a 1-D search (:mod:`omavctl.learn.effect_search`)
    and return the samples with their exact residual removed, and the estimates."""
    searched = [nm for nm in names if get_effect(nm).search is not None]
    if not searched:
        return samples, {}
    linear = [nm for nm in names if nm not in searched]
    found = search_effects(samples, searched, linear)
    return without_searched(samples, found), found


def without_searched(
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


def merged_estimates(
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
