"""The paper's informative-vs-task comparison in simulation (one seed).

Prior model from one flight of the attitude figure-8; plan the most
informative reference; fly it and fly the task again; add N points from each
flight to the prior (hyperparameters refit); fly the task with every model and
compare the mean absolute angular-acceleration tracking error |a* - omega_dot|.

Run: python benchmarks/paper_comparison.py [--seed S] [--points 20 40]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import load_model, save_model
from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs import read_vehicle_log, write_log
from omavctl.planning import PlanSettings, plan
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import load_truth
from omavctl.vehicle import default_vehicle


def tracking(path: Path, vehicle) -> np.ndarray:
    """Mean |a* - omega_dot| per axis of a flight log (same filtering as evaluate)."""
    flight = read_vehicle_log(path, vehicle)
    s = residual_samples(
        flight, vehicle, SavitzkyGolay(11, 2, 0.01), extra={"desired": "desired_acceleration"}
    )
    return np.abs(s.held["desired"] - s.omega_dot).mean(axis=0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--points", type=int, nargs="+", default=[20, 40])
    ap.add_argument("--candidates", type=int, default=20)
    args = ap.parse_args()
    start = time.perf_counter()
    vehicle = default_vehicle()
    truth = load_truth(None, vehicle)
    task = fig8(roll_deg=26, pitch_deg=26, period=8, duration=24)
    s = args.seed * 10
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        write_log(d / "prior.csv", simulate(task, vehicle, truth, seed=s + 1).log)
        prior = fit_model([d / "prior.csv"], vehicle, points=100, seed=args.seed).model
        save_model(d / "prior.npz", prior)
        result = plan(
            load_model(d / "prior.npz"),
            task,
            PlanSettings(candidates=args.candidates, sims=4, seed=args.seed),
        )
        informative = result.best_trajectory()
        write_log(d / "inf.csv", simulate(informative, vehicle, truth, seed=s + 2).log)
        write_log(d / "task2.csv", simulate(task, vehicle, truth, seed=s + 3).log)
        base = {}
        write_log(d / "none.csv", simulate(task, vehicle, truth, seed=s + 4).log)
        base["no model"] = tracking(d / "none.csv", vehicle)
        write_log(d / "p.csv", simulate(task, vehicle, truth, prior, seed=s + 4).log)
        base["prior"] = tracking(d / "p.csv", vehicle)
        rows = dict(base)
        for n in args.points:
            for label, log in (("informative", "inf.csv"), ("task", "task2.csv")):
                m = fit_model([d / log], vehicle, points=n, prior=prior, seed=args.seed).model
                out = d / f"fly-{label}-{n}.csv"
                write_log(out, simulate(task, vehicle, truth, m, seed=s + 4).log)
                rows[f"prior + {n} {label}"] = tracking(out, vehicle)
    print(
        f"seed {args.seed}: candidates {args.candidates}, best cost {result.cost[result.best]:.4g}"
        f" vs task {result.task_cost:.4g}"
    )
    print(f"{'model':28s} {'x':>7s} {'y':>7s} {'z':>7s} {'mean':>7s}  (rad/s^2)")
    for name, e in rows.items():
        print(f"{name:28s} {e[0]:7.3f} {e[1]:7.3f} {e[2]:7.3f} {e.mean():7.3f}")
    print(f"took {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
