"""The horizon band before and after the measured walk gain (docs/horizons.md, the band).

For each case (a model fitted on one flight, evaluated on another), the full
model's horizon table is computed twice on the same windows: with the band's
random walk as white noise (before: the model's ``rollout_walk`` entry
ignored) and times the gain ``fit`` measured on its own held-out blocks
(after, :mod:`omavctl.learn.rollout_walk`). Printed per horizon and axis: the
2σ coverage, the mean |error| and the median 2σ half-width, for windows inside
the fit flight's inputs and for those that start or pass beyond them (the
one-step rule: an input a quarter of its training range beyond the training
points' [min, max]).

Cases (fitted into ``--workdir`` when missing; fits are deterministic):

- ``sim:<draw>``: a draw of ``horizons_study.py`` (its flights and seeds), the
  model ``fit --effects rotor_interference`` and the one with the effect
  ``evaluate`` named there (``NAMED``), on the held-out figure-8;
- ``crazyflie``: log15, fit on the first half of the roll/pitch window,
  evaluated on the second (``make crazyflie``'s halves, both models);
  ``crazyflie-window``: fit on log10 and log16, evaluated on log15's window;
- ``px4``: the px4tools octocopter, fit on 6.5-15 s, evaluated from 15 s;
- ``bf-better-on-smooth`` and ``bf-smooth-on-better``: the Betaflight tunes.

    python benchmarks/horizons_walk.py --cases sim:drag,crazyflie --workdir DIR
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

import omavctl.diagnose.evaluate as ev
from omavctl.diagnose import horizons as hz
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import load_model, save_model
from omavctl.learn.rollout_residual import gather, per_sample
from omavctl.vehicle import load_vehicle

sys.path.insert(0, str(Path(__file__).resolve().parent))
import horizons_study as study
from horizons_band_cause import outside

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared/data/real"
#: the effect evaluate names first on each draw (docs/horizons.md, measured)
NAMED = {
    "drag": "rotational_drag",
    "com_offset": "com_offset",
    "motor_lag": "com_offset",
    "drag_strong": "rotational_drag",
    "clean": "com_offset",
}
CF = REAL / "arpl_crazyflie/log15"
BF = REAL / "betaflight_cs110"
AXES = ("x", "y", "z")


def _fit(path: Path, logs: list[Path], vehicle: Any, **kw: Any) -> Path:
    if not path.exists():
        save_model(path, fit_model(logs, vehicle, **kw).model)
    return path


def _sim(draw: str, work: Path) -> list[tuple[str, Path, Path, Any]]:
    vehicle, d, fit_log, held = study.draw_flights(draw, work)
    base = _fit(d / "gp.npz", [fit_log], vehicle, effects=("rotor_interference",))
    named = NAMED[draw]
    added = _fit(d / f"gp-{named}.npz", [fit_log], vehicle, effects=("rotor_interference", named))
    return [(f"{draw} (rotor_interference)", base, held, None),
            (f"{draw} (+{named})", added, held, None)]  # fmt: skip


def cases(name: str, work: Path) -> list[tuple[str, Path, Path, Any]]:
    """(label, model, log, time window) of a case."""
    if name.startswith("sim:"):
        return _sim(name[4:], work)
    if name == "crazyflie":
        v = load_vehicle(ROOT / "examples/crazyflie.yaml")
        first, second = (15.76, 33.26), (33.26, 50.76)
        base = _fit(work / "cf-half-base.npz", [CF], v, time_window=first)
        lag = _fit(
            work / "cf-half-lag.npz", [CF], v, time_window=first,
            effects=("inertia_error", "motor_lag"),
        )  # fmt: skip
        return [("crazyflie halves (base)", base, CF, second),
                ("crazyflie halves (lag)", lag, CF, second)]  # fmt: skip
    if name == "crazyflie-window":  # make crazyflie's window: fit on log10 + log16
        v = load_vehicle(ROOT / "examples/crazyflie.yaml")
        logs = [REAL / "arpl_crazyflie/log10", REAL / "arpl_crazyflie/log16"]
        base = _fit(work / "cf-base.npz", logs, v)
        return [("crazyflie window (base)", base, CF, (15.76, 50.76))]
    if name == "px4":
        v = load_vehicle(ROOT / "examples/px4tools-octocopter.yaml")
        log = REAL / "px4tools_octocopter/01_07_59.csv"
        model = _fit(work / "px4tools-gp.npz", [log], v, time_window=(6.5, 15.0))
        return [("px4tools octocopter", model, log, (15.0, None))]
    if name.startswith("bf-"):
        v = load_vehicle(ROOT / "examples/betaflight-cs110.yaml")
        fitted, judged = name[3:].split("-on-")
        tune = {"smooth": "example_smooth_tune", "better": "better_tune"}
        model = _fit(work / f"bf-{fitted}.npz", [BF / f"{tune[fitted]}.csv.gz"], v)
        return [(f"betaflight {fitted} -> {judged}", model, BF / f"{tune[judged]}.csv.gz", None)]
    raise SystemExit(f"unknown case {name}")


def measure(label: str, model: Path, log: Path, window: Any) -> None:
    m = load_model(model)
    rate, sg = ev._grid(m)
    samples, grids, _, _ = ev._read_logs([log], m.vehicle, rate, sg, window, None)
    dt = 1.0 / rate
    steps = hz.horizon_steps(hz.DEFAULT_HORIZONS, rate)
    n_total = sum(s.n for s in samples)
    stride = max(1, -(-n_total * (steps[-1] + 1) // hz.MAX_WINDOW_SAMPLES))
    win = gather(samples, grids, steps[-1], stride)
    v = m.vehicle
    with np.errstate(over="ignore", invalid="ignore"):
        fn = hz.residual_function(m, win, samples, True)
        err = hz._rolled(win, v.inertia, v.inertia_inv, dt, fn).rate
    after = hz._band(m, win, samples, dt)
    entry = m.provenance.pop("rollout_walk", None)
    before = hz._band(m, win, samples, dt)
    m.provenance["rollout_walk"] = entry
    beyond = per_sample(win, samples, outside(m, samples))[..., 0] > 0
    gain = "none" if not entry else "/".join(
        f"{entry['gain'][a][-1]:.3g}" for a in AXES
    )  # fmt: skip
    print(f"\n## {label}: {win.count} windows (stride {stride}); walk gain at "
          f"{_last_seconds(entry)} s x/y/z {gain}")  # fmt: skip
    print("| horizon | axis | coverage before → after | inside: |e|, 2σ before → after "
          "| beyond: |e|, 2σ before → after (windows) |")  # fmt: skip
    print("|---|---|---|---|---|")
    for k in steps:
        out_w = beyond[:, : k + 1].any(axis=1)
        for a, name in enumerate(AXES):
            e = np.abs(err[:, k, a])
            b, f = 2 * before[:, k, a], 2 * after[:, k, a]
            cells = [f"{np.mean(e <= b):.0%} → {np.mean(e <= f):.0%}"]
            for sel in (~out_w, out_w):
                if sel.any():
                    cells.append(
                        f"{np.mean(e[sel]):.3g}, {np.median(b[sel]):.3g} → "
                        f"{np.median(f[sel]):.3g} ({int(sel.sum())})"
                    )
                else:
                    cells.append("none")
            print(f"| {k * dt:g} s | {name} | " + " | ".join(cells) + " |")


def _last_seconds(entry: Any) -> str:
    if not entry:
        return "-"
    return f"{entry['steps'][-1] * entry['dt']:g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="sim:drag,sim:motor_lag,sim:clean,crazyflie")
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="horizons-walk-"))
    work.mkdir(parents=True, exist_ok=True)
    for name in args.cases.split(","):
        for case in cases(name.strip(), work):
            measure(*case)
            sys.stdout.flush()


if __name__ == "__main__":
    main()
