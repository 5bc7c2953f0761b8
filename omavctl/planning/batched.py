"""Fast batched closed-loop simulation: every candidate x posterior sample per step.

The same equations as the reference :func:`omavctl.planning.rollout.rollout`
(nominal PID, model inversion with the mean at the previous command, plant =
nominal rigid body + posterior sample + static effects, ``substeps``
semi-implicit Euler steps), arranged for speed:

* state in component-major layout (12, M, K): sample m, candidate k; every
  reference row (19, K) broadcasts over the samples without copies;
* the GP (posterior sample and mean at once) as one fused float32 matrix
  product per sample block (:class:`~omavctl.planning.fused.FusedSamples`);
* references generated in blocks of steps (:class:`ReferenceStream`), their
  rotation matrices precomputed;
* the tilt-rate check compares arm directions by a dot product (no arctan2);
  sines and cosines of the attitude in float32 (:func:`_trig`);
* only every ``stride``-th GP input is kept (float32), what the scoring uses;
  the task's own inputs (candidate 0) are kept in full for the task region.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omavctl.physics.controller import CommandRate
from omavctl.planning.candidates import ReferenceStream
from omavctl.planning.fused import FusedSamples
from omavctl.planning.rollout import Progress, control_times

__all__ = ["BatchRollouts", "rollout_batched"]

_BLOCK = 50  # control steps of references generated at once
_TOL = 1e-9  # as Allocation.allocate


@dataclass
class BatchRollouts:
    """K candidates x M samples.

    picks (K, M, Ts, d) float32 normalised GP inputs at steps 0, stride, ...;
    tracking (K, M) mean |a* - omega_dot| (rad/s^2); code (K, M) first violation
    (index into :data:`~omavctl.planning.rollout.REASONS`, 0 = feasible);
    task_inputs (M, T, d) all inputs of candidate 0 and task_gap the mean
    distance between commanded and achieved input there (when kept, else None).
    """

    picks: np.ndarray
    tracking: np.ndarray
    code: np.ndarray
    task_inputs: np.ndarray | None = None
    task_gap: float | None = None


def _trig(eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin (3, M, K) float64 of the Euler angles, evaluated in float32.

    numpy's float64 sin/cos are scalar loops (about 10 ns each); the float32
    ones are vectorised (about 0.5 ns). Their 6e-8 absolute error tilts the
    force and the Euler rates by that much, far below what the controller
    corrects; the state itself is integrated in float64.
    """
    e32 = eta.astype(np.float32)
    return np.cos(e32).astype(np.float64), np.sin(e32).astype(np.float64)


def _rotation(c: np.ndarray, s: np.ndarray) -> list[np.ndarray]:
    """Body-to-world rotation entries R_ij (row-major list of 9 (M, K)) from cos/sin."""
    cr, cp, cy = c
    sr, sp, sy = s
    spcr, spsr = sp * cr, sp * sr
    return [
        cy * cp, cy * spsr - sy * cr, cy * spcr + sy * sr,
        sy * cp, sy * spsr + cy * cr, sy * spcr - cy * sr,
        -sp, cp * sr, cp * cr,
    ]  # fmt: skip


def _apply(matrix: np.ndarray, x: np.ndarray) -> np.ndarray:
    """matrix (r, c) times x (c, M, K) as elementwise products and sums, not BLAS: a
    column's arithmetic is then the same in any batch (BLAS kernels, chosen by
    shape, round differently), so that plans do not depend on ``--jobs``."""
    rows = []
    for row in matrix:
        terms = [row[j] * x[j] for j in np.flatnonzero(row)]
        rows.append(sum(terms[1:], terms[0]) if terms else np.zeros_like(x[0]))
    return np.stack(rows)


def _gyro(w: np.ndarray, inertia: np.ndarray, inertia_inv: np.ndarray) -> np.ndarray:
    """l(w) = -I^-1 (w x I w) for w (3, M, K)."""
    iw = _apply(inertia, w)
    cr = np.stack(
        [w[1] * iw[2] - w[2] * iw[1], w[2] * iw[0] - w[0] * iw[2], w[0] * iw[1] - w[1] * iw[0]]
    )
    return -_apply(inertia_inv, cr)


