"""Why the GP hurt yaw at 0.5 s on the real log while it helped one step ahead.

The px4tools octocopter as in ``horizons_study.py`` (fit on 6.5-15 s, evaluate
on 15 s to the end), with the GP mean in rollouts on every axis (``rollout_gp``
1, the behaviour before fit's check on held-out rollouts). Prints the yaw
residual after the effects per 2 s block of the whole flight, the yaw command
and the GP's yaw mean after the fit span, the one-step and 0.5 s errors with
and without the GP, the 0.5 s ratio with the GP's prior mean replaced by the fit
span's mean residual, and what fit's check found; then the gyro noise estimated at
the log's own samples against the 100 Hz grid's estimate (docs/horizons.md).

    python benchmarks/horizons_yaw.py [--workdir DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from omavctl.diagnose.evaluate import _grid, _read_logs
from omavctl.diagnose.horizons import _rolled
from omavctl.learn.fit import fit_model
from omavctl.learn.model import ResidualGP
from omavctl.learn.model_file import load_model, save_model
from omavctl.learn.rollout_residual import gather, residual_function
from omavctl.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared/data/real/px4tools_octocopter/01_07_59.csv"
K = 50  # 0.5 s at 100 Hz


def _with(m: ResidualGP, **changes) -> ResidualGP:
    keys = (
        "vehicle", "features", "input_names", "inputs", "targets", "input_mean",
        "input_scale", "target_mean", "signal_variance", "length_scales",
        "noise_variance", "latent_scale", "beyond_scale", "mean_shrink", "effects",
    )  # fmt: skip
    return ResidualGP(**{**{k: getattr(m, k) for k in keys}, **changes})


def _ratio(m: ResidualGP, samples, grids) -> tuple[float, float, float]:
    """0.5 s mean |yaw error| of physics + effects and of the full model, and their ratio."""
    rate, _ = _grid(m)
    win = gather(samples, grids, K, 1)
    v = m.vehicle
    err = [
        _rolled(win, v.inertia, v.inertia_inv, 1.0 / rate, residual_function(m, win, samples, g))
        for g in (False, True)
    ]
    e = [float(np.abs(r.rate[:, K, 2]).mean()) for r in err]
    return e[0], e[1], e[1] / e[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=None)
    work = ap.parse_args().workdir or Path(tempfile.mkdtemp(prefix="horizons-yaw-"))
    work.mkdir(parents=True, exist_ok=True)
    vehicle = load_vehicle(ROOT / "examples" / "px4tools-octocopter.yaml")
    path = work / "px4tools-gp.npz"
    if not path.exists():
        save_model(path, fit_model([REAL], vehicle, time_window=(6.5, 15.0)).model)
    fitted = load_model(path)
    print("fit's check on held-out rollouts:", fitted.provenance.get("rollout_check"))
    m = _with(fitted)  # rollout_gp 1 on every axis: the GP mean in rollouts
    rate, sg = _grid(m)
    whole = _read_logs([REAL], vehicle, rate, sg, None, None)[0][0]
    r = whole.residual - m.effects_samples(whole)
    print("yaw residual after the effects per 2 s block (rad/s^2):")
    for t0 in np.arange(whole.t.min(), whole.t.max() - 1.0, 2.0):
        sel = (whole.t >= t0) & (whole.t < t0 + 2.0)
        print(f"  {t0:5.1f} s  {r[sel, 2].mean():+.4f}  ({sel.sum()} samples)")
    fit_s = _read_logs([REAL], vehicle, rate, sg, (6.5, 15.0), None)[0][0]
    samples, grids = _read_logs([REAL], vehicle, rate, sg, (15.0, None), None)[:2]
    s = samples[0]
    z = s.inputs(m.features)
    res = s.residual - m.effects_samples(s)
    shrunk, _ = m.gp_predict(z, variance=False)
    raw, var = _with(m, mean_shrink=np.zeros(3)).gp_predict(z)  # the latent variance alone
    assert var is not None
    yaw_cmd = m.normalise(z)[:, 5]
    print(
        f"after the fit span: yaw command (normalised) {yaw_cmd.mean():+.2f} ± {yaw_cmd.std():.2f}"
    )
    print(
        f"  yaw residual mean {res[:, 2].mean():+.4f}, GP mean {raw[:, 2].mean():+.4f} "
        f"(shrunk {shrunk[:, 2].mean():+.4f}), latent std {np.sqrt(var[:, 2]).mean():.4f}"
    )
    one = [np.sqrt((res[:, 2] ** 2).mean()), np.sqrt(((res[:, 2] - shrunk[:, 2]) ** 2).mean())]
    print(f"  one-step yaw RMSE: physics + effects {one[0]:.4f}, full model {one[1]:.4f}")
    e_eff, e_full, ratio = _ratio(m, samples, grids)
    print(f"  0.5 s yaw error: physics + effects {e_eff:.5f}, full {e_full:.5f} (x{ratio:.3f})")
    fit_mean = (fit_s.residual - m.effects_samples(fit_s)).mean(axis=0)
    alt = _ratio(_with(m, target_mean=fit_mean), samples, grids)[2]
    print(
        f"  GP prior mean {m.target_mean[2]:+.4f} -> the fit span's mean residual "
        f"{fit_mean[2]:+.4f}: 0.5 s ratio x{ratio:.3f} -> x{alt:.3f}"
    )
    print(f"gyro noise after the fit span at the log's rows: {native_noise().round(5)} rad/s,")
    print(f"  on the 100 Hz grid: {np.asarray(s.rate_noise).round(5)} rad/s")


def native_noise(start: float = 15.0) -> np.ndarray:
    """Gyro white-noise std (3,) rad/s at the log's own rows (about 83 Hz) from ``start``
    s, by the grid's estimator (:func:`omavctl.learn.signal.rate_noise`)."""
    import csv

    from omavctl.learn.signal import rate_noise

    with REAL.open() as fh:
        rows = list(csv.reader(fh))
    cols = [rows[0].index(c) for c in ("TIME_StartTime", "IMU_GyroX", "IMU_GyroY", "IMU_GyroZ")]
    data = []
    for r in rows[1:]:
        try:
            data.append([float(r[i]) for i in cols])
        except (ValueError, IndexError):
            continue
    a = np.array(data)
    a = a[np.all(np.isfinite(a), axis=1)]
    t = (a[:, 0] - a[0, 0]) * 1e-6
    return rate_noise(np.diff(a[t > start, 1:], 2, axis=0))


if __name__ == "__main__":
    main()
