"""``omavctl plan``: plan the most informative next reference for a task.

The options are declared once below as ``Annotated`` aliases; a new option is
one alias, one parameter of :func:`plan` and one field of ``PlanSettings``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from omavctl.cli.app import app
from omavctl.cli.common import (
    Json,
    Quiet,
    VehicleOpt,
    console,
    emit,
    reports_errors,
    transient_progress,
)

Task = Annotated[
    Path, typer.Option("--task", metavar="CSV", help="Task trajectory CSV to learn for.")
]
ModelIn = Annotated[
    Path, typer.Option("--model", metavar="MODEL.npz", help="Current model (.npz from fit).")
]
ReferenceOut = Annotated[
    Path,
    typer.Option("--out", "-o", metavar="CSV", help="Most informative reference, trajectory CSV."),
]
Candidates = Annotated[int, typer.Option(help="Candidate references K.")]
Sims = Annotated[
    int, typer.Option(help="Simulations M per candidate (one GP posterior sample each).")
]
Frequencies = Annotated[int, typer.Option(help="Frequencies P per axis.")]
MaxFreq = Annotated[float, typer.Option(help="Highest deviation frequency, Hz.")]
Amplitude = Annotated[float, typer.Option(help="Largest angular-acceleration deviation, rad/s^2.")]
MaxTilt = Annotated[
    float,
    typer.Option(
        metavar="DEG",
        help="Attitude limit: a candidate whose simulated |roll| or |pitch| goes beyond it "
        "is rejected (deg).",
    ),
]
TiltMargin = Annotated[
    float | None,
    typer.Option(
        metavar="DEG",
        help="Also reject a candidate whose simulated |roll| or |pitch| goes more than "
        "this beyond the task's largest tilt (deg; 90: only --max-tilt). Default: 10 for "
        "--objective variance (refits on flights that tilt much further than the task got "
        "worse on it, docs/informative.md), 90 for effects.",
    ),
]
YawMargin = Annotated[
    float | None,
    typer.Option(
        metavar="DEG",
        help="Only candidates whose reference turns at most this far from the task's yaw "
        "(deg; others are redrawn before simulating). Default: no limit.",
    ),
]
Epsilon = Annotated[
    float | None,
    typer.Option(
        help="Radius of the task region around visited inputs, normalised input units "
        "(default: mean distance between commanded and achieved input, the paper's heuristic)."
    ),
]
TestPoints = Annotated[int, typer.Option(help="Test points S the variance is integrated over.")]
Region = Annotated[
    str,
    typer.Option(
        help="Where the variance objective's test points are: 'pool' (medoids of the "
        "states the task and the feasible candidates reach in simulation: the region "
        "of the flights to come) or 'task' (within epsilon of the task's own states, the "
        "paper; favours flights that hug the task, docs/informative.md)."
    ),
]
Points = Annotated[
    int, typer.Option(help="Training points a flight would add (k-medoids per simulation).")
]
Search = Annotated[
    str,
    typer.Option(
        help="How candidates are proposed: 'random' (all at once, the paper) or 'cem' "
        "(cross-entropy method over the Fourier coefficients in --generations "
        "generations, same number of simulations)."
    ),
]
Generations = Annotated[
    int, typer.Option(help="Generations of --search cem (at most; 20 candidates or more each).")
]
Selection = Annotated[
    str,
    typer.Option(
        help="How the points a flight would add are picked: 'batched' (medoids spaced in time + "
        "k-medoids steps, all simulations at once) or 'kmedoids' (as fit, per "
        "simulation, slow)."
    ),
]
Jobs = Annotated[
    int,
    typer.Option(
        help="Worker processes for the simulations and the scoring; 0: one per usable "
        "core. The plan does not depend on it (docs/planning-performance.md)."
    ),
]
Objective = Annotated[
    str,
    typer.Option(
        help="What ranks the candidates: 'variance' (the GP's posterior variance over "
        "--region, the paper's objective) or 'effects' (D-optimal information about the named "
        "effects' parameters, docs/plan-effects.md)."
    ),
]
EffectsOpt = Annotated[
    str | None,
    typer.Option(
        "--effects",
        metavar="A,B",
        help="--objective effects: the effects to separate and pin down (default: those "
        "--evaluation names as missing or ambiguous, else the model's fitted effects).",
    ),
]
EvaluationOpt = Annotated[
    Path | None,
    typer.Option(
        "--evaluation",
        metavar="EVAL.json",
        help="Evaluation whose missing effects to plan for.",
    ),
]
Scores = Annotated[
    Path | None,
    typer.Option(help="Write every candidate's coefficients, cost and feasibility as CSV."),
]
Seed = Annotated[int, typer.Option(help="Random seed (deviations, GP samples, test points).")]
ReportOut = Annotated[
    Path | None,
    typer.Option(
        "--report",
        metavar="PLAN.html",
        help="Also write an HTML report: the task and the planned reference over time, "
        "and every candidate's cost.",
    ),
]


@app.command(short_help="Plan the most informative next reference for a task.")
@reports_errors
def plan(
    task: Task,
    model: ModelIn,
    out: ReferenceOut,
    vehicle: VehicleOpt = None,
    candidates: Candidates = 20,
    sims: Sims = 8,
    frequencies: Frequencies = 2,
    max_freq: MaxFreq = 2.0,
    amplitude: Amplitude = 1.0,
    max_tilt: MaxTilt = 80.0,
    tilt_margin: TiltMargin = None,
    yaw_margin: YawMargin = None,
    epsilon: Epsilon = None,
    test_points: TestPoints = 500,
    region: Region = "pool",
    points: Points = 40,
    search: Search = "random",
    generations: Generations = 8,
    selection: Selection = "batched",
    jobs: Jobs = 0,
    objective: Objective = "variance",
    effects: EffectsOpt = None,
    evaluation: EvaluationOpt = None,
    scores: Scores = None,
    seed: Seed = 0,
    report_out: ReportOut = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Plan the most informative next reference: the task plus a sampled Fourier deviation.

    Each of K candidates is flown M times in closed-loop simulation with GP posterior
    samples; its cost is the mean variance ((rad/s^2)^2) the model's band would have at
    test points of the region (--region) after adding its data (the GP's posterior variance,
    and the band's growth beyond the training inputs; lower = more informative).
    """
    from omavctl.planning import PlanSettings
    from omavctl.planning.run import prepare_plan

    settings = PlanSettings(
        candidates=candidates,
        sims=sims,
        frequencies=frequencies,
        max_freq=max_freq,
        amplitude=amplitude,
        max_tilt_deg=max_tilt,
        tilt_margin_deg=tilt_margin,
        yaw_margin_deg=yaw_margin,
        epsilon=epsilon,
        test_points=test_points,
        region=region,
        points=points,
        seed=seed,
        search=search,
        generations=generations,
        selection=selection,
        jobs=jobs,
        objective=objective,
        effects=tuple(e.strip() for e in effects.split(",") if e.strip()) if effects else (),
    )
    job = prepare_plan(
        task,
        model,
        out,
        settings,
        vehicle=vehicle,
        scores=scores,
        report=report_out,
        evaluation=evaluation,
    )
    con = console(quiet)
    with _stage_bars(con, quiet) as progress:
        result = job.run(progress)
    files = _render_plan(con, result, out, scores, report_out)
    emit(as_json, _plan_json(result, files))


