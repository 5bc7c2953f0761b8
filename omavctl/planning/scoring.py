"""Scoring simulated flights: which points a flight would add, and what they are worth.

The planner's cost of a candidate is the paper's: the posterior variance
integrated over the task region (mean over the S test points and the three
axes) after adding the points ``fit`` would pick from the flight, averaged
over the M simulations. Two ways to pick the points:

* ``kmedoids`` (reference): :func:`omavctl.learn.points.select_points` per simulation,
  exactly what ``fit`` does; about 25 ms per simulation in a Python loop.
* ``batched`` (default): all simulations at once: medoids evenly spaced in
  time, then two steps of the alternating k-medoids update (assign to the
  nearest medoid; a cluster's new medoid is its member closest to the cluster
  mean, which minimises the summed squared distances), as batched matrix
  products and one sort. With the default 40 points its cost ranks
  candidates like the k-medoids cost (Spearman 0.96-0.97 measured,
  ``tests/test_plan_fast.py`` asserts >= 0.95); with few points per flight
  (20 of 200 samples) it drops to about 0.90: use ``kmedoids`` there. Greedy
  farthest-point selection reached only 0.92; BUILD on a subsample was
  slower and no better.

The band the cost integrates is the model's (:meth:`GPAxes.band_variance`): the
posterior variance times fit's ``latent_scale``, plus the variance beyond the
training inputs' box (``beyond_scale``), which a flight's points shrink by
widening the box (:func:`beyond_variance`).

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

from omavctl.learn.validation import beyond_reach
from omavctl.planning.gp import GPAxes

__all__ = [
    "Flights",
    "Objective",
    "VarianceObjective",
    "batched_pick_indices",
    "batched_picks",
    "beyond_variance",
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
    from omavctl.learn.points import select_points

    out = np.empty((inputs.shape[0], points, inputs.shape[2]))
    for b in range(inputs.shape[0]):
        z = np.asarray(inputs[b], float)
        k = min(points, z.shape[0])
        chosen = z[select_points(z, k, seed=seed)[0]]
        out[b] = np.resize(chosen, (points, z.shape[1]))
    return out


def _refine(x: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """One alternating k-medoids step: x (b, Ts, d) float32, medoid indices idx (b, k) -> (b, k).

    Assignment to the nearest medoid by one batched GEMM of augmented rows
    (``argmin_j |c_j|^2 - 2 x.c_j``); cluster means by bincount; the new medoid
    of a cluster is its member nearest the mean (argmin found by one sort of
    (cluster, distance) keys); empty clusters keep their medoid.
    """
    b, n, d = x.shape
    k = idx.shape[1]
    rows = np.arange(b)[:, None]
    c = x[rows, idx]  # (b, k, d)
    aug_x = np.concatenate([x, np.ones((b, n, 1), x.dtype)], axis=2)
    aug_c = np.concatenate([-2.0 * c, (c * c).sum(axis=2, keepdims=True)], axis=2)
    assign = (aug_x @ aug_c.swapaxes(1, 2)).argmin(axis=2)  # (b, n)
    group = (rows * k + assign).ravel()
    count = np.bincount(group, minlength=b * k)
    mean = (
        np.stack(
            [np.bincount(group, weights=x[..., j].ravel(), minlength=b * k) for j in range(d)],
            axis=1,
        )
        / np.maximum(count, 1)[:, None]
    )
    dist = ((x.reshape(-1, d) - mean[group]) ** 2).sum(axis=1)
    order = np.lexsort((dist, group))  # by cluster, nearest the mean first
    first = np.ones(order.size, bool)
    first[1:] = group[order[1:]] != group[order[:-1]]
    out = idx.copy().ravel()
    out[group[order[first]]] = order[first] % n
    return out.reshape(b, k)


def batched_pick_indices(
    inputs: np.ndarray, points: int, steps: int = 2, chunk: int = 512
) -> np.ndarray:
    """(B, k) sorted sample indices of the points of every simulation (B, Ts, d), k =
    min(points, Ts): medoids evenly spaced in time along the flight (k-medoids places
    them by density, and a flight's density is its time), then ``steps`` alternating
    k-medoids steps (module docstring)."""
    n_sets, n_samples, _ = inputs.shape
    k = min(points, n_samples)
    out = np.empty((n_sets, k), np.intp)
    start = ((np.arange(k) + 0.5) * n_samples / k).astype(np.intp)
    for lo in range(0, n_sets, chunk):
        x = np.asarray(inputs[lo : lo + chunk], np.float32)
        idx = np.broadcast_to(start, (x.shape[0], k)).copy()
        for _ in range(steps):
            idx = _refine(x, idx)
        idx.sort(axis=1)
        out[lo : lo + x.shape[0]] = idx
    return out


def batched_picks(inputs: np.ndarray, points: int, steps: int = 2, chunk: int = 512) -> np.ndarray:
    """(B, points, d) points of every simulation (B, Ts, d) at
    :func:`batched_pick_indices`. Fewer samples than points: padded by repetition."""
    n_sets, _, d = inputs.shape
    idx = batched_pick_indices(inputs, points, steps, chunk)
    out = np.empty((n_sets, points, d))
    for lo in range(0, n_sets, chunk):
        b = min(chunk, n_sets - lo)
        rows = np.arange(lo, lo + b)[:, None]
        chosen = np.asarray(inputs[rows, idx[lo : lo + b]], float)
        out[lo : lo + b] = np.resize(chosen, (b, points, d)) if idx.shape[1] < points else chosen
    return out


def _kernel(gp: GPAxes, a: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """k_a(x, y) (r, s) for x (r, d), y (s, d): one GEMM of augmented rows, one exp, in place."""
    xl, yl = x / gp.length_scales[a], y / gp.length_scales[a]
    left = np.empty((x.shape[0], gp.d + 2))
    right = np.empty((y.shape[0], gp.d + 2))
    left[:, : gp.d], left[:, gp.d], left[:, gp.d + 1] = xl, -0.5 * (xl * xl).sum(axis=1), 1.0
    right[:, : gp.d], right[:, gp.d], right[:, gp.d + 1] = yl, 1.0, -0.5 * (yl * yl).sum(axis=1)
    out = left @ right.T
    np.minimum(out, 0.0, out=out)
    np.exp(out, out=out)
    out *= gp.signal_variance[a]
    return out


def _axis_terms(gp: GPAxes, a: int, test: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """L^-1 (n, n), A = L^-1 K_ZS (n, S) and the mean prior variance at S."""
    l_inv = solve_triangular(gp.chol[a], np.eye(gp.n), lower=True)
    a_zs = l_inv @ gp.kernel(a, gp.inputs, test)
    prior = gp.signal_variance[a] - np.einsum("ns,ns->s", a_zs, a_zs)
    return l_inv, a_zs, float(np.maximum(prior, 0.0).mean())


def integrated_variance(
    gp: GPAxes, picks: np.ndarray, test: np.ndarray, chunk: int = 128
) -> np.ndarray:
    """Mean posterior variance (B,) over test (S, d) and axes after adding picks (B, m, d),
    each axis' times its ``latent_scale``.

    Rank-m update (module docstring), float64 throughout: the posterior
    variance is orders of magnitude below the prior (``C`` is a small difference
    of large terms, and ``L^-1`` is ill-conditioned), float32 loses 1e-3 of it. Agrees
    with ``posterior_variance_with_data(gp, picks, test).mean(axis=(1, 2))``
    to about 1e-5 relative (``tests/test_plan_fast.py``).
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
            b1 = l_inv @ _kernel(gp, a, gp.inputs, flat)  # (n, b m)
            b1_sets = b1.T.reshape(b, m, -1)
            q = gp.kernel(a, x, x) + noise * eye - b1_sets @ b1_sets.swapaxes(1, 2)
            c = _kernel(gp, a, flat, test)
            c -= b1.T @ a_zs  # (b m, S)
            c3 = c.reshape(b, m, s_count)
            cct = c3 @ c3.swapaxes(1, 2)
            gain = np.einsum("bii->b", np.linalg.solve(q, cct)) / s_count
            out[lo : lo + b] += gp.latent_scale[a] * np.maximum(prior - gain, 0.0)
    return out / 3.0


def beyond_variance(gp: GPAxes, picks: np.ndarray, test: np.ndarray, chunk: int = 64) -> np.ndarray:
    """Mean variance (B,) beyond the training box over test (S, d) and axes after
    adding picks (B, m, d): the box grows to hold the picks.

    The second part of the model's band (:meth:`GPAxes.band_variance`): a flight
    that goes where the task goes beyond the training inputs shrinks it, however
    well the inputs inside the box are covered already.
    """
    out = np.zeros(picks.shape[0])
    if not np.any(gp.beyond_scale * gp.signal_variance > 0):
        return out
    for lo in range(0, picks.shape[0], chunk):
        x = picks[lo : lo + chunk]
        box_lo = np.minimum(gp.box[0], x.min(axis=1))[:, None, :]  # (b, 1, d)
        box_hi = np.maximum(gp.box[1], x.max(axis=1))[:, None, :]
        for a in range(3):
            weight = gp.beyond_scale[a] * gp.signal_variance[a]
            if weight > 0:
                reach = beyond_reach(test[None], box_lo, box_hi, gp.length_scales[a])
                out[lo : lo + x.shape[0]] += weight * reach.mean(axis=1)
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
        return batched_picks(inputs, self.points)

    def __call__(self, flights: Flights) -> np.ndarray:
        k_count, m_count, steps, d = flights.inputs.shape
        flat = flights.inputs.reshape(k_count * m_count, steps, d)
        return self.cost_of_points(self.picks(flat)).reshape(k_count, m_count)

    def cost_of_points(self, picks: np.ndarray) -> np.ndarray:
        """Cost (B,) of sets of new training points picks (B, m, d): the model's mean
        latent band over the task region once they are in (posterior variance, then
        the variance beyond the training box, which they may widen)."""
        cost = integrated_variance(self.gp, picks, self.test)
        return cost + beyond_variance(self.gp, picks, self.test)
