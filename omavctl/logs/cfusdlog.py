"""Crazyflie SD-card logs: Bitcraze's binary "cfusdlog" format, versions 1 and 2.

The layout, as the Crazyflie firmware project's ``tools/usdlog/cfusdlog.py``
decodes it (all numbers little-endian)::

    u8   0xBC                       magic
    u16  version                    1 or 2
    u16  number of event types
    per event type:
        u16  event id
        str  event name             NUL-terminated
        u16  number of variables
        str  "name(t)" per variable NUL-terminated; t a struct code (f, I, i, H, B, ...)
    records until the last 4 bytes:
        u16  event id
        u32  time in ms (version 1) | u64 time in us (version 2)
        the event's variables, packed
    u32  CRC-32 of every byte before it

:func:`read_cfusdlog` checks the CRC and gives every event's variables as named
columns with ``timestamp`` in ms since the vehicle booted, as the firmware's
decoder and the shared decoded CSV name them (``timestamp``, ``acc.x``,
``gyro.x``, ``motor.m1``, ...). The records are decoded with numpy: one pass
finds where each record starts (a scan over the event ids; none when every
record has the same length), then one strided read per event type.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import LogError
from omavctl.logs.tables import ColumnGroup, ColumnTable

__all__ = [
    "MAGIC",
    "UNITS",
    "CfEvent",
    "CfUsdLog",
    "cfusdlog_table",
    "looks_like_cfusdlog",
    "read_cfusdlog",
]

#: First byte of every cfusdlog file.
MAGIC = 0xBC
_TYPES = {
    "f": "<f4", "d": "<f8", "b": "i1", "B": "u1", "h": "<i2", "H": "<u2",
    "i": "<i4", "I": "<u4", "l": "<i4", "L": "<u4", "q": "<i8", "Q": "<u8", "?": "?",
}  # fmt: skip
#: Units of the variables the Crazyflie logs under these groups (firmware log
#: variables: ``acc`` in g, ``gyro`` in deg/s, ``motor`` the PWM compare value).
UNITS = {"acc": "g", "gyro": "deg/s", "motor": "PWM 0-65535", "pwm": "PWM 0-65535"}


@dataclass
class CfEvent:
    """One event type: ``timestamp`` (n,) in ms and its variables by name, each (n,)."""

    name: str
    timestamp: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class CfUsdLog:
    """A decoded cfusdlog file: its format version and events in file order."""

    path: Path
    version: int
    events: list[CfEvent]


def looks_like_cfusdlog(head: bytes) -> bool:
    """Whether the first bytes are a cfusdlog header (magic, version 1 or 2)."""
    return len(head) >= 3 and head[0] == MAGIC and int.from_bytes(head[1:3], "little") in (1, 2)


class _Header:
    """Reads the header's fields, each read past the end an error naming the field."""

    def __init__(self, data: bytes, path: Path):
        self.data, self.path, self.pos = data, path, 0

    def uint(self, size: int, what: str) -> int:
        if self.pos + size > len(self.data):
            raise LogError(f"not a readable Crazyflie SD-card log: the header ends in {what}",
                           self.path)  # fmt: skip
        value = int.from_bytes(self.data[self.pos : self.pos + size], "little")
        self.pos += size
        return value

    def text(self, what: str) -> str:
        end = self.data.find(b"\x00", self.pos)
        if end < 0:
            raise LogError(f"not a readable Crazyflie SD-card log: the header ends in {what}",
                           self.path)  # fmt: skip
        raw = self.data[self.pos : end]
        self.pos = end + 1
        try:
            return raw.decode("ascii")
        except UnicodeDecodeError:
            raise LogError(f"not a readable Crazyflie SD-card log: {what} is not ASCII text",
                           self.path) from None  # fmt: skip


def _event_types(h: _Header, count: int) -> dict[int, tuple[str, np.dtype]]:
    """Event id -> (name, record payload dtype) from the header."""
    events: dict[int, tuple[str, np.dtype]] = {}
    bad = "not a readable Crazyflie SD-card log"
    for _ in range(count):
        event_id = h.uint(2, "an event id")
        name = h.text("an event name")
        fields: list[tuple[str, str]] = []
        for _ in range(h.uint(2, f"event '{name}'")):
            spec = h.text(f"a variable of event '{name}'")
            var, code = spec[:-3], spec[-2:-1]
            if len(spec) < 4 or spec[-3] != "(" or spec[-1] != ")" or code not in _TYPES:
                raise LogError(f"{bad}: variable '{spec}' of event '{name}' is not "
                               "'name(type)' with a known type", h.path)  # fmt: skip
            if var in {"timestamp", *(f for f, _ in fields)}:
                raise LogError(f"{bad}: event '{name}' names variable '{var}' twice", h.path)
            fields.append((var, _TYPES[code]))
        if event_id in events:
            raise LogError(f"{bad}: event id {event_id} is declared twice", h.path)
        events[event_id] = (name, np.dtype(fields))
    return events


