"""What an inertia error looks like on a vehicle that has none: a large drag and the
simulator's default imperfections, three truth variants.

A rotational drag of 0.47, 0.54, 0.48 N m s^2 (report11 47's and own-drag 7's kind:
the loop named ``inertia_error`` beside it), flown on a wobble and on random steps
(16 s, truth seed 7), fitted by ``fit``'s first pass with ``rotational_drag`` and
``inertia_error`` together, with every default imperfection, without the rotors'
thrust spread, without it and the actuator lags (servo, motor, backlash), without it
and the rotors' interference, and with ideal actuators. Prints the inertia scale per
axis, its standard error and its systematic part (the spread's,
:mod:`omavctl.learn.spread`).

    python benchmarks/inertia_lookalike.py      # ~15 s

Read (docs/scorecard.md, session 19): with ideal actuators the scale is 1.01; without
the spread 1.02-1.19, unchanged without the lags and 1.01-1.02 without the
interference: the rotors' interference (the thrust lost at small tilts, a registered
effect) is what looks like an inertia error here; the spread moves the scale much
further (1.8 on the wobble's x, 7.5 on the steps' x), which its systematic part covers.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from omavctl.learn.effect_fit import estimate_effects
from omavctl.learn.flights import log_samples
from omavctl.learn.savgol import SavitzkyGolay
from omavctl.logs import align
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import steps, wobble
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle

DRAG = [0.47, 0.54, 0.48]
NO_INTERFERENCE = {"rotor_rotor": 0.0, "rotor_arm": 0.0}
NO_LAGS = {"servo_time_constant": 0.0, "motor_time_constant": 0.0, "servo_backlash_deg": 0.0}
VARIANTS = {
    "defaults": {},
    "no spread": {"actuators": {"thrust_spread": 0.0}},
    "no spread, no lags": {"actuators": {"thrust_spread": 0.0, **NO_LAGS}},
    "no spread, no interference": {
        "actuators": {"thrust_spread": 0.0, "interference": NO_INTERFERENCE}
    },
    "ideal": {"ideal": True},
}


def main() -> None:
    vehicle = default_vehicle()
    sg = SavitzkyGolay(11, 2, 1.0 / vehicle.gains.rate_hz)
    flights = {
        "wobble": wobble(amplitude_deg=20, duration=16, seed=4),
        "steps": steps(amplitude_deg=16, duration=16, seed=4),
    }
    for fam, ref in flights.items():
        for label, extra in VARIANTS.items():
            tree = {"seed": 7, "effects": {"rotational_drag": {"D": DRAG}}, **extra}
            log = align(simulate(ref, vehicle, truth_from_tree(tree, vehicle), seed=7).log)
            samples = log_samples(log, vehicle, sg)[0]
            est = estimate_effects([samples], ["rotational_drag", "inertia_error"]).estimates
            scale = est["inertia_error"]
            spread = scale.systematic["scale"] if scale.systematic is not None else np.zeros(3)
            print(
                f"{fam:6} {label:26}: D {np.round(est['rotational_drag'].values['D'], 3)}; "
                f"scale {np.round(scale.values['scale'], 3)} "
                f"± {np.round(scale.stderr['scale'], 3)} (spread {np.round(spread, 3)})"
            )


if __name__ == "__main__":
    main()
