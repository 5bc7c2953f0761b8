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
  widened; inside the fit inputs the band then follows the GP's distance from
  its data, below). Scaling signal and noise variance together leaves the GP
  mean unchanged.

Time blocks test the GP where the flight already went; a *new* trajectory
also leaves the training envelope, where a GP with long length scales
extrapolates confidently and wrongly. So the same is done with folds that are
slabs at the ends of each input the GP uses (the samples beyond its 85th or
below its 15th percentile, predicted from the others: an extrapolation in that
input). Beyond its training inputs an SE GP returns to a bounded prior, while
the residuals of a new flight (inertia error, lags, delays) keep growing with
the wrench and its rate; so the predictive variance also grows with the
distance beyond the training inputs' box (:func:`beyond_envelope_variance`),
with a weight ``lambda``, and the latent variance gets its own factor ``b``:
``var = c^2 (b^2 latent + lambda beyond + noise)``. ``lambda`` is the smallest
weight from :data:`BEYOND_PRIOR` up, then ``b`` the smallest factor from 1 up,
that bring the pooled held-out coverage of both kinds of fold to the target.
The switch-off compares the pooled held-out errors.

One factor ``c`` per axis treats the held-out errors as equally spread over the
flight, but they are not: where the held-out block's samples lie far from the
training points (the GP's latent variance a large share of its prior: the sharp
transitions of attitude steps) the errors outgrow the latent std, and there
alone ``c`` is set (docs/intervals.md, "A band that follows the GP's own
distance"). So the band inside the fit inputs gets its own per-sample factor
(:func:`band_slope`): the standardised held-out errors ``u = err / sqrt(latent +
noise)`` are modelled as ``N(0, s0^2 (1 + beta rho))``, ``rho`` the latent
variance over the signal variance (0 at the training points, 1 at the prior),
``beta >= 0`` and ``s0`` by maximum likelihood, then a factor ``h`` puts 95 % of
``u / (s0 sqrt(1 + beta rho))`` inside 2 sigma; the band's variance inside is
``h^2 s0^2 (1 + beta rho) (latent + noise)`` in place of ``c^2 (latent + noise)``
(:mod:`omavctl.learn.band`). ``c`` still scales the GP's signal variance, so the
mean (weighed by its latent variance, :mod:`omavctl.learn.mean_shrink`) is as before.

Arrays: n samples, m training points, d inputs; time-major.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve

__all__ = [
    "BEYOND_PRIOR",
    "BLOCK_SECONDS",
    "FOLDS",
    "KEEP_RATIO",
    "TARGET_COVERAGE",
    "AxisValidation",
    "band_slope",
    "beyond_envelope_variance",
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
#: Weight on the variance beyond the training box (:func:`beyond_envelope_variance`)
#: that no calibration goes below: one flight cannot show how far its trends carry
#: on (its own held-out input ends mostly say "not at all", and a new flight then
#: falls outside the band). Chosen on ``benchmarks/generalise.py``
#: (docs/generalisation.md: 0, 0.25, 0.5, 1 put 12, 5, 3, 2 axis-directions below
#: 0.85 coverage and 7, 8, 10, 16 above 0.99).
BEYOND_PRIOR = 0.5
#: Largest weight on the variance beyond the training box.
MAX_EXTRAPOLATION = 4.0
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
    #: weight lambda on the variance beyond the training box, >= 0
    beyond_scale: float = 0.0
    #: held-out MSE of the GP and of zero on the input-space folds
    mse_gp_region: float = float("nan")
    mse_physics_region: float = float("nan")
    #: the band inside the fit inputs: factor a on ``c^2 (latent + noise)`` at the training
    #: points and slope beta on ``rho`` (:func:`band_slope`): ``a (1 + beta rho)``
    band_scale: float = 1.0
    band_slope: float = 0.0
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class HeldOut:
    """Held-out samples of one kind of fold: error of the GP mean, latent variance,
    reach beyond the training box (:func:`beyond_reach`), noise variance and
    target; each (k, 3), or (k,) for one axis (:meth:`axis`)."""

    err: np.ndarray
    lat: np.ndarray
    ext: np.ndarray
    noise: np.ndarray
    y: np.ndarray

    def axis(self, a: int) -> HeldOut:
        """The samples of axis a."""
        return HeldOut(*(v[:, a] for v in (self.err, self.lat, self.ext, self.noise, self.y)))

    def __add__(self, other: HeldOut) -> HeldOut:
        """Both sets pooled."""
        return HeldOut(
            *(
                np.concatenate([u, v])
                for u, v in zip(
                    (self.err, self.lat, self.ext, self.noise, self.y),
                    (other.err, other.lat, other.ext, other.noise, other.y),
                    strict=True,
                )
            )
        )


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


def beyond_reach(z: np.ndarray, lo: np.ndarray, hi: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``sum_j (e_j / l_j)^2`` (k,) at z (k, d), e_j how far input j lies outside
    [lo_j, hi_j] (0 inside), l (d,) the length scales (normalised units)."""
    excess = np.maximum(z - hi, 0.0) + np.maximum(lo - z, 0.0)
    return np.asarray(((excess / lengths) ** 2).sum(axis=-1))


def beyond_envelope_variance(
    z: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    signal_variance: float,
    length_scales: np.ndarray,
) -> np.ndarray:
    """Variance (k,) the residual may gain beyond the training inputs' box, at z (k, d).

    ``s^2 sum_j (e_j / l_j)^2`` (:func:`beyond_reach`). Far from its data an SE GP
    returns to its prior: a bounded residual of variance ``s^2``. The residuals a
    model meets beyond the inputs it was fitted on (an inertia error, a lag, a
    delay) grow with the commanded wrench and its rate instead. A function drawn
    from the GP has a slope of variance ``s^2 / l_j^2`` along input j; continued
    beyond the box at such a slope it moves this far from the GP's prediction.
    Zero inside the box (where the band is the calibrated one); it never moves
    the mean. Zero on an axis whose GP is off (``s^2`` = 0).
    """
    return signal_variance * beyond_reach(z, lo, hi, length_scales)


def gp_posterior(
    z_train: np.ndarray,
    y_train: np.ndarray,
    z_test: np.ndarray,
    mean: float,
    signal_variance: float,
    length_scales: np.ndarray,
    noise_variance: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Posterior mean (k,), latent variance (k,) and reach beyond the training points'
    box (k,) (:func:`beyond_reach`, times ``s^2`` a variance) of one SE-ARD GP axis.

    z_train (m, d), z_test (k, d) normalised inputs; y_train (m,) targets.
    """
    c = cholesky_of_k(z_train, signal_variance, length_scales, noise_variance)
    k_ba = se_kernel(z_test, z_train, signal_variance, length_scales)
    mu = mean + k_ba @ cho_solve(c, y_train - mean)
    v = cho_solve(c, k_ba.T)
    var = np.maximum(signal_variance - np.einsum("km,mk->k", k_ba, v), 0.0)
    lo, hi = z_train.min(axis=0), z_train.max(axis=0)
    return mu, var, beyond_reach(z_test, lo, hi, length_scales)


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
) -> HeldOut:
    """Held-out errors and variances, each (k, 3), of the GP conditioned on the
    training points outside each held-out set.

    fold: (n,) fold numbers, each held out in turn, or a list of (n,) masks of
    held-out samples.
    """
    mean, sv, ls, nv = hyper
    out: list[list[np.ndarray]] = [[], [], [], [], []]
    masks = [fold == f for f in np.unique(fold)] if isinstance(fold, np.ndarray) else fold
    for held in masks:
        train = train_index[~held[train_index]]
        test = np.flatnonzero(held)
        if test.size > MAX_TEST:
            test = test[np.linspace(0, test.size - 1, MAX_TEST).astype(np.int64)]
        zt = np.concatenate([fixed[0], z_all[train]])
        yt = np.concatenate([fixed[1], y_all[train]])
        err, lat, ext = (np.zeros((test.size, 3)) for _ in range(3))
        for a in range(3):
            if zt.shape[0] == 0:
                mu, lat[:, a] = np.full(test.size, mean[a]), np.full(test.size, sv[a])
            else:
                mu, lat[:, a], ext[:, a] = gp_posterior(
                    zt, yt[:, a], z_all[test], mean[a], sv[a], ls[a], nv[a]
                )
            err[:, a] = y_all[test, a] - mu
        out[0].append(err)
        out[1].append(lat)
        out[2].append(ext)
        out[3].append(np.broadcast_to(nv, (test.size, 3)))
        out[4].append(y_all[test])
    return HeldOut(*(np.concatenate(o) for o in out))


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
        _axis_verdict(time_cv.axis(a), region_cv.axis(a), y_all[:, a], float(signal_variance[a]))
        for a in range(3)
    ]


def _coverage(err: np.ndarray, var: np.ndarray) -> float:
    return float(np.mean(np.abs(err) <= 2.0 * np.sqrt(var)))


def _smallest(covered: Callable[[float], bool], lo: float, hi: float) -> float:
    """Smallest x in [lo, hi] with ``covered(x)`` (coverage grows with x), by bisection;
    hi when even hi is not enough."""
    if covered(lo):
        return lo
    if not covered(hi):
        return hi
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if covered(mid):
            hi = mid
        else:
            lo = mid
    return hi


def _band_factors(h: HeldOut, c: float, signal_variance: float) -> tuple[float, float]:
    """Weight lambda in [BEYOND_PRIOR, MAX_EXTRAPOLATION] on the variance beyond the
    training box, then factor b in [1, MAX_STD_FACTOR] on the latent std, each the
    smallest that makes the held-out coverage of ``c^2 (b^2 lat + lambda s^2 reach +
    noise)`` the target."""

    def covered(b: float, lam: float) -> bool:
        var = c**2 * (b**2 * h.lat + lam * signal_variance * h.ext + h.noise)
        return _coverage(h.err, var) >= TARGET_COVERAGE

    lam = _smallest(lambda x: covered(1.0, x), BEYOND_PRIOR, MAX_EXTRAPOLATION)
    return _smallest(lambda x: covered(x, lam), 1.0, MAX_STD_FACTOR), lam


#: Largest slope beta of the band's variance on the latent share rho (:func:`band_slope`).
MAX_BAND_SLOPE = 1000.0


def band_slope(u: np.ndarray, rho: np.ndarray) -> tuple[float, float]:
    """Factor ``a = h^2 s0^2`` and slope ``beta`` of the variance ``a (1 + beta rho)`` of
    standardised held-out errors u (k,) at latent shares rho (k,) in [0, 1] (module
    docstring): ``beta`` in [0, :data:`MAX_BAND_SLOPE`] and ``s0`` by maximum likelihood
    of ``u ~ N(0, s0^2 (1 + beta rho))`` (``s0`` profiled out, ``beta`` by a grid in
    ``log beta``, refined between its neighbours), then ``h`` the factor that puts
    :data:`TARGET_COVERAGE` of ``u / (s0 sqrt(1 + beta rho))`` inside 2 sigma."""
    u2, rho = np.asarray(u, float) ** 2, np.clip(np.asarray(rho, float), 0.0, 1.0)
    if u2.size < 2 or not np.any(u2 > 0):
        return 1.0, 0.0

    def nll(beta: float) -> float:
        g = 1.0 + beta * rho
        return float(np.sum(np.log(g)) + u2.size * np.log(np.mean(u2 / g)))

    grid = np.concatenate([[0.0], np.geomspace(1e-2, MAX_BAND_SLOPE, 51)])
    best = int(np.argmin([nll(b) for b in grid]))
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    beta = min((grid[best], *np.linspace(lo, hi, 21)), key=nll)  # the ends are lo, hi
    g = 1.0 + beta * rho
    s0 = float(np.sqrt(np.mean(u2 / g)))
    h = float(np.quantile(np.sqrt(u2 / g) / s0, TARGET_COVERAGE)) / 2.0
    return (h * s0) ** 2, float(beta)


def _axis_verdict(
    time_cv: HeldOut, region_cv: HeldOut, y_all: np.ndarray, signal_variance: float
) -> AxisValidation:
    """Keep-or-switch-off and the calibration factors of one axis from its held-out
    samples of both kinds of fold, each (k,) (their ``ext``: the reach beyond the
    box, :func:`beyond_reach`); y_all (n,) every sample's target."""
    pooled = time_cv + region_cv
    off_variance = float(np.mean(y_all**2))
    mse_gp = float(np.mean(pooled.err**2))
    mse_phys = float(np.mean(pooled.y**2))
    coverage = _coverage(time_cv.err, time_cv.lat + time_cv.noise)
    keep = mse_gp < KEEP_RATIO * mse_phys
    latent, lam, scale, slope = 1.0, 0.0, 1.0, 0.0
    if keep:
        u = time_cv.err / np.sqrt(time_cv.lat + time_cv.noise)
        factor = _std_factor(u)
        latent, lam = _band_factors(pooled, factor, signal_variance)
        scale, slope = band_slope(u, time_cv.lat / signal_variance)
        scale /= factor**2  # on the band that c already scales
    else:
        factor = _std_factor(pooled.y / np.sqrt(max(off_variance, 1e-300)))
    return AxisValidation(
        mse_gp,
        mse_phys,
        coverage,
        factor,
        keep,
        off_variance,
        latent_factor=latent,
        beyond_scale=lam,
        mse_gp_region=float(np.mean(region_cv.err**2)),
        mse_physics_region=float(np.mean(region_cv.y**2)),
        band_scale=scale,
        band_slope=slope,
    )
