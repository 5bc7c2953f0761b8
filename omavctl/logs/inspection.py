"""What is in a flight log: topics, rates, problems, which contract roles it has.

Inspection is lenient: a contract topic of the wrong type, a CSV role with
missing columns or bad cells are reported as notes instead of errors. A CSV
of another layout (no contract columns) read without a column map gets its
numeric columns listed with ranges and a suggested column map
(:mod:`omavctl.logs.suggest`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from omavctl.base.errors import LogError
from omavctl.logs.align import DEFAULT_REQUIRED
from omavctl.logs.contract import merge_topics
from omavctl.logs.read import detect_format
from omavctl.logs.types import ROLE_COLUMNS, ROLE_TOPIC, RawLog, TopicInfo

if TYPE_CHECKING:
    from rich.console import Console

    from omavctl.logs.suggest import Suggestion
    from omavctl.logs.ulog import UlogTopics

__all__ = ["Inspection", "inspect_log", "render_inspect"]

_FORMAT_TITLES = {
    "ros1": "ROS 1 bag",
    "ros2-sqlite3": "ROS 2 bag (sqlite3 storage)",
    "ros2-mcap": "ROS 2 bag (mcap storage)",
    "mcap": "MCAP file",
    "csv": "CSV",
    "ulog": "PX4 ULog",
    "cfusdlog": "Crazyflie SD-card log (cfusdlog)",
    "betaflight": "Betaflight blackbox CSV",
}


@dataclass
class Inspection:
    """Summary of one log.

    ``roles_found`` maps each contract signal role present to where it came
    from (topic name, or ``"CSV columns"``); ``roles_missing`` maps each absent
    role to the topic (or columns) it would come from. ``column_ranges`` gives
    (min, max) per CSV column (CSV only). For a CSV of another layout read
    without a column map, ``suggested_columns`` is the guessed role-based map
    and ``suggestion`` its YAML text (to paste into a vehicle file).
    """

    path: Path
    format: str
    duration: float  # s
    t0: float  # s, absolute time of the first stamp
    topics: list[TopicInfo]
    roles_found: dict[str, str]
    roles_missing: dict[str, str]
    notes: list[str] = field(default_factory=list)
    column_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    suggested_columns: dict[str, Any] | None = None
    suggestion: str | None = None
    #: the roles ``fit``/``evaluate`` need of this log (body rate and motor
    #: outputs when a rotor list mixes them, :mod:`omavctl.physics.mixer`)
    required: tuple[str, ...] = DEFAULT_REQUIRED
    #: unit and rate (Hz) of each listed column, where the format tells
    #: (:func:`~.inventory.column_inventory`)
    column_units: dict[str, str] = field(default_factory=dict)
    column_rates: dict[str, float] = field(default_factory=dict)
    #: what the log's own header says, parsed (Betaflight: looptime_us, motor_output,
    #: vbatscale, vbatref, ...; Crazyflie: format version and event names)
    header_values: dict[str, Any] = field(default_factory=dict)

    @property
    def required_missing(self) -> list[str]:
        """Roles that ``fit``/``evaluate`` need but the log lacks."""
        return [r for r in self.required if r in self.roles_missing]


def _duration(raw: RawLog) -> float:
    spans = [
        (float(s.stamps.min()), float(s.stamps.max())) for s in raw.series.values() if s.stamps.size
    ]
    if spans:
        return max(b for _, b in spans) - min(a for a, _ in spans)
    return max((t.duration for t in raw.topics), default=0.0)


def inspect_log(
    path: str | Path,
    topics: Mapping[str, str] | None = None,
    columns: Mapping[str, Any] | None = None,
) -> Inspection:
    """Inspect a log (any format :func:`read_raw` reads) without aligning it.

    ``topics`` and ``columns`` are as for :func:`read_raw`.

    Raises:
        LogError: the file is missing or unreadable.
    """
    from omavctl.logs.read import _read

    p = Path(path)
    ranges: dict[str, tuple[float, float]] = {}
    kind = detect_format(p)
    if kind in ("cfusdlog", "betaflight"):
        if not columns:
            return _inspect_table(p)
        from omavctl.logs.columnlogs import load_table
        from omavctl.logs.tables import read_mapped_columns

        result = read_mapped_columns(load_table(p, kind), columns)
        raw, ranges = result.raw, result.ranges
    elif kind == "ulog":
        from omavctl.logs.ulog import load_ulog, read_mapped_ulog

        if not columns:
            return _inspect_ulog(p, load_ulog(p))
        result = read_mapped_ulog(p, dict(columns))
        raw, ranges = result.raw, result.ranges
    elif kind == "csv":
        if not columns and _is_foreign_csv(p):
            return _inspect_foreign_csv(p)
        if columns:
            from omavctl.logs.columnmap import read_mapped_csv

            result = read_mapped_csv(p, columns)
        else:
            from omavctl.logs.csvlog import read_csv

            result = read_csv(p, strict=False)
        raw, ranges = result.raw, result.ranges
    else:
        raw = _read(p, topics, strict=False)
    names = raw.topic_names or merge_topics(topics)
    found: dict[str, str] = {}
    missing: dict[str, str] = {}
    for role in ROLE_COLUMNS:
        if raw.mapped:  # read through a column map: its columns, or why not
            where = raw.mapped.get(role, "not in the column map")
            if role in raw.mapped and role not in raw.series:
                where = f"no usable rows in {where}"
        elif raw.format == "csv":
            where = f"CSV columns {role}_*"
        elif ROLE_TOPIC[role] not in names:
            continue  # no bag topic carries it (motor_command: column maps only)
        else:
            where = names[ROLE_TOPIC[role]]
        (found if role in raw.series else missing)[role] = where
    return Inspection(
        path=p,
        format=raw.format,
        duration=_duration(raw),
        t0=raw.t0,
        topics=list(raw.topics),
        roles_found=found,
        roles_missing=missing,
        notes=[*raw.notes, *_idle_notes(raw), *_look_alikes(p, raw, missing)],
        column_ranges=ranges,
    )


def _look_alikes(p: Path, raw: RawLog, missing: dict[str, str]) -> list[str]:
    """:func:`omavctl.logs.suggest.look_alike_notes` of a contract CSV (none otherwise)."""
    if raw.format != "csv" or raw.mapped or not missing:
        return []
    from omavctl.logs.suggest import look_alike_notes

    return look_alike_notes(p, list(missing))


def _idle_notes(raw: RawLog) -> list[str]:
    """A note when the thrust command is zero throughout (the vehicle did not fly:
    ``fit`` and ``evaluate`` refuse such a log)."""
    force = raw.series.get("force_command")
    if force is None or not force.values.size or np.any(force.values != 0.0):
        return []
    return ["the thrust command (force_command) is zero throughout: no flight in this log"]


def _is_foreign_csv(path: Path) -> bool:
    """Whether a CSV is not a wide contract CSV: no ``t`` or no contract column."""
    import csv
    import io

    from omavctl.logs.csvlog import csv_columns
    from omavctl.logs.textio import read_head

    try:
        head = read_head(path).decode("utf-8-sig", errors="replace")
        header = {h.strip() for h in next(csv.reader(io.StringIO(head, newline="")), [])}
    except (LogError, csv.Error):
        return False  # the wide-CSV reader reports it
    contract = {c for role in ROLE_COLUMNS for c in csv_columns(role)}
    return "t" not in header or not header & contract


def _needed(guess: Suggestion) -> tuple[str, ...]:
    """What fit and evaluate need from a log read through the suggested map: the
    body rate and the motor outputs when it maps those (its preset's rotor list mixes
    them; no attitude needed), else the contract's roles."""
    return ("body_rate", "motor_command") if guess.motors else DEFAULT_REQUIRED


