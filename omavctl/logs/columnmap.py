"""CSV logs of other layouts, read through a column map (DESIGN.md section 3).

A column map says where each contract signal comes from. Two spellings are
accepted, and may be mixed in one map.

Role-based (what users write in the vehicle YAML)::

    columns:
      time: {column: TIME_StartTime, scale: 1.0e-6}               # us -> s
      body_rate: {x: IMU_GyroX, y: IMU_GyroY, z: IMU_GyroZ}
      torque_command: {x: ATTC_Roll, y: ATTC_Pitch, z: ATTC_Yaw, scale: 1.0}
      force_command: {z: ATTC_Thrust}            # missing axes are zero (commands only)
      attitude: {roll: ATT_Roll, pitch: ATT_Pitch, yaw: ATT_Yaw}
      # or attitude: {quaternion: {w: ATT_qw, x: ATT_qx, y: ATT_qy, z: ATT_qz}}

A role maps its axes (:data:`ROLE_COLUMNS`: ``x/y/z``, ``roll/pitch/yaw``,
``0..5`` for ``tilt``) to columns. Role-level ``scale``/``offset`` apply to all
its axes; an axis may be ``{column:, scale:, offset:}`` itself, and then the
value is ``(cell * axis_scale + axis_offset) * role_scale + role_offset``.
Only ``force_command``, ``torque_command`` and ``motor_command`` may leave axes
out (they are 0). ``motor_command`` (raw per-output motor commands in the
vehicle's output order, :mod:`omavctl.rotors`) is also given as a list:
``motor_command: [motor.m1, motor.m2, motor.m3, motor.m4]`` maps outputs 0..3.
A role of one column (``battery_voltage``, V) is given as the time is:
``battery_voltage: vbatLatest`` or ``{column: vbat, scale: 0.01}``.

Flat (one key per wide-CSV column, converted from the role-based form by
:func:`flatten_column_map`)::

    columns:
      t: {column: TIME_StartTime, scale: 1.0e-6}
      body_rate_x: IMU_GyroX                       # shorthand: just the column
      force_command_x: {value: 0.0}                # a constant
      force_command_z: {column: ATTC_Thrust, scale: 160.0, offset: 0.0}
      attitude_qw: ATT_qw                          # quaternion (w, x, y, z) of attitude

Each value is ``cell * scale + offset``. A role is read when all of its
columns are mapped. Cells that are empty or ``nan`` mean "not updated in this
row" (as in PX4's sdlog2 CSV dumps): each role keeps the rows where all of its
columns have values, so roles may have different stamps. Rows without a time
are skipped. A missing column or a non-numeric cell is a :class:`LogError`
naming the column and the file; a bad map is a :class:`ConfigError` naming the key.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError, LogError
from omavctl.logs.contract import euler_from_quaternion
from omavctl.logs.csvlog import (
    CsvRead,
    csv_columns,
    cut_row_notes,
    parse_column,
    read_table,
    rows_skipped,
)
from omavctl.logs.stats import topic_info
from omavctl.logs.types import ROLE_COLUMNS, RawLog, RawSeries

__all__ = [
    "COMMAND_ROLES",
    "QUATERNION_ROLES",
    "ColumnSpec",
    "flatten_column_map",
    "parse_column_map",
    "quaternion_columns",
    "read_mapped_csv",
]

#: Roles whose unmapped axes are zero in a role-based map.
COMMAND_ROLES: tuple[str, ...] = ("force_command", "torque_command", "motor_command")
#: Roles that may be given as a quaternion ``(w, x, y, z)`` instead of Euler angles.
QUATERNION_ROLES: tuple[str, ...] = ("attitude", "reference_attitude")
_QUAT_AXES = ("w", "x", "y", "z")
#: Role-based key of the time column (flat key ``t``).
TIME_ROLE = "time"

_SPEC_KEYS = {"column", "scale", "offset", "value"}


def quaternion_columns(role: str) -> list[str]:
    """Flat keys of a role given as a quaternion: ``attitude_qw .. attitude_qz``."""
    return [f"{role}_q{a}" for a in _QUAT_AXES]


@dataclass(frozen=True)
class ColumnSpec:
    """Source of one contract column: ``column`` (scaled, offset) or a constant ``value``.

    ``label`` is the key as the user wrote it (``body_rate_x`` or ``body_rate.x``),
    used in messages.
    """

    column: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    value: float | None = None
    label: str = ""


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"key '{key}' must be a number")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"key '{key}' must be a number") from None
    if not math.isfinite(x):
        raise ConfigError(f"key '{key}' must be finite")
    return x


def _flat_keys() -> set[str]:
    keys = {"t"} | {c for role in ROLE_COLUMNS for c in csv_columns(role)}
    return keys | {c for role in QUATERNION_ROLES for c in quaternion_columns(role)}


def _axis_entry(entry: Any, name: str, scale: float, offset: float) -> dict[str, Any]:
    """One axis of a role-based entry as a flat entry, role scale/offset composed in."""
    if isinstance(entry, str):
        if not entry:
            raise ConfigError(f"key '{name}' must be a column name")
        entry = {"column": entry}
    if not isinstance(entry, Mapping):
        raise ConfigError(f"key '{name}' must be a column name or a mapping")
    extra = set(entry) - _SPEC_KEYS
    if extra:
        raise ConfigError(f"unknown key '{name}.{sorted(map(str, extra))[0]}'")
    if "value" in entry:
        if "column" in entry:
            raise ConfigError(f"key '{name}' has both 'column' and 'value'")
        return {"value": _number(entry["value"], f"{name}.value") * scale + offset}
    column = entry.get("column")
    if not isinstance(column, str) or not column:
        raise ConfigError(f"key '{name}.column' must be a column name")
    s = _number(entry.get("scale", 1.0), f"{name}.scale")
    o = _number(entry.get("offset", 0.0), f"{name}.offset")
    return {"column": column, "scale": s * scale, "offset": o * scale + offset}


def _expand_role(role: str, entry: Any) -> dict[str, tuple[Any, str]]:
    """Flat entries ``{flat key: (entry, label)}`` of one role-based entry."""
    name = f"columns.{role}"
    if role == TIME_ROLE:
        return {"t": (_axis_entry(entry, name, 1.0, 0.0), TIME_ROLE)}
    axes = ROLE_COLUMNS[role]
    if len(axes) == 1 and (
        isinstance(entry, str)
        or (isinstance(entry, Mapping) and ("column" in entry or "value" in entry))
    ):  # one column: as the time's
        return {csv_columns(role)[0]: (_axis_entry(entry, name, 1.0, 0.0), role)}
    if role == "motor_command" and isinstance(entry, list):  # outputs in order
        entry = dict(enumerate(entry))
    if not isinstance(entry, Mapping):
        example = ", ".join(f"{a}: ..." for a in axes[:3])
        raise ConfigError(f"key '{name}' must be a mapping of axes to columns, e.g. {{{example}}}")
    entry = {str(k): v for k, v in entry.items()}
    scale = _number(entry.get("scale", 1.0), f"{name}.scale")
    offset = _number(entry.get("offset", 0.0), f"{name}.offset")
    given = {k: v for k, v in entry.items() if k not in ("scale", "offset")}
    if role in QUATERNION_ROLES and ("quaternion" in given or "w" in given):
        if "quaternion" in given:
            if set(given) != {"quaternion"}:
                other = sorted(set(given) - {"quaternion"})[0]
                raise ConfigError(f"key '{name}' has both 'quaternion' and '{other}'")
            quat = given["quaternion"]
            qname = f"{name}.quaternion"
            if not isinstance(quat, Mapping):
                raise ConfigError(f"key '{qname}' must be a mapping {{w:, x:, y:, z:}}")
            quat = {str(k): v for k, v in quat.items()}
        else:
            quat, qname = given, name
        unknown = sorted(set(quat) - set(_QUAT_AXES))
        if unknown:
            raise ConfigError(
                f"unknown key '{qname}.{unknown[0]}': quaternion components are w, x, y, z"
            )
        missing = [a for a in _QUAT_AXES if a not in quat]
        if missing:
            raise ConfigError(f"key '{qname}' is missing component {', '.join(missing)}")
        label = qname.removeprefix("columns.")  # attitude.quaternion (or attitude for w..z)
        return {
            key: (_axis_entry(quat[a], f"{qname}.{a}", scale, offset), f"{label}.{a}")
            for key, a in zip(quaternion_columns(role), _QUAT_AXES, strict=True)
        }
    unknown = sorted(set(given) - set(axes))
    if unknown:
        also = " (or a quaternion w, x, y, z)" if role in QUATERNION_ROLES else ""
        raise ConfigError(
            f"unknown key '{name}.{unknown[0]}': {role} axes are {', '.join(axes)}{also}"
        )
    if not given:
        raise ConfigError(f"key '{name}' maps no axis to a column")
    missing = [a for a in axes if a not in given]
    if missing and role not in COMMAND_ROLES:
        raise ConfigError(
            f"key '{name}' is missing axis {', '.join(missing)} ({role} needs {', '.join(axes)})"
        )
    out: dict[str, tuple[Any, str]] = {}
    for key, axis in zip(csv_columns(role), axes, strict=True):
        if axis in given:
            out[key] = (_axis_entry(given[axis], f"{name}.{axis}", scale, offset), f"{role}.{axis}")
        else:
            out[key] = ({"value": 0.0}, f"{role}.{axis}")
    return out


def _expand(columns: Mapping[str, Any]) -> tuple[dict[str, tuple[Any, str]], bool]:
    """Every entry as ``{flat key: (flat entry, label)}``; whether any key was role-based."""
    if not isinstance(columns, Mapping):
        raise ConfigError("key 'columns' must be a mapping of roles to columns")
    known = _flat_keys()
    roles = {TIME_ROLE, *ROLE_COLUMNS}
    flat: dict[str, tuple[Any, str]] = {}
    role_based = False
    for raw_key, entry in columns.items():
        key = str(raw_key)
        if key in roles:
            role_based = True
            expanded = _expand_role(key, entry)
        elif key in known:
            expanded = {key: (entry, key)}
        else:
            listed = ", ".join([TIME_ROLE, *ROLE_COLUMNS])
            raise ConfigError(
                f"unknown key 'columns.{key}': expected a role ({listed}) "
                "or a wide-CSV column such as body_rate_x"
            )
        for flat_key, item in expanded.items():
            if flat_key in flat:
                first = flat[flat_key][1]
                raise ConfigError(
                    f"key 'columns.{item[1]}' maps {flat_key} again (also columns.{first})"
                )
            flat[flat_key] = item
    return flat, role_based


def flatten_column_map(columns: Mapping[str, Any]) -> dict[str, Any]:
    """The flat form of a column map (role-based entries expanded, flat ones kept).

    E.g. ``{"force_command": {"z": "T", "scale": 2.0}}`` gives
    ``{"force_command_x": {"value": 0.0}, "force_command_y": {"value": 0.0},
    "force_command_z": {"column": "T", "scale": 2.0, "offset": 0.0}}``.

    Raises:
        ConfigError: unknown role or axis, bad entry (see :func:`parse_column_map`).
    """
    flat, _ = _expand(columns)
    return {key: entry for key, (entry, _label) in flat.items()}


def parse_column_map(columns: Mapping[str, Any]) -> dict[str, ColumnSpec]:
    """Validate a column map (either spelling, see module docs); keys are reported as
    ``columns.<key>``.

    Returns one :class:`ColumnSpec` per flat key (``t``, ``body_rate_x``, ...,
    ``attitude_qw`` for a quaternion).

    Raises:
        ConfigError: unknown role, axis or column key, bad entry, no time
            column, a role with only some of its columns mapped, or a role
            given both as Euler angles and as a quaternion.
    """
    flat, role_based = _expand(columns)
    specs: dict[str, ColumnSpec] = {}
    for key, (entry, label) in flat.items():
        name = f"columns.{label}"
        spec = _axis_entry(entry, name, 1.0, 0.0)  # validates either spelling
        if "value" in spec:
            if key == "t":
                raise ConfigError(f"key '{name}' must name a column, not a value")
            specs[key] = ColumnSpec(value=spec["value"], label=label)
        else:
            specs[key] = ColumnSpec(
                column=spec["column"], scale=spec["scale"], offset=spec["offset"], label=label
            )
    if "t" not in specs:
        key = TIME_ROLE if role_based else "t"
        raise ConfigError(
            f"key 'columns.{key}' is missing: the column map must say which column is time"
        )
    for role in ROLE_COLUMNS:
        groups = [csv_columns(role)]
        if role in QUATERNION_ROLES:
            groups.append(quaternion_columns(role))
        for cols in groups:
            mapped = [c for c in cols if c in specs]
            if mapped and len(mapped) < len(cols):
                missing = ", ".join(c for c in cols if c not in specs)
                raise ConfigError(f"column map has {', '.join(mapped)} but not {missing}")
        if role in QUATERNION_ROLES and all(
            g[0] in specs for g in (csv_columns(role), quaternion_columns(role))
        ):
            raise ConfigError(f"column map gives {role} both as Euler angles and as a quaternion")
    return specs


def _missing_column(column: str, label: str, header: list[str], path: Path) -> LogError:
    close = set(difflib.get_close_matches(column, header, n=3, cutoff=0.75))
    shown = [h for h in header if h in close]
    if label == TIME_ROLE and not shown:  # time columns are named alike, not spelled alike
        shown = sorted((h for h in header if "time" in h.lower() or "stamp" in h.lower()),
                       key=lambda h: (_time_rank(h), header.index(h)))[:3]  # fmt: skip
    names = ", ".join(f"'{h}'" for h in shown)
    hint = f"; similar columns in the file: {names}" if shown else ""
    return LogError(f"missing column '{column}' (mapped to {label}){hint}", path)


def _time_rank(name: str) -> int:
    """0 for a plain time column (t, time, timestamp), 1 for one starting with time, 2 else."""
    low = name.lower()
    return 0 if low in ("t", "time", "timestamp") else 1 if low.startswith("time") else 2


def read_mapped_csv(path: Path, columns: Mapping[str, Any]) -> CsvRead:
    """Read a CSV of any layout through a column map (see module docs).

    Returns the :class:`RawLog` (format ``"csv"``; ``t0`` the earliest time,
    stamps in s from it; ``mapped`` names the source columns of each role) and
    (min, max) of each contract column read. A quaternion role is converted to
    ZYX Euler angles; rows with a zero quaternion count as empty.

    Raises:
        ConfigError: invalid map.
        LogError: unreadable file, a mapped column missing from the header, a
            non-numeric cell in a mapped column, no numeric time value.
    """
    specs = parse_column_map(columns)
    table = read_table(path)
    index = {name: j for j, name in enumerate(table.header)}
    parsed: dict[str, np.ndarray] = {}

    def source(name: str) -> np.ndarray:
        if name not in parsed:
            parsed[name] = parse_column(table.cells(index[name]), name, table.lines, path)
        return parsed[name]

    table_of = MappedTable(path, "csv", table.header, len(table.rows), source)
    return read_mapped(table_of, specs, cut_row_notes(table))


@dataclass
class MappedTable:
    """Numeric columns of a log of another layout, as a column map reads them:
    ``header`` every column name, ``rows`` the row count, ``source(name)`` the
    values (rows,) of one column, NaN where a row has none; ``format`` the
    :class:`RawLog` format. ``sparse``: rows hold values of one source only by
    construction (a ULog's topics), so rows without a role's values are not noted."""

    path: Path
    format: str
    header: list[str]
    rows: int
    source: Callable[[str], np.ndarray]
    sparse: bool = False


def read_mapped(table: MappedTable, specs: dict[str, ColumnSpec], notes: list[str]) -> CsvRead:
    """Read a table of another layout through parsed column map ``specs`` (see
    :func:`read_mapped_csv`); ``notes`` so far."""
    path, rows = table.path, table.rows
    index = set(table.header)

    def column(key: str) -> np.ndarray:
        spec = specs[key]
        if spec.value is not None:
            return np.full(rows, spec.value)
        assert spec.column is not None
        return table.source(spec.column) * spec.scale + spec.offset

    # every mapped column must exist before any is parsed: report the first missing one
    for spec in specs.values():
        if spec.column is not None and spec.column not in index:
            raise _missing_column(spec.column, spec.label, table.header, path)

    t_all = column("t")
    has_t = np.isfinite(t_all)
    if not has_t.any():
        raise LogError(f"column '{specs['t'].column}' (time) has no numeric value", path)
    if not has_t.all():
        notes.append(rows_skipped(int((~has_t).sum()), "without a time value"))
    t0 = float(t_all[has_t].min())
    series: dict[str, RawSeries] = {}
    topics = []
    mapped: dict[str, str] = {}
    ranges: dict[str, tuple[float, float]] = {}
    for role in ROLE_COLUMNS:
        quat = role in QUATERNION_ROLES and quaternion_columns(role)[0] in specs
        src_keys = quaternion_columns(role) if quat else csv_columns(role)
        if src_keys[0] not in specs:
            continue
        sources = [c for c in (specs[k].column for k in src_keys) if c is not None]
        mapped[role] = "columns " + ", ".join(sources) if sources else "constants"
        src = np.column_stack([column(k) for k in src_keys])
        read = _mapped_role(role, src, quat, has_t, [] if table.sparse else notes)
        if read is None:
            continue
        ok, values = read
        stamps = t_all[ok] - t0
        series[role] = RawSeries(stamps=stamps, values=values)
        topics.append(topic_info(role, f"{table.format} columns (mapped)", stamps))
        for j, key in enumerate(csv_columns(role)):
            if role == "motor_command" and specs[key].column is None:
                continue  # an output the map does not name (0)
            ranges[key] = (float(values[:, j].min()), float(values[:, j].max()))
    raw = RawLog(
        path=path,
        format=table.format,
        t0=t0,
        series=series,
        topics=topics,
        notes=notes,
        mapped=mapped,
    )
    return CsvRead(raw=raw, ranges=ranges)


def _mapped_role(
    role: str, src: np.ndarray, quat: bool, has_t: np.ndarray, notes: list[str]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Rows (mask (n,)) of one role with a value in every source column, and the values.

    ``src`` (n, k) holds the mapped source columns (w, x, y, z for a
    quaternion, converted to ZYX Euler angles here). ``None`` (with a note)
    when no row has them.
    """
    ok = has_t & np.isfinite(src).all(axis=1)
    if quat:
        ok &= np.linalg.norm(np.where(np.isfinite(src), src, 0.0), axis=1) > 0
    if not ok.any():
        why = "a non-zero quaternion" if quat else "values in all of its columns"
        notes.append(f"{role}: no row has {why}; not read")
        return None
    skipped = int(has_t.sum() - ok.sum())
    if skipped:
        notes.append(f"{role}: " + rows_skipped(skipped, "with empty cells"))
    if quat:
        w, x, y, z = src[ok].T
        return ok, euler_from_quaternion(np.column_stack([x, y, z, w]))
    return ok, src[ok]
