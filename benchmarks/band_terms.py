"""The terms of a model's 2-sigma band on a held-out log, inside the fit flight's inputs.

    python benchmarks/band_terms.py MODEL.npz LOG

Per axis, over the log's samples inside the model's training inputs (as ``evaluate``
counts them: at most a quarter of a training range beyond the training points' box):
the RMSE of the model, the RMS std of each term of the predictive variance, the total,
the 2-sigma coverage and the 95th percentile of |error| / std (2 for a calibrated
normal error). The terms: ``latent`` the calibrated GP posterior variance inside the
box, ``beyond`` its growth beyond the box, ``weigh`` the variance the mean's weighing
adds (``mean_shrink``), ``noise`` the band's noise (``band_noise`` inside the fit
inputs; beyond them rising to fit's floor from the held-out error, with the growth
with the torque and the reach: ``omavctl/learn/band.py``), ``effects`` the effects'
parameter term. Also the blocked
cross-validation's figures (``provenance.gp.validation``: the factor on the std, the
held-out coverage before it, the held-out RMSE) and the gyro-derived noise floor.
docs/intervals.md, "The model's band inside the fit flight's inputs".
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _r(x: object) -> object:
    """A list of numbers rounded to 3 digits for printing (anything else as it is)."""
    if isinstance(x, list) and all(isinstance(v, (int, float)) for v in x):
        return [round(float(v), 3) for v in x]
    return x


def main(argv: list[str] | None = None) -> int:
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.diagnose.metrics import ENVELOPE_MARGIN
    from omavctl.learn.model_file import load_model

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model", type=Path)
    ap.add_argument("log", type=Path)
    args = ap.parse_args(argv)
    m = load_model(args.model)
    rate, sg = _grid(m)
    s, *_ = _read_log(args.log, m.vehicle, rate, sg, None)
    z = s.inputs(m.features)
    shrink, beyond = m.mean_shrink.copy(), m.beyond_scale.copy()
    m.mean_shrink[:], m.beyond_scale[:] = 0.0, 0.0
    _, lat_box = m.gp_predict(z)
    m.beyond_scale[:] = beyond
    _, lat = m.gp_predict(z)
    m.mean_shrink[:] = shrink
    mean, gp_var = m.gp_predict(z)
    _, band = m.gp_predict(z, noise=True)
    assert lat_box is not None and lat is not None and gp_var is not None and band is not None
    eff = m.effects_variance(s) if m.effects else np.zeros_like(mean)
    err = s.residual - mean - m.effects_samples(s)
    lo, hi = m.inputs.min(0), m.inputs.max(0)
    span = np.where(hi - lo > 0, hi - lo, 1.0)
    inside = ~(np.maximum(lo - z, z - hi).clip(min=0) / span > ENVELOPE_MARGIN).any(axis=1)
    terms = {
        "latent": lat_box,
        "beyond": lat - lat_box,
        "weigh": gp_var - lat,
        "noise": band - gp_var,
        "effects": eff,
    }
    gp = m.provenance.get("gp", {})
    v = {k: _r(x) for k, x in gp.get("validation", {}).items()}
    print(f"{args.model.name} -> {args.log.name}: {inside.mean():.0%} of the samples inside")
    print(
        f"  cross-validation: std factor {v.get('std_factor')}, held-out coverage before it "
        f"{v.get('coverage')}, held-out RMSE {v.get('rmse_gp')}; gyro noise floor "
        f"{_r(gp.get('noise_floor'))}"
    )
    print(f"  noise std {np.sqrt(m.noise_variance).round(3)}")
    for a in range(3):
        e, tot = err[inside, a], band[inside, a] + eff[inside, a]
        if e.size == 0:
            continue
        parts = " ".join(f"{k} {np.sqrt(np.mean(t[inside, a])):.3f}" for k, t in terms.items())
        q95 = np.quantile(np.abs(e) / np.sqrt(tot), 0.95)
        print(
            f"  {'xyz'[a]}: RMSE {np.sqrt(np.mean(e**2)):.3f} | RMS std {parts} | total "
            f"{np.sqrt(np.mean(tot)):.3f} | coverage {np.mean(np.abs(e) <= 2 * np.sqrt(tot)):.3f}"
            f" | q95 |e|/std {q95:.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