def _inspect_foreign_csv(path: Path) -> Inspection:
    """Inspection of a CSV of another layout: column ranges and a suggested column map."""
    from omavctl.logs.suggest import scan_csv, suggest_column_map, suggestion_yaml

    scan = scan_csv(path)
    guess = suggest_column_map(scan)
    # motor outputs: a rotor list (preset) mixes them, no torque command is needed
    required = _needed(guess)
    notes = [
        f"not a wide contract CSV: {len(scan.header)} columns, {len(scan.values)} numeric "
        "with values; a column map (vehicle 'columns:') is needed to read it",
        *scan.notes,
    ]
    if scan.empty:
        shown = ", ".join(scan.empty[:12]) + (", ..." if len(scan.empty) > 12 else "")
        notes.append(f"{len(scan.empty)} all-empty columns skipped: {shown}")
    if scan.non_numeric:
        notes.append(f"non-numeric columns skipped: {', '.join(scan.non_numeric)}")
    return Inspection(
        path=path,
        format="csv",
        duration=guess.duration,
        t0=guess.t0,
        topics=[],
        roles_found={},
        # nothing is read without a column map: what fit and evaluate need is missing
        roles_missing={role: "needs a column map" for role in required},
        notes=notes,
        column_ranges=scan.ranges(),
        suggested_columns=guess.columns,
        suggestion=suggestion_yaml(guess, path.name),
        required=required,
    )


