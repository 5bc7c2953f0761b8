"""Blocked cross-validation of the residual GP: keep it only where it helps, and
make its uncertainty honest.

A GP fitted by maximum marginal likelihood on one flight can interpolate the
noise of that flight (noise variance at its lower bound, short length scales)
and then makes a *new* flight's error worse than the physics it sits on, with
a 2-sigma band that covers far less than 95 %. Random held-out points would
not show it: the Savitzky-Golay derivative and the vehicle's own dynamics
correlate neighbouring samples, so a point's neighbours predict it. Here the
held-out data are whole time blocks (:data:`BLOCK_SECONDS` of each log,
assigned to :data:`FOLDS` folds in turn); the GP is conditioned on its
training points *outside* the fold with the fitted hyperparameters and
predicts every sample inside it.

Per axis (:func:`cross_validate`):

- **switch-off**: if the GP's held-out mean squared error is not below
  :data:`KEEP_RATIO` x that of predicting zero (the physics-only model: the
  targets are the residual after the fitted effects), the axis' GP is switched
  off: mean zero, variance the residual's mean square;
- **calibration**: the predictive variance (latent + noise, or the off
  variance) is scaled by ``c^2`` with ``c`` the factor that makes the held-out
  2-sigma coverage :data:`TARGET_COVERAGE` (never below 1: the band is only
  widened). Scaling signal and noise variance together leaves the GP mean
  unchanged.

Time blocks test the GP where the flight already went; a *new* trajectory
also leaves the training envelope, where a GP with long length scales
extrapolates confidently and wrongly. So the same is done with folds that are
slabs at the ends of each input the GP uses (the samples beyond its 85th or
below its 15th percentile, predicted from the others: an extrapolation in that
input), and the GP's *latent* variance gets its
own factor ``b`` (``var = c^2 (b^2 latent + noise)``) chosen so that the
pooled held-out coverage of both kinds of fold reaches the target. The
switch-off compares the pooled held-out errors.

Arrays: n samples, m training points, d inputs; time-major.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve

__all__ = [
    "BLOCK_SECONDS",
    "FOLDS",
    "KEEP_RATIO",
    "TARGET_COVERAGE",
    "AxisValidation",
    "cholesky_of_k",
    "cross_validate",
    "fold_of",
    "gp_posterior",
    "se_kernel",
]

#: Length of a held-out time block, s.
BLOCK_SECONDS = 3.0
#: Number of folds (blocks assigned in turn).
FOLDS = 4
#: The GP stays on an axis only if its held-out MSE is below this fraction of
#: the physics-only MSE.
KEEP_RATIO = 0.95
#: Held-out 2-sigma coverage the variance is calibrated to.
TARGET_COVERAGE = 0.95
#: Largest factor on the predictive std (a band 10x wider says "unknown").
MAX_STD_FACTOR = 10.0
#: Fraction of the samples at each end of an input held out to test extrapolation.
SLAB_FRACTION = 0.15
#: Inputs with a length scale below this (normalised units) on some axis are used.
RELEVANT_LENGTH = 100.0
#: Held-out samples used per fold at most (evenly spaced): bounds the cost.
MAX_TEST = 4000


@dataclass
class AxisValidation:
    """Held-out verdict of one axis.

    mse_gp / mse_physics: held-out mean squared error of the GP mean and of
    zero (rad/s^2)^2; coverage: held-out 2-sigma coverage before calibration;
    std_factor: the calibration factor c on the predictive std; keep: the GP
    stays on; off_variance: the residual's mean square (the variance of the
    switched-off axis), (rad/s^2)^2.
    """

    mse_gp: float
    mse_physics: float
    coverage: float
    std_factor: float
    keep: bool
    off_variance: float
    #: factor b on the latent std (extrapolation), >= 1
    latent_factor: float = 1.0
    #: held-out MSE of the GP and of zero on the input-space folds
    mse_gp_region: float = float("nan")
    mse_physics_region: float = float("nan")
    notes: list[str] = field(default_factory=list)


def fold_of(t: np.ndarray, log_id: np.ndarray, seconds: float = BLOCK_SECONDS) -> np.ndarray:
    """Fold (n,) of every sample: consecutive ``seconds`` blocks per log, folds in turn.

    The block counter runs on across logs so that each log's blocks spread over
    all folds.
    """
    fold = np.empty(t.size, dtype=np.int64)
    offset = 0
    for lid in np.unique(log_id):
        sel = log_id == lid
        block = np.floor((t[sel] - t[sel].min()) / seconds).astype(np.int64)
        fold[sel] = (block + offset) % FOLDS
        offset += int(block.max()) + 1
    return fold


def se_kernel(
    a: np.ndarray, b: np.ndarray, signal_variance: float, length_scales: np.ndarray
) -> np.ndarray:
    """Squared-exponential ARD kernel (n, m) between rows of a (n, d) and b (m, d).

    Squared distances by matrix products (``|a|^2 + |b|^2 - 2 a.b``), clipped at 0.
    """
    al, bl = a / length_scales, b / length_scales
    d2 = (al * al).sum(1)[:, None] + (bl * bl).sum(1)[None] - 2.0 * al @ bl.T
    return np.asarray(signal_variance * np.exp(-0.5 * np.maximum(d2, 0.0)))


def cholesky_of_k(
    z: np.ndarray, signal_variance: float, length_scales: np.ndarray, noise_variance: float
) -> tuple[np.ndarray, bool]:
    """Cholesky factor (scipy ``cho_factor``) of ``s^2 k(z, z) + sigma^2 I`` (z (n, d))."""
    k = se_kernel(z, z, signal_variance, length_scales)
    k[np.diag_indices_from(k)] += noise_variance
    return cho_factor(k, lower=True)


def gp_posterior(
    z_train: np.ndarray,
    y_train: np.ndarray,
    z_test: np.ndarray,
    mean: float,
    signal_variance: float,
    length_scales: np.ndarray,
    noise_variance: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean (k,) and latent variance (k,) of one SE-ARD GP axis.

    z_train (m, d), z_test (k, d) normalised inputs; y_train (m,) targets.
    """
    c = cholesky_of_k(z_train, signal_variance, length_scales, noise_variance)
    k_ba = se_kernel(z_test, z_train, signal_variance, length_scales)
    mu = mean + k_ba @ cho_solve(c, y_train - mean)
    v = cho_solve(c, k_ba.T)
    var = np.maximum(signal_variance - np.einsum("km,mk->k", k_ba, v), 0.0)
    return mu, var


