"""Flight-log layer: round trips over every format, foreign writers, alignment, inspection."""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rich.console import Console

from omavctl.logs import (
    DEFAULT_TOPICS,
    ROLE_COLUMNS,
    ROLE_TOPIC,
    FlightLog,
    RawLog,
    RawSeries,
    align,
    inspect_log,
    read_log,
    read_raw,
    render_inspect,
    write_log,
)
from omavctl.logs.contract import euler_from_quaternion, quaternion_from_euler, wrap_angle

T0 = 1.7e9
DURATION = 3.0
ANGLES = ("attitude", "reference_attitude")


def _wave(t: np.ndarray, k: int, seed: int) -> np.ndarray:
    """Smooth test signal, shape (n, k): sums of sines, distinct per column."""
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.2, 2.0, size=(2, k))
    phase = rng.uniform(0, 2 * np.pi, size=(2, k))
    amp = rng.uniform(0.5, 3.0, size=(2, k))
    return (amp[0] * np.sin(freq[0] * 2 * np.pi * t[:, None] + phase[0])) + (
        amp[1] * np.cos(freq[1] * 2 * np.pi * t[:, None] + phase[1])
    )


def make_raw(duration: float = DURATION, t0: float = T0) -> RawLog:
    """Synthetic log: imu at 200 Hz, everything else at 100 Hz on the same 10 ms grid.

    Stamps are made as the readers make them (integer ns / 1e9), so they are exact.
    The yaw turns through +-pi to exercise angle unwrapping.
    """
    t200 = np.arange(round(duration * 200) + 1) * 5_000_000 / 1e9
    t100 = np.arange(round(duration * 100) + 1) * 10_000_000 / 1e9
    series = {}
    for i, (role, cols) in enumerate(ROLE_COLUMNS.items()):
        if role == "motor_command":  # no bag topic carries it
            continue
        t = t200 if ROLE_TOPIC[role] == "imu" else t100  # gyro and accelerometer
        values = _wave(t, len(cols), seed=i)
        if role in ANGLES:
            values[:, :2] *= 0.15  # roll, pitch within +-0.9 rad
            values[:, 2] = wrap_angle(2.5 + 1.5 * t)  # yaw wraps past pi
        if role == "battery_voltage":  # sensor_msgs/BatteryState's voltage is a float32
            values = (24.0 + values).astype(np.float32).astype(float)
        series[role] = RawSeries(stamps=t, values=values)
    return RawLog(path=Path("synthetic"), format="synthetic", t0=t0, series=series)


def angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(wrap_angle(a - b))


def assert_matches_source(log: FlightLog, raw: RawLog, atol: float = 1e-9) -> None:
    """Aligned signals equal the source sampled at the grid points."""
    assert set(log.signals) == set(raw.series)
    for role, values in log.signals.items():
        src = raw.series[role]
        expected = np.column_stack([np.interp(log.t, src.stamps, c) for c in src.values.T])
        if role in ANGLES:
            err = angle_diff(values, expected).max()
            assert np.all(values > -np.pi) and np.all(values <= np.pi)
        else:
            err = np.abs(values - expected).max()
        assert err < atol, f"{role}: max error {err}"


FORMATS = {"csv": "log.csv", "ros1": "log.bag", "mcap": "log.mcap", "ros2-mcap": "log_dir"}


@pytest.fixture(scope="module")
def source() -> RawLog:
    return make_raw()