def _inspect_ulog(path: Path, u: UlogTopics) -> Inspection:
    """Inspection of a ULog read without a column map: its topics, column ranges and a
    suggested column map."""
    from omavctl.logs.stats import topic_info
    from omavctl.logs.suggest import suggest_column_map
    from omavctl.logs.ulog import PX4_COLUMNS, scan_ulog, ulog_unit

    scan = scan_ulog(u)
    guess = suggest_column_map(scan, PX4_COLUMNS)
    # a ULog's time is always microseconds (no guessing from the step, which the
    # interleaved topics make short)
    stamps = scan.values["timestamp"]
    guess.columns = {"time": {"column": "timestamp", "scale": 1e-6}} | {
        k: v for k, v in guess.columns.items() if k != "time"
    }
    guess.comments["time"] = "ULog: microseconds since boot"
    _px4_conventions(guess)
    guess.alternatives.pop("time", None)
    guess.unrecognised = [r for r in guess.unrecognised if r != "time"]
    guess.t0, guess.duration = stamps[0] * 1e-6, (stamps[-1] - stamps[0]) * 1e-6
    t0 = float(stamps[0])
    topics = [
        topic_info(name, f"{len(fields)} fields", (st - t0) * 1e-6)
        for name, (st, fields) in u.topics.items()
    ]
    notes = [
        *u.notes,
        f"{len(topics)} topics, {len(scan.values) - 1} numeric columns named topic.field; "
        "a column map (vehicle 'columns:') is needed to read it",
    ]
    return _mapped_inspection(
        path,
        "ulog",
        guess,
        topics,
        notes,
        column_ranges={k: v for k, v in scan.ranges().items() if k != "timestamp"},
        column_units={k: ulog_unit(k) for k in scan.values if k != "timestamp"},
        column_rates={k: t.rate for t in topics for k in u.topics[t.name][1]},
    )


