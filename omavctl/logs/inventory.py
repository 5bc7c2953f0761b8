"""The column inventory of a log read through a column map: every column with its
group, count, rate, unit and range, and what the log's header says.

:func:`column_inventory` is the one call for code that proposes a column map
(``inspect``'s suggestion, the motor-role suggestion): it works on Crazyflie
SD-card logs, Betaflight blackbox CSVs, PX4 ULogs and CSVs of another layout
alike. Units are those of the values a column map reads (after any conversion
the reader makes, which the unit text says, e.g. ``rad/s FLU (from deg/s)``);
"as logged" where the format does not say.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import LogError
from omavctl.logs.columnlogs import TABLE_KINDS, load_table
from omavctl.logs.read import FORMAT_LABELS, detect_format
from omavctl.logs.tables import ColumnTable

__all__ = ["ColumnInfo", "ColumnInventory", "column_inventory", "table_inventory"]


@dataclass(frozen=True)
class ColumnInfo:
    """One column: the ``group`` (event, frame kind or ULog topic) whose rows hold it,
    its count of finite values, median ``rate`` (Hz) of its group's rows, ``unit``
    and (``lo``, ``hi``) range (NaN when it holds no value)."""

    name: str
    group: str
    count: int
    rate: float
    unit: str
    lo: float
    hi: float


@dataclass
class ColumnInventory:
    """The columns of a log (:class:`ColumnInfo` in file order), the time column a
    map's ``time:`` names with the ``time_scale`` to seconds, the header's values
    (``meta``) and notes."""

    path: Path
    format: str
    time_column: str | None
    time_scale: float
    columns: list[ColumnInfo]
    meta: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def units(self) -> dict[str, str]:
        """Unit of every column by name."""
        return {c.name: c.unit for c in self.columns}

    def find(self, name: str) -> ColumnInfo:
        """The column called ``name`` (KeyError when there is none)."""
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(name)


def _rate(stamps_s: np.ndarray) -> float:
    u = np.unique(stamps_s[np.isfinite(stamps_s)])
    return 1.0 / float(np.median(np.diff(u))) if u.size > 1 else 0.0


def _info(name: str, group: str, values: np.ndarray, rate: float, unit: str) -> ColumnInfo:
    finite = values[np.isfinite(values)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
    return ColumnInfo(name, group, int(finite.size), rate, unit, lo, hi)


def table_inventory(t: ColumnTable) -> ColumnInventory:
    """The inventory of a log already read as a :class:`~.tables.ColumnTable`."""
    cols = []
    for g in t.groups:
        rate = _rate(g.stamps * t.time_scale)
        cols += [_info(n, g.name, v, rate, t.units.get(n, "as logged"))
                 for n, v in g.columns.items()]  # fmt: skip
    return ColumnInventory(t.path, t.format, t.time_column, t.time_scale, cols, dict(t.meta),
                           list(t.notes))  # fmt: skip


def _from_ulog(path: Path) -> ColumnInventory:
    from omavctl.logs.ulog import TIME_COLUMN, load_ulog, ulog_unit

    u = load_ulog(path)
    cols = []
    for topic, (stamps, fields) in u.topics.items():
        rate = _rate(stamps * 1e-6)
        cols += [_info(n, topic, v, rate, ulog_unit(n)) for n, v in fields.items()]
    return ColumnInventory(path, "ulog", TIME_COLUMN, 1e-6, cols, {}, list(u.notes))


def _from_csv(path: Path) -> ColumnInventory:
    from omavctl.logs.suggest import scan_csv, suggest_column_map

    scan = scan_csv(path)
    time = suggest_column_map(scan).columns.get("time")
    name = time.get("column") if isinstance(time, dict) else time
    scale = float(time.get("scale", 1.0)) if isinstance(time, dict) else 1.0
    rate = _rate(scan.values[name] * scale) if name in scan.values else 0.0
    cols = [_info(n, "rows", v, rate, "as logged") for n, v in scan.values.items() if n != name]
    notes = (
        [f"non-numeric columns skipped: {', '.join(scan.non_numeric)}"] if scan.non_numeric else []
    )
    return ColumnInventory(path, "csv", name, scale, cols, {}, notes)


def column_inventory(path: str | Path) -> ColumnInventory:
    """Every column of a log that is read through a column map (see the module docs).

    Raises:
        LogError: unreadable log, or a bag / MCAP / wide contract CSV (their topics
            and columns are the contract's, not mapped).
    """
    p = Path(path)
    kind = detect_format(p)
    if kind in TABLE_KINDS:
        return table_inventory(load_table(p, kind))
    if kind == "ulog":
        return _from_ulog(p)
    if kind == "csv":
        return _from_csv(p)
    raise LogError(f"a {FORMAT_LABELS[kind]} holds contract topics, not mapped columns", p)
