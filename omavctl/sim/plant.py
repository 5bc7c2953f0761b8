"""Truth plant: the simulated vehicle that ``omavctl simulate`` flies.

Commanded wrench -> allocation -> actuator setpoints -> actuator dynamics and
imperfections -> actual wrench -> rigid body, plus hidden effects and sensor
noise from a truth file (:mod:`omavctl.sim.truth`).

Actuators: the servo shaft follows its setpoint with the first-order lag,
limited to ``servo.max_tilt_rate``; the arm follows the shaft through the
backlash dead band. Rotor thrust follows its (saturated) setpoint with the
motor lag. The thrust its speed gives is bent, lost and scaled with the battery
voltage by the motor-level effects (``thrust_curve``, ``motor_loss``,
``battery_sag``: :meth:`_Actuators.motor_level`), then scaled by ``1 + spread_i``
(drawn once per seed) and by an aerodynamic efficiency that depends on the tilts::

    eta_j = 1 - rotor_arm sin^2(alpha_i)
              - rotor_rotor sum_k max(0, -n_k . e_kj)^4   (pairs k next to arm i of rotor j)

where ``n_k`` is the thrust direction of pair k and ``e_kj`` the unit vector
from pair k to pair j: the wake of a pair tilted towards a neighbour hits it.

The rigid body is integrated with RK4 at ``physics_rate`` (default 1 kHz); the
controller runs at ``timing.controller_rate_hz`` (default the vehicle's
``controller.rate_hz``) on noisy measurements; the applied setpoints are those
of ``effects.command_delay.tau_d`` seconds before (sub-sample, at the physics
rate). The battery voltage falls over the flight and sags with the total thrust
(truth ``battery:``; logged as ``battery_voltage``). The IMU is logged at
``imu_rate`` (200 Hz), everything else at the
vehicle's ``controller.rate_hz`` (the log grid): each row holds the latest
command (held when the controller is slower, sampled when it is faster). When
the vehicle diverges (attitude error beyond 80 deg) the log goes on for
:data:`AFTER_LOSS_SECONDS` of the tumble, as a real log would, then ends.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.logs.types import RawLog, RawSeries
from omavctl.physics.allocation import Allocation
from omavctl.physics.controller import Controller, ControllerState, ResidualModel
from omavctl.physics.effects import Effect
from omavctl.physics.rigid_body import rotation_matrix, wrap_angle
from omavctl.sim.scalar import ScalarAllocation, ScalarBody, ScalarController, ScalarOutput
from omavctl.sim.trajectory import Trajectory
from omavctl.sim.truth import TruthParameters
from omavctl.vehicle import Vehicle

__all__ = ["SimulationResult", "simulate"]

#: Absolute time of the first sample of simulated logs (s since the epoch).
LOG_EPOCH = 1_700_000_000.0

#: Seconds of log kept after the vehicle diverged (a log ends in the crash).
AFTER_LOSS_SECONDS = 1.0
#: Shortest span (s) over which a commanded tilt rate is checked against the servo
#: limit: one step of a 100 Hz controller.
TILT_RATE_WINDOW = 0.01
#: Body rate (rad/s) beyond which the simulation of a tumbling vehicle stops.
MAX_RATE = 200.0


@dataclass
class SimulationResult:
    """A simulated flight: the log as recorded and what happened."""

    log: RawLog
    infeasible_steps: int  # controller steps whose wrench violated actuator limits
    steps: int
    max_attitude_error: float  # rad
    diverged: bool
    #: s from the start when the attitude error first exceeded 80 deg (None: never)
    diverged_at: float | None = None
    #: s of flight in the log (to its last row)
    duration: float = 0.0


class _Actuators:
    """Servo, backlash, motor lag, spread and interference (vectorised over arms)."""

    def __init__(
        self, vehicle: Vehicle, truth: TruthParameters, alloc: Allocation, rng, duration: float
    ) -> None:
        self.v, self.truth, self.alloc = vehicle, truth, alloc
        self.spread = 1.0 + truth.thrust_spread * rng.standard_normal(12)
        self.health = np.ones(12)  # remaining thrust fraction per rotor (failures)
        hover = vehicle.mass * vehicle.gravity / 12.0
        self.shaft = np.zeros(6)
        self.tilt = np.zeros(6)
        self.thrust = np.full(12, hover)
        #: tilts (n, 6) and rotor thrusts (n, 12) after each step of the last advance
        self.path = (np.empty((0, 6)), np.empty((0, 12)))
        self.duration = max(duration, 1e-9)
        self.voltage = truth.battery["nominal"] + 0.5 * truth.battery["drop"]
        self.volts = np.full(1, self.voltage)  # battery voltage after each step of a chunk

    def battery(self, t: np.ndarray, thrusts: np.ndarray) -> np.ndarray:
        """Battery voltage (n,) V at times t (n,) s with rotor thrusts (n, 12) N: the
        nominal voltage at mid-flight hover, falling by ``drop`` over the flight and
        sagging by ``sag`` per N of total thrust above hover."""
        b, hover = self.truth.battery, self.v.mass * self.v.gravity
        return (
            b["nominal"]
            + b["drop"] * (0.5 - t / self.duration)
            - b["sag"] * (thrusts.sum(axis=-1) - hover)
        )

    def motor_level(self, thrusts: np.ndarray, volts: np.ndarray) -> np.ndarray:
        """True rotor thrusts (n, 12) N from the thrusts their speeds give (n, 12): the
        thrust curve bent by ``c`` (``T + c (T - sqrt(T T_full))``), each rotor's loss,
        the battery's voltage about its nominal (thrust_curve, motor_loss, battery_sag)."""
        t = self.truth
        out = thrusts
        if t.thrust_curvature:
            full = self.v.max_thrust
            out = out + t.thrust_curvature * (out - np.sqrt(np.clip(out, 0.0, None) * full))
        out = out * (1.0 - t.rotor_loss)
        if t.battery_sag:
            out = out * (1.0 + t.battery_sag * (volts - t.battery["nominal"]))[:, None]
        return out

    def efficiency(self, tilt: np.ndarray) -> np.ndarray:
        """Per-arm thrust efficiency (..., 6) from tilts (..., 6)."""
        wake, arm = self.alloc.interference(tilt)
        return 1.0 - self.truth.rotor_arm * arm - self.truth.rotor_rotor * wake

    def advance(
        self, tilt_cmd: np.ndarray, thrust_cmd: np.ndarray, dt: float, n: int, t0: float
    ) -> np.ndarray:
        """Run ``n`` steps of ``dt`` from time ``t0`` towards constant setpoints; returns
        the actual wrench (n, 6) after each step (efficiency and forward map batched)."""
        t, rate = self.truth, self.v.max_tilt_rate
        half = t.servo_backlash / 2.0
        motor = 1.0 - math.exp(-dt / t.motor_time_constant) if t.motor_time_constant > 0 else 1.0
        lag = t.servo_time_constant if t.servo_time_constant > 0 else dt
        tilts, thrusts = np.empty((n, 6)), np.empty((n, 12))
        # the servos on Python floats (numpy's per-call overhead on 6-vectors was most
        # of a step; same arithmetic, so bit-identical): the shaft follows the setpoint,
        # rate-limited; the arm follows the shaft through the backlash dead band
        pi, two_pi = math.pi, 2.0 * math.pi
        cmd, shafts, arms = tilt_cmd.tolist(), self.shaft.tolist(), self.tilt.tolist()
        for a in range(6):
            c, shaft, arm = cmd[a], shafts[a], arms[a]
            col = tilts[:, a].tolist()
            for i in range(n):
                speed = ((c - shaft + pi) % two_pi - pi) / lag
                shaft = shaft + min(max(speed, -rate), rate) * dt
                gap = shaft - arm
                if gap > half:
                    arm = shaft - half
                elif gap < -half:
                    arm = shaft + half
                col[i] = arm
            tilts[:, a] = col
            shafts[a], arms[a] = shaft, arm
        self.shaft, self.tilt = np.array(shafts), np.array(arms)
        thrust = self.thrust
        for i in range(n):
            thrust = thrust + motor * (thrust_cmd - thrust)
            thrusts[i] = thrust
        self.thrust = thrust
        self.path = (tilts, thrusts)  # the states after each step, for the log
        eff = np.repeat(self.efficiency(tilts), 2, axis=-1)
        self.volts = self.battery(t0 + dt * np.arange(1, n + 1), thrusts)
        true = self.motor_level(thrusts, self.volts)
        return self.alloc.forward(tilts, true * self.spread * self.health * eff)

    def fail(self, arms: tuple[int, ...], factor: float) -> None:
        """The rotor pairs of ``arms`` keep ``factor`` of their thrust from now on."""
        for arm in arms:
            self.health[2 * arm : 2 * arm + 2] = factor

    def rotor_speed(self, thrust: np.ndarray | None = None) -> np.ndarray:
        """Rotor speeds (12,) rad/s of ``thrust`` (12,) N (default: the current state)."""
        t = self.thrust if thrust is None else thrust
        return np.sqrt(np.clip(t, 0.0, None) / self.v.thrust_coefficient)


