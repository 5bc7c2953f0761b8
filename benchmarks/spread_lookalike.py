"""What the default thrust spread looks like to a fit: com_offset against motor_loss.

The truth plant gives each of the omav's 12 rotors a thrust gain ``1 + 0.03 N(0, 1)``
drawn from the truth file's seed (omavctl/sim/plant.py). Fitted on such a vehicle with
no hidden effect, ``com_offset`` takes part of that torque (docs/scorecard.md, "The
apparent truth"), and a refit on two flights carried a flight-dependent r_z (the pin
round, session 17). ``motor_loss`` (per-rotor thrust loss relative to the mean) is the
spread's own form; it needs the rotor list, so the flights use the ``omav-rotors``
preset (docs/effects.md). For each truth seed: fit on a 20 s figure-8 (26 deg, 4 s
period) with ``rotor_interference`` and one of the two, evaluate on a wobble and a
steps flight (``--horizons none``), print the RMSE per axis of physics + effects and of
the full model, and the fitted values against the spread's relative losses.

    python benchmarks/spread_lookalike.py [--seeds 3,5] [--workdir build/spread]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

FITS = ("com_offset", "motor_loss")
HELD = {"wobble": ("wob", 4), "steps": ("steps", 5)}


def omavctl(*args: str, cwd: Path) -> str:
    argv = [sys.executable, "-m", "omavctl", *args]
    out = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, check=True)
    return out.stdout


def run_seed(seed: int, root: Path) -> None:
    d = root / f"seed{seed}"
    d.mkdir(parents=True, exist_ok=True)
    (d / "veh.yaml").write_text("preset: omav-rotors\n")
    (d / "truth.yaml").write_text(f"seed: {seed}\n")
    fig8 = "task fig8 --roll 26 --pitch 26 --period 4 --duration 20 --out fig8.csv -q"
    omavctl(*fig8.split(), cwd=d)
    omavctl("task", "wobble", "--duration", "20", "--out", "wob.csv", "-q", cwd=d)
    omavctl("task", "steps", "--duration", "20", "--out", "steps.csv", "-q", cwd=d)
    for ref, noise in (("fig8", 3), *HELD.values()):
        omavctl(
            "simulate",
            "-r",
            f"{ref}.csv",
            "--vehicle",
            "veh.yaml",
            "--truth",
            "truth.yaml",
            "--seed",
            str(noise),
            "--out",
            f"f-{ref}.csv",
            "-q",
            cwd=d,
        )
    spread = 1.0 + 0.03 * np.random.default_rng([seed, 0x5EED]).standard_normal(12)
    print(
        f"truth seed {seed}: the spread's relative losses", np.round(1 - spread / spread.mean(), 3)
    )
    for name in FITS:
        fit = json.loads(
            omavctl(
                "fit",
                "f-fig8.csv",
                "--vehicle",
                "veh.yaml",
                "--effects",
                f"rotor_interference,{name}",
                "--out",
                f"m-{name}.npz",
                "--json",
                "-q",
                cwd=d,
            )
        )
        est = fit["effects"][name]
        key = next(iter(est["values"]))
        values, se = np.asarray(est["values"][key]), np.asarray(est["stderr"][key])
        print(f"  {name}: {key} = {np.round(values, 4)} (median se {np.median(se):.3g})")
        for held, (ref, _) in HELD.items():
            out = f"ev-{name}-{ref}.json"
            omavctl(
                "evaluate",
                f"f-{ref}.csv",
                "--model",
                f"m-{name}.npz",
                "--horizons",
                "none",
                "--out",
                out,
                "-q",
                cwd=d,
            )
            tree = json.loads((d / out).read_text())
            rmse = {
                k: [round(tree["metrics"][k]["rmse"][a], 4) for a in "xyz"]
                for k in ("effects", "model")
            }
            print(f"    on {held}: physics + effects {rmse['effects']}, model {rmse['model']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="3,5")
    ap.add_argument("--workdir", type=Path, default=Path("build/spread"))
    args = ap.parse_args()
    for seed in (int(s) for s in args.seeds.split(",")):
        run_seed(seed, args.workdir.resolve())


if __name__ == "__main__":
    main()
