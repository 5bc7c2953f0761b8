"""Reading flight logs into a :class:`RawLog`: ROS 1 bags, ROS 2 bags, MCAP files, CSV, ULog.

The kind of log follows from the path: a directory with ``metadata.yaml`` is a
ROS 2 bag (sqlite3 or mcap storage), ``.bag`` a ROS 1 bag (both through
``rosbags.highlevel.AnyReader``), ``.mcap`` a standalone MCAP file (through the
``mcap`` reader, messages decoded with rosbags typestores, ROS 2 CDR or ROS 1
encoding), ``.db3`` a bare ROS 2 sqlite3 storage file and ``.csv`` the wide CSV
of DESIGN.md section 3 (or another layout, through a column map), ``.ulg`` a PX4
ULog (through a column map, :mod:`omavctl.logs.ulog`). rosbags and mcap are
imported only when a bag is read.

Inputs are only ever opened for reading.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import LogError, library_reason
from omavctl.logs.contract import TOPIC_MSGTYPES, merge_topics
from omavctl.logs.messages import ROW_EXTRACTORS, rows_to_signals
from omavctl.logs.stats import topic_info
from omavctl.logs.types import RawLog, RawSeries

__all__ = ["FORMAT_LABELS", "detect_format", "read_raw"]

#: What each input kind is called in messages.
FORMAT_LABELS = {
    "ros1": "ROS 1 bag",
    "ros2": "ROS 2 bag",
    "mcap": "MCAP file",
    "csv": "CSV file",
    "ulog": "ULog file",
    "cfusdlog": "Crazyflie SD-card log",
    "betaflight": "Betaflight blackbox CSV",
}

_SUFFIX_KIND = {".bag": "ros1", ".mcap": "mcap", ".csv": "csv", ".db3": "ros2", ".ulg": "ulog"}


#: First bytes of each binary kind (what a file really is, whatever its name).
_MAGIC = {
    "ros1": b"#ROSBAG V2.0\n",
    "mcap": b"\x89MCAP0\r\n",
    "sqlite": b"SQLite format 3\x00",
    "ulog": b"ULog\x01\x12\x35",
}
_MAGIC_LABELS = {**FORMAT_LABELS, "sqlite": "ROS 2 sqlite3 storage file (.db3)"}


def _reason(err: BaseException) -> str:
    """One line describing ``err`` for the user (no Python internals)."""
    return library_reason(err)


def _sniff(path: Path) -> str | None:
    """The kind the first bytes of ``path`` announce (``_MAGIC`` keys), else None."""
    try:
        with path.open("rb") as fh:
            head = fh.read(16)
    except OSError as err:
        raise LogError(f"cannot read: {err.strerror or err}", path) from None
    return next((kind for kind, magic in _MAGIC.items() if head.startswith(magic)), None)


def _check_magic(path: Path, kind: str) -> None:
    """Refuse a file whose content is not the format its name says."""
    real = _sniff(path)
    want = "sqlite" if path.suffix.lower() == ".db3" else kind
    if real == want or (kind == "csv" and real is None) or kind in ("cfusdlog", "betaflight"):
        return
    label = _MAGIC_LABELS[want]
    if real is not None:
        raise LogError(f"not a {label}: the file is a {_MAGIC_LABELS[real]}", path)
    raise LogError(f"not a readable {label}: the file does not start with its header", path)


def _check_metadata(path: Path) -> None:
    """A ROS 2 bag directory's metadata.yaml must hold rosbag2_bagfile_information."""
    import yaml

    meta = path / "metadata.yaml"
    try:
        tree = yaml.safe_load(meta.read_bytes())
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        raise LogError("not a readable ROS 2 bag: metadata.yaml is not valid YAML", path) from None
    info = tree.get("rosbag2_bagfile_information") if isinstance(tree, dict) else None
    if not isinstance(info, dict):
        raise LogError(
            "not a readable ROS 2 bag: metadata.yaml lacks 'rosbag2_bagfile_information'", path
        )
    problem = _metadata_problem(info)
    if problem:
        raise LogError(f"not a readable ROS 2 bag: metadata.yaml: {problem}", path)


