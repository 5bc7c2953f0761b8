"""Plan from files (``omavctl plan``): task CSV and model file in, reference CSV out.

Two steps, so that a caller can show progress only while the candidates are
flown: :func:`prepare_plan` refuses bad outputs and option values before any
work and reads the model (checked against ``--vehicle``) and the task;
:meth:`PlanJob.run` plans (:func:`omavctl.planning.planner.plan`) and writes
the most informative reference and the scores
(:func:`omavctl.planning.report.write_plan`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from threadpoolctl import threadpool_limits

from omavctl.base.atomic import check_outputs
from omavctl.base.errors import OmavctlError
from omavctl.base.replace import is_report_file, refuse_replacing
from omavctl.learn.model import ResidualGP
from omavctl.learn.model_file import check_model_paths, check_vehicle, load_model
from omavctl.planning.planner import PlanResult, PlanSettings, plan
from omavctl.planning.report import is_scores_file, no_feasible_candidate, write_plan
from omavctl.planning.rollout import Progress
from omavctl.sim.trajectory import Trajectory, check_replaceable, read_trajectory
from omavctl.vehicle import load_vehicle

__all__ = ["PlanJob", "check_plan_settings", "prepare_plan"]


def check_plan_settings(settings: PlanSettings) -> None:
    """:class:`OmavctlError` naming the option when a setting is out of range."""
    for name, value in (
        ("--candidates", settings.candidates),
        ("--sims", settings.sims),
        ("--points", settings.points),
        ("--test-points", settings.test_points),
        ("--frequencies", settings.frequencies),
        ("--generations", settings.generations),
    ):
        if value < 1:
            raise OmavctlError(f"{name} must be at least 1, got {value}")
    if settings.jobs < 0:
        raise OmavctlError(f"--jobs must be 0 (one per core) or more, got {settings.jobs}")
    if settings.search not in ("random", "cem"):
        raise OmavctlError(f"--search must be 'random' or 'cem', got '{settings.search}'")
    if settings.region not in ("pool", "task"):
        raise OmavctlError(f"--region must be 'pool' or 'task', got '{settings.region}'")
    if settings.selection not in ("batched", "kmedoids"):
        raise OmavctlError(
            f"--selection must be 'batched' or 'kmedoids', got '{settings.selection}'"
        )
    if not (0.1 < settings.max_freq <= 50.0 and 0 < settings.amplitude <= 100.0):
        raise OmavctlError("--max-freq must be in (0.1, 50] Hz and --amplitude in (0, 100] rad/s^2")
    if not 0 < settings.max_tilt_deg <= 90.0:
        raise OmavctlError(f"--max-tilt must be in (0, 90] deg, got {settings.max_tilt_deg:g}")
    margin = settings.tilt_margin_deg
    if margin is not None and not 0 <= margin <= 90.0:
        raise OmavctlError(f"--tilt-margin must be in [0, 90] deg, got {margin:g}")
    epsilon = settings.epsilon
    if epsilon is not None and not 0 < epsilon <= 1000:
        raise OmavctlError(f"--epsilon must be in (0, 1000] normalised units, got {epsilon}")


@dataclass(frozen=True)
class PlanJob:
    """A plan ready to run: the outputs and options checked, the model and task read."""

    model: ResidualGP
    task: Trajectory
    task_path: Path
    settings: PlanSettings
    out: Path
    scores: Path | None
    #: said before the planner's own notes (how the effects to plan for were chosen)
    notes: tuple[str, ...] = ()

    def run(self, progress: Progress | None = None) -> PlanResult:
        """Plan, then write the most informative reference to ``out`` (and the scores).

        ``progress`` gets (stage, fraction done). The result's ``task`` is the task.
        """
        # BLAS threads set once: one per process, so that worker processes (--jobs) and
        # BLAS do not fight over the cores and timings are stable (threadpoolctl)
        with threadpool_limits(limits=1, user_api="blas"):
            result = plan(self.model, self.task, self.settings, progress)
        if result.best < 0:
            raise no_feasible_candidate(result, self.task_path, self.scores)
        result.notes[:0] = self.notes  # before the files that carry them are written
        write_plan(self.out, result.best_trajectory(self.task_path), result, self.scores)
        return result


def prepare_plan(
    task: Path,
    model: Path,
    out: Path,
    settings: PlanSettings,
    *,
    vehicle: Path | None = None,
    scores: Path | None = None,
    report: Path | None = None,
    evaluation: Path | None = None,
) -> PlanJob:
    """Refuse bad outputs and option values, read the model (checked against
    ``vehicle`` when given) and the task.

    ``scores``: where every candidate's coefficients, cost and feasibility go (CSV).
    ``report`` is only checked as an output here (the plan report is rendered by
    :func:`omavctl.report.plan.write_plan_report`). ``evaluation``: an
    evaluation JSON whose missing (and ambiguous) effects the effects objective
    plans for when ``settings.effects`` names none.
    """
    check_model_paths([model])
    check_outputs([task, model, vehicle, evaluation], [out, scores, report])
    check_replaceable(out)
    refuse_replacing(scores, is_scores_file, "a plan's scores CSV")
    refuse_replacing(report, is_report_file, "an omavctl report")
    notes: tuple[str, ...] = ()
    if not settings.effects and evaluation is not None:
        from omavctl.planning.effects_objective import effects_from_evaluation

        settings = replace(settings, effects=effects_from_evaluation(evaluation))
        if not settings.effects:  # a new user's plan went on for the model's effects, silent
            notes = (
                f"{evaluation} names no effect missing: the plan is for the model's own "
                "fitted effects (name others with --effects)",
            )
    check_plan_settings(settings)
    mdl = load_model(model)
    mdl.vehicle.check_flyable("plan", model)
    if vehicle is not None:
        check_vehicle(mdl, load_vehicle(vehicle), vehicle)
    ref = read_trajectory(task)
    return PlanJob(mdl, ref, task, settings, out, scores, notes)