@contextmanager
def _stage_bars(con: Any, quiet: bool) -> Iterator[Callable[[str, float], None]]:
    """Transient progress bars, one per stage of the plan as the stages come."""
    with transient_progress(con, quiet) as bar:
        stages: dict[str, Any] = {}

        def progress(stage: str, fraction: float) -> None:
            if stage not in stages:
                stages[stage] = bar.add_task(stage, total=1.0)
            bar.update(stages[stage], completed=fraction)

        yield progress


def _render_plan(
    con: Any, result: Any, out: Path, scores: Path | None, report_out: Path | None
) -> dict[str, str]:
    """Print the best candidates and the plan's figures, write the HTML report if asked;
    returns the files written."""
    con.print(_candidates_table(result))
    rejected = int((~result.feasible).sum())
    if result.objective == "variance":
        task = (
            f"flying the task again: cost {result.task_cost:.4g} (rad/s^2)^2, from "
            f"{result.prior_variance:.4g} now"
        )
    else:
        task = (
            f"flying the task again: cost {result.task_cost:.4g} (-log det); the model's "
            f"variance now {result.prior_variance:.4g} (rad/s^2)^2"
        )
    from omavctl.planning.report import rejection_tally

    # a candidate may break several limits: the reasons are counted, not the candidates
    why = f" (reasons: {rejection_tally(result)})" if rejected else ""
    if result.region == "task":
        region = (
            f"task region: the inputs within {result.epsilon:.3g} input standard "
            "deviations (epsilon) of the task's"
        )
    else:
        region = "region: the states the task and the feasible candidates reach"
    con.print(f"{task}; {region}; {rejected}/{len(result.cost)} candidates rejected{why}")
    con.print(_tilt_line(result), markup=False)
    for note in result.notes:
        con.print(f"note: {note}", markup=False)
    from omavctl.planning.effects_forecast import effects_summary

    summary = effects_summary(result)
    for line in summary["lines"] if summary else []:
        con.print(line, markup=False)
    from omavctl.planning.envelope import envelope_lines
    from omavctl.planning.expectation import expectation_lines

    for line in expectation_lines(result) + envelope_lines(result):
        con.print(line, markup=False)
    from omavctl.planning.report import task_warning as _task_warning

    task_warning = _task_warning(result)
    if task_warning:
        con.print(f"warning: {task_warning}", markup=False)
    files = {"reference": str(out)}
    if scores is not None:
        files["scores"] = str(scores)
    if report_out is not None:
        from omavctl.report.plan import write_plan_report

        write_plan_report(report_out, result.task, result)
        files["report"] = str(report_out)
        con.print(f"wrote {report_out} (plan report)")
    con.print(f"wrote {out} (candidate {result.best})")
    return files


