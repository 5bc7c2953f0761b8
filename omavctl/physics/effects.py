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

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.vehicle import EFFECT_NAMES

if TYPE_CHECKING:
    from omavctl.physics.allocation import Allocation

__all__ = [
    "EFFECTS",
    "Effect",
    "EffectContext",
    "Parameter",
    "TruthConstants",
    "first_order_lag",
    "get_effect",
    "shift_held",
]


class TruthConstants(Protocol):
    """The constants of a truth plant an effect may change (:meth:`Effect.configure_truth`).

    The simulator's :class:`~omavctl.sim.truth.TruthParameters` is one; the
    physics does not depend on the simulator.
    """

    inertia: np.ndarray  # (3, 3) kg m^2
    servo_time_constant: float  # s
    motor_time_constant: float  # s
    command_delay: float  # s
    rotor_rotor: float  # thrust loss of a pair in a neighbour's wake
    rotor_arm: float  # thrust loss of a pair over its own tilted arm


@dataclass(frozen=True)
class Parameter:
    """One named parameter of an effect: ``size`` values in ``unit``."""

    name: str
    size: int
    unit: str
    description: str


@dataclass
class EffectContext:
    """The signals an effect's regressor may use, on a uniform grid.

    omega (N, 3) measured body rate rad/s; force (N, 3) commanded force N;
    torque (N, 3) commanded torque N m; omega_dot_nominal (N, 3) rad/s^2;
    dt grid step s; ``allocation`` the vehicle's allocation;
    ``derivative`` a callable differentiating (N, k) arrays along time
    (``fit`` passes its Savitzky-Golay derivative so that every signal is
    filtered alike). ``torque_normalised``: the torque command is in unknown
    units (vehicle ``command_units.torque: normalised``); ``torque`` is then
    that command, and ``inertia_error`` estimates its per-axis gain.
    """

    omega: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    omega_dot_nominal: np.ndarray
    inertia: np.ndarray
    dt: float
    allocation: Allocation
    derivative: Any
    torque_normalised: bool = False

    @property
    def inertia_inv(self) -> np.ndarray:
        return np.linalg.inv(self.inertia)

    @cached_property
    def allocated(self) -> tuple[np.ndarray, np.ndarray]:
        """Commanded tilts (N, 6) rad (unwrapped in time) and arm thrusts (N, 6) N."""
        wrench = np.concatenate([self.force, self.torque], axis=-1)
        res = self.allocation.allocate(wrench)
        return np.unwrap(res.tilt, axis=0), res.arm_thrust

    def angular(self, wrench_delta: np.ndarray) -> np.ndarray:
        """Angular acceleration (..., 3) caused by a body wrench change (..., 6)."""
        return wrench_delta[..., 3:] @ self.inertia_inv.T


