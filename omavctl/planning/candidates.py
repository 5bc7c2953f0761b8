"""Candidate references: the task plus a sampled Fourier deviation.

The paper samples the deviation on the angular-acceleration level about x, y
and z, below 2 Hz, with P frequencies per axis whose locations and magnitudes
are sampled (P = 2: 12 coefficients). Here the deviation is built on the
Euler-angle level so that angles, rates and accelerations stay exactly
consistent and vanish at both ends:

    delta_j(t) = e(t) sum_p  A_jp / (2 pi f_jp)^2  sin(2 pi f_jp t)

(``e`` the smooth 0 -> 1 -> 0 envelope of the tasks), whose second derivative
is ``-A_jp sin(2 pi f_jp t)`` away from the ramps: ``A`` is the magnitude in
rad/s^2 of the angular acceleration deviation (for moderate angles Euler and
body axes nearly coincide). The candidate's Euler angles are the task's plus
``delta``; its body rates and accelerations follow from
:func:`~omavctl.physics.rigid_body.euler_rates_to_body`.
"""

from __future__ import annotations

import numpy as np

from omavctl.physics.rigid_body import euler_rates, euler_rates_to_body, rotation_matrix
from omavctl.sim.tasks import Envelope
from omavctl.sim.trajectory import Trajectory

__all__ = [
    "ReferenceStream",
    "coefficient_names",
    "deviated_references",
    "sample_coefficients",
    "yaw_deviation_deg",
]


def coefficient_names(frequencies: int) -> list[str]:
    """Names of the 3 * 2 * P coefficients, e.g. ``f_x1, A_x1, f_x2, A_x2, f_y1, ...``."""
    return [
        f"{kind}_{axis}{p + 1}" for axis in "xyz" for p in range(frequencies) for kind in ("f", "A")
    ]


def sample_coefficients(
    rng: np.random.Generator,
    n: int,
    frequencies: int,
    min_freq: float,
    max_freq: float,
    amplitude: float,
) -> np.ndarray:
    """(n, 3, P, 2) frequency (Hz, uniform in [min_freq, max_freq]) and magnitude
    (rad/s^2, uniform in [-amplitude, amplitude]) per axis and component."""
    f = rng.uniform(min_freq, max_freq, size=(n, 3, frequencies))
    a = rng.uniform(-amplitude, amplitude, size=(n, 3, frequencies))
    return np.stack([f, a], axis=-1)


def yaw_deviation_deg(task: Trajectory, coefficients: np.ndarray, ramp: float = 2.0) -> np.ndarray:
    """Largest |yaw deviation| from the task's reference yaw over the task (K,), deg.

    coefficients (K, 3, P, 2); the z row of ``delta`` of the module docstring on the
    task's samples: the candidate's reference yaw minus the task's, known before any
    simulation (a low deviation frequency turns the vehicle far: A / (2 pi f)^2).
    """
    t = task.t - task.t[0]
    env = Envelope(float(t[-1]), min(ramp, float(t[-1]) / 2))(t)[0]
    f, amp = coefficients[:, 2, :, 0, None], coefficients[:, 2, :, 1, None]  # (K, P, 1)
    w = 2 * np.pi * f
    delta = env * (amp / w**2 * np.sin(w * t)).sum(axis=1)  # (K, N)
    return np.rad2deg(np.abs(delta).max(axis=1))


