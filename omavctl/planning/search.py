"""How candidates are proposed: random sampling or the cross-entropy method.

Random (the paper): all K candidates drawn uniformly at once
(:func:`~omavctl.planning.candidates.sample_coefficients`).

Cross-entropy method (``--search cem``): the same budget of K candidates x M
simulations spent in G generations. Generation 0 is drawn uniformly like the
random search; each next generation is drawn from a diagonal Gaussian over
the 3 * 2 * P Fourier coefficients fitted to the elite (lowest-cost feasible)
candidates so far, smoothed with the previous Gaussian, its standard
deviation kept above a floor, and clipped to the same bounds (frequencies in
[min_freq, max_freq] Hz, magnitudes in [-amplitude, amplitude] rad/s^2).
Infeasible candidates (cost inf) are never elite, so the search stays among
feasible references. All generations share the posterior samples and test
points (common random numbers): costs are comparable across generations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CrossEntropy", "generation_sizes"]


def generation_sizes(total: int, generations: int) -> list[int]:
    """Split ``total`` candidates into at most ``generations`` near-equal generations
    of at least 4 candidates each (fewer generations when the budget is small)."""
    g = max(1, min(generations, total // 4))
    base, extra = divmod(total, g)
    return [base + (1 if i < extra else 0) for i in range(g)]


@dataclass
class CrossEntropy:
    """Diagonal Gaussian over flattened coefficients (12 for P = 2), in bounds.

    low, high (C,) bounds per coefficient; elite fraction of the feasible
    candidates so far; smoothing weight of the new fit; floor on the std as a
    fraction of the range.
    """

    low: np.ndarray
    high: np.ndarray
    elite: float = 0.1
    smoothing: float = 0.7
    floor: float = 0.02
    mean: np.ndarray | None = None
    std: np.ndarray | None = None

    @classmethod
    def for_bounds(
        cls, frequencies: int, min_freq: float, max_freq: float, amplitude: float
    ) -> CrossEntropy:
        """Bounds in the layout of :func:`sample_coefficients` (3, P, 2) flattened."""
        low = np.empty((3, frequencies, 2))
        high = np.empty((3, frequencies, 2))
        low[..., 0], high[..., 0] = min_freq, max_freq
        low[..., 1], high[..., 1] = -amplitude, amplitude
        return cls(low.reshape(-1), high.reshape(-1))

    def update(self, coeffs: np.ndarray, cost: np.ndarray) -> None:
        """Refit on all candidates so far: coeffs (N, 3, P, 2), cost (N,) (inf: infeasible)."""
        ok = np.isfinite(cost)
        if not ok.any():
            return
        flat = coeffs.reshape(coeffs.shape[0], -1)[ok]
        n_elite = max(2, int(np.ceil(self.elite * ok.sum())))
        elite = flat[np.argsort(cost[ok], kind="stable")[:n_elite]]
        mean, std = elite.mean(axis=0), elite.std(axis=0)
        if self.mean is None or self.std is None:
            self.mean, self.std = mean, std
        else:
            a = self.smoothing
            self.mean = a * mean + (1 - a) * self.mean
            self.std = a * std + (1 - a) * self.std
        self.std = np.maximum(self.std, self.floor * (self.high - self.low))

    def sample(self, rng: np.random.Generator, n: int, shape: tuple[int, ...]) -> np.ndarray:
        """n candidates (n, *shape) from the current Gaussian, clipped to the bounds."""
        assert self.mean is not None and self.std is not None
        draw = self.mean + self.std * rng.standard_normal((n, self.mean.size))
        return np.clip(draw, self.low, self.high).reshape(n, *shape)
