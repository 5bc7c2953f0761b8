"""Betaflight blackbox logs decoded to CSV, by ``blackbox_decode`` or Blackbox Explorer.

Both tools write one row per main frame with Betaflight's field names;
``blackbox_decode`` puts units in the names (``time (us)``, ``vbatLatest (V)``,
``gyroADC[0] (deg/s)`` with ``--unit-rotation deg/s``), Blackbox Explorer quotes
them and writes the log's header above them as ``"key",value`` rows. A header in
the raw log's own form (``H key:value`` lines) is read from the top of the file or
from a sidecar ``<name>.headers.txt`` beside it (``<name>.csv`` or ``<name>.csv.gz``).

What the reader converts (the header's values are in :attr:`ColumnTable.meta`):

- ``time`` (µs) -> s;
- ``gyroADC[i]`` / ``gyroUnfilt[i]`` (deg/s, times the header's ``gyro_scale`` when
  the column carries no unit) -> rad/s. Betaflight's gyro axes are x roll (right
  side down positive), y pitch (nose down positive), z yaw (nose left positive):
  Betaflight's quad-X mixer (``mixerQuadX`` in ``src/main/flight/mixer.c``) raises
  the left motors for a positive roll output, the rear motors for a positive pitch
  output and, with ``yaw_motors_reversed`` off, the clockwise (props-in) motors for
  a positive yaw output, and the rate loop's feedback needs each output to drive
  its gyro axis positive. Those are the right-handed rates about x forward, y left,
  z up: the contract's FLU body frame, so no sign changes (the shared CS110 logs
  bear it out: each motor difference leads the matching gyro acceleration).
- ``accSmooth[i]`` -> g (divided by the header's ``acc_1G``);
- ``vbatLatest`` -> V (its ``(V)`` unit, else 0.1 V before Betaflight 4 and
  0.01 V from 4 on, from ``Firmware revision``; "raw" when neither is known,
  ``vbatref`` is then in the same unit).

``motor[i]`` stay as logged (DShot 0-2047 or PWM µs; ``meta['motor_output']`` is
the header's ``motorOutput`` range); Betaflight's quad-X order is motor[0]
rear-right, [1] front-right, [2] rear-left, [3] front-left.
"""

from __future__ import annotations

import csv
import io
import math
import re
import struct
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import LogError
from omavctl.logs.csvlog import rows_skipped
from omavctl.logs.tables import ColumnGroup, ColumnTable
from omavctl.logs.textio import read_head, read_text

__all__ = ["MOTOR_ORDER", "betaflight_table", "looks_like_betaflight", "parse_header"]

#: Betaflight's quad-X motor order (``motor[i]``, i from 0).
MOTOR_ORDER = ("rear-right", "front-right", "rear-left", "front-left")
_UNIT = re.compile(r"^(?P<name>.*?)\s*\((?P<unit>[^()]*)\)$")
_GYRO = re.compile(r"^gyro(ADC|Unfilt)\[[0-2]\]$")
_SUFFIXES = (".csv.gz", ".csv", ".gz", ".txt")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in next(csv.reader([line]), [])]


def _is_field_row(cells: list[str]) -> bool:
    names = {_split_unit(c)[0] for c in cells}
    gyro = any(n.startswith("gyroADC[") for n in names)
    return len(cells) > 2 and "time" in names and ("loopIteration" in names or gyro)


def looks_like_betaflight(head: bytes) -> bool:
    """Whether the first bytes of a (decompressed) file are a Betaflight blackbox CSV:
    a blackbox header line, or a field-name row with ``time`` and ``loopIteration``
    or ``gyroADC[..]``."""
    text = head.decode("utf-8-sig", errors="replace")
    for line in text.splitlines()[:400]:
        if line.startswith(("H Product:Blackbox", '"Product","Blackbox')):
            return True
        if _is_field_row(_cells(line)):
            return True
    return False


