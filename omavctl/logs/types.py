"""Data types shared by every log reader and writer.

A log is first read into a :class:`RawLog`: one :class:`RawSeries` per
*signal role* (``body_rate``, ``attitude``, ...) with its own stamps, exactly
as recorded. :func:`omavctl.logs.align.align` then puts every role on one
uniform grid (:class:`FlightLog`), detecting gaps, duplicated and
out-of-order stamps.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

__all__ = [
    "MOTOR_OUTPUTS",
    "ROLE_COLUMNS",
    "ROLE_TOPIC",
    "FlightLog",
    "LogLayout",
    "RawLog",
    "RawSeries",
    "TopicInfo",
]


class LogLayout(Protocol):
    """Where a vehicle's signals are in its logs (a :class:`~omavctl.vehicle.Vehicle` is one).

    The log readers need only this much of a vehicle, so they do not depend on
    the vehicle description: ``topics`` maps topic roles to topic names (bags),
    ``columns`` is a column map for CSVs of another layout (empty: the wide
    contract CSV), ``frame`` the body frame convention (``"FLU"`` or ``"FRD"``).
    """

    @property
    def topics(self) -> Mapping[str, str]: ...

    @property
    def columns(self) -> Mapping[str, Any]: ...

    @property
    def frame(self) -> str: ...


XYZ = ("x", "y", "z")
#: Columns of the ``motor_command`` role: the most outputs a vehicle may have
#: (the omav's 12 rotors and 6 servos); outputs a log does not map are 0.
MOTOR_OUTPUTS = 18
RPY = ("roll", "pitch", "yaw")

#: Signal roles and their wide-CSV column suffixes (DESIGN.md section 3).
#: Vectors are SI units, body frame FLU, except ``position`` (world) and
#: ``attitude`` (ZYX Euler angles of body in world, rad).
ROLE_COLUMNS: dict[str, tuple[str, ...]] = {
    "body_rate": XYZ,  # rad/s, body
    "attitude": RPY,  # rad
    "position": XYZ,  # m, world
    "velocity": XYZ,  # m/s, body
    "force_command": XYZ,  # N, body
    "torque_command": XYZ,  # N m, body
    "desired_acceleration": XYZ,  # rad/s^2, body (controller's a*)
    "desired_linear_acceleration": XYZ,  # m/s^2, world
    "reference_position": XYZ,  # m, world
    "reference_attitude": RPY,  # rad
    "tilt": tuple(str(i) for i in range(6)),  # rad
    "rotor": tuple(str(i) for i in range(12)),  # rad/s
    # raw per-output commands in the vehicle's output order and in the unit its
    # ``motors:`` section declares (PWM us, DShot, 0-65535, normalised, rad/s, rpm)
    "motor_command": tuple(str(i) for i in range(MOTOR_OUTPUTS)),
    # the battery's voltage, V (the ``battery_sag`` effect); one column
    "battery_voltage": ("v",),
    # the accelerometer: specific force (non-gravitational force per mass), m/s^2,
    # body (the ``drag_moment`` effect)
    "specific_force": XYZ,
}

#: Which topic role (vehicle ``topics:`` key) carries each signal role.
ROLE_TOPIC: dict[str, str] = {
    "body_rate": "imu",
    "attitude": "odometry",
    "position": "odometry",
    "velocity": "odometry",
    "force_command": "wrench_command",
    "torque_command": "wrench_command",
    "desired_acceleration": "desired_acceleration",
    "desired_linear_acceleration": "desired_acceleration",
    "reference_position": "reference",
    "reference_attitude": "reference",
    "tilt": "actuators",
    "rotor": "actuators",
    "motor_command": "motor_outputs",  # CSV and ULog column maps only (no bag topic)
    "battery_voltage": "battery",  # sensor_msgs/BatteryState.voltage on /omav/battery
    "specific_force": "imu",  # sensor_msgs/Imu.linear_acceleration (when its covariance[0] >= 0)
}

#: Angle roles: unwrapped before interpolation, wrapped to (-pi, pi] after.
ANGLE_ROLES = ("attitude", "reference_attitude")


@dataclass
class RawSeries:
    """Samples of one role as recorded: ``stamps`` shape (n,) in seconds since
    ``RawLog.t0``, ``values`` shape (n, k) with k = len(ROLE_COLUMNS[role])."""

    stamps: np.ndarray
    values: np.ndarray


@dataclass
class TopicInfo:
    """What a reader saw of one topic (or CSV column group)."""

    name: str
    msgtype: str
    count: int
    duration: float  # s between first and last stamp
    rate: float  # Hz, median
    gaps: list[tuple[float, float]] = field(default_factory=list)  # (start, end) s
    duplicates: int = 0
    out_of_order: int = 0


@dataclass
class RawLog:
    """A log as read: series per role, topic inventory, problems found.

    ``t0`` is the absolute time (s, e.g. ROS epoch) that series stamps count from.
    ``topic_names`` maps topic roles (vehicle ``topics:`` keys) to the topic
    names the reader looked for (empty for CSV): errors and notes name them.
    ``mapped`` maps each signal role of a CSV read through a column map to its
    source columns (e.g. ``"columns IMU_GyroX, IMU_GyroY, IMU_GyroZ"``), whether
    or not it had usable rows; empty otherwise.
    """

    path: Path
    format: str  # "ros1", "ros2-sqlite3", "ros2-mcap", "mcap", "csv"
    t0: float
    series: dict[str, RawSeries]
    topics: list[TopicInfo] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    topic_names: dict[str, str] = field(default_factory=dict)
    mapped: dict[str, str] = field(default_factory=dict)


@dataclass
class FlightLog:
    """Signals of one log on a uniform time grid.

    ``t`` shape (N,) in s from the grid start; ``signals[role]`` shape (N, k);
    ``valid`` shape (N,) is False at grid points inside a gap of any role and,
    when :func:`omavctl.logs.read_vehicle_log` trims or windows the log, on
    the ground / motors idle and outside the time window; ``segments`` are
    half-open index ranges ``[start, stop)`` of valid runs. Vectors are in
    the contract frames (body FLU, world z up) whatever the log's frame.
    """

    path: Path
    format: str
    t: np.ndarray
    signals: dict[str, np.ndarray]
    valid: np.ndarray
    segments: list[tuple[int, int]]
    rate: float
    topics: list[TopicInfo] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: Absolute time (s, the log's own clock, e.g. ROS epoch) of ``t = 0``.
    t0: float = 0.0
    #: The body rate as the log recorded it (``"body_rate"``: stamps (m,) s on the
    #: clock of ``t``, values (m, 3)), cleaned as the grid's source; the grid values
    #: are its linear interpolation. Empty for a log built without :func:`align`.
    recorded: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @property
    def dt(self) -> float:
        return 1.0 / self.rate

    def has(self, role: str) -> bool:
        return role in self.signals
