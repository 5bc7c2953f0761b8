"""The flight-log contract of DESIGN.md section 3 as data, plus attitude conversions.

Topic roles (the vehicle ``topics:`` keys) map to a topic name, a message type
and the signal roles (:data:`omavctl.logs.types.ROLE_COLUMNS`) they carry.
Everything here is pure numpy so importing it stays cheap.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.logs.types import ROLE_COLUMNS, ROLE_TOPIC

__all__ = [
    "DEFAULT_TOPICS",
    "TOPIC_FRAMES",
    "TOPIC_MSGTYPES",
    "TOPIC_SIGNALS",
    "euler_from_quaternion",
    "merge_topics",
    "quaternion_from_euler",
    "wrap_angle",
]

#: Default topic names per topic role (the built-in vehicle's ``topics:``).
DEFAULT_TOPICS: dict[str, str] = {
    "imu": "/omav/imu",
    "odometry": "/omav/odometry",
    "wrench_command": "/omav/wrench_command",
    "desired_acceleration": "/omav/desired_acceleration",
    "reference": "/omav/reference",
    "actuators": "/omav/actuators",
    "battery": "/omav/battery",
}

#: Message type (normalised ROS 2 spelling) expected on each topic role.
TOPIC_MSGTYPES: dict[str, str] = {
    "imu": "sensor_msgs/msg/Imu",
    "odometry": "nav_msgs/msg/Odometry",
    "wrench_command": "geometry_msgs/msg/WrenchStamped",
    "desired_acceleration": "geometry_msgs/msg/AccelStamped",
    "reference": "geometry_msgs/msg/PoseStamped",
    "actuators": "sensor_msgs/msg/JointState",
    "battery": "sensor_msgs/msg/BatteryState",
}

#: Signal roles carried by each topic role, in ROLE_COLUMNS order.
TOPIC_SIGNALS: dict[str, tuple[str, ...]] = {
    topic_role: tuple(r for r in ROLE_COLUMNS if ROLE_TOPIC[r] == topic_role)
    for topic_role in TOPIC_MSGTYPES
}

#: ``header.frame_id`` written per topic role (pose-like messages in the world frame).
TOPIC_FRAMES: dict[str, str] = {
    "imu": "base_link",
    "odometry": "world",
    "wrench_command": "base_link",
    "desired_acceleration": "base_link",
    "reference": "world",
    "actuators": "base_link",
    "battery": "base_link",
}

#: Joint names of the actuators topic: tilt servos (position) and rotors (velocity).
TILT_JOINTS: tuple[str, ...] = tuple(f"arm_{i}" for i in range(6))
ROTOR_JOINTS: tuple[str, ...] = tuple(f"rotor_{i}" for i in range(12))


def merge_topics(topics: Mapping[str, str] | None) -> dict[str, str]:
    """Topic role -> topic name: ``topics`` over :data:`DEFAULT_TOPICS`.

    Keys that are not topic roles are ignored (a vehicle YAML validates its own keys).
    Two roles naming one topic is a :class:`ConfigError`.
    """
    merged = dict(DEFAULT_TOPICS)
    if topics:
        merged.update({k: v for k, v in topics.items() if k in DEFAULT_TOPICS})
    seen: dict[str, str] = {}
    for role, name in merged.items():
        if name in seen:
            raise ConfigError(
                f"topic '{name}' is given for both topics.{seen[name]} and topics.{role}"
            )
        seen[name] = role
    return merged


def wrap_angle(x: np.ndarray) -> np.ndarray:
    """Wrap angles (any shape, rad) to (-pi, pi]."""
    return np.pi - np.mod(np.pi - x, 2.0 * np.pi)


def euler_from_quaternion(q: np.ndarray) -> np.ndarray:
    """ZYX Euler angles of unit quaternions.

    ``q`` shape (n, 4) as (x, y, z, w), normalised here; returns shape (n, 3)
    (roll, pitch, yaw) in rad with ``R = Rz(yaw) Ry(pitch) Rx(roll)``. Pitch
    uses ``atan2`` (not ``asin``) so it stays accurate near +-pi/2.
    """
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    r20 = 2.0 * (x * z - w * y)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    r10 = 2.0 * (x * y + w * z)
    r00 = 1.0 - 2.0 * (y * y + z * z)
    roll = np.arctan2(r21, r22)
    pitch = np.arctan2(-r20, np.hypot(r21, r22))
    yaw = np.arctan2(r10, r00)
    return np.stack([roll, pitch, yaw], axis=1)


def quaternion_from_euler(rpy: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w), shape (n, 4), of ZYX Euler angles shape (n, 3)."""
    rpy = np.asarray(rpy, dtype=float)
    cr, cp, cy = np.cos(0.5 * rpy).T
    sr, sp, sy = np.sin(0.5 * rpy).T
    w = cr * cp * cy + sr * sp * sy
    x = sr * cp * cy - cr * sp * sy
    y = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    return np.stack([x, y, z, w], axis=1)
