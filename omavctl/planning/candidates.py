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

from omavctl.physics.rigid_body import euler_rates, euler_rates_to_body
from omavctl.tasks import Envelope
from omavctl.trajectory import Trajectory

__all__ = ["coefficient_names", "deviated_references", "sample_coefficients"]


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
    task: Trajectory, coefficients: np.ndarray, ramp: float = 2.0
) -> np.ndarray:
    """Candidate references (K, N, 19) in trajectory column order.

    coefficients (K, 3, P, 2) from :func:`sample_coefficients`; the task's
    positions, velocities and linear accelerations are kept.
    """
    t = task.t - task.t[0]
    env, denv, ddenv, _ = Envelope(float(t[-1]), min(ramp, float(t[-1]) / 2))(t)
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
    eta, deta, ddeta = _task_euler_derivatives(task)
    eta_k = eta[None] + np.swapaxes(delta, 1, 2)
    deta_k = deta[None] + np.swapaxes(ddelta, 1, 2)
    ddeta_k = ddeta[None] + np.swapaxes(dddelta, 1, 2)
    omega, domega = euler_rates_to_body(eta_k, deta_k, ddeta_k)
    assert domega is not None
    out = np.broadcast_to(task.data, (coefficients.shape[0], *task.data.shape)).copy()
    out[..., 4:7] = eta_k
    out[..., 10:13] = omega
    out[..., 16:19] = domega
    return out
