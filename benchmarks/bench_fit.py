"""Time and peak memory of ``fit`` for 1, 10 and 30 logs of 60 s each.

Run: python benchmarks/bench_fit.py [--repeat 5]   (about 2-3 minutes on 2 cores)

Three 60 s flights are simulated once (figure-8 tasks of different size and
period, default actuator imperfections); the 10- and 30-log cases reuse them
with fresh gyro and command noise per copy, so that no two logs are equal.
Logs are passed to :func:`omavctl.learn.fit.fit_model` already aligned (reading
files is benchmarked in ``bench_read.py``). Defaults otherwise: 200 points,
3 optimiser restarts, window 11.

``--repeat N`` then fits the 1-log case N more times and prints the min, median
and max wall time and their spread around the median (``fit`` sets BLAS to one
thread for its small matrices, so that repeated runs take the same time).

Peak memory is the tracemalloc peak of the fit (numpy buffers included); the
largest distance matrix built by k-medoids is recorded by wrapping
``omavctl.learn.points._sq_dist``: above ``KMEDOIDS_MAX_DIRECT`` samples it stays at
the subsample size, never n x n.
"""

from __future__ import annotations

import argparse
import resource
import time
import tracemalloc
from dataclasses import replace

import numpy as np

from omavctl.learn import fit as fit_module
from omavctl.learn import points as points_module
from omavctl.logs import FlightLog, align
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle

DURATION = 60.0
CASES = (1, 10, 30)


def _flights() -> list[FlightLog]:
    vehicle = default_vehicle()
    truth = truth_from_tree({}, vehicle)
    shapes = [(26.0, 26.0, 8.0), (20.0, 15.0, 5.0), (15.0, 25.0, 6.0)]
    out = []
    for i, (roll, pitch, period) in enumerate(shapes):
        ref = fig8(roll_deg=roll, pitch_deg=pitch, period=period, duration=DURATION, ramp=2.0)
        flight = align(simulate(ref, vehicle, truth, seed=0).log)
        out.append(replace(flight, path=flight.path.with_name(f"flight-{i}")))
    return out


def _variant(flight: FlightLog, k: int, rng: np.random.Generator) -> FlightLog:
    """The flight with fresh gyro noise (0.003 rad/s) and 1 % command noise."""
    sig = dict(flight.signals)
    sig["body_rate"] = sig["body_rate"] + 0.003 * rng.standard_normal(sig["body_rate"].shape)
    for role in ("force_command", "torque_command"):
        scale = 0.01 * sig[role].std(axis=0)
        sig[role] = sig[role] + scale * rng.standard_normal(sig[role].shape)
    return replace(flight, signals=sig, path=flight.path.with_name(f"{flight.path.name}-{k}"))


def _repeat(flight: FlightLog, times: int) -> None:
    """The 1-log fit ``times`` times: min, median, max wall time and the spread."""
    walls = []
    for _ in range(times):
        start = time.perf_counter()
        fit_module.fit_model([flight], seed=0)
        walls.append(time.perf_counter() - start)
    walls.sort()
    med = walls[len(walls) // 2]
    low, high = 100 * (walls[0] / med - 1), 100 * (walls[-1] / med - 1)
    print(
        f"1 log, {times} runs: min {walls[0]:.1f} s, median {med:.1f} s, max {walls[-1]:.1f} s "
        f"({low:+.0f} % / {high:+.0f} % of the median)"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=0, help="time the 1-log fit this often more")
    repeat = ap.parse_args().repeat
    t0 = time.perf_counter()
    base = _flights()
    print(f"simulated {len(base)} flights of {DURATION:g} s in {time.perf_counter() - t0:.1f} s")
    rng = np.random.default_rng(0)
    largest = [0]
    original = points_module._sq_dist

    def recording(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        largest[0] = max(largest[0], a.shape[0] * b.shape[0])
        return original(a, b)

    points_module._sq_dist = recording  # type: ignore[assignment]
    print(
        f"{'logs':>4} {'samples':>8} {'fit s':>7} {'k-medoids s':>11} {'GP s':>6} "
        f"{'peak MiB':>9} {'largest D':>12} {'n x n would be':>15}  selection"
    )
    for n_logs in CASES:
        logs = [_variant(base[k % len(base)], k, rng) for k in range(n_logs)]
        largest[0] = 0
        tracemalloc.start()
        start = time.perf_counter()
        result = fit_module.fit_model(logs, seed=0)
        elapsed = time.perf_counter() - start
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        s = result.summary
        n = s.samples
        side = round(float(np.sqrt(largest[0])))
        print(
            f"{n_logs:4d} {n:8d} {elapsed:7.1f} {s.timings['kmedoids']:11.2f} "
            f"{s.timings['gp']:6.1f} {peak / 2**20:9.0f} {f'{side}x{side}':>12} "
            f"{n * n * 8 / 2**30:12.1f} GiB  {s.kmedoids}"
        )
        assert largest[0] < n * n or n <= points_module.KMEDOIDS_MAX_DIRECT
    if repeat:
        _repeat(base[0], repeat)
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"process peak RSS {maxrss:.0f} MiB; total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
