"""Guess a log's motor-output columns, their unit and the vehicle preset they fit.

Used by :func:`omavctl.logs.suggest.suggest_column_map`: columns whose names
hold a motor/output word and an index (``motor.m1``, ``motor[0]``,
``actuator_outputs.output[3]``, ``ESC_3``) form groups by their stem; the
best group (most columns that vary, then first in the file) becomes the
``motor_command`` list in index order. Outputs that never leave one value
(unused PWM channels) are dropped from the end. The command unit is read from
the range of the values; the preset from the logger's tell-tale columns
(Crazyflie ``motor.m1..m4``, Betaflight ``gyroADC`` / ``motor[i]``) or from
the number of outputs. Everything here is a guess printed for the user to check.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from omavctl.logs.colnames import ColumnScan, name_words, word_base

__all__ = ["MotorGuess", "guess_motor_outputs"]

#: Words of a per-motor output column.
_MOTOR_WORDS = {"motor", "motors", "m", "esc", "pwm", "output", "outputs", "out", "actuator"}
#: Words that make a column not a motor command (setpoints, measured values, RC input).
_NOT_COMMAND = {"rpm", "erpm", "rc", "ch", "chan", "channel", "in", "input", "temp", "current"}
#: Vehicle presets by name (``omavctl/data/presets``): the suggestion names one.
_PRESET_BY_COUNT = {4: "quad-x-?", 6: "hexa-x", 8: "octo-x"}


@dataclass
class MotorGuess:
    """``columns`` in output order; ``unit`` (a :data:`omavctl.rotors.COMMAND_UNITS`
    key) and ``range`` (lo, hi) of the commands; ``preset`` and why; ``note``."""

    columns: list[str]
    unit: str
    range: tuple[float, float]
    preset: str
    why: str
    note: str


def _index(name: str) -> tuple[str, int] | None:
    """(stem, index) of a motor-output column name, None for other columns."""
    match = re.search(r"(\d+)\D*$", name)
    if match is None:
        return None
    words = [word_base(t.lower()) for t in name_words(name[: match.start()])]
    words += [t.lower() for t in re.findall(r"[A-Za-z]+", name[: match.start()])]
    if not set(words) & _MOTOR_WORDS or set(words) & _NOT_COMMAND:
        return None
    return name[: match.start()], int(match.group(1))


def _unit(lo: float, hi: float) -> tuple[str, tuple[float, float]]:
    """The command unit a range of values looks like, and that unit's range."""
    if hi <= 1.0 + 1e-9 and lo >= -1.0:
        return "normalised", (0.0, 1.0)
    if 800.0 <= lo and hi <= 2200.0:
        return "pwm_us", (1000.0, 2000.0)
    if hi <= 2047.0:
        return "dshot", (48.0, 2047.0)
    if hi <= 65535.0:
        return "pwm16", (0.0, 65535.0)
    return "rpm", (0.0, hi)


def guess_motor_outputs(scan: ColumnScan) -> MotorGuess | None:
    """The motor-output columns of a log (rules in the module docs), None if none."""
    groups: dict[str, dict[int, str]] = {}
    for name in scan.values:
        found = _index(name)
        if found is not None:
            groups.setdefault(found[0], {}).setdefault(found[1], name)
    best: tuple[int, list[str]] | None = None
    for members in groups.values():
        cols = [members[i] for i in sorted(members)]
        varying = [c for c in cols if np.nanmax(scan.values[c]) > np.nanmin(scan.values[c])]
        if len(varying) < 3:  # a multirotor has three or more
            continue
        while cols and cols[-1] not in varying:
            cols.pop()  # unused outputs at the end
        if best is None or len(varying) > best[0]:
            best = (len(varying), cols)
    if best is None:
        return None
    cols = best[1]
    lo = min(float(np.nanmin(scan.values[c])) for c in cols)
    hi = max(float(np.nanmax(scan.values[c])) for c in cols)
    unit, span = _unit(lo, hi)
    preset, why = _preset(scan, cols)
    note = f"{len(cols)} outputs, range {lo:.4g}..{hi:.4g}: looks like {unit}"
    return MotorGuess(cols, unit, span, preset, why, note)


def _preset(scan: ColumnScan, cols: list[str]) -> tuple[str, str]:
    """The preset a log's motor columns fit, and why."""
    names = set(scan.values)
    if [c.lower() for c in cols] == [f"motor.m{i}" for i in range(1, 5)]:
        return "quad-x-crazyflie", "columns motor.m1..m4: a Crazyflie log (m1 front-right)"
    if {"gyroADC[0]", "motor[0]"} <= names:
        return "quad-x-betaflight", "columns gyroADC[i], motor[i]: a Betaflight blackbox log"
    preset = _PRESET_BY_COUNT.get(len(cols))
    if preset == "quad-x-?" and cols[0].startswith(("actuator_outputs", "actuator_motors")):
        return "quad-x-px4", "PX4 actuator outputs of 4 motors: PX4's quad-X order"
    if preset == "quad-x-?":
        return "quad-x-betaflight", (
            "4 outputs: a quad-X; check the motor order (quad-x-betaflight: rear-right, "
            "front-right, rear-left, front-left; quad-x-px4: front-right, rear-left, "
            "front-left, rear-right; quad-x-crazyflie: front-right first, clockwise)"
        )
    if preset is not None:
        return preset, f"{len(cols)} outputs; check the preset's output order against yours"
    return "", f"{len(cols)} outputs: no preset has them; describe the rotors (motors:)"
