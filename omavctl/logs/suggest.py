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
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.logs.columnmap import _MISSING_CELLS, read_table

__all__ = ["ColumnScan", "Suggestion", "scan_csv", "suggest_column_map", "suggestion_yaml"]


@dataclass
class ColumnScan:
    """The columns of a CSV file: ``values`` of the numeric ones (shape (rows,),
    NaN where empty), names of the all-empty and non-numeric ones, in file order."""

    path: Path
    header: list[str]
    rows: int
    values: dict[str, np.ndarray] = field(default_factory=dict)
    empty: list[str] = field(default_factory=list)
    non_numeric: list[str] = field(default_factory=list)

    def ranges(self) -> dict[str, tuple[float, float]]:
        """(min, max) of every numeric column, in file order."""
        return {name: (float(np.nanmin(v)), float(np.nanmax(v))) for name, v in self.values.items()}


def scan_csv(path: Path) -> ColumnScan:
    """Read every column of a CSV as numbers where it can (see :class:`ColumnScan`).

    Raises:
        LogError: unreadable file, no header or no data rows.
    """
    table = read_table(path)
    scan = ColumnScan(path=path, header=table.header, rows=len(table.rows))
    seen: set[str] = set()
    for j, name in enumerate(table.header):
        if not name or name in seen:
            continue
        seen.add(name)
        cells = table.cells(j)
        try:
            values = np.array([np.nan if c in _MISSING_CELLS else float(c) for c in cells])
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

_TOKEN = re.compile(r"[A-Z]+(?=[A-Z][a-z])\d*|[A-Z]?[a-z]+\d*|[A-Z]+\d*|\d+")
_SETPOINT = {
    "sp", "setpoint", "des", "desired", "dem", "demand", "ref", "reference", "target",
    "tgt", "goal", "cmdvel",
}  # fmt: skip
_NOISE = {
    "bias", "offset", "scale", "var", "variance", "std", "cov", "covariance", "err",
    "error", "integral", "int", "rint", "clip", "temp", "temperature", "cal", "calib",
    "noise", "vib", "innov", "test", "max", "min", "limit", "lim", "trim", "hover", "hvr",
}  # fmt: skip
_META = {"parm", "param", "params", "ver", "version"}
_OUTPUTS = {"pwm", "motor", "motors", "esc", "servo", "rpm", "rc", "ch", "chan", "channel", "in"}
_GYRO = {"gyro", "gyr", "gyroscope", "gyros", "omega", "angvel", "angrate"}
_RATE = {"rate", "rates", "bodyrate", "bodyrates"}
_CONTROL = {
    "ctrl", "control", "controls", "attc", "atc", "actuator", "actuators", "act", "out",
    "output", "cmd", "command", "mix", "mixer", "u",
}  # fmt: skip
_TORQUE = {"torque", "torques", "moment", "moments", "tau"}
_OUT_WORDS = {"out", "output", "outputs"}
_ATTITUDE = {"att", "attitude", "euler", "ahrs", "ahr", "orientation", "ekf", "nkf", "est", "pose"}
_THRUST = {"thrust", "throttle", "thr", "collective", "tho", "thro"}
_POSITION = {"pos", "position", "lpos"}
_VELOCITY_ACC = {"v", "vel", "velocity", "acc", "accel", "acceleration", "spd", "speed"}
_QUAT = {"q", "quat", "quaternion", "orientation"}
_TIME = {"time", "timestamp", "stamp", "utime", "timeus", "timestamps"}
_TIME_OK = _TIME | {"start", "log", "sys", "system", "boot", "us", "usec", "ms", "ns", "s", "sec"}
_TIME_BAD = {"offset", "delta", "dt", "since", "span", "rem", "remaining", "left", "hb", "diff"}
_UNIT_SCALES: dict[str, float] = {
    **dict.fromkeys(("us", "usec", "micros", "microseconds", "micro"), 1e-6),
    **dict.fromkeys(("ms", "msec", "millis", "milliseconds"), 1e-3),
    **dict.fromkeys(("ns", "nsec", "nanos", "nanoseconds", "nanosec"), 1e-9),
    **dict.fromkeys(("sec", "secs", "seconds"), 1.0),
}
_DEG = {"deg", "degs", "degrees", "dps"}
_AXES = ("x", "y", "z")
_RPY = ("roll", "pitch", "yaw")
_RPY_LETTER = {"r": "roll", "p": "pitch", "y": "yaw"}


