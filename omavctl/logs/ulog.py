"""PX4 ULog files (``.ulg``): read with pyulog, flattened into named columns.

A ULog holds uORB topics, each at its own rate with its own ``timestamp``
(microseconds since boot). Every numeric field becomes a column named
``topic.field`` (``topic_N.field`` for instance N > 0 of a multi-instance topic),
as PX4's ``ulog2csv`` names them: ``sensor_combined.gyro_rad[0]``,
``vehicle_attitude.q[0]``, ``actuator_controls_0.control[3]``. The column
``timestamp`` is the time of every row.

No topic of a ULog carries the contract's roles under the contract's names, so a
ULog is read through a column map, like a CSV of another layout
(:mod:`omavctl.logs.columnmap`; ``time: {column: timestamp, scale: 1.0e-6}``), and
``omavctl inspect`` suggests one. The table a map reads holds the rows of the
topics it names, in time order, each row with values only in its own topic's
columns: a role's columns must come from one topic.

pyulog (BSD-3-Clause, PX4's own parser) is imported only when a ULog is read.
"""

from __future__ import annotations

import contextlib
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import LogError, library_reason
from omavctl.logs.colnames import ColumnScan
from omavctl.logs.columnmap import (
    QUATERNION_ROLES,
    ColumnSpec,
    MappedTable,
    parse_column_map,
    quaternion_columns,
    read_mapped,
)
from omavctl.logs.csvlog import CsvRead, csv_columns
from omavctl.logs.types import ROLE_COLUMNS

__all__ = [
    "PX4_COLUMNS",
    "TIME_COLUMN",
    "ULOG_UNITS",
    "UlogTopics",
    "load_ulog",
    "read_mapped_ulog",
    "scan_ulog",
    "ulog_unit",
]

#: The time column of every row, microseconds.
TIME_COLUMN = "timestamp"


def _xyz(stem: str, axes: str = "xyz") -> dict[str, str]:
    return {a: f"{stem}[{i}]" for i, a in enumerate(axes)}


#: PX4's topics for the contract roles, newest message set first: (role, axis ->
#: column, quaternion). ``actuator_controls_0`` holds the rate controller's normalised
#: roll/pitch/yaw torque and thrust (0..1, along -z of the FRD body frame); PX4 1.13
#: and later log ``vehicle_torque_setpoint`` / ``vehicle_thrust_setpoint`` instead.
PX4_COLUMNS: tuple[tuple[str, dict[str, str], bool], ...] = (
    ("body_rate", _xyz("vehicle_angular_velocity.xyz"), False),
    ("body_rate", _xyz("sensor_combined.gyro_rad"), False),
    ("attitude", _xyz("vehicle_attitude.q", "wxyz"), True),
    ("torque_command", _xyz("vehicle_torque_setpoint.xyz"), False),
    ("torque_command", _xyz("actuator_controls_0.control"), False),
    ("force_command", {"z": "vehicle_thrust_setpoint.xyz[2]"}, False),
    ("force_command", {"z": "actuator_controls_0.control[3]"}, False),
    # the accelerometer's specific force (gravity included, m/s^2 FRD): drag_moment
    ("specific_force", _xyz("vehicle_acceleration.xyz"), False),
    ("specific_force", _xyz("sensor_combined.accelerometer_m_s2"), False),
)


#: Units of the ULog fields a column map reads most, by topic.field without the index
#: (PX4's uORB message definitions; instance N > 0 of a topic shares them).
ULOG_UNITS = {
    "sensor_combined.gyro_rad": "rad/s FRD",
    "sensor_combined.accelerometer_m_s2": "m/s^2 FRD (specific force)",
    "vehicle_acceleration.xyz": "m/s^2 FRD (specific force)",
    "vehicle_angular_velocity.xyz": "rad/s FRD",
    "vehicle_attitude.q": "quaternion FRD/NED",
    "actuator_controls_0.control": "normalised -1..1 (control[3] thrust 0..1)",
    "vehicle_torque_setpoint.xyz": "normalised -1..1 FRD",
    "vehicle_thrust_setpoint.xyz": "normalised -1..1 FRD",
    "actuator_outputs.output": "output value, PWM us for PWM outputs (the first noutputs used)",
    "actuator_outputs.noutputs": "count",
    "actuator_motors.control": "normalised motor thrust 0..1 (-1..1 reversible; NaN off)",
    "battery_status.voltage_v": "V",
    "battery_status.voltage_filtered_v": "V",
    "battery_status.current_a": "A",
    "battery_status.remaining": "fraction 0..1",
}


def ulog_unit(column: str) -> str:
    """Unit of a ULog column (``topic.field[i]``, ``topic_N.field``), "as logged" when
    :data:`ULOG_UNITS` does not know it."""
    topic, _, fieldname = column.partition(".")
    key = f"{re.sub(r'_[0-9]+$', '', topic)}.{fieldname.split('[')[0]}"
    if key in ULOG_UNITS:
        return ULOG_UNITS[key]
    return ULOG_UNITS.get(f"{topic}.{fieldname.split('[')[0]}", "as logged")