class _Loop:
    """Constants and state of one batched simulation (see :func:`rollout_batched`)."""

    def __init__(self, model, sims: int, k_count: int, limits: tuple[float, float]) -> None:
        v = model.vehicle
        self.model, self.v, self.g = model, v, v.gains
        self.dt = 1.0 / v.gains.rate_hz
        self.shape = (sims, k_count)
        self.x = np.zeros((12, sims, k_count))
        self.pos_int = np.zeros((3, sims, k_count))
        self.att_int = np.zeros((3, sims, k_count))
        self.track = np.zeros(self.shape)
        self.code = np.zeros(self.shape, np.int8)
        self.alive = np.ones(self.shape, bool)
        self.tilt_dir: np.ndarray | None = None  # (2, 6, M, K) sin, cos of the arm tilts
        from omavctl.physics.allocation import Allocation

        self.pinv = Allocation(v).pinv  # (12, 6)
        self.max_tilt, self.max_err = np.deg2rad(limits[0]), np.deg2rad(limits[1])
        self.cos_rate = np.cos(min((v.max_tilt_rate + _TOL) * self.dt, np.pi))
        self.col = (slice(None), None, None)  # (3,) gains -> (3, 1, 1)

    def mark(self, bad: np.ndarray, code: int) -> None:
        np.copyto(self.code, code, where=bad & (self.code == 0))

    def control(self, ref: np.ndarray, rot_ref: np.ndarray) -> tuple[np.ndarray, ...]:
        """PID step: u_f (3, M, K), target torque input, a* and l(x) (each (3, M, K))."""
        g, v, x, dt, col = self.g, self.v, self.x, self.dt, self.col
        p, eta, vel, w = x[0:3], x[3:6], x[6:9], x[9:12]
        ref = ref[:, None, :]
        e_p = ref[1:4] - p
        self.pos_int = np.clip(self.pos_int + e_p * dt, -0.5, 0.5)
        a_lin = ref[13:16] + g.pos_kd[col] * (ref[7:10] - vel) + g.pos_kp[col] * e_p
        a_lin += g.pos_ki[col] * self.pos_int
        a_lin[2] += v.gravity
        rot = _rotation(*_trig(eta))
        u_f = np.stack([sum(rot[3 * j + i] * a_lin[j] for j in range(3)) for i in range(3)])
        rr = rot_ref[:, None, :]

        def m(i: int, k: int) -> np.ndarray:  # (R^T R_ref)_ik
            return sum(rot[3 * j + i] * rr[3 * j + k] for j in range(3))

        e_att = 0.5 * np.stack([m(2, 1) - m(1, 2), m(0, 2) - m(2, 0), m(1, 0) - m(0, 1)])
        self.att_int = np.clip(self.att_int + e_att * dt, -0.5, 0.5)
        a_star = ref[16:19] + g.att_kd[col] * (ref[10:13] - w) + g.att_kp[col] * e_att
        a_star += g.att_ki[col] * self.att_int
        l_x = _gyro(w, v.inertia, v.inertia_inv)
        return u_f, a_star - l_x, a_star, l_x

    def allocate(self, u_f: np.ndarray, u_tau: np.ndarray) -> None:
        """Thrust and tilt-rate limits of the wrench; marks violations."""
        v = self.v
        wrench = np.concatenate([u_f * v.mass, _apply(v.inertia, u_tau)])
        sc = _apply(self.pinv, wrench)  # (12, M, K)
        thrust = np.sqrt(sc[:6] ** 2 + sc[6:] ** 2)
        half = thrust / 2.0
        bad = ((half > v.max_thrust + _TOL) | (half < v.min_thrust - _TOL)).any(axis=0)
        self.mark(bad, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            direction = sc.reshape(2, 6, *self.shape) / thrust
        if self.tilt_dir is None:
            direction = np.where(thrust > 0, direction, np.array([0.0, 1.0])[:, None, None, None])
        else:
            direction = np.where(thrust < 1e-6, self.tilt_dir, direction)
            cos_step = (direction * self.tilt_dir).sum(axis=0)
            self.mark((cos_step < self.cos_rate).any(axis=0), 2)
        self.tilt_dir = direction

    def integrate(self, u_f: np.ndarray, u_tau_g: np.ndarray, substeps: int) -> None:
        """``substeps`` semi-implicit Euler steps with the body force and torque input + g."""
        v, x = self.v, self.x
        h = self.dt / substeps
        force = u_f  # f / m
        for _ in range(substeps):
            eta, w = x[3:6], x[9:12]
            c, s = _trig(eta)
            rot = _rotation(c, s)
            acc = np.stack([sum(rot[3 * i + j] * force[j] for j in range(3)) for i in range(3)])
            acc[2] -= v.gravity
            w += h * (_gyro(w, v.inertia, v.inertia_inv) + u_tau_g)
            x[6:9] += h * acc
            sr, cr, cp = s[0], c[0], c[1]
            tp = s[1] / cp
            deta = np.stack(
                [
                    w[0] + sr * tp * w[1] + cr * tp * w[2],
                    cr * w[1] - sr * w[2],
                    (sr * w[1] + cr * w[2]) / cp,
                ]
            )
            x[3:6] = (eta + h * deta + np.pi) % (2.0 * np.pi) - np.pi
            x[0:3] += h * x[6:9]

    def check(self, eta_next: np.ndarray) -> None:
        """Attitude limit and divergence after a step; freezes diverged rows finite."""
        x = self.x
        err = np.abs((x[3:6] - eta_next[:, None, :] + np.pi) % (2.0 * np.pi) - np.pi).max(axis=0)
        self.mark(np.abs(x[3:5]).max(axis=0) > self.max_tilt, 3)
        diverged = ~np.isfinite(x).all(axis=0) | (err > self.max_err)
        self.mark(diverged, 4)
        if diverged.any():
            self.alive &= ~diverged
            dead = ~self.alive
            x[:, dead] = np.nan_to_num(x[:, dead])


def _gp_inputs(model, u: np.ndarray, w: np.ndarray, du: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Normalised GP inputs (d, M, K) from u (6, M, K), body rates w (3, M, K) and the
    command's rate of change du (6, M, K), in the order of the model's features."""
    mean, scale = model.input_mean[:, None, None], model.input_scale[:, None, None]
    names = model.features.split("+")
    parts = [u]
    if "rate" in names:
        parts.append(w)
    if "dtorque" in names:
        parts.append(du[3:])
    i = 0
    for part in parts:
        k = part.shape[0]
        out[i : i + k] = (part - mean[i : i + k]) / scale[i : i + k]
        i += k
    return out


def _effects(model, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Static effects (3, M, K) at u (6, M, K), w (3, M, K)."""
    shape = u.shape[1:]
    e = model.effects_mean(u.reshape(6, -1).T, w.reshape(3, -1).T)
    return np.ascontiguousarray(e.T).reshape(3, *shape)


def _evaluate(fused: FusedSamples, z: np.ndarray, out: np.ndarray, offset: int) -> np.ndarray:
    """Samples and means (6, M, K) at z (d, M, K): sample m for row block m; the K
    candidates are ``offset`` to ``offset + K`` of the whole batch."""
    for m in range(z.shape[1]):
        fused.evaluate(z[:, m], m, out=out[:, m], offset=offset)
    return out


def rollout_batched(
    model,
    fused: FusedSamples,
    stream: ReferenceStream,
    t_ref: np.ndarray,
    sims: int,
    stride: int,
    limits: tuple[float, float] = (80.0, 30.0),
    keep_task: bool = False,
    progress: Progress | None = None,
    label: str = "simulating",
    substeps: int = 4,
    offset: int = 0,
) -> BatchRollouts:
    """Simulate every candidate of ``stream`` ``sims`` times (one sample each), batched.

    t_ref (N,) the task's times; limits as for the reference rollout (degrees);
    ``keep_task``: keep candidate 0's full inputs and gap (it is the task);
    ``offset``: the first candidate's place in the whole batch (``--jobs`` shares).
    """
    k_count = stream.coefficients.shape[0]
    t = control_times(t_ref, model.vehicle.gains.rate_hz)
    steps, d = t.size, fused.d
    loop = _Loop(model, sims, k_count, limits)
    picks = np.empty((k_count, sims, (steps - 1) // stride + 1, d), np.float32)
    task_inputs = np.empty((sims, steps, d)) if keep_task else None
    gap = 0.0
    z = np.empty((d, sims, k_count))
    gout = np.empty((6, sims, k_count))
    u = np.empty((6, sims, k_count))
    rate = CommandRate(loop.dt)
    mu_last: np.ndarray | None = None
    torque_scale = model.input_scale[3:6, None]
    with np.errstate(over="ignore", invalid="ignore"):
        for lo in range(0, steps, _BLOCK):
            refs, rots = stream.block(lo, min(lo + _BLOCK + 1, steps))
            for j in range(min(_BLOCK, steps - lo)):
                i = lo + j
                if i == 0:  # start on the reference: [p, eta, v, omega] = columns 1..12
                    loop.x[:] = refs[0, 1:13, None, :]
                u_f, target, a_star, l_x = loop.control(refs[j], rots[j])
                omega = loop.x[9:12]
                # command rate: of the model-free command, as the controller (CommandRate)
                du = rate.update(np.concatenate([u_f, target]))
                u[:3] = u_f
                if mu_last is None:  # first step: the mean at u_tau = target
                    u[3:] = target
                    first = _evaluate(fused, _gp_inputs(model, u, omega, du, z), gout, offset)
                    mu_last = first[3:].copy()
                    if model.effects:
                        mu_last += _effects(model, u, omega)
                u[3:] = target - mu_last
                _evaluate(fused, _gp_inputs(model, u, omega, du, z), gout, offset)
                g, mu_last = gout[:3], gout[3:]
                if model.effects:
                    static = _effects(model, u, omega)
                    g += static
                    mu_last += static
                if i % stride == 0:
                    picks[:, :, i // stride] = np.transpose(z, (2, 1, 0))
                if task_inputs is not None:
                    task_inputs[:, i] = z[:, :, 0].T
                    gap += float(np.sqrt(((g[:, :, 0] / torque_scale) ** 2).sum(axis=0)).sum())
                loop.track += np.abs(a_star - l_x - u[3:] - g).sum(axis=0) / 3.0
                loop.allocate(u_f, u[3:])
                loop.integrate(u_f, u[3:] + g, substeps)
                loop.check(refs[min(j + 1, refs.shape[0] - 1), 4:7])
                if progress is not None:
                    progress(label, (i + 1) / steps)
    return BatchRollouts(
        picks=picks,
        tracking=(loop.track / steps).T.copy(),
        code=loop.code.T.copy(),
        task_inputs=task_inputs,
        task_gap=gap / (sims * steps) if keep_task else None,
    )
