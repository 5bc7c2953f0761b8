"""The band on the scorecard's held-out flights, post hoc under variants (issue 26).

    python benchmarks/band_steps.py RECORDS.jsonl[,...] DIR... [--out FILE.jsonl]

RECORDS: scorecard records (``benchmarks/scorecard.py run --out``); DIR: their draws'
work directories (``--workdir``: ``fit.*``, ``held.*`` and the loop's models). Each
draw's last model (the one whose held-out coverage the record holds) is judged on the
draw's held-out flight with its band as written, then under variants that only move
the band (the mean is the same in all):

- ``growth xK``: the std's growth per training range beyond the fit inputs' box
  (``range_growth``, :mod:`omavctl.learn.band`) K times the model's;
- ``from the edge``: that growth from the box's edge, not from the quarter range at
  which ``evaluate`` counts a sample outside (it then widens samples counted inside);
- ``nearest point``: growth with the distance (L-infinity, training ranges) to the
  nearest training point beyond what the fit flight's own samples reach (99th
  percentile): new combinations of inputs inside the box;
- ``scale >= 1``: the band's calibration factor inside the inputs (``band_scale``)
  never below 1.

Printed per variant and record set: the axis-flights whose 2-sigma coverage is
>= 0.85, those <= 0.99 inside the fit inputs (the scorecard's two band rows), the
mean ratio of the band's width to the model's own, and the axis-flights under 0.85
(draw, held-out family, axis, coverage). Results: docs/scorecard.md (session 31).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

Variant = Callable[[Any, Any, np.ndarray, np.ndarray], np.ndarray]


def nearest_reach(train: np.ndarray, z: np.ndarray) -> np.ndarray:
    """L-infinity distance (n,) of z (n, d) to the nearest row of train (m, d), in
    training ranges, over the inputs that varied in training."""
    lo, hi = train.min(axis=0), train.max(axis=0)
    span = hi - lo
    varied = span > 1e-9 * np.maximum(np.maximum(np.abs(lo), np.abs(hi)), 1.0)
    tr, zz = train[:, varied] / span[varied], z[:, varied] / span[varied]
    out = np.empty(zz.shape[0])
    for s in range(0, zz.shape[0], 500):
        out[s : s + 500] = np.abs(zz[s : s + 500, None, :] - tr[None]).max(axis=-1).min(axis=-1)
    return out


def variants(fit_z: np.ndarray) -> dict[str, Variant]:
    """Variant name -> f(model, samples, z, var) giving the band's variance (n, 3)."""
    from omavctl.learn.band import range_reach
    from omavctl.learn.effects_band import beyond_weight

    def growth(k: float) -> Variant:
        def f(m: Any, s: Any, z: np.ndarray, var: np.ndarray) -> np.ndarray:
            extra = (m.range_growth[None] * range_reach(m.inputs, z)[:, None]) ** 2
            return var + (k**2 - 1.0) * beyond_weight(m.inputs, z)[:, None] * extra

        return f

    def edge(m: Any, s: Any, z: np.ndarray, var: np.ndarray) -> np.ndarray:
        extra = (m.range_growth[None] * range_reach(m.inputs, z)[:, None]) ** 2
        return var + (1.0 - beyond_weight(m.inputs, z))[:, None] * extra

    def nearest(m: Any, s: Any, z: np.ndarray, var: np.ndarray) -> np.ndarray:
        margin = np.quantile(nearest_reach(m.inputs, fit_z), 0.99)
        excess = np.maximum(nearest_reach(m.inputs, z) - margin, 0.0)
        return var + (m.range_growth[None] * excess[:, None]) ** 2

    def floor(m: Any, s: Any, z: np.ndarray, var: np.ndarray) -> np.ndarray:
        kept = m.band_scale.copy()
        m.band_scale = np.maximum(kept, 1.0)
        try:
            return np.asarray(m.predict_samples(s, noise=True)[1])
        finally:
            m.band_scale = kept

    return {
        "as written": lambda m, s, z, var: var,
        "growth x2": growth(2.0),
        "growth x3": growth(3.0),
        "from the edge": edge,
        "nearest point": nearest,
        "scale >= 1": floor,
    }


