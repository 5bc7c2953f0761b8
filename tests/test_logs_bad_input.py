"""Bad flight logs: each gives one LogError line naming the file, and the input is untouched."""

from __future__ import annotations

import hashlib
import re
import shutil
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from omavctl.base.errors import ConfigError, LogError
from omavctl.logs import RawLog, RawSeries, read_log, read_raw, write_log
from omavctl.logs.types import ROLE_COLUMNS

try:  # tests/ as a package or as a rootdir on sys.path
    from .test_logs import _foreign_messages, make_raw
except ImportError:
    from test_logs import _foreign_messages, make_raw


def _digest(path: Path) -> dict[str, str]:
    """sha256 of every file under ``path`` (or of ``path`` itself), by relative name."""
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return {
        str(p.relative_to(path.parent)): hashlib.sha256(p.read_bytes()).hexdigest() for p in files
    }


def assert_log_error(path: Path, message: str, read: Callable[[Path], object] = read_log) -> None:
    """``read(path)`` raises a one-line LogError ``<path>: <message...>``; input unchanged."""
    before = _digest(path) if path.exists() else None
    with pytest.raises(LogError) as info:
        read(path)
    text = str(info.value)
    assert "\n" not in text
    assert info.value.path == path
    assert text.startswith(f"{path}: ")
    assert re.search(message, text), text
    if before is not None:
        assert _digest(path) == before


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("good")
    raw = make_raw(duration=2.0)
    paths = {"bag": base / "good.bag", "mcap": base / "good.mcap", "dir": base / "good_dir"}
    for p in paths.values():
        write_log(p, raw)
    return paths


def test_missing_file(tmp_path: Path) -> None:
    assert_log_error(tmp_path / "nope.bag", "^.*: file not found$")
    assert_log_error(tmp_path / "nope_dir", "file not found")


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("empty.bag", "not a readable ROS 1 bag: the file is empty"),
        ("empty.mcap", "not a readable MCAP file: the file is empty"),
        ("empty.csv", "not a CSV file: the file is empty"),
    ],
)
def test_empty_file(tmp_path: Path, name: str, message: str) -> None:
    path = tmp_path / name
    path.write_bytes(b"")
    assert_log_error(path, message)


