"""How the tilt beyond the task's relates to what a refit gains (docs/informative.md).

Run: python benchmarks/informative_tilt.py DRAW_DIR... [--margin 10]

Reads cached draws of benchmarks/informative.py (each ``DRAW_DIR`` holds its
``result.json``, ``task.csv`` and ``scores-variance.csv``; a ``cap10.json``, the
flown pick under a 10 deg margin, is counted as one more flown candidate). No
flight is flown. Prints:

1. over every flown candidate, the per cent of the first model's error its refit
   removed (region, task, tracking) by how far its reference tilts beyond the
   task's largest tilt, and the Spearman of the extra tilt with it;
2. for draws whose scores are the pool objective (``--pool-draws``): before (all
   flown candidates) and after the margin (those within it), the Spearman of the
   cost with the removed region error, the margin's pick against a random candidate
   within the margin (the mean of the other flown ones) and the oracle's room.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.informative_kept import read_scores
from benchmarks.informative_stats import gain, mean_interval, spearman
from omavctl.planning.candidates import deviated_references
from omavctl.sim.trajectory import read_trajectory

#: bins of the extra tilt (deg beyond the task's largest), (low, high]
BINS = ((-90.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 90.0))


def flown(w: Path) -> tuple[dict, dict[int, dict], np.ndarray, np.ndarray]:
    """A draw's result, its flown candidates by index (the cap pick included), their
    pool costs (K,) and every candidate's extra reference tilt (K,) in deg."""
    r = json.loads((w / "result.json").read_text())
    coeffs, cost = read_scores(w / "scores-variance.csv")
    task = read_trajectory(w / "task.csv")
    tilt = np.rad2deg(np.abs(deviated_references(task, coeffs)[..., 4:6])).max(axis=(1, 2))
    extra = tilt - np.rad2deg(np.abs(task.euler[:, :2])).max()
    cands = {int(k): v for k, v in r["pool"].items()}
    if (w / "cap10.json").is_file():
        cap = json.loads((w / "cap10.json").read_text())
        cands.setdefault(int(cap["k"]), cap)
    return r, cands, cost, extra


def by_tilt(draws: list[Path]) -> list[str]:
    """Lines of part 1 (module docstring)."""
    extra, removed = [], {k: [] for k in ("region", "task", "tracking")}
    for w in draws:
        r, cands, _, ex = flown(w)
        for k, c in cands.items():
            extra.append(float(ex[k]))
            for key in removed:
                removed[key].append(gain(r["first"][key], c[key]))
    out = [f"{len(extra)} flown candidates of {len(draws)} draws"]
    x = np.asarray(extra)
    for key, values in removed.items():
        v = np.asarray(values)
        rho = spearman(x, v)
        out.append(f"{key}: Spearman of the extra tilt with the removed error {rho:+.2f}")
        for lo, hi in BINS:
            m = (x > lo) & (x <= hi)
            if m.any():
                iv = mean_interval(list(v[m]))
                out.append(f"  extra tilt in ({lo:g}, {hi:g}] deg, n = {m.sum()}: {iv.text()}")
    return out


def before_after(draws: list[Path], margin: float) -> list[str]:
    """Lines of part 2 (module docstring); the margin's pick must have been flown."""
    rows: dict[str, list[float]] = {"pick": [], "room": [], "before": [], "room_before": []}
    sp_before, sp_after = [], []
    for w in draws:
        r, cands, cost, ex = flown(w)
        pick = int(np.argmin(np.where(ex <= margin, cost, np.inf)))
        inside = {k: c for k, c in cands.items() if ex[k] <= margin}
        ks = list(cands)
        sp_before.append(spearman([cost[k] for k in ks], [-cands[k]["region"] for k in ks]))
        rand = cands[int(r["random"])]["region"]
        rows["before"].append(gain(rand, cands[int(r["best"])]["region"]))
        rows["room_before"].append(gain(rand, min(c["region"] for c in cands.values())))
        if len(inside) >= 3:
            ks = list(inside)
            sp_after.append(spearman([cost[k] for k in ks], [-inside[k]["region"] for k in ks]))
        others = [c["region"] for k, c in inside.items() if k != pick]
        if pick in inside and others:
            base = float(np.mean(others))
            rows["pick"].append(gain(base, inside[pick]["region"]))
            rows["room"].append(gain(base, min(c["region"] for c in inside.values())))
    fmt = ", ".join
    return [
        f"Spearman of the cost with the removed region error, per draw: all flown "
        f"{fmt(f'{v:+.2f}' for v in sp_before)} (mean {np.nanmean(sp_before):+.2f}); within "
        f"+{margin:g} deg (draws with 3 or more) {fmt(f'{v:+.2f}' for v in sp_after)}"
        + (f" (mean {np.nanmean(sp_after):+.2f})" if sp_after else ""),
        f"planned vs the random candidate, region: {mean_interval(rows['before']).text()}; "
        f"oracle room {mean_interval(rows['room_before']).text()} ({len(rows['before'])} draws)",
        f"margin {margin:g}: its pick vs a random candidate within it, region: "
        f"{mean_interval(rows['pick']).text()}; oracle room within it "
        f"{mean_interval(rows['room']).text()} ({len(rows['pick'])} draws)",
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("draws", type=Path, nargs="+", help="draw directories of informative.py")
    ap.add_argument("--pool-draws", type=Path, nargs="*", default=[],
                    help="those whose scores-variance.csv is the pool objective")  # fmt: skip
    ap.add_argument("--margin", type=float, default=10.0)
    cfg = ap.parse_args(argv)
    print("\n".join(by_tilt(cfg.draws)))
    if cfg.pool_draws:
        print("\n".join(before_after(cfg.pool_draws, cfg.margin)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