def _inside_box(train: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(n,) whether each row of z lies inside the training box as ``evaluate`` counts it
    (within its margin of a training range beyond the box)."""
    from omavctl.learn.effects_band import beyond_weight

    return beyond_weight(train, z) == 0.0


def _last_model(record: dict[str, Any], workdir: Path, read: Callable[..., Any]) -> Any:
    """The draw's last model: the one whose held-out coverage matches the record's."""
    from omavctl.learn.model_file import load_model

    want = np.array([record["rounds"][-1]["coverage"][a] for a in "xyz"])
    best, gap = None, np.inf
    for path in sorted(p for p in workdir.glob("m*.npz") if ".eval." not in p.name):
        model = load_model(path)
        held = read(model, "held")
        mean, var = model.predict_samples(held, noise=True)
        cov = np.mean(np.abs(held.residual - mean) <= 2.0 * np.sqrt(var), axis=0)
        if np.abs(cov - want).sum() < gap:
            best, gap = (model, path.stem), float(np.abs(cov - want).sum())
    return best if gap < 0.02 else None


def judge(record: dict[str, Any], workdir: Path) -> list[dict[str, Any]]:
    """One row per variant for the draw's last model on its held-out flight."""
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.diagnose.metrics import training_envelope

    def read(model: Any, role: str) -> Any:
        skip = (f"{role}-ref.csv", f"{role}cache")  # the reference and fit's cache
        log = next(p for p in sorted(workdir.glob(f"{role}*")) if p.name not in skip)
        rate, sg = _grid(model)
        return _read_log(log, model.vehicle, rate, sg, None)[0]

    found = _last_model(record, workdir, read)
    if found is None:
        return []
    model, name = found
    held, fit = read(model, "held"), read(model, "fit")
    z = held.inputs(model.features)
    mean, var = model.predict_samples(held, noise=True)
    err = held.residual - mean
    fit_z = fit.inputs(model.features)
    margin = np.quantile(nearest_reach(model.inputs, fit_z), 0.99)
    joint = _inside_box(model.inputs, z) & (nearest_reach(model.inputs, z) <= margin)
    rows = []
    for label, f in variants(fit_z).items():
        v = f(model, held, z, var)
        env = training_envelope(model.inputs, z, list(model.input_names), err, np.sqrt(v))
        within = np.abs(err) <= 2.0 * np.sqrt(v)
        rows.append(
            {
                "draw": workdir.name,
                "held": record["flights"][1]["family"],
                "model": name,
                "variant": label,
                "coverage": np.mean(np.abs(err) <= 2.0 * np.sqrt(v), axis=0).tolist(),
                "inside": [env["coverage_inside"][a] for a in "xyz"],
                "inside_joint": within[joint].mean(axis=0).tolist() if joint.any() else None,
                "joint_share": float(joint.mean()),
                "width": (np.sqrt(v).mean(axis=0) / np.sqrt(var).mean(axis=0)).tolist(),
            }
        )
    return rows


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Per variant: the scorecard's two band rows, the width ratio and the shortfalls."""
    out = []
    for label in dict.fromkeys(r["variant"] for r in rows):
        sel = [r for r in rows if r["variant"] == label]
        cov = np.array([r["coverage"] for r in sel])
        ins = np.array([c for r in sel for c in r["inside"] if c is not None])
        low = [
            f"{r['draw']}:{r['held']}:{a}{c:.2f}"
            for r in sel
            for a, c in zip("xyz", r["coverage"], strict=True)
            if c < 0.85
        ]
        joint = np.array([c for r in sel for c in (r.get("inside_joint") or [])])
        width = np.array([r["width"] for r in sel])
        out.append(
            f"{label:14} {cov.size} axis-flights: >= 0.85 {(cov >= 0.85).sum()}, "
            f"<= 0.99 inside {(ins <= 0.99).sum()}/{ins.size} "
            f"(near the fit flight's samples {(joint <= 0.99).sum()}/{joint.size}), width x"
            f"{width.mean():.2f} (max {width.max():.2f})"
        )
        out.append("    under 0.85: " + (" ".join(low) or "none"))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("records", help="scorecard record files, comma-separated")
    ap.add_argument("dirs", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    records = {}
    for path in args.records.split(","):
        for line in Path(path).read_text().splitlines():
            r = json.loads(line)
            records[f"{r['split']}-{r['index']:04d}"] = r
    rows: list[dict[str, Any]] = []
    for d in args.dirs:
        if d.name in records:
            rows += judge(records[d.name], d)
    print("\n".join(summary(rows)))
    if args.out:
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
