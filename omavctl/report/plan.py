"""``plan --report``: a self-contained HTML page of a plan.

Two figures: the task and the planned (most informative) reference over time
(roll, pitch, yaw in deg and the angular-acceleration reference in rad/s^2),
and every candidate's cost (mean posterior variance after its data, lower is
more informative) against the task's own cost, infeasible candidates marked.
Plus a table of the best candidates. Same HTML writer and CSS as the
evaluation report.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from omavctl.base.atomic import atomic_path
from omavctl.report.document import Cell, Document, FigureBlock, Heading, Para, Table, to_html
from omavctl.report.figures import png, style

if TYPE_CHECKING:
    from omavctl.planning.planner import PlanResult
    from omavctl.sim.trajectory import Trajectory

__all__ = ["plan_document", "write_plan_report"]

ANGLES = ("roll", "pitch", "yaw")


def reference_figure(task: Trajectory, best: Trajectory, label: str) -> bytes:
    """Task vs planned reference: attitude (deg) and angular acceleration (rad/s^2)."""
    from matplotlib.figure import Figure

    with style():
        fig = Figure(figsize=(10, 6.4), dpi=100, layout="constrained")
        axs = fig.subplots(3, 2, sharex=True)
        for i, name in enumerate(ANGLES):
            left, right = axs[i, 0], axs[i, 1]
            left.plot(task.t, np.degrees(task.euler[:, i]), color="0.45", lw=1.2, ls="--",
                      label="task")  # fmt: skip
            left.plot(best.t, np.degrees(best.euler[:, i]), color="C0", lw=1.0, label=label)
            left.set_ylabel(f"{name}, deg")
            right.plot(task.t, task.angular_acceleration[:, i], color="0.45", lw=1.2, ls="--")
            right.plot(best.t, best.angular_acceleration[:, i], color="C0", lw=1.0)
            right.set_ylabel(f"dw{'xyz'[i]}, rad/s²")
            for ax in (left, right):
                ax.grid(True, lw=0.3, alpha=0.6)
        axs[-1, 0].set_xlabel("time, s")
        axs[-1, 1].set_xlabel("time, s")
        fig.legend(*axs[0, 0].get_legend_handles_labels(), loc="outside upper center", ncol=2,
                   fontsize=8, frameon=False)  # fmt: skip
        return png(fig)


def cost_figure(result: PlanResult) -> bytes:
    """Every candidate's cost, sorted, with the task's cost; infeasible ones marked."""
    from matplotlib.figure import Figure

    k = np.arange(result.cost.size)
    feasible = np.asarray(result.feasible, bool)
    order = np.concatenate([k[feasible][np.argsort(result.cost[feasible])], k[~feasible]])
    with style():
        fig = Figure(figsize=(10, 3.8), dpi=100, layout="constrained")
        ax = fig.subplots()
        # the effects cost (-log det) is negative: show its expected relative SE instead
        effects = result.objective == "effects" and "effects_rel_se" in result.metrics
        value = result.metrics["effects_rel_se"] if effects else result.cost
        task = float(result.task_metrics["effects_rel_se"]) if effects else result.task_cost
        finite = value[feasible]
        top = float(max(finite.max(initial=0.0), task)) * 1.15 or 1.0
        for pos, c in enumerate(order):
            if feasible[c]:
                colour = "C3" if c == result.best else "C0"
                ax.bar(pos, value[c], color=colour, width=0.7)
            else:  # full height, so that it does not read as a small (good) cost
                ax.axvspan(pos - 0.35, pos + 0.35, facecolor="0.93", edgecolor="0.6", hatch="xx")
        ax.axhline(task, color="k", ls="--", lw=1.0)
        ax.set_xticks(np.arange(order.size), [str(c) for c in order], fontsize=7)
        ax.set_xlabel("candidate (sorted by cost; hatched: rejected)")
        ax.set_ylabel("expected relative SE (geo. mean)" if effects else "cost, (rad/s²)²")
        ax.set_ylim(0, top)
        ax.grid(True, axis="y", lw=0.3, alpha=0.6)
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        handles = [
            Patch(color="C3", label=f"chosen (candidate {result.best})"),
            Patch(color="C0", label="feasible candidate"),
            Patch(facecolor="0.93", edgecolor="0.6", hatch="xx", label="rejected (no cost)"),
            Line2D([], [], color="k", ls="--", label="the task itself"),
        ]
        fig.legend(handles=handles, loc="outside upper center", ncol=4, fontsize=8, frameon=False)
        return png(fig)


def plan_document(task: Trajectory, result: PlanResult) -> str:
    """The plan report as an HTML string."""
    from omavctl.planning.effects_forecast import effects_summary
    from omavctl.planning.envelope import envelope_lines
    from omavctl.planning.report import task_warning

    best = result.best_trajectory()
    gain = result.versus_task(float(result.cost[result.best]))
    doc = Document("omavctl plan")
    doc.add(Heading(1, "omavctl plan"))
    what = (
        "the GP's mean posterior variance at test points of the region after adding the "
        "flight's data, (rad/s²)²"
        if result.objective == "variance"
        else "-log det of the information about the effects' parameters after the flight "
        "(vs task: ratio of geometric-mean standard errors)"
    )
    # the effects objective's "vs task" is of the standard errors, not of its -log det
    # cost (a new user read "cost -76.21, -77.9 % against ... (-52.09)")
    versus = "its cost" if result.objective == "variance" else "its standard errors"
    doc.add(
        Para(
            f"Most informative reference: candidate {result.best}, cost "
            f"{result.cost[result.best]:.4g} against the task's {result.task_cost:.4g}; "
            f"{versus} {gain:+.1f} % against flying the task itself; "
            f"{int((~result.feasible).sum())} of "
            f"{result.cost.size} candidates rejected. The cost ({result.objective}) is {what}: "
            "lower means the flight teaches the model more."
        )
    )
    warning = task_warning(result)  # as the terminal says it (envelope warnings below)
    if warning:
        doc.add(Para(f"warning: {warning}"))
    summary = effects_summary(result)
    for line in summary["lines"] if summary else []:
        doc.add(Para(line.strip()))
    from omavctl.planning.expectation import expectation_lines

    for line in expectation_lines(result) + envelope_lines(result):
        doc.add(Para(line))
    doc.add(
        FigureBlock(
            reference_figure(task, best, f"planned (candidate {result.best})"),
            "task and planned reference",
            "The task (dashed) and the planned reference: attitude and angular acceleration.",
        ),
        FigureBlock(
            cost_figure(result),
            "candidates' costs",
            "Every candidate's cost against the task's own (dashed line).",
        ),
    )
    order = [int(c) for c in np.argsort(result.cost) if result.feasible[c]][:10]
    rows: list[list[Cell]] = [
        [str(c), f"{result.cost[c]:.4g}", f"{result.versus_task(float(result.cost[c])):+.1f} %",
         f"{result.tracking[c]:.3f}"]
        for c in order
    ]  # fmt: skip
    head = "cost vs task" if result.objective == "variance" else "std error vs task"
    doc.add(Table(["candidate", "cost", f"{head} (- better)", "tracking, rad/s²"], rows))
    for note in result.notes:
        doc.add(Para(f"note: {note}", note=True))
    return to_html(doc)


def write_plan_report(out: str | Path, task: Trajectory, result: PlanResult) -> None:
    """Write the plan report atomically."""
    text = plan_document(task, result)
    with atomic_path(Path(out)) as tmp:
        tmp.write_bytes(text.encode("utf-8"))
