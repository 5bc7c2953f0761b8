"""Two models on one log, paired: does an added effect lower the error at every horizon?

Issue 28's must-show "adding the named effect lowers the 0.5 s error in the draws where
it lowers the one-step error", measured on a real log (docs/horizons.md, "Issue 28's
must-show, session 17"). Both models are rolled out on the same windows
(:func:`omavctl.diagnose.horizons.horizon_table`, as ``evaluate --model M0 --model M1``
does); printed:

- the one-step RMSE (rad/s^2, x/y/z) of physics only and of each model's physics +
  effects on the log's samples;
- per predictor and horizon the mean |body-rate error| x/y/z (rad/s) ± its standard
  error over chunks of window start times (1 s), and the full models' 2σ coverage;
- paired differences ± their standard error (:func:`paired_se`): model 1's physics +
  effects against physics only, against model 0's physics + effects and against hold
  the state, and the two full models;
- the evaluation's horizon findings.

    python benchmarks/horizons_pair.py LOG M0.npz M1.npz [--time-window A:B]
        [--stride N] [--horizons 0.002,0.01,0.1,0.5]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

import omavctl.diagnose.evaluate as ev
from omavctl.diagnose import horizons as hz
from omavctl.diagnose.horizon_findings import paired_se
from omavctl.learn.model_file import load_model

AXES = ("x", "y", "z")
PAIRS = (
    ("nominal", "effects_1"),
    ("nominal", "effects"),
    ("effects", "effects_1"),
    ("naive", "effects_1"),
    ("model", "model_1"),
)


def _row(rows: list[dict[str, Any]]) -> str:
    out = []
    for r in rows:
        se = r.get("rate_error_se") or {}
        err = "/".join(f"{r['rate_error'][a]:.3g}±{se.get(a, float('nan')):.2g}" for a in AXES)
        out.append(f"{r['seconds']:g} s {err}")
    cov = ""
    if rows[0].get("coverage"):
        cov = "  coverage " + "/".join(f"{100 * r['coverage']['all']:.0f}" for r in rows) + " %"
    return "  ".join(out) + cov


def _pair(table: dict[str, Any], a: str, b: str) -> str:
    out = []
    for ra, rb in zip(table[a], table[b], strict=True):
        parts = []
        for axis in AXES:
            d = rb["rate_error"][axis] - ra["rate_error"][axis]
            se = paired_se(ra, rb, axis)
            parts.append(f"{d:+.3g}" + ("" if se is None else f"±{se:.2g}"))
        out.append(f"{ra['seconds']:g} s " + "/".join(parts))
    return f"{b} - {a}: " + "  ".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("models", type=Path, nargs=2)
    ap.add_argument("--time-window", default=None, help="A:B, s from the log's first sample")
    ap.add_argument("--stride", type=int, default=2)
    ap.add_argument("--horizons", default="0.002,0.01,0.1,0.5")
    args = ap.parse_args()
    m0, m1 = (load_model(p) for p in args.models)
    window = None
    if args.time_window:
        a, b = args.time_window.split(":")
        window = (float(a) if a else None, float(b) if b else None)
    rate, sg = ev._grid(m0)
    samples, grids, _, _ = ev._read_logs([args.log], m0.vehicle, rate, sg, window, None)
    res = np.concatenate([s.residual for s in samples])
    print(f"one-step RMSE x/y/z rad/s^2: physics only {np.sqrt(np.mean(res**2, 0)).round(2)}")
    for j, m in enumerate((m0, m1)):
        eff = np.concatenate([m.effects_samples(s) for s in samples])
        rmse = np.sqrt(np.mean((res - eff) ** 2, 0)).round(2)
        print(f"  model {j} ({', '.join(m.effects) or 'no effects'}): physics + effects {rmse}")
    horizons = tuple(float(h) for h in args.horizons.split(","))
    t = hz.horizon_table([m0, m1], samples, grids, rate, horizons, stride=args.stride)
    print(f"{t['windows']} windows, a start every {t['stride']} samples, grid {rate:g} Hz")
    for p in t["predictors"]:
        print(f"  {p['key']:10s} {_row(t['table'][p['key']])}")
    for a, b in PAIRS:
        print("  " + _pair(t["table"], a, b))
    for f in t["findings"]:
        print(f"  finding {f['code']}: {f['message']}")


if __name__ == "__main__":
    main()
