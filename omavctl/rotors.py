"""Rotor layouts as data: the ``motors:`` section of a vehicle YAML and its mixer.

A vehicle whose logs hold what each motor was told (the ``motor_command``
signal role: raw per-output values, shape (N, n_outputs), in the vehicle's
output order) describes its rotors here; the commanded body wrench is then
computed from those outputs (:meth:`Motors.wrench`), so ``fit``, ``evaluate``
and the diagnosis work on logs that have no torque command. Spelling::

    motors:
      unit: pwm16                  # command unit of every output (or per rotor)
      range: [0, 65535]            # command that means 0 and 1 (pwm_us, dshot, pwm16)
      thrust_curve: [0.0, 0.0, 0.15]   # N per rotor: polynomial in the command value
      yaw_moment: 0.006            # m: reaction torque about the thrust axis per N
      rotors:
        - {position: [0.028, -0.028, 0.0], spin: ccw}   # output 0
        - {position: [-0.028, -0.028, 0.0], spin: cw, axis: [0, 0, 1], output: 1}

The *command value* a thrust curve takes is ``(c - lo) / (hi - lo)`` (0..1)
for ``pwm_us``, ``dshot``, ``pwm16`` and ``normalised`` (``range`` defaults:
1000-2000 us, 48-2047, 0-65535, 0-1), ``c`` rad/s for ``rad/s`` and
``c 2 pi / 60`` for ``rpm`` (a ``range`` of a speed unit names the speeds meaning
0 and full command: only ``thrust_curve``'s bend uses it). ``wrench_from: rotors``
mixes the wrench from the rotor outputs even where the log has a wrench command
of its own (default ``log``: the log's command wins). ``thrust_curve`` is a list of polynomial
coefficients (constant first) or ``{k: K}`` for ``K value^2`` (``k omega^2``
with a speed unit). ``spin`` is the propeller's sense seen from above the
thrust axis: a ``cw`` propeller pushes the body ``+yaw_moment x thrust``
about the axis, a ``ccw`` one the opposite. A rotor on a tilt servo names it:
``tilt: {servo: j, about: [x, y, z]}``: its axis is turned by the servo's
angle (the ``tilt`` role, column j, rad) about ``about`` (right-handed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.logs.types import MOTOR_OUTPUTS

__all__ = [
    "COMMAND_UNITS",
    "MAX_OUTPUTS",
    "SPEED_UNITS",
    "WRENCH_FROM",
    "Motors",
    "Rotor",
    "parse_motors",
]

#: Accepted command units and the default range of the normalised ones.
COMMAND_UNITS: dict[str, tuple[float, float] | None] = {
    "pwm_us": (1000.0, 2000.0),
    "dshot": (48.0, 2047.0),
    "pwm16": (0.0, 65535.0),
    "normalised": (0.0, 1.0),
    "rad/s": None,
    "rpm": None,
}
#: Most outputs a ``motor_command`` holds (the omav's 12 rotors and 6 servos).
MAX_OUTPUTS = MOTOR_OUTPUTS

_ROTOR_KEYS = {"position", "spin", "axis", "output", "unit", "range", "thrust_curve", "tilt"}
_MOTOR_KEYS = {"unit", "range", "thrust_curve", "yaw_moment", "rotors", "wrench_from"}
#: Units whose command is a rotor speed: the thrust curve takes the speed itself; a
#: ``range`` then only names the full speed (for ``thrust_curve``'s bend).
SPEED_UNITS = ("rad/s", "rpm")
#: Where ``fit`` and ``evaluate`` take the commanded wrench of a log that has both a
#: wrench command and the rotors' outputs: ``log`` (its own, default) or ``rotors``
#: (mixed from the rotor outputs by this list, so that the motor-level effects apply).
WRENCH_FROM = ("log", "rotors")


@dataclass(frozen=True)
class Rotor:
    """One rotor: ``position`` (3,) m and unit ``axis`` (3,) in body FLU; ``spin``
    +1 (cw) or -1 (ccw); ``output`` its column of ``motor_command``; ``unit`` and
    ``span`` (lo, hi) of its command (rad/s for a speed unit: the speeds meaning 0 and
    full command, None when not given); ``curve`` polynomial coefficients (constant
    first) of thrust N in the command value; ``tilt`` (servo, about (3,)) or None."""

    position: np.ndarray
    axis: np.ndarray
    spin: int
    output: int
    unit: str
    span: tuple[float, float] | None
    curve: np.ndarray
    tilt: tuple[int, np.ndarray] | None = None


@dataclass(frozen=True)
class Motors:
    """The rotors of a vehicle, its yaw-moment coefficient ``yaw_moment`` (m) and where
    the commanded wrench of a log with both comes from (``wrench_from``, :data:`WRENCH_FROM`)."""

    rotors: tuple[Rotor, ...]
    yaw_moment: float
    wrench_from: str = "log"

    @property
    def n_rotors(self) -> int:
        return len(self.rotors)

    @property
    def n_outputs(self) -> int:
        """Columns of ``motor_command`` the rotors read (highest output + 1)."""
        return 1 + max(r.output for r in self.rotors)

    @property
    def tilting(self) -> bool:
        """Whether any rotor sits on a tilt servo."""
        return any(r.tilt is not None for r in self.rotors)

    def values(self, commands: np.ndarray) -> np.ndarray:
        """Command values (N, n_rotors) the thrust curves take, from raw ``commands``
        (N, >= n_outputs)."""
        cols = []
        for r in self.rotors:
            c = np.asarray(commands[:, r.output], dtype=float)
            if r.unit == "rpm":
                c = c * (2.0 * math.pi / 60.0)
            elif r.span is not None and r.unit not in SPEED_UNITS:
                lo, hi = r.span
                c = (c - lo) / (hi - lo)
            cols.append(c)
        return np.stack(cols, axis=-1)

    def fractions(self, values: np.ndarray) -> np.ndarray:
        """Command values (N, n_rotors) as fractions 0..1 of each rotor's range: the
        values themselves for PWM, DShot and normalised units; ``(w - lo) / (hi - lo)``
        for a rotor speed with a ``range``; 0 for a speed without one."""
        out = np.array(values, dtype=float, copy=True)
        for j, r in enumerate(self.rotors):
            if r.unit in SPEED_UNITS:
                if r.span is None:
                    out[:, j] = 0.0
                else:
                    lo, hi = r.span
                    out[:, j] = (out[:, j] - lo) / (hi - lo)
        return out

    def full_thrust(self) -> np.ndarray:
        """Thrust span (n_rotors,) N of each curve over its range (command value 0 to 1,
        or the speed range); 0 for rotors without a range."""
        poly = np.polynomial.polynomial.polyval
        out = np.zeros(self.n_rotors)
        for j, r in enumerate(self.rotors):
            if r.span is None:
                continue
            lo, hi = r.span if r.unit in SPEED_UNITS else (0.0, 1.0)
            out[j] = poly(hi, r.curve) - poly(lo, r.curve)
        return out

    def thrust(self, commands: np.ndarray) -> np.ndarray:
        """Thrust per rotor (N, n_rotors) in N from raw commands (N, >= n_outputs).

        Command values below the range (a stopped or idling motor) give the
        curve's value at 0: no thrust curve is extrapolated below its range.
        """
        x = np.clip(self.values(commands), 0.0, None)
        out = np.empty_like(x)
        for j, r in enumerate(self.rotors):
            out[:, j] = np.polynomial.polynomial.polyval(x[:, j], r.curve)
        return out

    def axes(self, tilt: np.ndarray | None, n: int) -> np.ndarray:
        """Unit thrust axes (n, n_rotors, 3), turned by the servo angles ``tilt`` (n, k) rad."""
        out = np.empty((n, self.n_rotors, 3))
        for j, r in enumerate(self.rotors):
            if r.tilt is None:
                out[:, j] = r.axis
                continue
            if tilt is None:
                raise ValueError("rotors on tilt servos need the tilt angles")
            servo, k = r.tilt
            a = tilt[:, servo][:, None]
            v = r.axis[None, :]
            # Rodrigues: v cos a + (k x v) sin a + k (k . v) (1 - cos a)
            out[:, j] = (
                v * np.cos(a) + np.cross(k, v) * np.sin(a) + k * (k @ r.axis) * (1.0 - np.cos(a))
            )
        return out

    def wrench(
        self, thrust: np.ndarray, tilt: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Body force (N, 3) N and torque (N, 3) N m of rotor thrusts (N, n_rotors) N.

        ``tau = sum_i r_i x (T_i n_i) + spin_i yaw_moment T_i n_i``.
        """
        n = thrust.shape[0]
        axes = self.axes(tilt, n)  # (n, R, 3)
        forces = thrust[:, :, None] * axes
        pos = np.stack([r.position for r in self.rotors])  # (R, 3)
        spin = np.array([r.spin for r in self.rotors], dtype=float)
        torque = np.cross(pos[None], forces) + (self.yaw_moment * spin)[None, :, None] * forces
        return forces.sum(axis=1), torque.sum(axis=1)