@pytest.fixture(scope="module")
def written(source: RawLog, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("formats")
    paths = {}
    for fmt, name in FORMATS.items():
        write_log(base / name, source)
        paths[fmt] = base / name
    return paths


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_round_trip_every_format(fmt: str, source: RawLog, written: dict[str, Path]) -> None:
    log = read_log(written[fmt])
    assert log.format == fmt
    n = round(DURATION * 100) + 1
    assert log.t.shape == (n,)
    np.testing.assert_array_equal(log.t, np.arange(n) / 100.0)
    assert log.valid.all()
    assert log.segments == [(0, n)]
    assert log.notes == []
    assert_matches_source(log, source)


@pytest.mark.parametrize("fmt", ["ros1", "mcap", "ros2-mcap"])
def test_bag_stamps_exact(fmt: str, source: RawLog, written: dict[str, Path]) -> None:
    raw = read_raw(written[fmt])
    assert raw.t0 == T0
    for role, s in source.series.items():
        np.testing.assert_array_equal(raw.series[role].stamps, s.stamps)
    imu = next(t for t in raw.topics if t.name == "/omav/imu")
    assert imu.count == 601 and imu.rate == pytest.approx(200.0)
    assert imu.msgtype == "sensor_msgs/msg/Imu"


def test_formats_agree(written: dict[str, Path]) -> None:
    logs = {fmt: read_log(p, required=()) for fmt, p in written.items()}
    ref = logs["csv"]
    for fmt, log in logs.items():
        np.testing.assert_array_equal(log.t, ref.t)
        for role, values in ref.signals.items():
            diff = log.signals[role] - values
            if role in ANGLES:
                diff = wrap_angle(diff)
            assert np.abs(diff).max() < 1e-12, (fmt, role)


def test_csv_is_bit_exact(source: RawLog, written: dict[str, Path]) -> None:
    raw = read_raw(written["csv"])
    assert raw.format == "csv" and raw.t0 == 0.0
    header = written["csv"].read_text().splitlines()[0].split(",")
    assert header[:4] == ["t", "body_rate_x", "body_rate_y", "body_rate_z"]
    for role, s in raw.series.items():
        src = source.series[role]
        np.testing.assert_array_equal(s.values, src.values[np.searchsorted(src.stamps, s.stamps)])


def test_csv_with_offset_time(tmp_path: Path, source: RawLog) -> None:
    """A CSV whose t does not start at 0: the grid still starts at its first row."""
    path = tmp_path / "late.csv"
    write_log(path, source)
    lines = path.read_text().splitlines()
    rows = [lines[0]] + [
        ",".join([repr(float(r.split(",", 1)[0]) + 100.0), r.split(",", 1)[1]]) for r in lines[1:]
    ]
    path.write_text("\n".join(rows) + "\n")
    log = read_log(path)
    assert read_raw(path).t0 == 100.0
    assert log.t.size == 301
    assert_matches_source(log, source, atol=1e-9)


# --- logs not written by omavctl -------------------------------------------------


def _header(types: dict, ros1: bool, ns: int, frame: str = "base_link") -> object:
    stamp = types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    kwargs = {"stamp": stamp, "frame_id": frame}
    if ros1:
        kwargs["seq"] = 0
    return types["std_msgs/msg/Header"](**kwargs)


def _foreign_messages(store: object, ros1: bool, n: int = 150):
    """Messages as another recorder would write them: header stamps on a 10 ms
    grid, receive times 3 ms later, joints listed in a shuffled order, an
    unrelated topic. Returns (messages by topic, expected signals)."""
    types = store.types  # type: ignore[attr-defined]
    v3 = types["geometry_msgs/msg/Vector3"]
    t0 = 1_650_000_000_123_000_000
    stamps = t0 + np.arange(n) * 10_000_000
    k = np.arange(n)
    rate = np.stack([np.sin(0.05 * k), np.cos(0.03 * k), 0.1 * k], axis=1)
    rpy = np.stack([0.1 * np.sin(0.02 * k), -0.2 * np.cos(0.02 * k), 0.03 * k - 2.0], axis=1)
    force = np.stack([np.sin(0.01 * k), 2 + np.cos(0.01 * k), 40 + 0 * k], axis=1)
    torque = 0.1 * rate
    rotor = 1000 + np.arange(12)[None, :] + k[:, None]
    q = quaternion_from_euler(rpy)
    quat = types["geometry_msgs/msg/Quaternion"]
    zero9, zero36 = np.zeros(9), np.zeros(36)
    order = [7, 3, 0, 11, 5, 1, 9, 2, 10, 4, 8, 6]
    msgs: dict[str, list[tuple[int, object, str]]] = {}

    def add(topic: str, i: int, msg: object, typ: str) -> None:
        msgs.setdefault(topic, []).append((int(stamps[i]) + 3_000_000, msg, typ))

    for i in range(n):
        h = _header(types, ros1, int(stamps[i]))
        imu = types["sensor_msgs/msg/Imu"](
            header=h,
            orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=zero9,
            angular_velocity=v3(x=rate[i, 0], y=rate[i, 1], z=rate[i, 2]),
            angular_velocity_covariance=zero9,
            linear_acceleration=v3(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=zero9,
        )
        add("/omav/imu", i, imu, "sensor_msgs/msg/Imu")
        pose = types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=float(i)),
            orientation=quat(x=q[i, 0], y=q[i, 1], z=q[i, 2], w=q[i, 3]),
        )
        odom = types["nav_msgs/msg/Odometry"](
            header=_header(types, ros1, int(stamps[i]), "world"),
            child_frame_id="base_link",
            pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zero36),
            twist=types["geometry_msgs/msg/TwistWithCovariance"](
                twist=types["geometry_msgs/msg/Twist"](
                    linear=v3(x=0.5, y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0)
                ),
                covariance=zero36,
            ),
        )
        add("/omav/odometry", i, odom, "nav_msgs/msg/Odometry")
        wrench = types["geometry_msgs/msg/WrenchStamped"](
            header=h,
            wrench=types["geometry_msgs/msg/Wrench"](
                force=v3(x=force[i, 0], y=force[i, 1], z=force[i, 2]),
                torque=v3(x=torque[i, 0], y=torque[i, 1], z=torque[i, 2]),
            ),
        )
        add("/omav/wrench_command", i, wrench, "geometry_msgs/msg/WrenchStamped")
        joints = types["sensor_msgs/msg/JointState"](
            header=h,
            name=[f"rotor_{j}" for j in order],
            position=np.zeros(12),
            velocity=rotor[i, order].astype(float),
            effort=np.zeros(0),
        )
        add("/omav/actuators", i, joints, "sensor_msgs/msg/JointState")
        if i % 10 == 0:
            add("/diagnostics", i, types["std_msgs/msg/String"](data="ok"), "std_msgs/msg/String")
    expected = {
        "body_rate": rate,
        "attitude": rpy,
        "force_command": force,
        "torque_command": torque,
        "rotor": rotor.astype(float),
    }
    return msgs, expected, t0


