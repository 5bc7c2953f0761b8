"""The band's terms switched on one by one, post hoc on the same fitted models.

    python benchmarks/band_variants.py DIR [--out FILE.jsonl]

DIR: a ``benchmarks/band_calibration.py --workdir`` (its models ``CASE-FIT[+effects].npz``
and flights ``CASE-FAMILY.csv``). Every model is judged on every other family's flight
with its band as it was before (the floor from the held-out error everywhere, no growth
beyond the fit inputs but the GP's own), with the floor only beyond the fit inputs,
then adding the growth with the torque, then the growth with the reach (the band ``fit``
writes now: ``omavctl/learn/band.py``). The mean is the same in every variant, so only
coverage moves. Printed per variant: the axis-flights with 2-sigma coverage >= 0.85 (and
those that fell below it from before), and those whose coverage inside the fit inputs
(``evaluate``'s ``envelope.coverage_inside``) is <= 0.99 (issue 26).
docs/intervals.md, "The model's band inside the fit flight's inputs".
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

FAMILIES = ("fig8", "wobble", "chirp", "steps")


def variants(model: Any) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Variant name -> (band_noise, torque_growth, range_growth) of ``model``."""
    from omavctl.learn.band import RANGE_GROWTH, TORQUE_GROWTH

    zero, band = np.zeros(3), model.band_noise.copy()
    torque = np.full(3, TORQUE_GROWTH)
    reach = RANGE_GROWTH * np.std(model.targets, axis=0)
    return {
        "before": (model.noise_variance.copy(), zero, zero),
        "floor beyond only": (band, zero, zero),
        "+ torque": (band, torque, zero),
        "+ reach (now)": (band, torque, reach),
    }


def judge(model: Any, log: Path) -> list[dict[str, Any]]:
    """Coverage and coverage inside the fit inputs (3 each) of every variant on ``log``."""
    from omavctl.diagnose.evaluate import _grid, _read_log

    rate, sg = _grid(model)
    samples, *_ = _read_log(log, model.vehicle, rate, sg, None)
    z = samples.inputs(model.features)
    rows = []
    for name, (band, torque, reach) in variants(model).items():
        model.band_noise, model.torque_growth, model.range_growth = band, torque, reach
        rows.append({"variant": name, **band_row(model, samples, z)})
    return rows


def band_row(model: Any, samples: Any, z: np.ndarray) -> dict[str, Any]:
    """The model's band on ``samples`` (GP inputs ``z``): per-axis 2-sigma ``coverage``,
    coverage ``inside`` the fit inputs, the ``outside`` fraction and the ``rmse``."""
    from omavctl.diagnose.metrics import training_envelope

    mean, var = model.predict_samples(samples, noise=True)
    err = samples.residual - mean
    env = training_envelope(model.inputs, z, list(model.input_names), err, np.sqrt(var))
    return {
        "coverage": np.mean(np.abs(err) <= 2.0 * np.sqrt(var), axis=0).tolist(),
        "inside": [env["coverage_inside"][a] for a in "xyz"],
        "outside": env["outside_fraction"],
        "rmse": np.sqrt(np.mean(err**2, axis=0)).tolist(),
    }


def print_summary(rows: list[dict[str, Any]], base_variant: str, width: int) -> None:
    """Per variant of ``rows`` (a row per model, held-out flight and variant, with its
    per-axis ``coverage`` and ``inside``): the axis-flights >= 0.85, those that fell
    below 0.85 from ``base_variant``, and those <= 0.99 inside the fit inputs."""
    base = {(r["model"], r["held"]): r["coverage"] for r in rows if r["variant"] == base_variant}
    for name in dict.fromkeys(r["variant"] for r in rows):
        sel = [r for r in rows if r["variant"] == name]
        cov = np.array([r["coverage"] for r in sel]).ravel()
        was = np.array([base[(r["model"], r["held"])] for r in sel]).ravel()
        ins = np.array([np.nan if c is None else c for r in sel for c in r["inside"]], float)
        has = np.isfinite(ins)
        print(
            f"{name:{width}} {cov.size} axis-flights: coverage >= 0.85 on {(cov >= 0.85).sum()} "
            f"(min {cov.min():.3f}; fell below {int(((was >= 0.85) & (cov < 0.85)).sum())}); "
            f"inside <= 0.99 on {(ins[has] <= 0.99).sum()}/{has.sum()} "
            f"(median {np.median(ins[has]):.3f})"
        )


def main(argv: list[str] | None = None) -> int:
    from omavctl.learn.model_file import load_model

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("workdir", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    rows: list[dict[str, Any]] = []
    for path in sorted(args.workdir.glob("*.npz")):
        case, fit_on = path.stem.replace("+effects", "").split("-", 1)
        model = load_model(path)
        for held in FAMILIES:
            log = args.workdir / f"{case}-{held}.csv"
            if held != fit_on and log.exists():
                rows += [{"model": path.stem, "held": held, **r} for r in judge(model, log)]
    print_summary(rows, "before", 18)
    if args.out:
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
