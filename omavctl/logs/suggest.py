"""Guess a column map for a CSV of another layout from its column names.

Used by ``omavctl inspect`` on a CSV that is not a wide contract CSV. Generic
heuristics on the column names (no logger is special-cased):

- names are split into words (``IMU_GyroX`` -> ``IMU``, ``Gyro``, ``X``;
  ``gyro_rad[0]`` -> ``gyro``, ``rad``, ``0``); a trailing ``x/y/z`` or index
  ``0..2``, or a ``roll/pitch/yaw`` word, is the axis, the rest the *stem*;
- gyro / angular-velocity stems -> ``body_rate`` (``*RollRate`` style
  columns are a second choice); ``roll/pitch/yaw`` with a control word
  (``ctrl``, ``control``, ``out``, ``cmd``, ``torque``, ``moment``,
  ``attc`` ...) -> ``torque_command``; plain ``roll/pitch/yaw`` ->
  ``attitude``; ``q0..q3`` / ``qw..qz`` / ``quaternion.*`` -> attitude
  quaternion (``w`` first for numbered components); ``thrust`` / ``throttle``
  -> ``force_command`` z; ``pos``/``position`` x/y/z -> ``position``;
  ``acc``/``accel``/``accelerometer`` x/y/z (no velocity word) -> ``specific_force``,
  scaled from g when its median norm is about 1;
  ``time`` / ``timestamp`` / ``t`` -> time, its scale from unit words
  (``us``, ``ms``, ``ns``) or else from the size of its median step;
- setpoints (``sp``, ``des``, ``ref``, ``target`` ...), biases, variances,
  metadata and motor/PWM outputs are never suggested;
- among several candidates the primary sensor wins (a group word without a
  number, then the lowest number: ``IMU`` over ``IMU1`` over ``IMU2``), then
  non-constant columns, then the first in the file; the others are listed.

The result is a guess, printed as YAML to paste into a vehicle file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.logs.colnames import (
    DEG_WORDS,
    TIME_BAD_WORDS,
    TIME_OK_WORDS,
    TIME_WORDS,
    UNIT_SCALES,
    ColumnScan,
    candidates,
    name_words,
    word_base,
)
from omavctl.logs.csvlog import MISSING_CELLS, csv_columns, cut_row_notes, read_table
from omavctl.logs.motorcols import MotorGuess, guess_motor_outputs

__all__ = [
    "ColumnScan",
    "Suggestion",
    "look_alike_notes",
    "scan_csv",
    "suggest_column_map",
    "suggestion_yaml",
]


def scan_csv(path: Path) -> ColumnScan:
    """Read every column of a CSV as numbers where it can (see :class:`ColumnScan`).

    Raises:
        LogError: unreadable file, no header or no data rows.
    """
    table = read_table(path)
    scan = ColumnScan(
        path=path, header=table.header, rows=len(table.rows), notes=cut_row_notes(table)
    )
    seen: set[str] = set()
    for j, name in enumerate(table.header):
        if not name or name in seen:
            continue
        seen.add(name)
        cells = table.cells(j)
        try:
            values = np.array([np.nan if c in MISSING_CELLS else float(c) for c in cells])
        except ValueError:
            scan.non_numeric.append(name)
            continue
        values[~np.isfinite(values)] = np.nan
        if np.isnan(values).all():
            scan.empty.append(name)
        else:
            scan.values[name] = values
    return scan


# --- words ---------------------------------------------------------------------------


@dataclass
class _Time:
    column: str
    scale: float
    step: float  # median raw step
    t0: float  # s
    duration: float  # s


def _time_column(scan: ColumnScan) -> tuple[_Time | None, list[str]]:
    """The best time column (and the other candidates' names)."""
    ranked: list[tuple[tuple[int, float, int], str]] = []
    for j, (name, values) in enumerate(scan.values.items()):
        tokens = [t.lower() for t in name_words(name)]
        bases = {word_base(t) for t in tokens}
        if tokens and tokens[0] == "t" and set(tokens[1:]) <= set(UNIT_SCALES) | {"s"}:
            name_rank = 0  # t, t_s, t_us
        elif bases & TIME_WORDS and not bases & TIME_BAD_WORDS:
            name_rank = 0 if bases <= TIME_OK_WORDS else 1 + int("gps" in bases or "utc" in bases)
        else:
            continue
        v = values[np.isfinite(values)]
        if v.size < 2:
            continue
        d = np.diff(v)
        if np.mean(d >= 0) < 0.99 or not (d > 0).any():
            continue
        coverage = v.size / scan.rows
        if coverage < 0.5:
            continue
        ranked.append(((name_rank, -round(coverage, 2), j), name))
    if not ranked:
        return None, []
    ranked.sort()
    best = ranked[0][1]
    v = scan.values[best]
    v = v[np.isfinite(v)]
    step = float(np.median(np.diff(v)[np.diff(v) > 0]))
    words = {t.lower() for t in name_words(best)}
    if words & {"t", "time"} and "s" in words:
        words.add("sec")  # t_s, time_s
    hinted = [UNIT_SCALES[w] for w in words if w in UNIT_SCALES]
    if hinted:
        scale = hinted[0]
    else:  # the unit whose median step is nearest 10 ms (right for about 3 Hz to 3 kHz)
        scales = (1.0, 1e-3, 1e-6, 1e-9)
        scale = min(scales, key=lambda s: abs(math.log10(step * s) + 2.0))
    t = _Time(best, scale, step, float(v.min()) * scale, float(v.max() - v.min()) * scale)
    return t, [name for _, name in ranked[1:]]


@dataclass
class Suggestion:
    """A guessed column map: ``columns`` in the role-based format (see
    :mod:`omavctl.logs.columnmap`), a ``comment`` per role (units, ranges,
    how it was chosen), ``alternatives`` per role (other candidates, compact),
    ``unrecognised`` roles ``fit`` needs but no column was found for."""

    columns: dict[str, Any]
    comments: dict[str, str]
    alternatives: dict[str, list[str]]
    unrecognised: list[str]
    t0: float = 0.0  # s, first time value (scaled)
    duration: float = 0.0  # s
    #: the frame the logged vectors are in, and why (an accelerometer's sign of g);
    #: None when nothing in the log tells
    frame: tuple[str, str] | None = None
    #: per-motor output columns (``motor_command``) and the preset they fit
    motors: MotorGuess | None = None
    #: the command range the log's header declares (Betaflight's ``motorOutput``)
    header_range: tuple[float, float] | None = None


def _compact(cols: list[str]) -> str:
    """``IMU1_GyroX, IMU1_GyroY, IMU1_GyroZ`` -> ``IMU1_Gyro{X,Y,Z}``."""
    if len(cols) == 1:
        return cols[0]
    prefix = cols[0]
    for c in cols[1:]:
        while not c.startswith(prefix):
            prefix = prefix[:-1]
    rest = [c[len(prefix) :] for c in cols]
    suffix = rest[0]
    for r in rest[1:]:
        while not r.endswith(suffix):
            suffix = suffix[1:]
    mids = [r[: len(r) - len(suffix)] for r in rest]
    if any(not m for m in mids):
        return ", ".join(cols)
    return f"{prefix}{{{','.join(mids)}}}{suffix}"


def _fmt(x: float) -> str:
    """A float YAML (PyYAML) reads back as a float: ``1e-06`` -> ``1.0e-06``."""
    s = repr(float(x))
    if "e" in s:
        mant, exp = s.split("e")
        if "." not in mant:
            s = f"{mant}.0e{exp}"
    return s


def _range(scan: ColumnScan, cols: list[str]) -> tuple[float, float]:
    lo = min(float(np.nanmin(scan.values[c])) for c in cols)
    hi = max(float(np.nanmax(scan.values[c])) for c in cols)
    return lo, hi


#: Words of an accelerometer column and of columns that are not its measurement.
_ACC_WORDS = {"acc", "accel", "accelerometer", "acceleration"}
_NOT_MEASURED = {"bias", "var", "variance", "sp", "des", "ref", "target", "setpoint"}


def _frame(scan: ColumnScan) -> tuple[str, str] | None:
    """The body frame from an accelerometer's z axis: at rest or in hover it measures
    +g in FLU (z up) and -g in FRD (z down); its median tells, when near +-g. The first
    such column of the file (the primary sensor, as loggers list it first)."""
    for name, values in scan.values.items():
        words = [word_base(t.lower()) for t in name_words(name)]
        if not (_ACC_WORDS & set(words)) or words[-1] not in ("z", "2"):
            continue
        if _NOT_MEASURED & set(words):
            continue
        median = float(np.nanmedian(values))
        if abs(abs(median) - 9.81) < 2.5:
            up = median > 0
            return (
                "FLU" if up else "FRD",
                f"{name} reads {median:+.1f} m/s^2 (median): z points {'up' if up else 'down'}",
            )
    return None


def suggest_column_map(
    scan: ColumnScan, known: Sequence[tuple[str, dict[str, str], bool]] = ()
) -> Suggestion:
    """Guess a role-based column map from column names (rules in the module docs);
    ``known`` column groups of the log's format come first (:func:`candidates`)."""
    found = candidates(scan, known)
    columns: dict[str, Any] = {}
    comments: dict[str, str] = {}
    alternatives: dict[str, list[str]] = {}
    t, other_times = _time_column(scan)
    t0 = duration = 0.0
    if t is not None:
        entry: dict[str, Any] = {"column": t.column}
        if t.scale != 1.0:
            entry["scale"] = t.scale
        columns["time"] = entry
        dt = t.step * t.scale
        comments["time"] = f"median step {t.step:g} -> {dt * 1e3:.3g} ms ({1.0 / dt:.3g} Hz)"
        if other_times:
            alternatives["time"] = other_times[:4]
        t0, duration = t.t0, t.duration
    roles = ("body_rate", "attitude", "torque_command", "force_command", "position")
    for role in (*roles, "specific_force"):
        cands = found.get(role, [])
        if not cands:
            continue
        best = cands[0]
        cols = best.columns()
        lo, hi = _range(scan, cols)
        note = f"range {lo:.3g}..{hi:.3g}"
        scale = 1.0
        bases = {word_base(tok) for c in cols for tok in name_words(c)}
        if role == "body_rate":
            if bases & DEG_WORDS or max(abs(lo), abs(hi)) > 40.0:
                scale = math.pi / 180.0
                note += "; looks like deg/s: scale converts to rad/s"
            else:
                note += "; rad/s assumed"
        elif role == "attitude" and not best.quaternion:
            if bases & DEG_WORDS or max(abs(lo), abs(hi)) > 2.0 * math.pi + 0.2:
                scale = math.pi / 180.0
                note += "; looks like deg: scale converts to rad"
            else:
                note += "; rad assumed (ZYX Euler)"
        elif role == "attitude":
            note += "; quaternion, w first"
        elif role == "specific_force":
            scale, note = _accel_scale(scan, cols, note)
        elif role in ("torque_command", "force_command"):
            if max(abs(lo), abs(hi)) <= 1.5:
                note += "; looks normalised: units unknown"
            else:
                note += "; N / N m assumed"
        if best.quaternion:
            value: dict[str, Any] = {"quaternion": dict(best.members)}
        else:
            value = dict(best.members)
        if scale != 1.0:
            value["scale"] = scale
        columns[role] = value
        if best.constant:
            note += "; WARNING: a column is constant"
        comments[role] = note
        others = [_compact(c.columns()) for c in cands[1:]]
        if others:
            alternatives[role] = others[:6]
    motors, required = _motor_columns(scan, columns, comments)
    unrecognised = [r for r in required if r not in columns]
    frame = _frame(scan)
    force = columns.get("force_command")
    if frame and frame[0] == "FRD" and force and "z" in force:
        # thrust acts along -z in FRD: a thrust magnitude logged positive needs scale -1
        if float(np.nanmedian(scan.values[force["z"]])) > 0:
            force["scale"] = -float(force.get("scale", 1.0))
            comments["force_command"] += (
                "; thrust positive in an FRD log: scale -1 points it along -z, up"
            )
    return Suggestion(columns, comments, alternatives, unrecognised, t0, duration, frame, motors)


def look_alike_notes(path: Path, missing: Sequence[str]) -> list[str]:
    """For a contract CSV missing a role its other columns look like (``gyro_x`` for
    ``body_rate_x``: a new user read only "columns not in the contract ignored"), what to
    rename them to, one note per ``missing`` role."""
    guess = suggest_column_map(scan_csv(path)).columns
    notes = []
    for role in missing:
        cols = guess.get(role)
        if not isinstance(cols, dict) or not all(isinstance(c, str) for c in cols.values()):
            continue
        want = csv_columns(role)
        if len(want) != len(cols):
            continue
        notes.append(
            f"{role} is missing, but {', '.join(cols.values())} look like it: rename them "
            f"{', '.join(want)} (in the contract's units), or read the log with a vehicle "
            "file's column map (docs/logs.md)"
        )
    return notes


def _accel_scale(scan: ColumnScan, cols: list[str], note: str) -> tuple[float, str]:
    """The scale of an accelerometer group (m/s^2 or g, from the median norm of its
    samples, gravity's 1 g when still) and its note, for ``drag_moment``."""
    rows = np.column_stack([scan.values[c] for c in cols])
    norm = float(np.nanmedian(np.linalg.norm(rows, axis=1))) if rows.size else math.nan
    tail = "; the drag_moment effect (fit --effects drag_moment) reads it"
    if 0.5 < norm < 2.0:
        return 9.80665, note + f"; looks like g (median norm {norm:.3g}): scale to m/s^2{tail}"
    if 5.0 < norm < 15.0:
        return 1.0, note + f"; m/s^2 assumed (median norm {norm:.3g}){tail}"
    return 1.0, note + f"; unit unknown (median norm {norm:.3g}): set scale to m/s^2{tail}"


def _motor_columns(
    scan: ColumnScan, columns: dict[str, Any], comments: dict[str, str]
) -> tuple[MotorGuess | None, tuple[str, ...]]:
    """Add the motor outputs to a map without a torque command (a preset's rotor list
    mixes them into the wrench); the guess and the roles the map then needs."""
    motors = guess_motor_outputs(scan) if "torque_command" not in columns else None
    if motors is None:
        return None, ("time", "body_rate", "attitude", "torque_command", "force_command")
    columns["motor_command"] = list(motors.columns)
    comments["motor_command"] = motors.note
    return motors, ("time", "body_rate")


def _flow(value: Any) -> str:
    """A YAML flow mapping of strings (quoted) and floats."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value)
    return _fmt(value)


def suggestion_yaml(s: Suggestion, source: str) -> str:
    """The suggestion as YAML to paste into a vehicle file (``columns:`` and ``frame:``)."""
    lines = [
        f"# Column map GUESSED by omavctl inspect from the column names of {source}.",
        "# Check every entry (column, unit -> scale, sign) and the frame before use.",
    ]
    m = s.motors
    if m is not None:
        if m.preset:
            lines.append(f"preset: {m.preset}  # {m.why}")
        else:
            lines.append(f"# {m.why}")
        lines += _motor_unit_lines(m, s.header_range)
    lines.append("columns:")
    for role, value in s.columns.items():
        lines.append(f"  {role}: {_flow(value)}  # {s.comments[role]}")
        if role in s.alternatives:
            lines.append(f"  #   other candidates: {', '.join(s.alternatives[role])}")
    for role in s.unrecognised:
        lines.append(f"  # {role}: not recognised from the column names; map it by hand")
    if s.frame is not None:
        lines.append(f"frame: {s.frame[0]}  # {s.frame[1]}")
    else:
        lines.append(
            "frame: FLU  # not known from names: FRD if x forward, y right, z down (then a "
            "positive thrust needs scale: -1.0)"
        )
    if any("looks normalised" in c for c in s.comments.values()):
        lines.append(
            "# commands that look normalised: command_units: {torque: normalised, force: "
            "normalised} (fit then estimates their gain)"
        )
    return "\n".join(lines) + "\n"


def _preset_rotors(name: str) -> dict[str, Any]:
    """The rotor list (``motors:``) of preset ``name`` (a data file of the package),
    {} when there is no such preset or it has none."""
    import yaml

    path = Path(__file__).resolve().parents[1] / "data" / "presets" / f"{name}.yaml"
    try:
        motors = (yaml.safe_load(path.read_text()) or {}).get("motors") or {}
    except (OSError, yaml.YAMLError, AttributeError):
        return {}
    return motors if isinstance(motors, dict) else {}


def _preset_motors(name: str) -> tuple[str, list[float]] | None:
    """(unit, range) of the rotor list of preset ``name``, None when there is no such
    preset or it has no unit."""
    motors = _preset_rotors(name)
    unit, span = motors.get("unit"), motors.get("range")
    return (str(unit), list(span)) if unit and isinstance(span, list) else None


def _motor_unit_lines(m: MotorGuess, header: tuple[float, float] | None) -> list[str]:
    """The motor unit comment and, when the log's header declares an output range the
    preset's rotor list does not, why the preset's range stays: Betaflight's
    ``motorOutput`` runs from the armed idle (``48 + (2047 - 48) x digitalIdleOffset``
    for DShot: 138 at 4.5 %, motors spinning) to full, while the rotor list's range is
    the commands of zero and full throttle (DShot 48 and 2047), where the thrust curve
    takes 0 and 1. Taking the idle for zero thrust would shift every thrust."""
    line = _motor_unit_line(m.unit, m.range, m.preset)
    own = _preset_motors(m.preset) if m.preset else None
    if header is None or own is None or own[0] != m.unit:
        return [line]
    plo, phi = (float(v) for v in own[1])
    if [plo, phi] == [float(v) for v in header]:
        return [line]
    lo, hi = header
    idle = (
        f" (idle offset {100 * (lo - plo) / (phi - plo):.2f} % of {_fmt(plo)}..{_fmt(phi)})"
        if phi > lo > plo
        else ""
    )
    return [
        line,
        f"# the log's header says motorOutput {_fmt(lo)}..{_fmt(hi)}: the firmware's output "
        f"window, from its armed idle{idle} to full, not the command of zero thrust: keep "
        f"the range [{_fmt(plo)}, {_fmt(phi)}] (docs/logs.md)",
    ]


def _motor_unit_line(unit: str, span: tuple[float, float], preset: str) -> str:
    """The comment on the motor commands' unit: whether the suggested preset already
    declares it (then nothing is to be added) or a rotor list must."""
    lo, hi = (_fmt(v) for v in span)
    why = " (DShot: 48 is zero throttle, 2047 full)" if unit == "dshot" else ""
    own = _preset_motors(preset) if preset else None
    if own is not None and own[0] == unit:
        plo, phi = (_fmt(float(v)) for v in own[1])
        return (
            f"# motor commands look like {unit}{why}: preset {preset} declares that "
            f"(range [{plo}, {phi}]), nothing to add; a rotor list of your own must say "
            "so (motors: {unit: ..., range: [...]}; docs/logs.md)"
        )
    return (
        f"# motor commands look like {unit}{why}: the rotor list must say so "
        f"(motors: {{unit: {unit}, range: [{lo}, {hi}]}}; docs/logs.md)"
    )
