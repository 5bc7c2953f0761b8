"""Truth file: the hidden constants and effects of the plant ``omavctl simulate`` flies.

A truth YAML (every key optional)::


    seed: 3                      # the vehicle's rotor thrust spread (and default noise seed)
    ideal: false                 # true: no actuator imperfections at all
    actuators:
      servo_time_constant: 0.005 # s, first-order tilt servo lag (servo_lag sets slower)
      servo_backlash_deg: 0.3    # deg, dead band between servo and arm
      motor_time_constant: 0.005 # s, first-order rotor thrust lag (motor_lag sets slower)
      thrust_spread: 0.03        # std of per-rotor thrust-coefficient error (fraction)
      interference:
        rotor_rotor: 0.25        # max thrust loss when a pair blows onto a neighbour
        rotor_arm: 0.04          # thrust loss ~ sin^2(tilt), wash on the own arm
    effects:                     # hidden effects from the registry
      rotational_drag: {D: [0.02, 0.02, 0.01]}
    noise:                       # standard deviations of the logged signals
      gyro: 0.003                # rad/s
      attitude: 0.002            # rad
      position: 0.001            # m
      velocity: 0.01             # m/s
    battery:                     # the logged battery voltage (battery_sag scales thrust by it)
      nominal: 24.0              # V, where the rotors' thrust curve holds (mid-flight at hover)
      drop: 1.5                  # V the open-circuit voltage falls over the flight
      sag: 0.005                 # V lost per N of total thrust above hover
    timing:
      controller_rate_hz: 1000   # the controller's own rate (default: the log rate,
                                 # controller.rate_hz of the vehicle); the log samples the
                                 # latest command at the vehicle's rate
    failure:                     # actuator failure: loss of control
      time: 8.0                  # s after the start
      arms: [0, 1]               # arms whose rotor pairs lose thrust
      thrust_factor: 0.0         # remaining fraction of their thrust

What the plant does with them: :mod:`omavctl.sim.plant`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.physics.effects import Effect, get_effect
from omavctl.vehicle import Vehicle, load_yaml_mapping

__all__ = ["TruthParameters", "load_truth", "truth_from_tree"]

_ACTUATOR_DEFAULTS: dict[str, Any] = {
    "servo_time_constant": 0.005,
    "servo_backlash_deg": 0.3,
    "motor_time_constant": 0.005,
    "thrust_spread": 0.03,
    "interference": {"rotor_rotor": 0.25, "rotor_arm": 0.04},
}
_NOISE_DEFAULTS = {"gyro": 0.003, "attitude": 0.002, "position": 0.001, "velocity": 0.01}
_TIMING_DEFAULTS: dict[str, Any] = {"controller_rate_hz": None}
_BATTERY_DEFAULTS = {"nominal": 24.0, "drop": 1.5, "sag": 0.005}
_FAILURE_DEFAULTS: dict[str, Any] = {"time": 0.0, "arms": [], "thrust_factor": 0.0}


@dataclass
class TruthParameters:
    """Constants of the truth plant (after hidden effects were applied)."""

    inertia: np.ndarray
    servo_time_constant: float = 0.005
    servo_backlash: float = np.deg2rad(0.3)
    motor_time_constant: float = 0.005
    thrust_spread: float = 0.03
    rotor_rotor: float = 0.25
    rotor_arm: float = 0.04
    noise: dict[str, float] = field(default_factory=lambda: dict(_NOISE_DEFAULTS))
    seed: int = 0
    effects: list[tuple[Effect, dict[str, np.ndarray]]] = field(default_factory=list)
    #: s, the applied setpoints are the commands of this long ago (command_delay)
    command_delay: float = 0.0
    #: Hz, the controller's own rate; None: the vehicle's controller.rate_hz (the log rate)
    controller_rate_hz: float | None = None
    #: (time s, arm indices, remaining thrust fraction) of an actuator failure
    failure: tuple[float, tuple[int, ...], float] | None = None
    #: thrust_curve's c: each rotor's thrust T becomes T + c (T - sqrt(T T_full)),
    #: T_full the vehicle's rotor.max_thrust (the bend c T_full (x^2 - x) in x = w / w_full)
    thrust_curvature: float = 0.0
    #: (12,) fraction of each rotor's thrust lost (motor_loss)
    rotor_loss: np.ndarray = field(default_factory=lambda: np.zeros(12))
    #: 1/V, battery_sag's k: thrust scaled by 1 + k (V - battery["nominal"])
    battery_sag: float = 0.0
    #: V: the battery's nominal voltage, its drop over the flight and its sag per N
    battery: dict[str, float] = field(default_factory=lambda: dict(_BATTERY_DEFAULTS))


def _number(tree: dict[str, Any], key: str, where: str, path: Path | None) -> float:
    try:
        x = float(tree[key])
    except (TypeError, ValueError):
        raise ConfigError(f"'{where}{key}' must be a number", path) from None
    if not np.isfinite(x) or x < 0:
        raise ConfigError(f"'{where}{key}' must be >= 0", path)
    return x


def _check_keys(tree: Any, allowed: dict[str, Any], where: str, path: Path | None) -> None:
    if not isinstance(tree, dict):
        raise ConfigError(f"'{where.rstrip('.') or 'truth'}' must be a mapping", path)
    for key in tree:
        if key not in allowed:
            raise ConfigError(f"unknown key '{where}{key}'", path)


def truth_from_tree(
    tree: dict[str, Any], vehicle: Vehicle, path: Path | None = None
) -> TruthParameters:
    """Validate a truth mapping (see module docstring) and build the plant constants."""
    top = {
        "seed": 0,
        "ideal": False,
        "actuators": {},
        "effects": {},
        "noise": {},
        "timing": {},
        "failure": {},
        "battery": {},
    }
    _check_keys(tree, top, "", path)
    act_tree = tree.get("actuators") or {}
    _check_keys(act_tree, _ACTUATOR_DEFAULTS, "actuators.", path)
    act = {**_ACTUATOR_DEFAULTS, **act_tree}
    inter_tree = act["interference"] or {}
    _check_keys(inter_tree, _ACTUATOR_DEFAULTS["interference"], "actuators.interference.", path)
    inter = {**_ACTUATOR_DEFAULTS["interference"], **inter_tree}
    noise_tree = tree.get("noise") or {}
    _check_keys(noise_tree, _NOISE_DEFAULTS, "noise.", path)
    noise = {
        k: _number({**_NOISE_DEFAULTS, **noise_tree}, k, "noise.", path) for k in _NOISE_DEFAULTS
    }
    try:
        seed = int(tree.get("seed", 0))
    except (TypeError, ValueError, OverflowError):
        raise ConfigError("'seed' must be an integer", path) from None
    if not 0 <= seed < 2**63:
        raise ConfigError(f"'seed' must be a non-negative integer, got {seed}", path)
    truth = TruthParameters(
        inertia=vehicle.inertia.copy(),
        servo_time_constant=_number(act, "servo_time_constant", "actuators.", path),
        servo_backlash=np.deg2rad(_number(act, "servo_backlash_deg", "actuators.", path)),
        motor_time_constant=_number(act, "motor_time_constant", "actuators.", path),
        thrust_spread=_number(act, "thrust_spread", "actuators.", path),
        rotor_rotor=_number(inter, "rotor_rotor", "actuators.interference.", path),
        rotor_arm=_number(inter, "rotor_arm", "actuators.interference.", path),
        noise=noise,
        seed=seed,
    )
    if tree.get("ideal", False):
        truth.servo_time_constant = truth.motor_time_constant = 0.0
        truth.servo_backlash = truth.thrust_spread = 0.0
        truth.rotor_rotor = truth.rotor_arm = 0.0
    truth.controller_rate_hz = _timing(tree.get("timing") or {}, path)
    battery_tree = tree.get("battery") or {}
    _check_keys(battery_tree, _BATTERY_DEFAULTS, "battery.", path)
    merged = {**_BATTERY_DEFAULTS, **battery_tree}
    truth.battery = {k: _number(merged, k, "battery.", path) for k in _BATTERY_DEFAULTS}
    if truth.battery["nominal"] <= truth.battery["drop"]:
        raise ConfigError("'battery.nominal' must be above battery.drop", path)
    truth.failure = _failure(tree.get("failure") or {}, path)
    effects = tree.get("effects") or {}
    if not isinstance(effects, dict):
        raise ConfigError("'effects' must map effect names to their parameters", path)
    for name, params in effects.items():
        try:
            effect = get_effect(str(name))
            values = effect.validate(params)
            effect.configure_truth(values, truth)
        except ConfigError as err:
            raise ConfigError(err.message, path) from None
        truth.effects.append((effect, values))
    return truth


def _timing(tree: Any, path: Path | None) -> float | None:
    """``timing.controller_rate_hz`` (Hz) or None."""
    _check_keys(tree, _TIMING_DEFAULTS, "timing.", path)
    if tree.get("controller_rate_hz") is None:
        return None
    rate = _number(tree, "controller_rate_hz", "timing.", path)
    if rate <= 0:
        raise ConfigError("'timing.controller_rate_hz' must be > 0", path)
    return rate


def _failure(tree: Any, path: Path | None) -> tuple[float, tuple[int, ...], float] | None:
    """``failure``: (time, arms, thrust_factor), or None when no arm fails."""
    _check_keys(tree, _FAILURE_DEFAULTS, "failure.", path)
    if not tree:
        return None
    when = _number({**_FAILURE_DEFAULTS, **tree}, "time", "failure.", path)
    factor = _number({**_FAILURE_DEFAULTS, **tree}, "thrust_factor", "failure.", path)
    arms = tree.get("arms", [])
    if not isinstance(arms, list) or not arms or not all(isinstance(a, int) for a in arms):
        raise ConfigError("'failure.arms' must be a non-empty list of arm indices", path)
    if any(not 0 <= a < 6 for a in arms) or factor > 1:
        raise ConfigError("'failure.arms' must lie in 0..5 and thrust_factor in 0..1", path)
    return when, tuple(sorted(set(arms))), factor


def load_truth(path: str | Path | None, vehicle: Vehicle) -> TruthParameters:
    """Load a truth YAML; ``None`` gives the default imperfections, no hidden effects."""
    if path is None:
        return truth_from_tree({}, vehicle)
    p = Path(path)
    return truth_from_tree(load_yaml_mapping(p), vehicle, p)