def _check_foreign(raw: RawLog, expected: dict[str, np.ndarray], t0_ns: int) -> None:
    assert raw.t0 == t0_ns / 1e9
    n = expected["body_rate"].shape[0]
    np.testing.assert_array_equal(raw.series["body_rate"].stamps, np.arange(n) * 10_000_000 / 1e9)
    assert "tilt" not in raw.series
    assert any("arm_0..arm_5" in note for note in raw.notes)
    names = {t.name: t for t in raw.topics}
    assert names["/diagnostics"].count == 15
    assert names["/diagnostics"].msgtype == "std_msgs/msg/String"
    log = align(raw)
    for role, values in expected.items():
        got = log.signals[role]
        err = angle_diff(got, values) if role == "attitude" else np.abs(got - values)
        assert err.max() < 1e-9, role
    np.testing.assert_allclose(log.signals["position"][:, 2], np.arange(n), atol=1e-12)


def test_read_ros1_bag_from_rosbags_writer(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    msgs, expected, t0 = _foreign_messages(store, ros1=True)
    path = tmp_path / "foreign.bag"
    with Writer(path) as writer:
        for topic, items in msgs.items():
            conn = writer.add_connection(topic, items[0][2], typestore=store)
            for logtime, msg, typ in items:
                writer.write(conn, logtime, store.serialize_ros1(msg, typ))
    raw = read_raw(path)
    assert raw.format == "ros1"
    _check_foreign(raw, expected, t0)


def test_read_ros2_sqlite3_bag_from_rosbags_writer(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs, expected, t0 = _foreign_messages(store, ros1=False)
    path = tmp_path / "foreign_bag"
    with Writer(path, version=8) as writer:
        for topic, items in msgs.items():
            conn = writer.add_connection(topic, items[0][2], typestore=store)
            for logtime, msg, typ in items:
                writer.write(conn, logtime, store.serialize_cdr(msg, typ))
    assert any(p.suffix == ".db3" for p in path.iterdir())
    raw = read_raw(path)
    assert raw.format == "ros2-sqlite3"
    _check_foreign(raw, expected, t0)


def test_read_mcap_with_ros1_encoding(tmp_path: Path) -> None:
    """A standalone MCAP written with ros1msg schemas and ROS 1 serialisation."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    msgs, expected, t0 = _foreign_messages(store, ros1=True)
    path = tmp_path / "ros1.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros1", library="test")
        for topic, items in msgs.items():
            typ = items[0][2]
            schema = writer.register_schema(
                name=typ.replace("/msg/", "/"),
                encoding="ros1msg",
                data=store.generate_msgdef(typ)[0].encode(),
            )
            channel = writer.register_channel(
                topic=topic, message_encoding="ros1", schema_id=schema
            )
            for logtime, msg, _ in items:
                data = bytes(store.serialize_ros1(msg, typ))
                writer.add_message(channel, log_time=logtime, data=data, publish_time=logtime)
        writer.finish()
    raw = read_raw(path)
    assert raw.format == "mcap"
    _check_foreign(raw, expected, t0)


def test_receive_time_used_without_header_stamp(tmp_path: Path) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs, _expected, _t0 = _foreign_messages(store, ros1=False)
    for _, msg, _ in msgs["/omav/imu"]:
        msg.header.stamp.sec = 0
        msg.header.stamp.nanosec = 0
    path = tmp_path / "nostamp"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, items in msgs.items():
            conn = writer.add_connection(topic, items[0][2], typestore=store)
            for logtime, msg, typ in items:
                writer.write(conn, logtime, store.serialize_cdr(msg, typ))
    raw = read_raw(path)
    assert raw.format == "ros2-mcap"
    assert any("/omav/imu: 150 of 150 messages have no header stamp" in n for n in raw.notes)
    np.testing.assert_allclose(
        raw.series["body_rate"].stamps, raw.series["attitude"].stamps + 0.003, rtol=0, atol=1e-12
    )


# --- timing problems ------------------------------------------------------------


def test_gaps_duplicates_out_of_order_in_bag(tmp_path: Path) -> None:
    """Header stamps with a gap, duplicates and swaps, written in receive order."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs, expected, _t0 = _foreign_messages(store, ros1=False, n=300)
    imu = msgs["/omav/imu"]
    # header stamps are on a 10 ms grid: drop samples 100..141 (0.42 s gap),
    # duplicate samples 200 and 201, swap 250/251
    kept = imu[:100] + imu[142:]
    kept = [*kept[:150], kept[150], kept[150], *kept[151:]]
    i = kept.index(imu[250])
    kept[i], kept[i + 1] = kept[i + 1], kept[i]
    # receive times stay increasing
    base = [logtime for logtime, _, _ in kept]
    kept = [(sorted(base)[j], m, typ) for j, (_, m, typ) in enumerate(kept)]
    msgs["/omav/imu"] = kept
    path = tmp_path / "problems"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, items in msgs.items():
            conn = writer.add_connection(topic, items[0][2], typestore=store)
            for logtime, msg, typ in items:
                writer.write(conn, logtime, store.serialize_cdr(msg, typ))
    raw = read_raw(path)
    info = next(t for t in raw.topics if t.name == "/omav/imu")
    assert info.count == 300 - 42 + 1
    assert info.duplicates == 1
    assert info.out_of_order == 1
    assert info.gaps == [pytest.approx((0.99, 1.42))]

    log = align(raw)
    assert "/omav/imu: 1 duplicated stamps dropped (last kept)" in log.notes
    assert "/omav/imu: 1 out-of-order stamps (sorted)" in log.notes
    assert "gap of 0.43 s at t=0.99 s in /omav/imu: samples 100-141 excluded" in log.notes
    assert not log.valid[100:142].any()
    assert log.valid[:100].all() and log.valid[142:].all()
    assert log.segments == [(0, 100), (142, 300)]
    # sorted, deduplicated samples are interpolated correctly
    ok = log.valid
    np.testing.assert_allclose(log.signals["body_rate"][ok], expected["body_rate"][ok], atol=1e-9)


def test_align_handles_problems_in_raw_series() -> None:
    raw = make_raw(duration=2.0)
    s = raw.series["force_command"]
    # duplicate the 50th stamp (keep the last: value changed), reverse two samples
    stamps = np.insert(s.stamps, 51, s.stamps[50])
    values = np.insert(s.values, 51, s.values[50] + 1.0, axis=0)
    stamps[[80, 81]] = stamps[[81, 80]]
    values[[80, 81]] = values[[81, 80]]
    raw.series["force_command"] = RawSeries(stamps, values)
    raw.series["torque_command"] = RawSeries(stamps, values.copy())
    log = align(raw)
    assert log.notes.count("/omav/wrench_command: 1 duplicated stamps dropped (last kept)") == 1
    assert "/omav/wrench_command: 1 out-of-order stamps (sorted)" in log.notes
    np.testing.assert_allclose(log.signals["force_command"][50], s.values[50] + 1.0)
    np.testing.assert_allclose(log.signals["force_command"][80], s.values[80])
    assert log.valid.all()


def test_optional_role_with_nan_is_dropped_with_note() -> None:
    raw = make_raw(duration=1.0)
    raw.series["rotor"].values[10, 3] = np.nan
    log = align(raw)
    assert "/omav/actuators: 1 samples of rotor with non-finite values dropped" in log.notes
    assert np.isfinite(log.signals["rotor"]).all()


def test_grid_is_overlap_of_roles() -> None:
    raw = make_raw(duration=2.0)
    s = raw.series["reference_position"]
    raw.series["reference_position"] = RawSeries(s.stamps[20:150], s.values[20:150])
    log = align(raw, rate=50.0)
    assert log.rate == 50.0 and log.dt == 0.02
    assert log.t.size == round((s.stamps[149] - s.stamps[20]) * 50) + 1
    # grid starts at the latest first stamp: signals equal the source shifted
    br = raw.series["body_rate"]
    idx = np.round((s.stamps[20] + log.t) * 200).astype(int)
    np.testing.assert_allclose(log.signals["body_rate"], br.values[idx], atol=1e-12)


# --- topics, inspection, helpers -------------------------------------------------


CUSTOM = {"imu": "/vehicle/gyro", "odometry": "/vehicle/odom", "wrench_command": "/ctrl/wrench"}


@pytest.mark.parametrize("name", ["c.bag", "c.mcap", "c_dir"])
def test_custom_topic_names(tmp_path: Path, source: RawLog, name: str) -> None:
    path = tmp_path / name
    write_log(path, source, topics=CUSTOM)
    raw = read_raw(path, topics=CUSTOM)
    topic_names = {t.name for t in raw.topics}
    assert {"/vehicle/gyro", "/vehicle/odom", "/ctrl/wrench", "/omav/reference"} <= topic_names
    assert "/omav/imu" not in topic_names
    assert_matches_source(align(raw), source)
    from omavctl.base.errors import LogError

    with pytest.raises(LogError, match=r"missing topic '/omav/imu' \(role body_rate\)"):
        read_log(path)


def test_inspect_bag_and_render(written: dict[str, Path]) -> None:
    ins = inspect_log(written["ros1"])
    assert ins.format == "ros1"
    assert ins.duration == pytest.approx(DURATION)
    assert ins.roles_missing == {}
    assert ins.roles_found["body_rate"] == "/omav/imu"
    assert [t.name for t in ins.topics] == sorted(DEFAULT_TOPICS.values())
    buf = io.StringIO()
    render_inspect(ins, Console(file=buf, width=140))
    text = buf.getvalue()
    assert "ROS 1 bag" in text and "/omav/imu" in text and "200.0" in text
    assert "roles found" in text


def test_inspect_partial_csv(tmp_path: Path) -> None:
    path = tmp_path / "partial.csv"
    path.write_text(
        "t,body_rate_x,body_rate_y,body_rate_z,force_command_x,extra\n"
        "0.0,1,2,3,4,a\n0.01,1,2,nan,5,b\n0.02,1,2,3,6,c\n"
    )
    ins = inspect_log(path)
    assert ins.format == "csv"
    assert "body_rate" in ins.roles_found and "force_command" in ins.roles_missing
    assert ins.column_ranges["body_rate_z"] == (3.0, 3.0)
    assert any("missing column 'force_command_y'" in n for n in ins.notes)
    assert any("NaN in column 'body_rate_z' at row 2 (line 3)" in n for n in ins.notes)
    assert any("ignored: extra" in n for n in ins.notes)
    assert "attitude" in ins.required_missing
    buf = io.StringIO()
    render_inspect(ins, Console(file=buf, width=200))
    assert "body_rate_z" in buf.getvalue()


def test_inspect_reports_wrong_type_instead_of_failing(written: dict[str, Path]) -> None:
    swapped = {"imu": "/omav/odometry", "odometry": "/omav/imu"}
    ins = inspect_log(written["mcap"], topics=swapped)
    assert "body_rate" in ins.roles_missing
    assert any(
        "has type 'nav_msgs/msg/Odometry', expected 'sensor_msgs/msg/Imu'" in n for n in ins.notes
    )


def test_euler_quaternion_round_trip_matches_scipy() -> None:
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    rpy = np.column_stack(
        [
            rng.uniform(-np.pi, np.pi, 500),
            rng.uniform(-1.5, 1.5, 500),
            rng.uniform(-np.pi, np.pi, 500),
        ]
    )
    q = quaternion_from_euler(rpy)
    ref = Rotation.from_euler("ZYX", rpy[:, ::-1]).as_quat()
    sign = np.sign(np.sum(q * ref, axis=1, keepdims=True))
    np.testing.assert_allclose(q, sign * ref, atol=1e-12)
    back = euler_from_quaternion(-q)  # sign of q does not matter
    assert angle_diff(back, rpy).max() < 1e-12


def test_import_is_cheap() -> None:
    import subprocess
    import sys

    heavy = "('rosbags', 'mcap', 'rich', 'scipy')"
    code = (
        "import sys, omavctl.logs; "
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {heavy}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_log_starting_at_epoch_zero(tmp_path: Path) -> None:
    """t0 = 0 (e.g. from a CSV): the first header stamp is 0 and equals the
    receive time, so nothing is reported."""
    raw = make_raw(duration=1.0, t0=0.0)
    path = tmp_path / "zero.mcap"
    write_log(path, raw)
    back = read_raw(path)
    assert back.t0 == 0.0
    assert not any("header stamp" in n for n in back.notes)
    assert_matches_source(align(back), raw)


def test_read_mcap_without_schemas(tmp_path: Path) -> None:
    """Channels without schema: the contract's message types are assumed (ROS 2 Humble)."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs, expected, t0 = _foreign_messages(store, ros1=False)
    del msgs["/diagnostics"]
    path = tmp_path / "schemaless.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="test")
        for topic, items in msgs.items():
            channel = writer.register_channel(topic=topic, message_encoding="cdr", schema_id=0)
            for logtime, msg, typ in items:
                data = bytes(store.serialize_cdr(msg, typ))
                writer.add_message(channel, log_time=logtime, data=data, publish_time=logtime)
        writer.finish()
    log = read_log(path)
    np.testing.assert_allclose(log.signals["body_rate"], expected["body_rate"], atol=1e-12)
    assert read_raw(path).t0 == pytest.approx(t0 / 1e9, abs=1e-6)


# --- CSV of other layouts through a column map ------------------------------------

COLUMN_MAP = {
    "t": {"column": "time_us", "scale": 1e-6},
    "body_rate_x": "gx",
    "body_rate_y": "gy",
    "body_rate_z": {"column": "gz_deg", "scale": np.pi / 180},
    "attitude_roll": "roll",
    "attitude_pitch": "pitch",
    "attitude_yaw": "yaw",
    "force_command_x": {"value": 0.0},
    "force_command_y": {"value": 0.0},
    "force_command_z": {"column": "thrust", "scale": 40.0, "offset": 1.0},
    "torque_command_x": "mx",
    "torque_command_y": "my",
    "torque_command_z": "mz",
}


def test_column_map(tmp_path: Path) -> None:
    n = 50
    t = 1_000_000 + np.arange(n) * 10_000  # us
    lines = ["time_us,gx,gy,gz_deg,roll,pitch,yaw,thrust,mx,my,mz,mode"]
    for i in range(n):
        gyro = ",," if i == 7 else f"{0.01 * i},{-0.01 * i},{i}"  # not updated in row 7
        lines.append(f"{t[i]},{gyro},0.1,0.2,0.3,{i / n},0.5,0.6,0.7,AUTO")
    path = tmp_path / "foreign.csv"
    path.write_text("\n".join(lines) + "\n")
    raw = read_raw(path, columns=COLUMN_MAP)
    assert raw.format == "csv" and raw.t0 == 1.0
    assert raw.series["body_rate"].stamps.size == n - 1
    assert "body_rate: 1 row with empty cells skipped" in raw.notes
    log = read_log(path, columns=COLUMN_MAP)
    assert log.t.size == n
    np.testing.assert_allclose(log.signals["body_rate"][10], [0.1, -0.1, np.deg2rad(10)])
    np.testing.assert_allclose(log.signals["body_rate"][7], [0.07, -0.07, np.deg2rad(7)])
    np.testing.assert_allclose(log.signals["force_command"][:, 2], 40 * np.arange(n) / n + 1)
    np.testing.assert_allclose(log.signals["force_command"][:, :2], 0.0)
    ins = inspect_log(path, columns=COLUMN_MAP)
    assert ins.column_ranges["force_command_z"] == (1.0, pytest.approx(40 * 49 / 50 + 1))


def test_column_map_errors(tmp_path: Path) -> None:
    from omavctl.base.errors import ConfigError, LogError

    path = tmp_path / "x.csv"
    path.write_text("time_us,gx\n1,2\n")
    bad_maps: dict[str, dict[str, Any]] = {
        "unknown key 'columns.gyro_x'": {"t": "time_us", "gyro_x": "gx"},
        "key 'columns.t' is missing": {"body_rate_x": "gx"},
        "column map has body_rate_x but not body_rate_y, body_rate_z": {
            "t": "time_us",
            "body_rate_x": "gx",
        },
        "key 'columns.body_rate_x.scale' must be a number": {
            "t": "time_us",
            **{f"body_rate_{a}": {"column": "gx", "scale": "big"} for a in "xyz"},
        },
    }
    for message, columns in bad_maps.items():
        with pytest.raises(ConfigError, match=re.escape(message)):
            read_raw(path, columns=columns)
    columns = {"t": "time_us", **{f"body_rate_{a}": f"g{a}" for a in "xyz"}}
    with pytest.raises(LogError, match=re.escape("missing column 'gy' (mapped to body_rate_y)")):
        read_raw(path, columns=columns)
    path.write_text("time_us,gx,gy,gz\n1,2,3,4\n2,2,fast,4\n")
    with pytest.raises(
        LogError, match=r"non-numeric value 'fast' in column 'gy' at row 2 \(line 3\)"
    ):
        read_raw(path, columns=columns)


PX4_CSV = Path(__file__).parents[2] / "shared/data/real/px4tools_octocopter/01_07_59.csv"


@pytest.mark.skipif(not PX4_CSV.exists(), reason="real PX4 log not available")
def test_column_map_on_real_px4_log() -> None:
    """A real octocopter flight (PX4 sdlog2 CSV, ~83 Hz, sparse rows) through a column map."""
    columns = {
        "t": {"column": "TIME_StartTime", "scale": 1e-6},
        **{f"body_rate_{a}": f"IMU_Gyro{a.upper()}" for a in "xyz"},
        "attitude_roll": "ATT_Roll",
        "attitude_pitch": "ATT_Pitch",
        "attitude_yaw": "ATT_Yaw",
        "force_command_x": {"value": 0.0},
        "force_command_y": {"value": 0.0},
        "force_command_z": {"column": "ATTC_Thrust", "scale": 60.0},
        "torque_command_x": "ATTC_Roll",
        "torque_command_y": "ATTC_Pitch",
        "torque_command_z": "ATTC_Yaw",
    }
    before = PX4_CSV.stat().st_mtime_ns
    log = read_log(PX4_CSV, columns=columns)
    assert 21.0 < log.t[-1] < 21.5
    assert log.valid.all()
    assert np.abs(log.signals["body_rate"]).max() < 1.0
    assert PX4_CSV.stat().st_mtime_ns == before


def test_overlapping_gaps_in_two_topics() -> None:
    raw = make_raw(duration=2.0)

    def cut(role: str, a: float, b: float) -> None:
        s = raw.series[role]
        keep = ~((s.stamps > a + 1e-9) & (s.stamps < b - 1e-9))
        raw.series[role] = RawSeries(s.stamps[keep], s.values[keep])

    cut("body_rate", 0.5, 0.8)
    cut("force_command", 0.7, 1.0)
    cut("torque_command", 0.7, 1.0)
    log = align(raw)
    assert log.segments == [(0, 51), (100, 201)]
    assert "gap of 0.30 s at t=0.50 s in /omav/imu: samples 51-79 excluded" in log.notes
    assert "gap of 0.30 s at t=0.70 s in /omav/wrench_command: samples 71-99 excluded" in log.notes
    assert "49 of 201 grid samples inside gaps marked invalid" in log.notes


def test_rows_without_time_counted_in_words(tmp_path: Path) -> None:
    """The px4tools CSV's second line has no time value: the note says "1 row", and
    two such rows "2 rows" (it said "1 rows")."""
    n = 20
    for missing, note in ((1, "1 row without a time value skipped"), (2, "2 rows without")):
        lines = ["time_us,gx,gy,gz_deg,roll,pitch,yaw,thrust,mx,my,mz,mode"]
        for i in range(n):
            t = "" if i < missing else str(1_000_000 + i * 10_000)
            lines.append(f"{t},0.1,0.2,{i},0.1,0.2,0.3,{i / n},0.5,0.6,0.7,AUTO")
        path = tmp_path / f"notime{missing}.csv"
        path.write_text("\n".join(lines) + "\n")
        raw = read_raw(path, columns=COLUMN_MAP)
        assert any(line.startswith(note) for line in raw.notes), raw.notes
        assert raw.series["body_rate"].stamps.size == n - missing
