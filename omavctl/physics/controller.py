"""Model-based controller of DESIGN.md section 2 with a pluggable residual model.

Position loop (world): ``a_lin* = a_ref + Kd_p (v_ref - v) + Kp_p (p_ref - p) + Ki_p int``
and body force ``f = m R^T (a_lin* + g e_z)``.

Attitude loop (body): ``a* = dw_ref + Kd (w_ref - w) + Kp e_eta + Ki int e_eta``
with ``e_eta = vee(R^T R_ref - R_ref^T R) / 2`` (the attitude error as a body
rotation vector; equal to the Euler-angle error for small errors).

Model inversion: with ``u = [f/m, I^-1 tau]`` and the nominal
``omega_dot = l(x) + u_tau`` (``l(x) = -I^-1 (omega x I omega)``), find
``u_tau`` such that ``u_tau + mu(u, omega) = a* - l(x)`` where ``mu`` is the
residual model's mean at the measured body rate (zero by default). Solved by
Newton's method with a finite-difference Jacobian, batched.

All arrays carry a leading batch dimension B.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from omavctl.physics.rigid_body import cross, rotation_matrix
from omavctl.vehicle import Vehicle

__all__ = [
    "CommandRate",
    "ControlOutput",
    "Controller",
    "ControllerState",
    "ResidualModel",
    "ZeroResidual",
    "invert_residual",
]

#: Integral terms are clamped to this magnitude (anti-windup), rad s and m s.
INTEGRAL_LIMIT = np.array([0.5, 0.5, 0.5])


class ResidualModel(Protocol):
    """Anything that predicts the angular-acceleration residual from inputs.

    :class:`omavctl.learn.model.ResidualGP` (the output of ``fit``) is one.
    """

    def mean(
        self, u: np.ndarray, omega: np.ndarray | None = None, du: np.ndarray | None = None
    ) -> np.ndarray:
        """Residual mean (B, 3) rad/s^2 for scaled wrenches u (B, 6) at body rates
        omega (B, 3) rad/s and command rates of change du (B, 6) 1/s (models that do
        not depend on the state or the command's rate ignore them)."""
        ...


class ZeroResidual:
    """The nominal model: no residual."""

    def mean(
        self, u: np.ndarray, omega: np.ndarray | None = None, du: np.ndarray | None = None
    ) -> np.ndarray:
        return np.zeros((*u.shape[:-1], 3))


def invert_residual(
    target: np.ndarray,
    u_force: np.ndarray,
    model: ResidualModel,
    omega: np.ndarray | None = None,
    iterations: int = 6,
    tol: float = 1e-10,
    step: float = 1e-5,
    du: np.ndarray | None = None,
) -> np.ndarray:
    """Solve ``x + mu([u_force, x], omega, du) = target`` for x, batched (B, 3).

    omega (B, 3) is the measured body rate the model is evaluated at; du (B, 6)
    the command's recent rate of change (held fixed during the solve).
    Newton's method with a forward-difference Jacobian of ``mu``; rows that
    have converged are not updated further. Each step asks the model once, for
    the point and its three forward steps together (4B rows: a model's mean at a
    row depends on that row alone), not four times: ``simulate --model`` spent most
    of its time in the model's per-call overhead (docs/informative.md, "The cost of
    a draw").
    """

    def mean(u: np.ndarray, copies: int = 1) -> np.ndarray:
        # u (copies * B, 6): omega and du repeated for each copy; models that do not
        # use the command's rate take (u, omega) only
        om = None if omega is None else np.concatenate([omega] * copies)
        if du is None:
            return model.mean(u, om)
        return model.mean(u, om, np.concatenate([du] * copies))

    x = target - mean(np.concatenate([u_force, target], axis=-1))
    for _ in range(iterations):
        u = np.concatenate([u_force, x], axis=-1)
        # the point and its forward steps in torque j = 0, 1, 2: rows (4, B, 6)
        stacked = np.repeat(u[None], 4, axis=0)
        for j in range(3):
            stacked[1 + j, ..., 3 + j] += step
        means = mean(stacked.reshape(-1, u.shape[-1]), 4).reshape(4, *x.shape)
        mu = means[0]
        r = x + mu - target
        if np.max(np.abs(r)) < tol:
            break
        jac = np.empty((*x.shape, 3))
        for j in range(3):
            jac[..., :, j] = (means[1 + j] - mu) / step
        jac += np.eye(3)
        x = x - np.linalg.solve(jac, r[..., None])[..., 0]
    return x


#: Commands the rate of change of the command is fitted over (the default
#: Savitzky-Golay window of ``fit``, whose derivative the GP was trained on).
RATE_WINDOW = 11


class CommandRate:
    """Rate of change of a command from its last :data:`RATE_WINDOW` values.

    The least-squares slope of a line through the last ``window`` commands (fewer
    at the start), 1/s: causal, and as smooth as the Savitzky-Golay derivative
    the GP's ``dtorque`` inputs were fitted on. A one-step difference would carry
    the controller's reaction to sensor noise times 1/dt, inputs far outside the
    training data (measured: a closed-loop tracking error 18x larger). Works on
    arrays of any shape (the time axis is the buffer's own).
    """

    def __init__(self, dt: float, window: int = RATE_WINDOW) -> None:
        self.dt, self.window = dt, window
        self.history: list[np.ndarray] = []

    def update(self, u: np.ndarray) -> np.ndarray:
        """Add the newest command u (...); returns its rate of change (...)."""
        self.history.append(np.array(u, copy=True))
        if len(self.history) > self.window:
            self.history.pop(0)
        n = len(self.history)
        if n < 2:
            return np.zeros_like(self.history[0])
        j = np.arange(n) - (n - 1) / 2.0
        weights = j / (float(j @ j) * self.dt)
        out = weights[0] * self.history[0]
        for w, h in zip(weights[1:], self.history[1:], strict=True):
            out = out + w * h
        return out


@dataclass
class ControllerState:
    """Integrators of the attitude (B, 3) and position (B, 3) loops; the rate of change
    du (B, 6) 1/s of the model-free scaled command ``[f/m, a* - l(x)]``, fitted over
    its last values (:class:`CommandRate`: what a residual model with command-rate
    inputs is given)."""

    att_integral: np.ndarray
    pos_integral: np.ndarray
    last_du: np.ndarray | None = None
    rate: CommandRate | None = None

    @classmethod
    def zeros(cls, batch: int) -> ControllerState:
        return cls(np.zeros((batch, 3)), np.zeros((batch, 3)))


@dataclass(frozen=True)
class ControlOutput:
    """One control step: force (B, 3) N and torque (B, 3) N m in body frame,
    desired angular acceleration a* (B, 3), desired linear acceleration (B, 3)
    in world frame, scaled input u (B, 6)."""

    force: np.ndarray
    torque: np.ndarray
    desired_angular: np.ndarray
    desired_linear: np.ndarray
    u: np.ndarray


class Controller:
    """Attitude + position PID with model inversion for one vehicle."""

    def __init__(self, vehicle: Vehicle, residual: ResidualModel | None = None) -> None:
        self.vehicle = vehicle
        self.residual: ResidualModel = residual if residual is not None else ZeroResidual()
        self._has_model = residual is not None

    def step(
        self,
        state: ControllerState,
        x: np.ndarray,
        ref: np.ndarray,
        dt: float,
    ) -> ControlOutput:
        """Advance one step.

        x: measured state (B, 12) ``[p, eta, v, omega]``; ref: reference rows
        (B, 19) in trajectory column order (``t`` first). Updates ``state``.
        """
        v, g = self.vehicle, self.vehicle.gains
        p, eta, vel, omega = x[:, 0:3], x[:, 3:6], x[:, 6:9], x[:, 9:12]
        p_ref, eta_ref, v_ref = ref[:, 1:4], ref[:, 4:7], ref[:, 7:10]
        w_ref, a_ref, dw_ref = ref[:, 10:13], ref[:, 13:16], ref[:, 16:19]

        # position loop (world frame)
        e_p = p_ref - p
        state.pos_integral = np.clip(state.pos_integral + e_p * dt, -INTEGRAL_LIMIT, INTEGRAL_LIMIT)
        a_lin = a_ref + g.pos_kd * (v_ref - vel) + g.pos_kp * e_p + g.pos_ki * state.pos_integral
        rot = rotation_matrix(eta)
        acc_body = np.einsum("bji,bj->bi", rot, a_lin + np.array([0.0, 0.0, v.gravity]))
        force = v.mass * acc_body

        # attitude loop (body frame)
        r_ref = rotation_matrix(eta_ref)
        m = np.einsum("bji,bjk->bik", rot, r_ref)  # R^T R_ref
        e_att = 0.5 * np.stack(
            [m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=-1
        )
        state.att_integral = np.clip(
            state.att_integral + e_att * dt, -INTEGRAL_LIMIT, INTEGRAL_LIMIT
        )
        a_star = (
            dw_ref + g.att_kd * (w_ref - omega) + g.att_kp * e_att + g.att_ki * state.att_integral
        )

        # model inversion: u_tau + mu(u, omega) = a* - l(x)
        inertia = v.inertia
        l_x = -cross(omega, omega @ inertia.T) @ v.inertia_inv.T
        u_force = force / v.mass
        target = a_star - l_x
        # the command's rate of change for a model with command-rate inputs: that of
        # the model-free command [f/m, a* - l(x)], which the inversion does not
        # change (the inverted command's own rate would close an algebraic loop of
        # gain T/dt through a learned lag T: unstable for T > dt)
        u_free = np.concatenate([u_force, target], axis=-1)
        if state.rate is None:
            state.rate = CommandRate(dt)
        du = state.rate.update(u_free)
        state.last_du = du
        if self._has_model:
            uses_rate = getattr(self.residual, "uses_command_rate", False)
            u_tau = invert_residual(
                target, u_force, self.residual, omega, du=du if uses_rate else None
            )
        else:
            u_tau = target
        torque = u_tau @ inertia.T
        return ControlOutput(
            force=force,
            torque=torque,
            desired_angular=a_star,
            desired_linear=a_lin,
            u=np.concatenate([u_force, u_tau], axis=-1),
        )
