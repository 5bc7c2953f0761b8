"""Statistics of the informative-flight benchmark (benchmarks/informative.py).

Kept apart from the runner so that tests can check them on synthetic inputs in
milliseconds: the relative gain of one flight over another, the mean gain over
draws with its 95 % t-interval, and the Spearman rank correlation.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats


def gain(baseline: float, other: float) -> float:
    """Per cent by which ``other`` lowers the error of ``baseline`` (negative: raises it)."""
    if not baseline > 0:
        raise ValueError(f"baseline error must be positive, got {baseline}")
    return 100.0 * (baseline - other) / baseline


@dataclass(frozen=True)
class MeanInterval:
    """Mean of n draws and its two-sided t-interval (``level``, e.g. 0.95)."""

    mean: float
    low: float
    high: float
    n: int
    level: float

    def holds(self, target: float) -> bool:
        """Mean at least ``target`` with the interval's lower end above 0."""
        return self.mean >= target and self.low > 0

    def text(self, digits: int = 1) -> str:
        """E.g. ``+12.3 % [+4.0, +20.6]``; a single draw has no interval."""
        if self.n < 2:
            return f"{self.mean:+.{digits}f} % (one draw, no interval)"
        return f"{self.mean:+.{digits}f} % [{self.low:+.{digits}f}, {self.high:+.{digits}f}]"


def mean_interval(values: Sequence[float], level: float = 0.95) -> MeanInterval:
    """Mean of ``values`` (n,) with the Student-t interval ``mean ± t s / sqrt(n)``.

    One value: the interval is (-inf, inf) — nothing can be said about its spread.
    """
    x = np.asarray(values, dtype=float)
    if x.ndim != 1 or x.size == 0 or not np.all(np.isfinite(x)):
        raise ValueError("need one or more finite values")
    mean = float(x.mean())
    if x.size < 2:
        return MeanInterval(mean, -math.inf, math.inf, 1, level)
    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return MeanInterval(mean, mean - half, mean + half, int(x.size), level)


def random_draws(feasible: Sequence[int], seed: int, effects: str, n: int) -> list[int]:
    """``n`` of the ``feasible`` pool indices drawn at random for the draw of effect set
    ``effects`` and ``seed``: seeded by both, so the draws of one seed are judged against
    different random flights (before session 15's end the generator was seeded by the
    seed alone, ``default_rng(1000 + seed)``, and every effect set of a seed flew the
    same random candidate)."""
    rng = np.random.default_rng([1000 + seed, zlib.crc32(effects.encode())])
    return [int(k) for k in rng.permutation(np.asarray(feasible))[:n]]


def seed_interval(
    values: Sequence[float], seeds: Sequence[int], level: float = 0.95
) -> MeanInterval:
    """Mean of the per-seed means of ``values`` (n,) with the t-interval over the seeds
    (``n`` of the result: the number of seeds). The draws of one seed share their task
    flights, the candidate pool and the random candidate's index, so they are not
    independent; an interval over the seeds does not assume they are."""
    x, s = np.asarray(values, dtype=float), np.asarray(seeds)
    if x.shape != s.shape:
        raise ValueError(f"lengths differ: {x.size} values, {s.size} seeds")
    return mean_interval([float(x[s == k].mean()) for k in sorted(set(s.tolist()))], level)


def spearman(a: Sequence[float], b: Sequence[float]) -> float:
    """Spearman rank correlation of two equally long sequences (NaN if undefined)."""
    if len(a) != len(b):
        raise ValueError(f"lengths differ: {len(a)} and {len(b)}")
    if len(a) < 3 or np.ptp(np.asarray(a, float)) == 0 or np.ptp(np.asarray(b, float)) == 0:
        return math.nan
    return float(stats.spearmanr(a, b).statistic)
