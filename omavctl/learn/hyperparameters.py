"""GP hyperparameters for ``fit``: marginal likelihood per axis, then blocked validation.

* :func:`fit_hyperparameters` maximises the marginal likelihood of one GP per
  axis (scikit-learn, squared-exponential ARD kernel plus white noise,
  restarts), the noise bounded below by :func:`measurement_noise_std`.
* :func:`apply_validation` runs the blocked cross-validation
  (:func:`omavctl.learn.validation.cross_validate`) and applies its verdicts:
  an axis whose GP does not help on held-out time blocks is switched off, the
  others are calibrated.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from omavctl.learn.signal import ResidualSamples, SavitzkyGolay
from omavctl.learn.validation import (
    BEYOND_PRIOR,
    TARGET_COVERAGE,
    AxisValidation,
    cross_validate,
    fold_of,
)

__all__ = [
    "DEFAULT_RESTARTS",
    "HELD_OUT_NOISE",
    "AxisFit",
    "apply_validation",
    "fit_hyperparameters",
    "measurement_noise_std",
]

#: Restarts of the marginal-likelihood optimiser per axis (besides the first run).
DEFAULT_RESTARTS = 3
#: A kept axis' noise variance is at least this times its held-out MSE (time blocks and
#: input ends pooled): fitted on one flight the noise is the log's sensor floor, while a
#: new flight's error holds all the residual the inputs do not determine, which the fit
#: flight's own blocks understate. Measured (docs/generalisation.md): 0.5 left a chirp
#: -> figure-8 pitch at 0.83 coverage and a pinned two-flight case at 0.84; 1 put that
#: case's band above 0.99; 0.75 neither.
HELD_OUT_NOISE = 0.75
#: Hyperparameter bounds, for inputs normalised to unit std and targets scaled to unit std.
_SIGNAL_BOUNDS = (1e-4, 1e3)
_LENGTH_BOUNDS = (1e-2, 5.0)
_NOISE_BOUNDS = (1e-6, 10.0)


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
    beyond_scale: float = 0.0
    #: noise std of the band inside the fit flight's inputs (rad/s^2): the calibrated
    #: noise before the held-out floor (:data:`HELD_OUT_NOISE`); nan: ``noise_std``
    band_noise_std: float = float("nan")
    #: the band inside the fit inputs: ``band_scale (1 + band_slope rho)`` times its
    #: calibrated latent variance and noise (:func:`omavctl.learn.validation.band_slope`)
    band_scale: float = 1.0
    band_slope: float = 0.0


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


def apply_validation(
    samples: Sequence[ResidualSamples],
    inputs_all: np.ndarray,
    targets_all: np.ndarray,
    idx: np.ndarray,
    prior_x: np.ndarray,
    prior_y: np.ndarray,
    norm: tuple[np.ndarray, np.ndarray],
    hyper: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    axes: list[AxisFit],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Blocked cross-validation (:func:`omavctl.learn.validation.cross_validate`) applied.

    Returns the target means, signal and noise variances after switching off
    the axes whose GP does not help (mean 0, signal variance 0, noise variance
    the residual's mean square) and calibrating the others, the factors (3,) on
    the latent variance and the weights (3,) on the variance beyond the training
    box (:func:`omavctl.learn.validation.beyond_envelope_variance`); fills the
    validation fields of ``axes``; notes for the summary.
    """
    in_mean, in_scale = norm
    t_mean, sv, ls, nv = (np.array(h, dtype=float) for h in hyper)
    t = np.concatenate([s.t for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    fold = fold_of(t, log_id)
    notes: list[str] = []
    latent, beyond = np.ones(3), np.full(3, BEYOND_PRIOR)
    if np.unique(fold).size < 2:
        notes.append("too short for blocked cross-validation: the GP is kept as fitted")
        for ax in axes:
            ax.beyond_scale = BEYOND_PRIOR
        return t_mean, sv, nv, latent, beyond, notes
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
        latent[a], beyond[a] = v.latent_factor**2, v.beyond_scale
        if not v.keep:
            t_mean[a], sv[a], nv[a] = 0.0, 0.0, v.off_variance * v.std_factor**2
            notes.append(
                f"axis {name}: GP switched off: on held-out time blocks it predicts "
                f"{ax.cv_rmse_gp:.3g} rad/s^2 RMS error against {ax.cv_rmse_physics:.3g} for "
                "physics only (mean 0, variance the residual's)"
            )
        else:
            sv[a] *= v.std_factor**2
            # inside the fit flight's inputs the band keeps the calibrated noise: with it
            # the band already covers the held-out time blocks, and the floor below,
            # counted on top, made it cover all of a new flight's samples there
            # (docs/intervals.md, "The model's band")
            ax.band_noise_std = math.sqrt(nv[a] * v.std_factor**2)
            # the noise is at least what the GP fails to predict on held-out data: that
            # part of the residual is no function of its inputs (history, states it
            # does not see), and on a new flight it is noise (beyond the fit inputs)
            nv[a] = max(nv[a] * v.std_factor**2, HELD_OUT_NOISE * v.mse_gp)
        ax.signal_std, ax.noise_std = math.sqrt(sv[a]), math.sqrt(nv[a])
        ax.latent_factor, ax.beyond_scale = v.latent_factor, v.beyond_scale
        ax.band_scale, ax.band_slope = v.band_scale, v.band_slope
        notes += _axis_notes(name, v)
    return t_mean, sv, nv, latent, beyond, notes


def _axis_notes(name: str, v: AxisValidation) -> list[str]:
    """What the blocked cross-validation changed on one axis, for the summary."""
    notes: list[str] = []
    if round(v.std_factor, 2) > 1.0:  # "widened x1.00 ... (was 95%)" said nothing
        notes.append(
            f"axis {name}: predictive std widened x{v.std_factor:.2f} to cover "
            f"{TARGET_COVERAGE:.0%} of held-out time blocks (was {v.coverage:.0%})"
        )
    if v.beyond_scale > BEYOND_PRIOR:
        notes.append(
            f"axis {name}: the band grows beyond the training inputs with weight "
            f"{v.beyond_scale:.2f} (held-out ends of the inputs; {BEYOND_PRIOR:g} at least)"
        )
    if v.band_slope > 0:
        near, far = (
            v.std_factor * math.sqrt(v.band_scale * (1.0 + r * v.band_slope)) for r in (0, 1)
        )
        notes.append(
            f"axis {name}: inside the fit inputs the band's std is x{near:.2f} at the training "
            f"points, x{far:.2f} at the GP's prior (held-out errors grow with its variance)"
        )
    if round(v.latent_factor, 2) > 1.0:
        notes.append(
            f"axis {name}: extrapolation uncertainty widened x{v.latent_factor:.2f} "
            "(held-out regions of input space)"
        )
    return notes
