"""ROS messages <-> signal arrays for the contract topics (ROS 1 and ROS 2 alike).

Works on message objects of a rosbags typestore; never imports rosbags itself.
Reading takes one flat row of numbers per message, then converts all rows of
a topic with numpy at once.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from omavctl.logs.contract import (
    ROTOR_JOINTS,
    TILT_JOINTS,
    euler_from_quaternion,
    quaternion_from_euler,
)

__all__ = ["ROW_EXTRACTORS", "MessageBuilder", "rows_to_signals"]


# One flat row per message, taken right after deserialisation: (sec, nanosec,
# values...). Keeping rows instead of message objects keeps the garbage
# collector from rescanning tens of thousands of live objects while reading.


def _imu_row(m: Any) -> tuple[Any, ...]:
    s, w, a = m.header.stamp, m.angular_velocity, m.linear_acceleration
    provided = float(m.linear_acceleration_covariance[0]) >= 0.0  # REP 145: -1 = not provided
    return (s.sec, s.nanosec, w.x, w.y, w.z, a.x, a.y, a.z, provided)


def _odometry_row(m: Any) -> tuple[Any, ...]:
    s, pose, v = m.header.stamp, m.pose.pose, m.twist.twist.linear
    q, p = pose.orientation, pose.position
    return (s.sec, s.nanosec, q.x, q.y, q.z, q.w, p.x, p.y, p.z, v.x, v.y, v.z)


def _wrench_row(m: Any) -> tuple[Any, ...]:
    s, f, t = m.header.stamp, m.wrench.force, m.wrench.torque
    return (s.sec, s.nanosec, f.x, f.y, f.z, t.x, t.y, t.z)


def _accel_row(m: Any) -> tuple[Any, ...]:
    s, w, a = m.header.stamp, m.accel.angular, m.accel.linear
    return (s.sec, s.nanosec, w.x, w.y, w.z, a.x, a.y, a.z)


def _pose_row(m: Any) -> tuple[Any, ...]:
    s, p, q = m.header.stamp, m.pose.position, m.pose.orientation
    return (s.sec, s.nanosec, p.x, p.y, p.z, q.x, q.y, q.z, q.w)


def _battery_row(m: Any) -> tuple[Any, ...]:
    s = m.header.stamp
    return (s.sec, s.nanosec, m.voltage)


def _joint_row(m: Any) -> tuple[Any, ...]:
    s = m.header.stamp
    return (s.sec, s.nanosec, tuple(m.name), m.position, m.velocity)


#: Per topic role: message object -> flat row ``(sec, nanosec, ...)``.
ROW_EXTRACTORS: dict[str, Callable[[Any], tuple[Any, ...]]] = {
    "imu": _imu_row,
    "odometry": _odometry_row,
    "wrench_command": _wrench_row,
    "desired_acceleration": _accel_row,
    "reference": _pose_row,
    "actuators": _joint_row,
    "battery": _battery_row,
}


def _attitude(q: np.ndarray) -> np.ndarray:
    """ZYX Euler angles of quaternions shape (n, 4) (x, y, z, w), shape (n, 3);
    NaN for zero (invalid) quaternions."""
    q = q.copy()
    bad = ~(np.linalg.norm(q, axis=1) > 0)
    q[bad] = (0.0, 0.0, 0.0, 1.0)
    rpy = euler_from_quaternion(q)
    rpy[bad] = np.nan
    return rpy


def _joint_values(
    rows: Sequence[tuple[Any, ...]], joints: tuple[str, ...], which: int
) -> tuple[np.ndarray, int]:
    """Values of ``joints`` per JointState row (``which`` 3: position, 4: velocity).

    Returns shape (n, len(joints)) (NaN where a joint or value is missing) and
    the number of messages that had all of the joints.
    """
    out = np.full((len(rows), len(joints)), np.nan)
    index_cache: dict[tuple[str, ...], np.ndarray | None] = {}
    complete = 0
    for i, row in enumerate(rows):
        names = row[2]
        if names not in index_cache:
            lookup = {n: j for j, n in enumerate(names)}
            idx = [lookup.get(n, -1) for n in joints]
            index_cache[names] = None if min(idx) < 0 else np.array(idx)
        idx_arr = index_cache[names]
        values = row[which]
        if idx_arr is None or len(values) != len(names):
            continue
        out[i] = np.asarray(values, dtype=float)[idx_arr]
        complete += 1
    return out, complete


def rows_to_signals(
    topic_role: str, rows: Sequence[tuple[Any, ...]], topic: str
) -> tuple[np.ndarray, dict[str, np.ndarray], list[str]]:
    """Header stamps and signal arrays of the rows of one contract topic.

    Returns header stamps (int64 ns, shape (n,); 0 where the header stamp is
    unset), signal role -> values shape (n, k), and notes on content problems
    (e.g. joints missing from JointState).
    """
    notes: list[str] = []
    if topic_role == "actuators":
        st = np.array([row[:2] for row in rows], dtype=np.int64).reshape(-1, 2)
        stamps = st[:, 0] * 1_000_000_000 + st[:, 1]
        out: dict[str, np.ndarray] = {}
        for role, joints, which, kind in (
            ("tilt", TILT_JOINTS, 3, "position"),
            ("rotor", ROTOR_JOINTS, 4, "velocity"),
        ):
            values, complete = _joint_values(rows, joints, which)
            if complete == 0:
                notes.append(
                    f"{topic}: no message has {kind}s of all of {joints[0]}..{joints[-1]}; "
                    f"{role} not read"
                )
                continue
            if complete < len(rows):
                notes.append(
                    f"{topic}: {len(rows) - complete} of {len(rows)} messages lack {kind}s "
                    f"of some of {joints[0]}..{joints[-1]}"
                )
            out[role] = values
        return stamps, out, notes

    a = np.array(rows, dtype=float)
    # sec (int32) and nanosec (< 1e9) are exact in float64
    stamps = a[:, 0].astype(np.int64) * 1_000_000_000 + a[:, 1].astype(np.int64)
    if topic_role == "imu":
        signals = {"body_rate": a[:, 2:5]}
        if a.shape[1] > 8 and np.all(a[:, 8] > 0):  # every message has an accelerometer
            signals["specific_force"] = a[:, 5:8]
    elif topic_role == "odometry":
        signals = {"attitude": _attitude(a[:, 2:6]), "position": a[:, 6:9], "velocity": a[:, 9:12]}
    elif topic_role == "wrench_command":
        signals = {"force_command": a[:, 2:5], "torque_command": a[:, 5:8]}
    elif topic_role == "desired_acceleration":
        signals = {"desired_acceleration": a[:, 2:5], "desired_linear_acceleration": a[:, 5:8]}
    elif topic_role == "reference":
        signals = {"reference_position": a[:, 2:5], "reference_attitude": _attitude(a[:, 5:9])}
    elif topic_role == "battery":
        signals = {"battery_voltage": a[:, 2:3]}
    else:
        raise KeyError(topic_role)
    return stamps, {k: np.ascontiguousarray(v) for k, v in signals.items()}, notes


class MessageBuilder:
    """Builds contract messages for one rosbags typestore (ROS 1 or ROS 2 types).

    Every ``build_*`` method takes stamps (int64 ns, shape (n,)) and signal arrays
    shape (n, k) and returns a list of n message objects.
    """

    def __init__(self, typestore: Any) -> None:
        self.types = typestore.types
        header_fields = [f[0] for f in typestore.fielddefs["std_msgs/msg/Header"][1]]
        self.has_seq = "seq" in header_fields
        t = self.types
        self.Time = t["builtin_interfaces/msg/Time"]
        self.Header = t["std_msgs/msg/Header"]
        self.Vector3 = t["geometry_msgs/msg/Vector3"]
        self.Point = t["geometry_msgs/msg/Point"]
        self.Quaternion = t["geometry_msgs/msg/Quaternion"]
        self.Pose = t["geometry_msgs/msg/Pose"]
        self.zeros9 = np.zeros(9)
        self.zeros36 = np.zeros(36)
        self.no_estimate9 = np.zeros(9)
        self.no_estimate9[0] = -1.0  # REP 145: covariance[0] = -1 means "not provided"

    def headers(self, stamps_ns: np.ndarray, frame_id: str) -> list[Any]:
        sec = (stamps_ns // 1_000_000_000).tolist()
        nsec = (stamps_ns % 1_000_000_000).tolist()
        if self.has_seq:
            return [
                self.Header(seq=i, stamp=self.Time(sec=s, nanosec=n), frame_id=frame_id)
                for i, (s, n) in enumerate(zip(sec, nsec, strict=True))
            ]
        return [
            self.Header(stamp=self.Time(sec=s, nanosec=n), frame_id=frame_id)
            for s, n in zip(sec, nsec, strict=True)
        ]

    def _vec3(self, a: np.ndarray, cls: Any = None) -> list[Any]:
        cls = cls or self.Vector3
        return [cls(x=x, y=y, z=z) for x, y, z in a.tolist()]

    def _quat(self, rpy: np.ndarray) -> list[Any]:
        q = quaternion_from_euler(rpy)
        return [self.Quaternion(x=x, y=y, z=z, w=w) for x, y, z, w in q.tolist()]

    def imu(
        self, headers: list[Any], body_rate: np.ndarray, specific_force: np.ndarray | None = None
    ) -> list[Any]:
        """Imu messages; ``linear_acceleration`` is the specific force (n, 3) m/s^2 when
        given, else zeros marked "not provided" (covariance[0] = -1, REP 145)."""
        imu = self.types["sensor_msgs/msg/Imu"]
        identity = self.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        if specific_force is None:
            linear = [self.Vector3(x=0.0, y=0.0, z=0.0)] * len(headers)
            cov = self.no_estimate9
        else:
            linear, cov = self._vec3(specific_force), self.zeros9
        return [
            imu(
                header=h,
                orientation=identity,
                orientation_covariance=self.no_estimate9,
                angular_velocity=w,
                angular_velocity_covariance=self.zeros9,
                linear_acceleration=a,
                linear_acceleration_covariance=cov,
            )
            for h, w, a in zip(headers, self._vec3(body_rate), linear, strict=True)
        ]

    def odometry(
        self,
        headers: list[Any],
        attitude: np.ndarray,
        position: np.ndarray,
        velocity: np.ndarray,
        body_rate: np.ndarray,
        child_frame_id: str = "base_link",
    ) -> list[Any]:
        t = self.types
        odom = t["nav_msgs/msg/Odometry"]
        pwc = t["geometry_msgs/msg/PoseWithCovariance"]
        twc = t["geometry_msgs/msg/TwistWithCovariance"]
        twist = t["geometry_msgs/msg/Twist"]
        return [
            odom(
                header=h,
                child_frame_id=child_frame_id,
                pose=pwc(pose=self.Pose(position=p, orientation=q), covariance=self.zeros36),
                twist=twc(twist=twist(linear=v, angular=w), covariance=self.zeros36),
            )
            for h, q, p, v, w in zip(
                headers,
                self._quat(attitude),
                self._vec3(position, self.Point),
                self._vec3(velocity),
                self._vec3(body_rate),
                strict=True,
            )
        ]

    def battery(self, headers: list[Any], voltage: np.ndarray) -> list[Any]:
        """``sensor_msgs/BatteryState`` with the voltage (n, 1) V; what is not measured
        is NaN (the message's convention), the status unknown (0)."""
        state, nan = self.types["sensor_msgs/msg/BatteryState"], float("nan")
        return [
            state(
                header=h,
                voltage=v,
                temperature=nan,
                current=nan,
                charge=nan,
                capacity=nan,
                design_capacity=nan,
                percentage=nan,
                power_supply_status=0,
                power_supply_health=0,
                power_supply_technology=0,
                present=True,
                cell_voltage=np.zeros(0, np.float32),
                cell_temperature=np.zeros(0, np.float32),
                location="",
                serial_number="",
            )
            for h, (v,) in zip(headers, voltage.tolist(), strict=True)
        ]

    def wrench(self, headers: list[Any], force: np.ndarray, torque: np.ndarray) -> list[Any]:
        t = self.types
        stamped, wrench = t["geometry_msgs/msg/WrenchStamped"], t["geometry_msgs/msg/Wrench"]
        return [
            stamped(header=h, wrench=wrench(force=f, torque=m))
            for h, f, m in zip(headers, self._vec3(force), self._vec3(torque), strict=True)
        ]

    def accel(self, headers: list[Any], angular: np.ndarray, linear: np.ndarray) -> list[Any]:
        t = self.types
        stamped, accel = t["geometry_msgs/msg/AccelStamped"], t["geometry_msgs/msg/Accel"]
        return [
            stamped(header=h, accel=accel(linear=a, angular=w))
            for h, w, a in zip(headers, self._vec3(angular), self._vec3(linear), strict=True)
        ]

    def pose(self, headers: list[Any], position: np.ndarray, attitude: np.ndarray) -> list[Any]:
        stamped = self.types["geometry_msgs/msg/PoseStamped"]
        return [
            stamped(header=h, pose=self.Pose(position=p, orientation=q))
            for h, p, q in zip(
                headers, self._vec3(position, self.Point), self._quat(attitude), strict=True
            )
        ]

    def joint_state(
        self, headers: list[Any], tilt: np.ndarray | None, rotor: np.ndarray | None
    ) -> list[Any]:
        """JointState with ``arm_0..5`` (position = tilt) and/or ``rotor_0..11``
        (velocity = rotor speed); values not measured are NaN."""
        js = self.types["sensor_msgs/msg/JointState"]
        n = len(headers)
        names: list[str] = []
        pos_cols: list[np.ndarray] = []
        vel_cols: list[np.ndarray] = []
        if tilt is not None:
            names += TILT_JOINTS
            pos_cols.append(tilt)
            vel_cols.append(np.full((n, len(TILT_JOINTS)), np.nan))
        if rotor is not None:
            names += ROTOR_JOINTS
            pos_cols.append(np.full((n, len(ROTOR_JOINTS)), np.nan))
            vel_cols.append(rotor)
        position = np.ascontiguousarray(np.hstack(pos_cols), dtype=np.float64)
        velocity = np.ascontiguousarray(np.hstack(vel_cols), dtype=np.float64)
        effort = np.zeros(0)
        return [
            js(header=h, name=names, position=position[i], velocity=velocity[i], effort=effort)
            for i, h in enumerate(headers)
        ]
