"""k-medoids libraries compared on the inputs of a 30-flight fit.

Run: python benchmarks/bench_kmedoids.py [--save X.npy | --load X.npy] [BACKEND ...]
(simulating the flights takes about 1 minute on 2 cores; each backend a few s)

The 30 logs are those of ``bench_fit.py`` (three simulated 60 s figure-8
flights, fresh gyro and command noise per copy). ``fit_model`` is run up to
its training-point step and the normalised GP inputs it hands to
:func:`omavctl.learn.points.select_points` are kept (``--save`` writes them, ``--load``
reads them instead of simulating, so that environments with different NumPy
versions compare on the same matrix).

For every backend importable here, two cases with 200 points, seed 0:

* ``clara``: ``select_points`` on all samples (3 seeded subsamples of 2000,
  what ``fit`` does for 30 flights), the backend as its k-medoids step;
* ``direct``: one k-medoids run on the first 3000 samples (the largest direct
  case, what ``fit`` does for one short flight and ``plan`` for its stride
  samples).

Printed per case: wall and CPU time of the selection (CPU time is the steadier
one on a shared machine), the k-medoids objective (sum over
*all* samples of the case of the squared Euclidean distance to the nearest
medoid; lower is better) and its ratio to the best backend.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from omavctl.learn import fit as fit_module
from omavctl.learn import fit_steps
from omavctl.learn import points as points_module

POINTS = 200
N_LOGS = 30
DIRECT = 3000

Backend = Callable[[np.ndarray, int, int], np.ndarray]


class _Captured(Exception):
    def __init__(self, x: np.ndarray) -> None:
        super().__init__("captured")
        self.x = x


def fit_inputs() -> np.ndarray:
    """The normalised GP inputs (n, 6) of the 30-log fit of ``bench_fit.py``."""
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_fit import _flights, _variant

    base = _flights()
    rng = np.random.default_rng(0)
    logs = [_variant(base[k % len(base)], k, rng) for k in range(N_LOGS)]
    original = fit_steps.select_points

    def capture(x: np.ndarray, k: int, seed: int = 0) -> tuple[np.ndarray, str]:
        raise _Captured(x.copy())

    fit_steps.select_points = capture  # type: ignore[assignment]
    try:
        fit_module.fit_model(logs, seed=0)
    except _Captured as c:
        return c.x
    finally:
        fit_steps.select_points = original  # type: ignore[assignment]
    raise RuntimeError("fit_model did not reach select_points")


def _sq(x: np.ndarray) -> np.ndarray:
    return points_module._sq_dist(x, x)


def _sklearn_extra(method: str) -> Backend:
    def run(x: np.ndarray, k: int, seed: int) -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from sklearn_extra.cluster import KMedoids

            km = KMedoids(k, metric="precomputed", method=method, init="build", max_iter=300)
            return np.asarray(km.fit(_sq(x)).medoid_indices_)

    return run


def _banditpam(algorithm: str) -> Backend:
    def run(x: np.ndarray, k: int, seed: int) -> np.ndarray:
        import banditpam

        km = banditpam.KMedoids(n_medoids=k, algorithm=algorithm)
        km.seed = seed
        d = _sq(x).astype(np.float32)
        km.fit(x.astype(np.float32), "L2", dist_mat=d)
        return np.asarray(km.medoids, dtype=np.int64)

    return run


def _rustpam_defaults(x: np.ndarray, k: int, seed: int) -> np.ndarray:
    """rustpam with its default batch and swap cap (omavctl.learn.kmedoids lifts both)."""
    from rustpam import OneBatchPAM

    # distance="precomputed" fails in 0.2.1 (its labelling step reuses the matrix)
    km = OneBatchPAM(n_medoids=k, distance="sqeuclidean", random_state=seed, n_threads=1)
    return np.asarray(km.fit(x).medoid_indices_, dtype=np.int64)


_KMEDOIDS = points_module._kmedoids


def _omavctl(x: np.ndarray, k: int, seed: int) -> np.ndarray:
    """Whatever ``omavctl.learn.points._kmedoids`` calls in this checkout."""
    return np.asarray(_KMEDOIDS(x, k))


BACKENDS: dict[str, Backend] = {
    "omavctl": _omavctl,
    "sklearn-extra-alternate": _sklearn_extra("alternate"),
    "rustpam-defaults": _rustpam_defaults,
    "banditpam-FastPAM1": _banditpam("FastPAM1"),
    # slow: 16 s for 50 of 1000 samples, and the same for sklearn-extra's PAM
    "banditpam-BanditPAM": _banditpam("BanditPAM"),
    "sklearn-extra-pam": _sklearn_extra("pam"),
}
DEFAULT = ("omavctl", "sklearn-extra-alternate", "rustpam-defaults", "banditpam-FastPAM1")


def _clara(backend: Backend, x: np.ndarray) -> np.ndarray:
    original = points_module._kmedoids

    def step(sub: np.ndarray, k: int, *_: object) -> np.ndarray:
        return backend(sub, k, 0)

    points_module._kmedoids = step  # type: ignore[assignment]
    try:
        return points_module.select_points(x, POINTS, seed=0)[0]
    finally:
        points_module._kmedoids = original  # type: ignore[assignment]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("backends", nargs="*", default=list(DEFAULT), help=", ".join(BACKENDS))
    parser.add_argument("--save", type=Path)
    parser.add_argument("--load", type=Path)
    args = parser.parse_args()
    unknown = set(args.backends) - set(BACKENDS)
    if unknown:
        parser.error(f"unknown backends {sorted(unknown)}; known: {', '.join(BACKENDS)}")
    x = np.load(args.load) if args.load else fit_inputs()
    if args.save:
        np.save(args.save, x)
    print(f"numpy {np.__version__}; {x.shape[0]} samples x {x.shape[1]} inputs, {POINTS} points")
    cases = {"clara": (x, _clara), "direct": (x[:DIRECT], lambda b, xs: b(xs, POINTS, 0))}
    print(f"{'case':7} {'backend':26} {'time s':>7} {'cpu s':>7} {'objective':>12}  medoids")
    rows = []
    for name in args.backends:
        for case, (xs, run) in cases.items():
            try:
                start, cpu = time.perf_counter(), time.process_time()
                medoids = np.sort(np.asarray(run(BACKENDS[name], xs)))
                elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
            except ImportError as exc:
                print(f"{name}: not importable ({exc})")
                break
            assert len(np.unique(medoids)) == POINTS, name
            cost = points_module._cost(xs, xs[medoids])
            rows.append((case, name, cost))
            head = ",".join(str(i) for i in medoids[:4])
            print(
                f"{case:7} {name:26} {elapsed:7.2f} {cpu:7.2f} {cost:12.2f}  {head},...", flush=True
            )
    for case in cases:
        best = min(r[2] for r in rows if r[0] == case)
        ratios = ", ".join(f"{r[1]} {r[2] / best:.3f}" for r in rows if r[0] == case)
        print(f"{case}: objective / lowest: {ratios}")


if __name__ == "__main__":
    main()
