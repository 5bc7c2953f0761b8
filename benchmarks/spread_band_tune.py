"""The band's thrust-spread term on the tune draws' last models (docs/scorecard.md,
session 28; docs/intervals.md, "The rotors' spread on another flight").

For every draw directory of a replay (``scorecard_replay.py replay ... --label L
--refit-first``), the last model of the replay on the draw's held-out log: 2-sigma
coverage per axis and inside the fit flight's inputs, with the term as ``evaluate``
adds it (``weighted``: times the GP's distance from its training points), with it at
full weight everywhere (``full``), and without it (``none``). The mean is the same in
all three, so the scores of the loop are the replay's.

    python benchmarks/spread_band_tune.py /work/sc27/own-* --label v3 --jobs 2

prints one JSON line per draw, then the counts of axis-flights below 0.85 and above
0.99 inside the fit inputs.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def _draw(args: tuple[str, str]) -> dict[str, Any]:
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.diagnose.metrics import training_envelope
    from omavctl.learn.model_file import load_model
    from omavctl.learn.spread_band import gp_distance, spread_variance

    d, label = Path(args[0]), args[1]
    out: dict[str, Any] = {"draw": d.name}
    replays = sorted(d.glob(f"replay-{label}*"))
    if not replays:
        return {**out, "error": "no replay"}
    r = replays[0]
    models = sorted(
        (p for p in r.glob("m0*.npz") if ".eval." not in p.name), key=lambda p: len(p.name)
    )
    held = next(p for p in sorted(r.iterdir()) if p.name == "held" or p.name.startswith("held."))
    m = load_model(models[-1])
    rate, sg = _grid(m)
    s, *_ = _read_log(held, m.vehicle, rate, sg, None)
    mean, var = m.predict_samples(s, noise=True)
    weighted = spread_variance(m, s)
    z = s.inputs(m.features)
    rho = gp_distance(m, z)
    full = np.divide(weighted, rho, out=np.zeros_like(weighted), where=rho > 0)
    err = s.residual - mean
    for name, v in (("weighted", var), ("full", var - weighted + full), ("none", var - weighted)):
        env = training_envelope(m.inputs, z, list(m.input_names), err, np.sqrt(v))
        out[name] = {
            "coverage": np.mean(np.abs(err) <= 2.0 * np.sqrt(v), axis=0).round(4).tolist(),
            "inside": [env["coverage_inside"][a] for a in "xyz"],
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("draws", nargs="+", help="draw directories (WORKDIR/SPLIT-NNNN)")
    ap.add_argument("--label", required=True, help="the replay's label")
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args()
    dirs = [d for d in args.draws if Path(d).is_dir()]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(_draw, [(d, args.label) for d in dirs]))
    for row in rows:
        print(json.dumps(row))
    ok = [r for r in rows if "error" not in r]
    for name in ("none", "full", "weighted"):
        cov = np.array([r[name]["coverage"] for r in ok])
        inside = np.array([[np.nan if v is None else v for v in r[name]["inside"]] for r in ok])
        print(
            f"{name:>8}: 2-sigma < 0.85 on {int((cov < 0.85).sum())}/{cov.size} axis-flights; "
            f"> 0.99 inside the fit inputs on {int(np.nansum(inside > 0.99))}/"
            f"{int(np.isfinite(inside).sum())}"
        )


if __name__ == "__main__":
    main()
