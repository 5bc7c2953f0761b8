"""The Savitzky-Golay derivative filter and the kernel that holds commands alike.

The measured angular acceleration is the Savitzky-Golay derivative of the body rate
on the uniform grid (``scipy.signal.savgol_filter(deriv=1)``), per valid segment of
a log, the ``window // 2`` samples at both ends of each segment dropped
(:func:`usable_segments`). The controller holds each command over its period
``[t_k, t_k+1)``. The SG derivative at ``t_k`` is a weighted sum of the rate samples
``sum_j h_j w_{k+j}`` (``j = -m..m``, ``m = window // 2``); writing the rate
differences as integrals of the acceleration gives exactly::

    d_k = sum_{i=-m}^{m-1} g_i  abar_{k+i},   g_i = dt * sum_{j>i} h_j,   sum g_i = 1

where ``abar_i`` is the mean acceleration over the period ``[t_i, t_i+1)`` in which
command ``i`` is held. So the measured derivative is compared with
``sum g_i nominal_{k+i}``: the same kernel (:meth:`SavitzkyGolay.hold`) applied to
the per-period nominal accelerations. For a 3-sample window this is the average of
the periods before and after ``t_k`` (the command "at t - dt/2"); longer windows
give a parabolic weighting (order 2 or 3).

The filter alone, on arrays: what it is applied to (the residual the GP learns) is
:mod:`omavctl.learn.signal`. Arrays are time-major: shape (N, k) for N grid samples
of a k-vector.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.signal import savgol_coeffs, savgol_filter

from omavctl.base.errors import ConfigError

__all__ = ["DEFAULT_SG_ORDER", "DEFAULT_SG_WINDOW", "SavitzkyGolay", "usable_segments"]

#: Default Savitzky-Golay window (samples at the grid rate) and polynomial order.
#: Chosen by measurement on simulated 100 Hz logs (``benchmarks/sg_window.py``,
#: ``docs/fit.md``).
DEFAULT_SG_WINDOW = 11
DEFAULT_SG_ORDER = 2


@dataclass(frozen=True)
class SavitzkyGolay:
    """Savitzky-Golay derivative filter and its matching kernel for held commands.

    window: odd number of samples (>= 3); order: polynomial order (1 <= order < window);
    dt: grid step in s.
    """

    window: int
    order: int
    dt: float

    def __post_init__(self) -> None:
        if self.window < 3 or self.window % 2 == 0:
            raise ConfigError(f"--sg-window must be an odd number >= 3, got {self.window}")
        if not 1 <= self.order < self.window:
            raise ConfigError(
                f"--sg-order must be at least 1 and below --sg-window ({self.window}), "
                f"got {self.order}"
            )
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ConfigError(f"grid step must be > 0 s, got {self.dt}")

    @property
    def half(self) -> int:
        """Samples dropped at each end of a segment: ``window // 2``."""
        return self.window // 2

    @cached_property
    def derivative_coefficients(self) -> np.ndarray:
        """``h`` shape (window,): ``d_k = sum_j h[j] y[k - m + j]`` (1/s)."""
        return np.asarray(
            savgol_coeffs(self.window, self.order, deriv=1, delta=self.dt, use="dot"), float
        )

    @cached_property
    def hold_kernel(self) -> np.ndarray:
        """``g`` shape (window - 1,): weights of the held periods ``k-m .. k+m-1``; sums to 1."""
        h = self.derivative_coefficients
        # g_i = dt * sum_{j > i} h_j for i = -m .. m-1 (index i + m)
        tail = np.cumsum(h[::-1])[::-1]  # tail[j] = sum_{l >= j} h_l
        return self.dt * tail[1:]

    @property
    def noise_gain(self) -> float:
        """RMS of the derivative per unit of white rate noise (1/s): ``||h||``."""
        return float(np.linalg.norm(self.derivative_coefficients))

    def derivative(self, y: np.ndarray) -> np.ndarray:
        """SG derivative along time of ``y`` shape (N, k) (or (N,)); same shape, units/s.

        Needs ``N >= window``; the first and last ``half`` values are polynomial
        extrapolations and should be dropped (:func:`usable_segments`).
        """
        y = np.asarray(y, dtype=float)
        if y.shape[0] < self.window:
            raise ValueError(f"{y.shape[0]} samples, fewer than the window {self.window}")
        return np.asarray(
            savgol_filter(y, self.window, self.order, deriv=1, delta=self.dt, axis=0, mode="interp")
        )

    def hold(self, x: np.ndarray) -> np.ndarray:
        """Held per-period values ``x`` shape (N, ...) seen at the grid times like the derivative.

        ``out_k = sum_{i=-m}^{m-1} g_i x_{k+i}``; the ends are padded with the edge
        values (those samples are dropped anyway). Same shape as ``x``.
        """
        x = np.asarray(x, dtype=float)
        g = self.hold_kernel
        m = self.half
        n = x.shape[0]
        pad = [(m, m)] + [(0, 0)] * (x.ndim - 1)
        xp = np.pad(x, pad, mode="edge")  # xp[k + m] = x[k]
        out = np.zeros_like(x)
        for tap, weight in enumerate(g):  # offset i = tap - m
            out += weight * xp[tap : tap + n]
        return out


def usable_segments(
    segments: Sequence[tuple[int, int]], window: int
) -> tuple[list[tuple[int, int, int, int]], int, int]:
    """Which samples of each valid segment the SG filter covers.

    segments: half-open ``[start, stop)`` grid index ranges of valid runs.
    Returns ``(kept, edge_dropped, short_dropped)``: ``kept`` lists
    ``(start, stop, keep_start, keep_stop)`` for segments of at least ``window``
    samples (keep = start + m .. stop - m); ``edge_dropped`` counts the samples
    dropped at their ends; ``short_dropped`` the samples of shorter segments.
    """
    m = window // 2
    kept: list[tuple[int, int, int, int]] = []
    edge = short = 0
    for a, b in segments:
        if b - a < window:
            short += b - a
            continue
        kept.append((a, b, a + m, b - m))
        edge += 2 * m
    return kept, edge, short