def _metadata_problem(info: dict[str, Any]) -> str | None:
    """What is wrong with the fields of rosbag2_bagfile_information that are read."""
    if not isinstance(info.get("version"), int) or isinstance(info.get("version"), bool):
        return "'version' must be an integer"
    if not isinstance(info.get("storage_identifier"), str):
        return "'storage_identifier' must be a name"
    files = info.get("relative_file_paths")
    if not isinstance(files, list) or not all(isinstance(f, str) and f for f in files):
        return "'relative_file_paths' must be a list of file names"
    topics = info.get("topics_with_message_count")
    if not isinstance(topics, list):
        return "'topics_with_message_count' must be a list"
    for i, entry in enumerate(topics):
        meta = entry.get("topic_metadata") if isinstance(entry, dict) else None
        where = f"'topics_with_message_count[{i}]"
        if not isinstance(meta, dict):
            return f"{where}.topic_metadata' must be a mapping"
        for key in ("name", "type", "serialization_format"):
            if not isinstance(meta.get(key), str) or not meta[key]:
                return f"{where}.topic_metadata.{key}' must be a non-empty string"
        count = entry.get("message_count")
        if not isinstance(count, int) or isinstance(count, bool) or count < 0:
            return f"{where}.message_count' must be a count"
    return None


def detect_format(path: Path) -> str:
    """Kind of log at ``path``: ``"ros1"``, ``"ros2"``, ``"mcap"``, ``"ulog"`` or ``"csv"``.

    Raises :class:`LogError` for a missing path, a directory that is not a ROS 2
    bag, an unknown suffix, an empty file or a file whose content is another
    format than its name says.
    """
    if not path.exists():
        raise LogError("file not found", path)
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            _check_metadata(path)
            return "ros2"
        raise LogError("directory is not a ROS 2 bag (no metadata.yaml in it)", path)
    name = path.name.lower()
    kind = "csv" if name.endswith(".csv.gz") else _SUFFIX_KIND.get(path.suffix.lower())
    if kind is None:
        from omavctl.logs.columnlogs import content_kind

        kind = content_kind(path)
    if kind is None:
        shown = f"'{path.suffix}'" if path.suffix else "no suffix"
        raise LogError(
            f"unknown log format ({shown}): expected a .bag, .mcap, .ulg, .csv or .csv.gz "
            "file, a ROS 2 bag directory, a Crazyflie SD-card log or a Betaflight blackbox CSV",
            path,
        )
    try:
        size = path.stat().st_size
    except OSError as err:
        raise LogError(f"cannot read: {_reason(err)}", path) from err
    if size == 0:
        label = "CSV file" if kind == "csv" else f"readable {FORMAT_LABELS[kind]}"
        raise LogError(f"not a {label}: the file is empty", path)
    _check_magic(path, kind)
    if kind == "csv":
        from omavctl.logs.betaflight import sniff_betaflight

        return "betaflight" if sniff_betaflight(path) else "csv"
    return kind


@dataclass
class _Collected:
    """Messages gathered from a bag: every topic's type and receive times
    (int ns), rows (see :data:`ROW_EXTRACTORS`) of the contract topics in use."""

    msgtypes: dict[str, str] = field(default_factory=dict)
    logtimes: dict[str, list[int]] = field(default_factory=lambda: defaultdict(list))
    rows: dict[str, list[tuple[Any, ...]]] = field(default_factory=lambda: defaultdict(list))
    notes: list[str] = field(default_factory=list)


