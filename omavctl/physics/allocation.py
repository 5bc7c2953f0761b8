"""Tiltable-arm allocation of the omav: wrench <-> 6 tilt angles + 12 rotor thrusts.

Arm ``i`` points along ``d_i = [cos g_i, sin g_i, 0]`` (``g_i`` the arm angle),
its rotor pair sits at ``r_i = L d_i`` and tilts about the arm axis by
``alpha_i``. In the arm frame (x along the arm, z up, y = z x x) the pair's
force is ``F_i [0, sin alpha_i, cos alpha_i]``. Writing ``s_i = F_i sin alpha_i``
and ``c_i = F_i cos alpha_i`` as 12 free variables (variable decomposition)
makes the body wrench linear in them::

    [f; tau] = A [s; c],   A = [[y_i, z], [r_i x y_i, r_i x z]]  (6 x 12)

The minimum-norm solution is the pseudo-inverse; then ``alpha_i = atan2(s_i, c_i)``,
``F_i = hypot(s_i, c_i)``, split equally over the coaxial pair (top rotor
``2i``, bottom ``2i+1``). Equal split cancels the pair's drag torques.

Infeasible wrenches are *reported* (per-rotor thrust outside
``[min_thrust, max_thrust]``, tilt rate above ``max_tilt_rate``), never
silently clipped here: clipping is the actuators' business (see ``plant``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omavctl.physics.rigid_body import cross, wrap_angle
from omavctl.vehicle import Vehicle

__all__ = ["Allocation", "AllocationResult"]

#: Below this arm thrust (N) the tilt angle is undetermined; the previous one is kept.
TILT_THRUST_EPS = 1e-6
#: Slack on every limit check (a value at the limit is within it).
LIMIT_TOL = 1e-9


@dataclass(frozen=True)
class AllocationResult:
    """Actuator setpoints for a batch of wrenches (leading shape ``B``).

    tilt (B, 6) rad; arm_thrust (B, 6) N per coaxial pair; rotor_thrust (B, 12) N;
    thrust_high / thrust_low (B, 12) bool; tilt_rate_exceeded (B, 6) bool;
    feasible (B,) bool (no limit violated).
    """

    tilt: np.ndarray
    arm_thrust: np.ndarray
    rotor_thrust: np.ndarray
    thrust_high: np.ndarray
    thrust_low: np.ndarray
    tilt_rate_exceeded: np.ndarray

    @property
    def feasible(self) -> np.ndarray:
        return ~np.asarray(
            self.thrust_high.any(axis=-1)
            | self.thrust_low.any(axis=-1)
            | self.tilt_rate_exceeded.any(axis=-1)
        )


class Allocation:
    """Allocation for one vehicle geometry (matrix and pseudo-inverse built once)."""

    def __init__(self, vehicle: Vehicle) -> None:
        self.vehicle = vehicle
        g = vehicle.arm_angles
        n = g.size
        d = np.stack([np.cos(g), np.sin(g), np.zeros(n)], axis=-1)  # (6, 3) arm axes
        y = np.stack([-np.sin(g), np.cos(g), np.zeros(n)], axis=-1)  # (6, 3) tilt plane
        z = np.tile([0.0, 0.0, 1.0], (n, 1))
        r = vehicle.arm_length * d
        self.arm_axis = d
        self.arm_y = y
        self.arm_position = r
        a = np.zeros((6, 2 * n))
        a[:3, :n] = y.T
        a[3:, :n] = cross(r, y).T
        a[:3, n:] = z.T
        a[3:, n:] = cross(r, z).T
        self.matrix = a  # (6, 12)
        drag = np.zeros((6, 2 * n))
        drag[3:, :n], drag[3:, n:] = y.T, z.T  # a pair's drag torque acts along n_i
        #: (6, 24): the wrench of [T s, T c, d s, d c] (arm thrusts T, drag terms d)
        self.wrench_map = np.concatenate([a, drag], axis=1)
        self.pinv = np.linalg.pinv(a)  # (12, 6)
        # neighbours of each arm: the pairs at +-1 index around the hexagon
        self.neighbours = np.array([[(i - 1) % n, (i + 1) % n] for i in range(n)])
        diff = r[None, :, :] - r[:, None, :]  # [k, j] = r_j - r_k
        norm = np.linalg.norm(diff, axis=-1, keepdims=True)
        self.pair_direction = np.divide(diff, norm, out=np.zeros_like(diff), where=norm > 0)

    # --- maps -------------------------------------------------------------
    def thrust_directions(self, tilt: np.ndarray) -> np.ndarray:
        """Unit thrust direction of each arm in body frame: (..., 6) -> (..., 6, 3)."""
        s, c = np.sin(tilt)[..., None], np.cos(tilt)[..., None]
        return s * self.arm_y + c * np.array([0.0, 0.0, 1.0])

    def interference(self, tilt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shapes (..., 6) of the two tilt-dependent thrust losses of each arm's pair.

        ``wake``: ``sum_k max(0, -n_k . e_kj)^4`` over the two neighbouring pairs
        k of arm j (the wake of pair k, blown along ``-n_k``, hits pair j when
        pair k is tilted towards it); ``arm``: ``sin^2(alpha_j)`` (the pair's own
        wash on its arm). The plant's efficiency is ``1 - rotor_rotor * wake -
        rotor_arm * arm`` (:mod:`omavctl.sim.plant`, ``rotor_interference``).
        """
        n = self.thrust_directions(tilt)  # (..., 6, 3)
        hit = np.clip(-np.einsum("...kc,kjc->...kj", n, self.pair_direction), 0.0, None) ** 4
        cols = np.arange(tilt.shape[-1])
        wake = hit[..., self.neighbours[:, 0], cols] + hit[..., self.neighbours[:, 1], cols]
        return wake, np.sin(tilt) ** 2

    def forward(self, tilt: np.ndarray, rotor_thrust: np.ndarray) -> np.ndarray:
        """Body wrench [f, tau] (..., 6) from tilts (..., 6) rad and rotor thrusts (..., 12) N.

        Includes the rotor drag torques ``drag_ratio (T_top - T_bottom) n_i`` of
        each counter-rotating pair (zero for an equal split). One product with the
        allocation matrix and the drag map (:attr:`wrench_map`): the arm forces
        ``T_i (sin a_i y_i + cos a_i e_z)`` are what the matrix's columns map.
        """
        top, bottom = rotor_thrust[..., 0::2], rotor_thrust[..., 1::2]
        s, c = np.sin(tilt), np.cos(tilt)
        total, drag = top + bottom, self.vehicle.drag_ratio * (top - bottom)
        parts = np.concatenate([total * s, total * c, drag * s, drag * c], axis=-1)
        # numpy's own loops, not BLAS: a row's arithmetic must not depend on the batch
        return np.einsum("...k,jk->...j", parts, self.wrench_map)

    def allocate(
        self,
        wrench: np.ndarray,
        previous_tilt: np.ndarray | None = None,
        dt: float | None = None,
    ) -> AllocationResult:
        """Actuator setpoints for body wrenches (..., 6) [N, N m].

        ``previous_tilt`` (..., 6) and ``dt`` (s) enable the tilt-rate check and
        keep the tilt of an arm with (near) zero thrust where it was.
        """
        wrench = np.asarray(wrench, dtype=float)
        sc = wrench @ self.pinv.T  # (..., 12)
        n = self.vehicle.n_arms
        s, c = sc[..., :n], sc[..., n:]
        arm_thrust = np.hypot(s, c)
        tilt = np.arctan2(s, c)
        if previous_tilt is not None:
            tilt = np.where(arm_thrust < TILT_THRUST_EPS, previous_tilt, tilt)
        rotor = np.repeat(arm_thrust / 2.0, 2, axis=-1)
        v = self.vehicle
        high = rotor > v.max_thrust + LIMIT_TOL
        low = rotor < v.min_thrust - LIMIT_TOL
        if previous_tilt is not None and dt is not None:
            rate_bad = self.tilt_rate_exceeded(tilt, previous_tilt, dt)
        else:
            rate_bad = np.zeros(tilt.shape, dtype=bool)
        return AllocationResult(tilt, arm_thrust, rotor, high, low, rate_bad)

    def tilt_rate_exceeded(
        self, tilt: np.ndarray, previous_tilt: np.ndarray, dt: float
    ) -> np.ndarray:
        """Per arm (..., 6) whether going from ``previous_tilt`` to ``tilt`` in ``dt`` s
        is faster than the servos' ``max_tilt_rate``."""
        rate = np.abs(wrap_angle(tilt - previous_tilt)) / dt
        return np.asarray(rate > self.vehicle.max_tilt_rate + LIMIT_TOL)

    # --- sensitivities used by the lag effects -----------------------------
    def tilt_jacobian(self, tilt: np.ndarray, arm_thrust: np.ndarray) -> np.ndarray:
        """d wrench / d tilt_i: (..., 6) x2 -> (..., 6 wrench, 6 arms)."""
        dn = np.cos(tilt)[..., None] * self.arm_y - np.sin(tilt)[..., None] * np.array(
            [0.0, 0.0, 1.0]
        )
        df = arm_thrust[..., None] * dn  # (..., 6, 3)
        dtau = cross(self.arm_position, df)
        return np.concatenate([df, dtau], axis=-1).swapaxes(-1, -2)

    def thrust_jacobian(self, tilt: np.ndarray) -> np.ndarray:
        """d wrench / d arm_thrust_i: (..., 6) -> (..., 6 wrench, 6 arms)."""
        n = self.thrust_directions(tilt)
        dtau = cross(self.arm_position, n)
        return np.concatenate([n, dtau], axis=-1).swapaxes(-1, -2)
