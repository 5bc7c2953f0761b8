"""Vehicle description: mass, inertia, geometry, limits, controller gains, topics, log layout.

A vehicle YAML overrides the built-in default omav (``omavctl/data/default_vehicle.yaml``,
whose comments give the source of every value) key by key: a file holding only
``mass`` and ``inertia`` is valid. Unknown keys are errors naming the key.
``columns`` (CSV column map) and ``effects`` are replaced as a whole, not merged.

``command_units`` says in which units the logs' commands are: ``torque: "N m"``
(default) or ``normalised`` (a dimensionless controller output such as PX4's
``actuator_controls`` or ArduPilot's ``RATE.*Out``), ``force: "N"`` (default)
or ``normalised`` (a throttle 0..1). With a normalised torque, ``fit``
estimates the per-axis gain through the ``inertia_error`` effect and every
torque unit it reports is unknown (see ``docs/logs.md``).

``motors`` lists the rotors of a vehicle whose logs hold per-motor outputs
(:mod:`omavctl.rotors`); a file with ``preset: NAME`` starts from a built-in
rotor layout (``omavctl/data/presets/``, :func:`preset_names`) instead of
the omav.
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from omavctl.base.errors import ConfigError
from omavctl.rotors import Motors, parse_motors

__all__ = [
    "FORCE_UNITS",
    "NORMALISED",
    "TORQUE_UNITS",
    "ControllerGains",
    "Vehicle",
    "default_vehicle",
    "load_vehicle",
    "load_yaml_mapping",
    "preset_names",
]

TOPIC_ROLES = (
    "imu",
    "odometry",
    "wrench_command",
    "desired_acceleration",
    "reference",
    "actuators",
)


#: Value of ``command_units.torque`` / ``.force`` for dimensionless commands.
NORMALISED = "normalised"
#: Accepted values of ``command_units.torque`` and ``command_units.force``
#: (the SI unit first: the default).
TORQUE_UNITS = ("N m", NORMALISED)
FORCE_UNITS = ("N", NORMALISED)
#: Other spellings accepted in a vehicle YAML, mapped to the canonical values.
_UNIT_ALIASES = {
    "n m": "N m",
    "nm": "N m",
    "n*m": "N m",
    "n·m": "N m",
    "n": "N",
    "normalised": NORMALISED,
    "normalized": NORMALISED,
}


#: Names of the physical effects a vehicle file may list under ``effects:``
#: (DESIGN.md section 2). The description knows only the names; what each one
#: computes is :data:`omavctl.physics.effects.EFFECTS`, whose keys must be
#: exactly these (checked when the registry is built).
EFFECT_NAMES = (
    "rotational_drag",
    "com_offset",
    "inertia_error",
    "servo_lag",
    "motor_lag",
    "command_delay",
    "gyro_bias",
    "rotor_interference",
    "thrust_curve",
    "motor_loss",
    "battery_sag",
    "drag_moment",
    "arm_thrust",
)

#: Top-level keys whose value replaces the default's instead of being merged.
_FREE_FORM = ("effects", "columns", "motors")


def _default_tree() -> dict[str, Any]:
    text = resources.files("omavctl.data").joinpath("default_vehicle.yaml").read_text()
    tree = yaml.safe_load(text)
    assert isinstance(tree, dict)
    return tree


def load_yaml_mapping(path: str | Path) -> dict[str, Any]:
    """Read a YAML file whose top level must be a mapping (``yaml.safe_load`` only)."""
    p = Path(path)
    try:
        text = p.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise ConfigError("file not found", p) from None
    except IsADirectoryError:
        raise ConfigError("is a directory, not a YAML file", p) from None
    except OSError as err:
        raise ConfigError(f"cannot read: {err.strerror or err}", p) from None
    except UnicodeDecodeError:
        raise ConfigError("not a YAML file: it is not UTF-8 text", p) from None
    try:
        tree = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f"invalid YAML: {str(err).splitlines()[0]}", p) from None
    if tree is None:
        return {}
    if not isinstance(tree, dict):
        raise ConfigError("top level must be a mapping of keys to values", p)
    return tree


def _merge(base: dict[str, Any], override: dict[str, Any], path: Path, prefix: str) -> None:
    """Deep-merge ``override`` into ``base`` in place; unknown keys are errors."""
    for key, value in override.items():
        name = f"{prefix}{key}"
        if key not in base:
            raise ConfigError(f"unknown key '{name}'", path)
        # Free-form sections: replaced without a schema below them.
        if isinstance(base[key], dict) and key not in _FREE_FORM:
            if not isinstance(value, dict):
                raise ConfigError(f"key '{name}' must be a mapping", path)
            _merge(base[key], value, path, f"{name}.")
        else:
            base[key] = value


def _vec(tree: dict[str, Any], key: str, n: int, path: Path | None, name: str) -> np.ndarray:
    value = tree[key]
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"key '{name}' must be numbers", path) from None
    if arr.size == 1 and n > 1:
        arr = np.full(n, float(arr[0]))
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ConfigError(f"key '{name}' must be {n} finite numbers", path)
    if np.any(np.abs(arr) > MAX_GAIN):
        raise ConfigError(f"key '{name}' has values beyond ±{MAX_GAIN:g}", path)
    return arr


#: Plausible ranges (inclusive) of a multirotor's scalar parameters, SI units: a
#: value outside is a typo or a corrupt file, and would make the numerics
#: overflow (a mass of 1e-300 kg) rather than describe a vehicle.
PLAUSIBLE = {
    "mass": (1e-3, 1e4),
    "gravity": (0.1, 100.0),
    "geometry.arm_length": (1e-3, 100.0),
    "rotor.max_thrust": (1e-3, 1e5),
    "rotor.min_thrust": (0.0, 1e5),
    "rotor.thrust_coefficient": (1e-12, 1e3),
    "rotor.drag_ratio": (0.0, 10.0),
    "rotor.thrust_tolerance": (0.0, 0.5),
    "servo.max_tilt_rate": (1e-3, 1e4),
    "controller.rate_hz": (1.0, 1e5),
}
#: Plausible eigenvalues of the inertia matrix, kg m^2.
INERTIA_RANGE = (1e-7, 1e5)
#: Largest controller gain magnitude.
MAX_GAIN = 1e7


def _positive(value: Any, name: str, path: Path | None, allow_zero: bool = False) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"key '{name}' must be a number", path)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"key '{name}' must be a number", path) from None
    if not np.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        raise ConfigError(f"key '{name}' must be {'>= 0' if allow_zero else '> 0'}", path)
    lo, hi = PLAUSIBLE.get(name, (0.0, np.inf))
    if not lo <= x <= hi:
        raise ConfigError(
            f"key '{name}' = {x:g} is outside the plausible range {lo:g} to {hi:g}", path
        )
    return x


@dataclass(frozen=True)
class ControllerGains:
    """PID gains of the attitude and position loops (per axis, shape (3,))."""

    rate_hz: float
    att_kp: np.ndarray
    att_kd: np.ndarray
    att_ki: np.ndarray
    pos_kp: np.ndarray
    pos_kd: np.ndarray
    pos_ki: np.ndarray


@dataclass(frozen=True)
class Vehicle:
    """Physical description of the vehicle.

    ``inertia`` is a (3, 3) matrix in kg m^2 (body FLU frame); ``arm_angles`` in
    rad, shape (6,). ``effects`` are the names of physical effects that ``fit``
    estimates for this vehicle. ``columns`` is the CSV column map of its logs
    (role-based or flat, see :mod:`omavctl.logs.columnmap`; empty: wide
    contract CSV) and ``frame`` the frame its logs are in (``"FLU"`` or
    ``"FRD"``, see :mod:`omavctl.logs.frames`). ``command_units`` maps
    ``"torque"`` to ``"N m"`` or ``"normalised"`` and ``"force"`` to ``"N"`` or
    ``"normalised"`` (units of the logged commands).
    """

    mass: float
    inertia: np.ndarray
    gravity: float
    arm_length: float
    arm_angles: np.ndarray
    max_thrust: float
    min_thrust: float
    thrust_coefficient: float
    drag_ratio: float
    max_tilt_rate: float
    gains: ControllerGains
    topics: dict[str, str]
    effects: tuple[str, ...] = ()
    columns: dict[str, Any] = field(default_factory=dict)
    frame: str = "FLU"
    command_units: dict[str, str] = field(
        default_factory=lambda: {"torque": TORQUE_UNITS[0], "force": FORCE_UNITS[0]}
    )
    source: str = "built-in default omav"
    #: the rotors and their mixer (``motors:``), None when not described
    motors: Motors | None = None
    #: 1-sigma spread of the rotors' thrust coefficients, as a fraction (a batch of the
    #: same motors and propellers): no flight tells it from a centre-of-mass offset or
    #: a drag, so the effects' reported intervals carry it (:mod:`omavctl.learn.spread`)
    thrust_tolerance: float = 0.0
    tree: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @cached_property
    def inertia_inv(self) -> np.ndarray:
        """Inverse inertia, shape (3, 3) (computed once: it sits on hot paths)."""
        return np.linalg.inv(self.inertia)

    @property
    def n_arms(self) -> int:
        return int(self.arm_angles.size)

    @property
    def torque_normalised(self) -> bool:
        """Whether the logged torque command is normalised (units unknown)."""
        return self.command_units.get("torque") == NORMALISED

    @property
    def force_normalised(self) -> bool:
        """Whether the logged force (thrust) command is normalised (units unknown)."""
        return self.command_units.get("force") == NORMALISED

    @property
    def weight(self) -> float | None:
        """The vehicle's weight in the thrust command's unit (N), None when the force
        command is normalised (its unit unknown)."""
        return None if self.force_normalised else self.mass * self.gravity

    @property
    def fixed_rotors(self) -> bool:
        """Whether the vehicle is a rotor list without tilt servos (``motors:``)."""
        return self.motors is not None and not self.motors.tilting

    def check_flyable(self, command: str, path: str | Path | None = None) -> None:
        """Refuse, in one line, to ``simulate`` or ``plan`` a vehicle of fixed rotors:
        the simulator and the planner fly the omav (six tilting arms) only."""
        if self.fixed_rotors:
            assert self.motors is not None
            raise ConfigError(
                f"{command} flies only the omav (six tilting arms); this vehicle's "
                f"{self.motors.n_rotors} fixed rotors (motors:) are for fit, evaluate and "
                "report",
                path,
            )

    def to_json(self) -> str:
        """The merged YAML tree as canonical JSON (stored in model artifacts)."""
        return json.dumps(self.tree, sort_keys=True)


def _build(tree: dict[str, Any], path: Path | None, source: str) -> Vehicle:
    mass = _positive(tree["mass"], "mass", path)
    try:
        inertia = np.asarray(tree["inertia"], dtype=float)
    except (TypeError, ValueError):
        raise ConfigError("key 'inertia' must be numbers", path) from None
    if inertia.shape == (3,):
        inertia = np.diag(inertia)
    if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
        raise ConfigError("key 'inertia' must be 3 diagonal values or a 3x3 matrix", path)
    if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0):
        raise ConfigError("key 'inertia' must be symmetric positive definite", path)
    eig = np.linalg.eigvalsh(inertia)
    if eig.min() < INERTIA_RANGE[0] or eig.max() > INERTIA_RANGE[1]:
        raise ConfigError(
            f"key 'inertia' has principal moments {eig.min():.3g} to {eig.max():.3g} kg m^2, "
            f"outside the plausible range {INERTIA_RANGE[0]:g} to {INERTIA_RANGE[1]:g}",
            path,
        )
    geo, rot, servo, ctl = tree["geometry"], tree["rotor"], tree["servo"], tree["controller"]
    angles = _vec(geo, "arm_angles_deg", 6, path, "geometry.arm_angles_deg")
    att, pos = ctl["attitude"], ctl["position"]
    gains = ControllerGains(
        rate_hz=_positive(ctl["rate_hz"], "controller.rate_hz", path),
        att_kp=_vec(att, "kp", 3, path, "controller.attitude.kp"),
        att_kd=_vec(att, "kd", 3, path, "controller.attitude.kd"),
        att_ki=_vec(att, "ki", 3, path, "controller.attitude.ki"),
        pos_kp=_vec(pos, "kp", 3, path, "controller.position.kp"),
        pos_kd=_vec(pos, "kd", 3, path, "controller.position.kd"),
        pos_ki=_vec(pos, "ki", 3, path, "controller.position.ki"),
    )
    topics = tree["topics"]
    for role, topic in topics.items():
        if not isinstance(topic, str) or not topic:
            raise ConfigError(f"key 'topics.{role}' must be a topic name", path)
    effects = _effect_names(tree.get("effects"), path)
    columns, frame = _log_layout(tree, path)
    command_units = _command_units(tree, path)
    motors = parse_motors(tree.get("motors"), path)
    max_thrust = _positive(rot["max_thrust"], "rotor.max_thrust", path)
    min_thrust = _positive(rot["min_thrust"], "rotor.min_thrust", path, allow_zero=True)
    if min_thrust >= max_thrust:
        raise ConfigError("key 'rotor.min_thrust' must be below rotor.max_thrust", path)
    return Vehicle(
        mass=mass,
        inertia=inertia,
        gravity=_positive(tree["gravity"], "gravity", path),
        arm_length=_positive(geo["arm_length"], "geometry.arm_length", path),
        arm_angles=np.deg2rad(angles),
        max_thrust=max_thrust,
        min_thrust=min_thrust,
        thrust_coefficient=_positive(rot["thrust_coefficient"], "rotor.thrust_coefficient", path),
        drag_ratio=_positive(rot["drag_ratio"], "rotor.drag_ratio", path, allow_zero=True),
        max_tilt_rate=_positive(servo["max_tilt_rate"], "servo.max_tilt_rate", path),
        gains=gains,
        topics=dict(topics),
        effects=effects,
        columns=columns,
        frame=frame,
        command_units=command_units,
        source=source,
        motors=motors,
        thrust_tolerance=_positive(
            rot.get("thrust_tolerance", 0.0), "rotor.thrust_tolerance", path, allow_zero=True
        ),
        tree=tree,
    )


def _log_layout(tree: dict[str, Any], path: Path | None) -> tuple[dict[str, Any], str]:
    """Validated ``columns`` (column map, may be empty) and ``frame`` of a vehicle tree.

    Trees written before these keys existed (model artifacts) give ``{}`` and ``"FLU"``.
    """
    from omavctl.logs.columnmap import parse_column_map
    from omavctl.logs.frames import check_frame

    columns = tree.get("columns")
    if columns is None:
        columns = {}
    if not isinstance(columns, dict):
        raise ConfigError("key 'columns' must be a mapping of roles to columns", path)
    try:
        if columns:
            parse_column_map(columns)
        frame = check_frame(tree.get("frame", "FLU"))
    except ConfigError as err:
        raise ConfigError(err.message, path) from None
    return dict(columns), frame


def _command_units(tree: dict[str, Any], path: Path | None) -> dict[str, str]:
    """Validated ``command_units`` of a vehicle tree, canonical spellings.

    Trees written before the key existed (model artifacts) give SI units.
    """
    value = tree.get("command_units")
    if value is None:
        value = {}
    if not isinstance(value, dict):
        raise ConfigError("key 'command_units' must be a mapping {torque: ..., force: ...}", path)
    out = {"torque": TORQUE_UNITS[0], "force": FORCE_UNITS[0]}
    for key, allowed in (("torque", TORQUE_UNITS), ("force", FORCE_UNITS)):
        if value.get(key) is None:
            continue
        raw = value[key]
        unit = _UNIT_ALIASES.get(str(raw).strip().lower()) if isinstance(raw, str) else None
        if unit not in allowed:
            choices = " or ".join(f"'{a}'" for a in allowed)
            raise ConfigError(f"key 'command_units.{key}' must be {choices}, got {raw!r}", path)
        out[key] = unit
    for key in value:
        if key not in out:
            raise ConfigError(f"unknown key 'command_units.{key}' (expected: torque, force)", path)
    return out


def _effect_names(value: Any, path: Path | None) -> tuple[str, ...]:
    if value is None:
        return ()
    names = list(value) if isinstance(value, (list, dict)) else None
    if names is None:
        raise ConfigError("key 'effects' must be a list of effect names", path)
    for name in names:
        if name not in EFFECT_NAMES:
            known = ", ".join(sorted(EFFECT_NAMES))
            raise ConfigError(f"unknown effect '{name}' in 'effects' (known: {known})", path)
    return tuple(str(n) for n in names)


def default_vehicle() -> Vehicle:
    """The built-in omav."""
    return _build(_default_tree(), None, "built-in default omav")


def preset_names() -> list[str]:
    """Names of the built-in vehicle presets (``omavctl/data/presets/*.yaml``)."""
    folder = resources.files("omavctl.data").joinpath("presets")
    names = (f.name.removesuffix(".yaml") for f in folder.iterdir() if f.name.endswith(".yaml"))
    return sorted(names)


def _preset_tree(name: Any, path: Path) -> dict[str, Any]:
    """The default tree with preset ``name`` merged over it."""
    names = preset_names()
    if not isinstance(name, str) or name not in names:
        raise ConfigError(f"unknown preset {name!r} in 'preset' (known: {', '.join(names)})", path)
    text = resources.files("omavctl.data").joinpath("presets").joinpath(f"{name}.yaml").read_text()
    tree = _default_tree()
    _merge(tree, yaml.safe_load(text), Path(f"preset {name}"), "")
    return tree


def load_vehicle(path: str | Path | None = None) -> Vehicle:
    """Load a vehicle YAML over the built-in default; ``None`` gives the default.

    A file with ``preset: NAME`` starts from that preset (:func:`preset_names`:
    ``quad-x-betaflight``, ``quad-x-crazyflie``, ``hexa-x``, ...) instead of
    the omav; its other keys override the preset's.
    """
    if path is None:
        return default_vehicle()
    p = Path(path)
    override = load_yaml_mapping(p)
    tree = _preset_tree(override.pop("preset"), p) if "preset" in override else _default_tree()
    _merge(tree, override, p, "")
    return _build(copy.deepcopy(tree), p, str(p))