def _std_factor(z: np.ndarray) -> float:
    """Factor c >= 1 on the std that makes the 2-sigma coverage of z (n,) TARGET_COVERAGE."""
    if z.size == 0:
        return 1.0
    q = float(np.quantile(np.abs(z), TARGET_COVERAGE))
    return float(np.clip(q / 2.0, 1.0, MAX_STD_FACTOR))


def slabs(z: np.ndarray, length_scales: np.ndarray) -> list[np.ndarray]:
    """Held-out masks (n,) that each cut off one end of one input: extrapolations.

    For every input that some axis' GP uses (length scale below
    :data:`RELEVANT_LENGTH`), the samples beyond its upper and below its lower
    :data:`SLAB_FRACTION` quantile: predicted from the rest, they are what a new
    flight that goes further in that input looks like.
    """
    out = []
    for j in np.flatnonzero((length_scales < RELEVANT_LENGTH).any(axis=0)):
        lo, hi = np.quantile(z[:, j], [SLAB_FRACTION, 1.0 - SLAB_FRACTION])
        for mask in (z[:, j] > hi, z[:, j] < lo):
            if 0 < mask.sum() < z.shape[0]:
                out.append(mask)
    return out


def _held_out(
    z_all: np.ndarray,
    y_all: np.ndarray,
    fold: np.ndarray | list[np.ndarray],
    train_index: np.ndarray,
    fixed: tuple[np.ndarray, np.ndarray],
    hyper: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Held-out error, latent variance, noise variance and target, each (k, 3),
    of the GP conditioned on the training points outside each held-out set.

    fold: (n,) fold numbers, each held out in turn, or a list of (n,) masks of
    held-out samples.
    """
    mean, sv, ls, nv = hyper
    out: list[list[np.ndarray]] = [[], [], [], []]
    masks = [fold == f for f in np.unique(fold)] if isinstance(fold, np.ndarray) else fold
    for held in masks:
        train = train_index[~held[train_index]]
        test = np.flatnonzero(held)
        if test.size > MAX_TEST:
            test = test[np.linspace(0, test.size - 1, MAX_TEST).astype(np.int64)]
        zt = np.concatenate([fixed[0], z_all[train]])
        yt = np.concatenate([fixed[1], y_all[train]])
        err, lat = np.empty((test.size, 3)), np.empty((test.size, 3))
        for a in range(3):
            if zt.shape[0] == 0:
                mu, lat[:, a] = np.full(test.size, mean[a]), np.full(test.size, sv[a])
            else:
                mu, lat[:, a] = gp_posterior(
                    zt, yt[:, a], z_all[test], mean[a], sv[a], ls[a], nv[a]
                )
            err[:, a] = y_all[test, a] - mu
        out[0].append(err)
        out[1].append(lat)
        out[2].append(np.broadcast_to(nv, (test.size, 3)))
        out[3].append(y_all[test])
    e, lt, n, y = (np.concatenate(o) for o in out)
    return e, lt, n, y


def cross_validate(
    z_all: np.ndarray,
    y_all: np.ndarray,
    fold: np.ndarray,
    train_index: np.ndarray,
    z_fixed: np.ndarray,
    y_fixed: np.ndarray,
    mean: np.ndarray,
    signal_variance: np.ndarray,
    length_scales: np.ndarray,
    noise_variance: np.ndarray,
    seed: int = 0,
) -> list[AxisValidation]:
    """Blocked cross-validation of the per-axis GPs (see module docstring).

    z_all (n, d) normalised inputs and y_all (n, 3) targets of every sample;
    fold (n,) time-block folds from :func:`fold_of`; train_index (m,) indices
    of the selected training points among them; z_fixed (p, d), y_fixed (p, 3)
    training points that are in no fold (a prior model's); hyperparameters per
    axis as in the model (mean (3,), signal_variance (3,), length_scales
    (3, d), noise_variance (3,)).
    """
    hyper = (mean, signal_variance, length_scales, noise_variance)
    fixed = (z_fixed, y_fixed)
    time_cv = _held_out(z_all, y_all, fold, train_index, fixed, hyper)
    region_cv = _held_out(z_all, y_all, slabs(z_all, length_scales), train_index, fixed, hyper)
    return [
        _axis_verdict(
            tuple(c[:, a] for c in time_cv),  # type: ignore[arg-type]
            tuple(c[:, a] for c in region_cv),  # type: ignore[arg-type]
            y_all[:, a],
            float(signal_variance[a]),
        )
        for a in range(3)
    ]


def _coverage(err: np.ndarray, var: np.ndarray) -> float:
    return float(np.mean(np.abs(err) <= 2.0 * np.sqrt(var)))


def _latent_factor(err: np.ndarray, lat: np.ndarray, noise: np.ndarray, c: float) -> float:
    """Smallest b in [1, MAX_STD_FACTOR] with coverage of c^2 (b^2 lat + noise) >= target."""
    if _coverage(err, c**2 * (lat + noise)) >= TARGET_COVERAGE:
        return 1.0
    lo, hi = 1.0, MAX_STD_FACTOR
    if _coverage(err, c**2 * (hi**2 * lat + noise)) < TARGET_COVERAGE:
        return hi
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if _coverage(err, c**2 * (mid**2 * lat + noise)) >= TARGET_COVERAGE:
            hi = mid
        else:
            lo = mid
    return hi


def _axis_verdict(
    time_cv: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    region_cv: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    y_all: np.ndarray,
    signal_variance: float,
) -> AxisValidation:
    """Keep-or-switch-off and the calibration factors of one axis from held-out errors.

    Each of time_cv and region_cv: held-out error, latent variance, noise
    variance and target, each (k,).
    """
    err_t, lat_t, noise_t, y_t = time_cv
    err_r, lat_r, noise_r, y_r = region_cv
    off_variance = float(np.mean(y_all**2))
    mse_gp = float(np.mean(np.concatenate([err_t, err_r]) ** 2))
    mse_phys = float(np.mean(np.concatenate([y_t, y_r]) ** 2))
    coverage = _coverage(err_t, lat_t + noise_t)
    keep = mse_gp < KEEP_RATIO * mse_phys
    if keep:
        factor = _std_factor(err_t / np.sqrt(lat_t + noise_t))
        err, lat, noise = (
            np.concatenate(p) for p in ((err_t, err_r), (lat_t, lat_r), (noise_t, noise_r))
        )
        latent = _latent_factor(err, lat, noise, factor)
    else:
        y = np.concatenate([y_t, y_r])
        factor = _std_factor(y / np.sqrt(max(off_variance, 1e-300)))
        latent = 1.0
    return AxisValidation(
        math.sqrt(mse_gp) ** 2,
        mse_phys,
        coverage,
        factor,
        keep,
        off_variance,
        latent_factor=latent,
        mse_gp_region=float(np.mean(err_r**2)),
        mse_physics_region=float(np.mean(y_r**2)),
    )
