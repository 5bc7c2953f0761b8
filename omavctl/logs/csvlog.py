"""The wide CSV log of DESIGN.md section 3: ``t`` then ``<role>_<suffix>`` columns.

One row per sample, ``t`` in s from the log start, SI units. A role is read
when all of its columns are present; columns that belong to no role are
ignored (and noted). Values are written with ``repr`` (shortest exact form),
so a CSV round trip keeps every float bit for bit.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from omavctl.base.atomic import atomic_path
from omavctl.base.errors import LogError
from omavctl.logs.stats import topic_info
from omavctl.logs.textio import read_text
from omavctl.logs.types import ANGLE_ROLES, ROLE_COLUMNS, RawLog, RawSeries

__all__ = [
    "MISSING_CELLS",
    "CsvRead",
    "CsvTable",
    "csv_columns",
    "cut_row_notes",
    "parse_column",
    "read_csv",
    "read_table",
    "rows_skipped",
    "write_csv",
]

#: Cells that mean "no value in this row" in a CSV of another layout.
MISSING_CELLS = {"", "nan", "NaN", "NAN", "na", "NA", "null", "None"}


def csv_columns(role: str) -> list[str]:
    """Wide-CSV column names of a signal role, e.g. ``body_rate_x``."""
    return [f"{role}_{suffix}" for suffix in ROLE_COLUMNS[role]]


@dataclass
class CsvRead:
    """A CSV log as read, plus per-column (min, max) of the columns used."""

    raw: RawLog
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)


def _first_bad_cell(text: str, header: list[str], usecols: list[int]) -> str | None:
    """Describe the first row of the wrong width or non-numeric used cell (slow scan)."""
    rows = csv.reader(io.StringIO(text))
    next(rows, None)
    row_no = 0
    for row in rows:
        if not row or all(not c.strip() for c in row):
            continue
        row_no += 1
        where = f"row {row_no} (line {rows.line_num})"
        if len(row) != len(header):
            return f"{where} has {len(row)} cells, the header has {len(header)}"
        for j in usecols:
            cell = row[j].strip()
            try:
                float(cell)
            except ValueError:
                if not cell:
                    return f"empty cell in column '{header[j]}' at {where}"
                shown = cell if len(cell) <= 20 else cell[:17] + "..."
                return f"non-numeric value '{shown}' in column '{header[j]}' at {where}"
    return None


def read_csv(path: Path, strict: bool = True) -> CsvRead:
    """Read a wide CSV log.

    ``t0`` is the earliest ``t`` and stamps count from it. With ``strict``
    (the default) a role with only some of its columns, a non-numeric cell or
    a NaN/inf cell is a :class:`LogError`; otherwise (for ``inspect``) they
    become notes, bad cells NaN.
    """
    text, header = _text_and_header(path)
    notes: list[str] = []
    roles = _roles_present(path, header, strict, notes)
    names = ["t"] + [c for role in roles for c in csv_columns(role)]
    data = _numeric_columns(path, text, header, names, strict, notes)
    finite_t = np.isfinite(data[:, 0])
    if not finite_t.any():
        raise LogError("column 't' has no numeric value", path)
    data = data[finite_t]  # (lenient mode) rows without a time cannot be placed
    t = data[:, 0]
    t0 = float(t.min())
    stamps = t - t0
    series = {}
    topics = []
    col = 1
    for role in roles:
        k = len(ROLE_COLUMNS[role])
        series[role] = RawSeries(stamps=stamps, values=data[:, col : col + k].copy())
        topics.append(topic_info(role, "csv columns", stamps))
        col += k
    ranges = {}
    for j, name in enumerate(names):
        column = data[:, j][np.isfinite(data[:, j])]
        if column.size:
            ranges[name] = (float(column.min()), float(column.max()))
    raw = RawLog(path=path, format="csv", t0=t0, series=series, topics=topics, notes=notes)
    return CsvRead(raw=raw, ranges=ranges)


def _csv_text(path: Path) -> str:
    """The text of a CSV file, gzip-compressed or not; LogError when it cannot be
    read, its gzip stream is broken or it is not UTF-8 (:func:`~.textio.read_text`)."""
    return read_text(path)


def _text_and_header(path: Path) -> tuple[str, list[str]]:
    """The file's text and its header's column names (unique, with ``t``)."""
    text = _csv_text(path)
    first = text.split("\n", 1)[0].strip()
    if not first:
        raise LogError("not a CSV log: the first line must be a header starting with 't'", path)
    header = [h.strip() for h in next(csv.reader([first]))]
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise LogError(f"duplicate column '{name}'", path)
        seen.add(name)
    if "t" not in header:
        contract = {c for role in ROLE_COLUMNS for c in csv_columns(role)}
        if contract & set(header):
            raise LogError("missing column 't' (time in s)", path)
        raise LogError(
            "missing column 't' (time in s): not a wide contract CSV; "
            f"'omavctl inspect {path}' suggests a column map for a --vehicle file",
            path,
        )
    return text, header


def _roles_present(path: Path, header: list[str], strict: bool, notes: list[str]) -> list[str]:
    """Roles whose columns are all in ``header``; partial roles raise (strict) or are noted."""
    seen = set(header)
    roles: list[str] = []
    used = {"t"}
    for role in ROLE_COLUMNS:
        cols = csv_columns(role)
        present = [c for c in cols if c in seen]
        if not present:
            continue
        if len(present) < len(cols):
            missing = [c for c in cols if c not in seen]
            msg = f"missing column '{missing[0]}' (role {role} needs {', '.join(cols)})"
            if strict:
                raise LogError(msg, path)
            notes.append(msg + f"; {role} not read")
            continue
        roles.append(role)
        used.update(cols)
    contract = {c for role in ROLE_COLUMNS for c in csv_columns(role)}
    ignored = [h for h in header if h not in used and h not in contract]
    if ignored:
        notes.append(f"columns not in the contract ignored: {', '.join(ignored)}")
    return roles


def _numeric_columns(
    path: Path, text: str, header: list[str], names: list[str], strict: bool, notes: list[str]
) -> np.ndarray:
    """The columns ``names`` as floats (rows, len(names)); bad cells raise (strict) or are NaN."""
    usecols = [header.index(c) for c in names]
    lines = text.splitlines()
    data_lines = [i + 1 for i, line in enumerate(lines) if i > 0 and line.strip()]
    if not data_lines:
        raise LogError("no data rows below the header", path)
    try:
        data = np.loadtxt(
            io.StringIO(text),
            delimiter=",",
            skiprows=1,
            usecols=usecols,
            ndmin=2,
            dtype=float,
            comments=None,
        )
    except ValueError as err:
        msg = _first_bad_cell(text, header, usecols) or f"malformed rows ({_first_line(err)})"
        if strict:
            raise LogError(msg, path) from None
        data = _lenient_parse(text, usecols)
        notes.append(f"{msg}; unreadable cells read as NaN")
    bad_cells = ~np.isfinite(data)
    if bad_cells.any():
        r, c = (int(x) for x in np.argwhere(bad_cells)[0])
        value = "NaN" if np.isnan(data[r, c]) else "inf"
        msg = f"{value} in column '{names[c]}' at row {r + 1} (line {data_lines[r]})"
        if strict:
            raise LogError(msg, path)
        notes.append(f"{msg}; {int(bad_cells.sum())} non-finite cells in all")
    return data


def _first_line(err: BaseException) -> str:
    lines = str(err).strip().splitlines()
    return lines[0] if lines else type(err).__name__


def _lenient_parse(text: str, usecols: list[int]) -> np.ndarray:
    """Parse the used columns with NaN for any cell that is not a number."""
    rows = csv.reader(io.StringIO(text))
    next(rows, None)
    out = []
    for row in rows:
        if not row or all(not c.strip() for c in row):
            continue
        values = []
        for j in usecols:
            try:
                values.append(float(row[j]))
            except (ValueError, IndexError):
                values.append(float("nan"))
        out.append(values)
    return np.array(out, dtype=float).reshape(-1, len(usecols))


def write_csv(path: Path, raw: RawLog) -> None:
    """Write ``raw`` as a wide CSV atomically.

    One row per sample of the ``force_command`` series (the controller's
    rate; else the first role present) within the span every role covers;
    each other role is linearly interpolated there (angles through unwrap and
    wrap). ``t`` is in s since ``raw.t0``.
    """
    from omavctl.logs.align import interpolate
    from omavctl.logs.stats import stamp_stats

    roles = [r for r in ROLE_COLUMNS if r in raw.series]
    clean = {}
    for role in roles:
        s = raw.series[role]
        stamps = np.asarray(s.stamps, dtype=float)
        st = stamp_stats(stamps)
        idx = st.order[st.keep]
        clean[role] = (stamps[idx], np.asarray(s.values, dtype=float)[idx])
    base = "force_command" if "force_command" in clean else roles[0]
    lo = max(s[0] for s, _ in clean.values())
    hi = min(s[-1] for s, _ in clean.values())
    t = clean[base][0]
    t = t[(t >= lo) & (t <= hi)]
    if t.size == 0:
        raise LogError("nothing to write: the signals do not overlap in time", path)
    columns = [t[:, None]]
    header = ["t"]
    for role in roles:
        s, v = clean[role]
        if role == base or (s.size == t.size and np.array_equal(s, t)):
            columns.append(v[np.searchsorted(s, t)] if role == base else v)
        else:
            columns.append(interpolate(s, v, t, role in ANGLE_ROLES))
        header += csv_columns(role)
    table = np.hstack(columns)
    body = "\n".join(",".join(map(repr, row)) for row in table.tolist())
    with atomic_path(path) as tmp:
        tmp.write_text(",".join(header) + "\n" + body + "\n")


@dataclass
class CsvTable:
    """A CSV file as text cells: ``header`` names, ``rows`` of stripped cells,
    ``lines`` the file line of each row (for messages)."""

    path: Path
    header: list[str]
    rows: list[list[str]]
    lines: list[int]
    #: (file line, cells) of a last row the file ends in the middle of (no line
    #: break after it, fewer cells than the header): dropped, a truncated file
    cut_row: tuple[int, int] | None = None

    def cells(self, j: int) -> list[str]:
        """Stripped cells of column ``j`` (empty where a row is short)."""
        return [row[j].strip() if j < len(row) else "" for row in self.rows]


def read_table(path: Path) -> CsvTable:
    """Read a CSV file into text cells (header and non-blank rows). The separator
    is a comma, or a semicolon or tab when the header has no comma.

    Raises:
        LogError: unreadable or not UTF-8, no header, no data rows.
    """
    text = _csv_text(path)
    first = text.split("\n", 1)[0]
    # comma-separated, else the separator the header uses (semicolon or tab)
    delimiter = "," if "," in first else next((d for d in ";\t" if d in first), ",")
    reader = csv.reader(io.StringIO(text), delimiter=delimiter)
    header = [h.strip() for h in next(reader, [])]
    if not any(header):
        raise LogError("not a CSV log: the first line must be a header", path)
    rows: list[list[str]] = []
    lines: list[int] = []
    for row in reader:
        if row and any(c.strip() for c in row):
            rows.append(row)
            lines.append(reader.line_num)
    cut_row = None
    if rows and not text.endswith(("\n", "\r")) and len(rows[-1]) < len(header):
        cut_row = (lines.pop(), len(rows.pop()))
    if not rows:
        raise LogError("no data rows below the header", path)
    return CsvTable(path=path, header=header, rows=rows, lines=lines, cut_row=cut_row)


def cut_row_notes(table: CsvTable) -> list[str]:
    """A note when the file ended in the middle of its last row (dropped by
    :func:`read_table`), else none."""
    if table.cut_row is None:
        return []
    line, cells = table.cut_row
    return [
        f"the file ends in the middle of its last row (line {line}: {cells} of "
        f"{len(table.header)} cells): truncated? That row is dropped"
    ]


def rows_skipped(count: int, why: str) -> str:
    """The note for ``count`` rows skipped ``why`` ("1 row ...", "3 rows ...")."""
    return f"{count} {'row' if count == 1 else 'rows'} {why} skipped"


def parse_column(cells: list[str], name: str, lines: list[int], path: Path) -> np.ndarray:
    """Cells of one column as floats, NaN where empty/nan; shape (n,).

    Raises :class:`LogError` naming the column, row and line of the first
    non-numeric cell.
    """
    try:
        return np.array([np.nan if c in MISSING_CELLS else float(c) for c in cells])
    except ValueError:
        pass
    for i, cell in enumerate(cells):
        if cell in MISSING_CELLS:
            continue
        try:
            float(cell)
        except ValueError:
            shown = cell if len(cell) <= 20 else cell[:17] + "..."
            raise LogError(
                f"non-numeric value '{shown}' in column '{name}' at row {i + 1} (line {lines[i]})",
                path,
            ) from None
    raise AssertionError("unreachable")  # pragma: no cover
