"""Scoring simulated flights: which points a flight would add, and what they are worth.

The planner's cost of a candidate is the paper's: the posterior variance
integrated over the task region (mean over the S test points and the three
axes) after adding the points ``fit`` would pick from the flight, averaged
over the M simulations. Two ways to pick the points:

* ``kmedoids`` (reference): :func:`omavctl.fit.select_points` per simulation,
  exactly what ``fit`` does; about 25 ms per simulation in a Python loop.
* ``batched`` (default): all simulations at once: greedy farthest-point
  selection started at the medoid, then ``refine`` steps of the alternating
  k-medoids update (assign to the nearest medoid; a cluster's new medoid is
  its member closest to the cluster mean, which minimises the summed squared
  distances), all as batched matrix products. Its cost ranks candidates like
  the k-medoids cost (Spearman >= 0.95, ``tests/test_plan_fast.py``).

The value of the points, :func:`integrated_variance`, is a rank-m update of
the prior posterior without refitting, reduced to the integrated variance:
with ``A = L^-1 K_ZS`` (prior data Z, test points S, ``L L^T = K_ZZ +
sigma^2 I``), per set of points X: ``B = L^-1 K_ZX``, ``C = K_XS - B^T A``,
``Q = K_XX + sigma^2 I - B^T B`` and

    mean_s var(s | Z, X) = mean_s var(s | Z) - tr(Q^-1 C C^T) / S

so only m x m matrices are solved per set (never S x S, never a refit).

Objectives are pluggable: an objective maps the batch of simulated flights
(:class:`Flights`) to a cost per simulation (K, M); lower is better.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular

from omavctl.planning.gp import GPAxes

__all__ = [
    "Flights",
    "Objective",
    "VarianceObjective",
    "farthest_point_picks",
    "integrated_variance",
    "kmedoids_picks",
]


@dataclass
class Flights:
    """Simulated flights of K candidates x M samples, what objectives may use.

    inputs (K, M, Ts, d) normalised GP inputs at every ``stride``-th control
    step; tracking (K, M) mean |a* - omega_dot| (rad/s^2); feasible (K, M).
    """

    inputs: np.ndarray
    tracking: np.ndarray
    feasible: np.ndarray


#: An objective: cost (K, M) of every simulation (lower = better; inf allowed).
Objective = Callable[[Flights], np.ndarray]


def kmedoids_picks(inputs: np.ndarray, points: int, seed: int) -> np.ndarray:
    """(B, points, d) k-medoids of every simulation's inputs (B, Ts, d), as ``fit`` picks.

    Fewer samples than points: padded by repetition (adds no information beyond noise).
    """
    from omavctl.fit import select_points

    out = np.empty((inputs.shape[0], points, inputs.shape[2]))
    for b in range(inputs.shape[0]):
        z = np.asarray(inputs[b], float)
        k = min(points, z.shape[0])
        chosen = z[select_points(z, k, seed=seed)[0]]
        out[b] = np.resize(chosen, (points, z.shape[1]))
    return out


def _sq_to(x: np.ndarray, x2: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Squared distances (b, Ts, k) of x (b, Ts, d) (norms x2 (b, Ts)) to c (b, k, d)."""
    d2 = x2[:, :, None] + np.einsum("bkd,bkd->bk", c, c)[:, None, :] - 2.0 * x @ c.swapaxes(1, 2)
    return np.maximum(d2, 0.0)


