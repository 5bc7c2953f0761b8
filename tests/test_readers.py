"""Readers of motor-level logs: gzip CSV, Crazyflie SD-card binary (cfusdlog),
Betaflight blackbox CSV, PX4 ULog actuator outputs; their column inventory."""

from __future__ import annotations

import gzip
import json
import math
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from omavctl.base.errors import LogError
from omavctl.logs import read_raw, write_log
from omavctl.logs.betaflight import betaflight_table
from omavctl.logs.cfusdlog import cfusdlog_table, read_cfusdlog
from omavctl.logs.inventory import column_inventory
from omavctl.logs.read import detect_format

try:  # tests/ as a package or as a rootdir on sys.path
    from .test_logs import make_raw
    from .test_logs_bad_input import assert_log_error
    from .ulog_writer import write_ulog
except ImportError:
    from test_logs import make_raw
    from test_logs_bad_input import assert_log_error
    from ulog_writer import write_ulog

REAL = Path(__file__).parents[2] / "shared/data/real"
CF = REAL / "arpl_crazyflie"
BF = REAL / "betaflight_cs110"
needs_real = pytest.mark.skipif(
    not (CF / "log15").exists() or not (BF / "better_tune.csv.gz").exists(),
    reason=f"shared real logs not available at {REAL}",
)


# ---------------------------------------------------------------- cfusdlog
def write_cfusdlog(path: Path, version: int, events: dict, records: list) -> bytes:
    """A cfusdlog file: ``events`` id -> (name, [(var, struct code)]), ``records``
    [(id, stamp, values)] in file order (stamp in ms for version 1, us for 2)."""
    out = bytearray(struct.pack("<BHH", 0xBC, version, len(events)))
    for event_id, (name, variables) in events.items():
        out += struct.pack("<H", event_id) + name.encode() + b"\0"
        out += struct.pack("<H", len(variables))
        out += b"".join(f"{v}({c})".encode() + b"\0" for v, c in variables)
    for event_id, stamp, values in records:
        codes = "".join(c for _, c in events[event_id][1])
        out += struct.pack("<H" + ("I" if version == 1 else "Q"), event_id, stamp)
        out += struct.pack("<" + codes, *values)
    out += struct.pack("<I", zlib.crc32(bytes(out)))
    path.write_bytes(bytes(out))
    return bytes(out)


EVENTS = {
    0xFFFF: ("fixedFrequency", [("gyro.x", "f"), ("motor.m1", "I")]),
    7: ("estPose", [("x", "f"), ("y", "f"), ("flag", "B")]),
}


def test_cfusdlog_mixed_events_both_versions(tmp_path: Path) -> None:
    records = [
        (0xFFFF, 1000, (1.5, 100)),
        (7, 1500, (0.25, -0.5, 1)),
        (0xFFFF, 2000, (-2.0, 65535)),
        (0xFFFF, 3000, (0.0, 7)),
    ]
    for version, to_ms in ((1, 1.0), (2, 1e-3)):
        path = tmp_path / f"log_v{version}"
        write_cfusdlog(path, version, EVENTS, records)
        log = read_cfusdlog(path)
        assert log.version == version
        fixed, pose = log.events
        assert fixed.name == "fixedFrequency" and pose.name == "estPose"
        np.testing.assert_array_equal(fixed.timestamp, np.array([1000, 2000, 3000]) * to_ms)
        np.testing.assert_array_equal(fixed.columns["gyro.x"], [1.5, -2.0, 0.0])
        np.testing.assert_array_equal(fixed.columns["motor.m1"], [100, 65535, 7])
        np.testing.assert_array_equal(pose.columns["y"], [-0.5])
        assert pose.columns["flag"].dtype == np.uint8
        assert detect_format(path) == "cfusdlog"
    table = cfusdlog_table(tmp_path / "log_v2")
    assert table.units["gyro.x"] == "deg/s" and table.units["x"] == "as logged"
    assert [g.name for g in table.groups] == ["fixedFrequency", "estPose"]


