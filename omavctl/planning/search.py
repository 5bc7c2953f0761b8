"""How candidates are proposed: random sampling or the cross-entropy method.

Random (the paper): all K candidates drawn uniformly at once
(:func:`~omavctl.planning.candidates.sample_coefficients`).

Cross-entropy method (``--search cem``): the same budget of K candidates x M
simulations spent in G generations. Generation 0 is drawn uniformly like the
random search; each next generation is drawn from a Gaussian mixture over the
3 * 2 * P Fourier coefficients with one component at each elite (lowest-cost
feasible) candidate so far (:class:`CrossEntropy`), clipped to the same bounds
(frequencies in [min_freq, max_freq] Hz, magnitudes in [-amplitude, amplitude]
rad/s^2).
Infeasible candidates (cost inf) are never elite, so the search stays among
feasible references. All generations share the posterior samples and test
points (common random numbers): costs are comparable across generations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MIN_GENERATION", "CrossEntropy", "generation_sizes"]


#: Fewest candidates per generation: with fewer, the uniform first generation is too
#: small to find the good ridges of 12 coefficients (the demo's 100 candidates: 8
#: generations of 12 ended 2.4 % worse than the task, 5 of 20 1.5 % better)
MIN_GENERATION = 20


def generation_sizes(total: int, generations: int) -> list[int]:
    """Split ``total`` candidates into at most ``generations`` near-equal generations
    of at least MIN_GENERATION candidates each (fewer generations when the budget
    is small; one, a random search, below twice that)."""
    g = max(1, min(generations, total // MIN_GENERATION))
    base, extra = divmod(total, g)
    return [base + (1 if i < extra else 0) for i in range(g)]


@dataclass
class CrossEntropy:
    """A Gaussian mixture over flattened coefficients (12 for P = 2), in bounds.

    One component per elite: the ``elites`` lowest-cost feasible candidates so far
    are the means, and all share one diagonal std, ``scale`` times the spread of the
    best ``spread`` candidates so far, at least ``floor`` of the range. low, high (C,)
    bounds per coefficient.

    Why a mixture and not the one Gaussian of the textbook method: the cost
    depends mostly on the deviation's angle, ``|A| / f^2`` per component, so good
    candidates lie on ridges with either sign of A. One Gaussian fitted to elites
    on different ridges puts its mean between them, where the cost is poor; on the
    24 s figure-8 it found higher costs than random sampling at the same budget in
    4 of 4 seeds (docs/planning-performance.md). Around each elite the search
    refines instead.
    """

    low: np.ndarray
    high: np.ndarray
    elites: int = 5
    spread: int = 10
    scale: float = 0.3
    floor: float = 0.02
    centres: np.ndarray | None = None
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
        order = np.argsort(cost[ok], kind="stable")
        self.centres = flat[order[: self.elites]]
        spread = flat[order[: max(self.spread, self.elites)]].std(axis=0)
        self.std = np.maximum(self.scale * spread, self.floor * (self.high - self.low))

    def sample(self, rng: np.random.Generator, n: int, shape: tuple[int, ...]) -> np.ndarray:
        """n candidates (n, *shape): a component drawn uniformly, then its Gaussian,
        clipped to the bounds."""
        assert self.centres is not None and self.std is not None
        parents = self.centres[rng.integers(0, self.centres.shape[0], size=n)]
        draw = parents + self.std * rng.standard_normal(parents.shape)
        return np.clip(draw, self.low, self.high).reshape(n, *shape)