def _inspect_table(path: Path) -> Inspection:
    """Inspection of a Crazyflie SD-card log or Betaflight blackbox CSV read without a
    column map: each group of rows as a topic, every column with its unit and rate,
    and a suggested column map with the reader's time column."""
    from omavctl.logs.columnlogs import load_table
    from omavctl.logs.inventory import table_inventory
    from omavctl.logs.read import FORMAT_LABELS
    from omavctl.logs.stats import topic_info
    from omavctl.logs.suggest import suggest_column_map
    from omavctl.logs.tables import scan_table

    table = load_table(path, detect_format(path))
    inv = table_inventory(table)
    scan = scan_table(table)
    guess = suggest_column_map(scan)
    time: dict[str, Any] = {"column": table.time_column}
    if table.time_scale != 1.0:
        time["scale"] = table.time_scale
    guess.columns = {"time": time} | {k: v for k, v in guess.columns.items() if k != "time"}
    unit = table.units.get(table.time_column, "s")
    guess.comments["time"] = f"{FORMAT_LABELS[inv.format]}: {unit}"
    guess.alternatives.pop("time", None)
    guess.unrecognised = [r for r in guess.unrecognised if r != "time"]
    if inv.format == "betaflight":
        guess.frame = ("FLU", "the reader turns Betaflight's gyro into rad/s FLU")
        _betaflight_extras(guess, inv.meta, table.units)
    stamps = scan.values[table.time_column] * table.time_scale
    guess.t0, guess.duration = float(stamps[0]), float(stamps[-1] - stamps[0])
    topics = [topic_info(g.name, f"{len(g.columns)} columns", g.stamps * table.time_scale
                         - guess.t0) for g in table.groups]  # fmt: skip
    notes = [*inv.notes, f"{len(inv.columns)} numeric columns; a column map (vehicle "
             "'columns:') is needed to read it"]  # fmt: skip
    return _mapped_inspection(
        path,
        inv.format,
        guess,
        topics,
        notes,
        column_ranges={c.name: (c.lo, c.hi) for c in inv.columns if c.count},
        column_units=inv.units(),
        column_rates={c.name: c.rate for c in inv.columns},
        header_values={k: v for k, v in inv.meta.items() if k != "header"},
    )


def _betaflight_extras(guess: Suggestion, meta: dict[str, Any], units: dict[str, str]) -> None:
    """The battery voltage (``vbatLatest`` when the reader has it in volts, for
    battery_sag) and the header's ``motorOutput`` range, into a Betaflight suggestion."""
    if str(units.get("vbatLatest", "")).startswith("V"):
        guess.columns["battery_voltage"] = "vbatLatest"
        guess.comments["battery_voltage"] = f"{units['vbatLatest']}; battery_sag needs it"
    span = meta.get("motor_output")
    if guess.motors is not None and isinstance(span, list | tuple) and len(span) == 2:
        guess.header_range = (float(span[0]), float(span[1]))


def _mapped_inspection(
    path: Path,
    fmt: str,
    guess: Suggestion,
    topics: list[TopicInfo],
    notes: list[str],
    **columns: Any,
) -> Inspection:
    """The inspection of a log that only a column map can read (ULog, Crazyflie,
    Betaflight): no role found until mapped, the suggested map, and ``columns``
    (``column_ranges``, ``column_units``, ``column_rates``, ``header_values``)."""
    from omavctl.logs.suggest import suggestion_yaml

    return Inspection(
        path=path,
        format=fmt,
        duration=guess.duration,
        t0=guess.t0,
        topics=topics,
        roles_found={},
        roles_missing={role: "needs a column map" for role in _needed(guess)},
        required=_needed(guess),
        notes=notes,
        suggested_columns=guess.columns,
        suggestion=suggestion_yaml(guess, path.name),
        **columns,
    )


def _px4_conventions(guess: Suggestion) -> None:
    """What PX4 fixes whatever the data say: body vectors in FRD, and
    ``actuator_controls_0.control[3]`` a thrust 0..1 along -z (scale -1)."""
    if guess.frame is None:
        guess.frame = ("FRD", "PX4 logs body vectors in FRD")
    force = guess.columns.get("force_command")
    if force and force.get("z") == "actuator_controls_0.control[3]" and "scale" not in force:
        force["scale"] = -1.0
        guess.comments["force_command"] += (
            "; PX4 thrust 0..1 acts along -z (FRD): scale -1 points it up"
        )


#: Columns listed in full up to this many; beyond, only those of the suggested map.
MAX_LISTED_COLUMNS = 40


def _shown_columns(ins: Inspection) -> list[str]:
    """The columns whose ranges ``inspect`` prints: all of them, or, for a log of more
    than :data:`MAX_LISTED_COLUMNS` with a suggested map, the ones the map names."""
    if len(ins.column_ranges) <= MAX_LISTED_COLUMNS or not ins.suggested_columns:
        return list(ins.column_ranges)
    named: set[str] = set()

    def walk(value: Any) -> None:
        if isinstance(value, dict):
            for v in value.values():
                if isinstance(v, str):  # a column name (scales and offsets are numbers)
                    named.add(v)
                walk(v)

    walk(ins.suggested_columns)
    return [name for name in ins.column_ranges if name in named]


