"""The band beyond the fit inputs on the scorecard's first (or last) models, post hoc.

    python benchmarks/band_first.py OUT.jsonl RECORDS.jsonl:ROOT:SUB ... [--last]

Each spec names scorecard records (``benchmarks/scorecard.py run --out``), the folder
holding their draws (``ROOT/<split>-<index>``, with ``held.*``) and the sub-folder of a
draw that holds its models (empty: the draw's own folder; ``replay-v8N``: N is the
draw's index mod 2, as ``scorecard_replay.py`` labels two jobs). Each draw's first model
(``m0.npz``, ``fit`` with defaults) or, with ``--last``, its last model (the one whose
held-out coverage the record holds, :func:`band_steps._last_model`) is judged on the
draw's held-out flight with the band's growth beyond the fit inputs
(``range_growth``, :mod:`omavctl.learn.band`) at K times the model's, K in
:data:`MULTIPLES`. Nothing inside the fit inputs moves with K (the growth starts a
quarter range beyond the box), nor does the mean.

Printed per K: the axis-flights whose 2-sigma coverage is >= 0.85 (all, and those fit
on steps and judged on a figure-8), and the band's mean width against the model's own.
Rows (one per draw and K) go to OUT. Results: docs/scorecard.md (session 33); about
30 s for 70 draws on 2 cores.
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
    sys.path.insert(0, str(Path(__file__).resolve().parent))

#: multiples of the model's ``range_growth`` judged
MULTIPLES = (0.5, 1.0, 2.0, 4.0)


def judge(job: tuple[dict[str, Any], str, str, bool]) -> list[dict[str, Any]]:
    """Rows (one per multiple) for one draw's model on its held-out flight."""
    from band_steps import _last_model

    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.learn.band import range_reach
    from omavctl.learn.effects_band import beyond_weight
    from omavctl.learn.model_file import load_model

    record, folder, sub, last = job
    draw = Path(folder)
    models = draw / sub if sub else draw
    log = next(p for p in sorted(draw.glob("held*")) if p.name not in ("held-ref.csv",))

    def read(model: Any, role: str = "held") -> Any:
        return _read_log(log, model.vehicle, *_grid(model), None)[0]

    if last:
        found = _last_model(record, models, read)
        if found is None:
            return []
        model = found[0]
    elif (models / "m0.npz").exists():
        model = load_model(models / "m0.npz")
    else:
        return []
    held = read(model)
    z = held.inputs(model.features)
    mean, var = model.predict_samples(held, noise=True)
    err = held.residual - mean
    weight = beyond_weight(model.inputs, z)[:, None]
    growth = weight * (model.range_growth[None] * range_reach(model.inputs, z)[:, None]) ** 2
    rows = []
    for k in MULTIPLES:
        band = var + (k**2 - 1.0) * growth
        rows.append(
            {
                "draw": draw.name,
                "families": [f["family"] for f in record["flights"]],
                "k": k,
                "coverage": np.mean(np.abs(err) <= 2.0 * np.sqrt(band), axis=0).tolist(),
                "width": (np.sqrt(band).mean(axis=0) / np.sqrt(var).mean(axis=0)).tolist(),
                "beyond": float(np.mean(weight > 0)),
            }
        )
    return rows


def jobs(specs: list[str], last: bool) -> list[tuple[dict[str, Any], str, str, bool]]:
    """One job per record whose draw folder exists."""
    out = []
    for spec in specs:
        records, root, sub = spec.split(":")
        for line in Path(records).read_text().splitlines():
            r = json.loads(line)
            folder = Path(root) / f"{r['split']}-{r['index']:04d}"
            if folder.is_dir():
                out.append((r, str(folder), sub.replace("N", str(r["index"] % 2)), last))
    return out


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """A line per multiple: coverage >= 0.85 (all; steps -> figure-8) and the width."""
    out = []
    for k in MULTIPLES:
        sel = [r for r in rows if r["k"] == k]
        if not sel:
            continue
        cov = np.array([r["coverage"] for r in sel])
        pair = np.array([r["coverage"] for r in sel if r["families"] == ["steps", "fig8"]])
        width = np.array([r["width"] for r in sel])
        out.append(
            f"growth x{k:g}: >= 0.85 on {(cov >= 0.85).sum()}/{cov.size} axis-flights, "
            f"steps -> fig8 {(pair >= 0.85).sum()}/{pair.size}; width x{width.mean():.2f} "
            f"(max {width.max():.2f})"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("specs", nargs="+", help="RECORDS.jsonl:ROOT:SUB")
    ap.add_argument("--last", action="store_true", help="the last model, not the first")
    args = ap.parse_args(argv)
    work = jobs(args.specs, args.last)
    with Pool(2) as pool:
        rows = [row for res in pool.imap(judge, work) for row in res]
    args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"{len(work)} draws, {'last' if args.last else 'first'} models")
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