def _split_unit(name: str) -> tuple[str, str | None]:
    m = _UNIT.match(name)
    return (m["name"], m["unit"]) if m else (name, None)


def parse_header(lines: list[str]) -> dict[str, str]:
    """Header values from ``H key:value`` lines and Blackbox Explorer's ``"key",value``
    rows (other lines are skipped)."""
    out: dict[str, str] = {}
    for line in lines:
        if line.startswith("H ") and ":" in line:
            key, value = line[2:].split(":", 1)
            out[key.strip()] = value.strip()
        else:
            cells = _cells(line)
            if len(cells) == 2 and cells[0]:
                out[cells[0]] = cells[1]
    return out


def _sidecar_name(path: Path) -> str:
    """``<name>.headers.txt`` of a log ``<name>.csv`` or ``<name>.csv.gz``."""
    name = path.name
    stem = next((name[: -len(s)] for s in _SUFFIXES if name.lower().endswith(s)), path.stem)
    return stem + ".headers.txt"


def _sidecar(path: Path) -> list[str]:
    """Lines of ``<name>.headers.txt`` beside the log, if there is one."""
    side = path.with_name(_sidecar_name(path))
    if side == path or not side.is_file():
        return []
    return read_text(side, "blackbox header file").splitlines()


def _number(meta: dict[str, str], key: str) -> float | None:
    try:
        value = float(meta[key].split(",")[0])
    except (KeyError, ValueError):
        return None
    return value if math.isfinite(value) else None


def _gyro_scale(meta: dict[str, str]) -> float:
    """The header's ``gyro_scale`` (a float's bits in hex, as Betaflight writes it), 1 else."""
    raw = meta.get("gyro_scale", "")
    try:
        value = float(struct.unpack(">f", int(raw, 16).to_bytes(4, "big"))[0])
    except (ValueError, OverflowError):
        return 1.0
    return value if math.isfinite(value) and value > 0 else 1.0


def _vbat_unit(meta: dict[str, str], unit: str | None) -> tuple[float | None, str]:
    if unit == "V":
        return 1.0, "V"
    # the raw header's "Firmware revision: Betaflight 3.1.5 (...)", or Blackbox
    # Explorer's parsed "firmwareVersion: 4.2.0" when its firmwareType is Betaflight (3)
    m = re.search(r"Betaflight (\d+)\.", meta.get("Firmware revision", ""))
    if m is None and meta.get("firmwareType", "").lower() in ("3", "betaflight"):
        m = re.match(r"(\d+)\.", meta.get("firmwareVersion", ""))
    if m:
        return (0.1, "V (from 0.1 V)") if int(m[1]) < 4 else (0.01, "V (from 0.01 V)")
    return None, "raw (vbatref is in the same unit)"


def _meta(header: dict[str, str]) -> dict[str, Any]:
    """The header values that whoever maps motors needs, parsed, plus every raw value."""
    out: dict[str, Any] = {"header": dict(header), "motor_order": list(MOTOR_ORDER)}
    out["firmware"] = header.get("Firmware revision")
    out["looptime_us"] = _number(header, "looptime")
    out["p_interval"] = header.get("P interval") or header.get("P_interval")
    lo_hi = [v.strip() for v in header.get("motorOutput", "").split(",")]
    try:
        out["motor_output"] = [float(lo_hi[0]), float(lo_hi[1])]
    except (ValueError, IndexError):
        out["motor_output"] = None
    out["vbatscale"] = _number(header, "vbatscale")
    out["vbatref"] = _number(header, "vbatref")
    out["vbat_pid_compensation"] = _number(header, "vbat_pid_compensation")
    out["acc_1G"] = _number(header, "acc_1G")
    out["gyro_scale"] = _gyro_scale(header)
    return out