def test_cfusdlog_through_a_column_map(tmp_path: Path) -> None:
    records = [(0xFFFF, 1000 * k, (10.0 * k, 40000)) for k in range(1, 6)]
    path = tmp_path / "flight"
    write_cfusdlog(path, 2, {0xFFFF: EVENTS[0xFFFF]}, records)
    columns = {
        "time": {"column": "timestamp", "scale": 1e-3},
        "body_rate": {"x": "gyro.x", "y": "gyro.x", "z": "gyro.x", "scale": math.pi / 180},
        "force_command": {"z": "motor.m1", "scale": 1 / 65535},
    }
    raw = read_raw(path, columns=columns)
    assert raw.format == "cfusdlog"
    np.testing.assert_allclose(raw.series["body_rate"].stamps, [0, 1e-3, 2e-3, 3e-3, 4e-3])
    np.testing.assert_allclose(
        raw.series["body_rate"].values[:, 0], np.radians([10, 20, 30, 40, 50])
    )
    np.testing.assert_allclose(raw.series["force_command"].values[:, 2], 40000 / 65535)


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda b: b[:-100], "CRC-32 at its end does not match .*truncated"),
        (lambda b: b[:60] + bytes([b[60] ^ 0x40]) + b[61:], "CRC-32 .* does not match"),
        (lambda b: b[:3], "ends inside its header"),
        (lambda b: b"\xbc\x09\x00" + b[3:], "does not start with the cfusdlog header"),
    ],
)
def test_cfusdlog_damage_is_one_line(tmp_path: Path, damage, message: str) -> None:
    good = write_cfusdlog(tmp_path / "good", 2, EVENTS, [(0xFFFF, 1, (1.0, 2)), (7, 2, (1, 2, 3))])
    path = tmp_path / "bad"
    path.write_bytes(damage(good))
    assert_log_error(path, message, read_cfusdlog)


def test_cfusdlog_records_that_do_not_parse(tmp_path: Path) -> None:
    """A CRC that matches over records that do not parse (written by another tool)."""
    events = {1: ("e", [("a", "f")])}
    data = bytearray(write_cfusdlog(tmp_path / "x", 2, events, [(1, 5, (1.0,))])[:-4])
    for extra, message in ((b"\x09\x00" + bytes(12), "unknown event id 9 at byte"),
                           (b"\x01\x00" + bytes(5), "last record is cut short")):  # fmt: skip
        body = bytes(data) + extra
        path = tmp_path / "odd"
        path.write_bytes(body + struct.pack("<I", zlib.crc32(body)))
        assert_log_error(path, message, read_cfusdlog)


@needs_real
def test_cfusdlog_log15_equals_its_decoded_csv() -> None:
    table = cfusdlog_table(CF / "log15")
    with gzip.open(CF / "log15.csv.gz", "rt") as fh:
        names = fh.readline().strip().split(",")
        ref = np.loadtxt(fh, delimiter=",")
    (group,) = table.groups
    assert [table.time_column, *group.columns] == names
    assert ref.shape == (62774, 11)
    np.testing.assert_array_equal(group.stamps, ref[:, 0])
    for j, name in enumerate(names[1:], start=1):
        np.testing.assert_array_equal(group.columns[name], ref[:, j], err_msg=name)


@needs_real
def test_truncated_crazyflie_log_from_the_cli(tmp_path: Path) -> None:
    bad = tmp_path / "log15"
    bad.write_bytes((CF / "log15").read_bytes()[:200_000])
    out = subprocess.run(
        [sys.executable, "-m", "omavctl", "inspect", str(bad)], capture_output=True, text=True
    )
    assert out.returncode == 2
    assert out.stderr == (
        f"error: {bad}: not a readable Crazyflie SD-card log: the CRC-32 at its end does not "
        "match its contents (corrupt or truncated)\n"
    )


