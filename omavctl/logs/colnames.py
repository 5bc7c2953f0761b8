"""Words of CSV column names: the vocabulary and role candidates of :mod:`~.suggest`.

A column name is split into words, its axis found, and the column classified
as a candidate for a contract role (see the heuristics in
:mod:`omavctl.logs.suggest`). Nothing here reads files.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "DEG_WORDS",
    "TIME_BAD_WORDS",
    "TIME_OK_WORDS",
    "TIME_WORDS",
    "UNIT_SCALES",
    "ColumnScan",
    "candidates",
    "name_words",
    "word_base",
]


@dataclass
class ColumnScan:
    """The columns of a CSV file: ``values`` of the numeric ones (shape (rows,),
    NaN where empty), names of the all-empty and non-numeric ones, in file order;
    ``notes`` what the reading found (a last row the file ends in the middle of)."""

    path: Path
    header: list[str]
    rows: int
    values: dict[str, np.ndarray] = field(default_factory=dict)
    empty: list[str] = field(default_factory=list)
    non_numeric: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def ranges(self) -> dict[str, tuple[float, float]]:
        """(min, max) of every numeric column, in file order."""
        return {name: (float(np.nanmin(v)), float(np.nanmax(v))) for name, v in self.values.items()}


_TOKEN = re.compile(r"[A-Z]+(?=[A-Z][a-z])\d*|[A-Z]?[a-z]+\d*|[A-Z]+\d*|\d+")
_SETPOINT = {
    "sp", "setpoint", "des", "desired", "dem", "demand", "ref", "reference", "target",
    "tgt", "goal", "cmdvel", "rc",  # rc: a pilot's stick input (Betaflight rcCommand)
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
_STATE = {"state", "estimate", "estimated"}
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
#: accelerometer words (the ``specific_force`` role); not with a velocity word
_ACCEL = {"acc", "accel", "accelerometer", "acceleration", "accsmooth", "imuacc"}
_SPEED = {"v", "vel", "velocity", "spd", "speed", "angular"}
TIME_WORDS = {"time", "timestamp", "stamp", "utime", "timeus", "timestamps"}
TIME_OK_WORDS = TIME_WORDS | {
    "start",
    "log",
    "sys",
    "system",
    "boot",
    "us",
    "usec",
    "ms",
    "ns",
    "s",
    "sec",
}
TIME_BAD_WORDS = {
    "offset",
    "delta",
    "dt",
    "since",
    "span",
    "rem",
    "remaining",
    "left",
    "hb",
    "diff",
}
UNIT_SCALES: dict[str, float] = {
    **dict.fromkeys(("us", "usec", "micros", "microseconds", "micro"), 1e-6),
    **dict.fromkeys(("ms", "msec", "millis", "milliseconds"), 1e-3),
    **dict.fromkeys(("ns", "nsec", "nanos", "nanoseconds", "nanosec"), 1e-9),
    **dict.fromkeys(("sec", "secs", "seconds"), 1.0),
}
DEG_WORDS = {"deg", "degs", "degrees", "dps"}
_AXES = ("x", "y", "z")
_RPY = ("roll", "pitch", "yaw")
_RPY_LETTER = {"r": "roll", "p": "pitch", "y": "yaw"}


def name_words(name: str) -> list[str]:
    """Words of a column name, original case: ``IMU1_GyroX`` -> ``IMU1, Gyro, X``."""
    return [m.group(0) for part in re.split(r"[^A-Za-z0-9]+", name) for m in _TOKEN.finditer(part)]


def word_base(token: str) -> str:
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
    tokens = name_words(name)
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
    if len(low) >= 2 and word_base(low[-2]) in _QUAT and re.fullmatch(r"[wxyz0-4]", last):
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
        if bases & _STATE:  # an estimate (PX4's control_state.roll_rate), not a command
            return [("body_rate", xyz, 2)] if bases & _RATE else []
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
        elif bases & _ACCEL and not bases & (_SPEED | _CONTROL):
            out.append(("specific_force", xyz, 1))
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
    elif bases & _ACCEL and not bases & (_SPEED | _CONTROL):
        out.append(("specific_force", xyz, 0))
    return out


def candidates(
    scan: ColumnScan, known: Sequence[tuple[str, dict[str, str], bool]] = ()
) -> dict[str, list[_Candidate]]:
    """Every plausible column group per role, best first.

    ``known``: (role, members, quaternion) groups a log format names by
    convention (PX4's topics in a ULog), best first: each one whose columns are
    all in the scan ranks before anything guessed from words.
    """
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

    def add(
        role: str,
        members: dict[str, str],
        rank: int,
        stem: list[str],
        quat: bool,
        known: bool = False,
    ) -> None:
        flags = constant(list(members.values()))
        if all(flags) and not known:
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
        bases = {word_base(t) for t in stem if t != "*"}
        for role, members, rank in _classify(key[0], bases, axes):
            add(role, members, rank, stem, key[0] == "quat")
    for name in singles:
        tokens = name_words(name)
        # words and whole name parts: CTUN.ThO has the part "tho" (throttle out)
        bases = {word_base(t) for t in tokens} | {
            p.lower() for p in re.split(r"[^A-Za-z0-9]+", name) if p
        }
        if bases & _THRUST and not (bases & (_NOISE | _META | _OUTPUTS) or _is_setpoint(bases)):
            add("force_command", {"z": name}, 0 if bases & _CONTROL else 1, tokens, False)
    for rank, (role, members, quat) in enumerate(known, start=-len(known)):
        if all(c in scan.values for c in members.values()):
            # by convention, even when constant (a thrust of 0 on the bench: said so)
            found[role] = [c for c in found.get(role, []) if c.members != members]
            add(role, members, rank, [], quat, known=True)
    for role in found:
        found[role].sort(key=lambda c: c.key)
    return found
