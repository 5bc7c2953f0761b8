"""The measured specific force predicted along a rollout window (issue 28, session 15).

An effect of the accelerometer's force (``drag_moment``) needs that force over a
rollout window, which the log records but an open-loop prediction may not read
ahead. Where the log has an attitude, the lateral force is rolled forward from
the window's start: a multirotor's horizontal specific force is its rotors' drag,
``f_lat = f_lat(0) - m d (v_lat - v_lat(0))`` (a linear drag ``d``, 1/s, on the body
velocity), and the body velocity changes with gravity in the rolled-out attitude
and that force, ``dv_lat/dt = f_lat / m + (R^T g)_lat`` (the Coriolis term
``omega x v`` is left out: it needs the absolute velocity, and the logs' body rates
are small). So a rollout that tilts the vehicle predicts the drag the tilt's
acceleration brings. ``d`` is the log's own: the least-squares slope of the
force's change over a window against the velocity change the force and gravity
integrate to (:func:`lateral_drag`), a statistic of the log as its rate noise is.
The force is median-free (``m (a - median a)``, as the effect's regressor), the
same in the drag (a constant accelerometer offset integrates to a negligible
velocity over 0.5 s).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from omavctl.physics.rigid_body import rotation_matrix

__all__ = [
    "GRAVITY",
    "ForceRollout",
    "force_residual",
    "gravity_body",
    "gravity_offset",
    "lateral_drag",
    "roll_force",
    "trailing_mean",
]

#: standard gravity, m/s^2
GRAVITY = 9.80665


def gravity_body(eta: np.ndarray) -> np.ndarray:
    """Gravity (..., 3) m/s^2 in the body frame (FLU) at ZYX Euler attitudes eta (..., 3):
    ``R^T (0, 0, -g)`` with R body-to-world (z up)."""
    return -GRAVITY * rotation_matrix(eta)[..., 2, :]


def gravity_offset(attitude: np.ndarray, log: np.ndarray) -> np.ndarray:
    """Per window (W, 2) m/s^2: the median over its log's window starts of gravity's lateral
    part in the body (attitude (W, K + 1, 3) rad, log (W,) the windows' log): the tilt
    the vehicle holds on average, which does not accelerate it (the attitude estimate's
    level against the accelerometer's, 2 degrees on the px4tools log; the force is
    median-free alike)."""
    g = gravity_body(attitude[:, 0])[:, :2]
    out = np.zeros_like(g)
    for i in np.unique(log):
        sel = log == i
        out[sel] = np.median(g[sel], axis=0)
    return out


def lateral_drag(
    force: np.ndarray, attitude: np.ndarray, offset: np.ndarray, mass: float, dt: float
) -> float:
    """The linear drag d (1/s, >= 0) of windows' lateral specific force.

    force (W, K + 1, 3) N, median-free; attitude (W, K + 1, 3) rad, logged; offset
    (W, 2) :func:`gravity_offset`. Regresses the force's change over each window,
    ``(f_K - f_0) / m``, on the lateral velocity change
    ``int (f / m + g_body - offset) dt`` (trapezoidal), x and y pooled, through the
    origin: ``f_K - f_0 = -m d dv``. 0 with no windows or no velocity change."""
    if force.shape[0] == 0:
        return 0.0
    acc = force[..., :2] / mass + gravity_body(attitude)[..., :2] - offset[:, None]
    dv = 0.5 * dt * (acc[:, 1:] + acc[:, :-1]).sum(axis=1)  # (W, 2)
    df = (force[:, -1, :2] - force[:, 0, :2]) / mass
    den = float(np.sum(dv * dv))
    if den <= 0.0:
        return 0.0
    return max(-float(np.sum(dv * df)) / den, 0.0)


def roll_force(
    f0: np.ndarray,
    offset: np.ndarray,
    attitude_mid: np.ndarray,
    drag: float,
    mass: float,
    dt: float,
) -> np.ndarray:
    """The lateral force (W, K, 3) N predicted at each step's midpoint from the start's
    f0 (W, 3) N and the attitudes at the steps' midpoints (W, K, 3) rad (the logged ones:
    what the band compares with the log); offset (W, 2) :func:`gravity_offset`."""
    roll = ForceRollout(f0, offset, drag, mass, dt)
    return np.stack([roll.step(attitude_mid[:, k]) for k in range(attitude_mid.shape[1])], 1)


class ForceRollout:
    """The lateral force along one batch of windows, stepped by the rolled-out attitude.

    f0 (W, 3) N the median-free measured force at the windows' starts, offset (W, 2)
    :func:`gravity_offset`; ``step(eta)`` advances the lateral velocity change one grid
    step with gravity at attitude eta (W, 3) (the step's midpoint) and returns the force
    (W, 3) N at that midpoint (z held at the start's)."""

    def __init__(
        self, f0: np.ndarray, offset: np.ndarray, drag: float, mass: float, dt: float
    ) -> None:
        self.f0 = np.asarray(f0, dtype=float)
        self.offset = np.asarray(offset, dtype=float)
        self.drag, self.mass, self.dt = float(drag), float(mass), float(dt)
        self.dv = np.zeros((self.f0.shape[0], 2))

    def _force(self, dv: np.ndarray) -> np.ndarray:
        out = self.f0.copy()
        out[:, :2] -= self.mass * self.drag * dv
        return out

    def step(self, eta: np.ndarray) -> np.ndarray:
        g = gravity_body(eta)[:, :2] - self.offset
        half = self.dv + 0.5 * self.dt * (self._force(self.dv)[:, :2] / self.mass + g)
        force = self._force(half)
        self.dv = self.dv + self.dt * (force[:, :2] / self.mass + g)
        return force


def force_residual(effects: Any, df: np.ndarray, inertia_inv: np.ndarray) -> np.ndarray:
    """Residual (..., 3) rad/s^2 the measured-state effects (name -> estimate) add for a
    change df (..., 3) N of the measured force (their torque is linear in it)."""
    out = np.zeros(df.shape)
    for est in effects.values():
        tau = est.effect.body_torque(est.values, np.zeros(df.shape), df)
        if tau is not None:
            out = out + tau @ inertia_inv.T
    return out


def trailing_mean(values: np.ndarray, n: int) -> np.ndarray:
    """Mean (N, c) of each sample and the n - 1 before it (fewer at the start) of values
    (N, c): the force at a window's start without its vibration, from the past only."""
    c = np.cumsum(np.vstack([np.zeros((1, values.shape[1])), values]), axis=0)
    idx = np.arange(values.shape[0])
    lo = np.maximum(idx - n + 1, 0)
    return (c[idx + 1] - c[lo]) / (idx + 1 - lo)[:, None]
