"""The persistent bias of a model's residual on its fit flight and on a held-out flight,
and what the accelerometer's lateral specific force says of it (docs/horizons.md,
"The Crazyflie halves' persistent bias": issue #28).

Per case (``horizons_lag.py``'s cases: a model fitted on one flight, judged on
another; fitted into ``--workdir`` when missing), per flight (the fit flight's
samples, the judged flight's) and axis, rad/s^2:

- the mean of the residual after the physical effects and after the full model
  (effects + GP mean: does the GP carry the bias on the fit flight?), the mean
  commanded torque (``I^-1 tau``; the rate loop's integrator holds the trim), and
  the RMS of the residual's block means over 0.5 s and 2 s (what a 0.5 s rollout
  integrates: a constant ``a`` gives ``a t`` of rate, ``a t^2 / 2`` of angle);
- where the log has an accelerometer (the Crazyflie's ``acc.x/y`` in g, read from
  the ``.csv.gz`` beside the log; Betaflight's ``accSmooth[0/1]``, raw units): the
  correlation of the 0.5 s block means of roll's residual with the lateral
  specific force ``a_y`` and of pitch's with ``a_x`` (a rotor-drag moment: a
  torque ``r_z x f`` of the horizontal drag force acting above the centre of
  mass, which the accelerometer measures and the motor mix does not have);
- a torque ``c + k a_lat`` per axis (roll on ``a_y``, pitch on ``a_x``) fitted by
  least squares on the fit flight's residual after the effects, then on the
  judged flight: the one-step RMSE before -> after and the 0.5 s horizon table
  (mean |body-rate error| and 2σ coverage per axis) with the term added to the
  rollout's residual, two ways: ``along`` the measured specific force at every
  step (an oracle: the force depends on the velocity, a state the rollout does
  not integrate) and ``held`` at the window's start (what an open-loop
  prediction from the start's state may use).

``--smooth S`` averages the specific force over the trailing S seconds first.

    python benchmarks/trim_bias.py --cases crazyflie --workdir DIR [--stride 2] [--smooth 0]
"""

from __future__ import annotations

import argparse
import csv
import gzip
import sys
from pathlib import Path
from typing import Any

import numpy as np

import omavctl.diagnose.evaluate as ev
from omavctl.diagnose import horizons as hz
from omavctl.learn.model_file import load_model
from omavctl.learn.rollout_residual import per_sample

sys.path.insert(0, str(Path(__file__).resolve().parent))
import horizons_lag as lag

AXES = ("x", "y", "z")
#: (time column, its scale to s, lateral x and y columns, their scale to m/s^2)
ACC_COLUMNS = (
    ("timestamp", 1e-3, "acc.x", "acc.y", 9.81),  # Crazyflie SD-card log: ms, g
    ("time", 1e-6, "accSmooth[0]", "accSmooth[1]", 1.0),  # Betaflight: us, raw
)


def _fmt(v: np.ndarray) -> str:
    return "/".join(f"{x:+.3g}" for x in v)


def block_means(x: np.ndarray, t: np.ndarray, seconds: float) -> np.ndarray:
    """Means (B, c) of x (n, c) over blocks of ``seconds`` of t (n,) holding > 10 samples."""
    ids = np.floor((t - t[0]) / seconds).astype(int)
    return np.array([x[ids == i].mean(axis=0) for i in np.unique(ids) if (ids == i).sum() > 10])


def read_accelerometer(log: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """Time (n,) s from the first sample and lateral specific force (n, 2) of a log's CSV
    (the log itself or ``<log>.csv.gz``), or None when it has no accelerometer."""
    path = log if log.name.endswith(".csv.gz") else log.with_name(log.name + ".csv.gz")
    if not path.exists():
        return None
    with gzip.open(path, "rt") as fh:
        header = next(csv.reader(fh))
    for time_col, t_scale, ax, ay, scale in ACC_COLUMNS:
        if {time_col, ax, ay} <= set(header):
            cols = [header.index(c) for c in (time_col, ax, ay)]
            data = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=cols)
            data = data[np.all(np.isfinite(data), axis=1)]
            return (data[:, 0] - data[0, 0]) * t_scale, data[:, 1:] * scale
    return None


def lateral(acc: tuple[np.ndarray, np.ndarray], s: Any, smooth: float) -> np.ndarray:
    """The specific force (n, 3) at the samples' times: column 0 the roll regressor a_y,
    column 1 the pitch regressor a_x, column 2 zero; a trailing mean over ``smooth`` s."""
    t, f = acc
    a = np.stack([np.interp(s.t, t, f[:, 1]), np.interp(s.t, t, f[:, 0]), np.zeros(s.n)], axis=1)
    w = int(np.rint(smooth / np.median(np.diff(s.t)))) if smooth > 0 else 1
    if w > 1:
        ker = np.ones(w) / w
        a = np.stack([np.convolve(a[:, i], ker, mode="full")[: s.n] for i in range(3)], axis=1)
    return a