def _tokens(name: str) -> list[str]:
    """Words of a column name, original case: ``IMU1_GyroX`` -> ``IMU1, Gyro, X``."""
    return [m.group(0) for part in re.split(r"[^A-Za-z0-9]+", name) for m in _TOKEN.finditer(part)]


def _base(token: str) -> str:
    """Lower-case word without trailing digits (``IMU1`` -> ``imu``)."""
    stripped = token.lower().rstrip("0123456789")
    return stripped or token


def _primary(tokens: Iterable[str]) -> int:
    """0 for a group word without a number, 1 + the number otherwise (largest)."""
    rank = 0
    for tok in tokens:
        m = re.search(r"[A-Za-z](\d+)$", tok)
        if m:
            rank = max(rank, int(m.group(1)) + 1)
    return rank


def _is_setpoint(bases: set[str]) -> bool:
    return bool(bases & _SETPOINT) or any(b.endswith("sp") and 3 <= len(b) <= 5 for b in bases)


# --- candidates ----------------------------------------------------------------------


@dataclass
class _Candidate:
    """Columns for one role: ``members`` axis -> column (axis names of the role
    entry, ``quaternion`` axes w/x/y/z), ranked by ``key`` (lower is better)."""

    role: str
    members: dict[str, str]
    rank: int
    primary: int
    order: int
    constant: bool = False
    quaternion: bool = False

    @property
    def key(self) -> tuple[int, int, int, int]:
        return (self.rank, int(self.constant), self.primary, self.order)

    def columns(self) -> list[str]:
        return list(self.members.values())


def _split(name: str) -> tuple[str, str, list[str]] | None:
    """``(kind, axis, stem tokens)`` of a vector-like column name, or None.

    kind is ``quat`` (axis w/x/y/z or 0..4), ``xyz``, ``index`` (axis a digit
    string) or ``rpy``.
    """
    tokens = _tokens(name)
    if not tokens:
        return None
    low = [t.lower() for t in tokens]
    last = low[-1]
    m = re.fullmatch(r"(w|omega)_?([xyz])", "".join(low))
    if m:  # wx, omega_y
        return "xyz", m.group(2), ["omega"]
    m = re.fullmatch(r"(q|quat|quaternion)([wxyz0-4])", last)
    if m:
        return "quat", m.group(2), tokens[:-1]
    if len(low) >= 2 and _base(low[-2]) in _QUAT and re.fullmatch(r"[wxyz0-4]", last):
        return "quat", last, tokens[:-2]
    if last in _AXES:
        return "xyz", last, tokens[:-1]
    if last.isdigit():
        return "index", last, tokens[:-1]
    for i, tok in enumerate(low):
        if tok in _RPY:
            return "rpy", tok, [*tokens[:i], "*", *tokens[i + 1 :]]
        nxt = low[i + 1] if i + 1 < len(low) else ""
        if tok in _RPY_LETTER and nxt in ("out", "output", "cmd"):
            return "rpy", _RPY_LETTER[tok], [*tokens[:i], "*", *tokens[i + 1 :]]
    return None


def _quat_axes(axes: dict[str, str]) -> dict[str, str] | None:
    """Quaternion components w, x, y, z -> column, from letters or numbers (w first)."""
    if set(axes) >= {"w", "x", "y", "z"}:
        return {a: axes[a] for a in "wxyz"}
    for first in ("0", "1"):
        nums = [str(int(first) + i) for i in range(4)]
        if set(nums) <= set(axes):
            return dict(zip("wxyz", (axes[n] for n in nums), strict=True))
    return None