_RECORDED = (
    "attitude",
    "position",
    "velocity",
    "force_command",
    "torque_command",
    "desired_acceleration",
    "desired_linear_acceleration",
)


@dataclass
class _Rates:
    """Step counts of one simulation, all in physics steps."""

    dt: float  # physics step, s
    ctrl_every: int
    log_every: int
    imu_every: int
    steps: int  # physics steps in the flight

    @classmethod
    def of(
        cls, physics_rate: float, ctrl: float, log: float, imu: float, duration: float
    ) -> _Rates:
        every = [round(physics_rate / r) for r in (ctrl, log, imu)]
        if any(
            e < 1 or abs(e * r - physics_rate) > 1e-6
            for e, r in zip(every, (ctrl, log, imu), strict=True)
        ):
            raise ConfigError(
                f"the physics rate ({physics_rate:g} Hz) must be a multiple of the controller "
                f"({ctrl:g} Hz), log ({log:g} Hz) and IMU ({imu:g} Hz) rates"
            )
        steps = int(np.floor(duration * physics_rate + 1e-9))
        steps -= steps % every[1]  # end on a log sample
        return cls(1.0 / physics_rate, every[0], every[1], every[2], steps)


class _Flight:
    """One closed-loop flight through the truth plant (state of :func:`simulate`)."""

    def __init__(
        self,
        reference: Trajectory,
        vehicle: Vehicle,
        truth: TruthParameters,
        model: ResidualModel | None,
        rng: np.random.Generator,
        rates: _Rates,
    ) -> None:
        self.v, self.truth, self.rng, self.r = vehicle, truth, rng, rates
        self.alloc = Allocation(vehicle)
        self.act = _Actuators(
            vehicle,
            truth,
            self.alloc,
            np.random.default_rng([truth.seed, 0x5EED]),
            rates.steps * rates.dt,
        )
        # without a learned model the controller runs on Python floats (same equations)
        self.ctrl = Controller(vehicle, model) if model is not None else None
        self.scalar = ScalarController(vehicle)
        self.scalar_alloc = ScalarAllocation(self.alloc)
        self.state = ControllerState.zeros(1)
        self.body = ScalarBody(vehicle.mass, truth.inertia, vehicle.gravity)
        self.noise = truth.noise
        n = truth.noise
        self.noise_scale = np.repeat([n["position"], n["attitude"], n["velocity"], n["gyro"]], 3)
        self.gyro_bias = np.zeros(3)
        for effect, params in truth.effects:
            off = effect.gyro_offset(params)
            if off is not None:
                self.gyro_bias = self.gyro_bias + off
        self.bias = np.concatenate([np.zeros(9), self.gyro_bias])
        self.torque_effects = [
            (e, p) for e, p in truth.effects if type(e).body_torque is not Effect.body_torque
        ]
        n_ctrl = rates.steps // rates.ctrl_every + 1
        self.ref_rows = reference.sample(
            np.arange(n_ctrl) * rates.ctrl_every * rates.dt + reference.t[0]
        )
        first = self.ref_rows[0]
        self.x = np.concatenate([first[1:4], first[4:7], first[7:10], first[10:13]])
        hover = self.alloc.allocate(
            np.concatenate([vehicle.mass * vehicle.gravity * np.array([0.0, 0.0, 1.0]), [0, 0, 0]])
        )
        self.act.tilt = self.act.shaft = hover.tilt
        self.hover_cmd = (hover.tilt.copy(), np.clip(hover.rotor_thrust, 0.0, None))
        self.cmd_tilt = np.empty((n_ctrl, 6))
        self.cmd_thrust = np.empty((n_ctrl, 12))
        self.outputs: list[ScalarOutput] = []
        n_log = rates.steps // rates.log_every + 1
        self.rec = {k: np.empty((n_log, 3)) for k in _RECORDED}
        self.rec_t = np.empty(n_log)
        self.tilt_log, self.rotor_log = np.empty((n_log, 6)), np.empty((n_log, 12))
        self.volt_log = np.empty((n_log, 1))
        n_imu = rates.steps // rates.imu_every + 1
        self.imu_t, self.imu_v = np.empty(n_imu), np.empty((n_imu, 3))
        self.n_log = self.n_imu = 0
        self.infeasible = 0
        self.max_att_err = 0.0
        self.diverged_at: float | None = None
        self.prev_tilt_cmd = hover.tilt.tolist()

    # ---------------------------------------------------------------- events
    def measure(self) -> np.ndarray:
        """Noisy measurement (12,) of the state: world velocity, wrapped angles."""
        meas = self.x + self.bias + self.noise_scale * self.rng.standard_normal(12)
        meas[3:6] = wrap_angle(meas[3:6])
        return meas

    def command(self, k: int, dt_ctrl: float) -> ScalarOutput:
        """The controller's output at controller step k from a fresh measurement."""
        if self.ctrl is None:
            return self.scalar.step(self.measure().tolist(), self.ref_rows[k].tolist(), dt_ctrl)
        out = self.ctrl.step(self.state, self.measure()[None, :], self.ref_rows[k : k + 1], dt_ctrl)
        rows = (out.force, out.torque, out.desired_angular, out.desired_linear)
        return ScalarOutput(*(a[0].tolist() for a in rows))

    def control(self, k: int) -> None:
        """Controller step k: command from a fresh measurement, setpoints stored."""
        dt_ctrl = self.r.ctrl_every * self.r.dt
        out = self.command(k, dt_ctrl)
        tilt, rotor, ok = self.scalar_alloc.allocate(out.force + out.torque, self.prev_tilt_cmd)
        # the tilt rate over TILT_RATE_WINDOW at least: per 1 ms step of a fast controller,
        # sensor noise through the controller jitters the tilt at rates no servo could
        # follow, and every step would count as infeasible
        back = max(1, math.ceil(TILT_RATE_WINDOW / dt_ctrl - 1e-9))
        old = self.cmd_tilt[k - back].tolist() if k >= back else self.hover_cmd[0].tolist()
        if not ok or self.scalar_alloc.rate_exceeded(tilt, old, back * dt_ctrl):
            self.infeasible += 1
        self.cmd_tilt[k] = tilt
        self.prev_tilt_cmd = tilt
        self.cmd_thrust[k] = [min(max(r, self.v.min_thrust), self.v.max_thrust) for r in rotor]
        self.outputs.append(out)
        x, ref = self.x.tolist(), self.ref_rows[k].tolist()
        pi, two_pi = math.pi, 2.0 * math.pi
        att_err = max(abs((x[3 + i] - ref[4 + i] + pi) % two_pi - pi) for i in range(3))
        self.max_att_err = max(self.max_att_err, att_err)
        lost = att_err > math.radians(80) or abs(x[4]) > math.radians(85)
        if lost and self.diverged_at is None:
            self.diverged_at = k * dt_ctrl

    def record_log(self, t: float, actuators: tuple[np.ndarray, np.ndarray]) -> None:
        """A log row at time t: measured state, the latest controller output, the
        actuators' state ``(tilts (6,) rad, rotor thrusts (12,) N)`` at t."""
        i, out, meas = self.n_log, self.outputs[-1], self.measure()
        self.rec_t[i] = t
        self.rec["attitude"][i] = meas[3:6]
        self.rec["position"][i] = meas[0:3]
        self.rec["velocity"][i] = rotation_matrix(self.x[3:6]).T @ meas[6:9]
        self.rec["force_command"][i] = out.force
        self.rec["torque_command"][i] = out.torque
        self.rec["desired_acceleration"][i] = out.desired_angular
        self.rec["desired_linear_acceleration"][i] = out.desired_linear
        self.tilt_log[i] = actuators[0]
        self.rotor_log[i] = self.act.rotor_speed(actuators[1])
        self.volt_log[i] = self.act.voltage
        self.n_log += 1

    def record_imu(self, t: float) -> None:
        n = self.noise["gyro"]
        self.imu_t[self.n_imu] = t
        self.imu_v[self.n_imu] = self.x[9:12] + self.gyro_bias + n * self.rng.standard_normal(3)
        self.n_imu += 1

    def applied(self, step: int) -> int:
        """Index of the controller step whose setpoints act at physics ``step`` (-1: hover)."""
        t = step * self.r.dt - self.truth.command_delay
        return min(math.floor(t / (self.r.ctrl_every * self.r.dt) + 1e-9), len(self.outputs) - 1)

    # ------------------------------------------------------------------ loop
    def run(self, progress: Callable[[float], None] | None = None) -> None:
        """Fly until the end of the reference or shortly after a loss of control."""
        r = self.r
        i = 0
        while True:
            if i % r.ctrl_every == 0:
                self.control(i // r.ctrl_every)
            if i >= r.steps or not self._airborne(i):
                finite = bool(np.all(np.isfinite(self.x)))  # a state that blew up is not logged
                if finite and i % r.log_every == 0 and self.n_log < self.rec_t.size:
                    self.record_log(i * r.dt, (self.act.tilt, self.act.thrust))
                if finite and i % r.imu_every == 0 and self.n_imu < self.imu_t.size:
                    self.record_imu(i * r.dt)
                return
            failure = self.truth.failure
            if failure is not None and i * r.dt >= failure[0]:
                self.act.fail(failure[1], failure[2])
            n = self._chunk(i)
            i = self._integrate(i, n)
            if progress is not None:
                progress(i / r.steps)

    def _airborne(self, step: int) -> bool:
        """False once the log has run AFTER_LOSS_SECONDS past a divergence or blew up."""
        x = self.x.tolist()
        if not all(map(math.isfinite, x)) or max(abs(w) for w in x[9:12]) > MAX_RATE:
            return False
        return self.diverged_at is None or step * self.r.dt < self.diverged_at + AFTER_LOSS_SECONDS

    def _chunk(self, i: int) -> int:
        """Physics steps from i with the same applied setpoints, up to the next control step."""
        r, j = self.r, self.applied(i)
        n = 1
        while i + n < r.steps and (i + n) % r.ctrl_every != 0 and self.applied(i + n) == j:
            n += 1
        return n

    def _integrate(self, i: int, n: int) -> int:
        """Advance ``n`` physics steps from step i with constant setpoints; returns i + n."""
        r, j = self.r, self.applied(i)
        tilt, thrust = (self.cmd_tilt[j], self.cmd_thrust[j]) if j >= 0 else self.hover_cmd
        # the log records the actuators where they are at its instant: before the chunk's
        # first step, after the step before for the others (advance runs the whole chunk)
        start = (self.act.tilt.copy(), self.act.thrust.copy())
        wrenches = self.act.advance(tilt, thrust, r.dt, n, i * r.dt)
        path = self.act.path
        forces, torques = wrenches[:, :3].tolist(), wrenches[:, 3:]
        volts = self.act.volts.tolist()
        xs = self.x.tolist()
        isfinite = math.isfinite
        for s in range(n):
            step = i + s
            self.act.voltage = volts[s]
            if step % r.log_every == 0:
                self.x = np.array(xs)
                self.record_log(step * r.dt, start if s == 0 else (path[0][s - 1], path[1][s - 1]))
            if step % r.imu_every == 0:
                self.x = np.array(xs)
                self.record_imu(step * r.dt)
            torque = torques[s]
            # effect torques from the state at the start of the physics step
            for effect, params in self.torque_effects:
                extra = effect.body_torque(params, np.asarray(xs[9:12]), wrenches[s, :3])
                if extra is not None:
                    torque = torque + extra
            xs = self.body.rk4(xs, forces[s], torque.tolist(), r.dt)
            if not all(map(isfinite, xs)):
                self.x = np.array(xs)
                return step + 1
        self.x = np.array(xs)
        return i + n

    def result(self, reference: Trajectory) -> SimulationResult:
        """The log as recorded (every contract role) and what happened."""
        n, ct = self.n_log, self.rec_t[: self.n_log].copy()
        ref_rows = reference.sample(ct + reference.t[0])
        series = {
            "body_rate": RawSeries(
                self.imu_t[: self.n_imu].copy(), self.imu_v[: self.n_imu].copy()
            ),
            **{k: RawSeries(ct.copy(), v[:n].copy()) for k, v in self.rec.items()},
            "reference_position": RawSeries(ct.copy(), ref_rows[:, 1:4].copy()),
            "reference_attitude": RawSeries(ct.copy(), ref_rows[:, 4:7].copy()),
            "tilt": RawSeries(ct.copy(), self.tilt_log[:n].copy()),
            "rotor": RawSeries(ct.copy(), self.rotor_log[:n].copy()),
            "battery_voltage": RawSeries(ct.copy(), self.volt_log[:n].copy()),
        }
        log = RawLog(path=Path("<simulated>"), format="simulated", t0=LOG_EPOCH, series=series)
        return SimulationResult(
            log,
            self.infeasible,
            len(self.outputs),
            self.max_att_err,
            self.diverged_at is not None,
            self.diverged_at,
            float(ct[-1]) if n else 0.0,
        )


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
    the same vehicle. The controller runs at ``truth.controller_rate_hz``
    (default the vehicle's ``controller.rate_hz``), the log at the vehicle's
    rate, the IMU at ``imu_rate``; all must divide ``physics_rate``.
    Returns the log with every contract role (stamps from 0 at the first
    controller step, ``t0`` = :data:`LOG_EPOCH`).
    """
    log_rate = vehicle.gains.rate_hz
    ctrl_rate = truth.controller_rate_hz or log_rate
    rates = _Rates.of(physics_rate, ctrl_rate, log_rate, imu_rate, reference.duration)
    rng = np.random.default_rng(truth.seed if seed is None else seed)
    flight = _Flight(reference, vehicle, truth, model, rng, rates)
    flight.run(progress)
    return flight.result(reference)
