"""Effects of the actuation chain: servo and motor lags, a pure command delay, rotor interference.

Part of the registry :data:`omavctl.physics.effects.EFFECTS` (formulas in the
class docstrings and ``docs/effects.md``).
"""

from __future__ import annotations

import math

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.physics.effect_base import Effect, EffectContext, Parameter

__all__ = [
    "CommandDelay",
    "MotorLag",
    "RotorInterference",
    "ServoLag",
    "first_order_lag",
    "shift_held",
]


class ServoLag(Effect):
    """Tilt servos follow their setpoints with a first-order lag ``T_s``.

    ``alpha_dot = (alpha_cmd - alpha) / T_s`` gives ``alpha ~= alpha_cmd - T_s
    alpha_cmd_dot``, so the wrench error is ``-T_s J_alpha alpha_cmd_dot`` with
    ``J_alpha = d wrench / d alpha`` of the allocation; residual
    ``-T_s I^-1 [J_alpha alpha_cmd_dot]_torque``. ``T_s`` in s. A vehicle of fixed
    rotors (``ctx.fixed_rotors``) has no servos: the regressor is zero, never excited.
    """

    name = "servo_lag"
    summary = "first-order tilt-servo lag T_s"
    parameters = (Parameter("T_s", 1, "s", "servo time constant"),)
    prior_std = 0.05  # s
    theta_range = (0.0, 0.5)
    search = (0.0, 0.3)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        if ctx.fixed_rotors:  # no tilt servos: nothing to lag (never excited)
            return np.zeros((ctx.torque.shape[0], 3, 1))
        tilt, thrust = ctx.allocated
        rate = ctx.derivative(tilt)  # (N, 6)
        jac = ctx.allocation.tilt_jacobian(tilt, thrust)  # (N, 6, 6)
        dw = -np.einsum("nij,nj->ni", jac, rate)
        return ctx.angular(dw)[:, :, None]

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Tilts through the exact first-order lag of the held setpoints (period means)."""
        if ctx.fixed_rotors:
            return np.zeros((ctx.torque.shape[0], 3))
        tilt, thrust = ctx.allocated
        lagged = first_order_lag(tilt, value, ctx.dt)
        rotor = np.repeat(thrust / 2.0, 2, axis=-1)
        dw = ctx.allocation.forward(lagged, rotor) - ctx.allocation.forward(tilt, rotor)
        return ctx.angular(dw)

    def configure_truth(self, params, truth):
        truth.servo_time_constant = float(params["T_s"][0])


class MotorLag(Effect):
    """Rotor thrust follows its setpoint with a first-order lag ``T_m``.

    ``F ~= F_cmd - T_m F_cmd_dot`` per arm, so the wrench error is
    ``-T_m J_F F_cmd_dot`` (``J_F`` = thrust directions and their moments);
    residual ``-T_m I^-1 [J_F F_cmd_dot]_torque``. ``T_m`` in s.

    On a vehicle described by a fixed rotor list (``ctx.fixed_rotors``: the
    wrench is a fixed matrix times the rotor thrusts, :mod:`omavctl.physics.mixer`)
    a first-order lag of every rotor's thrust with one ``T_m`` is exactly the
    same lag of the commanded torque: residual ``I^-1 (lag(tau_cmd) - tau_cmd)``,
    to first order ``-T_m I^-1 tau_cmd_dot``. Small motors lag by tens of ms
    while their commands carry the rate controller's fast content, where that
    first order fails (and would look exactly like ``command_delay``): the
    linear regressor the diagnosis uses is then the secant
    ``I^-1 (lag(tau_cmd, T_ref) - tau_cmd) / T_ref`` at :attr:`SECANT` (its
    ``T_m`` is exact at ``T_ref`` and a rough value elsewhere; ``fit``'s 1-D
    search over the exact form gives the estimate).
    """

    #: Reference time constant (s) of the rotor-list regressor's secant.
    SECANT: float = 0.04

    name = "motor_lag"
    summary = "first-order rotor-thrust lag T_m"
    parameters = (Parameter("T_m", 1, "s", "motor time constant"),)
    prior_std = 0.05  # s
    theta_range = (0.0, 0.5)
    search = (0.0, 0.3)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        if ctx.fixed_rotors:
            lagged = first_order_lag(ctx.torque, self.SECANT, ctx.dt)
            return ((lagged - ctx.torque) @ ctx.inertia_inv.T / self.SECANT)[:, :, None]
        tilt, thrust = ctx.allocated
        rate = ctx.derivative(thrust)
        jac = ctx.allocation.thrust_jacobian(tilt)
        dw = -np.einsum("nij,nj->ni", jac, rate)
        return ctx.angular(dw)[:, :, None]

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Arm thrusts (rotor thrusts: the torque) through the exact first-order lag
        of the held setpoints."""
        if ctx.fixed_rotors:
            lagged = first_order_lag(ctx.torque, value, ctx.dt)
            return (lagged - ctx.torque) @ ctx.inertia_inv.T
        tilt, thrust = ctx.allocated
        lagged = first_order_lag(thrust, value, ctx.dt)
        dw = ctx.allocation.forward(tilt, np.repeat(lagged / 2.0, 2, axis=-1))
        dw = dw - ctx.allocation.forward(tilt, np.repeat(thrust / 2.0, 2, axis=-1))
        return ctx.angular(dw)

    def configure_truth(self, params, truth):
        truth.motor_time_constant = float(params["T_m"][0])


