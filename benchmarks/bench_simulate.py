"""Seconds to simulate 60 s of flight through the truth plant (1 kHz physics).

Run: python benchmarks/bench_simulate.py
"""

from __future__ import annotations

import time

from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import load_truth
from omavctl.vehicle import default_vehicle


def main() -> None:
    vehicle = default_vehicle()
    truth = load_truth(None, vehicle)
    ref = fig8(duration=60.0)
    start = time.perf_counter()
    result = simulate(ref, vehicle, truth, seed=0)
    elapsed = time.perf_counter() - start
    print(
        f"simulate 60 s fig8 at 1 kHz physics: {elapsed:.2f} s "
        f"({60.0 / elapsed:.1f}x real time, {result.steps} controller steps)"
    )


if __name__ == "__main__":
    main()
