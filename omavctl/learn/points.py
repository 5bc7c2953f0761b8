"""Training-point selection for ``fit``: k-medoids on the normalised GP inputs.

:func:`select_points` picks the GP training points among every sample of the
new logs (squared Euclidean distance, as in the paper); above
:data:`KMEDOIDS_MAX_DIRECT` samples it clusters seeded subsamples instead of
building the n x n distance matrix. :func:`normalisation` is the per-column
mean and scale the inputs are normalised with. With several logs
:func:`select_points_per_log` picks each log's points among its own samples, so
that a second flight adds points beside the first one's instead of taking a share
of them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "KMEDOIDS_DRAWS",
    "KMEDOIDS_MAX_DIRECT",
    "KMEDOIDS_SUBSAMPLE",
    "LOGS_BUDGET",
    "normalisation",
    "select_points",
    "select_points_per_log",
]

#: Above this many samples k-medoids runs on seeded subsamples (CLARA-style):
#: the n x n float64 distance matrix of 3000 samples is 72 MB.
KMEDOIDS_MAX_DIRECT = 3000
#: Size of each subsample, and how many subsamples are tried.
KMEDOIDS_SUBSAMPLE = 2000
KMEDOIDS_DRAWS = 3
#: With several logs the training points total at most this many times ``points``
#: (each of two logs gets ``points``; more logs share the budget).
LOGS_BUDGET = 2


def _sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances (n, m) between rows of a (n, d) and b (m, d)."""
    d2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.maximum(d2, 0.0)


def _kmedoids(x: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Indices (k,) of k-medoids of x (n, d), squared Euclidean (:mod:`omavctl.learn.kmedoids`)."""
    from omavctl.learn.kmedoids import kmedoids

    return kmedoids(x, k, seed)


def _cost(x: np.ndarray, medoids: np.ndarray, chunk: int = 20000) -> float:
    """Sum over samples of the squared distance to the nearest medoid, in chunks (n x k)."""
    total = 0.0
    for start in range(0, x.shape[0], chunk):
        total += float(_sq_dist(x[start : start + chunk], medoids).min(axis=1).sum())
    return total


def select_points(x: np.ndarray, k: int, seed: int = 0) -> tuple[np.ndarray, str]:
    """Pick k training points among the rows of x (n, d) (normalised inputs) by k-medoids.

    Squared Euclidean distance (as in the paper); the library call is
    :func:`omavctl.learn.kmedoids.kmedoids` (eager-swap PAM, seeded random start).
    Above :data:`KMEDOIDS_MAX_DIRECT` samples no n x n matrix is built: like
    CLARA, :data:`KMEDOIDS_DRAWS` seeded subsamples of
    ``max(KMEDOIDS_SUBSAMPLE, 4 k)`` samples (each holding the best medoids so
    far) are clustered and the medoids with the lowest cost over all samples
    kept. Returns sorted indices (k,) and a description of the method.
    """
    n = x.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"cannot select {k} points from {n} samples")
    if k == n:
        return np.arange(n), "all samples"
    if n <= KMEDOIDS_MAX_DIRECT:
        return np.sort(_kmedoids(x, k, seed)), f"k-medoids on all {n} samples"
    size = min(n, max(KMEDOIDS_SUBSAMPLE, 4 * k))
    rng = np.random.default_rng(seed)
    best: np.ndarray | None = None
    best_cost = np.inf
    for _ in range(KMEDOIDS_DRAWS):
        if best is None:
            sub = np.sort(rng.choice(n, size=size, replace=False))
        else:
            rest = np.setdiff1d(np.arange(n), best)
            sub = np.sort(np.concatenate([best, rng.choice(rest, size=size - k, replace=False)]))
        medoids = sub[_kmedoids(x[sub], k, seed)]
        cost = _cost(x, x[medoids])
        if cost < best_cost:
            best, best_cost = medoids, cost
    assert best is not None
    return np.sort(best), (
        f"k-medoids on {KMEDOIDS_DRAWS} seeded subsamples of {size} of {n} samples"
    )


def normalisation(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column mean (d,) and scale (d,) of x (n, d); a constant column gets scale 1."""
    mean = x.mean(axis=0)
    std = x.std(axis=0)
    scale = np.where(std > 1e-9 * np.maximum(1.0, np.abs(mean)), std, 1.0)
    return mean, scale


def select_points_per_log(
    x: np.ndarray, lengths: Sequence[int], k: int, seed: int = 0
) -> tuple[np.ndarray, str]:
    """Training points of several logs: each log's own k-medoids among its own samples.

    x (n, d): the GP inputs (not normalised) of every sample, the logs' samples one
    after the other, ``lengths`` of them each (sum n). Each log's inputs are
    normalised by their own :func:`normalisation` and ``k`` of its samples picked by
    :func:`select_points` with ``seed``, exactly the points a fit on that log alone
    picks; with more than :data:`LOGS_BUDGET` logs each gets
    ``LOGS_BUDGET * k // len(lengths)`` (at least 1), and a log with fewer samples
    all of them. Why: one k-medoids over the pooled samples gave a deviated second
    flight 75 % of the points and the first flight's states a quarter, and the
    refitted model predicted the first flight's task worse than one refitted on the
    task flown again (docs/informative.md, session 16). Returns sorted indices
    (m,) into the pooled samples and a description of the method.
    """
    ends = np.cumsum(np.asarray(lengths, dtype=np.int64))
    if ends.size == 0 or ends[-1] != x.shape[0]:
        raise ValueError(f"log lengths {list(lengths)} do not add up to {x.shape[0]} samples")
    share = k if len(lengths) <= LOGS_BUDGET else max(1, LOGS_BUDGET * k // len(lengths))
    picks, methods = [], []
    for start, end in zip(ends - np.asarray(lengths), ends, strict=True):
        xi = x[start:end]
        mean, scale = normalisation(xi)
        idx, method = select_points((xi - mean) / scale, min(share, end - start), seed)
        picks.append(start + idx)
        methods.append(method)
    text = "; ".join(f"log {i + 1}: {m}" for i, m in enumerate(methods))
    return np.concatenate(picks), f"per log, up to {share} points each ({text})"
