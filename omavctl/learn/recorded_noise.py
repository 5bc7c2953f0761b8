"""The body-rate measurement noise at a log's grid samples, from what the log recorded.

A log whose gyro was recorded more slowly than the grid (the px4tools PX4 log:
about 83 Hz on a 100 Hz grid) is linearly interpolated onto it: a grid value
is ``(1 - w) r[i] + w r[i + 1]`` of two recorded samples, so neighbouring grid
values share their noise, and second differences on the grid see about half
of it (0.0026 against 0.0055 rad/s on the px4tools log's roll axis). Here the
noise is estimated on the recorded samples themselves (over those inside the
kept grid spans; :func:`band_scale`: the scale whose 2 sigma holds 95 % of it,
the std for normal noise) and carried to the grid through the interpolation weights:
the variance of the difference of two grid values' noise (the horizon band's
start and end terms) and the Savitzky-Golay derivative's noise variance are
exact for white recorded noise.

A log recorded at the grid rate or faster keeps the grid's own estimate
(``ResidualSamples.rate_noise``) with independent noise per grid sample: on
a filtered high-rate gyro, second differences of neighbouring recorded
samples would miss the noise the grid sees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omavctl.logs.types import FlightLog

__all__ = ["RecordedNoise", "band_scale", "independent_noise", "recorded_noise"]

#: a recorded body rate counts as upsampled when its median step exceeds the grid's by this
UPSAMPLED = 1.05
#: the share of the noise a 2-sigma band is to hold (a normal variable's, within 2 std)
BAND_SHARE = 0.9545


def band_scale(second_differences: np.ndarray) -> np.ndarray:
    """Noise scale (3,) rad/s of a body rate from its second differences (m, 3): the
    std of normal noise whose second differences have the same 95.45 % quantile of
    |d - median| (``q / (2 sqrt 6)``). For normal noise it is the std (as the MAD
    estimate :func:`omavctl.learn.signal.rate_noise`); for heavier tails it is larger,
    so that a 2-sigma band holds 95 % of the noise. NaN without data."""
    if second_differences.shape[0] == 0:
        return np.full(3, np.nan)
    d = second_differences
    q = np.quantile(np.abs(d - np.median(d, axis=0)), BAND_SHARE, axis=0)
    return np.asarray(q / (2.0 * np.sqrt(6.0)), dtype=float)


@dataclass(frozen=True)
class RecordedNoise:
    """The body-rate noise of one log at its kept grid samples (n of them).

    std (3,) rad/s: white-noise std of the recorded samples; left (n,) int: the
    recorded sample at or before each kept grid sample; weight (n,) in [0, 1]:
    the share of the next recorded sample in the grid value; upsampled: whether
    the grid interpolates a slower recording (else left is the grid index and
    weight 0: independent noise per grid sample).
    """

    std: np.ndarray
    left: np.ndarray
    weight: np.ndarray
    upsampled: bool = False

    def overlap(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Covariance (same shape as p, q) of the noise of kept samples p and q (positions,
        p <= q) in units of ``std**2``."""
        lp, lq = self.left[p], self.left[q]
        wp, wq = self.weight[p], self.weight[q]
        same = (1.0 - wp) * (1.0 - wq) + wp * wq
        return np.where(lq == lp, same, np.where(lq == lp + 1, wp * (1.0 - wq), 0.0))

    def difference_factor(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Variance of (noise at q - noise at p) in units of ``std**2``: 2 for independent
        samples, less where the two grid values share recorded samples, 0 for p = q."""
        return self.overlap(p, p) + self.overlap(q, q) - 2.0 * self.overlap(p, q)

    def derivative_factor(self, coefficients: np.ndarray, index: np.ndarray) -> float:
        """Mean variance of a filter's output (``sum_k h_k y[p + k - half]``, coefficients
        (2 half + 1,)) over the kept samples, in units of ``std**2``: ``||h||^2`` for
        independent noise. index (n,): the kept samples' grid indices (the filter runs
        over consecutive grid samples)."""
        h = np.asarray(coefficients, dtype=float)
        if not self.upsampled:
            return float(h @ h)
        n, span = index.size, h.size
        cov = np.zeros(span)  # mean overlap at lag d over consecutive kept pairs
        for d in range(span):
            p = np.arange(n - d)
            p = p[index[p + d] - index[p] == d]
            cov[d] = float(self.overlap(p, p + d).mean()) if p.size else float(d == 0)
        lags = np.abs(np.arange(span)[:, None] - np.arange(span)[None, :])
        return float(h @ cov[lags] @ h)


def independent_noise(std: np.ndarray, index: np.ndarray) -> RecordedNoise:
    """Independent noise of std (3,) at every kept grid sample (grid indices (n,))."""
    std = np.nan_to_num(np.asarray(std, dtype=float), nan=0.0)
    return RecordedNoise(std, np.asarray(index, dtype=np.int64), np.zeros(index.size))


def recorded_noise(flight: FlightLog, index: np.ndarray, grid_std: np.ndarray) -> RecordedNoise:
    """The body-rate noise of ``flight`` at its kept grid samples (grid indices (n,),
    increasing): estimated on the recorded samples when the grid interpolates a slower
    recording, else ``grid_std`` (3,) (the grid's estimate) with independent noise."""
    rec = flight.recorded.get("body_rate")
    index = np.asarray(index, dtype=np.int64)
    if rec is None or rec[0].size < 3 or index.size == 0:
        return independent_noise(grid_std, index)
    stamps, values = rec
    if float(np.median(np.diff(stamps))) <= UPSAMPLED * flight.dt:
        return independent_noise(grid_std, index)
    t = flight.t[index]
    left = np.clip(np.searchsorted(stamps, t, side="right") - 1, 0, stamps.size - 2)
    step = stamps[left + 1] - stamps[left]
    weight = np.clip((t - stamps[left]) / np.where(step > 0, step, 1.0), 0.0, 1.0)
    # second differences of the recorded samples inside each run of consecutive kept samples
    runs = np.flatnonzero(np.diff(index) != 1)
    first = np.concatenate([[0], runs + 1])
    last = np.concatenate([runs, [index.size - 1]])
    diffs = [
        np.diff(values[(stamps >= t[a]) & (stamps <= t[b])], 2, axis=0)
        for a, b in zip(first, last, strict=True)
    ]
    d2 = np.concatenate([d for d in diffs if d.size] or [np.empty((0, 3))])
    std = band_scale(d2)
    if not np.all(np.isfinite(std)):
        return independent_noise(grid_std, index)
    return RecordedNoise(std, left, weight, upsampled=True)