def _err(msg: str, path: Path | None) -> ConfigError:
    return ConfigError(msg, path)


def _floats(value: Any, key: str, n: int | None, path: Path | None) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise _err(f"key '{key}' must be numbers", path) from None
    if isinstance(value, (bool, str)) or (n is not None and arr.size != n):
        raise _err(f"key '{key}' must be {n} numbers", path)
    if not np.all(np.isfinite(arr)) or np.any(np.abs(arr) > 1e9):
        raise _err(f"key '{key}' must be finite numbers", path)
    return arr


def _unit(value: Any, key: str, path: Path | None) -> str:
    if not isinstance(value, str) or value.strip().lower() not in COMMAND_UNITS:
        known = ", ".join(COMMAND_UNITS)
        raise _err(f"key '{key}' must be one of {known}, got {value!r}", path)
    return value.strip().lower()


def _curve(value: Any, key: str, path: Path | None) -> np.ndarray:
    if isinstance(value, dict):
        if set(value) != {"k"}:
            raise _err(f"key '{key}' must be a list of coefficients or {{k: K}}", path)
        k = _floats(value["k"], f"{key}.k", 1, path)[0]
        coeffs = np.array([0.0, 0.0, k])
    else:
        coeffs = _floats(value, key, None, path)
        if coeffs.size == 0 or coeffs.size > 6:
            raise _err(f"key '{key}' must have 1 to 6 coefficients (constant first)", path)
    if not np.any(coeffs[1:] != 0):
        raise _err(f"key '{key}' gives no thrust change with the command", path)
    return coeffs


