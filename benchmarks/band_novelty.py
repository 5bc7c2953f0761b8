"""A band that also grows with the distance from the training points, post hoc.

    python benchmarks/band_novelty.py OUT.jsonl RECORDS.jsonl:ROOT:SUB ... [--last]

The specs as ``benchmarks/band_first.py``'s. Each draw's first model (or, with
``--last``, its last) is judged on the draw's held-out flight with its band as
``evaluate`` computes it, and with a *novelty* term added to the GP's calibrated latent
variance: ``latent_scale s^2 min(1, e / L)^2``, ``e`` how far a sample's nearest
training point (Euclidean, inputs in units of the fit's input std) lies beyond the
fit flight's own largest such distance, ``L`` in :data:`LENGTHS`. The term enters
the mean's weight too (:mod:`omavctl.learn.mean_shrink`), so the GP mean falls back
to physics where the held-out flight combines its inputs as the fit flight never did.

Made for the remaining 2σ shortfalls inside the fit inputs' box (steps -> figure-8:
96-98 % of the figure-8's samples lie beyond the steps' own largest distance) and
report26 draw 17's first model (z 1.44x physics-only inside the box).

Printed per variant: axis-flights with 2σ coverage >= 0.85, > 0.99, model > 1.05x
physics-only, <= 0.99 inside the box and near the fit data (within its largest
distance), the band's mean width against the model's own, and the mean NLPD (a proper
score: lower is better) and on how many axis-flights it beats the model's own band.
Results: docs/scorecard.md (session 34); about 90 s for 70 draws on 2 cores.
"""

from __future__ import annotations

import json
import sys
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from band_first import jobs
from gp_signal_cap import draw_log

#: Lengths L (input stds) over which the novelty term reaches the GP's prior; None: the
#: model's own band.
LENGTHS = (None, 1.0, 2.0, 4.0, 8.0)


def judge(job: tuple[dict[str, Any], str, str, bool]) -> list[dict[str, Any]]:
    """Rows (one per length) for one draw's model on its held-out flight."""
    from band_steps import _last_model
    from scipy.spatial import cKDTree

    from omavctl.diagnose.logread import _grid, _read_log
    from omavctl.learn.band import band_variance
    from omavctl.learn.effects_band import beyond_weight
    from omavctl.learn.mean_shrink import shrink_mean
    from omavctl.learn.model_file import load_model

    record, folder, sub, last = job
    draw = Path(folder)
    held_log, fit_log = draw_log(draw, "held"), draw_log(draw, "fit")

    def read(model: Any, role: str = "held") -> Any:
        log = held_log if role == "held" else fit_log
        return _read_log(log, model.vehicle, *_grid(model), None)[0]

    if last:
        found = _last_model(record, draw / sub if sub else draw, read)
        if found is None:
            return []
        model = found[0]
    else:
        model = load_model((draw / sub if sub else draw) / "m0.npz")
    held, fit = read(model), read(model, "fit")
    zh = held.inputs(model.features)
    tree = cKDTree(model.normalise(model.inputs))
    dh = tree.query(model.normalise(zh))[0]
    d0 = float(tree.query(model.normalise(fit.inputs(model.features)))[0].max())
    mean0, latent0 = model.latent(zh)
    physics = held.residual - model.effects_samples(held)
    inside, near = beyond_weight(model.inputs, zh) == 0, dh <= d0
    prior = model.latent_scale * model.signal_variance
    rows = []
    for length in LENGTHS:
        excess = 0.0 if length is None else np.clip((dh - d0) / length, 0.0, 1.0)
        latent = latent0 + prior[None, :] * np.asarray(excess)[..., None] ** 2
        mean, added = shrink_mean(mean0, latent, model.mean_shrink)
        var = band_variance(model, zh, latent + added, latent) + model.effects_variance(held)
        err = physics - mean
        u = np.abs(err) / np.sqrt(var)

        def cov(mask: np.ndarray, a: int, u: np.ndarray = u) -> float | None:
            return float(np.mean(u[mask, a] <= 2)) if mask.sum() >= 20 else None

        rows.append(
            {
                "draw": draw.name,
                "length": length,
                "coverage": np.mean(u <= 2, axis=0).tolist(),
                "inside": [cov(inside, a) for a in range(3)],
                "near": [cov(near, a) for a in range(3)],
                "ratio": (np.sqrt((err**2).mean(0)) / np.sqrt((physics**2).mean(0))).tolist(),
                "nlpd": (0.5 * np.log(2 * np.pi * var) + 0.5 * err**2 / var).mean(0).tolist(),
                "width": np.sqrt(var).mean(0).tolist(),
                "novel": float(np.mean(~near)),
            }
        )
    return rows


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """A line per length (see the module docstring)."""
    base = {r["draw"]: r for r in rows if r["length"] is None}
    out = []
    for length in LENGTHS:
        sel = [r for r in rows if r["length"] == length]
        cov, ratio = np.array([r["coverage"] for r in sel]), np.array([r["ratio"] for r in sel])
        nlpd = np.array([r["nlpd"] for r in sel])
        own = np.array([base[r["draw"]]["nlpd"] for r in sel])
        own_width = np.array([base[r["draw"]]["width"] for r in sel])
        width = np.array([r["width"] for r in sel]) / own_width
        ins = [c for r in sel for c in r["inside"] if c is not None]
        near = [c for r in sel for c in r["near"] if c is not None]
        name = "the model's own band" if length is None else f"L = {length:g}"
        out.append(
            f"{name}: >= 0.85 {(cov >= 0.85).sum()}/{cov.size}, > 0.99 {(cov > 0.99).sum()}; "
            f"model > 1.05x physics {(ratio > 1.05).sum()} (max {ratio.max():.2f}); "
            f"<= 0.99 inside the box {sum(c <= 0.99 for c in ins)}/{len(ins)}, near the fit "
            f"data {sum(c <= 0.99 for c in near)}/{len(near)}; width x{width.mean():.2f}; "
            f"NLPD {nlpd.mean():.3f}, better than the own band on {(nlpd < own).sum()}"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    out, *specs = [a for a in args if a != "--last"]
    work = jobs(specs, "--last" in args)
    with Pool(2) as pool:
        rows = [row for res in pool.imap(judge, work) for row in res]
    Path(out).write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"{len(work)} draws, {'last' if '--last' in args else 'first'} models")
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
