"""The truth plant's per-step pieces on Python floats: the rigid body, and the controller
and allocation of one vehicle without a learned model.

numpy's per-call overhead on 3-vectors dominated the plant's 1 kHz inner loop.
:class:`ScalarBody` is :func:`omavctl.physics.rigid_body.state_derivative` with RK4
(``tests/test_physics.py`` checks they agree). :class:`ScalarController` and
:class:`ScalarAllocation` are :class:`omavctl.physics.controller.Controller` (with no residual
model) and :meth:`omavctl.physics.allocation.Allocation.allocate` for a batch of one
(profiled before: about 0.4 ms a controller step, so 12 s of flight with a 1 kHz
controller cost about 5 CPU s in the controller alone). ``tests/test_plant.py``
checks that both give the same commands to 1e-12 over a closed-loop flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from omavctl.physics.allocation import LIMIT_TOL, TILT_THRUST_EPS, Allocation
from omavctl.physics.controller import INTEGRAL_LIMIT
from omavctl.vehicle import Vehicle

__all__ = ["ScalarAllocation", "ScalarBody", "ScalarController", "ScalarOutput"]

Vec = list[float]


class ScalarBody:
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
        d, h, sixth = self.derivative, 0.5 * dt, dt / 6.0
        k1 = d(x, f, tau)
        k2 = d([a + h * b for a, b in zip(x, k1)], f, tau)  # noqa: B905 - all 12 long
        k3 = d([a + h * b for a, b in zip(x, k2)], f, tau)  # noqa: B905
        k4 = d([a + dt * b for a, b in zip(x, k3)], f, tau)  # noqa: B905
        return [
            a + sixth * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
            for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4)  # noqa: B905
        ]


def _rotation(r: float, p: float, y: float) -> list[Vec]:
    """Body-to-world rotation rows of ZYX Euler angles (as ``rotation_matrix``)."""
    cr, cp, cy = math.cos(r), math.cos(p), math.cos(y)
    sr, sp, sy = math.sin(r), math.sin(p), math.sin(y)
    return [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]


def _rows(a: np.ndarray) -> list[Vec]:
    return [[float(v) for v in row] for row in a]


@dataclass
class ScalarOutput:
    """One control step: force (3,) N and torque (3,) N m (body), desired angular
    acceleration (3,) rad/s^2 (body) and linear acceleration (3,) m/s^2 (world)."""

    force: Vec
    torque: Vec
    desired_angular: Vec
    desired_linear: Vec


@dataclass
class ScalarController:
    """Attitude and position PID of one vehicle (no residual model), integrators kept."""

    vehicle: Vehicle
    att_integral: Vec = field(default_factory=lambda: [0.0, 0.0, 0.0])
    pos_integral: Vec = field(default_factory=lambda: [0.0, 0.0, 0.0])

    def __post_init__(self) -> None:
        v, g = self.vehicle, self.vehicle.gains
        self.gains = [
            [float(x) for x in k]
            for k in (g.pos_kp, g.pos_kd, g.pos_ki, g.att_kp, g.att_kd, g.att_ki)
        ]
        self.inertia, self.inertia_inv = _rows(v.inertia), _rows(v.inertia_inv)
        self.limit = [float(x) for x in INTEGRAL_LIMIT]

    def _integrate(self, integral: Vec, error: Vec, dt: float) -> Vec:
        lim = self.limit
        return [min(max(integral[i] + error[i] * dt, -lim[i]), lim[i]) for i in range(3)]

    def step(self, x: Vec, ref: Vec, dt: float) -> ScalarOutput:
        """One step from the measured state x (12,) ``[p, eta, v, omega]`` and a
        reference row (19,) in trajectory column order (``t`` first)."""
        v = self.vehicle
        pkp, pkd, pki, akp, akd, aki = self.gains
        e_p = [ref[1 + i] - x[i] for i in range(3)]
        self.pos_integral = self._integrate(self.pos_integral, e_p, dt)
        a_lin = [
            ref[13 + i]
            + pkd[i] * (ref[7 + i] - x[6 + i])
            + pkp[i] * e_p[i]
            + pki[i] * self.pos_integral[i]
            for i in range(3)
        ]
        rot = _rotation(x[3], x[4], x[5])
        b = [a_lin[0], a_lin[1], a_lin[2] + v.gravity]
        force = [
            v.mass * (rot[0][i] * b[0] + rot[1][i] * b[1] + rot[2][i] * b[2]) for i in range(3)
        ]
        r_ref = _rotation(ref[4], ref[5], ref[6])
        m = [
            [
                rot[0][i] * r_ref[0][k] + rot[1][i] * r_ref[1][k] + rot[2][i] * r_ref[2][k]
                for k in range(3)
            ]
            for i in range(3)
        ]
        e_att = [0.5 * (m[2][1] - m[1][2]), 0.5 * (m[0][2] - m[2][0]), 0.5 * (m[1][0] - m[0][1])]
        self.att_integral = self._integrate(self.att_integral, e_att, dt)
        w = x[9:12]
        a_star = [
            ref[16 + i]
            + akd[i] * (ref[10 + i] - w[i])
            + akp[i] * e_att[i]
            + aki[i] * self.att_integral[i]
            for i in range(3)
        ]
        ii, iv = self.inertia, self.inertia_inv
        h = [ii[i][0] * w[0] + ii[i][1] * w[1] + ii[i][2] * w[2] for i in range(3)]
        c = [w[1] * h[2] - w[2] * h[1], w[2] * h[0] - w[0] * h[2], w[0] * h[1] - w[1] * h[0]]
        lc = [iv[i][0] * c[0] + iv[i][1] * c[1] + iv[i][2] * c[2] for i in range(3)]  # -l(x)
        u_tau = [a_star[i] + lc[i] for i in range(3)]
        torque = [ii[i][0] * u_tau[0] + ii[i][1] * u_tau[1] + ii[i][2] * u_tau[2] for i in range(3)]
        return ScalarOutput(force, torque, a_star, a_lin)


class ScalarAllocation:
    """Tilt and rotor-thrust setpoints of one wrench (``Allocation.allocate``, batch 1)."""

    def __init__(self, alloc: Allocation) -> None:
        v = alloc.vehicle
        self.pinv, self.n = alloc.pinv, v.n_arms
        self.max, self.min = v.max_thrust, v.min_thrust
        self.tol, self.eps = LIMIT_TOL, TILT_THRUST_EPS
        self.max_rate = v.max_tilt_rate

    def allocate(self, wrench: Vec, previous_tilt: Vec) -> tuple[Vec, Vec, bool]:
        """(tilt (6,) rad, rotor thrust (12,) N unclipped, thrust within limits)."""
        sc = (self.pinv @ np.array(wrench)).tolist()
        n, tilt, rotor = self.n, [], []
        for i in range(n):
            thrust = math.hypot(sc[i], sc[n + i])
            tilt.append(previous_tilt[i] if thrust < self.eps else math.atan2(sc[i], sc[n + i]))
            rotor += [thrust / 2.0, thrust / 2.0]
        ok = all(self.min - self.tol <= r <= self.max + self.tol for r in rotor)
        return tilt, rotor, ok

    def rate_exceeded(self, tilt: Vec, old: Vec, dt: float) -> bool:
        """Whether going from ``old`` to ``tilt`` in dt s is faster than the servos allow."""
        pi, two_pi = math.pi, 2.0 * math.pi
        return any(
            abs((a - b + pi) % two_pi - pi) / dt > self.max_rate + self.tol
            for a, b in zip(tilt, old, strict=True)
        )
