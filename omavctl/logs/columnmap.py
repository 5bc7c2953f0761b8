"""CSV logs of other layouts, read through a column map (DESIGN.md section 3).

A column map says, for each wide-CSV column name of the contract (``t``,
``body_rate_x``, ``force_command_z``, ...), where its values come from::

    columns:
      t: {column: TIME_StartTime, scale: 1.0e-6}   # us -> s
      body_rate_x: IMU_GyroX                       # shorthand: just the column
      body_rate_y: IMU_GyroY
      body_rate_z: IMU_GyroZ
      force_command_x: {value: 0.0}                # a constant
      force_command_z: {column: ATTC_Thrust, scale: 160.0, offset: 0.0}

Each value is ``cell * scale + offset``. A role is read when all of its
columns are mapped. Cells that are empty or ``nan`` mean "not updated in this
row" (as in PX4's sdlog2 CSV dumps): each role keeps the rows where all of its
columns have values, so roles may have different stamps. Rows without a time
are skipped. A non-numeric cell is an error naming column and row.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.errors import ConfigError, LogError
from omavctl.logs.csvlog import CsvRead, csv_columns
from omavctl.logs.stats import topic_info
from omavctl.logs.types import ROLE_COLUMNS, RawLog, RawSeries

__all__ = ["ColumnSpec", "parse_column_map", "read_mapped_csv"]

_MISSING_CELLS = {"", "nan", "NaN", "NAN", "na", "NA", "null", "None"}


@dataclass(frozen=True)
class ColumnSpec:
    """Source of one contract column: ``column`` (scaled, offset) or a constant ``value``."""

    column: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    value: float | None = None


def _number(value: Any, key: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"key '{key}' must be a number") from None
    if not math.isfinite(x):
        raise ConfigError(f"key '{key}' must be finite")
    return x


def parse_column_map(columns: Mapping[str, Any]) -> dict[str, ColumnSpec]:
    """Validate a column map (see module docs); keys are reported as ``columns.<key>``.

    Raises:
        ConfigError: unknown contract column, bad entry, no ``t``, or a role
            with only some of its columns mapped.
    """
    known = {"t"} | {c for role in ROLE_COLUMNS for c in csv_columns(role)}
    specs: dict[str, ColumnSpec] = {}
    for key, entry in columns.items():
        name = f"columns.{key}"
        if key not in known:
            raise ConfigError(
                f"unknown key '{name}': keys are 't' and wide-CSV columns such as body_rate_x"
            )
        if isinstance(entry, str) and entry:
            specs[key] = ColumnSpec(column=entry)
            continue
        if not isinstance(entry, Mapping):
            raise ConfigError(f"key '{name}' must be a column name or a mapping")
        extra = set(entry) - {"column", "scale", "offset", "value"}
        if extra:
            raise ConfigError(f"unknown key '{name}.{sorted(extra)[0]}'")
        if "value" in entry:
            if "column" in entry:
                raise ConfigError(f"key '{name}' has both 'column' and 'value'")
            if key == "t":
                raise ConfigError("key 'columns.t' must name a column, not a value")
            specs[key] = ColumnSpec(value=_number(entry["value"], f"{name}.value"))
            continue
        column = entry.get("column")
        if not isinstance(column, str) or not column:
            raise ConfigError(f"key '{name}.column' must be a column name")
        specs[key] = ColumnSpec(
            column=column,
            scale=_number(entry.get("scale", 1.0), f"{name}.scale"),
            offset=_number(entry.get("offset", 0.0), f"{name}.offset"),
        )
    if "t" not in specs:
        raise ConfigError(
            "key 'columns.t' is missing: the column map must say which column is time"
        )
    for role in ROLE_COLUMNS:
        cols = csv_columns(role)
        mapped = [c for c in cols if c in specs]
        if mapped and len(mapped) < len(cols):
            missing = ", ".join(c for c in cols if c not in specs)
            raise ConfigError(f"column map has {', '.join(mapped)} but not {missing}")
    return specs


def _parse_column(
    rows: list[list[str]], j: int, name: str, lines: list[int], path: Path
) -> np.ndarray:
    """Cells of column ``j`` as floats, NaN where empty/nan; shape (n,)."""
    out = np.empty(len(rows))
    for i, row in enumerate(rows):
        cell = row[j].strip() if j < len(row) else ""
        if cell in _MISSING_CELLS:
            out[i] = np.nan
            continue
        try:
            out[i] = float(cell)
        except ValueError:
            shown = cell if len(cell) <= 20 else cell[:17] + "..."
            raise LogError(
                f"non-numeric value '{shown}' in column '{name}' at row {i + 1} (line {lines[i]})",
                path,
            ) from None
    return out


def read_mapped_csv(path: Path, columns: Mapping[str, Any]) -> CsvRead:
    """Read a CSV of any layout through a column map (see module docs).

    Returns the :class:`RawLog` (format ``"csv"``; ``t0`` the earliest time,
    stamps in s from it) and (min, max) of each contract column read.
    """
    specs = parse_column_map(columns)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise LogError("not a CSV file: it is not UTF-8 text", path) from None
    except OSError as err:
        raise LogError(f"cannot read: {err.strerror or err}", path) from err
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader, [])]
    if not any(header):
        raise LogError("not a CSV log: the first line must be a header", path)
    rows: list[list[str]] = []
    lines: list[int] = []
    for row in reader:
        if row and any(c.strip() for c in row):
            rows.append(row)
            lines.append(reader.line_num)
    if not rows:
        raise LogError("no data rows below the header", path)
    index = {name: j for j, name in enumerate(header)}

    def column(key: str) -> np.ndarray:
        spec = specs[key]
        if spec.value is not None:
            return np.full(len(rows), spec.value)
        assert spec.column is not None
        if spec.column not in index:
            raise LogError(f"missing column '{spec.column}' (mapped to {key})", path)
        raw = _parse_column(rows, index[spec.column], spec.column, lines, path)
        return raw * spec.scale + spec.offset

    notes: list[str] = []
    t_all = column("t")
    has_t = np.isfinite(t_all)
    if not has_t.any():
        raise LogError(f"column '{specs['t'].column}' (time) has no numeric value", path)
    if not has_t.all():
        notes.append(f"{int((~has_t).sum())} rows without a time value skipped")
    t0 = float(t_all[has_t].min())
    series: dict[str, RawSeries] = {}
    topics = []
    ranges: dict[str, tuple[float, float]] = {}
    for role in ROLE_COLUMNS:
        keys = csv_columns(role)
        if keys[0] not in specs:
            continue
        values = np.column_stack([column(k) for k in keys])
        ok = has_t & np.isfinite(values).all(axis=1)
        if not ok.any():
            notes.append(f"{role}: no row has values in all of its columns; not read")
            continue
        skipped = int(has_t.sum() - ok.sum())
        if skipped:
            notes.append(f"{role}: {skipped} rows with empty cells skipped")
        stamps = t_all[ok] - t0
        series[role] = RawSeries(stamps=stamps, values=values[ok])
        topics.append(topic_info(role, "csv columns (mapped)", stamps))
        for j, key in enumerate(keys):
            ranges[key] = (float(values[ok, j].min()), float(values[ok, j].max()))
    raw = RawLog(path=path, format="csv", t0=t0, series=series, topics=topics, notes=notes)
    return CsvRead(raw=raw, ranges=ranges)
