"""Logs from other vehicles: role-based column maps, frames, flight segmentation,
time windows, irregular sampling, and the column map ``inspect`` suggests."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from omavctl.base.errors import ConfigError, LogError
from omavctl.cli import app
from omavctl.logs import (
    RawLog,
    RawSeries,
    flatten_column_map,
    inspect_log,
    parse_time_window,
    read_log,
    read_vehicle_log,
    write_log,
)
from omavctl.logs.contract import quaternion_from_euler, wrap_angle
from omavctl.logs.frames import FRD_TO_FLU, flip_quaternion
from omavctl.logs.segment import segment_flight
from omavctl.vehicle import default_vehicle, load_vehicle

REPO = Path(__file__).parents[1]
PX4_CSV = Path(__file__).parents[2] / "shared/data/real/px4tools_octocopter/01_07_59.csv"
PX4_VEHICLE = REPO / "examples/px4tools-octocopter.yaml"
needs_px4 = pytest.mark.skipif(
    not PX4_CSV.exists(), reason=f"real PX4 log not available at {PX4_CSV}"
)
runner = CliRunner()


def px4_column(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(t in s from the first stamp, values) of one column of the px4tools CSV, read
    here with the csv module (rows where the column or the time is empty dropped)."""
    with PX4_CSV.open(newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    jt, jv = header.index("TIME_StartTime"), header.index(name)
    pairs = [(float(r[jt]), float(r[jv])) for r in rows[1:] if r[jt].strip() and r[jv].strip()]
    t_us, v = np.array(pairs).T
    t0 = min(float(r[jt]) for r in rows[1:] if r[jt].strip())
    return (t_us - t0) * 1e-6, v


def write_vehicle(path: Path, tree: dict[str, Any]) -> Path:
    path.write_text(yaml.safe_dump({"mass": 2.0, "inertia": [0.03, 0.03, 0.05], **tree}))
    return path


# --- the real px4tools octocopter ----------------------------------------------------


@needs_px4
def test_role_based_map_reads_px4tools_log() -> None:
    vehicle = load_vehicle(PX4_VEHICLE)
    assert vehicle.frame == "FRD" and vehicle.mass == 2.0
    before = PX4_CSV.stat().st_mtime_ns
    log = read_vehicle_log(PX4_CSV, vehicle, trim=False)
    assert PX4_CSV.stat().st_mtime_ns == before
    assert log.rate == 100.0 and 21.4 < log.t[-1] < 21.5
    assert log.valid.all() and log.segments == [(0, log.t.size)]
    # first grid time is the latest first stamp of the roles: recover it from the gyro
    t_g, gx = px4_column("IMU_GyroX")
    _, gy = px4_column("IMU_GyroY")
    _, thrust = px4_column("ATTC_Thrust")
    start = max(px4_column(c)[0][0] for c in ("IMU_GyroX", "ATT_Roll", "ATTC_Roll", "LPOS_X"))
    grid = start + log.t
    # FRD -> FLU: x kept, y and z negated; thrust magnitude becomes +z
    np.testing.assert_allclose(log.signals["body_rate"][:, 0], np.interp(grid, t_g, gx))
    np.testing.assert_allclose(log.signals["body_rate"][:, 1], -np.interp(grid, t_g, gy))
    np.testing.assert_allclose(log.signals["force_command"][:, 2], np.interp(grid, t_g, thrust))
    np.testing.assert_allclose(log.signals["force_command"][:, :2], 0.0)
    assert any(n.startswith("frame FRD: ") for n in log.notes)
    # the same map in the flat spelling reads the same signals
    flat = flatten_column_map(vehicle.columns)
    assert flat["force_command_z"] == {"column": "ATTC_Thrust", "scale": -1.0, "offset": -0.0}
    same = read_log(PX4_CSV, columns=flat, frame="FRD")
    for role, values in log.signals.items():
        np.testing.assert_array_equal(same.signals[role], values, err_msg=role)


@needs_px4
def test_in_flight_detection_excludes_ground_segment_of_px4tools_log() -> None:
    log = read_vehicle_log(PX4_CSV, load_vehicle(PX4_VEHICLE))
    assert len(log.segments) == 1
    a, b = log.segments[0]
    assert b == log.t.size  # the log ends in flight: nothing excluded at the end
    t_end = log.t[a]  # first in-flight sample
    note = next(n for n in log.notes if n.startswith("ground/idle: "))
    assert note.startswith(f"ground/idle: 0.00-{log.t[a - 1]:.2f} s excluded")

    # the rule recomputed from the thrust column read here, on the raw rows
    t, thrust = px4_column("ATTC_Thrust")
    level = np.percentile(log.signals["force_command"][:, 2], 90)
    idle = thrust < 0.25 * level
    hover = np.median(thrust[~idle])
    assert 0.40 < hover < 0.45  # normalised hover thrust of this octocopter
    takeoff = t[np.argmax(thrust >= 0.9 * hover)]  # first row at take-off thrust
    offset = max(px4_column(c)[0][0] for c in ("IMU_GyroX", "ATT_Roll", "ATTC_Roll", "LPOS_X"))
    # excluded until take-off thrust plus the 0.2 s margin; the grid interpolates
    # between rows ~12 ms apart, so a one-row spike over the threshold may not count
    assert takeoff + 0.2 <= t_end + offset <= takeoff + 0.2 + 0.08
    assert 5.0 < t_end < 5.6
    # before: motors idle (thrust exactly 0) for the first second, then spool-up
    # below hover; after: never again near idle
    assert (thrust[t < 0.9] == 0).all()
    assert thrust[t < takeoff].max() < 0.9 * hover
    assert np.mean(thrust[t < t_end + offset - 0.2]) < 0.6 * hover
    assert thrust[t >= t_end + offset].min() > 0.8 * hover
    # hover samples are kept: every grid sample after take-off is valid
    f = log.signals["force_command"][:, 2]
    in_hover = (log.t > t_end) & (np.abs(f - hover) < 0.15 * hover)
    assert in_hover.sum() > 1000 and log.valid[in_hover].all()
    assert log.valid[log.t >= t_end].all()


@needs_px4
def test_time_window_on_px4tools_log() -> None:
    vehicle = load_vehicle(PX4_VEHICLE)
    log = read_vehicle_log(PX4_CSV, vehicle, time_window=(8.0, 15.0))
    assert log.segments == [(800, 1500)]  # 8 <= t < 15
    assert log.valid.sum() == 700
    assert f"time window 8:15 s: {log.t.size - 700} of {log.t.size} samples outside excluded" in (
        log.notes
    )
    # the window and the ground trimming combine; split windows share no sample
    first = read_vehicle_log(PX4_CSV, vehicle, time_window=(None, 13.0))
    rest = read_vehicle_log(PX4_CSV, vehicle, time_window=(13.0, None))
    (a, b), (c, d) = first.segments[0], rest.segments[0]
    assert first.t[a] > 5.0 and b == c == 1300 and d == rest.t.size
    assert not (first.valid & rest.valid).any()
    with pytest.raises(LogError) as err:
        read_vehicle_log(PX4_CSV, vehicle, time_window=(1.0, 3.0))
    # where the window is counted from: the log's first sample, 579.46 s on its clock
    span = (
        "the log spans 0.00-21.44 s from its first sample, at 579.46 s on the log's own "
        "clock; windows count from that first sample; its valid samples span 5.34-21.44 s"
    )
    assert str(err.value) == (
        f"{PX4_CSV}: time window 1:3 s has no valid samples (all in gaps or on the ground): " + span
    )
    with pytest.raises(LogError) as err:
        read_vehicle_log(PX4_CSV, vehicle, time_window=(30.0, 40.0))
    assert str(err.value) == f"{PX4_CSV}: time window 30:40 s has no samples: {span}"
    with pytest.raises(LogError) as err:
        read_vehicle_log(PX4_CSV, vehicle, time_window=(12.0, 12.0))
    assert str(err.value) == f"{PX4_CSV}: empty time window 12:12 s: START must be below END"


def test_parse_time_window() -> None:
    assert parse_time_window("5:12.5") == (5.0, 12.5)
    assert parse_time_window(":10") == (None, 10.0)
    assert parse_time_window("3:") == (3.0, None)
    for bad in ("5", "a:b", "1:2:3", "nan:3"):
        with pytest.raises(ConfigError, match="must be START:END"):
            parse_time_window(bad)
    with pytest.raises(ConfigError, match="START must be below END, got '9:2'"):
        parse_time_window("9:2")


# --- inspect suggests a column map ---------------------------------------------------


@needs_px4
def test_inspect_suggests_column_map_for_px4tools_log(tmp_path: Path) -> None:
    ins = inspect_log(PX4_CSV)
    cols = ins.suggested_columns
    assert cols is not None and ins.suggestion is not None
    assert cols["time"] == {"column": "TIME_StartTime", "scale": 1e-6}
    assert cols["body_rate"] == {"x": "IMU_GyroX", "y": "IMU_GyroY", "z": "IMU_GyroZ"}
    assert cols["torque_command"] == {"x": "ATTC_Roll", "y": "ATTC_Pitch", "z": "ATTC_Yaw"}
    # the accelerometer reads -g: an FRD log, whose positive thrust points along -z
    assert cols["force_command"] == {"z": "ATTC_Thrust", "scale": -1.0}
    assert "frame: FRD  # IMU_AccZ reads -9.7 m/s^2 (median): z points down" in ins.suggestion
    assert "command_units: {torque: normalised, force: normalised}" in ins.suggestion
    assert cols["attitude"] == {"roll": "ATT_Roll", "pitch": "ATT_Pitch", "yaw": "ATT_Yaw"}
    assert "other candidates: IMU1_Gyro{X,Y,Z}, ATT_{Roll,Pitch,Yaw}Rate" in ins.suggestion
    assert "GUESSED" in ins.suggestion
    assert ins.column_ranges["ATTC_Thrust"] == (0.0, pytest.approx(0.504642963409))
    assert "IMU2_GyroX" not in ins.column_ranges  # all-empty columns are skipped
    # unmapped, nothing can be read: a script sees what fit and evaluate lack
    assert ins.roles_found == {}
    assert ins.required_missing == ["body_rate", "attitude", "force_command", "torque_command"]
    assert 21.4 < ins.duration < 21.5

    # the CLI prints it; pasted into a vehicle file it reads the log
    result = runner.invoke(app, ["inspect", str(PX4_CSV)])
    assert result.exit_code == 0, result.output
    pasted = result.output.split("then check it):\n", 1)[1]
    assert pasted == ins.suggestion
    vehicle_file = tmp_path / "octo.yaml"
    vehicle_file.write_text("mass: 2.0\ninertia: [0.035, 0.035, 0.065]\n" + pasted)
    vehicle = load_vehicle(vehicle_file)
    assert vehicle.columns == cols
    log = read_vehicle_log(PX4_CSV, vehicle)
    assert log.segments and log.segments[-1][1] == log.t.size

    # with the map in the vehicle file, inspect reads the roles through it
    result = runner.invoke(app, ["inspect", str(PX4_CSV), "--vehicle", str(vehicle_file)])
    assert result.exit_code == 0, result.output
    assert "suggested column map" not in result.output
    assert "roles found: body_rate, attitude, position, force_command, torque_command" in (
        result.output
    )


def _foreign_csv(path: Path, header: list[str], n: int = 300, t_scale: float = 1e6) -> Path:
    """A CSV with the given header: first column time (s * t_scale), the rest smooth."""
    t = np.arange(n) * 0.004
    rng = np.random.default_rng(1)
    cols = [t * t_scale] + [
        0.3 * np.sin(2 * np.pi * rng.uniform(0.2, 1.0) * t + rng.uniform(0, 6)) for _ in header[1:]
    ]
    data = np.column_stack(cols)
    body = "\n".join(",".join(repr(float(x)) for x in row) for row in data)
    path.write_text(",".join(header) + "\n" + body + "\n")
    return path


@pytest.mark.parametrize(
    ("header", "expected"),
    [
        (  # ArduPilot-style dump: Group.Field
            "TimeUS IMU.GyrX IMU.GyrY IMU.GyrZ IMU2.GyrX IMU2.GyrY IMU2.GyrZ ATT.DesRoll ATT.Roll "
            "ATT.DesPitch ATT.Pitch ATT.DesYaw ATT.Yaw RATE.ROut RATE.POut RATE.YOut CTUN.ThI "
            "CTUN.ThO".split(),
            {
                "time": {"column": "TimeUS", "scale": 1e-6},
                "body_rate": {"x": "IMU.GyrX", "y": "IMU.GyrY", "z": "IMU.GyrZ"},
                "attitude": {"roll": "ATT.Roll", "pitch": "ATT.Pitch", "yaw": "ATT.Yaw"},
                "torque_command": {"x": "RATE.ROut", "y": "RATE.POut", "z": "RATE.YOut"},
                "force_command": {"z": "CTUN.ThO"},
            },
        ),
        (  # ULog topics flattened: topic.field[i]
            ["timestamp"]
            + [f"sensor_combined.gyro_rad[{i}]" for i in range(3)]
            + [f"vehicle_attitude.q[{i}]" for i in range(4)]
            + [f"actuator_controls_0.control[{i}]" for i in range(8)]
            + [f"actuator_outputs.output[{i}]" for i in range(8)],
            {
                "time": {"column": "timestamp", "scale": 1e-6},
                "body_rate": {
                    f"{a}": f"sensor_combined.gyro_rad[{i}]" for i, a in enumerate("xyz")
                },
                "attitude": {
                    "quaternion": {a: f"vehicle_attitude.q[{i}]" for i, a in enumerate("wxyz")}
                },
                "torque_command": {
                    a: f"actuator_controls_0.control[{i}]" for i, a in enumerate("xyz")
                },
                "force_command": {"z": "actuator_controls_0.control[3]"},
            },
        ),
        (  # ROS topic echo: field.a.b.x, time in ns
            ["%time"]
            + [f"field.angular_velocity.{a}" for a in "xyz"]
            + [f"field.orientation.{a}" for a in "xyzw"]
            + [f"field.wrench.{k}.{a}" for k in ("force", "torque") for a in "xyz"],
            {
                "time": {"column": "%time", "scale": 1e-9},
                "body_rate": {a: f"field.angular_velocity.{a}" for a in "xyz"},
                "attitude": {"quaternion": {a: f"field.orientation.{a}" for a in "wxyz"}},
                "force_command": {a: f"field.wrench.force.{a}" for a in "xyz"},
                "torque_command": {a: f"field.wrench.torque.{a}" for a in "xyz"},
            },
        ),
        (  # hand-written names, seconds, degrees
            "t_s wx wy wz roll_deg pitch_deg yaw_deg tau_x tau_y tau_z thrust_sp thrust".split(),
            {
                "time": {"column": "t_s"},
                "body_rate": {"x": "wx", "y": "wy", "z": "wz"},
                "attitude": {
                    "roll": "roll_deg",
                    "pitch": "pitch_deg",
                    "yaw": "yaw_deg",
                    "scale": pytest.approx(np.pi / 180),
                },
                "torque_command": {"x": "tau_x", "y": "tau_y", "z": "tau_z"},
                "force_command": {"z": "thrust"},
            },
        ),
    ],
    ids=["ardupilot", "ulog", "ros", "generic"],
)
def test_inspect_suggestion_for_other_layouts(
    tmp_path: Path, header: list[str], expected: dict[str, Any]
) -> None:
    scale = {"%time": 1e9, "t_s": 1.0}.get(header[0], 1e6)
    path = _foreign_csv(tmp_path / "log.csv", header, t_scale=scale)
    ins = inspect_log(path)
    assert ins.suggested_columns == expected
    # round trip: the suggestion pasted into a vehicle file reads the log
    assert ins.suggestion is not None
    vehicle_file = tmp_path / "v.yaml"
    vehicle_file.write_text("mass: 1.0\n" + ins.suggestion)
    log = read_vehicle_log(path, load_vehicle(vehicle_file), trim=False)
    assert log.t.size == 120 and log.valid.all()


# --- frames --------------------------------------------------------------------------


def _rot(rpy: np.ndarray) -> np.ndarray:
    """Rotation matrices shape (n, 3, 3) of ZYX Euler angles shape (n, 3)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("ZYX", rpy[:, ::-1]).as_matrix()


def test_frd_euler_and_quaternion_rules_are_the_rotation_about_x() -> None:
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    rpy = np.column_stack(
        [rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)]
    )
    F = np.diag([1.0, -1.0, -1.0])
    np.testing.assert_allclose(_rot(rpy * FRD_TO_FLU), F @ _rot(rpy) @ F, atol=1e-12)
    q_xyzw = quaternion_from_euler(rpy)
    q_wxyz = np.column_stack([q_xyzw[:, 3], q_xyzw[:, :3]])
    flipped = flip_quaternion(q_wxyz)
    m = Rotation.from_quat(np.column_stack([flipped[:, 1:], flipped[:, 0]])).as_matrix()
    np.testing.assert_allclose(m, F @ _rot(rpy) @ F, atol=1e-12)


def _flight(n: int = 801, rate: float = 100.0) -> dict[str, np.ndarray]:
    """A synthetic flight in FLU / z-up, shape (n, 3) per role, and ``t`` shape (n,)."""
    t = np.arange(n) / rate
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7])
    return {
        "t": t,
        "body_rate": 0.5 * np.sin(np.outer(t, w)),
        "attitude": np.column_stack(
            [0.3 * np.sin(w[0] * t), 0.2 * np.cos(w[1] * t), wrap_angle(2.8 + 0.6 * t)]
        ),
        "position": np.column_stack([np.sin(t), np.cos(t), 1.0 + 0.1 * t]),
        "force_command": np.column_stack([0.5 * np.sin(t), 0.3 * np.cos(t), 19.6 + np.sin(3 * t)]),
        "torque_command": 0.2 * np.cos(np.outer(t, w)),
    }


def _write_rows(path: Path, header: list[str], columns: list[np.ndarray]) -> Path:
    data = np.column_stack(columns)
    body = "\n".join(",".join(repr(float(x)) for x in row) for row in data)
    path.write_text(",".join(header) + "\n" + body + "\n")
    return path


def test_frd_and_flu_csvs_of_one_flight_read_to_the_same_signals(tmp_path: Path) -> None:
    fl = _flight()
    # FLU: the wide contract CSV, no column map, default vehicle
    roles = ("body_rate", "attitude", "position", "force_command", "torque_command")
    raw = RawLog(
        path=Path("x"),
        format="synthetic",
        t0=0.0,
        series={r: RawSeries(fl["t"], fl[r]) for r in roles},
    )
    flu_path = tmp_path / "flu.csv"
    write_log(flu_path, raw)
    flu = read_vehicle_log(flu_path, default_vehicle())

    # FRD: another layout, time in us, attitude as a quaternion, thrust magnitude
    frd = {r: fl[r] * FRD_TO_FLU for r in roles}  # FRD body, NED world
    q = quaternion_from_euler(frd["attitude"])  # (x, y, z, w)
    assert (frd["force_command"][:, 2] < 0).all()  # thrust is -z in FRD
    header = ["stamp_us", "gx", "gy", "gz", "qw", "qx", "qy", "qz", "px", "py", "pz"]
    header += ["fx", "fy", "thrust", "mx", "my", "mz"]
    frd_path = _write_rows(
        tmp_path / "frd.csv",
        header,
        [
            fl["t"] * 1e6 + 5e6,
            *frd["body_rate"].T,
            q[:, 3],
            *q[:, :3].T,
            *frd["position"].T,
            frd["force_command"][:, 0],
            frd["force_command"][:, 1],
            -frd["force_command"][:, 2],  # logged as a positive magnitude
            *(frd["torque_command"] * 100.0).T,  # in N cm
        ],
    )
    vehicle = load_vehicle(
        write_vehicle(
            tmp_path / "frd.yaml",
            {
                "frame": "FRD",
                "columns": {
                    "time": {"column": "stamp_us", "scale": 1e-6},
                    "body_rate": {"x": "gx", "y": "gy", "z": "gz"},
                    "attitude": {"quaternion": {a: f"q{a}" for a in "wxyz"}},
                    "position": {"x": "px", "y": "py", "z": "pz"},
                    "force_command": {"x": "fx", "y": "fy", "z": {"column": "thrust", "scale": -1}},
                    "torque_command": {"x": "mx", "y": "my", "z": "mz", "scale": 0.01},
                },
            },
        )
    )
    got = read_vehicle_log(frd_path, vehicle)
    np.testing.assert_allclose(got.t, flu.t, atol=1e-9)
    assert got.valid.all() and flu.valid.all()
    assert set(got.signals) == set(flu.signals) == set(roles)
    for role in roles:
        a, b = got.signals[role], flu.signals[role]
        err = np.abs(wrap_angle(a - b)) if role == "attitude" else np.abs(a - b)
        assert err.max() < 1e-9, role

    # the FRD flight as a wide contract CSV and as a bag: frame applies to both
    frd_raw = RawLog(
        path=Path("x"),
        format="synthetic",
        t0=0.0,
        series={r: RawSeries(fl["t"], frd[r]) for r in roles},
    )
    frd_vehicle = load_vehicle(write_vehicle(tmp_path / "frd2.yaml", {"frame": "frd"}))
    for name in ("frd_wide.csv", "frd.mcap"):
        write_log(tmp_path / name, frd_raw)
        log = read_vehicle_log(tmp_path / name, frd_vehicle)
        for role in roles:
            a, b = log.signals[role], flu.signals[role]
            err = np.abs(wrap_angle(a - b)) if role == "attitude" else np.abs(a - b)
            assert err.max() < 1e-9, f"{name} {role}"


# --- irregular sampling, gaps --------------------------------------------------------


def _jittered_csv(path: Path, cut: tuple[float, float] | None = None) -> tuple[Path, np.ndarray]:
    """About 83 Hz with jitter (steps 10.5-23.6 ms, median 12 ms), time in us, 20 s."""
    rng = np.random.default_rng(7)
    steps = np.where(rng.random(2000) < 0.9, rng.uniform(0.0105, 0.0135, 2000), 0.0236)
    t = np.concatenate([[0.0], np.cumsum(steps)])
    t = t[t <= 20.0]
    if cut is not None:
        t = t[(t <= cut[0]) | (t >= cut[1])]
    f = 2 * np.pi * np.array([0.5, 0.8, 1.1])
    gyro = np.sin(np.outer(t, f))
    header = ["time_us", "gx", "gy", "gz", "r", "p", "y", "thr", "mx", "my", "mz"]
    _write_rows(
        path,
        header,
        [np.round(t * 1e6), *gyro.T, *(0.1 * gyro).T, 0.5 + 0.0 * t, *(0.2 * gyro).T],
    )
    return path, t


JITTER_MAP = {
    "time": {"column": "time_us", "scale": 1e-6},
    "body_rate": {"x": "gx", "y": "gy", "z": "gz"},
    "attitude": {"roll": "r", "pitch": "p", "yaw": "y"},
    "force_command": {"z": "thr"},
    "torque_command": {"x": "mx", "y": "my", "z": "mz"},
}


def test_jittered_83hz_csv_is_resampled_on_the_100hz_grid(tmp_path: Path) -> None:
    path, t = _jittered_csv(tmp_path / "jitter.csv")
    steps = np.diff(t)
    assert 0.0119 < np.median(steps) < 0.0125 and steps.max() < 0.0237  # ~83 Hz
    vehicle = load_vehicle(write_vehicle(tmp_path / "v.yaml", {"columns": JITTER_MAP}))
    log = read_vehicle_log(path, vehicle)
    assert log.rate == 100.0
    np.testing.assert_allclose(np.diff(log.t), 0.01, atol=1e-12)
    assert log.valid.all() and log.segments == [(0, log.t.size)]
    assert log.t[-1] == pytest.approx(np.floor((t[-1] - t[0]) * 100) / 100)
    # linear interpolation of a 1.1 Hz sine over steps <= 23.6 ms: error < w^2 h^2 / 8,
    # plus w x 0.5 us for the stamps rounded to whole us in the file
    truth = np.sin(np.outer(t[0] + log.t, 2 * np.pi * np.array([0.5, 0.8, 1.1])))
    w = 2 * np.pi * 1.1
    bound = w**2 * 0.0236**2 / 8 + w * 0.5e-6 + 1e-9
    assert np.abs(log.signals["body_rate"] - truth).max() < bound


def test_gaps_in_a_jittered_csv_split_segments(tmp_path: Path) -> None:
    path, _ = _jittered_csv(tmp_path / "gap.csv", cut=(7.0, 7.5))
    vehicle = load_vehicle(write_vehicle(tmp_path / "v.yaml", {"columns": JITTER_MAP}))
    log = read_vehicle_log(path, vehicle)
    assert len(log.segments) == 2
    (a0, b0), (a1, b1) = log.segments
    assert a0 == 0 and b1 == log.t.size
    assert 6.98 <= log.t[b0 - 1] <= 7.0 and 7.5 <= log.t[a1] <= 7.52
    assert any(re.match(r"gap of 0\.5\d s at t=\d\.\d\d s in CSV", n) for n in log.notes)
    # a window inside the second segment leaves one segment
    log = read_vehicle_log(path, vehicle, time_window=(8.0, 12.0))
    assert log.segments == [(800, 1200)]


# --- segmentation rule ---------------------------------------------------------------


def _thrust_log(
    tmp_path: Path, thrust: np.ndarray, rate: float = 100.0, roll_rate: np.ndarray | None = None
) -> Path:
    t = np.arange(thrust.size) / rate
    zeros = np.zeros_like(t)
    header = [
        "t",
        *[f"{r}_{a}" for r in ("body_rate", "force_command", "torque_command") for a in "xyz"],
    ]
    header += ["attitude_roll", "attitude_pitch", "attitude_yaw"]
    wx = zeros if roll_rate is None else roll_rate
    cols = [t, wx, zeros, zeros, zeros, zeros, thrust, zeros, zeros, zeros, zeros, zeros, zeros]
    return _write_rows(tmp_path / "thrust.csv", header, cols)


def test_ground_idle_and_spool_up_are_excluded_with_margin(tmp_path: Path) -> None:
    # idle 0-2 s, spool-up to 70 % of hover 2-4 s, hover 4-16 s, landing, idle 17-20 s
    t = np.arange(2001) / 100.0
    hover = 15.0
    thrust = np.interp(t, [0, 2, 2.5, 4, 4.5, 16, 17, 20], [0, 0, 0.7, 0.7, 1, 1, 0, 0]) * hover
    thrust += 0.01 * hover * np.sin(7 * t)
    path = _thrust_log(tmp_path, thrust)
    log = read_vehicle_log(path, default_vehicle())
    assert len(log.segments) == 1
    a, b = log.segments[0]
    # take-off: thrust first >= 0.9 x hover at t = 4.4 s; + 0.2 s margin
    first = t[np.argmax(thrust >= 0.9 * hover)]
    last = t[np.flatnonzero(thrust >= 0.9 * hover)[-1]]
    assert log.t[a] == pytest.approx(first + 0.2, abs=0.011)
    assert log.t[b - 1] == pytest.approx(last - 0.2, abs=0.011)
    note = next(n for n in log.notes if n.startswith("ground/idle: "))
    assert note.startswith(
        f"ground/idle: 0.00-{log.t[a - 1]:.2f} s, {log.t[b]:.2f}-20.00 s excluded"
    )
    assert "below 25% of the in-flight level" in note
    # its numbers carry their unit: the commands' own without the weight, N with it
    assert " [force unit] [90th percentile" in note and " [force unit] [median]" in note
    from omavctl.logs.segment import segment_flight

    raw = read_vehicle_log(path, default_vehicle(), trim=False)
    heavy = segment_flight(raw, weight=default_vehicle().weight)
    note = next(n for n in heavy.notes if n.startswith("ground/idle: "))
    assert " N [90th percentile" in note and " N [median]" in note
    # trim=False keeps everything
    assert read_vehicle_log(path, default_vehicle(), trim=False).valid.all()


def test_armed_minimum_throttle_on_the_ground_is_excluded(tmp_path: Path) -> None:
    # throttle 0..1: armed at 0.1 on the ground for 3 s (not below 25 % of the
    # level, ~0.4), quick take-off to hover at 0.35, then climbs and manoeuvres
    t = np.arange(1501) / 100.0
    thrust = (
        np.interp(t, [0, 3, 3.3, 15], [0.1, 0.1, 0.35, 0.35]) + 0.05 * (t > 6) * np.sin(3 * t) ** 2
    )
    assert 0.1 >= 0.25 * np.percentile(thrust, 90)  # not idle by rule 2: rule 3 finds it
    log = read_vehicle_log(_thrust_log(tmp_path, thrust), default_vehicle())
    hover = np.median(thrust)
    first = t[np.argmax(thrust >= 0.9 * hover)]
    assert log.segments == [(round((first + 0.2) * 100), t.size)]


def test_semicolon_separated_csv(tmp_path: Path) -> None:
    path = _small_csv(tmp_path / "semi.csv")
    path.write_text(path.read_text().replace(",", ";"))
    vehicle = load_vehicle(write_vehicle(tmp_path / "v.yaml", {"columns": SMALL_MAP}))
    assert read_vehicle_log(path, vehicle, trim=False).t.size == 20
    assert inspect_log(path).suggested_columns == {"time": {"column": "TIME_us", "scale": 1e-6}}


def test_idle_dip_mid_flight_is_excluded_but_normal_manoeuvres_are_not(tmp_path: Path) -> None:
    t = np.arange(1501) / 100.0
    thrust = 10.0 + 4.0 * np.sin(2 * t)  # 6..14: hard manoeuvres, never idle
    thrust[(t > 7.0) & (t < 7.5)] = 0.5  # motors cut for 0.5 s
    log = read_vehicle_log(_thrust_log(tmp_path, thrust), default_vehicle())
    assert len(log.segments) == 2
    (_, b0), (a1, _) = log.segments
    assert log.t[b0 - 1] == pytest.approx(7.0 - 0.2, abs=0.011)
    assert log.t[a1] == pytest.approx(7.5 + 0.2, abs=0.011)


def test_a_flight_that_ends_in_a_crash_keeps_its_flight(tmp_path: Path) -> None:
    # a simulated omav's log (a report12 draw that failed to fit): 40 N for 8 s, then
    # the controller's wound-up commands while it tumbles and falls, 200-845 N at 31-34
    # rad/s for 1.3 s, which set the in-flight level (285 N) and made the flight "idle"
    t = np.arange(931) / 100.0
    crash = t >= 8.0
    thrust = np.where(crash, np.interp(t, [8.0, 9.3], [200.0, 845.0]), 40.0 + np.sin(t))
    rate = np.where(crash, 32.0, 0.3 * np.sin(3 * t))
    log = read_vehicle_log(_thrust_log(tmp_path, thrust, roll_rate=rate), default_vehicle())
    assert log.valid.all() and not any(n.startswith("ground/idle") for n in log.notes)
    # without the rates the wound-up commands still set the level: the flight is idle
    log = read_vehicle_log(_thrust_log(tmp_path, thrust), default_vehicle())
    assert not log.valid[:800].any()


def test_a_struggling_vehicles_commands_do_not_make_its_hover_idle(tmp_path: Path) -> None:
    # a report12 draw's fit flight (strong rotor interference and a servo lag): 40 N to
    # hover for 5 s, then 150-200 N for 4 s while it no longer follows its reference, its
    # rates under 10 rad/s: level 174 N and the hover "idle" (0-5 s excluded); at most
    # twice the weight (4 kg: 39.2 N) the level keeps the hover
    t = np.arange(901) / 100.0
    thrust = np.where(t < 5.0, 40.0 + np.sin(t), 175.0 + 25.0 * np.sin(3 * t))
    path = _thrust_log(tmp_path, thrust)
    vehicle = default_vehicle()
    log = read_vehicle_log(path, vehicle, weight=vehicle.weight)
    assert vehicle.weight == pytest.approx(39.24, abs=0.01)
    assert log.valid.all()
    assert not read_vehicle_log(path, vehicle).valid[:480].any()


def test_zero_thrust_throughout_is_an_error(tmp_path: Path) -> None:
    path = _thrust_log(tmp_path, np.zeros(500))
    with pytest.raises(LogError) as err:
        read_vehicle_log(path, default_vehicle())
    assert str(err.value) == (
        f"{path}: no flight: the thrust command (|force_command|) is zero throughout"
    )


def test_log_without_force_command_is_not_trimmed(tmp_path: Path) -> None:
    path = _thrust_log(tmp_path, np.zeros(500))
    log = read_log(path, required=("body_rate",))
    del log.signals["force_command"]
    assert segment_flight(log).notes[-1] == "no force_command: flight segmentation skipped"


def test_simulated_omav_flight_loses_nothing(tmp_path: Path, vehicle, short_fig8) -> None:
    from conftest import fly

    result = fly(vehicle, short_fig8, {})
    path = tmp_path / "sim.csv"
    write_log(path, result.log)
    log = read_vehicle_log(path, vehicle, rate=vehicle.gains.rate_hz)
    assert log.valid.all() and log.segments == [(0, log.t.size)]
    assert not any(n.startswith("ground/idle") for n in log.notes)


# --- bad maps: one line naming the key / column and the file -------------------------


def _small_csv(path: Path, bad_cell: str | None = None) -> Path:
    lines = ["TIME_us,GX,GY,GZ,R,P,Y,T,MX,MY,MZ"]
    for i in range(20):
        gy = bad_cell if (bad_cell and i == 4) else f"{0.01 * i}"
        lines.append(f"{10000 * i},0.1,{gy},0.3,0,0,0,0.5,0,0,0")
    path.write_text("\n".join(lines) + "\n")
    return path


SMALL_MAP: dict[str, Any] = {
    "time": {"column": "TIME_us", "scale": 1e-6},
    "body_rate": {"x": "GX", "y": "GY", "z": "GZ"},
    "attitude": {"roll": "R", "pitch": "P", "yaw": "Y"},
    "force_command": {"z": "T"},
    "torque_command": {"x": "MX", "y": "MY", "z": "MZ"},
}


@pytest.mark.parametrize(
    ("columns", "message"),
    [
        (
            {**SMALL_MAP, "gyro": {"x": "GX"}},
            "unknown key 'columns.gyro': expected a role (time, body_rate, attitude, position, "
            "velocity, force_command, torque_command, desired_acceleration, "
            "desired_linear_acceleration, reference_position, reference_attitude, tilt, rotor, "
            "motor_command, battery_voltage, specific_force) "
            "or a wide-CSV column such as body_rate_x",
        ),
        (
            {**SMALL_MAP, "body_rate": {"x": "GX", "y": "GY", "w": "GZ"}},
            "unknown key 'columns.body_rate.w': body_rate axes are x, y, z",
        ),
        (
            {**SMALL_MAP, "attitude": {"roll": "R", "pitch": "P", "heading": "Y"}},
            "unknown key 'columns.attitude.heading': attitude axes are roll, pitch, yaw "
            "(or a quaternion w, x, y, z)",
        ),
        (
            {**SMALL_MAP, "body_rate": {"x": "GX", "y": "GY"}},
            "key 'columns.body_rate' is missing axis z (body_rate needs x, y, z)",
        ),
        (
            {**SMALL_MAP, "torque_command": {"x": "MX", "scale": "big"}},
            "key 'columns.torque_command.scale' must be a number",
        ),
        (
            {**SMALL_MAP, "attitude": {"quaternion": {"w": "R", "x": "P", "y": "Y"}}},
            "key 'columns.attitude.quaternion' is missing component z",
        ),
        (
            {k: v for k, v in SMALL_MAP.items() if k != "time"},
            "key 'columns.time' is missing: the column map must say which column is time",
        ),
        (
            {**SMALL_MAP, "body_rate_x": "GX"},
            "key 'columns.body_rate_x' maps body_rate_x again (also columns.body_rate.x)",
        ),
    ],
    ids=["role", "axis", "euler-axis", "missing-axis", "scale", "quaternion", "time", "twice"],
)
def test_bad_map_is_one_line_naming_key_and_vehicle_file(
    tmp_path: Path, columns: dict[str, Any], message: str
) -> None:
    path = write_vehicle(tmp_path / "bad.yaml", {"columns": columns})
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert str(err.value) == f"{path}: {message}"


def test_missing_and_non_numeric_columns_name_column_and_file(tmp_path: Path) -> None:
    csv_path = _small_csv(tmp_path / "log.csv")
    good = load_vehicle(write_vehicle(tmp_path / "ok.yaml", {"columns": SMALL_MAP}))
    assert read_vehicle_log(csv_path, good, trim=False).t.size == 20

    cases = {
        "GYRO_NOPE": "missing column 'GYRO_NOPE' (mapped to body_rate.y)",
        "GYY": "missing column 'GYY' (mapped to body_rate.y); similar columns in the file: 'GY'",
    }
    for column, message in cases.items():
        columns = {**SMALL_MAP, "body_rate": {"x": "GX", "y": column, "z": "GZ"}}
        vehicle = load_vehicle(write_vehicle(tmp_path / "v.yaml", {"columns": columns}))
        with pytest.raises(LogError) as err:
            read_vehicle_log(csv_path, vehicle)
        assert str(err.value) == f"{csv_path}: {message}"

    # a time column named otherwise: the file's time columns, a plain one first; a
    # quaternion component named by its key in the vehicle file
    for columns, message in (
        (
            {**SMALL_MAP, "time": {"column": "stamp_ns", "scale": 1e-9}},
            "missing column 'stamp_ns' (mapped to time); similar columns in the file: 'TIME_us'",
        ),
        (
            {**SMALL_MAP, "attitude": {"quaternion": {"w": "R", "x": "P", "y": "Y", "z": "QZ"}}},
            "missing column 'QZ' (mapped to attitude.quaternion.z)",
        ),
    ):
        vehicle = load_vehicle(write_vehicle(tmp_path / "v.yaml", {"columns": columns}))
        with pytest.raises(LogError) as err:
            read_vehicle_log(csv_path, vehicle)
        assert str(err.value) == f"{csv_path}: {message}"

    bad = _small_csv(tmp_path / "bad.csv", bad_cell="fast")
    with pytest.raises(LogError) as err:
        read_vehicle_log(bad, good)
    assert str(err.value) == f"{bad}: non-numeric value 'fast' in column 'GY' at row 5 (line 6)"

    # a required role the map leaves out
    columns = {k: v for k, v in SMALL_MAP.items() if k != "attitude"}
    vehicle = load_vehicle(write_vehicle(tmp_path / "v.yaml", {"columns": columns}))
    with pytest.raises(LogError) as err:
        read_vehicle_log(csv_path, vehicle)
    assert str(err.value) == (
        f"{csv_path}: the column map has no entry for attitude (columns.attitude)"
    )

    # through the CLI: one line, exit status 2
    vehicle_file = write_vehicle(
        tmp_path / "v2.yaml",
        {"columns": {**SMALL_MAP, "body_rate": {"x": "GX", "y": "GYRO_NOPE", "z": "GZ"}}},
    )
    result = runner.invoke(app, ["inspect", str(csv_path), "--vehicle", str(vehicle_file)])
    assert result.exit_code == 2
    assert result.output.strip() == (
        f"error: {csv_path}: missing column 'GYRO_NOPE' (mapped to body_rate.y)"
    )


def test_vehicle_frame_and_columns_keys(tmp_path: Path) -> None:
    veh = default_vehicle()
    assert veh.columns == {} and veh.frame == "FLU"
    for value, shown in (("NED", "'NED'"), (3, "3")):
        path = write_vehicle(tmp_path / "f.yaml", {"frame": value})
        with pytest.raises(ConfigError) as err:
            load_vehicle(path)
        assert str(err.value) == f"{path}: key 'frame' must be FLU or FRD, got {shown}"
    path = write_vehicle(tmp_path / "c.yaml", {"columns": ["a", "b"]})
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert str(err.value) == f"{path}: key 'columns' must be a mapping of roles to columns"
    # the flat spelling still works in a vehicle file, mixed with role-based keys
    flat = {"t": {"column": "TIME_us", "scale": 1e-6}, "body_rate_x": "GX", "body_rate_y": "GY"}
    flat |= {"body_rate_z": "GZ"}
    mixed = {k: v for k, v in SMALL_MAP.items() if k not in ("time", "body_rate")} | flat
    vehicle = load_vehicle(write_vehicle(tmp_path / "m.yaml", {"columns": mixed}))
    log = read_vehicle_log(_small_csv(tmp_path / "log.csv"), vehicle, trim=False)
    np.testing.assert_allclose(log.signals["body_rate"][:, 0], 0.1)
    # model artifacts store vehicle trees written before these keys existed
    from omavctl.vehicle import _build

    tree = dict(veh.tree)
    del tree["columns"], tree["frame"]
    old = _build(tree, None, "old artifact")
    assert old.columns == {} and old.frame == "FLU"


def test_flatten_composes_scales_and_zeroes_missing_command_axes() -> None:
    flat = flatten_column_map(
        {
            "time": "t_s",
            "torque_command": {
                "x": "a",
                "y": {"column": "b", "scale": 2.0, "offset": 1.0},
                "scale": 0.5,
                "offset": 0.1,
            },
        }
    )
    assert flat == {
        "t": {"column": "t_s", "scale": 1.0, "offset": 0.0},
        "torque_command_x": {"column": "a", "scale": 0.5, "offset": 0.1},
        "torque_command_y": {"column": "b", "scale": 1.0, "offset": 0.6},
        "torque_command_z": {"value": 0.0},
    }


def test_a_csv_cut_in_its_last_row_is_named_truncated_and_the_row_dropped(tmp_path: Path) -> None:
    """A log copied while it was written ends mid-row: the mapped reader names it as a
    truncation and drops the row, instead of counting it among rows without time."""
    from omavctl.logs.columnmap import read_mapped_csv

    t = np.arange(50) * 0.01
    header = ["time", "gx", "gy", "gz"]
    full = _write_rows(tmp_path / "full.csv", header, [t, np.sin(t), np.cos(t), t])
    text = full.read_text()
    cut = tmp_path / "cut.csv"
    cut.write_text(text[: text.rindex(",", 0, len(text) - 1) - 3])  # inside the last row
    columns = {"time": {"column": "time"}, "body_rate": {"x": "gx", "y": "gy", "z": "gz"}}
    whole, part = read_mapped_csv(full, columns), read_mapped_csv(cut, columns)
    assert part.raw.series["body_rate"].values.shape == (49, 3)
    np.testing.assert_array_equal(
        part.raw.series["body_rate"].values, whole.raw.series["body_rate"].values[:49]
    )
    assert part.raw.notes == [
        "the file ends in the middle of its last row (line 51: 3 of 4 cells): truncated? "
        "That row is dropped"
    ]
    assert whole.raw.notes == []
    # inspect of the same file, before any column map, says so too (it said nothing)
    result = runner.invoke(app, ["inspect", str(cut), "--json"])
    assert result.exit_code == 0, result.output
    assert part.raw.notes[0] in json.loads(result.stdout)["notes"]


@pytest.mark.parametrize(("acc_z", "frame"), [(9.78, "FLU"), (-9.81, "FRD"), (0.3, None)])
def test_the_suggested_frame_comes_from_the_accelerometers_sign_of_g(
    tmp_path: Path, acc_z: float, frame: str | None
) -> None:
    t = np.arange(200) * 0.01
    header = ["time_s", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z", "thrust"]
    cols = [t, *(0.1 * np.sin(t + k) for k in range(3)), 0 * t, 0 * t, acc_z + 0 * t]
    path = _write_rows(tmp_path / "log.csv", header, [*cols, 0.4 + 0.01 * np.sin(t)])
    ins = inspect_log(path)
    assert ins.suggestion is not None and ins.suggested_columns is not None
    force = ins.suggested_columns["force_command"]
    if frame is None:
        assert "frame: FLU  # not known from names" in ins.suggestion
        assert force == {"z": "thrust"}
    else:
        up = "up" if frame == "FLU" else "down"
        assert f"frame: {frame}  # acc_z reads {acc_z:+.1f} m/s^2 (median): z points {up}" in (
            ins.suggestion
        )
        assert force == ({"z": "thrust", "scale": -1.0} if frame == "FRD" else {"z": "thrust"})


def test_inspect_names_columns_that_look_like_a_missing_role(tmp_path: Path) -> None:
    """A contract CSV with gyro_x/y/z for the body rate: inspect said only "columns not in
    the contract ignored: gyro_x, gyro_y, gyro_z" (a new user)."""
    t = np.arange(300) / 100.0
    cols = {
        "t": t,
        "gyro_x": 0.1 * np.sin(t), "gyro_y": 0.1 * np.cos(t), "gyro_z": 0 * t,
        **{f"attitude_{a}": 0 * t for a in ("roll", "pitch", "yaw")},
        **{f"force_command_{a}": (30.0 if a == "z" else 0.0) + 0 * t for a in "xyz"},
        **{f"torque_command_{a}": 0.01 + 0 * t for a in "xyz"},
    }  # fmt: skip
    path = tmp_path / "g.csv"
    path.write_text(
        ",".join(cols) + "\n"
        + "\n".join(",".join(f"{v[i]:.6g}" for v in cols.values()) for i in range(t.size))
        + "\n"
    )  # fmt: skip
    notes = inspect_log(path).notes
    assert (
        "body_rate is missing, but gyro_x, gyro_y, gyro_z look like it: rename them "
        "body_rate_x, body_rate_y, body_rate_z (in the contract's units), or read the log "
        "with a vehicle file's column map (docs/logs.md)"
    ) in notes


def test_inspect_json_carries_the_whole_suggested_vehicle_snippet(tmp_path: Path) -> None:
    """A script that built its vehicle YAML from inspect --json's suggested_columns alone
    fitted a PX4 log in the wrong frame and units without a word (a new user): the JSON
    now holds the snippet the terminal prints, frame and preset lines included."""
    import yaml

    from omavctl.report.summary import inspect_json

    ins = inspect_log(_small_csv(tmp_path / "small.csv"))
    out = inspect_json(ins)
    assert out["suggestion_yaml"] == ins.suggestion
    snippet = yaml.safe_load(out["suggestion_yaml"])
    assert snippet["columns"] == out["suggested_columns"] and "frame" in snippet