# ---------------------------------------------------------------- gzip CSV
def test_gzip_csv_reads_as_the_plain_csv(tmp_path: Path) -> None:
    plain = tmp_path / "log.csv"
    write_log(plain, make_raw(duration=1.0))
    packed = tmp_path / "log.csv.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    misnamed = tmp_path / "packed.csv"  # gzip content under a plain name: found by magic
    misnamed.write_bytes(packed.read_bytes())
    want = read_raw(plain)
    for path in (packed, misnamed):
        assert detect_format(path) == "csv"
        got = read_raw(path)
        assert got.series.keys() == want.series.keys()
        for role, s in want.series.items():
            np.testing.assert_array_equal(got.series[role].values, s.values)


def test_broken_gzip_csv_is_one_line(tmp_path: Path) -> None:
    plain = tmp_path / "log.csv"
    write_log(plain, make_raw(duration=1.0))
    data = gzip.compress(plain.read_bytes())
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(data[: len(data) // 2])
    assert_log_error(cut, "gzip stream ends before its end marker \\(truncated\\?\\)", read_raw)
    crc = tmp_path / "crc.csv.gz"
    crc.write_bytes(data[:-8] + bytes([data[-8] ^ 1]) + data[-7:])
    assert_log_error(crc, "gzip data is corrupt \\(CRC check failed", read_raw)
    binary = tmp_path / "bin.csv.gz"
    binary.write_bytes(gzip.compress(b"t,a\n\xff\xfe\x00\n"))
    assert_log_error(binary, "not a CSV file: it is not UTF-8 text", read_raw)
    empty = tmp_path / "empty.csv.gz"
    empty.write_bytes(b"")
    assert_log_error(empty, "not a CSV file: the file is empty", read_raw)


# ---------------------------------------------------------------- Betaflight
DECODE_CSV = (
    "loopIteration, time (us), gyroADC[0] (deg/s), gyroADC[1] (deg/s), gyroADC[2] (deg/s), "
    "vbatLatest (V), motor[0], motor[1], motor[2], motor[3], flightModeFlags (flags)\n"
    "0, 1000000, 90, -180, 45, 12.6, 1000, 1100, 1200, 1300, ANGLE_MODE\n"
    "1, 1000500, 0, 0, 0, 12.5, 1000, 1000, 1000, 1000, \n"
    "2, 1001000, -90, 180, 0, 12.4, 1000, 1000, 1000, 1000, ANGLE_MODE|ARM\n"
)
EXPLORER_CSV = (
    '"Product","Blackbox flight data recorder by Nicholas Sherlock"\n'
    '"firmwareType",3\n"firmwareVersion","4.2.0"\n'
    '"looptime",125\n"motorOutput","48,2047"\n"vbatscale",110\n"gyro_scale","0x3f800000"\n'
    '"loopIteration","time","gyroADC[0]","gyroADC[1]","gyroADC[2]","vbatLatest","motor[0]"\n'
    "10,2000000,57.29577951308232,0,-57.29577951308232,1650,48\n"
    "11,2000125,0,0,0,1640,NaN\n"
)


def test_betaflight_blackbox_decode_csv(tmp_path: Path) -> None:
    path = tmp_path / "LOG00001.01.csv"
    path.write_text(DECODE_CSV)
    (tmp_path / "LOG00001.01.headers.txt").write_text(
        "H Firmware revision:Betaflight 3.1.5 (4646f9d) OMNIBUSF4\nH looptime:125\n"
        "H motorOutput:138,2047\nH vbatscale:110\nH vbatref:125\n"
    )
    assert detect_format(path) == "betaflight"
    t = betaflight_table(path)
    (g,) = t.groups
    np.testing.assert_allclose(g.stamps, [1.0, 1.0005, 1.001])
    np.testing.assert_allclose(g.columns["gyroADC[0]"], np.radians([90, 0, -90]))
    np.testing.assert_allclose(g.columns["gyroADC[1]"], np.radians([-180, 0, 180]))
    np.testing.assert_allclose(g.columns["vbatLatest"], [12.6, 12.5, 12.4])  # (V): as written
    np.testing.assert_array_equal(g.columns["motor[3]"], [1300, 1000, 1000])
    assert "flightModeFlags" not in g.columns
    assert t.notes == ["non-numeric columns skipped: flightModeFlags"]
    assert t.units["gyroADC[2]"] == "rad/s FLU (from deg/s)"
    assert t.units["motor[0]"] == "motor command (motorOutput 138-2047)"
    assert t.meta["looptime_us"] == 125 and t.meta["motor_output"] == [138, 2047]
    assert t.meta["vbatscale"] == 110 and t.meta["vbatref"] == 125
    # the same log copied without its sidecar: the defaults are said, not only used
    (tmp_path / "LOG00001.01.headers.txt").unlink()
    bare = betaflight_table(path)
    assert bare.notes[0] == (
        "no blackbox header (no lines above the field names and no LOG00001.01.headers.txt "
        "beside the log): the gyro scale, the battery voltage's unit and the motor output "
        "range are the defaults"
    )


def test_betaflight_explorer_csv_gzip(tmp_path: Path) -> None:
    path = tmp_path / "export.csv.gz"
    path.write_bytes(gzip.compress(EXPLORER_CSV.encode()))
    assert detect_format(path) == "betaflight"
    t = betaflight_table(path)
    (g,) = t.groups
    np.testing.assert_allclose(g.stamps, [2.0, 2.000125])
    np.testing.assert_allclose(g.columns["gyroADC[0]"], [1.0, 0.0])
    np.testing.assert_allclose(g.columns["gyroADC[2]"], [-1.0, 0.0])
    np.testing.assert_allclose(g.columns["vbatLatest"], [16.5, 16.4])  # 0.01 V from 4.x on
    np.testing.assert_array_equal(g.columns["motor[0]"], [48, np.nan])
    assert t.meta["header"]["firmwareVersion"] == "4.2.0"
    assert t.meta["motor_output"] == [48, 2047] and t.meta["gyro_scale"] == 1.0
    raw = read_raw(path, columns={"time": "time", "body_rate": {
        "x": "gyroADC[0]", "y": "gyroADC[1]", "z": "gyroADC[2]"}})  # fmt: skip
    assert raw.format == "betaflight"
    np.testing.assert_allclose(raw.series["body_rate"].values[0], [1.0, 0.0, -1.0])


def test_betaflight_bad_rows_name_the_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(DECODE_CSV.replace("1, 1000500, 0, 0,", "1, 1000500, 0, fast,"))
    assert_log_error(path, "non-numeric value 'fast' in column 'gyroADC\\[1\\]' at line 3$",
                     betaflight_table)  # fmt: skip
    path.write_text(DECODE_CSV.replace("12.5, 1000, 1000, 1000, 1000, \n", "12.5\n"))
    assert_log_error(path, "line 3 has 6 cells, the field names 11", betaflight_table)


@needs_real
def test_betaflight_shared_log_header_and_frame() -> None:
    """The sidecar header is read, and the data bear out the FLU signs: each motor
    difference (left-right, rear-front, clockwise-counter-clockwise props-in) leads the
    matching gyro axis's acceleration."""
    from scipy.signal import butter, filtfilt

    t = betaflight_table(BF / "example_smooth_tune.csv.gz")
    assert t.meta["looptime_us"] == 125 and t.meta["motor_output"] == [138, 2047]
    assert t.meta["vbat_pid_compensation"] == 1
    (g,) = t.groups
    rate = 1 / np.median(np.diff(g.stamps))
    assert 1900 < rate < 2050
    b, a = butter(2, 30 / (rate / 2))
    gyro = filtfilt(b, a, np.column_stack([g.columns[f"gyroADC[{i}]"] for i in range(3)]), axis=0)
    m = filtfilt(b, a, np.column_stack([g.columns[f"motor[{i}]"] for i in range(4)]), axis=0)
    accel = np.gradient(gyro, g.stamps, axis=0)
    drive = np.column_stack([m[:, 2] + m[:, 3] - m[:, 0] - m[:, 1],  # left - right: roll
                             m[:, 0] + m[:, 2] - m[:, 1] - m[:, 3],  # rear - front: pitch
                             m[:, 0] + m[:, 3] - m[:, 1] - m[:, 2]])  # fmt: skip
    lag = int(0.01 * rate)  # 10 ms: motor and filter delay
    flying = (m.mean(axis=1) > 300)[:-lag]
    for axis in range(3):
        r = np.corrcoef(drive[:-lag][flying, axis], accel[lag:][flying, axis])[0, 1]
        assert r > 0.25, (axis, r)


# ---------------------------------------------------------------- ULog actuators
def test_ulog_actuator_outputs_motors_and_battery(tmp_path: Path) -> None:
    n = 50
    st = np.arange(n) * 4000.0 + 1e6
    outputs = np.column_stack([1100 + 10 * np.arange(n) + 100 * k for k in range(16)])
    motors = np.column_stack([np.linspace(0, 1, n)] * 4 + [np.full(n, np.nan)] * 8)
    path = tmp_path / "motors.ulg"
    write_ulog(path, {
        "actuator_outputs": (st, {"noutputs": np.full(n, 4.0), "output": outputs}),
        "actuator_motors": (st + 1000, {"control": motors}),
        "battery_status": (st[::10], {"voltage_v": np.linspace(16.8, 15.9, 5)}),
    })  # fmt: skip
    columns = {
        "time": {"column": "timestamp", "scale": 1e-6},
        "torque_command": {f"{a}": f"actuator_outputs.output[{i}]" for i, a in enumerate("xyz")},
        "force_command": {"z": "actuator_motors.control[3]"},
    }
    raw = read_raw(path, columns=columns)
    np.testing.assert_allclose(raw.series["torque_command"].values[:, 1], outputs[:, 1])
    np.testing.assert_allclose(raw.series["force_command"].values[:, 2], motors[:, 3], atol=1e-7)
    inv = column_inventory(path)
    volt = inv.find("battery_status.voltage_v")
    assert volt.unit == "V" and volt.count == 5 and volt.rate == pytest.approx(25.0)
    assert volt.lo == pytest.approx(15.9) and volt.hi == pytest.approx(16.8)
    out0 = inv.find("actuator_outputs.output[0]")
    assert out0.unit.startswith("output value, PWM us") and out0.rate == pytest.approx(250.0)
    assert inv.find("actuator_motors.control[0]").unit.startswith("normalised motor thrust")
    assert inv.find("actuator_motors.control[7]").count == 0  # disabled: NaN throughout
    assert inv.time_column == "timestamp" and inv.time_scale == 1e-6


@needs_real
def test_inspect_json_lists_units_and_rates_of_real_logs() -> None:
    out = subprocess.run([sys.executable, "-m", "omavctl", "inspect", str(CF / "log16"), "--json"],
                         capture_output=True, text=True, check=True)  # fmt: skip
    got = json.loads(out.stdout)
    assert got["format"] == "cfusdlog"
    assert got["column_units"]["motor.m4"] == "PWM 0-65535"
    assert got["column_rates"]["gyro.z"] == pytest.approx(1011, abs=15)
    assert got["suggested_columns"]["time"] == {"column": "timestamp", "scale": 0.001}
    assert got["header_values"] == {"version": 2, "events": ["fixedFrequency"]}
    ulog = column_inventory(REAL / "pyulog_bench/sample.ulg")
    out0 = ulog.find("actuator_outputs.output[0]")
    assert (out0.lo, out0.hi) == (900.0, 900.0)  # disarmed: motors off throughout
    assert 15 < out0.rate < 25


def test_unknown_file_without_suffix(tmp_path: Path) -> None:
    path = tmp_path / "notes"
    path.write_text("hello\n")
    assert_log_error(path, "unknown log format \\(no suffix\\)", detect_format)


def test_inspect_with_a_column_map_reads_the_roles(tmp_path: Path) -> None:
    from omavctl.logs import inspect_log

    path = tmp_path / "cf"
    write_cfusdlog(
        path, 2, {0xFFFF: EVENTS[0xFFFF]}, [(0xFFFF, 1000 * k, (1.0, 9)) for k in range(5)]
    )
    rate = {"x": "gyro.x", "y": "gyro.x", "z": "gyro.x"}
    ins = inspect_log(
        path, columns={"time": {"column": "timestamp", "scale": 1e-3}, "body_rate": rate}
    )
    assert ins.format == "cfusdlog"
    assert ins.roles_found == {"body_rate": "columns gyro.x, gyro.x, gyro.x"}
    assert ins.duration == pytest.approx(4e-3)
    assert ins.column_ranges["body_rate_x"] == (1.0, 1.0)


def test_betaflight_without_field_names_or_time(tmp_path: Path) -> None:
    path = tmp_path / "x.csv"
    path.write_text('"Product","Blackbox flight data recorder by Nicholas Sherlock"\n"a","b"\n')
    assert detect_format(path) == "betaflight"  # the header says so
    assert_log_error(path, "no row of field names with 'time' and 'loopIteration'",
                     betaflight_table)  # fmt: skip
    path.write_text("loopIteration,time,gyroADC[0]\n1,,3\n2,,4\n")
    assert_log_error(path, "^.*: column 'time' holds no numbers$", betaflight_table)
    path.write_text("loopIteration,time,gyroADC[0]\n")
    assert_log_error(path, "no data rows below the field names", betaflight_table)
    assert_log_error(path, "a Betaflight blackbox CSV is read through a column map", read_raw)


def test_inventory_units_of_other_logs(tmp_path: Path) -> None:
    from omavctl.logs.ulog import ulog_unit

    assert ulog_unit("actuator_outputs_1.output[3]") == ulog_unit("actuator_outputs.output[0]")
    assert ulog_unit("battery_status_2.voltage_v") == "V"
    assert ulog_unit("vehicle_gps_position.lat") == "as logged"
    csv = tmp_path / "other.csv"
    csv.write_text("time_us,GyroX,mode\n0,0.5,a\n10000,0.25,b\n20000,0.0,c\n")
    inv = column_inventory(csv)
    assert inv.format == "csv" and (inv.time_column, inv.time_scale) == ("time_us", 1e-6)
    gyro = inv.find("GyroX")
    assert (gyro.count, gyro.unit, gyro.lo, gyro.hi) == (3, "as logged", 0.0, 0.5)
    assert gyro.rate == pytest.approx(100.0)
    assert inv.notes == ["non-numeric columns skipped: mode"]
    bag = tmp_path / "log.mcap"
    write_log(bag, make_raw(duration=0.5))
    assert_log_error(bag, "holds contract topics, not mapped columns", column_inventory)


def test_gzip_csv_errors_are_those_of_the_plain_csv(tmp_path: Path) -> None:
    plain = tmp_path / "log.csv"
    write_log(plain, make_raw(duration=1.0))
    lines = plain.read_text().splitlines()
    cells = lines[5].split(",")
    cells[2] = "fast"
    lines[5] = ",".join(cells)
    plain.write_text("\n".join(lines) + "\n")
    packed = tmp_path / "log.csv.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    messages = []
    for path in (plain, packed):
        with pytest.raises(LogError) as info:
            read_raw(path)
        messages.append(info.value.message)
    assert messages[0] == messages[1]
    assert (
        messages[0].startswith("non-numeric value 'fast' in column") and "(line 6)" in messages[0]
    )


def test_inspect_suggests_a_map_for_a_gzip_csv_of_another_layout(tmp_path: Path) -> None:
    from omavctl.logs import inspect_log

    rows = ["timestamp,gyro.x,gyro.y,gyro.z,motor.m1"]
    rows += [f"{1000 + k:.3f},{k * 10.0},0,-5,{30000 + k}" for k in range(50)]
    path = tmp_path / "cf.csv.gz"
    path.write_bytes(gzip.compress(("\r\n".join(rows) + "\r\n").encode()))
    ins = inspect_log(path)
    assert ins.format == "csv"
    assert ins.suggested_columns is not None
    assert ins.suggested_columns["time"] == {"column": "timestamp", "scale": 0.001}
    assert ins.suggested_columns["body_rate"]["x"] == "gyro.x"
    assert ins.column_ranges["motor.m1"] == (30000.0, 30049.0)
