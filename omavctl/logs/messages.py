"""ROS messages <-> signal arrays for the contract topics (ROS 1 and ROS 2 alike).

Works on message objects of a rosbags typestore; never imports rosbags itself.
Extraction is one list comprehension per field group, then numpy.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from omavctl.logs.contract import (
    ROTOR_JOINTS,
    TILT_JOINTS,
    euler_from_quaternion,
    quaternion_from_euler,
)

__all__ = ["MessageBuilder", "extract_signals", "header_stamps_ns"]


def _vec3(objs: Sequence[Any]) -> np.ndarray:
    """(x, y, z) of each object, shape (n, 3)."""
    return np.array([(o.x, o.y, o.z) for o in objs], dtype=float).reshape(-1, 3)


def _quat(objs: Sequence[Any]) -> np.ndarray:
    """(x, y, z, w) of each quaternion object, shape (n, 4)."""
    return np.array([(o.x, o.y, o.z, o.w) for o in objs], dtype=float).reshape(-1, 4)


def _attitude(objs: Sequence[Any]) -> np.ndarray:
    """ZYX Euler angles of quaternion objects, shape (n, 3); NaN for zero quaternions."""
    q = _quat(objs)
    bad = ~(np.linalg.norm(q, axis=1) > 0)
    q[bad] = (0.0, 0.0, 0.0, 1.0)
    rpy = euler_from_quaternion(q)
    rpy[bad] = np.nan
    return rpy


def header_stamps_ns(msgs: Sequence[Any]) -> np.ndarray | None:
    """Header stamps (int64 ns, shape (n,)) of messages, or None if they have no header."""
    if not msgs or not hasattr(msgs[0], "header"):
        return None
    st = np.array([(m.header.stamp.sec, m.header.stamp.nanosec) for m in msgs], dtype=np.int64)
    return st[:, 0] * 1_000_000_000 + st[:, 1]


def _joint_values(
    msgs: Sequence[Any], joints: tuple[str, ...], attr: str
) -> tuple[np.ndarray, int]:
    """Values of ``attr`` (position/velocity) of ``joints`` per JointState message.

    Returns shape (n, len(joints)) (NaN where a joint or value is missing) and
    the number of messages that had all of the joints.
    """
    out = np.full((len(msgs), len(joints)), np.nan)
    index_cache: dict[tuple[str, ...], np.ndarray | None] = {}
    complete = 0
    for i, m in enumerate(msgs):
        names = tuple(m.name)
        if names not in index_cache:
            lookup = {n: j for j, n in enumerate(names)}
            idx = [lookup.get(n, -1) for n in joints]
            index_cache[names] = None if min(idx) < 0 else np.array(idx)
        idx_arr = index_cache[names]
        values = getattr(m, attr)
        if idx_arr is None or len(values) != len(names):
            continue
        out[i] = np.asarray(values, dtype=float)[idx_arr]
        complete += 1
    return out, complete


def extract_signals(
    topic_role: str, msgs: Sequence[Any], topic: str
) -> tuple[dict[str, np.ndarray], list[str]]:
    """Signal arrays (role -> shape (n, k)) carried by ``msgs`` of one contract topic.

    Also returns notes on content problems (e.g. joints missing from JointState).
    """
    notes: list[str] = []
    if topic_role == "imu":
        return {"body_rate": _vec3([m.angular_velocity for m in msgs])}, notes
    if topic_role == "odometry":
        poses = [m.pose.pose for m in msgs]
        return {
            "attitude": _attitude([p.orientation for p in poses]),
            "position": _vec3([p.position for p in poses]),
            "velocity": _vec3([m.twist.twist.linear for m in msgs]),
        }, notes
    if topic_role == "wrench_command":
        wrenches = [m.wrench for m in msgs]
        return {
            "force_command": _vec3([w.force for w in wrenches]),
            "torque_command": _vec3([w.torque for w in wrenches]),
        }, notes
    if topic_role == "desired_acceleration":
        accels = [m.accel for m in msgs]
        return {
            "desired_acceleration": _vec3([a.angular for a in accels]),
            "desired_linear_acceleration": _vec3([a.linear for a in accels]),
        }, notes
    if topic_role == "reference":
        poses = [m.pose for m in msgs]
        return {
            "reference_position": _vec3([p.position for p in poses]),
            "reference_attitude": _attitude([p.orientation for p in poses]),
        }, notes
    if topic_role == "actuators":
        out: dict[str, np.ndarray] = {}
        for role, joints, attr in (
            ("tilt", TILT_JOINTS, "position"),
            ("rotor", ROTOR_JOINTS, "velocity"),
        ):
            values, complete = _joint_values(msgs, joints, attr)
            if complete == 0:
                notes.append(
                    f"{topic}: no message has {attr}s of all of {joints[0]}..{joints[-1]}; "
                    f"{role} not read"
                )
                continue
            if complete < len(msgs):
                notes.append(
                    f"{topic}: {len(msgs) - complete} of {len(msgs)} messages lack {attr}s "
                    f"of some of {joints[0]}..{joints[-1]}"
                )
            out[role] = values
        return out, notes
    raise KeyError(topic_role)


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
                for i, (s, n) in enumerate(zip(sec, nsec))
            ]
        return [
            self.Header(stamp=self.Time(sec=s, nanosec=n), frame_id=frame_id)
            for s, n in zip(sec, nsec)
        ]

    def _vec3(self, a: np.ndarray, cls: Any = None) -> list[Any]:
        cls = cls or self.Vector3
        return [cls(x=x, y=y, z=z) for x, y, z in a.tolist()]

    def _quat(self, rpy: np.ndarray) -> list[Any]:
        q = quaternion_from_euler(rpy)
        return [self.Quaternion(x=x, y=y, z=z, w=w) for x, y, z, w in q.tolist()]

    def imu(self, headers: list[Any], body_rate: np.ndarray) -> list[Any]:
        imu = self.types["sensor_msgs/msg/Imu"]
        identity = self.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        zero = self.Vector3(x=0.0, y=0.0, z=0.0)
        return [
            imu(
                header=h,
                orientation=identity,
                orientation_covariance=self.no_estimate9,
                angular_velocity=w,
                angular_velocity_covariance=self.zeros9,
                linear_acceleration=zero,
                linear_acceleration_covariance=self.no_estimate9,
            )
            for h, w in zip(headers, self._vec3(body_rate))
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
            )
        ]

    def wrench(self, headers: list[Any], force: np.ndarray, torque: np.ndarray) -> list[Any]:
        t = self.types
        stamped, wrench = t["geometry_msgs/msg/WrenchStamped"], t["geometry_msgs/msg/Wrench"]
        return [
            stamped(header=h, wrench=wrench(force=f, torque=m))
            for h, f, m in zip(headers, self._vec3(force), self._vec3(torque))
        ]

    def accel(self, headers: list[Any], angular: np.ndarray, linear: np.ndarray) -> list[Any]:
        t = self.types
        stamped, accel = t["geometry_msgs/msg/AccelStamped"], t["geometry_msgs/msg/Accel"]
        return [
            stamped(header=h, accel=accel(linear=a, angular=w))
            for h, w, a in zip(headers, self._vec3(angular), self._vec3(linear))
        ]

    def pose(self, headers: list[Any], position: np.ndarray, attitude: np.ndarray) -> list[Any]:
        stamped = self.types["geometry_msgs/msg/PoseStamped"]
        return [
            stamped(header=h, pose=self.Pose(position=p, orientation=q))
            for h, p, q in zip(headers, self._vec3(position, self.Point), self._quat(attitude))
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
