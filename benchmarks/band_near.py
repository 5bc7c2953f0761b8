"""The band narrowed near the fit flight's data (the GP's own distance), post hoc.

    python benchmarks/band_near.py DIR [--out FILE.jsonl]

DIR: a ``benchmarks/band_calibration.py --workdir``. Tried for issue 26 (the band
inside the fit flight's inputs, docs/intervals.md) and not landed: a sample is *near*
the fit flight's data on an axis when the GP's posterior variance there, over its
signal variance (:func:`posterior_ratio`: every input jointly, in the kernel's length
scales, so a combination of inputs the fit flight never flew is not near), is at most
``t``: the median of that ratio at the training points left out one at a time, capped
at 0.1. Up to ``t`` the band's variance (the GP's and the noise, not the effects'
parameter term) is multiplied by ``f^2``, ``f <= 1`` the factor that puts 95 % of the
training points' leave-one-out errors within 2 stds; the factor fades to 1 at ``2 t``
and beyond a quarter range beyond the box. Every model is judged on every other
family's flight with its band as ``fit`` writes it and with the narrowing (the mean is
the same); printed: axis-flights with coverage >= 0.85 (and those that fell below),
<= 0.99 inside the fit inputs by ``evaluate``'s box and on the near samples, and the
axis-flights whose near samples are covered < 0.85 (overconfident where narrowed).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

FAMILIES = ("fig8", "wobble", "chirp", "steps")
#: share of the leave-one-out errors inside 2 stds; quantile of their variance ratio
#: that sets ``t``, and its cap; ``t`` times this: the narrowing gone
NEAR_COVERAGE, NEAR_SHARE, NEAR_RATIO_MAX, NEAR_REACH = 0.95, 0.5, 0.1, 2.0


def posterior_ratio(model: Any, z: np.ndarray) -> np.ndarray:
    """Posterior variance (B, 3) over signal variance at GP inputs z (B, d), as the
    kernel gives it (1 on an axis without a GP)."""
    zn = model.normalise(np.atleast_2d(z))
    out = np.ones((zn.shape[0], 3))
    for a in np.flatnonzero(model.signal_variance > 0):
        zq = zn / model.length_scales[a]
        k = model._kernel(a, zq, np.einsum("bd,bd->b", zq, zq))
        v = solve_triangular(model._chol[a], k.T, lower=True, check_finite=False)
        out[:, a] = 1.0 - np.einsum("nb,nb->b", v, v) / model.signal_variance[a]
    return np.asarray(out.clip(0.0, 1.0))


def near_calibration(model: Any) -> tuple[np.ndarray, np.ndarray]:
    """Threshold ``t`` (3,) and factor ``f`` (3,) from the training points left out
    one at a time (the GP mean before weighing, the latent variance as calibrated plus
    the band's noise)."""
    n = model._chol.shape[1]
    t, f = np.zeros(3), np.ones(3)
    for a in np.flatnonzero(model.signal_variance > 0):
        inv = solve_triangular(model._chol[a], np.eye(n), lower=True, check_finite=False)
        diag = np.einsum("ij,ij->j", inv, inv)  # diag of (K + s^2 I)^-1
        latent = np.maximum(1.0 / diag - model.noise_variance[a], 0.0)
        share = float(np.quantile(latent, NEAR_SHARE)) / model.signal_variance[a]
        t[a] = min(share, NEAR_RATIO_MAX)
        error = model._alpha[a] / diag
        var = model.latent_scale[a] * latent + model.band_noise[a]
        ratio = np.abs(error) / np.sqrt(np.maximum(var, 1e-300))
        f[a] = min(float(np.quantile(ratio, NEAR_COVERAGE)) / 2.0, 1.0)
    return t, f


def near_weight(model: Any, z: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Weight (B, 3) of the narrowing: 1 up to ``t``, 0 from ``NEAR_REACH t`` and from a
    quarter range beyond the training box."""
    from omavctl.learn.effects_band import beyond_weight

    r = posterior_ratio(model, z)
    w = np.clip((NEAR_REACH * t - r) / ((NEAR_REACH - 1.0) * np.maximum(t, 1e-300)), 0, 1)
    w[:, t <= 0] = 0.0
    return np.asarray(w * (beyond_weight(model.inputs, z) <= 0)[:, None])


def judge(model: Any, log: Path) -> dict[str, Any]:
    """Coverage, inside the box and on the near samples, without and with the narrowing."""
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.diagnose.metrics import training_envelope

    rate, sg = _grid(model)
    s = _read_log(log, model.vehicle, rate, sg, None)[0]
    z = s.inputs(model.features)
    t, f = near_calibration(model)
    w = near_weight(model, z, t)
    mean, var = model.predict_samples(s, noise=True)
    err = s.residual - mean
    params = model.effects_variance(s) if model.effects else np.zeros_like(var)
    row: dict[str, Any] = {
        "t": t.tolist(),
        "f": f.tolist(),
        "near_share": (w >= 1).mean(0).tolist(),
    }
    for label, v in (("before", var), ("after", (var - params) * (1 - (1 - f**2) * w) + params)):
        ok = np.abs(err) <= 2.0 * np.sqrt(v)
        env = training_envelope(model.inputs, z, list(model.input_names), err, np.sqrt(v))
        near = [ok[w[:, a] >= 1, a] for a in range(3)]
        row[label] = {
            "coverage": ok.mean(0).tolist(),
            "inside": [env["coverage_inside"][a] for a in "xyz"],
            "near": [float(c.mean()) if c.size >= 20 else None for c in near],
        }
    return row


def print_summary(rows: list[dict[str, Any]]) -> None:
    """The counts of the module docstring, before and after."""
    was = np.array([r["before"]["coverage"] for r in rows]).ravel()
    for label in ("before", "after"):
        cov = np.array([r[label]["coverage"] for r in rows]).ravel()
        line = f"{label}: {cov.size} axis-flights, coverage >= 0.85 on {(cov >= 0.85).sum()} "
        line += f"(min {cov.min():.3f}; fell below {int(((was >= 0.85) & (cov < 0.85)).sum())})"
        for key in ("inside", "near"):
            v = np.array([np.nan if c is None else c for r in rows for c in r[label][key]])
            has = np.isfinite(v)
            line += f"; {key} <= 0.99 on {(v[has] <= 0.99).sum()}/{has.sum()}"
            if key == "near":
                line += f", near < 0.85 on {(v[has] < 0.85).sum()} (min {v[has].min():.3f})"
        print(line)


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
                rows.append({"model": path.stem, "held": held, **judge(model, log)})
    print_summary(rows)
    if args.out:
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
