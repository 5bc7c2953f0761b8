"""Does the 95 % interval hold the truth once the rotors' thrust spread is in it?

Vehicles of the project's simulator with its default 3 % rotor thrust spread (each
truth seed draws another spread), a hidden centre-of-mass offset drawn from N(0, 5 mm)
per horizontal component (and none on every third vehicle), flown on one of four
trajectory families; ``fit --effects com_offset`` (the library's ``fit_model``, 200
points, no restarts). Per component r_x, r_y: is the hidden value inside the reported
95 % interval (standard error and the spread's systematic part,
:mod:`omavctl.learn.spread`), and inside the flight's statistical interval alone?

    python benchmarks/spread_systematic.py --vehicles 24

Prints one line per flight and the coverage of both intervals with Wilson 95 %
intervals (docs/intervals.md, "The rotors' thrust spread").
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from omavctl.learn.fit import fit_model
from omavctl.logs import align
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import chirp, fig8, steps, wobble
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle

FAMILIES = {
    "wobble": lambda s: wobble(amplitude_deg=18.0, duration=16.0, seed=s),
    "steps": lambda s: steps(amplitude_deg=16.0, duration=16.0, seed=s),
    "fig8": lambda s: fig8(roll_deg=20, pitch_deg=20, period=6.0, duration=16.0, ramp=1.5),
    "chirp": lambda s: chirp(amplitude_deg=12.0, duration=16.0),
}


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson score 95 % interval of k/n."""
    if n == 0:
        return 0.0, 1.0
    z, p = 1.959963984540054, k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=24)
    ap.add_argument("--seed-base", type=int, default=500)
    args = ap.parse_args()
    vehicle = default_vehicle()
    fams = sorted(FAMILIES)
    total = {"reported": 0, "statistical": 0, "n": 0}
    for k in range(args.vehicles):
        seed = args.seed_base + k
        rng = np.random.default_rng([seed, 0x5EED])
        r = np.zeros(3)
        if k % 3:
            r[:2] = rng.normal(0.0, 0.005, 2)
        fam = fams[k % len(fams)]
        tree = (
            {"seed": seed, "effects": {"com_offset": {"r": r.tolist()}}}
            if k % 3
            else {"seed": seed}
        )
        start = time.process_time()
        log = align(
            simulate(FAMILIES[fam](seed), vehicle, truth_from_tree(tree, vehicle), seed=seed).log
        )
        with threadpool_limits(1):
            est = fit_model([log], vehicle, effects=["com_offset"], points=200, restarts=0)
        e = est.model.effects["com_offset"]
        rep, stat = e.interval95()["r"], e.interval95(systematic=False)["r"]
        inside = [bool(rep[i, 0] <= r[i] <= rep[i, 1]) for i in (0, 1)]
        inside_stat = [bool(stat[i, 0] <= r[i] <= stat[i, 1]) for i in (0, 1)]
        total["reported"] += sum(inside)
        total["statistical"] += sum(inside_stat)
        total["n"] += 2
        sys_r = e.systematic["r"] if e.systematic is not None else np.zeros(3)
        print(
            f"seed {seed} {fam:6} r {np.round(1e3 * r[:2], 2)} mm: est "
            f"{np.round(1e3 * e.values['r'][:2], 2)} se {np.round(1e3 * e.stderr['r'][:2], 2)} "
            f"spread {np.round(1e3 * sys_r[:2], 2)}; inside {inside} (statistical alone "
            f"{inside_stat}) {time.process_time() - start:.1f} CPU s",
            flush=True,
        )
    n = total["n"]
    for key in ("reported", "statistical"):
        lo, hi = wilson(total[key], n)
        print(
            f"{key}: truth inside {total[key]}/{n} = {100 * total[key] / n:.0f} % "
            f"[{100 * lo:.0f}, {100 * hi:.0f}]"
        )


if __name__ == "__main__":
    main()
