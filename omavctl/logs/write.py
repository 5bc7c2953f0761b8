"""Writing a :class:`RawLog` as a flight log: CSV, ROS 1 bag, MCAP file or ROS 2 bag.

The output kind follows the path: ``.csv`` wide CSV, ``.bag`` ROS 1 bag,
``.mcap`` standalone MCAP file (ros2msg schemas, CDR messages), anything else
a ROS 2 bag directory with mcap storage. Every output is written atomically
(a temporary sibling renamed into place), so an error never leaves a
half-written log behind.

Header stamps are ``t0 + stamp`` in integer nanoseconds; the log (receive)
time of every message equals its header stamp. Roles sharing a topic (the
odometry carries attitude, position and velocity) are written at the stamps
of the first of them present; the others are interpolated there, and the
parts of a message with no series behind them are zeros (identity
orientation). ``frame_id`` is ``base_link`` for body-frame messages and
``world`` for odometry and reference poses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.atomic import atomic_dir, atomic_path
from omavctl.base.errors import LogError
from omavctl.base.replace import is_mcap_from
from omavctl.logs.contract import TOPIC_FRAMES, TOPIC_MSGTYPES, TOPIC_SIGNALS, merge_topics
from omavctl.logs.types import ANGLE_ROLES, ROLE_COLUMNS, RawLog

__all__ = ["check_log_replaceable", "output_kind", "write_log"]


_KINDS = {".csv": "csv", ".bag": "ros1", ".mcap": "mcap"}
#: Who wrote a log, as the logs this module writes say it: the ROS 2 bag's
#: ``custom_data`` entry, the ROS 1 bag's caller id on every connection, the MCAP
#: header's library (``omavctl <version>``).
WRITER = "omavctl"


def output_kind(path: Path) -> str:
    """``"csv"``, ``"ros1"``, ``"mcap"`` or ``"ros2"`` (directory) for an output path.

    A name ending in another extension (one starting with a letter: ``.txt``,
    ``.db3``, a mistyped ``.cvs``) is refused rather than written as a ROS 2 bag
    directory of that name; directories and names like ``run.2`` are ROS 2 bags.
    """
    suffix = path.suffix.lower()
    if path.is_dir():
        return "ros2"
    if suffix in _KINDS:
        return _KINDS[suffix]
    if suffix[1:2].isalpha():
        raise LogError(
            f"unknown log kind '{path.suffix}': write a directory (ROS 2 bag), "
            ".bag (ROS 1), .mcap or .csv",
            path,
        )
    return "ros2"


@dataclass
class _Topic:
    """Messages of one topic, ready to serialise: stamps int64 ns shape (n,)."""

    name: str
    msgtype: str
    stamps_ns: np.ndarray
    msgs: list[Any]


def _t0_ns(t0: float) -> int:
    """``t0`` (s) as integer ns, exact to the nanosecond nearest the float."""
    sec = math.floor(t0)
    return int(sec) * 1_000_000_000 + round((t0 - sec) * 1e9)


def _check(raw: RawLog, path: Path) -> None:
    if not raw.series:
        raise LogError("nothing to write: the log has no signals", path)
    for role, s in raw.series.items():
        if role not in ROLE_COLUMNS:
            raise LogError(f"cannot write unknown signal role '{role}'", path)
        k = len(ROLE_COLUMNS[role])
        stamps, values = np.asarray(s.stamps), np.asarray(s.values)
        if stamps.ndim != 1 or values.shape != (stamps.size, k):
            raise LogError(
                f"series {role}: values shape {values.shape} does not match "
                f"{stamps.size} stamps x {k} columns",
                path,
            )
        if stamps.size == 0:
            raise LogError(f"series {role} has no samples", path)
        if not np.all(np.isfinite(stamps)):
            raise LogError(f"series {role} has non-finite stamps", path)


def _values_at(raw: RawLog, role: str, stamps: np.ndarray) -> np.ndarray | None:
    """Values of ``role`` at ``stamps`` shape (n,) (shape (n, k)), None if absent."""
    from omavctl.logs.align import interpolate
    from omavctl.logs.stats import stamp_stats

    s = raw.series.get(role)
    if s is None:
        return None
    st_arr = np.asarray(s.stamps, dtype=float)
    values = np.asarray(s.values, dtype=float)
    if st_arr.shape == stamps.shape and np.array_equal(st_arr, stamps):
        return values
    st = stamp_stats(st_arr)
    idx = st.order[st.keep]
    if idx.size == 1:
        return np.repeat(values[idx], stamps.size, axis=0)
    return interpolate(st_arr[idx], values[idx], stamps, role in ANGLE_ROLES)


def _build_topics(raw: RawLog, names: Mapping[str, str], typestore: Any) -> list[_Topic]:
    """Messages of every topic with at least one series in ``raw``."""
    from omavctl.logs.messages import MessageBuilder

    builder = MessageBuilder(typestore)
    t0_ns = _t0_ns(raw.t0)
    out = []
    for topic_role, roles in TOPIC_SIGNALS.items():
        present = [r for r in roles if r in raw.series]
        if not present:
            continue
        stamps = np.asarray(raw.series[present[0]].stamps, dtype=float)
        stamps_ns = t0_ns + np.round(stamps * 1e9).astype(np.int64)
        n = stamps.size

        def get(role: str, n: int = n, stamps: np.ndarray = stamps) -> np.ndarray:
            v = _values_at(raw, role, stamps)
            return np.zeros((n, len(ROLE_COLUMNS[role]))) if v is None else v

        headers = builder.headers(stamps_ns, TOPIC_FRAMES[topic_role])
        if topic_role == "imu":
            msgs = builder.imu(headers, get("body_rate"), _values_at(raw, "specific_force", stamps))
        elif topic_role == "odometry":
            msgs = builder.odometry(
                headers, get("attitude"), get("position"), get("velocity"), get("body_rate")
            )
        elif topic_role == "wrench_command":
            msgs = builder.wrench(headers, get("force_command"), get("torque_command"))
        elif topic_role == "desired_acceleration":
            msgs = builder.accel(
                headers, get("desired_acceleration"), get("desired_linear_acceleration")
            )
        elif topic_role == "reference":
            msgs = builder.pose(headers, get("reference_position"), get("reference_attitude"))
        elif topic_role == "battery":
            msgs = builder.battery(headers, get("battery_voltage"))
        else:
            msgs = builder.joint_state(
                headers, _values_at(raw, "tilt", stamps), _values_at(raw, "rotor", stamps)
            )
        out.append(_Topic(names[topic_role], TOPIC_MSGTYPES[topic_role], stamps_ns, msgs))
    return out


def _time_order(topics: list[_Topic]) -> tuple[np.ndarray, np.ndarray]:
    """(topic index, message index) of all messages sorted by stamp (stable)."""
    which = np.concatenate([np.full(t.stamps_ns.size, i) for i, t in enumerate(topics)])
    index = np.concatenate([np.arange(t.stamps_ns.size) for t in topics])
    stamps = np.concatenate([t.stamps_ns for t in topics])
    order = np.argsort(stamps, kind="stable")
    return which[order], index[order]


def _write_ros1(tmp: Path, raw: RawLog, names: Mapping[str, str]) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    topics = _build_topics(raw, names, store)
    data = [[store.serialize_ros1(m, t.msgtype) for m in t.msgs] for t in topics]
    with Writer(tmp) as writer:
        conns = [
            writer.add_connection(t.name, t.msgtype, typestore=store, callerid=f"/{WRITER}")
            for t in topics
        ]
        for i, j in zip(*_time_order(topics), strict=True):
            writer.write(conns[i], int(topics[i].stamps_ns[j]), data[i][j])


def _write_ros2(tmp: Path, raw: RawLog, names: Mapping[str, str]) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    topics = _build_topics(raw, names, store)
    data = [[store.serialize_cdr(m, t.msgtype) for m in t.msgs] for t in topics]
    with Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.set_custom_data("written_by", WRITER)
        conns = [writer.add_connection(t.name, t.msgtype, typestore=store) for t in topics]
        for i, j in zip(*_time_order(topics), strict=True):
            writer.write(conns[i], int(topics[i].stamps_ns[j]), data[i][j])


def _write_mcap(tmp: Path, raw: RawLog, names: Mapping[str, str]) -> None:
    from mcap.writer import CompressionType, Writer
    from rosbags.typesys import Stores, get_typestore

    from omavctl import __version__

    store = get_typestore(Stores.ROS2_HUMBLE)
    topics = _build_topics(raw, names, store)
    data = [[bytes(store.serialize_cdr(m, t.msgtype)) for m in t.msgs] for t in topics]
    with tmp.open("wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library=f"{WRITER} {__version__}")
        schemas: dict[str, int] = {}
        channels = []
        for t in topics:
            if t.msgtype not in schemas:
                msgdef, _ = store.generate_msgdef(t.msgtype, ros_version=2)
                schemas[t.msgtype] = writer.register_schema(
                    name=t.msgtype, encoding="ros2msg", data=msgdef.encode()
                )
            channels.append(
                writer.register_channel(
                    topic=t.name, message_encoding="cdr", schema_id=schemas[t.msgtype]
                )
            )
        for i, j in zip(*_time_order(topics), strict=True):
            stamp = int(topics[i].stamps_ns[j])
            writer.add_message(
                channels[i], log_time=stamp, data=data[i][j], publish_time=stamp, sequence=int(j)
            )
        writer.finish()


def write_log(path: str | Path, raw: RawLog, topics: Mapping[str, str] | None = None) -> None:
    """Write ``raw`` as a flight log; the kind follows ``path`` (see module docs).

    Args:
        path: ``x.csv``, ``x.bag``, ``x.mcap``, or a directory path for a ROS 2 bag
            (an existing bag there is replaced; any other non-empty directory is
            refused).
        raw: series to write (stamps shape (n,) s since ``raw.t0``, values shape (n, k)).
        topics: topic role -> topic name, over :data:`DEFAULT_TOPICS`.

    Raises:
        LogError: nothing to write, inconsistent series, or output not writable.
    """
    p = Path(path)
    _check(raw, p)
    kind = output_kind(p)
    names = merge_topics(topics)
    if kind == "csv":
        from omavctl.logs.csvlog import write_csv

        write_csv(p, raw)
    elif kind == "ros1":
        with atomic_path(p) as tmp:
            tmp.unlink()  # the rosbag1 writer refuses an existing file
            _write_ros1(tmp, raw, names)
    elif kind == "mcap":
        with atomic_path(p) as tmp:
            _write_mcap(tmp, raw, names)
    else:
        if p.is_dir() and any(p.iterdir()) and not (p / "metadata.yaml").is_file():
            raise LogError(
                "output directory exists and is not a ROS 2 bag: refusing to replace it "
                "(name a new directory, or a .bag, .mcap or .csv file)",
                p,
            )
        with atomic_dir(p) as tmp:
            _write_ros2(tmp, raw, names)


def check_log_replaceable(path: str | Path) -> None:
    """Refuse an existing ``path`` that is not a log omavctl wrote (``simulate``'s
    output may replace its own earlier log, never a flight log or another file the
    user keeps under that name): a ROS 2 bag or ROS 1 bag without omavctl's mark,
    an MCAP file another library wrote, a CSV whose header is not the wide layout
    :func:`write_log` writes. A missing path, an empty file or an empty directory
    passes; so does a path that cannot be read (the writer says what is wrong).

    Raises:
        LogError: ``<path>: exists and is not a log omavctl simulate wrote; ...``.
    """
    p = Path(path)
    try:
        if not p.exists() or (p.is_dir() and not any(p.iterdir())):
            return
        if p.is_file() and p.stat().st_size == 0:
            return
        ours = _written_here(p)
    except OSError:
        return
    if not ours:
        raise LogError(
            "exists and is not a log omavctl simulate wrote; choose another name (or remove it)",
            p,
        )


def _written_here(p: Path) -> bool:
    """Whether the existing, non-empty ``p`` bears the mark of :func:`write_log`."""
    import yaml

    if p.is_dir():
        meta = p / "metadata.yaml"
        if not meta.is_file():
            return False
        try:
            tree = yaml.safe_load(meta.read_text(encoding="utf-8", errors="replace"))
        except yaml.YAMLError:
            return False
        info = tree.get("rosbag2_bagfile_information") if isinstance(tree, dict) else None
        custom = info.get("custom_data") if isinstance(info, dict) else None
        return isinstance(custom, dict) and custom.get("written_by") == WRITER
    kind = p.suffix.lower()
    if kind == ".mcap":
        return is_mcap_from(p, WRITER, "ros2")  # a series MCAP of evaluate is no log
    if kind == ".bag":
        return _ros1_callers(p) == {f"/{WRITER}"}
    if kind == ".csv":
        return _wide_csv_header(p)
    return False


def _ros1_callers(p: Path) -> set[str]:
    """The caller ids of a ROS 1 bag's connections (empty when it cannot be read)."""
    from rosbags.rosbag1 import Reader

    try:
        with Reader(p) as reader:
            return {str(getattr(c.ext, "callerid", None)) for c in reader.connections}
    except Exception:  # any unreadable bag is not one omavctl wrote
        return set()


def _wide_csv_header(p: Path) -> bool:
    """Whether the CSV's first line is ``t`` and whole column groups of the contract's
    roles in the order :func:`omavctl.logs.csvlog.write_csv` writes them."""
    from omavctl.logs.csvlog import csv_columns

    with p.open("rb") as fh:
        first = fh.readline(1 << 16).decode("utf-8", "replace").strip()
    names = [h.strip() for h in first.split(",")]
    if names[:1] != ["t"]:
        return False
    at = 1
    for role in ROLE_COLUMNS:
        cols = csv_columns(role)
        if names[at : at + len(cols)] == cols:
            at += len(cols)
    return at == len(names) > 1
