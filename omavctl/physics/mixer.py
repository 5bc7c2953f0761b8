"""The commanded wrench of a log from its motor outputs, through the vehicle's rotor list.

A log with ``motor_command`` (raw per-output commands) but no torque command
gets ``force_command`` and ``torque_command`` computed here: each rotor's
thrust from its command and thrust curve, then the body force and torque of
all of them (:meth:`omavctl.rotors.Motors.wrench`). A vehicle whose rotors
run on rotor speeds in rad/s (the omav) may take them from the ``rotor`` role
(its ``/omav/actuators``) when the log has no ``motor_command``; rotors on tilt
servos take their angles from the ``tilt`` role.

Per-rotor first-order motor lag with one time constant is linear in the
thrusts, and the mixer is linear in them, so it acts on this wrench exactly as
a first-order lag of the mixed wrench: ``motor_lag`` models it so on this path
(:class:`omavctl.physics.actuator_effects.MotorLag`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import replace

import numpy as np

from omavctl.base.errors import LogError
from omavctl.logs.inspection import Inspection
from omavctl.logs.types import FlightLog
from omavctl.physics.effect_base import MotorSignals
from omavctl.vehicle import Vehicle

__all__ = [
    "MIXED_NOTE",
    "REQUIRED_MIXED",
    "mixed_inspection",
    "mixed_source",
    "motor_signals",
    "motor_source",
    "motor_wrench",
    "required_roles",
    "wrench_hook",
]

#: Roles ``fit`` and ``evaluate`` need of a log whose motor outputs are mixed.
REQUIRED_MIXED = ("body_rate", "motor_command")
#: The start of the note :func:`motor_wrench` adds to a flight it mixes.
MIXED_NOTE = "force and torque commands computed from "


def motor_source(vehicle: Vehicle, roles: Collection[str]) -> str | None:
    """The role a log's motor commands come from for ``vehicle``, or None.

    ``motor_command`` when the log has it; else ``rotor`` (measured speeds,
    rad/s) when every rotor's unit is rad/s; None when the vehicle has no
    ``motors:`` or the log has a torque command of its own (that one is used, unless
    the rotor list says ``wrench_from: rotors``).
    """
    motors = vehicle.motors
    if motors is None or ("torque_command" in roles and motors.wrench_from == "log"):
        return None
    if "motor_command" in roles:
        return "motor_command"
    if "rotor" in roles and all(r.unit == "rad/s" for r in motors.rotors):
        return "rotor"
    return None


def motor_wrench(flight: FlightLog, vehicle: Vehicle, source: str = "motor_command") -> FlightLog:
    """``flight`` with ``force_command`` and ``torque_command`` (N, 3) from its motor outputs.

    ``source`` is the role holding the commands (N, k >= the vehicle's outputs).
    Raises LogError when the log lacks it, or the servo angles its tilting rotors need.
    """
    motors = vehicle.motors
    if motors is None:
        raise LogError("the vehicle has no 'motors:' rotor list to mix motor commands", flight.path)
    if not flight.has(source):
        raise LogError(f"the log has no {source} signal to mix", flight.path)
    commands = flight.signals[source]
    if commands.shape[1] < motors.n_outputs:
        raise LogError(
            f"{source} has {commands.shape[1]} outputs, the vehicle's rotors use "
            f"{motors.n_outputs}",
            flight.path,
        )
    tilt = flight.signals.get("tilt")
    if motors.tilting and tilt is None:
        raise LogError("the vehicle's rotors are on tilt servos: the log needs tilt", flight.path)
    thrust = motors.thrust(commands)
    force, torque = motors.wrench(thrust, tilt)
    signals = {**flight.signals, "force_command": force, "torque_command": torque}
    note = (
        f"{MIXED_NOTE}{source} through the vehicle's "
        f"{motors.n_rotors} rotors (motors: thrust curves, positions, spins)"
    )
    return replace(flight, signals=signals, notes=[*flight.notes, note])


def mixed_source(flight: FlightLog) -> str | None:
    """The role :func:`motor_wrench` mixed ``flight``'s wrench from, or None when the
    log's wrench is its own."""
    for note in flight.notes:
        if note.startswith(MIXED_NOTE):
            source = note[len(MIXED_NOTE) :].split(" ", 1)[0]
            return source if flight.has(source) else None
    return None


def motor_signals(flight: FlightLog, vehicle: Vehicle, rows: slice) -> MotorSignals | None:
    """Per-rotor command values and thrusts over ``rows`` of a flight whose wrench was
    mixed from its motor outputs (for the motor-level effects), else None."""
    source = mixed_source(flight)
    motors = vehicle.motors
    if source is None or motors is None:
        return None
    commands = flight.signals[source][rows]
    tilt = flight.signals["tilt"][rows] if motors.tilting and flight.has("tilt") else None
    values = np.clip(motors.values(commands), 0.0, None)
    return MotorSignals(motors, values, motors.thrust(commands), tilt)


Mix = tuple[str, Callable[[FlightLog], FlightLog]]


def wrench_hook(vehicle: Vehicle) -> Callable[[set[str]], Mix | None]:
    """For :func:`omavctl.logs.read_vehicle_log`: given the roles a log holds, the
    role its commands come from and the function that adds the wrench, or None."""

    def hook(roles: set[str]) -> Mix | None:
        source = motor_source(vehicle, roles)
        if source is None:
            return None
        return source, lambda flight: motor_wrench(flight, vehicle, source)

    return hook


def mixed_inspection(ins: Inspection, vehicle: Vehicle) -> Inspection:
    """``ins`` as ``fit``/``evaluate`` of ``vehicle`` see the log: when the vehicle's
    rotor list mixes the log's motor outputs, the force and torque commands count as
    found (computed) and the roles needed are the body rate and those outputs."""
    if ins.suggestion:  # not read with the vehicle: its suggested map says the needs
        return ins
    source = motor_source(vehicle, ins.roles_found)
    if source is None or vehicle.motors is None:
        return replace(ins, required=required_roles(vehicle))
    where = f"computed from {source} by the vehicle's {vehicle.motors.n_rotors} rotors"
    found = {**ins.roles_found, "force_command": where, "torque_command": where}
    missing = {
        r: w for r, w in ins.roles_missing.items() if r not in ("force_command", "torque_command")
    }
    return replace(ins, roles_found=found, roles_missing=missing, required=REQUIRED_MIXED)


def required_roles(vehicle: Vehicle) -> tuple[str, ...]:
    """The roles ``fit`` and ``evaluate`` (and ``inspect --vehicle``) need from a log
    of ``vehicle`` that holds a wrench command: the body rate and that command for a
    vehicle with a rotor list (IMU-only logs: the tilt is then unknown), and the
    attitude too for any other vehicle (the log contract's pose)."""
    imu = ("body_rate", "force_command", "torque_command")
    # the attitude last: a missing wrench (or unmixable motor outputs) is said first
    return imu if vehicle.motors is not None else (*imu, "attitude")