def _classify(
    kind: str, bases: set[str], axes: dict[str, str]
) -> list[tuple[str, dict[str, str], int]]:
    """Roles a column group may fill: ``(role, members, rank)``."""
    if bases & (_NOISE | _META) or _is_setpoint(bases):
        return []
    out: list[tuple[str, dict[str, str], int]] = []
    if kind == "quat":
        quat = _quat_axes(axes)
        if quat is not None and not bases & _OUTPUTS:
            out.append(("attitude", quat, 1))
        return out
    if kind == "rpy":
        if not set(_RPY) <= set(axes) or bases & _OUTPUTS:
            return []
        xyz = dict(zip(_AXES, (axes[a] for a in _RPY), strict=True))
        if bases & _RATE and bases & {"cmd", "command"}:
            return []  # a rate command is a setpoint
        if bases & _TORQUE:
            out.append(("torque_command", xyz, 0))
        elif bases & _CONTROL:
            out.append(("torque_command", xyz, 1))
        elif bases & _RATE:
            out.append(("body_rate", xyz, 2))
        elif not bases & (_VELOCITY_ACC | _GYRO | _THRUST):
            out.append(("attitude", {a: axes[a] for a in _RPY}, 0 if bases & _ATTITUDE else 2))
        return out
    if kind == "index":
        numbers = sorted(int(a) for a in axes)
        if numbers[:3] != [0, 1, 2]:
            return []
        xyz = {a: axes[str(i)] for i, a in enumerate(_AXES)}
        if bases & _GYRO or {"angular", "velocity"} <= bases:
            out.append(("body_rate", xyz, 1))
        elif bases & _TORQUE:
            out.append(("torque_command", xyz, 1))
        elif bases & _CONTROL and not bases & _OUT_WORDS:
            # actuator-control style: 0..2 roll/pitch/yaw, 3 thrust
            out.append(("torque_command", xyz, 2))
            if "3" in axes:
                out.append(("force_command", {"z": axes["3"]}, 2))
        return out
    # kind == "xyz"
    if not set(_AXES) <= set(axes) or bases & _OUTPUTS:
        return []
    xyz = {a: axes[a] for a in _AXES}
    if bases & _GYRO or {"angular", "velocity"} <= bases:
        out.append(("body_rate", xyz, 0))
    elif "force" in bases:
        out.append(("force_command", xyz, 0))
    elif bases & _TORQUE:
        out.append(("torque_command", xyz, 0))
    elif bases & _POSITION and not bases & _VELOCITY_ACC:
        out.append(("position", xyz, 0))
    elif bases & _RATE and not bases & _VELOCITY_ACC:
        out.append(("body_rate", xyz, 2))
    return out


