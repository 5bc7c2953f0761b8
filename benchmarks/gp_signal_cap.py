"""The first model's GP with its signal variance capped at the targets', post hoc.

    python benchmarks/gp_signal_cap.py OUT.jsonl --cap C DRAW_FOLDER ...

Each scorecard draw folder (``fit*`` and ``held*`` logs) gets its first model refitted
(``fit`` with defaults) with the GP's signal variance bounded above by ``C`` times the
variance of its training targets (``omavctl.learn.hyperparameters._SIGNAL_BOUNDS``,
whose upper end is 1000 today; ``--cap 0`` keeps it), and is judged on the draw's
held-out flight: per axis the model's RMSE over the physics-only one (nominal + the
model's effects) and the 2σ coverage. Rows to OUT, one per draw; a summary printed.

Made for the first models whose yaw GP, fitted on a chirp, is worse than physics only on
attitude steps (report26 draw 17 z 1.44x, report27 draw 48 z 1.30x): their signal
variance was 16x and 10x the targets'. A GP prior wider than anything the fit flight's
residual spans extrapolates a trend with that amplitude. Results: docs/scorecard.md
(session 34); about 6 min for 70 draws on 2 cores per cap.
"""

from __future__ import annotations

import argparse
import json
import sys
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def draw_log(draw: Path, role: str) -> Path:
    """The draw's fit or held-out log (any format; a ROS 2 bag is a folder)."""
    skip = (f"{role}-ref.csv", f"{role}cache")
    return next(
        p
        for p in sorted(draw.glob(f"{role}*"))
        if p.name not in skip and (p.is_file() or p.name == role)
    )


def judge(job: tuple[str, float]) -> dict[str, Any]:
    """One draw's refitted first model on its held-out flight."""
    folder, cap = job
    import omavctl.learn.hyperparameters as hp

    if cap > 0:
        hp._SIGNAL_BOUNDS = (1e-4, cap)
    from omavctl.diagnose.logread import _grid, _read_log
    from omavctl.learn.fit import fit_model

    draw = Path(folder)
    model = fit_model([draw_log(draw, "fit")]).model
    held = _read_log(draw_log(draw, "held"), model.vehicle, *_grid(model), None)[0]
    mean, var = model.predict_samples(held, noise=True)
    physics = held.residual - model.effects_samples(held)
    err = held.residual - mean
    return {
        "draw": draw.name,
        "cap": cap,
        "ratio": (np.sqrt((err**2).mean(0)) / np.sqrt((physics**2).mean(0))).tolist(),
        "coverage": np.mean(np.abs(err) <= 2.0 * np.sqrt(var), axis=0).tolist(),
        "signal_over_targets": (model.signal_variance / np.var(model.targets, axis=0)).tolist(),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("draws", nargs="+")
    ap.add_argument("--cap", type=float, default=0.0)
    args = ap.parse_args(argv)
    with Pool(2) as pool:
        rows = pool.map(judge, [(d, args.cap) for d in args.draws])
    args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    ratio, cov = np.array([r["ratio"] for r in rows]), np.array([r["coverage"] for r in rows])
    print(
        f"cap {args.cap:g}: {len(rows)} draws; model > 1.05x physics-only on "
        f"{(ratio > 1.05).sum()}/{ratio.size} axis-flights (max {ratio.max():.3f}); 2σ >= 0.85 "
        f"{(cov >= 0.85).sum()}, > 0.99 {(cov > 0.99).sum()}; median ratio {np.median(ratio):.3f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