def _use_topic(
    topic: str,
    msgtype: str,
    wanted: Mapping[str, str],
    strict: bool,
    notes: list[str],
    path: Path,
) -> bool:
    """Whether messages on ``topic`` are decoded: it is a contract topic of the
    expected type. A contract topic of another type is an error (strict) or a note."""
    role = wanted.get(topic)
    if role is None:
        return False
    expected = TOPIC_MSGTYPES[role]
    if msgtype != expected:
        msg = f"topic '{topic}' has type '{msgtype}', expected '{expected}' (role {role})"
        if strict:
            raise LogError(msg, path)
        notes.append(msg + "; not read")
        return False
    return True


def _read_rosbag(path: Path, kind: str, names: Mapping[str, str], strict: bool) -> RawLog:
    """Read a ROS 1 bag or a ROS 2 bag (directory or bare ``.db3``) with AnyReader."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    label = FORMAT_LABELS[kind]
    wanted = {name: role for role, name in names.items()}
    default = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    col = _Collected()
    try:
        with AnyReader([path], default_typestore=default) as reader:
            usable: dict[str, Callable[[Any], tuple[Any, ...]]] = {}
            for conn in reader.connections:
                col.msgtypes.setdefault(conn.topic, conn.msgtype)
                if _use_topic(conn.topic, conn.msgtype, wanted, strict, col.notes, path):
                    usable[conn.topic] = ROW_EXTRACTORS[wanted[conn.topic]]
            store = reader.typestore
            decode = store.deserialize_cdr if reader.is2 else store.deserialize_ros1
            logtimes, rows = col.logtimes, col.rows
            for conn, stamp, data in reader.messages():
                topic = conn.topic
                logtimes[topic].append(stamp)
                extract = usable.get(topic)
                if extract is not None:
                    rows[topic].append(extract(decode(data, conn.msgtype)))
    except LogError:
        raise
    except Exception as err:  # any failure inside rosbags: corrupt or truncated input
        raise LogError(f"not a readable {label}: {_reason(err)}", path) from err
    if kind == "ros1":
        fmt = "ros1"
    else:
        fmt = f"ros2-{_ros2_storage(path)}"
    return _assemble(path, fmt, names, col)


def _ros2_storage(path: Path) -> str:
    """Storage plugin of a ROS 2 bag: ``"sqlite3"`` or ``"mcap"``."""
    if path.is_file():
        return "sqlite3" if path.suffix.lower() == ".db3" else "mcap"
    import yaml

    try:
        meta = yaml.safe_load((path / "metadata.yaml").read_text())
        ident = meta["rosbag2_bagfile_information"]["storage_identifier"]
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return "sqlite3"
    return str(ident) if ident in ("sqlite3", "mcap") else "sqlite3"


_ROS_SCHEMA_ENCODINGS = ("ros1msg", "ros2msg", "ros2idl")


class _McapDecoders:
    """Decoders per MCAP channel: rosbags typestores filled from the file's schemas.

    Types come from the schema text stored in the file (as rosbags' AnyReader
    does); a channel without schema text falls back to the ROS 2 Humble or
    ROS 1 Noetic definitions of the type the contract expects.
    """

    def __init__(self, path: Path, wanted: Mapping[str, str], col: _Collected, strict: bool):
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self.wanted = wanted
        self.col = col
        self.strict = strict
        self.stores = {"cdr": get_typestore(Stores.EMPTY), "ros1": get_typestore(Stores.EMPTY)}
        self.cache: dict[int, Callable[[bytes], tuple[Any, ...]] | None] = {}

    @staticmethod
    def msgtype(schema: Any, channel: Any) -> str:
        """Message type of a channel (ROS types normalised to ``pkg/msg/Name``)."""
        from rosbags.typesys.msg import normalize_msgtype

        if schema is None or not schema.name:
            return f"(no schema, {channel.message_encoding or 'no'} encoding)"
        if schema.encoding in _ROS_SCHEMA_ENCODINGS:
            return normalize_msgtype(schema.name)
        return str(schema.name)

    def get(self, schema: Any, channel: Any) -> Callable[[bytes], tuple[Any, ...]] | None:
        """Function from message bytes to a row, or None for a topic not read."""
        if channel.id not in self.cache:
            self.cache[channel.id] = self._make(schema, channel)
        return self.cache[channel.id]

    def _make(self, schema: Any, channel: Any) -> Callable[[bytes], tuple[Any, ...]] | None:
        from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

        topic, encoding = channel.topic, channel.message_encoding
        text = bytes(schema.data).decode() if schema is not None else ""
        role = self.wanted.get(topic)
        if role is not None and not text.strip() and encoding in self.stores:
            msgtype = TOPIC_MSGTYPES[role]  # no schema: trust the contract
        else:
            msgtype = self.msgtype(schema, channel)
        self.col.msgtypes.setdefault(topic, msgtype)
        if not _use_topic(topic, msgtype, self.wanted, self.strict, self.col.notes, self.path):
            return None
        if encoding not in self.stores:
            raise LogError(
                f"topic '{topic}' has message encoding '{encoding}', expected cdr or ros1",
                self.path,
            )
        store = self.stores[encoding]
        if msgtype not in store.fielddefs:
            if not text.strip():
                store = get_typestore(
                    Stores.ROS2_HUMBLE if encoding == "cdr" else Stores.ROS1_NOETIC
                )
            elif schema.encoding == "ros2idl":
                sep = "=" * 80 + "\n"
                if text.startswith(f"{sep}IDL: "):
                    for part in text.split(sep)[1:]:
                        store.register(get_types_from_idl(part.split("\n", 1)[1]))
                else:
                    store.register(get_types_from_idl(text))
            else:
                store.register(get_types_from_msg(text, msgtype))
        extract = ROW_EXTRACTORS[self.wanted[topic]]
        decode = store.deserialize_cdr if encoding == "cdr" else store.deserialize_ros1
        return lambda data: extract(decode(data, msgtype))


def _read_mcap(path: Path, names: Mapping[str, str], strict: bool) -> RawLog:
    """Read a standalone MCAP file with the ``mcap`` reader."""
    from mcap.reader import make_reader

    wanted = {name: role for role, name in names.items()}
    col = _Collected()
    decoders = _McapDecoders(path, wanted, col, strict)
    try:
        with path.open("rb") as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            if summary is not None:
                for channel in summary.channels.values():
                    schema = summary.schemas.get(channel.schema_id)
                    col.msgtypes.setdefault(channel.topic, decoders.msgtype(schema, channel))
            logtimes, rows = col.logtimes, col.rows
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                topic = channel.topic
                logtimes[topic].append(message.log_time)
                to_row = decoders.get(schema, channel)
                if to_row is not None:
                    rows[topic].append(to_row(message.data))
    except LogError:
        raise
    except Exception as err:  # any failure inside mcap/rosbags: corrupt or truncated input
        raise LogError(f"not a readable MCAP file: {_reason(err)}", path) from err
    return _assemble(path, "mcap", names, col)


def _assemble(path: Path, fmt: str, names: Mapping[str, str], col: _Collected) -> RawLog:
    """Turn collected messages into series (stamps relative to the earliest used stamp)."""
    wanted = {name: role for role, name in names.items()}
    notes = list(col.notes)
    stamps_ns: dict[str, np.ndarray] = {}
    signals: dict[str, dict[str, np.ndarray]] = {}
    for topic, rows in col.rows.items():
        if not rows:
            continue
        recv = np.asarray(col.logtimes[topic], dtype=np.int64)
        hdr, signals[topic], extract_notes = rows_to_signals(wanted[topic], rows, topic)
        notes += extract_notes
        missing = hdr <= 0
        # an unset (zero) header stamp matters only where the receive time differs
        replaced = int(np.count_nonzero(missing & (recv != hdr)))
        if replaced:
            notes.append(
                f"{topic}: {replaced} of {len(rows)} messages have no header "
                "stamp; their log receive time is used"
            )
        stamps_ns[topic] = np.where(missing, recv, hdr)

    if stamps_ns:
        t0_ns = int(min(int(s.min()) for s in stamps_ns.values()))
    else:
        all_times = [min(v) for v in col.logtimes.values() if v]
        t0_ns = int(min(all_times)) if all_times else 0

    series: dict[str, RawSeries] = {}
    for topic, st in stamps_ns.items():
        rel = (st - t0_ns) / 1e9
        for role, values in signals[topic].items():
            series[role] = RawSeries(stamps=rel, values=values)

    topics = []
    for topic in sorted(set(col.msgtypes) | set(col.logtimes)):
        if topic in stamps_ns:
            st = stamps_ns[topic]
        else:
            st = np.asarray(col.logtimes.get(topic, []), dtype=np.int64)
        topics.append(topic_info(topic, col.msgtypes.get(topic, "?"), (st - t0_ns) / 1e9))

    absent = [name for name in names.values() if name not in col.msgtypes]
    if absent:
        notes.append(f"contract topics not in the log: {', '.join(absent)}")
    empty = [n for n in names.values() if n in col.msgtypes and not col.logtimes.get(n)]
    if empty:
        notes.append(f"contract topics without messages: {', '.join(empty)}")
    return RawLog(
        path=path,
        format=fmt,
        t0=t0_ns / 1e9,
        series=series,
        topics=topics,
        notes=notes,
        topic_names=dict(names),
    )


def _read(
    path: str | Path,
    topics: Mapping[str, str] | None,
    strict: bool,
    columns: Mapping[str, Any] | None = None,
) -> RawLog:
    p = Path(path)
    kind = detect_format(p)
    if kind == "csv":
        if columns:
            from omavctl.logs.columnmap import read_mapped_csv

            return read_mapped_csv(p, columns).raw
        from omavctl.logs.csvlog import read_csv

        return read_csv(p, strict=strict).raw
    if kind in ("cfusdlog", "betaflight"):
        from omavctl.logs.columnlogs import load_table
        from omavctl.logs.tables import read_mapped_columns

        if not columns:
            raise LogError(
                f"a {FORMAT_LABELS[kind]} is read through a column map (the vehicle's "
                f"'columns:'); 'omavctl inspect {p}' suggests one",
                p,
            )
        return read_mapped_columns(load_table(p, kind), columns).raw
    if kind == "ulog":
        from omavctl.logs.ulog import read_mapped_ulog

        if not columns:
            raise LogError(
                "a ULog is read through a column map (the vehicle's 'columns:'); "
                f"'omavctl inspect {p}' suggests one",
                p,
            )
        return read_mapped_ulog(p, dict(columns)).raw
    names = merge_topics(topics)
    if kind == "mcap":
        return _read_mcap(p, names, strict)
    return _read_rosbag(p, kind, names, strict)


def read_raw(
    path: str | Path,
    topics: Mapping[str, str] | None = None,
    columns: Mapping[str, Any] | None = None,
) -> RawLog:
    """Read a flight log as recorded (no resampling).

    Args:
        path: a ROS 2 bag directory, a ``.bag``, ``.mcap``, ``.db3``, ``.ulg`` or ``.csv`` file.
        topics: topic role -> topic name, over :data:`DEFAULT_TOPICS` (e.g. a
            vehicle's ``topics``); ignored for CSV.
        columns: for a CSV of another layout or a PX4 ULog (required there), a
            column map (contract column -> source column with scale/offset, see
            :mod:`omavctl.logs.columnmap`, :mod:`omavctl.logs.ulog`); ignored for bags.

    Returns:
        A :class:`RawLog`: per signal role a :class:`RawSeries` (stamps shape (n,)
        in s since ``t0``, values shape (n, k)); header stamps are used when
        present and nonzero, else the log receive time. ``topics`` lists every
        topic in the file (unused ones timed by receive time).

    Raises:
        LogError: missing or unreadable file, corrupt/truncated bag, contract
            topic of the wrong message type, bad CSV.
        ConfigError: invalid ``topics`` or ``columns``.
    """
    return _read(path, topics, strict=True, columns=columns)