def _span(value: Any, unit: str, key: str, path: Path | None) -> tuple[float, float] | None:
    """The command range (lo, hi); for a speed unit in rad/s (rpm converted), None when
    not given."""
    if value is None:
        return COMMAND_UNITS[unit]
    lo, hi = _floats(value, key, 2, path)
    if not hi > lo:
        raise _err(f"key '{key}' must be [low, high] with high > low", path)
    if unit == "rpm":
        lo, hi = lo * (2.0 * math.pi / 60.0), hi * (2.0 * math.pi / 60.0)
    return float(lo), float(hi)


def _unit_axis(value: Any, key: str, path: Path | None) -> np.ndarray:
    v = _floats(value, key, 3, path)
    norm = float(np.linalg.norm(v))
    if norm < 1e-9:
        raise _err(f"key '{key}' must be a non-zero vector", path)
    return v / norm


def _rotor(item: Any, i: int, defaults: dict[str, Any], path: Path | None) -> Rotor:
    key = f"motors.rotors[{i}]"
    if not isinstance(item, dict):
        raise _err(f"key '{key}' must be a mapping {{position:, spin:, ...}}", path)
    extra = sorted(set(map(str, item)) - _ROTOR_KEYS)
    if extra:
        known = ", ".join(sorted(_ROTOR_KEYS))
        raise _err(f"unknown key '{key}.{extra[0]}' (known: {known})", path)
    for need in ("position", "spin"):
        if need not in item:
            raise _err(f"key '{key}.{need}' is missing", path)
    spin = str(item["spin"]).strip().lower()
    if spin not in ("cw", "ccw"):
        raise _err(f"key '{key}.spin' must be cw or ccw, got {item['spin']!r}", path)
    output = item.get("output", i)
    if isinstance(output, bool) or not isinstance(output, int) or not 0 <= output < MAX_OUTPUTS:
        raise _err(f"key '{key}.output' must be an integer 0 to {MAX_OUTPUTS - 1}", path)
    unit_raw = item.get("unit", defaults.get("unit"))
    if unit_raw is None:
        raise _err(f"key '{key}.unit' is missing (or give motors.unit for every rotor)", path)
    unit = _unit(unit_raw, f"{key}.unit" if "unit" in item else "motors.unit", path)
    curve_raw = item.get("thrust_curve", defaults.get("thrust_curve"))
    if curve_raw is None:
        raise _err(f"key '{key}.thrust_curve' is missing (or give motors.thrust_curve)", path)
    ckey = f"{key}.thrust_curve" if "thrust_curve" in item else "motors.thrust_curve"
    rkey = f"{key}.range" if "range" in item else "motors.range"
    tilt = None
    if item.get("tilt") is not None:
        t = item["tilt"]
        if not isinstance(t, dict) or set(t) != {"servo", "about"}:
            raise _err(f"key '{key}.tilt' must be {{servo: j, about: [x, y, z]}}", path)
        servo = t["servo"]
        if isinstance(servo, bool) or not isinstance(servo, int) or not 0 <= servo < 6:
            raise _err(f"key '{key}.tilt.servo' must be an integer 0 to 5", path)
        tilt = (servo, _unit_axis(t["about"], f"{key}.tilt.about", path))
    return Rotor(
        position=_floats(item["position"], f"{key}.position", 3, path),
        axis=_unit_axis(item.get("axis", [0.0, 0.0, 1.0]), f"{key}.axis", path),
        spin=1 if spin == "cw" else -1,
        output=int(output),
        unit=unit,
        span=_span(item.get("range", defaults.get("range")), unit, rkey, path),
        curve=_curve(curve_raw, ckey, path),
        tilt=tilt,
    )