class CommandDelay(Effect):
    """The applied wrench is the command of ``tau_d`` seconds ago.

    Transport, bus and filter delays: ``tau_applied(t) = tau_cmd(t - tau_d)``,
    hence the residual ``I^-1 (tau_cmd(t - tau_d) - tau_cmd(t))``. Signed: a
    negative ``tau_d`` means the logged command lags what was applied (a
    controller faster than the log, stamps taken late). To first order
    ``-tau_d I^-1 d/dt tau_cmd`` (the linear regressor the diagnosis uses);
    ``fit`` estimates ``tau_d`` exactly, sub-sample, with the held command
    shifted by a fraction of a period. ``tau_d`` in s.
    """

    name = "command_delay"
    summary = "pure delay tau_d of the applied wrench (signed)"
    parameters = (Parameter("tau_d", 1, "s", "delay of the applied wrench behind the command"),)
    prior_std = 0.05  # s
    theta_range = (-0.02, 0.2)
    search = (-0.02, 0.2)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        rate = ctx.derivative(ctx.torque)  # (N, 3)
        return -(rate @ ctx.inertia_inv.T)[:, :, None]

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Mean over each period of the held command delayed by ``value`` s."""
        delayed = shift_held(ctx.torque, value, ctx.dt)
        return (delayed - ctx.torque) @ ctx.inertia_inv.T

    def configure_truth(self, params, truth):
        if params["tau_d"][0] < 0:
            raise ConfigError(
                "'effects.command_delay.tau_d' must be >= 0 in a truth file (the simulator "
                "delays the applied wrench)"
            )
        truth.command_delay = float(params["tau_d"][0])


class RotorInterference(Effect):
    """Tilt-dependent thrust loss of the rotor pairs (aerodynamic interference).

    Each pair's thrust is scaled by ``1 - rotor_rotor w_j - rotor_arm sin^2
    alpha_j``: ``w_j = sum_k max(0, -n_k . e_kj)^4`` over the neighbouring
    pairs k (pair k tilted towards pair j blows its wake onto it) and the
    pair's own wash on its arm. The wrench lost is linear in the two
    coefficients: residual ``-I^-1 [A(alpha) (F w)]_torque rotor_rotor - I^-1
    [A(alpha) (F sin^2 alpha)]_torque rotor_arm`` with the arm thrusts ``F`` of
    the allocation and the tilts ``alpha`` where the arms are (``ctx.arm_tilt``:
    measured where the log records them, else commanded): the wake follows the
    arms, and a lagging servo moves it (at the commanded tilts the cross term of a
    servo lag and the interference is left to neither). Both dimensionless.

    At small tilts it acts like a thrust-centre offset (a torque growing with
    the force and the tilt): on flights of one kind it is easily taken for a
    ``com_offset``; flights with large, varied tilts separate the two.
    On a vehicle of fixed rotors (``ctx.fixed_rotors``) the regressor is zero.
    """

    name = "rotor_interference"
    summary = "tilt-dependent thrust loss: wake of neighbouring pairs, wash on the arm"
    parameters = (
        Parameter("rotor_rotor", 1, "1", "thrust loss of a pair fully in a neighbour's wake"),
        Parameter("rotor_arm", 1, "1", "thrust loss of a pair tilted 90 deg over its arm"),
    )
    prior_std = 0.3
    theta_range = (0.0, 1.0)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        if ctx.fixed_rotors:  # the omav's tilting pairs only (never excited)
            return np.zeros((ctx.torque.shape[0], 3, 2))
        thrust = ctx.allocated[1]
        tilt = ctx.arm_tilt
        cols = []
        for shape in ctx.allocation.interference(tilt):
            rotor = np.repeat(thrust * shape / 2.0, 2, axis=-1)
            cols.append(-ctx.angular(ctx.allocation.forward(tilt, rotor)))
        return np.stack(cols, axis=-1)

    def configure_truth(self, params, truth):
        for key in ("rotor_rotor", "rotor_arm"):
            value = float(params[key][0])
            if not 0.0 <= value < 1.0:
                raise ConfigError(f"'effects.rotor_interference.{key}' must be in [0, 1)")
            setattr(truth, key, value)


def first_order_lag(setpoint: np.ndarray, time_constant: float, dt: float) -> np.ndarray:
    """Mean over each period of a first-order lag following held setpoints.

    setpoint (N, k) held over periods of ``dt``; the state starts at the first
    setpoint; ``x_{i+1} = a x_i + (1 - a) c_i`` with ``a = exp(-dt / T)``, and
    the mean over period i is ``c_i + (x_i - c_i) T (1 - a) / dt``. Exact for
    piecewise-constant setpoints; ``T <= 0`` returns the setpoints.
    """
    from scipy.signal import lfilter

    if time_constant <= 0:
        return setpoint.copy()
    a = math.exp(-dt / time_constant)
    c0 = setpoint[0]
    start = lfilter([0.0, 1.0 - a], [1.0, -a], setpoint - c0, axis=0) + c0  # x_i
    return setpoint + (start - setpoint) * (time_constant * (1.0 - a) / dt)


def shift_held(values: np.ndarray, delay: float, dt: float) -> np.ndarray:
    """Mean over each period of held ``values`` (N, k) delayed by ``delay`` s (signed).

    With ``delay = (q + f) dt`` (q integer, 0 <= f < 1) period i sees
    ``f values[i-q-1] + (1-f) values[i-q]``; indices beyond the ends take the
    edge values.
    """
    steps = delay / dt
    q = math.floor(steps)
    f = steps - q
    n = values.shape[0]
    idx = np.arange(n) - q
    a = values[np.clip(idx, 0, n - 1)]
    b = values[np.clip(idx - 1, 0, n - 1)]
    return (1.0 - f) * a + f * b
