"""Why the open-loop band misses: per axis and horizon, where and which term.

Evaluates a model on a log as ``evaluate`` does (the same samples, windows and
band), then per axis and horizon prints the coverage of the full model's 2σ
band for windows inside the fit flight's inputs and for windows that start or
pass beyond them (the one-step rule of ``training_envelope``: an input a
quarter of its training range beyond the training points' [min, max]), the
mean |error| and the median 2σ half-width there, and the share of the band's
variance each term holds: the measured noise, the drift of the residual
function (GP latent, beyond-the-box growth, effects' parameters, the GP mean
left out of rollouts) and the random walk of the GP's noise variance (times the
walk gain ``fit`` measured, :mod:`omavctl.learn.rollout_walk`; 1 for an older file).

    python benchmarks/horizons_band_cause.py MODEL.npz LOG [--time-window A:B]
        [--stride N]
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

import omavctl.diagnose.evaluate as ev
from omavctl.diagnose import horizons as hz
from omavctl.diagnose.metrics import outside_envelope
from omavctl.learn.model_file import load_model
from omavctl.learn.rollout_residual import gather, per_sample
from omavctl.learn.rollout_walk import walk_gain_at
from omavctl.learn.validation import beyond_envelope_variance

AXES = ("x", "y", "z")


def captured(model: str, log: str, window: Any) -> tuple[Any, list[Any], list[Any], float]:
    """The model, and the samples, grid signals and rate ``evaluate`` reads the log with."""
    m = load_model(model)
    rate, sg = ev._grid(m)
    samples, grids, _, _ = ev._read_logs([log], m.vehicle, rate, sg, window, None)
    return m, samples, grids, rate


def outside(m: Any, samples: list[Any]) -> list[np.ndarray]:
    """Per log (n, 1) 1.0 where a sample's GP inputs lie outside the training envelope,
    as ``evaluate`` counts it (:func:`~omavctl.diagnose.metrics.outside_envelope`)."""
    return [
        outside_envelope(m.inputs, s.inputs(m.features))[:, None].astype(float) for s in samples
    ]


def terms(m: Any, samples: list[Any]) -> dict[str, list[np.ndarray]]:
    """Per log (n, 3) the variances of the residual function's parts."""
    out: dict[str, list[np.ndarray]] = {"latent": [], "beyond": [], "effects": [], "left": []}
    lo, hi = m._box
    for s in samples:
        z = s.inputs(m.features)
        mean, var = m.gp_predict(z, noise=False)
        zn = m.normalise(z)
        beyond = np.stack(
            [
                m.beyond_scale[a]
                * beyond_envelope_variance(zn, lo, hi, m.signal_variance[a], m.length_scales[a])
                for a in range(3)
            ],
            axis=1,
        )
        out["beyond"].append(beyond)
        out["latent"].append(np.maximum(var - beyond, 0.0))
        out["effects"].append(m.effects_variance(s) if m.effects else np.zeros_like(var))
        out["left"].append(((1.0 - m.rollout_gp) * mean) ** 2)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model")
    ap.add_argument("log")
    ap.add_argument("--time-window", default=None)
    ap.add_argument("--stride", type=int, default=0, help="0: as evaluate chooses")
    args = ap.parse_args()
    window = None
    if args.time_window:
        a, b = args.time_window.split(":")
        window = (float(a) if a else None, float(b) if b else None)
    m, samples, grids, rate = captured(args.model, args.log, window)
    dt = 1.0 / rate
    steps = hz.horizon_steps(hz.DEFAULT_HORIZONS, rate)
    n_total = sum(s.n for s in samples)
    stride = args.stride or max(1, -(-n_total * (steps[-1] + 1) // hz.MAX_WINDOW_SAMPLES))
    win = gather(samples, grids, steps[-1], stride)
    print(f"{win.count} windows, stride {stride}, dt {dt:g} s")
    print(
        "model: gp on "
        + "/".join(str(int(v)) for v in m.gp_enabled)
        + ", rollout_gp "
        + "/".join(f"{v:g}" for v in m.rollout_gp)
        + ", noise std "
        + "/".join(f"{v:.3g}" for v in np.sqrt(m.noise_variance))
        + ", signal std "
        + "/".join(f"{v:.3g}" for v in np.sqrt(m.signal_variance))
        + ", beyond_scale "
        + "/".join(f"{v:.3g}" for v in m.beyond_scale)
    )
    with np.errstate(over="ignore", invalid="ignore"):
        full = hz._rolled(
            win,
            m.vehicle.inertia,
            m.vehicle.inertia_inv,
            dt,
            hz.residual_function(m, win, samples, True),
        )
    std = hz._band(m, win, samples, dt)
    err = full.rate
    out_w = per_sample(win, samples, outside(m, samples))[..., 0]  # (W, K + 1)
    parts = {k: per_sample(win, samples, v) for k, v in terms(m, samples).items()}
    total_fun = np.sqrt(sum(parts.values()))
    measured = win.noise_factor[:, :, None] * win.noise[:, None, :] ** 2
    process = np.maximum(m.noise_variance[None, :] - win.derivative_noise, 0.0)
    for k in steps:
        starts_out = out_w[:, 0] > 0
        passes_out = out_w[:, : k + 1].max(axis=1) > 0
        drift = dt * total_fun[:, :k].sum(axis=1)  # (W, 3)
        walk = k * dt**2 * process * walk_gain_at(m.provenance.get("rollout_walk"), [k])[0]
        print(f"\nhorizon {k * dt:g} s ({k} steps): windows inside {np.mean(~passes_out):.0%}")
        for a, name in enumerate(AXES):
            e = np.abs(err[:, k, a])
            sd = std[:, k, a]
            cov = e <= 2 * sd
            line = [f"  {name}: coverage {cov.mean():.0%}"]
            for label, sel in (
                ("inside", ~passes_out),
                ("starts beyond", starts_out),
                ("passes beyond", passes_out & ~starts_out),
            ):
                if sel.any():
                    line.append(
                        f"{label} {cov[sel].mean():.0%} (n {sel.sum()}, |e| "
                        f"{e[sel].mean():.3g}, 2σ med {np.median(2 * sd[sel]):.3g})"
                    )
            print("; ".join(line))
            var = sd**2
            share = {
                "noise": measured[:, k, a],
                "walk": walk[:, a],
                "drift": drift[:, a] ** 2,
            }
            fun = {
                p: dt * np.sqrt(v[:, :k, a]).sum(axis=1) for p, v in parts.items()
            }  # drift of each part alone
            txt = ", ".join(f"{p} {np.median(v / var):.0%}" for p, v in share.items())
            txt2 = ", ".join(f"{p} {np.median(v):.3g}" for p, v in fun.items())
            miss = ~cov
            ratio = np.median(e[miss] / sd[miss]) if miss.any() else float("nan")
            print(f"     variance shares (median): {txt}; drift alone, rad/s: {txt2}")
            print(f"     missed windows: median |e| / σ {ratio:.3g}")


if __name__ == "__main__":
    main()