@dataclass
class UlogTopics:
    """The numeric data of a ULog: per topic (``topic`` or ``topic_N``) its
    timestamps (n,) in us and its fields by column name (``topic.field``), each (n,)."""

    path: Path
    topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]
    #: what reading it noticed (corrupt data, dropouts, topics without time), for notes
    notes: list[str]

    def column_topic(self) -> dict[str, str]:
        """Topic of every column."""
        return {name: topic for topic, (_, cols) in self.topics.items() for name in cols}


def load_ulog(path: Path) -> UlogTopics:
    """Read every topic of a ULog (numeric fields as float64).

    Raises:
        LogError: the file cannot be parsed, or holds no data.
    """
    from pyulog import ULog

    said = io.StringIO()  # pyulog prints its warnings: they become a note
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            ulog = ULog(str(path))
    except Exception as err:  # pyulog raises plain exceptions on corrupt input
        raise LogError(f"not a readable ULog file: {library_reason(err)}", path) from err
    topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    untimed: list[str] = []
    for data in ulog.data_list:
        stamps = np.asarray(data.data.get(TIME_COLUMN, ()), dtype=float)
        prefix = data.name if data.multi_id == 0 else f"{data.name}_{data.multi_id}"
        if stamps.size == 0:
            continue
        if stamps.size > 1 and stamps.min() == stamps.max():
            untimed.append(prefix)
            continue
        fields = {
            f"{prefix}.{field}": np.asarray(values, dtype=float)
            for field, values in data.data.items()
            if field != TIME_COLUMN and np.asarray(values).dtype.kind in "fiub"
        }
        topics[prefix] = (stamps, fields)
    if not topics:
        raise LogError("not a readable ULog file: it holds no logged data", path)
    notes = []
    complaint = next((ln.strip() for ln in said.getvalue().splitlines() if ln.strip()), "")
    if ulog.file_corruption or complaint:
        notes.append(f"the file is corrupt in places ({complaint or 'pyulog'}): read what it could")
    if untimed:
        notes.append(
            f"topics whose messages all carry one timestamp, not read: {', '.join(untimed)}"
        )
    if ulog.dropouts:
        lost = sum(d.duration for d in ulog.dropouts)
        notes.append(f"the logger dropped data {len(ulog.dropouts)} times ({lost} ms in all)")
    return UlogTopics(path=path, topics=topics, notes=notes)


def scan_ulog(u: UlogTopics) -> ColumnScan:
    """Every column of a ULog for ``inspect``'s column-map guess: ``timestamp`` over
    all rows, each field over its own topic's rows only (the arrays differ in
    length; nothing is padded)."""
    stamps = np.sort(np.concatenate([st for st, _ in u.topics.values()]))
    scan = ColumnScan(path=u.path, header=[TIME_COLUMN], rows=stamps.size)
    scan.values[TIME_COLUMN] = stamps
    for _, fields in u.topics.values():
        for name, values in fields.items():
            scan.header.append(name)
            finite = values[np.isfinite(values)]
            if finite.size:
                scan.values[name] = finite
            else:
                scan.empty.append(name)
    return scan


def read_mapped_ulog(path: Path, columns: dict[str, Any]) -> CsvRead:
    """Read a ULog through a column map (see module docs); the :class:`RawLog` has
    format ``"ulog"``.

    Raises:
        ConfigError: invalid map.
        LogError: unreadable file, a mapped column that is not in the file.
    """
    specs = parse_column_map(columns)
    u = load_ulog(path)
    owner = u.column_topic()
    _one_topic_per_role(specs, owner, path)
    used = sorted({owner[s.column] for s in specs.values() if s.column in owner})
    stamps = [u.topics[t][0] for t in used]
    all_stamps = np.concatenate(stamps) if stamps else np.zeros(0)
    order = np.argsort(all_stamps, kind="stable")
    starts = np.cumsum([0] + [s.size for s in stamps])
    block = {t: (int(starts[i]), int(starts[i + 1])) for i, t in enumerate(used)}

    def source(name: str) -> np.ndarray:
        if name == TIME_COLUMN:
            return all_stamps[order]
        out = np.full(all_stamps.size, np.nan)
        lo, hi = block[owner[name]]
        out[lo:hi] = u.topics[owner[name]][1][name]
        return out[order]

    header = [TIME_COLUMN, *owner]
    table = MappedTable(path, "ulog", header, all_stamps.size, source, sparse=True)
    return read_mapped(table, specs, u.notes)


def _one_topic_per_role(specs: dict[str, ColumnSpec], owner: dict[str, str], path: Path) -> None:
    """Refuse a map that takes one role's axes from two topics: each row of a ULog's
    table holds one topic's values, so no row would hold them all."""
    for role in ROLE_COLUMNS:
        keys = csv_columns(role) + (quaternion_columns(role) if role in QUATERNION_ROLES else [])
        used = [specs[k].column for k in keys if k in specs]
        topics = sorted({owner[c] for c in used if c in owner})
        if len(topics) > 1:
            raise LogError(
                f"the column map takes {role} from {len(topics)} topics ({', '.join(topics)}): "
                "a role's axes must come from one topic of a ULog",
                path,
            )