def _find_fields(lines: list[str], path: Path) -> int:
    for i, line in enumerate(lines[:2000]):
        if _is_field_row(_cells(line)):
            return i
    raise LogError("not a Betaflight blackbox CSV: no row of field names with 'time' and "
                   "'loopIteration' or 'gyroADC[0]'", path)  # fmt: skip


def _first_problem(rows: list[str], width: int, numeric: list[int], names: list[str]) -> str:
    for k, row in enumerate(rows):
        if not row.strip():
            continue
        cells = _cells(row)
        if len(cells) != width:
            return f"line {k + 1} has {len(cells)} cells, the field names {width}"
        for j in numeric:
            try:
                float(cells[j] or "nan")
            except ValueError:
                return f"non-numeric value '{cells[j][:20]}' in column '{names[j]}' at line {k + 1}"
    return "malformed rows"


def _numeric_columns(rows: list[str], width: int) -> list[int]:
    """Columns whose first value (in the first 2000 rows) is a number: text columns
    (flag names) are skipped, a later text cell in a numeric column is an error."""
    sample = [_cells(r) for r in rows[:2000] if r.strip()]
    keep = []
    for j in range(width):
        first = next((c[j] for c in sample if j < len(c) and c[j] not in ("", "NaN", "nan")), "0")
        try:
            float(first)
        except ValueError:
            continue
        keep.append(j)
    return keep


def _fill_empty(body: str) -> str:
    """Rows with every empty cell written ``nan`` (and no blank after a comma, as
    ``blackbox_decode`` writes), so that numpy's C parser reads them."""
    while ", " in body:
        body = body.replace(", ", ",")
    for _ in range(2):  # a run of commas: every other gap is filled by each pass
        body = body.replace(",,", ",nan,")
    body = body.replace(",\n", ",nan\n").replace("\n,", "\nnan,")
    if body.endswith(","):
        body += "nan"
    return "nan" + body if body.startswith(",") else body


def _parse_rows(rows: list[str], names: list[str], path: Path, first: int) -> dict[str, np.ndarray]:
    """The numeric columns of the data rows (file lines from ``first + 1``), NaN where empty."""
    if not any(r.strip() for r in rows):
        raise LogError("no data rows below the field names", path)
    width = len(names)
    numeric = _numeric_columns(rows, width)
    body = _fill_empty("\n".join(rows))
    try:
        data = np.loadtxt(io.StringIO(body), delimiter=",", usecols=numeric, ndmin=2,
                          comments=None, quotechar='"')  # fmt: skip
    except ValueError:
        problem = _first_problem(rows, width, numeric, names)
        problem = re.sub(r"line (\d+)", lambda m: f"line {int(m[1]) + first}", problem)
        raise LogError(problem, path) from None
    return {names[j]: data[:, k] for k, j in enumerate(numeric)}


def _convert(name: str, unit: str | None, values: np.ndarray, meta: dict[str, Any],
             header: dict[str, str], path: Path) -> tuple[np.ndarray, str]:  # fmt: skip
    """A column in the units the reader gives (see the module docs) and its unit."""
    if name == "time":
        scale = {"us": 1e-6, "ms": 1e-3, "s": 1.0}.get(unit or "us")
        if scale is None:
            raise LogError(f"column 'time ({unit})': unknown time unit", path)
        return values * scale, f"s (from {unit or 'us'})"
    if _GYRO.match(name):
        if unit in (None, "raw"):
            return values * meta["gyro_scale"] * math.pi / 180, "rad/s FLU (from deg/s)"
        if unit in ("deg/s", "rad/s"):
            return (
                values * math.pi / 180 if unit == "deg/s" else values
            ), f"rad/s FLU (from {unit})"
    if name.startswith("accSmooth[") and unit in (None, "raw") and meta["acc_1G"]:
        return values / meta["acc_1G"], "g (from acc_1G units)"
    if name == "vbatLatest":
        scale, text = _vbat_unit(header, unit)
        return (values * scale if scale else values), text
    if name.startswith("motor[") and meta["motor_output"]:
        lo, hi = meta["motor_output"]
        return values, f"motor command (motorOutput {lo:g}-{hi:g})"
    return values, unit or "as logged"


