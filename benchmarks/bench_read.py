"""Reading speed: ``omavctl.logs.read_raw`` against bare rosbags iteration.

Writes a 60 s log (imu at 200 Hz, the five other contract topics at 100 Hz:
42 006 messages) as a ROS 2 bag (mcap storage) and a ROS 1 bag in a temporary
directory, then times, over the same file:

- ``bare``: ``rosbags.highlevel.AnyReader`` iterating every message and
  deserialising it (the floor any rosbags-based reader pays);
- ``read_raw``: the same plus stamp selection, signal extraction, topic
  statistics.

Run: ``python benchmarks/bench_read.py [--repeat N]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from omavctl.logs import ROLE_COLUMNS, RawLog, RawSeries, read_raw, write_log

DURATION = 60.0


def synthetic(duration: float = DURATION) -> RawLog:
    """Every contract role; imu at 200 Hz, the rest at 100 Hz."""
    t200 = np.arange(round(duration * 200) + 1) * 5_000_000 / 1e9
    t100 = np.arange(round(duration * 100) + 1) * 10_000_000 / 1e9
    series = {}
    for i, (role, cols) in enumerate(ROLE_COLUMNS.items()):
        t = t200 if role == "body_rate" else t100
        k = np.arange(len(cols))
        series[role] = RawSeries(t, 0.5 * np.sin(np.outer(t, 1.0 + k) + i))
    return RawLog(path=Path("bench"), format="synthetic", t0=1.7e9, series=series)


def bare(path: Path) -> int:
    """Iterate and deserialise every message with AnyReader; returns the count."""
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([path]) as reader:
        for conn, _, data in reader.messages():
            reader.deserialize(data, conn.msgtype)
            n += 1
    return n


def ours(path: Path) -> int:
    raw = read_raw(path)
    return sum(t.count for t in raw.topics)


def best_of(fn: Callable[[Path], int], path: Path, repeat: int) -> tuple[float, int]:
    best, n = float("inf"), 0
    for _ in range(repeat):
        start = time.perf_counter()
        n = fn(path)
        best = min(best, time.perf_counter() - start)
    return best, n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement (best kept)")
    args = parser.parse_args()
    raw = synthetic()
    with tempfile.TemporaryDirectory() as tmp:
        files = {"ROS 2 bag (mcap)": Path(tmp) / "flight", "ROS 1 bag": Path(tmp) / "flight.bag"}
        for path in files.values():
            start = time.perf_counter()
            write_log(path, raw)
            print(f"wrote {path.name}: {time.perf_counter() - start:.2f} s")
        print(
            f"{'file':<18} {'messages':>8} {'bare msg/s':>11} {'read_raw msg/s':>15} {'ratio':>6}"
        )
        for label, path in files.items():
            t_bare, n_bare = best_of(bare, path, args.repeat)
            t_ours, n_ours = best_of(ours, path, args.repeat)
            assert n_bare == n_ours, (n_bare, n_ours)
            print(
                f"{label:<18} {n_bare:>8} {n_bare / t_bare:>11,.0f} {n_ours / t_ours:>15,.0f} "
                f"{t_bare / t_ours:>6.2f}"
            )
        print("ratio = read_raw speed / bare speed (1.0 = no overhead over rosbags)")


if __name__ == "__main__":
    main()
