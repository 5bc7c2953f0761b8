"""k-medoids (omavctl.learn.kmedoids, points.select_points): PAM quality, determinism, and the
same points under NumPy 1 and NumPy 2 (.ci/run runs this file in both environments)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from omavctl.learn import points as points_module
from omavctl.learn.kmedoids import kmedoids
from omavctl.learn.points import _cost, select_points


def curve(n: int) -> np.ndarray:
    """A deterministic 6-D point cloud (no random generator, so no version can change it)."""
    i = np.arange(n, dtype=np.float64)
    return np.stack(
        [
            np.sin(0.37 * i),
            np.cos(0.11 * i),
            np.sin(0.05 * i) * np.cos(0.7 * i),
            0.5 * np.sin(0.013 * i * i % 7.0),
            np.cos(0.023 * i) ** 3,
            (i % 17) / 17.0 - 0.5,
        ],
        axis=1,
    )


# Selected under NumPy 1.26.4 and 2.4.6 (rustpam 0.2.1): the same indices. A change
# here means fits on the same logs pick other training points than before.
GOLDEN_DIRECT = [7, 49, 57, 66, 77, 129, 179, 267, 307, 361, 368, 393]
GOLDEN_SUBSAMPLED = [19, 61, 129, 393, 495, 567, 609, 721, 779, 792]


def test_same_points_as_recorded_direct():
    idx, how = select_points(curve(400), 12, seed=0)
    assert idx.tolist() == GOLDEN_DIRECT
    assert how == "k-medoids on all 400 samples"


def test_same_points_as_recorded_subsampled(monkeypatch):
    monkeypatch.setattr(points_module, "KMEDOIDS_MAX_DIRECT", 300)
    monkeypatch.setattr(points_module, "KMEDOIDS_SUBSAMPLE", 200)
    idx, how = select_points(curve(900), 10, seed=3)
    assert idx.tolist() == GOLDEN_SUBSAMPLED
    assert "3 seeded subsamples of 200 of 900" in how


def test_no_single_swap_improves_the_objective():
    """PAM's fixed point: swapping any medoid for any other sample does not lower the cost."""
    x = curve(70)
    medoids = kmedoids(x, 5, seed=1)
    best = _cost(x, x[medoids])
    for pos, cand in itertools.product(range(5), range(70)):
        if cand in medoids:
            continue
        trial = medoids.copy()
        trial[pos] = cand
        assert _cost(x, x[trial]) >= best * (1 - 1e-5)


def test_one_medoid_per_separated_cluster():
    rng = np.random.default_rng(4)
    centres = 10.0 * np.eye(6)[:5]
    x = np.concatenate([c + 0.1 * rng.standard_normal((40, 6)) for c in centres])
    medoids = kmedoids(x, 5, seed=0)
    assert sorted(int(m) // 40 for m in medoids) == [0, 1, 2, 3, 4]


def test_seed_reproduces_and_result_is_valid():
    x = curve(300)
    a, b = kmedoids(x, 20, seed=7), kmedoids(x, 20, seed=7)
    assert a.dtype == np.int64 and np.array_equal(a, b)
    assert len(np.unique(a)) == 20 and a.min() >= 0 and a.max() < 300


def test_bad_k():
    with pytest.raises(ValueError, match="cannot select"):
        kmedoids(curve(10), 11)
    with pytest.raises(ValueError, match="cannot select"):
        kmedoids(curve(10), 0)


def test_several_logs_keep_each_logs_own_points():
    # two logs far apart in input space: pooled k-medoids gives the wide second one most
    # of the points; per log, the first keeps exactly the points a fit on it alone picks
    from omavctl.learn.points import normalisation, select_points_per_log

    first, second = curve(300), 5.0 * curve(400)[::-1] + 3.0
    x = np.concatenate([first, second])
    idx, how = select_points_per_log(x, [300, 400], 12, seed=0)
    alone, _ = select_points((first - normalisation(first)[0]) / normalisation(first)[1], 12)
    assert idx[:12].tolist() == alone.tolist()
    assert idx.size == 24 and np.all(idx[12:] >= 300)
    assert how.startswith("per log, up to 12 points each (log 1: k-medoids on all 300")
    # three logs share twice the budget; a log shorter than its share gives all its samples
    idx3, _ = select_points_per_log(np.concatenate([x, curve(5)]), [300, 400, 5], 12)
    assert np.bincount(np.searchsorted([300, 700, 705], idx3, side="right")).tolist() == [8, 8, 5]
    with pytest.raises(ValueError, match=r"log lengths \[300, 300\] do not add up to 700"):
        select_points_per_log(x, [300, 300], 12)
