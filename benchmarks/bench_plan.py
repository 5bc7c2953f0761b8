"""Time and peak memory of ``plan``: the reference path against the fast one, and CEM vs random.

Run: python benchmarks/bench_plan.py [--candidates 1000] [--ref-candidates 10] [--repeat 3]

Data (built once in --workdir): the 24 s figure-8 of the paper's protocol
(26 deg, 8 s period), one flight of it through the default truth plant
(``examples/truth-paper.yaml``), a model fitted with 200 points; the 30 s
pitching task of the paper for the search comparison.

Every case runs in a fresh child process (imports, model loading and all)
with one BLAS thread, as ``omavctl plan`` does; wall time and the child's
peak resident memory (ru_maxrss) are printed.

1. reference vs fast on the same case (``--ref-candidates`` x 8 simulations,
   k-medoids selection on both paths, so the costs must agree), with the
   ratio, and the reference's time per candidate;
2. the fast path on ``--candidates`` x 8 simulations (the issue's target),
   ``--repeat`` times with the default --jobs (one process per core) and once
   with --jobs 1 (whose costs must be identical): best, median, CPU seconds; then
   the ``omavctl plan`` command line itself;
3. random sampling against ``--search cem`` at the same number of simulations
   (``--search-candidates`` x 4) on the figure-8 and the pitch task, per seed
   (``--search-seeds``) and their geometric mean.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _data(workdir: Path) -> dict[str, Path]:
    """Task CSVs and the 200-point model, built once."""
    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model
    from omavctl.logs import align
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8, pitch
    from omavctl.sim.trajectory import write_trajectory
    from omavctl.sim.truth import load_truth
    from omavctl.vehicle import default_vehicle

    workdir.mkdir(parents=True, exist_ok=True)
    paths = {k: workdir / f"{k}" for k in ("fig8.csv", "pitch.csv", "model.npz")}
    if all(p.exists() for p in paths.values()):
        return paths
    vehicle = default_vehicle()
    task = fig8(roll_deg=26, pitch_deg=26, period=8.0, duration=24.0)
    write_trajectory(paths["fig8.csv"], task)
    write_trajectory(paths["pitch.csv"], pitch())
    truth = load_truth(ROOT / "examples" / "truth-paper.yaml", vehicle)
    flight = align(simulate(task, vehicle, truth, seed=101).log)
    save_model(paths["model.npz"], fit_model([flight], vehicle, points=200, seed=1).model)
    return paths


def _case(spec: dict) -> dict:
    """Child process body: run plan() for spec, print the result as JSON."""
    from dataclasses import replace

    from threadpoolctl import threadpool_limits

    from omavctl.learn.model_file import load_model
    from omavctl.planning import PlanSettings, plan
    from omavctl.sim.trajectory import read_trajectory

    start = time.perf_counter()
    with threadpool_limits(1, user_api="blas"):
        model, task = load_model(spec["model"]), read_trajectory(spec["task"])
        settings = replace(PlanSettings(), **spec["settings"])
        result = plan(model, task, settings)
    usage = resource.getrusage
    me, kids = usage(resource.RUSAGE_SELF), usage(resource.RUSAGE_CHILDREN)
    return {
        "wall": time.perf_counter() - start,
        "cpu": me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime,
        "peak_mib": usage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "workers_peak_mib": usage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
        "best": float(result.cost[result.best]) if result.best >= 0 else None,
        "cost": [float(c) if c < float("inf") else None for c in result.cost],
        "feasible": int(result.feasible.sum()),
    }


def _run(spec: dict) -> dict:
    """Run one case in a fresh child process (it reports its own peak RSS)."""
    out = subprocess.run(
        [sys.executable, __file__, "--child", json.dumps(spec)],
        check=True,
        capture_output=True,
        text=True,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _spec(paths: dict[str, Path], task: str, **settings) -> dict:
    return {"model": str(paths["model.npz"]), "task": str(paths[task]), "settings": settings}


def _cores() -> int:
    from omavctl.planning.workers import available_cores

    return available_cores()


def _cli(paths: dict[str, Path], n: int) -> None:
    """The issue's command line itself, timed from outside (wall, CPU of the process
    tree, peak RSS of the largest process)."""
    out = paths["model.npz"].parent
    exe = Path(sys.executable).with_name("omavctl")
    args = [str(exe), "plan", "--task", str(paths["fig8.csv"]), "--model"]
    args += [str(paths["model.npz"]), "--out", str(out / "next.csv"), "--scores"]
    args += [str(out / "scores.csv"), "--candidates", str(n), "--sims", "8", "-q"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(args, check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    rows = len((out / "scores.csv").read_text().splitlines()) - 1
    print(
        f"CLI: omavctl plan --candidates {n} --sims 8 --scores ...: {wall:.1f} s wall, "
        f"{cpu:.1f} s CPU, largest process {after.ru_maxrss / 1024:.0f} MiB, {rows} rows in "
        "--scores"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/omavctl-bench-plan"))
    ap.add_argument("--candidates", type=int, default=1000)
    ap.add_argument("--ref-candidates", type=int, default=10)
    ap.add_argument("--search-candidates", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--search-seeds", type=int, nargs="+", default=list(range(8)))
    ap.add_argument("--skip-speed", action="store_true", help="only the search comparison")
    ap.add_argument("--child")
    args = ap.parse_args()
    if args.child:
        print(json.dumps(_case(json.loads(args.child))))
        return
    print(f"load average before: {os.getloadavg()}, cores: {os.cpu_count()}")
    paths = _data(args.workdir)
    if not args.skip_speed:
        _speed(paths, args)
    _search(paths, args)
    print(f"\nload average after: {os.getloadavg()}")


def _speed(paths: dict[str, Path], args: argparse.Namespace) -> None:
    """Sections 1 and 2: reference vs fast, the 1000 x 8 target, the CLI."""
    k = args.ref_candidates
    print(f"\n1. reference vs fast, fig8 24 s, 200-point model, {k} candidates x 8, k-medoids")
    ref = _run(_spec(paths, "fig8.csv", candidates=k, sims=8, selection="kmedoids", fast=False))
    fast = _run(_spec(paths, "fig8.csv", candidates=k, sims=8, selection="kmedoids"))
    rel = max(abs(a / b - 1) for a, b in zip(fast["cost"], ref["cost"], strict=True) if a and b)
    print(f"{'path':<10} {'wall s':>8} {'peak MiB':>9}")
    for name, r in (("reference", ref), ("fast", fast)):
        print(f"{name:<10} {r['wall']:8.1f} {r['peak_mib']:9.0f}")
    print(f"ratio {ref['wall'] / fast['wall']:.1f}x; max relative cost difference {rel:.1e}")
    print(f"reference per candidate: {ref['wall'] / k:.1f} s")

    n = args.candidates
    print(f"\n2. fast, fig8 24 s, {n} candidates x 8 (batched selection), default --jobs (0: "
          f"one per core, {_cores()} here)")  # fmt: skip
    walls, costs = [], []
    for i in range(args.repeat):
        r = _run(_spec(paths, "fig8.csv", candidates=n, sims=8))
        walls.append(r["wall"])
        costs.append(r["cost"])
        print(
            f"run {i + 1}: {r['wall']:.1f} s wall, {r['cpu']:.1f} s CPU, peak {r['peak_mib']:.0f} "
            f"MiB parent, {r['workers_peak_mib']:.0f} MiB largest worker, {r['feasible']}/{n} "
            f"feasible, load {os.getloadavg()[0]:.1f}"
        )
    walls.sort()
    print(f"best {walls[0]:.1f} s, median {walls[len(walls) // 2]:.1f} s")
    r = _run(_spec(paths, "fig8.csv", candidates=n, sims=8, jobs=1))
    print(f"--jobs 1: {r['wall']:.1f} s wall, {r['cpu']:.1f} s CPU, peak {r['peak_mib']:.0f} MiB")
    same = all(c == r["cost"] for c in costs)
    print(f"every candidate's cost identical with --jobs 1 and the default: {same}")
    print(
        f"reference extrapolated: {ref['wall'] / k * n:.0f} s; "
        f"ratio {ref['wall'] / k * n / walls[0]:.0f}x"
    )
    _cli(paths, n)


def _search(paths: dict[str, Path], args: argparse.Namespace) -> None:
    """Section 3: random sampling against --search cem, per seed."""
    m = args.search_candidates
    print(f"\n3. random vs cem at {m} candidates x 4 simulations (best cost, lower is better)")
    print(f"{'task':<6} {'seed':>4} {'random':>12} {'cem':>12} {'cem/random':>11}")
    for task in ("fig8.csv", "pitch.csv"):
        ratios = []
        for seed in args.search_seeds:
            best = {}
            for search in ("random", "cem"):
                # the paper's test points: with --region pool (the default) the two
                # searches' costs are over different test points (CEM's first generation
                # sets its region), not comparable
                spec = _spec(
                    paths, task, candidates=m, sims=4, search=search, seed=seed, region="task"
                )
                best[search] = _run(spec)["best"]
            ratios.append(best["cem"] / best["random"])
            print(
                f"{task[:-4]:<6} {seed:>4} {best['random']:12.5g} {best['cem']:12.5g} "
                f"{ratios[-1]:11.3f}"
            )
        geo = float(np.exp(np.mean(np.log(ratios))))
        wins = sum(r < 1 for r in ratios)
        n_seeds = len(ratios)
        print(f"{task[:-4]:<6} geometric mean cem/random {geo:.3f}, cem lower in {wins}/{n_seeds}")


if __name__ == "__main__":
    main()