@pytest.mark.parametrize(
    ("kind", "message"),
    [("bag", "not a readable ROS 1 bag: "), ("mcap", "not a readable MCAP file: ")],
)
def test_truncated_file(tmp_path: Path, good: dict[str, Path], kind: str, message: str) -> None:
    data = good[kind].read_bytes()
    path = tmp_path / f"cut.{kind}"
    path.write_bytes(data[: len(data) // 2])
    assert_log_error(path, message)


def test_garbage_bag(tmp_path: Path) -> None:
    path = tmp_path / "garbage.bag"
    path.write_bytes(b"this is not a bag\n" * 100)
    assert_log_error(path, "not a readable ROS 1 bag: ")


def test_truncated_ros2_storage(tmp_path: Path, good: dict[str, Path]) -> None:
    bag = tmp_path / "cut_dir"
    shutil.copytree(good["dir"], bag)
    storage = next(bag.glob("*.mcap"))
    data = storage.read_bytes()
    storage.write_bytes(data[: len(data) // 2])
    assert_log_error(bag, "not a readable ROS 2 bag: ")


def test_directory_that_is_not_a_bag(tmp_path: Path) -> None:
    (tmp_path / "flight").mkdir()
    (tmp_path / "flight" / "notes.txt").write_text("hello")
    assert_log_error(tmp_path / "flight", "directory is not a ROS 2 bag \\(no metadata.yaml")


def test_unknown_extension(tmp_path: Path) -> None:
    path = tmp_path / "flight.px4log"
    path.write_bytes(b"\xa3\x95\x80")
    assert_log_error(
        path,
        r"unknown log format \('\.px4log'\): expected a \.bag, \.mcap, \.ulg, \.csv or \.csv\.gz",
    )


def test_a_cut_or_corrupt_ulog_is_refused_or_read_with_a_note(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A ULog shorter than its header is refused; one cut in the middle of a message
    is read up to the cut; a message of an unknown topic is skipped and named in a
    note, and the reader's own warning does not reach stdout (JSON may be there)."""
    from omavctl.logs.ulog import load_ulog
    from tests.ulog_writer import message, write_ulog

    path = tmp_path / "flight.ulg"
    path.write_bytes(b"ULog\x01")
    assert_log_error(path, r"not a readable ULog file: the file does not start with its header")
    t = np.arange(0.0, 2e6, 1e4)
    write_ulog(path, {"sensor_combined": (t, {"gyro_rad": np.ones((t.size, 3))})})
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 1010])  # 40.4 data messages of 25 bytes
    stamps, fields = load_ulog(path).topics["sensor_combined"]
    assert stamps.size == t.size - 41
    assert set(fields) == {f"sensor_combined.gyro_rad[{i}]" for i in range(3)}
    path.write_bytes(data + message(b"D", struct.pack("<HQ", 9, 10) + bytes(12)))
    u = load_ulog(path)
    assert u.topics["sensor_combined"][0].size == t.size
    assert u.notes == [
        "the file is corrupt in places (Warning: no subscription found for message id 9. "
        "Continuing, but file is most likely corrupt): read what it could"
    ]
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize("kind", ["bag", "mcap", "dir"])
def test_missing_required_topic(tmp_path: Path, kind: str) -> None:
    raw = make_raw(duration=1.0)
    del raw.series["attitude"], raw.series["position"], raw.series["velocity"]
    path = tmp_path / {"bag": "x.bag", "mcap": "x.mcap", "dir": "x_dir"}[kind]
    write_log(path, raw)
    assert_log_error(path, r"missing topic '/omav/odometry' \(role attitude\)$")
    read_log(path, required=("body_rate",))  # fine when not required


def test_wrong_message_type_on_contract_topic(good: dict[str, Path]) -> None:
    swapped = {"imu": "/omav/wrench_command", "wrench_command": "/ctrl/wrench"}
    for path in good.values():
        assert_log_error(
            path,
            "topic '/omav/wrench_command' has type 'geometry_msgs/msg/WrenchStamped', "
            r"expected 'sensor_msgs/msg/Imu' \(role imu\)$",
            lambda p: read_raw(p, topics=swapped),
        )


def test_one_topic_for_two_roles(good: dict[str, Path]) -> None:
    with pytest.raises(ConfigError, match=r"topic '/omav/imu' is given for both topics\.imu and"):
        read_raw(good["bag"], topics={"odometry": "/omav/imu"})


def test_nan_in_required_role_of_bag(tmp_path: Path) -> None:
    raw = make_raw(duration=1.0)
    raw.series["body_rate"].values[40, 1] = np.nan
    path = tmp_path / "nan.mcap"
    write_log(path, raw)
    assert_log_error(path, r"non-finite value in /omav/imu \(role body_rate\) at t=0\.200 s$")


def test_too_short(tmp_path: Path) -> None:
    raw = make_raw(duration=0.05)
    path = tmp_path / "short.bag"
    write_log(path, raw)
    assert_log_error(path, r"too little data: .*6 samples at 100 Hz \(need at least 10\)")


def test_signals_do_not_overlap(tmp_path: Path) -> None:
    raw = make_raw(duration=1.0)
    s = raw.series["force_command"]
    raw.series["force_command"] = RawSeries(s.stamps + 5.0, s.values)
    path = tmp_path / "apart.bag"
    write_log(path, raw)
    assert_log_error(path, "too little data: the signals overlap for 0.000 s")


# --- CSV ---------------------------------------------------------------------------


def _csv(tmp_path: Path, header: list[str], rows: list[list[str]], name: str = "x.csv") -> Path:
    path = tmp_path / name
    path.write_text("\n".join([",".join(header)] + [",".join(r) for r in rows]) + "\n")
    return path


def _good_csv_rows(n: int = 20, cols: int = 12) -> list[list[str]]:
    return [[repr(i / 100)] + [repr(0.1 * i + j) for j in range(cols)] for i in range(n)]


REQUIRED_HEADER = ["t"] + [
    f"{r}_{c}"
    for r in ("body_rate", "attitude", "force_command", "torque_command")
    for c in ROLE_COLUMNS[r]
]


def test_csv_reads_when_good(tmp_path: Path) -> None:
    log = read_log(_csv(tmp_path, REQUIRED_HEADER, _good_csv_rows()))
    assert log.t.size == 20


def test_csv_nan_cell(tmp_path: Path) -> None:
    rows = _good_csv_rows()
    rows[6][5] = "nan"
    path = _csv(tmp_path, REQUIRED_HEADER, rows)
    assert_log_error(path, r"NaN in column 'attitude_pitch' at row 7 \(line 8\)$")


def test_csv_non_numeric_cell(tmp_path: Path) -> None:
    rows = _good_csv_rows()
    rows[3][1] = "fast"
    path = _csv(tmp_path, REQUIRED_HEADER, rows)
    assert_log_error(path, r"non-numeric value 'fast' in column 'body_rate_x' at row 4 \(line 5\)$")


def test_csv_empty_cell(tmp_path: Path) -> None:
    rows = _good_csv_rows()
    rows[2][12] = ""
    path = _csv(tmp_path, REQUIRED_HEADER, rows)
    assert_log_error(path, r"empty cell in column 'torque_command_z' at row 3 \(line 4\)$")


def test_csv_short_row(tmp_path: Path) -> None:
    rows = _good_csv_rows()
    rows[9] = rows[9][:5]
    path = _csv(tmp_path, REQUIRED_HEADER, rows)
    assert_log_error(path, r"row 10 \(line 11\) has 5 cells, the header has 13$")


def test_csv_partial_role(tmp_path: Path) -> None:
    header = [h for h in REQUIRED_HEADER if h != "torque_command_y"]
    path = _csv(tmp_path, header, [r[:12] for r in _good_csv_rows()])
    assert_log_error(
        path,
        r"missing column 'torque_command_y' \(role torque_command needs "
        r"torque_command_x, torque_command_y, torque_command_z\)$",
    )


def test_csv_missing_required_role(tmp_path: Path) -> None:
    header = [h for h in REQUIRED_HEADER if not h.startswith("attitude")]
    path = _csv(tmp_path, header, [r[:10] for r in _good_csv_rows()])
    assert_log_error(
        path,
        r"missing columns for attitude: attitude_roll, attitude_pitch, attitude_yaw \(omavctl "
        r"inspect names columns that look like them\)$",
    )


def test_csv_without_t(tmp_path: Path) -> None:
    path = _csv(tmp_path, ["time", *REQUIRED_HEADER[1:]], _good_csv_rows())
    assert_log_error(path, r"missing column 't' \(time in s\)$")
    # another layout altogether: inspect suggests the column map it needs
    path = _csv(tmp_path, [f"col{i}" for i in range(len(REQUIRED_HEADER))], _good_csv_rows())
    assert_log_error(
        path,
        r"missing column 't' \(time in s\): not a wide contract CSV; "
        f"'omavctl inspect {re.escape(str(path))}' suggests a column map for a --vehicle file$",
    )


def test_csv_duplicate_column(tmp_path: Path) -> None:
    path = _csv(tmp_path, [*REQUIRED_HEADER, "body_rate_x"], [[*r, "1"] for r in _good_csv_rows()])
    assert_log_error(path, "duplicate column 'body_rate_x'$")


def test_csv_header_only(tmp_path: Path) -> None:
    path = _csv(tmp_path, REQUIRED_HEADER, [])
    assert_log_error(path, "no data rows below the header$")


def test_csv_not_text(tmp_path: Path) -> None:
    path = tmp_path / "binary.csv"
    path.write_bytes(b"\xff\xfe\x00\x81" * 10)
    assert_log_error(path, "not a CSV file: it is not UTF-8 text")


# --- writing -----------------------------------------------------------------------


@pytest.mark.parametrize("name", ["out.csv", "out.bag", "out.mcap", "out_dir"])
def test_aborted_write_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    """An error in the middle of writing leaves neither output nor temporary files."""
    import omavctl.logs.csvlog as csvlog
    import omavctl.logs.write as write

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("disk on fire")

    if name.endswith(".csv"):
        original = Path.write_text

        def half_then_boom(self: Path, text: str, *a: object, **k: object) -> int:
            original(self, text[: len(text) // 2])
            raise RuntimeError("disk on fire")

        monkeypatch.setattr(csvlog.Path, "write_text", half_then_boom)
    else:
        # fails after the writer has opened its output and added connections
        monkeypatch.setattr(write, "_time_order", boom)
    out = tmp_path / "sub"
    out.mkdir()
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_log(out / name, make_raw(duration=0.5))
    assert list(out.iterdir()) == []


def test_failed_write_keeps_previous_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import omavctl.logs.write as write

    path = tmp_path / "keep.bag"
    write_log(path, make_raw(duration=0.5))
    before = _digest(path)

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(write, "_time_order", boom)
    with pytest.raises(RuntimeError):
        write_log(path, make_raw(duration=1.0))
    assert _digest(path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.bag"]


def test_write_rejects_empty_and_inconsistent(tmp_path: Path) -> None:
    empty = RawLog(path=Path("x"), format="synthetic", t0=0.0, series={})
    with pytest.raises(LogError, match="nothing to write: the log has no signals"):
        write_log(tmp_path / "e.bag", empty)
    bad = RawLog(
        path=Path("x"),
        format="synthetic",
        t0=0.0,
        series={"body_rate": RawSeries(np.arange(5.0), np.zeros((5, 2)))},
    )
    with pytest.raises(LogError, match="series body_rate: values shape"):
        write_log(tmp_path / "b.mcap", bad)
    assert list(tmp_path.iterdir()) == []


def test_sqlite_bag_directory_untouched(tmp_path: Path) -> None:
    """Reading a sqlite3 bag creates no journal files and changes no byte."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    msgs, _, _ = _foreign_messages(store, ros1=False, n=30)
    path = tmp_path / "sq"
    with Writer(path, version=9) as writer:
        for topic, items in msgs.items():
            conn = writer.add_connection(topic, items[0][2], typestore=store)
            for logtime, msg, typ in items:
                writer.write(conn, logtime, store.serialize_cdr(msg, typ))
    before = _digest(path)
    read_log(path)
    assert _digest(path) == before


def test_write_refuses_to_replace_a_non_bag_directory(tmp_path: Path) -> None:
    folder = tmp_path / "flights"
    folder.mkdir()
    (folder / "task-01.bag").write_bytes(b"precious")
    with pytest.raises(LogError, match="output directory exists and is not a ROS 2 bag"):
        write_log(folder, make_raw(duration=0.5))
    assert (folder / "task-01.bag").read_bytes() == b"precious"
    bag = tmp_path / "bag"
    write_log(bag, make_raw(duration=0.5))
    write_log(bag, make_raw(duration=1.0))  # an existing bag is replaced
    assert read_log(bag).t.size == 101


def test_library_internals_of_a_truncated_mcap_are_not_shown():
    """The mcap reader's record-length complaint about a truncated file is internals."""
    from omavctl.base.errors import library_reason

    text = (
        "unknown (opcode 151) record has length 6048615774535352343 that exceeds limit 4294967296"
    )
    assert library_reason(ValueError(text)) == "the file is damaged or truncated"
    assert library_reason(ValueError("file is empty")) == "file is empty"
