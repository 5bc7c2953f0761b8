"""Informative trajectory generation (the paper's "Generation of Informative Trajectories").

1. Fly the task M times in a batched closed-loop simulation: nominal rigid body,
   the model-based controller (PID + inversion of the model's mean), and as
   "truth" the nominal dynamics plus one consistent GP posterior function sample
   per simulation (:class:`~omavctl.planning.gp.PathwiseSamples`). The visited
   GP inputs estimate the task region; epsilon defaults to the mean distance
   between commanded and achieved input (the paper's heuristic); S test points
   are drawn uniformly in the epsilon-balls around visited inputs.
2. Sample K deviation coefficient sets (:mod:`~omavctl.planning.candidates`).
3. Simulate every candidate M times, all K*M simulations in one batch per time
   step; reject those that break allocation limits, attitude limits or diverge.
4. For each simulation pick the points ``fit`` would train on
   (:func:`omavctl.fit.select_points`, k-medoids, on every ``stride``-th sample
   to keep it cheap) and compute the posterior variance at the test points
   given prior data + those points by a rank update (never a refit).
5. Cost = mean variance over test points, axes and simulations; lowest wins.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from omavctl.errors import OmavctlError
from omavctl.physics.allocation import Allocation
from omavctl.physics.controller import Controller, ControllerState
from omavctl.physics.rigid_body import cross, euler_rates, rotation_matrix, wrap_angle
from omavctl.planning.candidates import deviated_references, sample_coefficients
from omavctl.planning.gp import GPAxes, PathwiseSamples, posterior_variance_with_data
from omavctl.trajectory import Trajectory

__all__ = ["PlanResult", "PlanSettings", "Rollouts", "plan", "rollout"]

Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class PlanSettings:
    """Options of :func:`plan` (CLI flags of ``omavctl plan``)."""

    candidates: int = 20
    sims: int = 8
    frequencies: int = 2
    min_freq: float = 0.1  # Hz
    max_freq: float = 2.0  # Hz
    amplitude: float = 1.0  # rad/s^2
    epsilon: float | None = None  # normalised input units; None: paper's heuristic
    test_points: int = 500
    points: int = 40
    seed: int = 0
    rff_features: int = 256
    max_tilt_deg: float = 80.0  # attitude limit on roll and pitch
    max_error_deg: float = 30.0  # attitude error beyond which a simulation diverged
    stride: int = 4  # k-medoids on every stride-th simulated sample


@dataclass
class Rollouts:
    """Batched simulations: B = K * M rows (candidate k = b // M, sample m = b % M).

    inputs (B, T, d) normalised GP inputs visited; gap (B, T) distance between
    commanded and achieved input (normalised units); tracking (B,) mean absolute
    angular-acceleration tracking error |a* - omega_dot| (rad/s^2); feasible (B,);
    reason (B,) why not ("" if feasible).
    """

    inputs: np.ndarray
    gap: np.ndarray
    tracking: np.ndarray
    feasible: np.ndarray
    reason: list[str]


def _resample(refs: np.ndarray, t_ref: np.ndarray, t: np.ndarray) -> np.ndarray:
    """refs (K, N, 19) on t_ref -> (K, T, 19) on t (linear)."""
    if t_ref.size == t.size and np.allclose(t_ref, t):
        return refs
    idx = np.clip(np.searchsorted(t_ref, t, side="right") - 1, 0, t_ref.size - 2)
    w = ((t - t_ref[idx]) / (t_ref[idx + 1] - t_ref[idx]))[None, :, None]
    w = np.clip(w, 0.0, 1.0)
    return refs[:, idx] * (1 - w) + refs[:, idx + 1] * w


def rollout(
    model,
    samples: PathwiseSamples,
    refs: np.ndarray,
    t_ref: np.ndarray,
    sims: int,
    settings: PlanSettings,
    progress: Progress | None = None,
    label: str = "simulating",
    substeps: int = 4,
) -> Rollouts:
    """Simulate every reference in ``refs`` (K, N, 19) ``sims`` times, batched.

    The controller (nominal PID) runs at the vehicle's rate; its torque is
    corrected by two fixed-point iterations of ``u + mu(u) = a*`` with the
    model mean; the plant is ``omega_dot = l(x) + u_tau + g_m(u)`` with g_m the
    m-th posterior sample plus the model's static effects, integrated with
    ``substeps`` semi-implicit Euler steps per control period.
    """
    vehicle = model.vehicle
    rate = vehicle.gains.rate_hz
    dt = 1.0 / rate
    t = np.arange(int(np.floor((t_ref[-1] - t_ref[0]) * rate + 1e-9)) + 1) / rate + t_ref[0]
    refs = _resample(refs, t_ref, t)
    k_count, steps = refs.shape[0], t.size
    b_count = k_count * sims
    cand = np.repeat(np.arange(k_count), sims)
    sample_idx = np.tile(np.arange(sims), k_count)
    inertia, inertia_inv, mass = vehicle.inertia, vehicle.inertia_inv, vehicle.mass
    ctrl = Controller(vehicle)
    state = ControllerState.zeros(b_count)
    alloc = Allocation(vehicle)
    x = np.zeros((b_count, 12))
    x[:, 0:3] = refs[cand, 0, 1:4]
    x[:, 3:6] = refs[cand, 0, 4:7]
    x[:, 6:9] = refs[cand, 0, 7:10]
    x[:, 9:12] = refs[cand, 0, 10:13]
    d = samples.gp.d
    inputs = np.empty((b_count, steps, d))
    gap = np.empty((b_count, steps))
    track = np.zeros(b_count)
    feasible = np.ones(b_count, dtype=bool)
    reason = [""] * b_count
    prev_tilt: np.ndarray | None = None
    torque_scale = model.input_scale[3:6]
    max_tilt, max_err = np.deg2rad(settings.max_tilt_deg), np.deg2rad(settings.max_error_deg)
    alive = np.ones(b_count, dtype=bool)

    def mark(bad: np.ndarray, why: str) -> None:
        for b in np.flatnonzero(bad & feasible):
            reason[b] = why
        feasible[bad] = False

    u_last: np.ndarray | None = None
    du = np.zeros((b_count, 6))  # the command's rate of change over the last step
    for i in range(steps):
        ref = refs[cand, i]
        out = ctrl.step(state, x, ref, dt)
        omega = x[:, 9:12]
        u_f, target = out.u[:, :3], out.u[:, 3:]
        u = out.u.copy()
        for _ in range(2):  # fixed-point inversion of u_tau + mu(u) = target
            z = model.normalise(model.gp_inputs(u, omega, du))
            mu = samples.mean(z)
            if model.effects:
                mu = mu + model.effects_mean(u, omega)
            u[:, 3:] = target - mu
        z = model.normalise(model.gp_inputs(u, omega, du))
        if u_last is not None:
            du = (u - u_last) / dt
        u_last = u.copy()
        g, _ = samples.evaluate(z, sample_idx)
        if model.effects:
            g = g + model.effects_mean(u, omega)
        inputs[:, i] = z
        gap[:, i] = np.linalg.norm(g / torque_scale, axis=1)
        l_x = -cross(omega, omega @ inertia.T) @ inertia_inv.T
        omega_dot = l_x + u[:, 3:] + g
        track += np.abs(out.desired_angular - omega_dot).mean(axis=1)
        wrench = np.concatenate([u_f * mass, u[:, 3:] @ inertia.T], axis=1)
        res = alloc.allocate(wrench, prev_tilt, dt if prev_tilt is not None else None)
        prev_tilt = res.tilt
        mark(res.thrust_high.any(axis=1) | res.thrust_low.any(axis=1), "thrust limit")
        mark(res.tilt_rate_exceeded.any(axis=1), "tilt rate limit")
        force = wrench[:, :3]
        h = dt / substeps
        for _ in range(substeps):
            acc = np.einsum("bij,bj->bi", rotation_matrix(x[:, 3:6]), force) / mass
            acc[:, 2] -= vehicle.gravity
            w = x[:, 9:12]
            w_dot = -cross(w, w @ inertia.T) @ inertia_inv.T + u[:, 3:] + g
            x[:, 9:12] = w + h * w_dot
            x[:, 6:9] += h * acc
            x[:, 3:6] = wrap_angle(x[:, 3:6] + h * euler_rates(x[:, 3:6], x[:, 9:12]))
            x[:, 0:3] += h * x[:, 6:9]
        att_err = np.abs(wrap_angle(x[:, 3:6] - refs[cand, min(i + 1, steps - 1), 4:7])).max(axis=1)
        tilt_bad = np.abs(x[:, 3:5]).max(axis=1) > max_tilt
        mark(tilt_bad, "attitude limit")
        diverged = ~np.isfinite(x).all(axis=1) | (att_err > max_err)
        mark(diverged, "diverged")
        if diverged.any():  # keep the batch finite: freeze diverged rows at the reference
            alive &= ~diverged
            x[~alive] = np.nan_to_num(x[~alive])
        if progress is not None:
            progress(label, (i + 1) / steps)
    return Rollouts(inputs, gap, track / steps, feasible, reason)


def _test_points(
    visited: np.ndarray, epsilon: float, count: int, rng: np.random.Generator
) -> np.ndarray:
    """count points uniform in epsilon-balls around rows of visited (n, d)."""
    n, d = visited.shape
    centre = visited[rng.integers(0, n, size=count)]
    direction = rng.standard_normal((count, d))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = epsilon * rng.uniform(size=(count, 1)) ** (1.0 / d)
    return centre + radius * direction


@dataclass
class PlanResult:
    """Outcome of :func:`plan`.

    coefficients (K, 3, P, 2); cost (K,) mean posterior variance ((rad/s^2)^2),
    inf when infeasible; feasible (K,); reason (K,); tracking (K,) mean absolute
    tracking error in the simulations (rad/s^2); references (K, N, 19);
    best index (-1 if none is feasible); task_cost the cost of flying the task
    itself; epsilon used; prior_variance mean prior variance at the test points.
    """

    coefficients: np.ndarray
    cost: np.ndarray
    feasible: np.ndarray
    reason: list[str]
    tracking: np.ndarray
    references: np.ndarray
    best: int
    task_cost: float
    epsilon: float
    prior_variance: float
    test_points: np.ndarray
    notes: list[str] = field(default_factory=list)

    def best_trajectory(self, task: str | Path | None = None) -> Trajectory:
        """The chosen reference; ``task`` (the task file) is named when none is feasible."""
        if self.best < 0:
            raise OmavctlError(
                "no feasible candidate for this task: lower --amplitude or --max-freq", task
            )
        return Trajectory(self.references[self.best])


def _cost_of(
    model,
    gp: GPAxes,
    roll: Rollouts,
    test: np.ndarray,
    settings: PlanSettings,
    progress: Progress | None,
) -> np.ndarray:
    """Mean posterior variance (B,) over test points and axes after each simulation's data."""
    from omavctl.fit import select_points

    b_count = roll.inputs.shape[0]
    picks = np.empty((b_count, settings.points, gp.d))
    for b in range(b_count):
        z = roll.inputs[b, :: settings.stride]
        k = min(settings.points, z.shape[0])
        idx, _ = select_points(z, k, seed=settings.seed)
        chosen = z[idx]
        if k < settings.points:  # pad by repeating (adds no information beyond noise)
            chosen = np.resize(chosen, (settings.points, chosen.shape[1]))
        picks[b] = chosen
        if progress is not None:
            progress("selecting points", (b + 1) / b_count)
    var = posterior_variance_with_data(gp, picks, test)  # (B, S, 3)
    return var.mean(axis=(1, 2))


def plan(
    model,
    task: Trajectory,
    settings: PlanSettings,
    progress: Progress | None = None,
) -> PlanResult:
    """Sample, simulate and score candidate references (see module docstring)."""
    rng = np.random.default_rng(settings.seed)
    gp = GPAxes.from_model(model)
    samples = PathwiseSamples(gp, settings.sims, rng, settings.rff_features)
    notes: list[str] = []

    # 1. the task region
    task_roll = rollout(
        model, samples, task.data[None], task.t, settings.sims, settings, progress, "task"
    )
    visited = task_roll.inputs.reshape(-1, gp.d)
    epsilon = float(task_roll.gap.mean()) if settings.epsilon is None else settings.epsilon
    if epsilon <= 0:
        raise OmavctlError("--epsilon must be > 0 (the model predicts no residual at all)")
    test = _test_points(visited, epsilon, settings.test_points, rng)
    prior_var = float(gp.posterior_variance(test).mean())
    task_cost = float(_cost_of(model, gp, task_roll, test, settings, None).mean())
    if not task_roll.feasible.all():
        notes.append(
            "the task itself breaks limits in simulation: "
            + ", ".join(sorted({r for r in task_roll.reason if r}))
        )

    # 2-3. candidates
    coeffs = sample_coefficients(
        rng,
        settings.candidates,
        settings.frequencies,
        settings.min_freq,
        settings.max_freq,
        settings.amplitude,
    )
    refs = deviated_references(task, coeffs)
    roll = rollout(model, samples, refs, task.t, settings.sims, settings, progress, "candidates")

    # 4-5. score
    per_sim = _cost_of(model, gp, roll, test, settings, progress)
    k_count, m = settings.candidates, settings.sims
    feasible = roll.feasible.reshape(k_count, m).all(axis=1)
    reasons = []
    for k in range(k_count):
        why = sorted({r for r in roll.reason[k * m : (k + 1) * m] if r})
        reasons.append(", ".join(why))
    cost = np.where(feasible, per_sim.reshape(k_count, m).mean(axis=1), np.inf)
    best = int(np.argmin(cost)) if feasible.any() else -1
    return PlanResult(
        coefficients=coeffs,
        cost=cost,
        feasible=feasible,
        reason=reasons,
        tracking=roll.tracking.reshape(k_count, m).mean(axis=1),
        references=refs,
        best=best,
        task_cost=task_cost,
        epsilon=epsilon,
        prior_variance=prior_var,
        test_points=test,
        notes=notes,
    )