def _candidates(scan: ColumnScan) -> dict[str, list[_Candidate]]:
    """Every plausible column group per role, best first."""
    order = {name: i for i, name in enumerate(scan.header)}
    groups: dict[tuple[str, str], dict[str, str]] = {}
    stems: dict[tuple[str, str], list[str]] = {}
    singles: list[str] = []
    for name in scan.values:
        parts = _split(name)
        if parts is None:
            singles.append(name)
            continue
        kind, axis, stem = parts
        key = (kind, "_".join(t.lower() for t in stem))
        groups.setdefault(key, {}).setdefault(axis, name)
        stems[key] = stem
        if kind == "xyz" and len(stem) == 0:
            singles.append(name)
    found: dict[str, list[_Candidate]] = {}

    def constant(cols: list[str]) -> list[bool]:
        return [bool(np.nanmin(scan.values[c]) == np.nanmax(scan.values[c])) for c in cols]

    def add(role: str, members: dict[str, str], rank: int, stem: list[str], quat: bool) -> None:
        flags = constant(list(members.values()))
        if all(flags):
            return  # no information in any column (e.g. an unused quaternion of zeros)
        found.setdefault(role, []).append(
            _Candidate(
                role=role,
                members=members,
                rank=rank,
                primary=_primary(stem),
                order=min(order[c] for c in members.values()),
                constant=any(flags),
                quaternion=quat,
            )
        )

    for key, axes in groups.items():
        stem = stems[key]
        bases = {_base(t) for t in stem if t != "*"}
        for role, members, rank in _classify(key[0], bases, axes):
            add(role, members, rank, stem, key[0] == "quat")
    for name in singles:
        tokens = _tokens(name)
        # words and whole name parts: CTUN.ThO has the part "tho" (throttle out)
        bases = {_base(t) for t in tokens} | {
            p.lower() for p in re.split(r"[^A-Za-z0-9]+", name) if p
        }
        if bases & _THRUST and not (bases & (_NOISE | _META | _OUTPUTS) or _is_setpoint(bases)):
            add("force_command", {"z": name}, 0 if bases & _CONTROL else 1, tokens, False)
    for role in found:
        found[role].sort(key=lambda c: c.key)
    return found


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
        tokens = [t.lower() for t in _tokens(name)]
        bases = {_base(t) for t in tokens}
        if tokens and tokens[0] == "t" and set(tokens[1:]) <= set(_UNIT_SCALES) | {"s"}:
            name_rank = 0  # t, t_s, t_us
        elif bases & _TIME and not bases & _TIME_BAD:
            name_rank = 0 if bases <= _TIME_OK else 1 + int("gps" in bases or "utc" in bases)
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
    words = {t.lower() for t in _tokens(best)}
    if words & {"t", "time"} and "s" in words:
        words.add("sec")  # t_s, time_s
    hinted = [_UNIT_SCALES[w] for w in words if w in _UNIT_SCALES]
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


def suggest_column_map(scan: ColumnScan) -> Suggestion:
    """Guess a role-based column map from column names (rules in the module docs)."""
    found = _candidates(scan)
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
    for role in ("body_rate", "attitude", "torque_command", "force_command", "position"):
        cands = found.get(role, [])
        if not cands:
            continue
        best = cands[0]
        cols = best.columns()
        lo, hi = _range(scan, cols)
        note = f"range {lo:.3g}..{hi:.3g}"
        scale = 1.0
        bases = {_base(tok) for c in cols for tok in _tokens(c)}
        if role == "body_rate":
            if bases & _DEG or max(abs(lo), abs(hi)) > 40.0:
                scale = math.pi / 180.0
                note += "; looks like deg/s: scale converts to rad/s"
            else:
                note += "; rad/s assumed"
        elif role == "attitude" and not best.quaternion:
            if bases & _DEG or max(abs(lo), abs(hi)) > 2.0 * math.pi + 0.2:
                scale = math.pi / 180.0
                note += "; looks like deg: scale converts to rad"
            else:
                note += "; rad assumed (ZYX Euler)"
        elif role == "attitude":
            note += "; quaternion, w first"
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
    required = ("time", "body_rate", "attitude", "torque_command", "force_command")
    unrecognised = [r for r in required if r not in columns]
    return Suggestion(columns, comments, alternatives, unrecognised, t0, duration)


def _flow(value: Any) -> str:
    """A YAML flow mapping of strings (quoted) and floats."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, str):
        return json.dumps(value)
    return _fmt(value)


def suggestion_yaml(s: Suggestion, source: str) -> str:
    """The suggestion as YAML to paste into a vehicle file (``columns:`` and ``frame:``)."""
    lines = [
        f"# Column map GUESSED by omavctl inspect from the column names of {source}.",
        "# Check every entry (column, unit -> scale, sign) and the frame before use.",
        "columns:",
    ]
    for role, value in s.columns.items():
        lines.append(f"  {role}: {_flow(value)}  # {s.comments[role]}")
        if role in s.alternatives:
            lines.append(f"  #   other candidates: {', '.join(s.alternatives[role])}")
    for role in s.unrecognised:
        lines.append(f"  # {role}: not recognised from the column names; map it by hand")
    lines.append(
        "frame: FLU  # not known from names: FRD if x forward, y right, z down (then a "
        "positive thrust needs scale: -1.0)"
    )
    return "\n".join(lines) + "\n"