def _record_starts(body: np.ndarray, sizes: dict[int, int], head: int, path: Path) -> np.ndarray:
    """Offsets (n,) of the records in ``body``: a stride when the first event's records
    fill it exactly, else a walk over the event ids."""
    first = int(body[0]) | int(body[1]) << 8 if body.size >= 2 else -1
    if first in sizes and body.size % sizes[first] == 0:
        starts = np.arange(0, body.size, sizes[first])
        ids = body[starts].astype(np.int64) | body[starts + 1].astype(np.int64) << 8
        if np.all(ids == first):
            return starts
    out: list[int] = []
    pos, n = 0, body.size
    raw = body.tobytes()
    while pos < n:
        event_id = int.from_bytes(raw[pos : pos + 2], "little")
        size = sizes.get(event_id)
        if size is None:
            raise LogError(f"not a readable Crazyflie SD-card log: unknown event id {event_id} "
                           f"at byte {head + pos}", path)  # fmt: skip
        if pos + size > n:
            raise LogError("not a readable Crazyflie SD-card log: the last record is cut "
                           f"short at byte {head + pos} (truncated?)", path)  # fmt: skip
        out.append(pos)
        pos += size
    return np.asarray(out, dtype=np.int64)


def read_cfusdlog(path: Path) -> CfUsdLog:
    """Decode a cfusdlog file (see the module docs).

    Returns:
        A :class:`CfUsdLog`: per event type its ``timestamp`` (n,) in ms (version 2's
        microseconds / 1000, as the firmware's decoder gives them) and its variables
        as columns (n,), in their logged type.

    Raises:
        LogError: unreadable file, wrong magic or version, a CRC that does not match
            (corrupt or truncated), a header or record that is cut short, an unknown
            event id, no records.
    """
    try:
        data = path.read_bytes()
    except OSError as err:
        raise LogError(f"cannot read: {err.strerror or err}", path) from None
    bad = "not a readable Crazyflie SD-card log"
    if not looks_like_cfusdlog(data[:3]):
        raise LogError(f"{bad}: it does not start with the cfusdlog header (0xBC, version 1 "
                       "or 2)", path)  # fmt: skip
    if len(data) < 9:
        raise LogError(f"{bad}: the file ends inside its header (truncated?)", path)
    stored = int.from_bytes(data[-4:], "little")
    if zlib.crc32(data[:-4]) != stored:
        raise LogError(f"{bad}: the CRC-32 at its end does not match its contents "
                       "(corrupt or truncated)", path)  # fmt: skip
    h = _Header(data[:-4], path)
    h.pos = 1
    version = h.uint(2, "the version")
    events = _event_types(h, h.uint(2, "the number of event types"))
    stamp = np.dtype("<u4") if version == 1 else np.dtype("<u8")
    sizes = {k: 2 + stamp.itemsize + dt.itemsize for k, (_, dt) in events.items()}
    body = np.frombuffer(data, dtype=np.uint8, count=len(data) - 4 - h.pos, offset=h.pos)
    if body.size == 0:
        raise LogError(f"{bad}: it holds no records", path)
    starts = _record_starts(body, sizes, h.pos, path)
    ids = body[starts].astype(np.int64) | body[starts + 1].astype(np.int64) << 8
    out = []
    for event_id, (name, dtype) in events.items():
        at = starts[ids == event_id]
        if at.size == 0:
            continue
        record = np.dtype([("id", "<u2"), ("t", stamp), ("v", dtype)])
        if at.size * record.itemsize == body.size:  # one event type: the body is its records
            rows = body.view(record)
        else:  # gather each record's bytes, then read them as the record type
            rows = body[at[:, None] + np.arange(record.itemsize)].copy().view(record)[:, 0]
        t_ms = rows["t"].astype(float) / (1.0 if version == 1 else 1000.0)
        columns = {var: rows["v"][var].copy() for var in dtype.names or ()}
        out.append(CfEvent(name=name, timestamp=t_ms, columns=columns))
    return CfUsdLog(path=path, version=version, events=out)


def cfusdlog_table(path: Path) -> ColumnTable:
    """A cfusdlog file as named columns (:class:`~.tables.ColumnTable`): the time
    column ``timestamp`` in ms (scale 1e-3 to s), each event type a group, its
    variables under their logged names (``event:variable`` where two event types
    log the same name). Units of the firmware's ``acc``, ``gyro``, ``motor`` and
    ``pwm`` groups are known (:data:`UNITS`); other variables are "as logged".

    Raises:
        LogError: see :func:`read_cfusdlog`.
    """
    log = read_cfusdlog(path)
    if not log.events:
        raise LogError("not a readable Crazyflie SD-card log: it holds no records", path)
    counts: dict[str, int] = {}
    for event in log.events:
        for var in event.columns:
            counts[var] = counts.get(var, 0) + 1
    groups = []
    units = {"timestamp": "ms since boot"}
    for event in log.events:
        columns = {}
        for var, values in event.columns.items():
            name = var if counts[var] == 1 else f"{event.name}:{var}"
            columns[name] = values.astype(float)
            units[name] = UNITS.get(var.split(".", 1)[0], "as logged")
        groups.append(ColumnGroup(event.name, event.timestamp, columns))
    meta: dict[str, Any] = {"version": log.version, "events": [e.name for e in log.events]}
    return ColumnTable(path, "cfusdlog", "timestamp", 1e-3, groups, units, meta)
