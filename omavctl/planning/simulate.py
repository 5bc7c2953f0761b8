"""Simulating a batch of candidates: the fast path, the reference path, worker processes.

Both paths return a :class:`Batch`: per candidate and sample the GP inputs at
every ``stride``-th step, the tracking error and the first violated limit;
with ``with_task`` also the task's own simulations (its full inputs and the
mean commanded-achieved gap that sets epsilon). The fast path simulates the
task as candidate 0 of the same batch; the reference path flies it on its own
and every candidate one after the other (:func:`~omavctl.planning.rollout.rollout`).

``jobs > 1`` splits the candidates over worker processes
(:mod:`~omavctl.planning.workers`), each running the fast path on its share with
one BLAS thread; the arrays come back through pipes. The per-simulation results do
not depend on the split, to the bit: every operation of a step is column-wise
(candidates are columns), and the fused GP product pads its blocks to whole BLAS
tiles (:mod:`~omavctl.planning.fused`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from omavctl.planning.batched import BatchRollouts, rollout_batched
from omavctl.planning.candidates import ReferenceStream, deviated_references
from omavctl.planning.fused import FusedSamples
from omavctl.planning.gp import PathwiseSamples
from omavctl.planning.rollout import REASONS, Progress, rollout
from omavctl.planning.workers import run_tasks
from omavctl.sim.trajectory import Trajectory

__all__ = ["Batch", "Simulator"]


@dataclass
class Batch:
    """K candidates x M samples: inputs (K, M, Ts, d), tracking (K, M), code (K, M)
    (index into REASONS); task_inputs (M, T, d), task_gap and task_code (M,) when
    the task was simulated too."""

    inputs: np.ndarray
    tracking: np.ndarray
    code: np.ndarray
    task_inputs: np.ndarray | None = None
    task_gap: float | None = None
    task_code: np.ndarray | None = None


class Simulator:
    """Simulates candidate deviations of ``task`` with ``samples`` (see module docstring).

    limits (attitude limit, divergence threshold) in degrees; ``fast`` picks the
    path; ``jobs`` worker processes for the fast path.
    """

    def __init__(
        self,
        model,
        samples: PathwiseSamples,
        task: Trajectory,
        stride: int,
        limits: tuple[float, float],
        fast: bool = True,
        jobs: int = 1,
        progress: Progress | None = None,
    ) -> None:
        self.model, self.samples, self.task = model, samples, task
        self.sims = samples.w.shape[1]
        self.stride, self.limits, self.fast, self.jobs = stride, limits, fast, jobs
        self.progress = progress
        self.fused = FusedSamples(samples) if fast else None

    def __call__(self, coeffs: np.ndarray, with_task: bool, label: str = "simulating") -> Batch:
        """Simulate candidates coeffs (K, 3, P, 2) (and the task first when with_task)."""
        if not self.fast:
            return self._reference(coeffs, with_task, label)
        shares = np.array_split(coeffs, max(1, min(self.jobs, coeffs.shape[0] // 2)))
        assert self.fused is not None
        self.fused.set_batch(coeffs.shape[0] + with_task)  # one GEMM shape for every share

        # each share's first column's place in the whole batch (the task, if flown, is 0)
        ends = np.cumsum([len(c) for c in shares])
        starts = [0, *(int(e) + int(with_task) for e in ends[:-1])]

        def share(i: int, report: Callable[[float], None]) -> BatchRollouts:
            first = with_task and i == 0
            return self.fast_rollout(shares[i], first, lambda _, f: report(f), starts[i])

        parts = run_tasks(share, len(shares), self.jobs, self.progress, label)
        first = 1 if with_task else 0
        return Batch(
            inputs=np.concatenate([p.picks for p in parts])[first:],
            tracking=np.concatenate([p.tracking for p in parts])[first:],
            code=np.concatenate([p.code for p in parts])[first:],
            task_inputs=parts[0].task_inputs,
            task_gap=parts[0].task_gap,
            task_code=parts[0].code[0] if with_task else None,
        )

    def fast_rollout(
        self,
        coeffs: np.ndarray,
        with_task: bool,
        progress: Progress | None = None,
        offset: int = 0,
    ) -> BatchRollouts:
        """The fast path on coeffs; with_task prepends the task as candidate 0;
        ``offset``: the first candidate's place in the whole batch."""
        assert self.fused is not None
        if with_task:
            coeffs = np.concatenate([np.zeros((1, *coeffs.shape[1:])), coeffs])
        t = _control_times(self.task, self.model)
        stream = ReferenceStream(self.task, coeffs, t, task_first=with_task)
        return rollout_batched(
            self.model,
            self.fused,
            stream,
            self.task.t,
            self.sims,
            self.stride,
            self.limits,
            keep_task=with_task,
            progress=progress,
            offset=offset,
        )

    def _reference(self, coeffs: np.ndarray, with_task: bool, label: str) -> Batch:
        """Straightforward: the task, then every candidate on its own, float64."""
        model, samples, task, m = self.model, self.samples, self.task, self.sims
        out = Batch(
            inputs=np.empty((coeffs.shape[0], m, 0, self.samples.gp.d)),
            tracking=np.empty((coeffs.shape[0], m)),
            code=np.zeros((coeffs.shape[0], m), np.int8),
        )
        if with_task:
            roll = rollout(model, samples, task.data[None], task.t, m, self.limits)
            out.task_inputs, out.task_gap = roll.inputs, float(roll.gap.mean())
            out.task_code = np.array([REASONS.index(r) for r in roll.reason], np.int8)
        inputs = []
        for k in range(coeffs.shape[0]):
            refs = deviated_references(task, coeffs[k : k + 1])
            roll = rollout(model, samples, refs, task.t, m, self.limits)
            inputs.append(roll.inputs[:, :: self.stride])
            out.tracking[k] = roll.tracking
            out.code[k] = [REASONS.index(r) for r in roll.reason]
            if self.progress is not None:
                self.progress(label, (k + 1) / coeffs.shape[0])
        if inputs:
            out.inputs = np.stack(inputs)
        return out


def _control_times(task: Trajectory, model) -> np.ndarray:
    from omavctl.planning.rollout import control_times

    return control_times(task.t, model.vehicle.gains.rate_hz)
