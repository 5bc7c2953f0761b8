"""The band inside the fit inputs with one factor, and following the GP's own distance.

    python benchmarks/band_slope.py DIR [--out FILE.jsonl]
    python benchmarks/band_slope.py --pairs MODEL=LOG [MODEL=LOG ...] [--out FILE.jsonl]

DIR: a ``benchmarks/band_calibration.py --workdir`` (its models ``CASE-FIT[+effects].npz``,
each judged on its case's flights ``CASE-FAMILY.csv`` of the other families); or
``--pairs``, each a model fitted now and the held-out log to judge it on. Each model is
judged twice, post hoc: with the band inside the fit inputs as one factor for every
sample (``band_scale`` 1, ``band_slope`` 0: the band of a model fitted before them) and
as ``fit`` writes it now, ``a (1 + beta rho)`` (:func:`omavctl.learn.validation.band_slope`).
The mean is the same in both, so only coverage moves (every ratio to physics stays).
Printed per variant: the axis-flights with 2-sigma coverage >= 0.85 (and those that fell
below it), and those <= 0.99 inside the fit inputs (issue 26). docs/intervals.md, "A band
that follows the GP's own distance".
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.band_variants import FAMILIES, band_row, print_summary


def judge(model: Any, log: Path) -> list[dict[str, Any]]:
    """Coverage and coverage inside the fit inputs (3 each) of ``model`` on ``log``, with
    one factor inside (``one factor``) and with the band as fitted (``following rho``)."""
    from omavctl.diagnose.evaluate import _grid, _read_log

    rate, sg = _grid(model)
    samples, *_ = _read_log(log, model.vehicle, rate, sg, None)
    z = samples.inputs(model.features)
    fitted = (model.band_scale.copy(), model.band_slope.copy())
    rows = []
    for name, (scale, slope) in (
        ("one factor", (np.ones(3), np.zeros(3))),
        ("following rho", fitted),
    ):
        model.band_scale, model.band_slope = scale, slope
        rows.append({"variant": name, **band_row(model, samples, z)})
    return rows


def _pairs(args: argparse.Namespace) -> list[tuple[Path, Path]]:
    """(model, held-out log) pairs: from ``--pairs`` or the band_calibration workdir."""
    if args.pairs:
        return [(Path(m), Path(log)) for m, log in (p.split("=", 1) for p in args.pairs)]
    out = []
    for path in sorted(args.workdir.glob("*.npz")):
        case, fit_on = path.stem.replace("+effects", "").split("-", 1)
        for held in FAMILIES:
            log = args.workdir / f"{case}-{held}.csv"
            if held != fit_on and log.exists():
                out.append((path, log))
    return out


def main(argv: list[str] | None = None) -> int:
    from omavctl.learn.model_file import load_model

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("workdir", type=Path, nargs="?", default=None)
    ap.add_argument("--pairs", nargs="+", default=None, metavar="MODEL=LOG")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    if (args.workdir is None) == (args.pairs is None):
        ap.error("give a band_calibration workdir or --pairs")
    rows: list[dict[str, Any]] = []
    for model_path, log in _pairs(args):
        model = load_model(model_path)
        for r in judge(model, log):
            rows.append({"model": str(model_path), "held": str(log), **r})
            cov, ins = r["coverage"], r["inside"]
            print(
                f"{model_path.name:40} {log.name:14} {r['variant']:14} "
                + " ".join(
                    f"{c:.3f}/{'-' if i is None else f'{i:.3f}'}"
                    for c, i in zip(cov, ins, strict=True)
                ),
                flush=True,
            )
    print_summary(rows, "one factor", 14)
    if args.out:
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
