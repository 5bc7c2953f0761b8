"""Measure the Savitzky-Golay window and order that ``fit`` uses by default.

Run: python benchmarks/sg_window.py   (about 30 s)

Two simulated flights of the figure-8 task (24 s, 100 Hz grid):

A. Ideal actuators, default sensor noise (gyro 0.003 rad/s). The true
   acceleration is the nominal model with the held commands, so
   - "derivative error" = RMS(SG derivative - nominal averaged over the two
     periods around t_k) is the error of the derivative itself;
   - "residual noise" = RMS(SG derivative - hold-filtered nominal) is what the
     residual of a perfect model looks like with fit's hold rule.
B. Default actuator imperfections, gyro noise switched off in the plant. The
   residual with a 3-sample window on the noise-free rate is the reference
   ("true residual", mean over two control periods). Gyro noise of the default
   level is then added to the logged rate and the residual recomputed with each
   window: its RMS error against the reference is what the GP is trained on.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs import align
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle

GYRO_NOISE = 0.003
WINDOWS = (5, 7, 9, 11, 13, 15, 17, 21, 25)
ORDERS = (2, 3)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def main() -> None:
    vehicle = default_vehicle()
    ref = fig8()
    dt = 1.0 / vehicle.gains.rate_hz
    ideal = align(simulate(ref, vehicle, truth_from_tree({"ideal": True}, vehicle), seed=1).log)
    quiet = align(
        simulate(ref, vehicle, truth_from_tree({"noise": {"gyro": 0.0}}, vehicle), seed=1).log
    )
    rng = np.random.default_rng(0)
    rate = quiet.signals["body_rate"]
    signals = {**quiet.signals, "body_rate": rate + GYRO_NOISE * rng.standard_normal(rate.shape)}
    noisy = replace(quiet, signals=signals)
    half = SavitzkyGolay(3, 2, dt)
    truth = residual_samples(quiet, vehicle, half)
    a3 = residual_samples(ideal, vehicle, half)
    margin = max(WINDOWS) // 2  # compare every window on the same samples

    print(f"gyro noise {GYRO_NOISE} rad/s, grid {1 / dt:g} Hz, figure-8 {ref.duration:g} s")
    print(
        "order window | A: derivative error  residual noise (predicted) | "
        "B: residual error (bias only) | rad/s^2 RMS over 3 axes"
    )
    for order in ORDERS:
        for window in WINDOWS:
            if order >= window:
                continue
            sg = SavitzkyGolay(window, order, dt)
            a = residual_samples(ideal, vehicle, sg)
            sel = (a.index >= margin) & (a.index < ideal.t.size - margin)
            nom = a.nominal  # hold-filtered
            # per-sample nominal averaged over the two periods around t_k (window-3 hold)
            nom3 = a3.nominal[np.searchsorted(a3.index, a.index)]
            deriv_err = _rms((a.omega_dot - nom3)[sel])
            res_noise = _rms((a.omega_dot - nom)[sel])
            predicted = GYRO_NOISE * sg.noise_gain
            b = residual_samples(noisy, vehicle, sg)
            b0 = residual_samples(quiet, vehicle, sg)
            ref_res = truth.residual[np.searchsorted(truth.index, b.index)]
            selb = (b.index >= margin) & (b.index < quiet.t.size - margin)
            err = _rms((b.residual - ref_res)[selb])
            bias = _rms((b0.residual - ref_res)[selb])
            print(
                f"{order:5d} {window:6d} | {deriv_err:10.4f} {res_noise:16.4f} ({predicted:.4f})"
                f"      | {err:10.4f} ({bias:.4f})"
            )
    print(f"RMS of the true residual (B): {_rms(truth.residual):.4f} rad/s^2")


if __name__ == "__main__":
    main()
