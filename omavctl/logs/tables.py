"""Logs that readers turn into named columns: the table, its units and what a
column map reads from it.

A :class:`ColumnTable` is what the Crazyflie SD-card reader
(:mod:`~.cfusdlog`) and the Betaflight blackbox CSV reader (:mod:`~.betaflight`)
give: one or more groups of rows (an event type, a frame kind), each with its own
stamps and named numeric columns, the unit of every column, and what the log's
header says (``meta``: loop time, motor output range, battery scale, ...). Such a
log is read through a column map exactly like a CSV of another layout
(:func:`read_mapped_columns`); :func:`scan_table` lists its columns for
``inspect``'s suggestion.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.logs.colnames import ColumnScan
from omavctl.logs.columnmap import MappedTable, parse_column_map, read_mapped
from omavctl.logs.csvlog import CsvRead

__all__ = ["ColumnGroup", "ColumnTable", "read_mapped_columns", "scan_table"]


@dataclass
class ColumnGroup:
    """Rows logged together: ``stamps`` (n,) in the table's time unit and the
    columns by name, each (n,) float64 (NaN where a row has no value)."""

    name: str
    stamps: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class ColumnTable:
    """A log as named columns (see the module docs).

    ``time_column`` names the stamps of every row in the column map (``time:``);
    ``time_scale`` turns them into seconds. ``units`` gives each column's unit as
    the table holds it (after any conversion the reader made, which it says).
    """

    path: Path
    format: str
    time_column: str
    time_scale: float
    groups: list[ColumnGroup]
    units: dict[str, str] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def header(self) -> list[str]:
        """The time column, then every column in group order."""
        return [self.time_column, *(n for g in self.groups for n in g.columns)]


def _merged(table: ColumnTable) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[int, int, str]]]:
    """All rows' stamps (N,), the order sorting them, and per column (start, end, group)
    of its group's rows in the unsorted concatenation."""
    stamps = np.concatenate([g.stamps for g in table.groups]) if table.groups else np.zeros(0)
    order = np.argsort(stamps, kind="stable")
    where: dict[str, tuple[int, int, str]] = {}
    start = 0
    for g in table.groups:
        for name in g.columns:
            where[name] = (start, start + g.stamps.size, g.name)
        start += g.stamps.size
    return stamps, order, where


def read_mapped_columns(table: ColumnTable, columns: Mapping[str, Any]) -> CsvRead:
    """Read a :class:`ColumnTable` through a column map (as
    :func:`~.columnmap.read_mapped_csv` reads a CSV): the :class:`RawLog` has the
    table's format and notes.

    Raises:
        ConfigError: invalid map.
        LogError: a mapped column that is not in the table.
    """
    specs = parse_column_map(columns)
    stamps, order, where = _merged(table)
    groups = {g.name: g for g in table.groups}

    def source(name: str) -> np.ndarray:
        if name == table.time_column:
            return stamps[order].astype(float)
        out = np.full(stamps.size, np.nan)
        lo, hi, group = where[name]
        out[lo:hi] = groups[group].columns[name]
        return out[order]

    sparse = len(table.groups) > 1
    mapped = MappedTable(table.path, table.format, table.header(), stamps.size, source, sparse)
    return read_mapped(mapped, specs, list(table.notes))


def scan_table(table: ColumnTable) -> ColumnScan:
    """Every column for ``inspect``'s column-map guess: the time column over all rows,
    each other column over its own group's rows (nothing padded)."""
    stamps, order, _ = _merged(table)
    scan = ColumnScan(path=table.path, header=table.header(), rows=stamps.size)
    scan.values[table.time_column] = stamps[order].astype(float)
    for g in table.groups:
        for name, values in g.columns.items():
            finite = values[np.isfinite(values)]
            if finite.size:
                scan.values[name] = finite
            else:
                scan.empty.append(name)
    return scan