def _cell(value: float | str | None) -> str:
    """A rate (one decimal) or unit for the columns table; empty when unknown."""
    if value is None:
        return ""
    return f"{value:.1f}" if isinstance(value, float) else value


def render_inspect(ins: Inspection, console: Console) -> None:
    """Print an :class:`Inspection` to a rich console: topic table, roles, notes."""
    from rich.markup import escape
    from rich.table import Table

    console.print(
        f"[bold]{escape(str(ins.path))}[/bold]: {_FORMAT_TITLES.get(ins.format, ins.format)}, "
        f"{ins.duration:.2f} s"
    )
    table = Table(title="Topics" if ins.format != "csv" else "Column groups")
    # full topic and type names matter more than column widths: fold, never elide
    table.add_column("name", overflow="fold")
    table.add_column("type", overflow="fold")
    for name in ("count", "rate Hz", "gaps", "dup.", "unordered"):
        table.add_column(name, justify="right")
    for t in ins.topics:
        table.add_row(
            t.name,
            t.msgtype,
            str(t.count),
            f"{t.rate:.1f}",
            str(len(t.gaps)),
            str(t.duplicates),
            str(t.out_of_order),
        )
    if ins.topics or ins.format != "csv":
        console.print(table)
    if ins.column_ranges:
        shown = _shown_columns(ins)
        ranges = Table(title="Columns" if len(shown) == len(ins.column_ranges) else
                       "Columns of the suggested map")  # fmt: skip
        ranges.add_column("column", overflow="fold")
        ranges.add_column("min", justify="right")
        ranges.add_column("max", justify="right")
        extra: list[tuple[str, Mapping[str, float | str]]] = [
            (title, values)
            for title, values in (("rate Hz", ins.column_rates), ("unit", ins.column_units))
            if values
        ]
        for title, _ in extra:
            ranges.add_column(title, justify="right" if title == "rate Hz" else "left")
        for name in shown:
            lo, hi = ins.column_ranges[name]
            more = [_cell(values.get(name)) for _, values in extra]
            ranges.add_row(name, f"{lo:.6g}", f"{hi:.6g}", *more)
        console.print(ranges)
        if len(shown) < len(ins.column_ranges):
            console.print(
                f"and {len(ins.column_ranges) - len(shown)} more columns: "
                "inspect --json lists every one (column_ranges)"
            )
    if ins.roles_found:
        found = ", ".join(ins.roles_found)
        console.print(f"[green]roles found[/green]: {found}")
    # what fit and evaluate need is said below in red; the other roles are optional
    needed = [r for r in ins.roles_missing if r in ins.required_missing]
    if needed:
        missing = escape(", ".join(f"{r} ({ins.roles_missing[r]})" for r in needed))
        console.print(f"[yellow]roles missing[/yellow]: {missing}", soft_wrap=True)
    optional = [r for r in ins.roles_missing if r not in ins.required_missing]
    if optional:
        console.print(f"optional roles not in the log: {', '.join(optional)}", soft_wrap=True)
    if ins.required_missing:
        console.print("[red]fit and evaluate need[/red]: " + ", ".join(ins.required_missing))
    shown_header = {k: v for k, v in ins.header_values.items() if v is not None}
    if shown_header:
        text = ", ".join(f"{k} {v}" for k, v in shown_header.items())
        console.print(f"log header: {text}", markup=False, highlight=False, soft_wrap=True)
    for note in ins.notes:
        console.print(f"note: {note}", markup=False, highlight=False)
    if ins.suggestion:
        console.print("\nsuggested column map (paste into the vehicle YAML, then check it):")
        console.print(ins.suggestion, markup=False, highlight=False, soft_wrap=True, end="")
