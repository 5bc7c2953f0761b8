"""The motor-level effects hidden in the simulated omav, recovered with its rotor list.

The flows of ``tests/test_motor_sim.py`` (8 s of roll/pitch/yaw sines, physics at
400 Hz, ``fit --effects rotor_interference,NAME --points 40`` with the
``omav-rotors`` preset), printing the estimates ``docs/effects.md`` quotes::

    python benchmarks/motor_sim.py [--workdir build/motor-sim]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def main() -> None:
    import test_motor_sim as flows

    from omavctl.learn.fit import fit_model

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--workdir", type=Path, default=Path("build/motor-sim"))
    work = ap.parse_args().workdir
    work.mkdir(parents=True, exist_ok=True)
    veh = flows._rotors(work)
    loss = np.zeros(12)
    loss[2] = 0.3
    tree = {"effects": {"motor_loss": {"l": loss.tolist()}}, "actuators": {"thrust_spread": 0}}
    log = flows._fly(work, veh, tree, "loss")
    est = fit_model([log], veh, effects=["rotor_interference", "motor_loss"], points=40)
    ml = est.model.effects["motor_loss"]
    print("motor_loss l:", np.round(ml.values["l"], 3).tolist())
    print("  standard errors:", np.round(ml.stderr["l"], 2).tolist())
    battery = {"drop": 3.0}
    hidden = {"thrust_curve": {"c": -0.2}, "battery_sag": {"k": 0.1}}
    for name, truth in (
        ("bent", {"effects": hidden, "battery": battery}),
        ("clean", {"battery": battery}),
    ):
        log = flows._fly(work, veh, truth, name)
        effects = ["rotor_interference", "thrust_curve", "battery_sag"]
        fitted = fit_model([log], veh, effects=effects, points=40).model.effects
        c, k = fitted["thrust_curve"], fitted["battery_sag"]
        print(
            f"{name}: c = {c.values['c'][0]:.3f} ± {c.stderr['c'][0]:.3f}, "
            f"k = {k.values['k'][0]:.3f} ± {k.stderr['k'][0]:.3f} /V"
        )


if __name__ == "__main__":
    main()
