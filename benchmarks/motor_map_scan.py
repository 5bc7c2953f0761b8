"""What hides the mixed torque in a motor log: the thrust map, the idle offset, a lag, or noise.

Run: python benchmarks/motor_map_scan.py VEHICLE.yaml LOG [--rate HZ] [--lags ...] [--cutoffs ...]
[--segments]

The log is read as ``fit`` reads it (the vehicle's column map, ground and idle
time cut), on a grid of ``--rate`` Hz (default the vehicle's controller rate).
For each command-to-thrust map (the rotor list's curve; quadratic and linear
in the command above an idle value ``--idle``), each first-order lag ``T`` of
the thrusts and each low-pass cut-off ``fc`` (a zero-phase 4th-order
Butterworth applied alike to the mixed torque and to the body rate before
differentiating: what the rotors cannot move at frequencies above ``fc`` —
vibration, aliasing of the gyro into the grid — is then left out on both
sides), the angular acceleration of each axis is fitted by least squares
with one gain on the mixed torque (``gain``); with a gain and a constant
torque (``+offset``: a centre-of-mass offset or a weak motor the rate loop
trims out); plus the torque of the thrust curve's bend (``+offset+bend``,
``thrust_curve``'s regressor, one coefficient per axis); plus the torque
scaled by the battery voltage's change (``+offset+battery``, ``battery_sag``'s,
when the vehicle maps ``battery_voltage``); and on the rotor thrusts freely
with a constant (``free``: an upper bound for any mixer with that map).
Printed per variant: R^2 (about zero) roll/pitch/yaw for each. The
table in docs/real-motors.md ("Why, measured") is its output.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from omavctl.learn.flights import read_flights
from omavctl.physics.actuator_effects import first_order_lag
from omavctl.vehicle import load_vehicle

Map = Callable[[np.ndarray], np.ndarray]


def thrust_maps(vehicle_motors, idle: float, top: float) -> dict[str, Map]:
    """Per-rotor thrust (N, R) of raw commands (N, >= R), up to a common scale."""

    def above(p: float) -> Map:
        return lambda c: (
            np.clip((c[:, : vehicle_motors.n_rotors] - idle) / (top - idle), 0, None) ** p
        )

    return {"curve": vehicle_motors.thrust, "x^2 idle": above(2.0), "x idle": above(1.0)}


def _lowpass(y: np.ndarray, fc: float, rate: float) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt

    if fc <= 0 or fc >= rate / 2:
        return y
    return np.asarray(sosfiltfilt(butter(4, fc, fs=rate, output="sos"), y, axis=0))


def _r2(x: np.ndarray, y: np.ndarray, offset: bool = True) -> float:
    """R^2 (about zero) of y (n,) on the columns of x (n, p), and a constant with ``offset``."""
    a = np.c_[x, np.ones(len(y))] if offset else x
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return 1.0 - float(np.sum((y - a @ coef) ** 2) / np.sum(y**2))


def _columns(flight, motors, tmap: Map, lag: float, fc: float, keep: int) -> dict[str, np.ndarray]:
    """Per kept segment, stacked: the mixed torque, the thrust-curve bend's torque,
    the per-rotor thrusts (lagged, filtered), the voltage change and the acceleration."""
    mix = motors.wrench(np.eye(motors.n_rotors))[1].T  # (3, R)
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("x", "bend", "f", "dv", "y")}
    volts = flight.signals.get("battery_voltage")
    for a, b in flight.segments:
        if b - a < 4 * keep:
            continue
        cmd = flight.signals["motor_command"][a:b]
        x = np.clip(motors.values(cmd), 0.0, None)

        def prep(thrust: np.ndarray, a: int = a, b: int = b) -> np.ndarray:
            thrust = first_order_lag(thrust, lag, flight.dt) if lag > 0 else thrust
            return _lowpass(thrust, fc, flight.rate)[keep:-keep]

        f = prep(tmap(cmd))
        out["x"].append(f @ mix.T)
        out["f"].append(f)
        out["bend"].append(prep(x * x - x) @ mix.T)
        dv = np.zeros(b - a) if volts is None else volts[a:b, 0] - np.median(volts[:, 0])
        out["dv"].append(dv[keep:-keep])
        omega = _lowpass(flight.signals["body_rate"][a:b], fc, flight.rate)
        out["y"].append(np.gradient(omega, flight.dt, axis=0)[keep:-keep])
    return {k: np.concatenate(v) for k, v in out.items()}


def per_segment(flight, motors, lag: float, fc: float, keep: int = 50) -> None:
    """Per flight segment of at least 6 ``keep``: roll/pitch/yaw gain (with a constant)
    and R^2 of the rotor list's mixed torque, lagged by ``lag`` and low-passed at ``fc``."""
    for a, b in flight.segments:
        if b - a < 6 * keep:
            continue
        one = replace(flight, segments=[(a, b)])
        c = _columns(one, motors, motors.thrust, lag, fc, keep)
        x, y = c["x"], c["y"]
        gains = [np.linalg.lstsq(np.c_[x[:, k], np.ones(len(y))], y[:, k])[0][0] for k in range(3)]
        r2 = [_r2(x[:, [k]], y[:, k]) for k in range(3)]
        thrust = float(flight.signals["force_command"][a:b, 2].mean())
        print(
            f"{flight.t[a]:6.1f}-{flight.t[b - 1]:6.1f} s thrust {thrust:5.2f} | gain "
            + " / ".join(f"{g:7.0f}" for g in gains)
            + " | R2 "
            + " / ".join(f"{v:.2f}" for v in r2)
        )