def parse_motors(tree: Any, path: Path | None) -> Motors | None:
    """The validated ``motors:`` section of a vehicle tree (None when absent or empty).

    Raises:
        ConfigError: naming the file and the key (``motors.rotors[2].spin``).
    """
    if tree is None or tree == {}:
        return None
    if not isinstance(tree, dict):
        raise _err("key 'motors' must be a mapping {unit:, thrust_curve:, rotors: [...]}", path)
    extra = sorted(set(map(str, tree)) - _MOTOR_KEYS)
    if extra:
        known = ", ".join(sorted(_MOTOR_KEYS))
        raise _err(f"unknown key 'motors.{extra[0]}' (known: {known})", path)
    items = tree.get("rotors")
    if not isinstance(items, list) or not items:
        raise _err("key 'motors.rotors' must be a non-empty list of rotors", path)
    yaw = _floats(tree.get("yaw_moment", 0.0), "motors.yaw_moment", 1, path)[0]
    if not 0.0 <= yaw <= 10.0:
        raise _err("key 'motors.yaw_moment' must be 0 to 10 m", path)
    rotors = tuple(_rotor(item, i, tree, path) for i, item in enumerate(items))
    wrench_from = tree.get("wrench_from", "log")
    if wrench_from not in WRENCH_FROM:
        raise _err(
            f"key 'motors.wrench_from' must be {' or '.join(WRENCH_FROM)}, got {wrench_from!r}",
            path,
        )
    seen: dict[int, int] = {}
    for i, r in enumerate(rotors):
        if r.output in seen:
            raise _err(
                f"key 'motors.rotors[{i}].output' = {r.output} is also rotor {seen[r.output]}'s",
                path,
            )
        seen[r.output] = i
    return Motors(rotors=rotors, yaw_moment=float(yaw), wrench_from=str(wrench_from))
