"""The base of every physical effect: parameters, the signals a regressor sees, the class.

:mod:`omavctl.physics.effects` holds the registry; the effects themselves are
there (body effects) and in :mod:`omavctl.physics.actuator_effects` (timing and
actuator effects).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

from omavctl.base.errors import ConfigError

if TYPE_CHECKING:
    from omavctl.physics.allocation import Allocation

__all__ = ["Effect", "EffectContext", "MotorSignals", "Parameter", "TruthConstants"]


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
    thrust_curvature: float  # c of thrust_curve: each rotor's thrust bent by c (T - sqrt(T T_full))
    rotor_loss: np.ndarray  # (12,) fraction of each rotor's thrust lost (motor_loss)
    battery_sag: float  # 1/V, relative thrust change per volt about the nominal voltage


@dataclass(frozen=True)
class Parameter:
    """One named parameter of an effect: ``size`` values in ``unit``."""

    name: str
    size: int
    unit: str
    description: str


@dataclass(frozen=True)
class MotorSignals:
    """Per-rotor signals of a log whose wrench the vehicle's rotor list mixed from its
    motor outputs (:mod:`omavctl.physics.mixer`), for the motor-level effects.

    ``motors`` the rotor list (:class:`omavctl.rotors.Motors`); ``values`` (N, R)
    the command values its thrust curves take (clipped at 0); ``thrust`` (N, R) N
    (in the torque command's unit when it is normalised); ``tilt`` (N, 6) rad of
    rotors on tilt servos, or None.
    """

    motors: Any
    values: np.ndarray
    thrust: np.ndarray
    tilt: np.ndarray | None = None

    def torque(self, thrust_delta: np.ndarray) -> np.ndarray:
        """Body torque (N, 3) of per-rotor thrust changes (N, R)."""
        return np.asarray(self.motors.wrench(thrust_delta, self.tilt)[1])


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
    ``fixed_rotors``: the vehicle is a rotor list without tilt servos
    (``motors:``, :mod:`omavctl.rotors`): its wrench is linear in the rotor
    thrusts, and the omav's allocation (tilts, arm thrusts) does not apply.
    ``motor``: the per-rotor signals when the wrench was mixed from motor outputs
    (:class:`MotorSignals`), else None (the motor-level effects are then not
    excited). ``battery_voltage`` (N,) V and ``battery_reference`` V (the log's
    median voltage) when the log maps ``battery_voltage``, else None.
    ``measured_force`` (N, 3) N: the body force the accelerometer measures (the
    vehicle's mass times the ``specific_force`` role, less its median over the log's
    valid samples: the accelerometer's calibration offset, and less the accelerometer's
    lever-arm term where the log pins it down: ``omavctl.learn.imu_lever``) when the log
    maps ``specific_force``, else None. ``measured_tilt`` (N, 6) rad: the arms' tilts
    the log records (role ``tilt``: where the servos are, not where they were told to
    go), else None.
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
    fixed_rotors: bool = False
    motor: MotorSignals | None = None
    battery_voltage: np.ndarray | None = None
    battery_reference: float = 0.0
    measured_force: np.ndarray | None = None
    measured_tilt: np.ndarray | None = None

    @property
    def inertia_inv(self) -> np.ndarray:
        return np.linalg.inv(self.inertia)

    @cached_property
    def allocated(self) -> tuple[np.ndarray, np.ndarray]:
        """Commanded tilts (N, 6) rad (unwrapped in time) and arm thrusts (N, 6) N."""
        wrench = np.concatenate([self.force, self.torque], axis=-1)
        res = self.allocation.allocate(wrench)
        return np.unwrap(res.tilt, axis=0), res.arm_thrust

    @cached_property
    def arm_tilt(self) -> np.ndarray:
        """Where the arms are (N, 6) rad while sample i's command acts: the measured tilts
        of sample i + 1 (the last sample keeps its own) on the commanded tilts' branch
        (within pi of them) when the log records them, else the commanded tilts.

        A tilt logged at t_i is where the arms were when command i was sent; over the
        period that command acts the arms move towards it, and a servo faster than the
        log period is nearly there by t_(i+1). Measured (docs/effects.md,
        ``rotor_interference``): at the truth's coefficients the interference's
        regressor left x 0.038, y 0.066 rad/s^2 of a figure-8 with the tilts of sample i
        and 0.022, 0.022 (the noise) with those of i + 1, at the midpoint 0.026, 0.035."""
        commanded = self.allocated[0]
        if self.measured_tilt is None:
            return commanded
        ahead = np.concatenate([self.measured_tilt[1:], self.measured_tilt[-1:]])
        gap = (ahead - commanded + np.pi) % (2.0 * np.pi) - np.pi
        return np.asarray(commanded + gap)

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
    #: Plausible range of every physical parameter value when theta is not the
    #: parameters component by component (``motor_loss``'s contrasts); None: the
    #: range follows from ``theta_range`` through :meth:`to_parameters`.
    parameter_range: ClassVar[tuple[float, float] | None] = None
    #: Search interval of the effect's one physical parameter when it enters the
    #: residual nonlinearly (time constants, delays): ``fit`` then estimates it
    #: exactly by a 1-D search over :meth:`exact` with the linear parameters of
    #: the other effects profiled out. None: linear in theta (least squares).
    #: The :meth:`regressor` of such an effect is its first-order linearisation
    #: (theta = the parameter), used by ``evaluate``'s diagnosis to detect it.
    search: ClassVar[tuple[float, float] | None] = None
    #: What else leaves a residual of this effect's shape (for the verdict to say
    #: when it names the effect); empty when nothing common does.
    look_alikes: ClassVar[str] = ""
    #: Whether a benchmark's draws may hide it (``SIMULATED_EFFECTS``): the truth plant
    #: hides every registered effect, but the motor-level ones (False) act on the
    #: rotors' thrusts and ``fit`` sees them only through a rotor list that mixes the
    #: log's rotor speeds (``preset: omav-rotors``), not with the default vehicle the
    #: scorecard's loop uses.
    simulated: ClassVar[bool] = True
    #: Whether ``evaluate``'s diagnosis considers it (False: ``fit --effects`` only). An
    #: effect of many confounded parameters whose look-alikes the diagnosis already
    #: names can take a real effect's claim from it (``arm_thrust``: docs/effects.md).
    diagnosed: ClassVar[bool] = True
    #: Whether its regressor reads a measured state the angular rollout does not predict
    #: (the accelerometer's force): an open-loop rollout holds it at the window's start
    #: (:mod:`omavctl.learn.rollout_residual`) instead of reading the window's future.
    measured_state: ClassVar[bool] = False
    #: Parameters of which a component no flight excites is one the vehicle does not
    #: have (``motor_loss``'s ``l`` beyond its rotors): left out where shown, not named
    #: "not excited" (a quad's report listed l_4 .. l_11).
    absent_when_unexcited: ClassVar[tuple[str, ...]] = ()
    #: Why a component (its label, "r_z") may stay unexcited, said beside it.
    unexcited_why: ClassVar[dict[str, str]] = {}

    # --- estimation --------------------------------------------------------
    @property
    def n_theta(self) -> int:
        return sum(p.size for p in self.parameters)

    @abstractmethod
    def regressor(self, ctx: EffectContext) -> np.ndarray:
        """Regressor X, shape (N, 3, n_theta): residual ~= X @ theta."""

    def unavailable(self, ctx: EffectContext) -> str | None:
        """Why ``fit`` cannot estimate this effect from a log with these signals (one
        phrase naming what is missing), or None when it can. The diagnosis needs no
        such check: a regressor of zeros is never excited."""
        return None

    def exact(self, ctx: EffectContext, value: float) -> np.ndarray:
        """Residual (N, 3) rad/s^2 of the exact nonlinear form at parameter ``value``.

        Per control period (commands held), before the Savitzky-Golay hold
        kernel. Only for effects with :attr:`search`.
        """
        raise NotImplementedError(f"{self.name} has no exact nonlinear form")

    def excited_parameters(self, excited: np.ndarray) -> np.ndarray:
        """Which parameter components (bool, concatenated in :attr:`parameters` order) an
        estimate whose theta components ``excited`` (bool (n_theta,)) were excited
        determines. Default: theta are the parameters."""
        return np.asarray(excited, bool).copy()

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

    def null_parameters(self) -> dict[str, np.ndarray]:
        """Each parameter's value (size,) at which the effect is absent: its null
        (theta 0 through :meth:`to_parameters`: inertia scale 1; lags, delays, drag,
        offsets, biases, interference 0). A claim that the effect is present needs an
        interval that excludes it (``omavctl.diagnose.claims``)."""
        zero = np.zeros(self.n_theta)
        return {
            k: np.asarray(v, float)
            for k, (v, _) in self.to_parameters(zero, np.zeros((zero.size, zero.size))).items()
        }

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