def scan(args: argparse.Namespace) -> None:
    vehicle = load_vehicle(args.vehicle)
    if args.rate:
        tmp = Path(args.vehicle).with_name(f".scan-{args.rate:g}.yaml")
        tmp.write_text(f"{Path(args.vehicle).read_text()}\ncontroller: {{rate_hz: {args.rate}}}\n")
        vehicle = load_vehicle(tmp)
        tmp.unlink()
    flight = read_flights([args.log], vehicle)[0]
    motors = vehicle.motors
    assert motors is not None
    print(f"{args.log}: {flight.t.size} samples at {flight.rate:g} Hz")
    if args.segments:
        per_segment(flight, motors, args.lags[0], args.cutoffs[0])
        return
    print("map       lag  cut-off | gain | +offset | +offset+bend | +offset+battery | free")
    for name, tmap in thrust_maps(motors, args.idle, args.top).items():
        for lag in args.lags:
            for fc in args.cutoffs:
                c = _columns(flight, motors, tmap, lag, fc, 50)
                x, y = c["x"], c["y"]
                rows = [
                    [_r2(x[:, [k]], y[:, k], False) for k in range(3)],
                    [_r2(x[:, [k]], y[:, k]) for k in range(3)],
                    [_r2(np.c_[x[:, k], c["bend"][:, k]], y[:, k]) for k in range(3)],
                    [_r2(np.c_[x[:, k], c["dv"] * x[:, k]], y[:, k]) for k in range(3)],
                    [_r2(c["f"], y[:, k]) for k in range(3)],
                ]
                row = " | ".join("/".join(f"{v:.2f}" for v in r) for r in rows)
                print(f"{name:9s} {lag * 1e3:3.0f} ms {fc:3.0f} Hz | {row}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("vehicle")
    parser.add_argument("log")
    parser.add_argument("--rate", type=float, default=0.0, help="grid rate, Hz")
    parser.add_argument("--idle", type=float, default=138.0, help="command of zero thrust")
    parser.add_argument("--top", type=float, default=2047.0, help="full command")
    parser.add_argument("--lags", default="0,0.02,0.04", help="time constants, s")
    parser.add_argument("--cutoffs", default="0,30,10", help="low-pass cut-offs, Hz (0: none)")
    parser.add_argument(
        "--segments", action="store_true", help="per flight segment, first lag and cut-off"
    )
    args = parser.parse_args()
    args.lags = [float(x) for x in args.lags.split(",")]
    args.cutoffs = [float(x) for x in args.cutoffs.split(",")]
    scan(args)


if __name__ == "__main__":
    main()