def betaflight_table(path: Path) -> ColumnTable:
    """A Betaflight blackbox CSV as named columns (see the module docs): one group,
    names without their unit suffix, ``time`` in s.

    Raises:
        LogError: unreadable or not UTF-8, no field-name row, a row of the wrong
            width or a non-numeric cell in a numeric column (naming the file line),
            no data rows, no ``time`` column.
    """
    lines = read_text(path, "Betaflight blackbox CSV").splitlines()
    at = _find_fields(lines, path)
    header = parse_header(_sidecar(path) + lines[:at])
    meta = _meta(header)
    split = [_split_unit(c) for c in _cells(lines[at])]
    names = [n for n, _ in split]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise LogError(f"duplicate column '{dup}'", path)
    notes = []
    if not header:  # a log copied without its sidecar: say so, not only "vbat raw"
        notes.append(
            "no blackbox header (no lines above the field names and no "
            f"{_sidecar_name(path)} beside the log): the gyro scale, the battery voltage's "
            "unit and the motor output range are the defaults"
        )
    rows = lines[at + 1 :]
    if rows and rows[-1].count(",") < len(names) - 1 and rows[-1].strip():
        notes.append(f"the file ends in the middle of its last row (line {len(lines)}): "
                     "truncated? That row is dropped")  # fmt: skip
        rows = rows[:-1]
    parsed = _parse_rows(rows, names, path, at + 1)
    units = dict(split)
    columns: dict[str, np.ndarray] = {}
    unit_of: dict[str, str] = {}
    for name, values in parsed.items():
        columns[name], unit_of[name] = _convert(name, units[name], values, meta, header, path)
    if "time" not in columns:
        raise LogError("column 'time' holds no numbers", path)
    time = columns.pop("time")
    has_t = np.isfinite(time)
    if not has_t.any():
        raise LogError("column 'time' holds no numbers", path)
    if not has_t.all():
        notes.append(rows_skipped(int((~has_t).sum()), "without a time value"))
        time, columns = time[has_t], {k: v[has_t] for k, v in columns.items()}
    order = np.argsort(time, kind="stable")
    group = ColumnGroup("main", time[order], {k: v[order] for k, v in columns.items()})
    skipped = [n for n in names if n not in parsed]
    if skipped:
        notes.append(f"non-numeric columns skipped: {', '.join(skipped)}")
    return ColumnTable(path, "betaflight", "time", 1.0, [group], unit_of, meta, notes)


def sidecar_error(path: Path, head: bytes) -> LogError | None:
    """The error for a Betaflight header sidecar (``<name>.headers.txt``, its first
    bytes ``head`` an ``H name:value`` line) given as a log: it names the CSV
    beside it to give instead; None for any other file."""
    if not (head.startswith(b"H ") and b":" in head.split(b"\n", 1)[0]):
        return None
    name = path.name
    stem = name[: -len(".headers.txt")] if name.lower().endswith(".headers.txt") else path.stem
    beside = [path.with_name(stem + s) for s in (".csv", ".csv.gz")]
    found = next((str(b) for b in beside if b.is_file()), None)
    give = (
        f"give the CSV beside it: {found}"
        if found
        else (f"give the CSV blackbox_decode wrote beside it ({stem}.csv)")
    )
    return LogError(
        "a Betaflight blackbox header sidecar ('H name:value' lines), not a log: its "
        f"values are read with the CSV they describe; {give}",
        path,
    )


def sniff_betaflight(path: Path) -> bool:
    """Whether the file at ``path`` (plain or gzip) is a Betaflight blackbox CSV."""
    try:
        return looks_like_betaflight(read_head(path, 65536))
    except LogError:
        return False
