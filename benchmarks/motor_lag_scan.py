"""How much of a motor log's angular acceleration its mixed torque explains, per lag.

Run: python benchmarks/motor_lag_scan.py VEHICLE.yaml LOG [START:END] [--lags 0,0.02,...]

The log is read as ``fit`` reads it (the vehicle's column map, the rotor list's
mixer, ground and idle time cut, the controller-rate grid). Per lag ``T`` the
mixed torque goes through the exact first-order lag, then through ``I^-1`` and
``fit``'s hold kernel, and one least-squares gain per axis is fitted to the
Savitzky-Golay derivative of the body rate. Printed per axis: the gain and the
share of the acceleration's variance it explains (R^2, about zero). Last, the
yaw with the rotors' inertia reaction: the yaw torque as
``g (lag(tau_z) + beta (tau_z - lag(tau_z)))``, ``g`` and ``beta`` by least squares
(``beta = rho / T``: the reaction ``J_r omega_r_dot`` is ``rho`` times the lagged
drag torque's rate, and ``T d/dt lag = tau - lag`` for a first-order lag;
``beta = 1`` cancels the lag exactly). The tables in docs/real-motors.md are its
output on the Crazyflie logs.
"""

from __future__ import annotations

import argparse

import numpy as np

from omavctl.learn.flights import read_flights
from omavctl.learn.signal import SavitzkyGolay
from omavctl.logs import parse_time_window
from omavctl.physics.actuator_effects import first_order_lag
from omavctl.vehicle import load_vehicle


def scan(vehicle_path: str, log: str, window: str | None, lags: list[float]) -> None:
    vehicle = load_vehicle(vehicle_path)
    flight = read_flights([log], vehicle, parse_time_window(window) if window else None)[0]
    sg = SavitzkyGolay(11, 2, flight.dt)
    m = sg.half
    segments = [(a, b) for a, b in flight.segments if b - a >= 5 * sg.window]
    measured = np.concatenate(
        [sg.derivative(flight.signals["body_rate"][a:b])[m:-m] for a, b in segments]
    )
    print(f"{log} {window or ''}: {measured.shape[0]} samples at {flight.rate:g} Hz")
    for lag in lags:
        parts = []
        for a, b in segments:
            torque = flight.signals["torque_command"][a:b]
            lagged = first_order_lag(torque, lag, flight.dt) if lag > 0 else torque
            parts.append(sg.hold(lagged @ vehicle.inertia_inv.T)[m:-m])
        model = np.concatenate(parts)
        cells = []
        for k, axis in enumerate("xyz"):
            x, y = model[:, k], measured[:, k]
            gain = float(x @ y / (x @ x))
            r2 = 1.0 - float(np.sum((y - gain * x) ** 2) / np.sum(y**2))
            cells.append(f"{axis}: gain {gain:6.3f} R2 {r2:5.3f}")
        raw = np.concatenate(
            [sg.hold(flight.signals["torque_command"][a:b] @ vehicle.inertia_inv.T)[m:-m]
             for a, b in segments]
        )  # fmt: skip
        both = np.c_[model[:, 2], raw[:, 2] - model[:, 2]]
        coef, *_ = np.linalg.lstsq(both, measured[:, 2], rcond=None)
        r2 = 1.0 - float(np.sum((measured[:, 2] - both @ coef) ** 2) / np.sum(measured[:, 2] ** 2))
        beta = coef[1] / coef[0] if coef[0] != 0 else 0.0
        cells.append(f"z + reaction: beta {beta:5.2f} R2 {r2:5.3f}")
        print(f"T = {lag * 1e3:5.1f} ms | " + " | ".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("vehicle")
    parser.add_argument("log")
    parser.add_argument("window", nargs="?", default=None, help="START:END, s from the log start")
    parser.add_argument("--lags", default="0,0.02,0.04,0.06,0.08", help="time constants, s")
    args = parser.parse_args()
    scan(args.vehicle, args.log, args.window, [float(x) for x in args.lags.split(",")])


if __name__ == "__main__":
    main()
