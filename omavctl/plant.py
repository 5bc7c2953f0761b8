"""Truth plant: the simulated vehicle that ``omavctl simulate`` flies.

Commanded wrench -> allocation -> actuator setpoints -> actuator dynamics and
imperfections -> actual wrench -> rigid body, plus hidden effects and sensor
noise from a truth YAML::

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

Actuators: the servo shaft follows its setpoint with the first-order lag,
limited to ``servo.max_tilt_rate``; the arm follows the shaft through the
backlash dead band. Rotor thrust follows its (saturated) setpoint with the
motor lag. Each rotor's thrust is scaled by ``1 + spread_i`` (drawn once per
seed) and by an aerodynamic efficiency that depends on the tilts::

    eta_j = 1 - rotor_arm sin^2(alpha_i)
              - rotor_rotor sum_k max(0, -n_k . e_kj)^4   (pairs k next to arm i of rotor j)

where ``n_k`` is the thrust direction of pair k and ``e_kj`` the unit vector
from pair k to pair j: the wake of a pair tilted towards a neighbour hits it.

The rigid body is integrated with RK4 at ``physics_rate`` (default 1 kHz); the
controller runs at the vehicle's ``controller.rate_hz`` on noisy measurements;
the IMU is logged at ``imu_rate`` (200 Hz), everything else at the controller
rate.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.errors import ConfigError
from omavctl.logs.types import RawLog, RawSeries
from omavctl.physics.allocation import Allocation
from omavctl.physics.controller import Controller, ControllerState, ResidualModel
from omavctl.physics.effects import Effect, get_effect
from omavctl.physics.rigid_body import rotation_matrix, wrap_angle
from omavctl.trajectory import Trajectory
from omavctl.vehicle import Vehicle, load_yaml_mapping

__all__ = [
    "SimulationResult",
    "TruthParameters",
    "load_truth",
    "simulate",
]

#: Absolute time of the first sample of simulated logs (s since the epoch).
LOG_EPOCH = 1_700_000_000.0

_ACTUATOR_DEFAULTS: dict[str, Any] = {
    "servo_time_constant": 0.005,
    "servo_backlash_deg": 0.3,
    "motor_time_constant": 0.005,
    "thrust_spread": 0.03,
    "interference": {"rotor_rotor": 0.25, "rotor_arm": 0.04},
}
_NOISE_DEFAULTS = {"gyro": 0.003, "attitude": 0.002, "position": 0.001, "velocity": 0.01}


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
    top = {"seed": 0, "ideal": False, "actuators": {}, "effects": {}, "noise": {}}
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


def load_truth(path: str | Path | None, vehicle: Vehicle) -> TruthParameters:
    """Load a truth YAML; ``None`` gives the default imperfections, no hidden effects."""
    if path is None:
        return truth_from_tree({}, vehicle)
    p = Path(path)
    return truth_from_tree(load_yaml_mapping(p), vehicle, p)


@dataclass
class SimulationResult:
    """A simulated flight: the log as recorded and what happened."""

    log: RawLog
    infeasible_steps: int  # controller steps whose wrench violated actuator limits
    steps: int
    max_attitude_error: float  # rad
    diverged: bool


class _Actuators:
    """Servo, backlash, motor lag, spread and interference (vectorised over arms)."""

    def __init__(self, vehicle: Vehicle, truth: TruthParameters, alloc: Allocation, rng) -> None:
        self.v, self.truth, self.alloc = vehicle, truth, alloc
        self.spread = 1.0 + truth.thrust_spread * rng.standard_normal(12)
        hover = vehicle.mass * vehicle.gravity / 12.0
        self.shaft = np.zeros(6)
        self.tilt = np.zeros(6)
        self.thrust = np.full(12, hover)
        pos = alloc.arm_position
        # neighbours of each arm: the pairs at +-1 index around the hexagon
        self.neigh = np.array([[(i - 1) % 6, (i + 1) % 6] for i in range(6)])
        diff = pos[None, :, :] - pos[:, None, :]  # [k, j] = r_j - r_k
        norm = np.linalg.norm(diff, axis=-1, keepdims=True)
        self.e_kj = np.divide(diff, norm, out=np.zeros_like(diff), where=norm > 0)

    def efficiency(self, tilt: np.ndarray) -> np.ndarray:
        """Per-arm thrust efficiency (..., 6) from tilts (..., 6)."""
        t = self.truth
        n = self.alloc.thrust_directions(tilt)  # (..., 6, 3)
        # wake of pair k along -n_k hits pair j when -n_k . e_kj > 0
        hit = np.clip(-np.einsum("...kc,kjc->...kj", n, self.e_kj), 0.0, None) ** 4
        cols = np.arange(6)
        loss_rr = hit[..., self.neigh[:, 0], cols] + hit[..., self.neigh[:, 1], cols]
        return 1.0 - t.rotor_arm * np.sin(tilt) ** 2 - t.rotor_rotor * loss_rr

    def advance(
        self, tilt_cmd: np.ndarray, thrust_cmd: np.ndarray, dt: float, n: int
    ) -> np.ndarray:
        """Run ``n`` steps of ``dt`` towards constant setpoints; returns the actual
        wrench (n, 6) after each step (efficiency and forward map batched)."""
        t, rate = self.truth, self.v.max_tilt_rate
        half = t.servo_backlash / 2.0
        motor = 1.0 - math.exp(-dt / t.motor_time_constant) if t.motor_time_constant > 0 else 1.0
        lag = t.servo_time_constant if t.servo_time_constant > 0 else dt
        tilts, thrusts = np.empty((n, 6)), np.empty((n, 12))
        for i in range(n):
            speed = wrap_angle(tilt_cmd - self.shaft) / lag
            self.shaft = self.shaft + np.clip(speed, -rate, rate) * dt
            gap = self.shaft - self.tilt
            self.tilt = np.where(
                gap > half, self.shaft - half, np.where(gap < -half, self.shaft + half, self.tilt)
            )
            self.thrust = self.thrust + motor * (thrust_cmd - self.thrust)
            tilts[i], thrusts[i] = self.tilt, self.thrust
        eff = np.repeat(self.efficiency(tilts), 2, axis=-1)
        return self.alloc.forward(tilts, thrusts * self.spread * eff)

    def rotor_speed(self) -> np.ndarray:
        return np.sqrt(np.clip(self.thrust, 0.0, None) / self.v.thrust_coefficient)


class _Body:
    """Newton–Euler derivative of one vehicle on Python floats.

    Same equations as :func:`omavctl.physics.rigid_body.state_derivative`
    (a test checks they agree); scalar code because numpy's per-call overhead
    on 3-vectors dominated the 1 kHz inner loop (profiled: 4x slower).
    """

    def __init__(self, mass: float, inertia: np.ndarray, gravity: float) -> None:
        self.m, self.g = mass, gravity
        self.i = [[float(v) for v in row] for row in inertia]
        self.ii = [[float(v) for v in row] for row in np.linalg.inv(inertia)]

    def derivative(self, x: list[float], f: list[float], tau: list[float]) -> list[float]:
        _, _, _, r, p, y, vx, vy, vz, wx, wy, wz = x
        cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
        cy, sy = math.cos(y), math.sin(y)
        tp = sp / cp
        f0, f1, f2 = f
        ax = (cy * cp * f0 + (cy * sp * sr - sy * cr) * f1 + (cy * sp * cr + sy * sr) * f2) / self.m
        ay = (sy * cp * f0 + (sy * sp * sr + cy * cr) * f1 + (sy * sp * cr - cy * sr) * f2) / self.m
        az = (-sp * f0 + cp * sr * f1 + cp * cr * f2) / self.m - self.g
        i, ii = self.i, self.ii
        hx = i[0][0] * wx + i[0][1] * wy + i[0][2] * wz
        hy = i[1][0] * wx + i[1][1] * wy + i[1][2] * wz
        hz = i[2][0] * wx + i[2][1] * wy + i[2][2] * wz
        mx = tau[0] - (wy * hz - wz * hy)
        my = tau[1] - (wz * hx - wx * hz)
        mz = tau[2] - (wx * hy - wy * hx)
        return [
            vx,
            vy,
            vz,
            wx + sr * tp * wy + cr * tp * wz,
            cr * wy - sr * wz,
            (sr * wy + cr * wz) / cp,
            ax,
            ay,
            az,
            ii[0][0] * mx + ii[0][1] * my + ii[0][2] * mz,
            ii[1][0] * mx + ii[1][1] * my + ii[1][2] * mz,
            ii[2][0] * mx + ii[2][1] * my + ii[2][2] * mz,
        ]

    def rk4(self, x: list[float], f: list[float], tau: list[float], dt: float) -> list[float]:
        """One RK4 step with the wrench held over ``dt``."""
        d = self.derivative
        k1 = d(x, f, tau)
        k2 = d([a + 0.5 * dt * b for a, b in zip(x, k1, strict=True)], f, tau)
        k3 = d([a + 0.5 * dt * b for a, b in zip(x, k2, strict=True)], f, tau)
        k4 = d([a + dt * b for a, b in zip(x, k3, strict=True)], f, tau)
        return [
            a + dt / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
            for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4, strict=True)
        ]


def simulate(
    reference: Trajectory,
    vehicle: Vehicle,
    truth: TruthParameters,
    model: ResidualModel | None = None,
    seed: int | None = None,
    physics_rate: float = 1000.0,
    imu_rate: float = 200.0,
    progress: Callable[[float], None] | None = None,
) -> SimulationResult:
    """Fly ``reference`` in closed loop through the truth plant.

    The rotor thrust spread is a property of the simulated vehicle: it is drawn
    from the truth file's ``seed``. ``seed`` (default: the truth file's) draws
    the sensor noise, so flights with different seeds are different flights of
    the same vehicle.
    Returns the log with every contract role (stamps from 0 at the first
    controller step, ``t0`` = :data:`LOG_EPOCH`).
    """
    alloc = Allocation(vehicle)
    act = _Actuators(vehicle, truth, alloc, np.random.default_rng([truth.seed, 0x5EED]))
    rng = np.random.default_rng(truth.seed if seed is None else seed)
    ctrl = Controller(vehicle, model)
    state = ControllerState.zeros(1)
    body = _Body(vehicle.mass, truth.inertia, vehicle.gravity)
    noise = truth.noise
    gyro_bias = np.zeros(3)
    for effect, params in truth.effects:
        off = effect.gyro_offset(params)
        if off is not None:
            gyro_bias = gyro_bias + off
    torque_effects = [
        (e, p) for e, p in truth.effects if type(e).body_torque is not Effect.body_torque
    ]

    ctrl_rate = vehicle.gains.rate_hz
    n_sub = round(physics_rate / ctrl_rate)
    imu_every = round(physics_rate / imu_rate)
    if (
        abs(n_sub * ctrl_rate - physics_rate) > 1e-9
        or abs(imu_every * imu_rate - physics_rate) > 1e-9
    ):
        raise ConfigError("physics rate must be a multiple of the controller and IMU rates")
    dt_phys, dt_ctrl = 1.0 / physics_rate, 1.0 / ctrl_rate
    n_ctrl = int(np.floor(reference.duration * ctrl_rate + 1e-9)) + 1
    times = np.arange(n_ctrl) / ctrl_rate
    ref_rows = reference.sample(times + reference.t[0])

    x = np.zeros(12)
    x[0:3] = ref_rows[0, 1:4]
    x[3:6] = ref_rows[0, 4:7]
    x[6:9] = ref_rows[0, 7:10]
    x[9:12] = ref_rows[0, 10:13]
    act.tilt = act.shaft = alloc.allocate(
        np.concatenate([vehicle.mass * vehicle.gravity * np.array([0.0, 0.0, 1.0]), np.zeros(3)])
    ).tilt

    n_imu = (n_ctrl - 1) * (n_sub // imu_every) + 1
    imu_t, imu_v = np.empty(n_imu), np.empty((n_imu, 3))
    rec = {
        k: np.empty((n_ctrl, 3))
        for k in (
            "attitude",
            "position",
            "velocity",
            "force_command",
            "torque_command",
            "desired_acceleration",
            "desired_linear_acceleration",
        )
    }
    tilt_log, rotor_log = np.empty((n_ctrl, 6)), np.empty((n_ctrl, 12))
    infeasible, max_att_err, diverged = 0, 0.0, False
    prev_tilt_cmd = act.tilt.copy()
    gyro_meas = x[9:12] + gyro_bias + noise["gyro"] * rng.standard_normal(3)
    imu_t[0], imu_v[0] = times[0], gyro_meas
    i_imu = 1

    for k in range(n_ctrl):
        t = times[k]
        # measured state; velocity in world frame for the controller, logged in body frame
        meas = np.concatenate(
            [
                x[0:3] + noise["position"] * rng.standard_normal(3),
                wrap_angle(x[3:6] + noise["attitude"] * rng.standard_normal(3)),
                x[6:9] + noise["velocity"] * rng.standard_normal(3),
                gyro_meas,
            ]
        )
        out = ctrl.step(state, meas[None, :], ref_rows[k : k + 1], dt_ctrl)
        wrench = np.concatenate([out.force[0], out.torque[0]])
        res = alloc.allocate(wrench[None, :], prev_tilt_cmd[None, :], dt_ctrl)
        if not bool(res.feasible[0]):
            infeasible += 1
        tilt_cmd = res.tilt[0]
        thrust_cmd = np.clip(res.rotor_thrust[0], vehicle.min_thrust, vehicle.max_thrust)
        prev_tilt_cmd = tilt_cmd

        r_wb = rotation_matrix(x[3:6])
        rec["attitude"][k] = meas[3:6]
        rec["position"][k] = meas[0:3]
        rec["velocity"][k] = r_wb.T @ meas[6:9]
        rec["force_command"][k] = out.force[0]
        rec["torque_command"][k] = out.torque[0]
        rec["desired_acceleration"][k] = out.desired_angular[0]
        rec["desired_linear_acceleration"][k] = out.desired_linear[0]
        tilt_log[k] = act.tilt
        rotor_log[k] = act.rotor_speed()
        att_err = float(np.max(np.abs(wrap_angle(x[3:6] - ref_rows[k, 4:7]))))
        max_att_err = max(max_att_err, att_err)
        if not np.all(np.isfinite(x)) or att_err > np.deg2rad(80) or abs(x[4]) > np.deg2rad(85):
            diverged = True
            # a non-finite state is not logged: the log ends at the last finite sample
            n_ctrl = k + 1 if np.all(np.isfinite(x)) else k
            break
        if k == len(times) - 1:
            break
        xs = x.tolist()
        wrenches = act.advance(tilt_cmd, thrust_cmd, dt_phys, n_sub)
        for s in range(n_sub):
            force, torque = wrenches[s, :3], wrenches[s, 3:]
            # effect torques from the state at the start of the 1 ms step
            for effect, params in torque_effects:
                extra = effect.body_torque(params, np.asarray(xs[9:12]), force)
                if extra is not None:
                    torque = torque + extra
            xs = body.rk4(xs, force.tolist(), torque.tolist(), dt_phys)
            if (s + 1) % imu_every == 0:
                x = np.asarray(xs)
                gyro_meas = x[9:12] + gyro_bias + noise["gyro"] * rng.standard_normal(3)
                imu_t[i_imu] = t + (s + 1) * dt_phys
                imu_v[i_imu] = gyro_meas
                i_imu += 1
        x = np.asarray(xs)
        if progress is not None:
            progress((k + 1) / len(times))

    ct = times[:n_ctrl]
    finite_imu = np.isfinite(imu_v[:i_imu]).all(axis=1)
    i_imu = int(np.argmin(finite_imu)) if not finite_imu.all() else i_imu
    series = {
        "body_rate": RawSeries(imu_t[:i_imu].copy(), imu_v[:i_imu].copy()),
        **{k: RawSeries(ct.copy(), v[:n_ctrl].copy()) for k, v in rec.items()},
        "reference_position": RawSeries(ct.copy(), ref_rows[:n_ctrl, 1:4].copy()),
        "reference_attitude": RawSeries(ct.copy(), ref_rows[:n_ctrl, 4:7].copy()),
        "tilt": RawSeries(ct.copy(), tilt_log[:n_ctrl].copy()),
        "rotor": RawSeries(ct.copy(), rotor_log[:n_ctrl].copy()),
    }
    log = RawLog(path=Path("<simulated>"), format="simulated", t0=LOG_EPOCH, series=series)
    return SimulationResult(log, infeasible, n_ctrl, max_att_err, diverged)
