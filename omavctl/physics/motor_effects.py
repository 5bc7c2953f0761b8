"""Motor-level effects: the thrust curve's curvature, one weak motor, battery sag, and
the omav's arms that push unequally.

They act on each rotor's thrust before the rotor list mixes it
(:mod:`omavctl.physics.mixer`), so they need a log whose wrench was computed from
its motor outputs (:class:`~omavctl.physics.effect_base.MotorSignals`) or, for
``battery_sag``, its battery voltage. Without those signals their regressor is
zero (the diagnosis never names them) and ``fit --effects`` refuses them in one
line (:meth:`Effect.unavailable`). Part of the registry
:data:`omavctl.physics.effects.EFFECTS` (formulas in the class docstrings and
``docs/effects.md``). The simulator hides them in the omav's rotors
(:meth:`Effect.configure_truth` sets the truth plant's constants; the plant bends,
scales and sags each rotor's thrust); its logs carry the rotor speeds and the
battery voltage they need, mixed by the ``omav-rotors`` preset.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.physics.effect_base import Effect, EffectContext, Parameter

__all__ = [
    "ARMS",
    "MAX_LOSS_ROTORS",
    "ArmThrust",
    "BatterySag",
    "MotorLoss",
    "ThrustCurve",
    "loss_contrasts",
    "rotor_residuals",
]


def rotor_residuals(
    thrust: np.ndarray, torque_of: Callable[[np.ndarray], np.ndarray], inertia_inv: np.ndarray
) -> np.ndarray:
    """Angular acceleration (N, 3, R) of each rotor's thrust alone: ``I^-1
    torque_of(T e_i)`` for the thrusts (N, R), every other rotor's zeroed
    (``torque_of``, (N, R) -> (N, 3) N m, linear in the thrusts)."""
    out = np.empty((thrust.shape[0], 3, thrust.shape[1]))
    for i in range(thrust.shape[1]):
        one = np.zeros_like(thrust)
        one[:, i] = thrust[:, i]
        out[:, :, i] = torque_of(one) @ inertia_inv.T
    return out


#: Rotors ``motor_loss`` has a parameter for (the omav's 12, an octo-X's, a coaxial X8's).
MAX_LOSS_ROTORS = 12

#: |theta| at or below which a ``motor_loss`` contrast counts as never excited.
_UNEXCITED = 1e-12

_NEED_MOTORS = (
    "needs a log of motor outputs mixed by the vehicle's rotor list "
    "(motors: in the vehicle, motor_command in the log)"
)


def _within(params: dict[str, np.ndarray], name: str, key: str, lo: float, hi: float) -> None:
    if np.any(params[key] < lo) or np.any(params[key] > hi):
        raise ConfigError(f"'effects.{name}.{key}' must lie in {lo:g} to {hi:g}")


class ThrustCurve(Effect):
    """Curvature of the command-to-thrust map beyond the rotor list's polynomial.

    Each rotor's thrust is ``T_i(x_i) + c T_i^full (x_i^2 - x_i)``, with ``x_i`` the
    command value (0..1 over the rotor's ``range``), ``T_i`` its curve and
    ``T_i^full = T_i(1) - T_i(0)``: the thrust at zero and full command is kept,
    ``c`` bends the curve between (shared by the rotors; PX4's ``THR_MDL_FAC``
    form: a curve ``k x^2`` becomes ``k ((1 + c) x^2 - c x)``, ``c = -1`` linear).
    Residual ``c I^-1 tau(T^full (x^2 - x))`` with ``tau(.)`` the rotor list's torque of
    per-rotor thrusts. Dimensionless. Identifiable when the collective thrust
    varies: at one operating point the bend is a gain change (``inertia_error``'s).
    Rotors whose command has no range (rad/s, rpm) are not bent.
    """

    name = "thrust_curve"
    summary = "curvature c of the command-to-thrust map (shared by the rotors)"
    parameters = (Parameter("c", 1, "1", "curvature beyond the curve: c (x^2 - x) T_full"),)
    prior_std = 0.5
    theta_range = (-1.0, 1.0)
    simulated = False  # hidden by the plant; not drawn (see Effect.simulated)
    look_alikes = (
        "a per-axis torque gain (inertia_error) where the collective thrust barely changes"
    )

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        motor = ctx.motor
        if motor is None:
            return np.zeros((ctx.torque.shape[0], 3, 1))
        x = motor.motors.fractions(motor.values)
        shape = motor.motors.full_thrust()[None, :] * (x * x - x)
        return (motor.torque(shape) @ ctx.inertia_inv.T)[:, :, None]

    def unavailable(self, ctx: EffectContext) -> str | None:
        if ctx.motor is None:
            return f"{self.name} {_NEED_MOTORS}"
        if not np.any(ctx.motor.motors.full_thrust() != 0):
            return (
                f"{self.name} needs rotors whose command has a range (pwm_us, dshot, pwm16, "
                "normalised, or a speed unit with range: [0, full speed]); these rotors run "
                "on speeds without one"
            )
        return None

    def configure_truth(self, params, truth):
        _within(params, self.name, "c", -1.0, 1.0)
        truth.thrust_curvature = float(params["c"][0])


def loss_contrasts(size: int = MAX_LOSS_ROTORS) -> np.ndarray:
    """Helmert contrasts (size, size): column 0 zero, column j (1 <= j < size)
    ``(1, ..., 1, -j, 0, ..., 0) / sqrt(j (j + 1))`` (j ones). Orthonormal, each sums
    to zero, and column j touches rotors 0..j only: for a vehicle of R rotors,
    columns 1..R-1 span exactly the losses that differ between its rotors."""
    h = np.zeros((size, size))
    for j in range(1, size):
        h[:j, j] = 1.0
        h[j, j] = -float(j)
        h[:, j] /= np.sqrt(j * (j + 1.0))
    return h


def contrast_values(h: np.ndarray, theta: Any, cov: Any) -> tuple[np.ndarray, np.ndarray]:
    """Values ``h theta`` (size,) and their standard errors of Helmert contrasts
    ``theta`` with covariance ``cov``: a contrast no regressor excites (the common part,
    rotors or arms the vehicle lacks) stays at its prior mean 0 with the prior's
    variance, which is not a loss or a gain, so it carries nothing into them."""
    excited = np.abs(np.asarray(theta, float)) > _UNEXCITED
    t = np.where(excited, np.asarray(theta, float), 0.0)
    c = np.where(np.outer(excited, excited), np.asarray(cov, float), 0.0)
    return h @ t, np.sqrt(np.clip(np.diag(h @ c @ h.T), 0.0, None))


class MotorLoss(Effect):
    """Per-motor thrust loss relative to the rotors' mean: rotor i delivers
    ``(1 - lbar - l_i)`` of its curve's thrust, ``sum_i l_i = 0``.

    A loss shared by every rotor (``lbar``) scales the whole wrench: it is a torque
    gain (``inertia_error``'s), not a weak motor, and cannot be told from one. So
    ``l`` are the losses *relative to their mean* over the vehicle's rotors, estimated
    as Helmert contrasts ``theta`` (:func:`loss_contrasts`, ``l = H theta``): column j
    of the regressor is ``-sum_i H_ij I^-1 tau(e_i T_i)`` for 1 <= j < R (``T_i`` the
    rotor's thrust from its command, ``tau(.)`` the rotor list's torque), and zero for
    j = 0 (the common loss) and j >= R, which are never excited. Fit it with
    ``inertia_error`` when the rotors' mean loss is not 0 (one weak motor lowers the
    mean too): left out, the common part biases ``l`` by about ``lbar l_i``. A component of theta
    that is exactly 0 was not excited and carries no variance into ``l``. ``l`` has
    :data:`MAX_LOSS_ROTORS` entries in the rotor list's order; entries beyond the
    vehicle's rotors stay 0. Dimensionless. On a quadrotor near hover one weak motor
    is a constant torque, which a centre-of-mass offset (``com_offset``) also leaves
    on roll and pitch: they are told apart only where the thrusts vary independently.
    """

    name = "motor_loss"
    summary = "per-motor thrust loss l_i relative to the rotors' mean (one weak motor)"
    parameters = (
        Parameter(
            "l", MAX_LOSS_ROTORS, "1", "thrust lost by each rotor beyond the rotors' mean loss"
        ),
    )
    prior_std = 0.2
    theta_range = (-0.5, 0.5)
    parameter_range = (-0.5, 0.5)
    simulated = False  # hidden by the plant; not drawn (see Effect.simulated)
    look_alikes = (
        "a centre-of-mass offset (com_offset: a constant roll/pitch torque near hover); "
        "a loss shared by the rotors is a torque gain (inertia_error), not a motor_loss"
    )

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        n = ctx.torque.shape[0]
        out = np.zeros((n, 3, MAX_LOSS_ROTORS))
        motor = ctx.motor
        rotors = 0 if motor is None else motor.thrust.shape[1]
        if motor is None or not 2 <= rotors <= MAX_LOSS_ROTORS:
            return out
        each = -rotor_residuals(motor.thrust, motor.torque, ctx.inertia_inv)
        out[:, :, 1:rotors] = each @ loss_contrasts()[:rotors, 1:rotors]
        return out

    def unavailable(self, ctx: EffectContext) -> str | None:
        if ctx.motor is None:
            return f"{self.name} {_NEED_MOTORS}"
        rotors = ctx.motor.thrust.shape[1]
        if rotors > MAX_LOSS_ROTORS:
            return f"{self.name} covers at most {MAX_LOSS_ROTORS} rotors; the vehicle has {rotors}"
        if rotors < 2:
            return f"{self.name} needs two rotors or more: one rotor's loss is a gain"
        return None

    #: l beyond the vehicle's rotors is never excited: those rotors do not exist
    absent_when_unexcited = ("l",)

    def excited_parameters(self, excited: np.ndarray) -> np.ndarray:
        """l_i is determined where a contrast that touches rotor i was excited: on a
        quad contrasts 1..3 give l_0 .. l_3 (l_0 = -(l_1 + l_2 + l_3)); the common
        contrast 0 is never excited and l_4 .. l_11 are rotors it lacks. (The flags of
        the contrasts were read as l's: "not excited: l_0", eyes6.)"""
        touches = (np.abs(loss_contrasts()) > 0).astype(int)
        return np.asarray(touches @ np.asarray(excited, bool).astype(int) > 0)

    def to_parameters(self, theta, cov):
        return {"l": contrast_values(loss_contrasts(), theta, cov)}

    def to_theta(self, params):
        return loss_contrasts().T @ np.asarray(params["l"], float).reshape(-1)

    def configure_truth(self, params, truth):
        # in the truth plant l is each of the omav's 12 rotors' own loss (absolute)
        _within(params, self.name, "l", -0.5, 0.9)
        truth.rotor_loss = np.asarray(params["l"], float).copy()


class BatterySag(Effect):
    """Thrust that follows the battery voltage: ``T_true = T (1 + k (V - V_ref))``.

    ``V`` the logged battery voltage (role ``battery_voltage``, V), ``V_ref`` its
    median over the log: a constant thrust change is the torque gain's
    (``inertia_error``), what ``k`` adds is the change along the flight as the
    battery sags. The mixer is linear in the thrusts, so the residual is
    ``k (V - V_ref) I^-1 tau_cmd``. ``k`` in 1/V (about ``2 / V`` for a motor
    whose thrust goes with the voltage squared; near 0 when the flight controller
    compensates, Betaflight's ``vbat_pid_compensation``). Identifiable when the
    voltage changes while the torque command does: a flight long enough to sag.
    """

    name = "battery_sag"
    summary = "thrust scaling k with the battery voltage (about its median)"
    parameters = (Parameter("k", 1, "1/V", "relative thrust change per volt"),)
    prior_std = 0.5  # 1/V
    theta_range = (-1.0, 2.0)
    simulated = False  # hidden by the plant; not drawn (see Effect.simulated)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        v = ctx.battery_voltage
        if v is None:
            return np.zeros((ctx.torque.shape[0], 3, 1))
        dv = np.asarray(v, float).reshape(-1) - ctx.battery_reference
        return (dv[:, None] * (ctx.torque @ ctx.inertia_inv.T))[:, :, None]

    def unavailable(self, ctx: EffectContext) -> str | None:
        if ctx.battery_voltage is None:
            return (
                f"{self.name} needs the battery voltage: map the log's voltage column "
                "(e.g. Betaflight's vbatLatest) to battery_voltage in the vehicle's columns:"
            )
        return None

    def configure_truth(self, params, truth):
        _within(params, self.name, "k", -1.0, 2.0)
        truth.battery_sag = float(params["k"][0])


#: The omav's arms (one tilting coaxial pair each): ``arm_thrust`` has a gain per arm.
ARMS = 6


class ArmThrust(Effect):
    """Thrust of each tilting arm's rotor pair beyond the arms' mean: arm j delivers
    ``(1 + gbar + g_j)`` of its commanded thrust, ``sum_j g_j = 0``.

    No two rotors of a batch push alike (the vehicle's ``rotor.thrust_tolerance``), so
    no two of the omav's arms do: each pair's thrust is off by the mean of its two
    rotors' errors. The torque that leaves follows the arm's thrust *and tilt*: near
    hover a roll/pitch torque (what a ``com_offset`` also leaves), and as the arms tilt
    to push sideways a yaw torque ``L T_j sin(alpha_j)`` that no centre-of-mass offset
    gives (the roll/pitch torques pin ``r_x``, ``r_y`` while the yaw wants other
    values). A gain shared by the arms (``gbar``) scales the whole wrench: the torque
    gain of ``inertia_error``, not a spread; so ``g`` are the gains relative to their
    mean, estimated as Helmert contrasts (:func:`loss_contrasts`, ``g = H theta``):
    column j of the regressor is ``sum_i H_ij I^-1 tau(e_i F_i)`` for 1 <= j < 6
    (``F_i`` the arm's thrust, ``tau`` the torque of the arm's pair at the tilts where
    the arms are, the pair split equally), and zero for j = 0. Dimensionless.

    Identifiable when the arms' thrusts and tilts vary apart (attitude manoeuvres that
    tilt the arms); near hover only the five gains' roll/pitch torques show, which a
    ``com_offset`` takes as well. The two rotors of a pair push along one axis, so a
    spread *within* a pair is left to ``motor_loss`` on a rotor list's log. Needs the
    omav's tilting arms and a wrench command in physical units (the allocation gives
    the arms' thrusts): a vehicle of fixed rotors gets zeros (``motor_loss`` is its
    form).
    """

    name = "arm_thrust"
    summary = "thrust gain g_j of each arm's rotor pair relative to the arms' mean (spread)"
    parameters = (
        Parameter("g", ARMS, "1", "thrust of each arm's pair beyond the arms' mean (fraction)"),
    )
    prior_std = 0.03  # the default vehicle's thrust tolerance: a batch's spread
    theta_range = (-0.5, 0.5)
    parameter_range = (-0.5, 0.5)
    simulated = False  # the plant's spread is every draw's; not drawn (see Effect.simulated)
    diagnosed = False  # fit --effects only: in the pool it took a drag's claim (docs)
    look_alikes = (
        "a centre-of-mass offset (com_offset: a roll/pitch torque near hover) and the "
        "rotors' interference (rotor_interference: a per-arm thrust loss with the tilts); "
        "a gain shared by the arms is a torque gain (inertia_error)"
    )

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        n = ctx.torque.shape[0]
        out = np.zeros((n, 3, ARMS))
        if self.unavailable(ctx) is not None:
            return out
        tilt, arm = ctx.arm_tilt, ctx.allocated[1]
        if arm.shape[-1] != ARMS:
            return out
        pair = np.repeat(arm / 2.0, 2, axis=-1)  # (n, 12): the pair split equally
        each = np.empty((n, 3, ARMS))
        for j in range(ARMS):
            one = np.zeros_like(pair)
            one[:, 2 * j : 2 * j + 2] = pair[:, 2 * j : 2 * j + 2]
            each[:, :, j] = ctx.angular(ctx.allocation.forward(tilt, one))
        out[:, :, 1:] = each @ loss_contrasts(ARMS)[:, 1:]
        return out

    def unavailable(self, ctx: EffectContext) -> str | None:
        if ctx.fixed_rotors:
            return (
                f"{self.name} needs the omav's tilting arms; a rotor list of fixed rotors "
                "has motor_loss for its motors"
            )
        if ctx.torque_normalised or ctx.allocation.vehicle.force_normalised:
            return (
                f"{self.name} needs the wrench command in N and N m: the arms' thrusts are "
                "allocated from it"
            )
        return None

    def excited_parameters(self, excited: np.ndarray) -> np.ndarray:
        """g_j is determined where a contrast that touches arm j was excited (the
        common contrast 0 never is)."""
        touches = (np.abs(loss_contrasts(ARMS)) > 0).astype(int)
        return np.asarray(touches @ np.asarray(excited, bool).astype(int) > 0)

    def to_parameters(self, theta, cov):
        return {"g": contrast_values(loss_contrasts(ARMS), theta, cov)}

    def to_theta(self, params):
        return loss_contrasts(ARMS).T @ np.asarray(params["g"], float).reshape(-1)

    def configure_truth(self, params, truth):
        # in the truth plant each arm's two rotors lose -g_j (on top of any motor_loss)
        _within(params, self.name, "g", -0.5, 0.5)
        truth.rotor_loss = truth.rotor_loss - np.repeat(np.asarray(params["g"], float), 2)
