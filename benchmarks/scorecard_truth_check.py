"""Check the scorecard's apparent truth (benchmarks/scorecard_truth.py) on the simulator.

Each case flies one 20 s flight through a plant with only some default imperfections
(own seeds, no report split), fits one or two effects with ``omavctl fit`` as the
loop does, and prints the fitted 95 % interval beside the apparent value:

- ``spread*``: a 3 % thrust spread alone (no lags, backlash or interference):
  ``com_offset`` against the spread's least-squares offset over the flight and the
  hover closed form;
- ``inter*``: the default interference alone: ``com_offset`` against its projection;
- ``ri*``: a spread and an interference of 0.8 / 0.2: ``rotor_interference`` alone
  and with ``com_offset``;
- ``lag*``, ``lead*``: noise-free plants with 5 ms motor (and servo) lags at 100 Hz,
  or ideal actuators with a 1 kHz controller: ``command_delay`` against the lag's
  first-order delay ``T`` and the controller's lead ``-4.5 ms``.

    python benchmarks/scorecard_truth_check.py [--only NAME...] [--workdir DIR]

Takes 1-2 min per case on the shared 2-core machine (run it under ``nice``).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import scorecard_truth as st

NONE = {"servo_time_constant": 0.0, "motor_time_constant": 0.0, "servo_backlash_deg": 0.0}
QUIET = {"gyro": 0.0, "attitude": 0.0, "position": 0.0, "velocity": 0.0}
NO_SPREAD = {"thrust_spread": 0.0, "interference": {"rotor_rotor": 0.0, "rotor_arm": 0.0}}
TASKS = {
    "fig8": ["fig8"],
    "steps": ["steps", "--amplitude", "16", "--seed", "77"],
    "wobble": ["wobble", "--amplitude", "20", "--bandwidth", "0.7", "--seed", "5"],
}
SPREAD = {**NONE, "thrust_spread": 0.03, "interference": {"rotor_rotor": 0.0, "rotor_arm": 0.0}}
RI = {**NONE, "thrust_spread": 0.03, "interference": {"rotor_rotor": 0.8, "rotor_arm": 0.2}}
LAGS = {**NO_SPREAD, "servo_backlash_deg": 0.0, "motor_time_constant": 0.005}
#: name -> (truth tree, task, flight seed, effects fitted)
CASES: dict[str, tuple[dict[str, Any], str, int, str]] = {
    "spread11": ({"seed": 11, "actuators": SPREAD}, "fig8", 1011, "com_offset"),
    "spread22": ({"seed": 22, "actuators": SPREAD}, "steps", 1022, "com_offset"),
    "spread33": ({"seed": 33, "actuators": SPREAD}, "wobble", 1033, "com_offset"),
    "inter55": (
        {"seed": 55, "actuators": {**NONE, "thrust_spread": 0.0}},
        "steps",
        1055,
        "com_offset",
    ),
    "inter66": (
        {"seed": 66, "actuators": {**NONE, "thrust_spread": 0.0}},
        "fig8",
        1066,
        "com_offset",
    ),
    "ri71": ({"seed": 71, "actuators": RI}, "steps", 1071, "rotor_interference"),
    "ric71": ({"seed": 71, "actuators": RI}, "steps", 1071, "rotor_interference,com_offset"),
    "ri72": ({"seed": 72, "actuators": RI}, "fig8", 1072, "rotor_interference"),
    "ric72": ({"seed": 72, "actuators": RI}, "fig8", 1072, "rotor_interference,com_offset"),
    "lag-motor": (
        {"seed": 7, "noise": QUIET, "actuators": {**LAGS, "servo_time_constant": 0.0}},
        "steps",
        4401,
        "command_delay",
    ),
    "lag-both": (
        {"seed": 7, "noise": QUIET, "actuators": {**LAGS, "servo_time_constant": 0.005}},
        "steps",
        4401,
        "command_delay",
    ),
    "lead-1k": (
        {"seed": 7, "noise": QUIET, "ideal": True, "timing": {"controller_rate_hz": 1000}},
        "steps",
        4401,
        "command_delay",
    ),
}


def _omavctl(args: list[str], cwd: Path) -> str:
    argv = [sys.executable, "-m", "omavctl", *args]
    return subprocess.run(argv, cwd=cwd, check=True, capture_output=True, text=True).stdout


def run_case(name: str, workdir: Path) -> list[str]:
    """Fly and fit one case; one line per fitted component against its apparent value."""
    import yaml

    tree, task, seed, effects = CASES[name]
    d = workdir / name
    d.mkdir(parents=True, exist_ok=True)
    (d / "truth.yaml").write_text(yaml.safe_dump(tree))
    _omavctl(["task", *TASKS[task], "--duration", "20", "--out", "ref.csv"], d)
    sim = ["simulate", "--reference", "ref.csv", "--truth", "truth.yaml", "--seed", str(seed)]
    _omavctl([*sim, "--out", "log.csv", "--quiet"], d)
    fit_args = ["fit", "log.csv", "--effects", effects, "--out", "m.npz", "--points", "200"]
    fit = json.loads(_omavctl([*fit_args, "--seed", "0", "--json"], d))["effects"]
    truth, vehicle = st.plant_truth(tree)
    fitted = effects.split(",")
    expected: dict[str, dict[str, list[float]]] = {}
    if "command_delay" in fitted:
        expected["command_delay"] = st.timing_truth("command_delay", truth, fitted) or {}
    else:
        spread = st.spread_factors(truth.seed, truth.thrust_spread)
        geom = st.simulated_geometry(d / "ref.csv", tree, seed)
        ri = (truth.rotor_rotor, truth.rotor_arm)
        expected = st.linear_shift(geom, fitted, spread, *ri, vehicle)
        hover = st.linear_shift(st.hover_geometry(vehicle), fitted, spread, *ri, vehicle)
        if "rotor_interference" in expected:
            for key, base in zip(("rotor_rotor", "rotor_arm"), ri, strict=True):
                expected["rotor_interference"][key][0] += base
                hover["rotor_interference"][key][0] += base
    lines = []
    for effect, params in expected.items():
        for pname, values in params.items():
            for i, t in enumerate(values):
                est = fit[effect]["values"][pname][i]
                lo, hi = fit[effect]["ci95"][pname][i]
                # a null end is unbounded (an inertia scale whose gain is not told from 0)
                lo = -math.inf if lo is None else lo
                hi = math.inf if hi is None else hi
                mark = "inside" if lo <= t <= hi else "OUTSIDE"
                h = "" if "command_delay" in fitted else f"; hover {hover[effect][pname][i]:+.5g}"
                lines.append(
                    f"{name} ({task}, fit {effects}): {effect}.{pname}[{i}] fitted {est:+.5g} "
                    f"[{lo:+.5g}, {hi:+.5g}], apparent {t:+.5g} {mark}{h}"
                )
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", default=None, choices=sorted(CASES))
    ap.add_argument("--workdir", type=Path, default=Path("build/scorecard-truth"))
    args = ap.parse_args(argv)
    for name in args.only or list(CASES):
        for line in run_case(name, args.workdir.resolve()):
            print(line, flush=True)


if __name__ == "__main__":
    main()