def _tilt_line(result: Any) -> str:
    """The attitude limit the candidates were held to, beside the task's largest tilt."""
    from omavctl.planning.planner import task_tilt_deg

    return (
        f"attitude limit: |roll|, |pitch| <= {result.max_tilt_deg:.0f} deg in simulation "
        f"(the task tilts to {task_tilt_deg(result.task):.0f}; --tilt-margin, --max-tilt)"
    )


def _candidates_table(result: Any) -> Any:
    """The five most informative feasible candidates, cost relative to the task."""
    from rich.table import Table

    effects = result.objective == "effects"
    title = "most informative candidates (lower cost = more informative)"
    if effects:  # -log det of the effects' information; vs task: their standard errors
        columns = ("id", "cost -log det", "std error vs task (- better)", "tracking rad/s^2")
    else:  # the model's band over the task region after the flight
        columns = ("id", "cost (rad/s^2)^2", "cost vs task (- better)", "tracking rad/s^2")
    table = Table(title=title)
    for col in columns:
        table.add_column(col, justify="right")
    order = [int(k) for k in result.cost.argsort() if result.feasible[k]][:5]
    for k in order:
        table.add_row(
            str(k),
            f"{result.cost[k]:.4g}",
            f"{result.versus_task(result.cost[k]):+.1f}%",
            f"{result.tracking[k]:.3f}",
        )
    return table


def _candidate_json(result: Any, k: int) -> dict[str, Any]:
    """One candidate of --json: its cost, every objective's number (as the scores CSV;
    null where not computed or infeasible), tracking, feasibility and the reason."""
    import math

    from omavctl.planning.report import METRIC_COLUMNS

    out: dict[str, Any] = {"id": k, "cost": float(result.cost[k])}
    for column, key in METRIC_COLUMNS.items():
        values = result.metrics.get(key)
        v = float(values[k]) if values is not None and result.feasible[k] else math.nan
        out[column] = v if math.isfinite(v) else None
    out["tracking"] = float(result.tracking[k])
    out["feasible"] = bool(result.feasible[k])
    out["reason"] = result.reason[k] or None
    return out


def _plan_json(result: Any, files: dict[str, str]) -> dict[str, Any]:
    """The --json object of plan: files, the best candidate, every candidate's cost,
    the objective and (for the effects objective) the effects' expected errors."""
    from omavctl.planning.effects_forecast import effects_summary
    from omavctl.planning.envelope import envelope, envelope_warnings
    from omavctl.planning.expectation import expectation

    summary = effects_summary(result)
    from omavctl.planning.report import task_warning as _task_warning

    task_warning = _task_warning(result)
    return {
        "command": "plan",
        "files": files,
        "best": int(result.best),
        "best_cost": float(result.cost[result.best]),
        "task_cost": float(result.task_cost),
        "prior_variance": float(result.prior_variance),
        "epsilon": float(result.epsilon),
        "region": result.region,
        "rejected": int((~result.feasible).sum()),
        "max_tilt_deg": float(result.max_tilt_deg),
        "candidates": [_candidate_json(result, k) for k in range(len(result.cost))],
        "notes": list(result.notes),
        # what the terminal prints as "warning:": read before flying the reference
        "warnings": ([task_warning] if task_warning else []) + envelope_warnings(result),
        "objective": result.objective,
        "expected": expectation(result),
        "envelope": envelope(result.best_trajectory()) if result.best >= 0 else None,
        "task_envelope": envelope(result.task),
        "effects": {k: v for k, v in summary.items() if k != "lines"} if summary else None,
    }