def _task_euler_derivatives(task: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Euler angles, their rates and accelerations (N, 3) from the task's body rates.

    ``eta_dot = T(eta) omega`` and ``eta_ddot = T(eta) (omega_dot - W_dot eta_dot)``.
    """
    eta, omega = task.euler, task.body_rate
    deta = euler_rates(eta, omega)
    _, wdot_deta = euler_rates_to_body(eta, deta, np.zeros_like(eta))
    assert wdot_deta is not None
    ddeta = euler_rates(eta, task.angular_acceleration - wdot_deta)
    return eta, deta, ddeta


def deviated_references(
    task: Trajectory, coefficients: np.ndarray, ramp: float = 2.0, rows: slice | None = None
) -> np.ndarray:
    """Candidate references (K, N, 19) in trajectory column order.

    coefficients (K, 3, P, 2) from :func:`sample_coefficients`; the task's
    positions, velocities and linear accelerations are kept. ``rows`` restricts
    the output to those task rows (K, len(rows), 19), the same values as the
    full call: the batched rollouts generate references block by block.
    """
    rows = slice(None) if rows is None else rows
    t_all = task.t - task.t[0]
    t = t_all[rows]
    duration = float(t_all[-1])
    env, denv, ddenv, _ = Envelope(duration, min(ramp, duration / 2))(t)
    f = coefficients[..., 0][..., None]  # (K, 3, P, 1)
    amp = coefficients[..., 1][..., None]
    w = 2 * np.pi * f
    s, c = np.sin(w * t), np.cos(w * t)  # (K, 3, P, N)
    g = amp / w**2
    base = (g * s).sum(axis=2)  # (K, 3, N)
    dbase = (g * w * c).sum(axis=2)
    ddbase = (-g * w**2 * s).sum(axis=2)
    delta = env * base
    ddelta = denv * base + env * dbase
    dddelta = ddenv * base + 2 * denv * dbase + env * ddbase
    eta, deta, ddeta = (v[rows] for v in _task_euler_derivatives(task))
    eta_k = eta[None] + np.swapaxes(delta, 1, 2)
    deta_k = deta[None] + np.swapaxes(ddelta, 1, 2)
    ddeta_k = ddeta[None] + np.swapaxes(dddelta, 1, 2)
    omega, domega = euler_rates_to_body(eta_k, deta_k, ddeta_k)
    assert domega is not None
    data = task.data[rows]
    out = np.broadcast_to(data, (coefficients.shape[0], *data.shape)).copy()
    out[..., 4:7] = eta_k
    out[..., 10:13] = omega
    out[..., 16:19] = domega
    return out


class ReferenceStream:
    """Candidate references on the controller grid, generated block by block.

    The batched rollouts need, per control step i, every candidate's reference
    row; (K, N, 19) at once would be 365 MB for 1000 candidates of 24 s.
    ``block(lo, hi)`` returns the rows of steps lo..hi-1 as (hi - lo, 19, K)
    (C order: one step is one contiguous (19, K) slice) and the rotation
    matrices of their reference attitudes (hi - lo, 9, K), row-major entries.
    On a controller grid that differs from the task's, rows are interpolated
    linearly (as :func:`omavctl.planning.rollout.rollout` does). With
    ``task_first``, candidate 0 is the task's own data (its coefficients are
    ignored).
    """

    def __init__(
        self,
        task: Trajectory,
        coefficients: np.ndarray,
        t: np.ndarray,
        task_first: bool = False,
    ) -> None:
        self.task, self.coefficients, self.task_first = task, coefficients, task_first
        t_ref = task.t
        self.same_grid = t_ref.size == t.size and bool(np.allclose(t_ref, t))
        self.idx = np.clip(np.searchsorted(t_ref, t, side="right") - 1, 0, t_ref.size - 2)
        w = (t - t_ref[self.idx]) / (t_ref[self.idx + 1] - t_ref[self.idx])
        self.weight = np.clip(w, 0.0, 1.0)

    def _rows(self, lo: int, hi: int) -> np.ndarray:
        """Task rows lo..hi-1 of every candidate (K, hi - lo, 19)."""
        out = deviated_references(self.task, self.coefficients, rows=slice(lo, hi))
        if self.task_first:
            out[0] = self.task.data[lo:hi]
        return out

    def block(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        """Reference rows (hi - lo, 19, K) and attitudes as rotations (hi - lo, 9, K)."""
        if self.same_grid:
            refs = self._rows(lo, hi)
        else:
            idx, w = self.idx[lo:hi], self.weight[lo:hi, None]
            first = int(idx.min())
            rows = self._rows(first, int(idx.max()) + 2)
            refs = rows[:, idx - first] * (1 - w) + rows[:, idx + 1 - first] * w
        refs = np.ascontiguousarray(np.transpose(refs, (1, 2, 0)))
        rot = rotation_matrix(np.moveaxis(refs[:, 4:7], 1, -1))  # (L, K, 3, 3)
        rot = np.ascontiguousarray(np.moveaxis(rot.reshape(*rot.shape[:2], 9), -1, 1))
        return refs, rot
