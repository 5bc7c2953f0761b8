"""Band variants sized by the fit flight's held-out time blocks, post hoc on fitted models.

    python benchmarks/band_heldout.py DIR [--out FILE.jsonl]

DIR: a ``benchmarks/band_calibration.py --workdir``. Per model the fit flight's time
blocks (``fold_of``) are rebuilt from its training points (matched to the flight's
samples), the model is conditioned on the points outside each block and predicts it
(the band's variance v and the error e). Fitted on those: a factor <= 1 on the band
(``narrowT``: T held-out coverage), whole-band scales ``a + b x`` (``h-KIND``, least
squares on e^2 / v, then scaled to T; x the torque, every input, the torque rate or the
latent share; ``m-*`` several at once), the noise ``a + b x`` by the Gaussian
likelihood (``n-KIND``, as ``fit`` now does with x the torque) and constant factors
``fF`` for scale. Each is applied inside the fit inputs, rising to the band as it is
beyond them; printed: axis-flights >= 0.85, those that fell below, inside <= 0.99.
docs/intervals.md, "The model's band inside the fit flight's inputs" (the table of
variants tried post hoc, measured on models fitted at 15ff461, before ``fit`` fitted the
noise itself). Exploratory: written to find the rule, kept to reproduce it.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
FAMILIES = ("fig8", "wobble", "chirp", "steps")
TORQUE = ("(I^-1 tau)x", "(I^-1 tau)y", "(I^-1 tau)z")


def read(model: Any, log: Path) -> Any:
    from omavctl.diagnose.evaluate import _grid, _read_log

    rate, sg = _grid(model)
    return _read_log(log, model.vehicle, rate, sg, None)[0]


def sub_model(model: Any, keep: np.ndarray) -> Any:
    m = copy.copy(model)
    m.inputs, m.targets = model.inputs[keep], model.targets[keep]
    m.train_regressors = {k: v[keep] for k, v in model.train_regressors.items()}
    m._factorise(int(keep.sum()))
    return m


def size(model: Any, s: Any, kind: str) -> np.ndarray:
    """Input size (B,) per sample."""
    z = s.inputs(model.features)
    if kind == "dtau":
        du = s.du[:, 3:] / model.input_scale[[model.input_names.index(n) for n in TORQUE]]
        return np.sqrt((du**2).sum(1))
    if kind == "torque":
        cols = [model.input_names.index(n) for n in TORQUE]
    elif kind == "rate":
        cols = [j for j, n in enumerate(model.input_names) if n.startswith("omega")]
    else:
        cols = list(range(len(model.input_names)))
    zn = (z - model.input_mean) / model.input_scale
    return np.sqrt((zn[:, cols] ** 2).sum(1))


def held_out(model: Any, fit_log: Path) -> tuple[Any, ...]:
    """The fit flight's samples and, in its held-out time blocks: the error (k, 3), the
    band's variance (k, 3), the latent share of the signal variance (k, 3), the band's
    variance without its noise (k, 3); and the largest distance of a training point to
    its matched sample (0: matched exactly)."""
    from omavctl.learn.validation import fold_of

    s = read(model, fit_log)
    z = s.inputs(model.features)
    # training point -> nearest sample (its time block)
    d2 = ((model.normalise(model.inputs)[:, None, :] - model.normalise(z)[None]) ** 2).sum(-1)
    near = d2.argmin(1)
    fold = fold_of(s.t, np.zeros(s.n, int))
    tfold = fold[near]
    errs, vars_, sel = [], [], []
    for f in np.unique(fold):
        sub = sub_model(model, tfold != f)
        ss = s.select(fold == f)
        mean, var = sub.predict_samples(ss, noise=True)
        _, lat = sub.latent(ss.inputs(model.features))
        _, rest = sub.predict_samples(ss, noise=False)
        lat = np.concatenate([lat / np.maximum(model.signal_variance, 1e-300), rest], 1)
        errs.append(ss.residual - mean)
        vars_.append(np.concatenate([var, lat], 1))
        sel.append(np.flatnonzero(fold == f))
    idx = np.concatenate(sel)
    order = np.argsort(idx)
    vv = np.concatenate(vars_)[order]
    return (
        s.select(np.ones(s.n, bool)),
        np.concatenate(errs)[order],
        vv[:, :3],
        vv[:, 3:6],
        vv[:, 6:],
        float(np.sqrt(d2.min(1)).max()),
    )


def noise_ml(e, vr, x):
    """Per axis (a, b) >= 0 of the noise a + b x maximising the Gaussian likelihood of the
    held-out errors e with variance vr + a + b x."""
    from scipy.optimize import minimize

    out = np.zeros((3, 2))
    for k in range(3):
        m = np.mean(e[:, k] ** 2)

        def nll(p, k=k, m=m):
            n = m * (np.exp(p[0]) + np.exp(p[1]) * x[:, k])
            var = vr[:, k] + n
            return np.mean(np.log(var) + e[:, k] ** 2 / var)

        r = minimize(nll, [np.log(0.5), np.log(0.1)], method="Nelder-Mead")
        out[k] = m * np.exp(r.x)
    return out


def multi_fit(e, v, xl, target=0.95):
    """g = a + sum_j b_j x_j (NNLS on e^2/v), then scaled to the target held-out coverage."""
    from scipy.optimize import nnls

    C = []
    for k in range(3):
        r = e[:, k] ** 2 / v[:, k]
        X = np.stack([np.ones(len(r))] + [x[:, k] for x in xl], 1)
        coef, _ = nnls(X, r)
        coef[0] = max(coef[0], 1e-3 * r.mean())
        g = X @ coef
        q = np.quantile(np.abs(e[:, k]) / np.sqrt(v[:, k] * g), target)
        C.append(coef * (q / 2.0) ** 2)
    return np.array(C)


def factor_fit(e, v, x, target=0.95):
    """Per axis (a, b) of g(u) = a + b u^2 fitted to e^2/v (least squares, b >= 0, a > 0),
    then both scaled so the held-out 2-sigma coverage is 0.95."""
    A, B = np.zeros(3), np.zeros(3)
    for k in range(3):
        r = e[:, k] ** 2 / v[:, k]
        X = np.stack([np.ones_like(x[:, k]), x[:, k]], 1)
        coef, *_ = np.linalg.lstsq(X, r, rcond=None)
        a, b = coef
        if b < 0:
            a, b = r.mean(), 0.0
        a = max(a, 1e-3 * r.mean())
        g = a + b * x[:, k]
        q = np.quantile(np.abs(e[:, k]) / np.sqrt(v[:, k] * g), target)
        c2 = (q / 2.0) ** 2
        A[k], B[k] = a * c2, b * c2
    return A, B


def main() -> int:
    from omavctl.diagnose.metrics import training_envelope
    from omavctl.learn.effects_band import beyond_weight
    from omavctl.learn.model_file import load_model

    ap = argparse.ArgumentParser()
    ap.add_argument("workdir", type=Path)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--kind", default="torque")
    args = ap.parse_args()
    rows = []
    for path in sorted(args.workdir.glob("*.npz")):
        case, fit_on = path.stem.replace("+effects", "").split("-", 1)
        model = load_model(path)
        s_fit, e, v, latf, vrest, match = held_out(model, args.workdir / f"{case}-{fit_on}.csv")
        xs = {}
        for kind in ("torque", "all", "dtau"):
            u = size(model, s_fit, kind)
            m2 = np.mean(u**2)
            xs[kind] = lambda s, kind=kind, m2=m2, model=model: np.repeat(
                (size(model, s, kind) ** 2 / m2)[:, None], 3, 1
            )
        xs["latent"] = None
        rules = {}
        for f in (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9):
            rules[f"f{f}"] = ("const", np.full(3, f), None)
        xl = [xs["torque"](s_fit), xs["dtau"](s_fit), latf]
        for kind in ("torque", "all"):
            rules[f"n-{kind}"] = ("noise-" + kind, noise_ml(e, vrest, xs[kind](s_fit)), None)
        for T in (0.95, 0.98, 0.99):
            q = np.quantile(np.abs(e) / np.sqrt(v), T, axis=0) / 2
            rules[f"narrow{T}"] = ("const", np.minimum(q, 1.0) ** 2, None)
            for kind in xs:
                xf = latf if kind == "latent" else xs[kind](s_fit)
                A, B = factor_fit(e, v, xf, T)
                rules[f"h-{kind}{T}"] = (kind, A, B)
            rules[f"m-tdl{T}"] = ("multi", multi_fit(e, v, xl, T), None)
            rules[f"m-td{T}"] = ("multi2", multi_fit(e, v, xl[:2], T), None)
        print(
            f"{path.stem}: match {match:.1e}; held-out coverage "
            f"{np.mean(np.abs(e) <= 2 * np.sqrt(v), 0).round(3)}",
            flush=True,
        )
        for held in FAMILIES:
            log = args.workdir / f"{case}-{held}.csv"
            if held == fit_on or not log.exists():
                continue
            s = read(model, log)
            z = s.inputs(model.features)
            mean, var = model.predict_samples(s, noise=True)
            _, lat = model.latent(z)
            err = s.residual - mean
            rho = beyond_weight(model.inputs, z)[:, None]
            var_sets = {"now": var}
            for name, (kind, A, B) in rules.items():
                if kind.startswith("noise-"):
                    _, vr = model.predict_samples(s, noise=False)
                    x = xs[kind[6:]](s)
                    vin = vr + A[:, 0] + A[:, 1] * x
                    var_sets[name] = (1 - rho) * vin + rho * np.maximum(var, vin)
                    continue
                if kind.startswith("multi"):
                    xl = [
                        xs["torque"](s),
                        xs["dtau"](s),
                        lat / np.maximum(model.signal_variance, 1e-300),
                    ]
                    xl = xl[: 3 if kind == "multi" else 2]
                    X = np.stack([np.ones_like(var), *xl], -1)
                    g = np.einsum("bkj,kj->bk", X, A)
                elif kind == "const":
                    g = np.broadcast_to(A, var.shape)
                else:
                    x = (
                        lat / np.maximum(model.signal_variance, 1e-300)
                        if kind == "latent"
                        else xs[kind](s)
                    )
                    g = A + B * x
                var_sets[name] = var * ((1 - rho) * g + rho * np.maximum(g, 1.0))
            for name, vv in var_sets.items():
                env = training_envelope(model.inputs, z, list(model.input_names), err, np.sqrt(vv))
                rows.append(
                    {
                        "model": path.stem,
                        "held": held,
                        "variant": name,
                        "coverage": np.mean(np.abs(err) <= 2 * np.sqrt(vv), 0).tolist(),
                        "inside": [env["coverage_inside"][a] for a in "xyz"],
                    }
                )
    from benchmarks.band_variants import print_summary

    print_summary(rows, "now", 10)
    if args.out:
        args.out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