def _refine(x: np.ndarray, x2: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """One alternating k-medoids step on medoid indices idx (b, k) into x (b, Ts, d)."""
    b, _, k = *x.shape[:2], idx.shape[1]
    rows = np.arange(b)[:, None]
    assign = _sq_to(x, x2, x[rows, idx]).argmin(axis=2)  # (b, Ts)
    onehot = (assign[:, :, None] == np.arange(k)).astype(x.dtype)  # (b, Ts, k)
    count = onehot.sum(axis=1)  # (b, k)
    centre = onehot.swapaxes(1, 2) @ x / np.maximum(count, 1.0)[:, :, None]
    own = np.take_along_axis(centre, assign[:, :, None], axis=1)  # (b, Ts, d)
    dist = ((x - own) ** 2).sum(axis=2)
    masked = np.where(onehot > 0, dist[:, :, None], np.inf)
    best = masked.argmin(axis=1)  # (b, k)
    return np.where(count > 0, best, idx)


def farthest_point_picks(
    inputs: np.ndarray, points: int, refine: int = 2, chunk: int = 256
) -> np.ndarray:
    """(B, points, d) points of every simulation (B, Ts, d), batched (module docstring).

    Greedy farthest-point selection from the sample nearest the mean, then
    ``refine`` alternating k-medoids steps. Fewer samples than points: padded by
    repetition.
    """
    n_sets, n_samples, d = inputs.shape
    k = min(points, n_samples)
    out = np.empty((n_sets, points, d))
    for lo in range(0, n_sets, chunk):
        x = np.asarray(inputs[lo : lo + chunk], np.float32)
        b = x.shape[0]
        rows = np.arange(b)
        x2 = np.einsum("btd,btd->bt", x, x)
        centre = x.mean(axis=1)
        idx = np.empty((b, k), np.intp)
        idx[:, 0] = (x2 - 2.0 * np.einsum("btd,bd->bt", x, centre)).argmin(axis=1)
        dmin = np.full((b, n_samples), np.inf, np.float32)
        for j in range(1, k):
            c = x[rows, idx[:, j - 1]]
            dist = x2 + np.einsum("bd,bd->b", c, c)[:, None] - 2.0 * np.einsum("btd,bd->bt", x, c)
            np.minimum(dmin, dist, out=dmin)
            idx[:, j] = dmin.argmax(axis=1)
        for _ in range(refine):
            idx = _refine(x, x2, idx)
        idx.sort(axis=1)
        chosen = np.asarray(inputs[lo : lo + chunk], float)[rows[:, None], idx]
        out[lo : lo + b] = np.resize(chosen, (b, points, d)) if k < points else chosen
    return out


def _axis_terms(gp: GPAxes, a: int, test: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """L^-1 (n, n), A = L^-1 K_ZS (n, S) and the mean prior variance at the test points."""
    l_inv = solve_triangular(gp.chol[a], np.eye(gp.n), lower=True)
    a_zs = l_inv @ gp.kernel(a, gp.inputs, test)
    prior = gp.signal_variance[a] - np.einsum("ns,ns->s", a_zs, a_zs)
    return l_inv, a_zs, float(np.maximum(prior, 0.0).mean())


def integrated_variance(
    gp: GPAxes, picks: np.ndarray, test: np.ndarray, chunk: int = 128
) -> np.ndarray:
    """Mean posterior variance (B,) over test (S, d) and axes after adding picks (B, m, d).

    Rank-m update (module docstring), float64; equal to
    ``posterior_variance_with_data(gp, picks, test).mean(axis=(1, 2))`` up to
    rounding where the posterior variance stays positive.
    """
    n_sets, m, d = picks.shape
    s_count = test.shape[0]
    out = np.zeros(n_sets)
    eye = np.eye(m)
    for a in range(3):
        if gp.signal_variance[a] <= 0:  # GP switched off on this axis: no variance
            continue
        l_inv, a_zs, prior = _axis_terms(gp, a, test)
        noise = gp.noise_variance[a]
        for lo in range(0, n_sets, chunk):
            x = picks[lo : lo + chunk]
            b = x.shape[0]
            flat = x.reshape(-1, d)
            b1 = (l_inv @ gp.kernel(a, gp.inputs, flat)).T.reshape(b, m, -1)  # (b, m, n)
            q = gp.kernel(a, x, x) + noise * eye - b1 @ b1.swapaxes(1, 2)
            c = gp.kernel(a, flat, test) - b1.reshape(b * m, -1) @ a_zs  # (b m, S)
            c = c.reshape(b, m, s_count)
            cct = c @ c.swapaxes(1, 2)
            gain = np.einsum("bii->b", np.linalg.solve(q, cct)) / s_count
            out[lo : lo + b] += np.maximum(prior - gain, 0.0)
    return out / 3.0


class VarianceObjective:
    """The paper's cost: integrated posterior variance after each flight's points.

    gp the current model's GPs; test (S, d) the task region's test points;
    ``points`` per flight; ``selection`` ``"batched"`` or ``"kmedoids"``.
    """

    def __init__(
        self, gp: GPAxes, test: np.ndarray, points: int, selection: str = "batched", seed: int = 0
    ) -> None:
        if selection not in ("batched", "kmedoids"):
            raise ValueError(f"unknown selection '{selection}'")
        self.gp, self.test, self.points = gp, test, points
        self.selection, self.seed = selection, seed

    def picks(self, inputs: np.ndarray) -> np.ndarray:
        """Points (B, points, d) of flights inputs (B, Ts, d)."""
        if self.selection == "kmedoids":
            return kmedoids_picks(inputs, self.points, self.seed)
        return farthest_point_picks(inputs, self.points)

    def __call__(self, flights: Flights) -> np.ndarray:
        k_count, m_count, steps, d = flights.inputs.shape
        flat = flights.inputs.reshape(k_count * m_count, steps, d)
        cost = integrated_variance(self.gp, self.picks(flat), self.test)
        return cost.reshape(k_count, m_count)
