"""Plan from files (``omavctl plan``): task CSV and model file in, reference CSV out.

:func:`run_plan` does the command's work in the order the command checks it:
the outputs are refused before any work, then the option values, the model
(and that it fits ``--vehicle``) and the task are read, the candidates are
planned (:func:`omavctl.planning.planner.plan`) and the most informative
reference and the scores are written (:func:`omavctl.planning.report.write_plan`).
"""

from __future__ import annotations

from pathlib import Path

from threadpoolctl import threadpool_limits

from omavctl.base.atomic import check_outputs
from omavctl.base.errors import OmavctlError
from omavctl.learn.model import check_vehicle, load_model
from omavctl.planning.planner import PlanResult, PlanSettings, plan
from omavctl.planning.report import write_plan
from omavctl.planning.rollout import Progress
from omavctl.sim.trajectory import read_trajectory
from omavctl.vehicle import load_vehicle

__all__ = ["check_plan_settings", "run_plan"]


def check_plan_settings(settings: PlanSettings) -> None:
    """:class:`OmavctlError` naming the option when a setting is out of range."""
    for name, value in (
        ("--candidates", settings.candidates),
        ("--sims", settings.sims),
        ("--points", settings.points),
        ("--test-points", settings.test_points),
        ("--frequencies", settings.frequencies),
        ("--generations", settings.generations),
        ("--jobs", settings.jobs),
    ):
        if value < 1:
            raise OmavctlError(f"{name} must be at least 1, got {value}")
    if settings.search not in ("random", "cem"):
        raise OmavctlError(f"--search must be 'random' or 'cem', got '{settings.search}'")
    if settings.selection not in ("batched", "kmedoids"):
        raise OmavctlError(
            f"--selection must be 'batched' or 'kmedoids', got '{settings.selection}'"
        )
    if not (0.1 < settings.max_freq <= 50.0 and 0 < settings.amplitude <= 100.0):
        raise OmavctlError("--max-freq must be in (0.1, 50] Hz and --amplitude in (0, 100] rad/s^2")
    epsilon = settings.epsilon
    if epsilon is not None and not 0 < epsilon <= 1000:
        raise OmavctlError(f"--epsilon must be in (0, 1000] normalised units, got {epsilon}")


def run_plan(
    task: Path,
    model: Path,
    out: Path,
    settings: PlanSettings,
    *,
    vehicle: Path | None = None,
    scores: Path | None = None,
    report: Path | None = None,
    progress: Progress | None = None,
) -> PlanResult:
    """Plan the most informative reference for ``task`` and write it to ``out``.

    ``scores``: also write every candidate's coefficients, cost and feasibility
    (CSV). ``report`` is only checked as an output here (the plan report is
    rendered by :func:`omavctl.report.plan.write_plan_report`). ``progress`` gets
    (stage, fraction done). The result's ``task`` is the task trajectory read.
    """
    check_outputs([task, model, vehicle], [out, scores, report])
    check_plan_settings(settings)
    mdl = load_model(model)
    if vehicle is not None:
        check_vehicle(mdl, load_vehicle(vehicle), vehicle)
    ref = read_trajectory(task)
    # BLAS threads set once: one per process, so that worker processes (--jobs) and
    # BLAS do not fight over the cores and timings are stable (threadpoolctl)
    with threadpool_limits(limits=1, user_api="blas"):
        result = plan(mdl, ref, settings, progress)
    write_plan(out, result.best_trajectory(task), result, scores)
    return result
