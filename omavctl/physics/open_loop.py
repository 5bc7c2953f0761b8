"""Batched open-loop rollouts of the angular dynamics over logged commands.

Many windows of a log (W of them, each K grid steps long) are integrated at
once: body rate and ZYX Euler attitude from the rigid body
(:func:`~omavctl.physics.rigid_body.angular_acceleration`,
:func:`~omavctl.physics.rigid_body.euler_rates`) plus a residual angular
acceleration that a caller supplies per step. Each grid step holds the torque
command (zero-order hold, as the controller applies it) and the residual, and
takes one classical Runge-Kutta step of ``dt``. The residual is evaluated at
the step's midpoint (a half Euler step from its start with the previous
step's residual; the first step's from its start): a residual fitted on a
log stands for the period's mean (the Savitzky-Golay derivative and the held
inputs average over it), and a drag
held at its start value of a 10 ms step is off by half the step's change of
the body rate (measured: 3 % of the drag torque on a brisk figure-8, 0.1 % at
the midpoint).

Nothing here knows models or logs: the residual is a callable.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from omavctl.physics.rigid_body import angular_acceleration, euler_rates

__all__ = ["AttitudeResidual", "Residual", "rollout"]

#: residual angular acceleration (W, 3) rad/s^2 at step k from the body rates (W, 3)
Residual = Callable[[int, np.ndarray], np.ndarray]


class AttitudeResidual:
    """A residual that also needs the rolled-out attitude: ``fn(k, omega, eta)`` (W, 3)
    with eta (W, 3) ZYX Euler rad at the same instant as omega (an effect of the
    measured force, predicted from gravity's direction in the body)."""

    def __init__(self, fn: Callable[[int, np.ndarray, np.ndarray], np.ndarray]) -> None:
        self.fn = fn

    def __call__(self, k: int, omega: np.ndarray, eta: np.ndarray) -> np.ndarray:
        return self.fn(k, omega, eta)


def _rk4(
    omega: np.ndarray,
    eta: np.ndarray,
    torque: np.ndarray,
    extra: np.ndarray,
    inertia: np.ndarray,
    inertia_inv: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One RK4 step of (omega, eta) (W, 3) each with torque and extra held."""

    def f(w: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return angular_acceleration(w, torque, inertia, inertia_inv) + extra, euler_rates(e, w)

    k1w, k1e = f(omega, eta)
    k2w, k2e = f(omega + 0.5 * dt * k1w, eta + 0.5 * dt * k1e)
    k3w, k3e = f(omega + 0.5 * dt * k2w, eta + 0.5 * dt * k2e)
    k4w, k4e = f(omega + dt * k3w, eta + dt * k3e)
    omega_next = omega + dt / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
    eta_next = eta + dt / 6.0 * (k1e + 2.0 * k2e + 2.0 * k3e + k4e)
    return omega_next, eta_next


def rollout(
    omega0: np.ndarray,
    eta0: np.ndarray,
    torque: np.ndarray,
    inertia: np.ndarray,
    inertia_inv: np.ndarray,
    dt: float,
    residual: Residual | AttitudeResidual | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate W windows of K steps open loop.

    omega0, eta0 (W, 3): body rate (rad/s) and ZYX Euler angles (rad) at each
    window's start; torque (W, K, 3): the command held over each step;
    ``residual(k, omega)`` (W, 3): the extra angular acceleration at step k
    (None: the rigid body alone), called once per step (at its midpoint) and once more at the start;
    an :class:`AttitudeResidual` gets the attitude at the same instant as a third argument.
    Returns omega and eta (W, K + 1, 3), index 0 the start.
    """
    w_count, k_count, _ = torque.shape
    omega = np.empty((w_count, k_count + 1, 3))
    eta = np.empty((w_count, k_count + 1, 3))
    omega[:, 0], eta[:, 0] = omega0, eta0
    extra = np.zeros((w_count, 3))
    if isinstance(residual, AttitudeResidual):
        extra = residual(0, omega[:, 0], eta[:, 0])
    elif residual is not None:
        extra = residual(0, omega[:, 0])
    for k in range(k_count):
        if residual is not None:
            w = omega[:, k]
            start = angular_acceleration(w, torque[:, k], inertia, inertia_inv) + extra
            mid = w + 0.5 * dt * start
            if isinstance(residual, AttitudeResidual):
                e_mid = eta[:, k] + 0.5 * dt * euler_rates(eta[:, k], w)
                extra = residual(k, mid, e_mid)  # eta at the midpoint too
            else:
                extra = residual(k, mid)
        omega[:, k + 1], eta[:, k + 1] = _rk4(
            omega[:, k], eta[:, k], torque[:, k], extra, inertia, inertia_inv, dt
        )
    return omega, eta
