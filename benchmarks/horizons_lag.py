"""Rolling out a model with a motor lag: its first step against its one-step prediction,
and the horizon table of the four predictors (docs/horizons.md, 2026-11-26).

Per case (a model fitted on one flight, evaluated on another; fitted into
``--workdir`` when missing, as ``horizons_walk.py`` does) it prints:

- the RMS difference (rad/s^2) between the rollout's first step
  ``(omega_1 - omega_0) / dt`` and the model's one-step prediction at the same
  sample (physics + effects; they must agree but for the rigid body's raw
  against held command), and of each against the logged increment;
- per predictor and horizon the mean |body-rate error| per axis (rad/s), and
  the full model's 2σ coverage per axis and over all axes.

Cases: ``crazyflie`` (log15's halves, base and ``inertia_error,motor_lag``),
``crazyflie-window`` (log10 + log16 -> log15's window, base and lag),
``sim:motor_lag`` (the study's hidden motor-lag draw, fitted with
``rotor_interference`` and with ``rotor_interference,motor_lag``), ``px4``.
Run it with an older tree on ``PYTHONPATH`` (and another ``--workdir``) for
the before.

    python benchmarks/horizons_lag.py --cases crazyflie,sim:motor_lag --workdir DIR [--stride N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

import omavctl.diagnose.evaluate as ev
from omavctl.diagnose import horizons as hz
from omavctl.learn.model_file import load_model
from omavctl.learn.rollout_residual import gather, residual_function
from omavctl.physics.open_loop import rollout
from omavctl.vehicle import load_vehicle

sys.path.insert(0, str(Path(__file__).resolve().parent))
import horizons_walk as walk

AXES = ("x", "y", "z")
KEYS = ("naive", "nominal", "effects", "model")


def cases(name: str, work: Path) -> list[tuple[str, Path, Path, Any]]:
    """(label, model, log, time window) of a case."""
    if name == "sim:motor_lag":
        out = walk._sim("motor_lag", work)[:1]
        d = work / "motor_lag"
        lagged = walk._fit(
            d / "gp-motor_lag.npz", [d / "flight-01.csv"], walk.default_vehicle(),
            effects=("rotor_interference", "motor_lag"),
        )  # fmt: skip
        return [*out, ("motor_lag (+motor_lag)", lagged, d / "flight-02.csv", None)]
    if name == "crazyflie-window":
        v = load_vehicle(walk.ROOT / "examples/crazyflie.yaml")
        logs = [walk.REAL / "arpl_crazyflie/log10", walk.REAL / "arpl_crazyflie/log16"]
        base = walk._fit(work / "cf-base.npz", logs, v)
        lag = walk._fit(work / "cf-lag.npz", logs, v, effects=("inertia_error", "motor_lag"))
        window = (15.76, 50.76)
        return [("crazyflie window (base)", base, walk.CF, window),
                ("crazyflie window (lag)", lag, walk.CF, window)]  # fmt: skip
    return walk.cases(name, work)


def _rms(x: np.ndarray) -> str:
    return "/".join(f"{v:.3g}" for v in np.sqrt(np.mean(x**2, axis=0)))


def first_step(m: Any, samples: list[Any], grids: list[Any], dt: float) -> None:
    """The rollout's first step against the one-step prediction (physics + effects)."""
    win = gather(samples, grids, 1, 1)
    one = np.concatenate([s.nominal + m.effects_samples(s) for s in samples])
    offsets = np.cumsum([0] + [s.n for s in samples[:-1]])
    one = one[offsets[win.log] + win.pos[:, 0]]
    v = m.vehicle
    res = residual_function(m, win, samples, False)
    om, _ = rollout(
        win.omega[:, 0], np.zeros((win.count, 3)), win.torque[:, :1], v.inertia,
        v.inertia_inv, dt, res,
    )  # fmt: skip
    step = (om[:, 1] - om[:, 0]) / dt
    logged = (win.omega[:, 1] - win.omega[:, 0]) / dt
    print(
        f"  first step (rad/s^2 RMS x/y/z): rollout - one-step {_rms(step - one)}; "
        f"against the logged increment: rollout {_rms(step - logged)}, "
        f"one-step {_rms(one - logged)}"
    )


def measure(label: str, model: Path, log: Path, window: Any, stride: int) -> None:
    m = load_model(model)
    rate, sg = ev._grid(m)
    samples, grids, _, _ = ev._read_logs([log], m.vehicle, rate, sg, window, None)
    print(f"{label}: {model.name} on {log.name} {window or ''}, effects {list(m.effects)}, "
          f"rollout_gp {m.rollout_gp.tolist()}")  # fmt: skip
    if m.effects:
        first_step(m, samples, grids, 1.0 / rate)
    t = hz.horizon_table([m], samples, grids, rate, stride=stride)
    print(f"  {t['windows']} windows, stride {t['stride']}; mean |rate error| x/y/z rad/s")
    for key in KEYS:
        rows = t["table"][key]
        errs = "  ".join(
            f"{r['seconds']:g} s " + "/".join(f"{r['rate_error'][a]:.3g}" for a in AXES)
            for r in rows
        )
        print(f"  {key:8s} {errs}")
    cov = "  ".join(
        f"{r['seconds']:g} s "
        + "/".join(f"{100 * r['coverage'][a]:.0f}" for a in AXES)
        + f" ({100 * r['coverage']['all']:.0f})"
        for r in t["table"]["model"]
    )
    print(f"  coverage x/y/z (all) %: {cov}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="crazyflie,crazyflie-window,sim:motor_lag,px4")
    ap.add_argument("--workdir", type=Path, required=True)
    ap.add_argument("--stride", type=int, default=1)
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    for name in args.cases.split(","):
        for case in cases(name.strip(), args.workdir):
            measure(*case, args.stride)
            sys.stdout.flush()


if __name__ == "__main__":
    main()