def describe(m: Any, s: Any, label: str, acc: np.ndarray | None) -> np.ndarray:
    """Print the bias of one flight's samples; returns the residual after the effects."""
    after_fx = s.residual - m.effects_samples(s)
    gp, _ = m.gp_predict(s.inputs(m.features), variance=False)
    print(f"  {label} ({s.n} samples, {s.t[0]:.2f}-{s.t[-1]:.2f} s):")
    print(f"    mean residual after effects {_fmt(after_fx.mean(axis=0))}; after effects + GP "
          f"mean {_fmt((after_fx - gp).mean(axis=0))}; mean commanded torque I^-1 tau "
          f"{_fmt(s.u[:, 3:].mean(axis=0))}")  # fmt: skip
    for sec in (0.5, 2.0):
        rms = np.sqrt(np.mean(block_means(after_fx, s.t, sec) ** 2, axis=0))
        rms_all = np.sqrt(np.mean(block_means(after_fx - gp, s.t, sec) ** 2, axis=0))
        print(f"    block means over {sec:g} s, RMS: after effects {_fmt(rms)}; "
              f"after the full model {_fmt(rms_all)}")  # fmt: skip
    cmd = block_means(s.u[:, 3:], s.t, 2.5)
    print(f"    2.5 s block means of the commanded torque range {_fmt(cmd.min(axis=0))} to "
          f"{_fmt(cmd.max(axis=0))}")  # fmt: skip
    if acc is not None:
        r, a = block_means(after_fx, s.t, 0.5), block_means(acc, s.t, 0.5)
        cor = [np.corrcoef(r[:, i], a[:, i])[0, 1] for i in (0, 1)]
        print(f"    0.5 s block means: corr(roll residual, a_y) {cor[0]:+.2f}, "
              f"corr(pitch residual, a_x) {cor[1]:+.2f}")  # fmt: skip
    return after_fx


def fit_term(residual: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """Least-squares (c, k) (2, 3) of ``residual ~ c + k acc`` per axis (z: none)."""
    coef = np.zeros((2, 3))
    for i in (0, 1):
        design = np.column_stack([np.ones(acc.shape[0]), acc[:, i]])
        coef[:, i] = np.linalg.lstsq(design, residual[:, i], rcond=None)[0]
    return coef


def _table(m: Any, samples: Any, grids: Any, rate: float, stride: int, tag: str) -> None:
    t = hz.horizon_table([m], samples, grids, rate, stride=stride)
    for key in ("effects", "model"):
        errs = "  ".join(
            f"{r['seconds']:g} s " + "/".join(f"{r['rate_error'][a]:.3g}" for a in AXES)
            for r in t["table"][key]
        )
        print(f"    {tag:7s} {key:8s} {errs}")
    cov = "  ".join(
        f"{r['seconds']:g} s " + "/".join(f"{100 * r['coverage'][a]:.0f}" for a in AXES)
        for r in t["table"]["model"]
    )
    print(f"    {tag:7s} coverage {cov}")


def rollouts(m: Any, judged: Any, grids: Any, rate: float, term: np.ndarray, stride: int) -> None:
    """The horizon table without the term, with it along the window, held at the start."""
    original = hz.residual_function
    _table(m, [judged], grids, rate, stride, "without")
    for mode in ("along", "held"):

        def patched(mm: Any, win: Any, samples: Any, with_gp: bool, mode: str = mode) -> Any:
            base = original(mm, win, samples, with_gp)
            extra = per_sample(win, samples, [term])
            if mode == "held":
                return lambda k, omega: base(k, omega) + extra[:, 0]
            return lambda k, omega: base(k, omega) + extra[:, k]

        hz.residual_function = patched  # type: ignore[assignment]
        try:
            _table(m, [judged], grids, rate, stride, mode)
        finally:
            hz.residual_function = original


def run_case(label: str, model: Path, log: Path, window: Any, args: Any) -> None:
    m = load_model(model)
    rate, sg = ev._grid(m)
    print(f"{label}: {model.name}, effects {list(m.effects)}, rollout_gp {m.rollout_gp.tolist()}")
    sources = [Path(p["abspath"]) for p in m.provenance.get("sources", [])]
    tw = m.provenance.get("time_window")
    fit_samples, _, _, _ = ev._read_logs(sources, m.vehicle, rate, sg, tw and tuple(tw), None)
    fit_res, fit_acc = [], []
    for src, s in zip(sources, fit_samples, strict=True):
        raw = read_accelerometer(src)
        acc = None if raw is None else lateral(raw, s, args.smooth)
        fit_res.append(describe(m, s, f"fit flight {src.name} {tw or ''}", acc))
        fit_acc.append(acc)
    judged, grids, _, _ = ev._read_logs([log], m.vehicle, rate, sg, window, None)
    raw = read_accelerometer(log)
    acc = None if raw is None else lateral(raw, judged[0], args.smooth)
    res = describe(m, judged[0], f"judged flight {log.name} {window or ''}", acc)
    if acc is None or any(a is None for a in fit_acc):
        return
    coef = fit_term(np.concatenate(fit_res), np.concatenate(fit_acc))
    term = coef[0] + coef[1] * acc
    term[:, 2] = 0.0
    full = judged[0].residual - m.predict_samples(judged[0], variance=False)[0]
    rmse = lambda x: np.sqrt(np.mean(x**2, axis=0))  # noqa: E731
    print(f"  term fitted on the fit flight: roll {coef[0, 0]:+.3g} {coef[1, 0]:+.3g} a_y, "
          f"pitch {coef[0, 1]:+.3g} {coef[1, 1]:+.3g} a_x; judged one-step RMSE, physics + "
          f"effects {_fmt(rmse(res))} -> {_fmt(rmse(res - term))}, full model "
          f"{_fmt(rmse(full))} -> {_fmt(rmse(full - term))}")  # fmt: skip
    rollouts(m, judged[0], grids, rate, term, args.stride)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="crazyflie")
    ap.add_argument("--workdir", type=Path, required=True)
    ap.add_argument("--stride", type=int, default=2)
    ap.add_argument("--smooth", type=float, default=0.0)
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    for name in args.cases.split(","):
        for case in lag.cases(name.strip(), args.workdir):
            run_case(*case, args)
            sys.stdout.flush()


if __name__ == "__main__":
    main()