class Effect(ABC):
    """Base class. Subclasses set ``name``, ``summary``, ``parameters`` and
    implement :meth:`regressor`."""

    name: ClassVar[str]
    summary: ClassVar[str]
    parameters: ClassVar[tuple[Parameter, ...]]
    #: Whether its parameters can be recovered from angular accelerations alone.
    identifiable: ClassVar[bool] = True
    #: Prior standard deviation of each estimation parameter theta in ``fit``'s
    #: joint effects + GP estimate: wide for what is physically plausible, so
    #: that a parameter the data do not excite stays near 0.
    prior_std: ClassVar[float]
    #: Physically plausible range of theta, used as bounds by ``evaluate``'s
    #: diagnosis (a missing effect must explain the error with possible values).
    theta_range: ClassVar[tuple[float, float]] = (-np.inf, np.inf)
    #: Search interval of the effect's one physical parameter when it enters the
    #: residual nonlinearly (time constants, delays): ``fit`` then estimates it
    #: exactly by a 1-D search over :meth:`exact` with the linear parameters of
    #: the other effects profiled out. None: linear in theta (least squares).
    #: The :meth:`regressor` of such an effect is its first-order linearisation
    #: (theta = the parameter), used by ``evaluate``'s diagnosis to detect it.
    search: ClassVar[tuple[float, float] | None] = None

    # --- estimation --------------------------------------------------------
    @property
    def n_theta(self) -> int:
        return sum(p.size for p in self.parameters)

    @abstractmethod
    def regressor(self, ctx: EffectContext) -> np.ndarray:
        """Regressor X, shape (N, 3, n_theta): residual ~= X @ theta."""

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Residual (N, 3) rad/s^2 of the exact nonlinear form at parameter ``value``.

        Per control period (commands held), before the Savitzky-Golay hold
        kernel. Only for effects with :attr:`search`.
        """
        raise NotImplementedError(f"{self.name} has no exact nonlinear form")

    def to_parameters(
        self, theta: np.ndarray, cov: np.ndarray
    ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Physical parameters and standard errors from ``theta`` (p,) and its covariance
        (p, p). Default: theta are the parameters."""
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        i = 0
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        for p in self.parameters:
            out[p.name] = (theta[i : i + p.size].copy(), se[i : i + p.size].copy())
            i += p.size
        return out

    def to_theta(self, params: dict[str, np.ndarray]) -> np.ndarray:
        """Inverse of :meth:`to_parameters` (values only)."""
        return np.concatenate(
            [np.atleast_1d(np.asarray(params[p.name], float)) for p in self.parameters]
        )

    # --- simulation (truth plant) -----------------------------------------
    def validate(self, params: Any, where: str = "effects") -> dict[str, np.ndarray]:
        """Check a parameter mapping from a YAML file; returns arrays per parameter."""
        if not isinstance(params, dict):
            raise ConfigError(f"'{where}.{self.name}' must map parameter names to values")
        names = {p.name: p for p in self.parameters}
        for key in params:
            if key not in names:
                raise ConfigError(
                    f"unknown parameter '{where}.{self.name}.{key}' (expected: {', '.join(names)})"
                )
        out = {}
        for p in self.parameters:
            if p.name not in params:
                raise ConfigError(f"missing parameter '{where}.{self.name}.{p.name}' ({p.unit})")
            try:
                arr = np.asarray(params[p.name], dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise ConfigError(f"'{where}.{self.name}.{p.name}' must be numbers") from None
            if arr.size != p.size or not np.all(np.isfinite(arr)):
                raise ConfigError(
                    f"'{where}.{self.name}.{p.name}' must be {p.size} finite number(s)"
                )
            out[p.name] = arr
        return out

    def body_torque(
        self, params: dict[str, np.ndarray], omega: np.ndarray, force: np.ndarray
    ) -> np.ndarray | None:
        """Extra torque (..., 3) N m on the true body; None if the effect adds none."""
        return None

    def configure_truth(  # noqa: B027 - optional hook, a no-op for most effects
        self, params: dict[str, np.ndarray], truth: TruthConstants
    ) -> None:
        """Change constants of the truth plant (inertia, actuator time constants)."""

    def gyro_offset(self, params: dict[str, np.ndarray]) -> np.ndarray | None:
        """Constant offset (3,) rad/s added to the measured body rate, or None."""
        return None


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


class ServoLag(Effect):
    """Tilt servos follow their setpoints with a first-order lag ``T_s``.

    ``alpha_dot = (alpha_cmd - alpha) / T_s`` gives ``alpha ~= alpha_cmd - T_s
    alpha_cmd_dot``, so the wrench error is ``-T_s J_alpha alpha_cmd_dot`` with
    ``J_alpha = d wrench / d alpha`` of the allocation; residual
    ``-T_s I^-1 [J_alpha alpha_cmd_dot]_torque``. ``T_s`` in s.
    """

    name = "servo_lag"
    summary = "first-order tilt-servo lag T_s"
    parameters = (Parameter("T_s", 1, "s", "servo time constant"),)
    prior_std = 0.05  # s
    theta_range = (0.0, 0.5)
    search = (0.0, 0.3)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        tilt, thrust = ctx.allocated
        rate = ctx.derivative(tilt)  # (N, 6)
        jac = ctx.allocation.tilt_jacobian(tilt, thrust)  # (N, 6, 6)
        dw = -np.einsum("nij,nj->ni", jac, rate)
        return ctx.angular(dw)[:, :, None]

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Tilts through the exact first-order lag of the held setpoints (period means)."""
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
    """

    name = "motor_lag"
    summary = "first-order rotor-thrust lag T_m"
    parameters = (Parameter("T_m", 1, "s", "motor time constant"),)
    prior_std = 0.05  # s
    theta_range = (0.0, 0.5)
    search = (0.0, 0.3)

    def regressor(self, ctx: EffectContext) -> np.ndarray:
        tilt, thrust = ctx.allocated
        rate = ctx.derivative(thrust)
        jac = ctx.allocation.thrust_jacobian(tilt)
        dw = -np.einsum("nij,nj->ni", jac, rate)
        return ctx.angular(dw)[:, :, None]

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Arm thrusts through the exact first-order lag of the held setpoints."""
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
    [A(alpha) (F sin^2 alpha)]_torque rotor_arm`` with the commanded tilts
    ``alpha`` and arm thrusts ``F`` of the allocation. Both dimensionless.

    At small tilts it acts like a thrust-centre offset (a torque growing with
    the force and the tilt): on flights of one kind it is easily taken for a
    ``com_offset``; flights with large, varied tilts separate the two.
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
        tilt, thrust = ctx.allocated
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
    )
}
if tuple(EFFECTS) != EFFECT_NAMES:  # the description's names and the registry agree
    raise ImportError(f"effect registry {tuple(EFFECTS)} != vehicle.EFFECT_NAMES {EFFECT_NAMES}")


def get_effect(name: str) -> Effect:
    """Look up an effect by name; ConfigError listing the known ones otherwise."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise ConfigError(
            f"unknown effect '{name}' (known: {', '.join(sorted(EFFECTS))})"
        ) from None
