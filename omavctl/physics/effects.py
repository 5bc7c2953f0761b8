"""Registry of named physical effects (DESIGN.md section 2).

Each effect is one small class: a name, parameters with units, a docstring
with its formula, a **regressor** (the angular-acceleration residual it causes
is linear in its estimation parameters ``theta``, so ``fit`` and ``evaluate``
estimate it by least squares) and a **simulation form** used by the truth
plant (an extra body torque, a change of plant constants, or a sensor error).

The residual is ``omega_dot_measured - I^-1 (tau_cmd - omega x I omega)``;
for each effect ``residual ~= X(theta)`` with ``X = regressor(ctx)`` of shape
(N, 3, p).  To add an effect, subclass :class:`Effect` and add an instance to
:data:`EFFECTS` (see ``docs/adding-an-effect.md``).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.physics.actuator_effects import (
    CommandDelay,
    MotorLag,
    RotorInterference,
    ServoLag,
    first_order_lag,
    shift_held,
)
from omavctl.physics.effect_base import Effect, EffectContext, Parameter, TruthConstants
from omavctl.physics.motor_effects import ArmThrust, BatterySag, MotorLoss, ThrustCurve
from omavctl.vehicle import EFFECT_NAMES

__all__ = [
    "EFFECTS",
    "SIMULATED_EFFECTS",
    "Effect",
    "EffectContext",
    "Parameter",
    "TruthConstants",
    "first_order_lag",
    "get_effect",
    "shift_held",
]


class RotationalDrag(Effect):
    """Aerodynamic drag torque, quadratic in the body rate.

    ``tau_drag = -D omega |omega|`` (element-wise, D diagonal), hence the residual
    ``-I^-1 D omega |omega|``. ``D`` in N m s^2 (per rad^2).
    """

    name = "rotational_drag"
    summary = "aerodynamic drag torque -D omega|omega|"
    parameters = (Parameter("D", 3, "N m s^2", "diagonal drag coefficients"),)
    prior_std = 0.1  # N m s^2
    theta_range = (0.0, 1.0)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        q = ctx.omega * np.abs(ctx.omega)  # (N, 3)
        return -ctx.inertia_inv[None, :, :] * q[:, None, :]

    def body_torque(self, params, omega, force):
        return -params["D"] * omega * np.abs(omega)


class ComOffset(Effect):
    """Centre of mass displaced by ``r`` from the geometric centre the allocation assumes.

    Forces act at the geometric centre, so about the true centre of mass they
    add ``tau = r x f`` (``f`` body force); residual ``I^-1 (r x f)``. ``r`` in m,
    body frame. Identifiable when the body-frame force changes direction
    (attitude manoeuvres of an omav, lateral force commands).
    """

    name = "com_offset"
    summary = "centre of mass offset r: extra torque r x f"
    parameters = (Parameter("r", 3, "m", "centre-of-mass offset, body frame"),)
    prior_std = 0.05  # m
    theta_range = (-0.2, 0.2)
    look_alikes = (
        "a thrust spread between the rotors and the rotors' interference at small tilts "
        "(rotor_interference), which also shift where the thrust acts"
    )
    unexcited_why: ClassVar[dict[str, str]] = {
        "r_z": "only a force along x or y shows it, which a multirotor's thrust along z "
        "never gives",
    }

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        eye = np.eye(3)
        # column j: I^-1 (e_j x f)
        cols = [np.cross(eye[j], ctx.force) @ ctx.inertia_inv.T for j in range(3)]
        return np.stack(cols, axis=-1)

    def body_torque(self, params, omega, force):
        return np.cross(params["r"], force)


class InertiaError(Effect):
    """True inertia ``I_true = diag(scale) I`` differs from the nominal one.

    ``omega_dot_k = (tau - omega x I_true omega)_k / (scale_k I_k)``. To first
    order the residual is ``theta_k * omega_dot_nominal_k`` with
    ``theta_k = 1/scale_k - 1`` (estimated linearly; ``scale = 1/(1+theta)``,
    standard error by the delta method).

    It also estimates the gain of a normalised torque command (units unknown,
    ``ctx.torque_normalised``): the body torque is ``diag(g) tau_cmd``, so the
    residual is ``I^-1 diag(theta) tau_cmd`` with ``g = 1 + theta = 1/scale``.
    The regressor is then ``I^-1 e_k tau_k`` without the gyroscopic term, which
    is in physical units whatever the command's.
    """

    name = "inertia_error"
    summary = "true/nominal inertia scale per axis"
    parameters = (Parameter("scale", 3, "1", "true/nominal inertia per axis"),)
    prior_std = 0.5  # theta = 1/scale - 1
    theta_range = (-0.5, 1.0)  # true inertia within half and twice the nominal

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        if ctx.torque_normalised:
            # column k: I^-1 e_k tau_k
            return ctx.inertia_inv[None, :, :] * ctx.torque[:, None, :]
        return np.eye(3)[None, :, :] * ctx.omega_dot_nominal[:, None, :]

    def to_parameters(self, theta, cov):
        scale = 1.0 / (1.0 + theta)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None)) * scale**2
        return {"scale": (scale, se)}

    def to_theta(self, params):
        return 1.0 / np.asarray(params["scale"], float) - 1.0

    def configure_truth(self, params, truth):
        if np.any(params["scale"] <= 0):
            raise ConfigError("'effects.inertia_error.scale' must be > 0")
        s = np.sqrt(params["scale"])
        truth.inertia = s[:, None] * truth.inertia * s[None, :]


class GyroBias(Effect):
    """Constant bias ``b`` in the measured body rate: ``omega_meas = omega + b``.

    It leaves ``omega_dot`` unchanged; it enters the residual only through the
    gyroscopic term evaluated with the biased rate,
    ``I^-1 (b x I omega + omega x I b)`` to first order, which is small at the
    rates an omav flies: not identifiable from angular accelerations (its
    visible trace is a steady attitude offset ``Kd b / Kp`` of the controller).
    """

    name = "gyro_bias"
    summary = "constant gyro bias b"
    parameters = (Parameter("b", 3, "rad/s", "gyro bias, body frame"),)
    prior_std = 0.05  # rad/s
    theta_range = (-0.2, 0.2)
    identifiable = False

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        eye = np.eye(3)
        i_omega = ctx.omega @ ctx.inertia.T
        cols = [
            (np.cross(eye[j], i_omega) + np.cross(ctx.omega, ctx.inertia[:, j])) @ ctx.inertia_inv.T
            for j in range(3)
        ]
        return np.stack(cols, axis=-1)

    def gyro_offset(self, params):
        return params["b"]


class DragMoment(Effect):
    """Moment of the force the accelerometer measures, acting ``h`` above the centre of mass.

    A moving multirotor's rotors feel a horizontal drag (and their blades flap
    with it) at the rotor plane, above the centre of mass; the accelerometer
    measures that force (gravity is not a specific force). With ``f = m a_meas``
    (N; ``a_meas`` the ``specific_force`` role less its median over the log, the
    accelerometer's offset, and less its lever-arm term ``alpha x r + omega x (omega x r)``
    where the log pins ``r`` down, :mod:`omavctl.learn.imu_lever`) the torque is
    ``tau = h e_z x f = h (-f_y, f_x, 0)``;
    residual ``I^-1 tau``; ``h`` in m (in the torque command's unit per N when it is
    normalised). ``com_offset``'s ``r_z`` on the measured, not the commanded, force.
    Identifiable from roll and pitch accelerations when the lateral measured force
    varies (a multirotor flying about); needs a log with an accelerometer. An
    open-loop rollout (``measured_state``) rolls the lateral force forward from the
    rolled-out attitude where the log has one (:mod:`omavctl.learn.rollout_force`),
    else holds it at the window's start.
    """

    name = "drag_moment"
    summary = "moment h e_z x f of the measured (accelerometer) force"
    parameters = (Parameter("h", 1, "m", "height above the centre of mass it acts at"),)
    prior_std = 0.05  # m
    theta_range = (-0.2, 0.2)
    simulated = False  # the plant logs no accelerometer
    measured_state = True
    look_alikes = "a lateral drag at the rotor plane and the blades' flapping alike"

    def unavailable(self, ctx: EffectContext) -> str | None:
        if ctx.measured_force is None:
            return (
                f"{self.name} needs the accelerometer: map the log's specific force "
                "(m/s^2, body) as the specific_force role (docs/logs.md)"
            )
        return None

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        if ctx.measured_force is None:
            return np.zeros((ctx.omega.shape[0], 3, 1))
        f = ctx.measured_force
        tau = np.stack([-f[:, 1], f[:, 0], np.zeros_like(f[:, 0])], axis=-1)
        return (tau @ ctx.inertia_inv.T)[:, :, None]

    def body_torque(self, params, omega, force):
        f = np.asarray(force, dtype=float)
        h = float(params["h"][0])
        return h * np.stack([-f[..., 1], f[..., 0], np.zeros_like(f[..., 0])], axis=-1)


#: All registered effects by name; CLI choices are derived from this.
EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        RotationalDrag(),
        ComOffset(),
        InertiaError(),
        ServoLag(),
        MotorLag(),
        CommandDelay(),
        GyroBias(),
        RotorInterference(),
        ThrustCurve(),
        MotorLoss(),
        BatterySag(),
        DragMoment(),
        ArmThrust(),
    )
}
if tuple(EFFECTS) != EFFECT_NAMES:  # the description's names and the registry agree
    raise ImportError(f"effect registry {tuple(EFFECTS)} != vehicle.EFFECT_NAMES {EFFECT_NAMES}")

#: The effects a benchmark may draw as hidden (``simulated``), in registry order. The
#: truth plant hides every registered effect; the motor-level ones act on the rotors'
#: thrusts, which ``fit`` sees only with a rotor list mixing the log's rotor speeds
#: (``preset: omav-rotors``), not with the default vehicle of the scorecard's loop.
SIMULATED_EFFECTS: tuple[str, ...] = tuple(n for n, e in EFFECTS.items() if e.simulated)


def get_effect(name: str) -> Effect:
    """Look up an effect by name; ConfigError listing the known ones otherwise."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise ConfigError(
            f"unknown effect '{name}' (known: {', '.join(sorted(EFFECTS))})"
        ) from None
