"""Text outputs of the planner: the ``--scores`` CSV, and writing it with the reference."""

from __future__ import annotations

import hashlib
import io
import math
from collections import Counter
from pathlib import Path

import numpy as np

from omavctl.base.atomic import atomic_paths
from omavctl.base.errors import OmavctlError
from omavctl.planning.candidates import coefficient_names
from omavctl.planning.planner import PlanResult
from omavctl.sim.trajectory import Trajectory, format_trajectory

__all__ = ["METRIC_COLUMNS", "format_scores", "is_scores_file", "task_warning", "write_plan"]

#: Columns after ``cost``: every objective's number for every candidate (empty when
#: not computed for this model, or infeasible), whichever objective ranks.
METRIC_COLUMNS = {
    "variance_cost": "variance",
    "effects_cost": "effects",
    "effects_rel_se": "effects_rel_se",
    "effects_max_correlation": "effects_correlation",
}


def _num(v: float) -> str:
    """A finite number as text; empty for NaN or infinity (never written)."""
    return f"{v:.9g}" if math.isfinite(v) else ""


def is_scores_file(path: Path) -> bool:
    """Whether ``path`` is a scores CSV :func:`format_scores` wrote (its first line
    starts ``candidate,f_x1,``): what ``plan --scores`` may replace."""
    mark = b"candidate,f_x1,"
    with path.open("rb") as fh:
        return fh.read(len(mark)) == mark


def format_scores(result: PlanResult, reference_sha256: str | None = None) -> str:
    """CSV: candidate id, the 3*2*P coefficients (Hz and rad/s^2), cost (of the ranking
    objective), :data:`METRIC_COLUMNS`, tracking, feasible, reason, generation (of the
    search that proposed it; 0 for random) and, when given, the sha256 of the reference
    CSV written with it (same in every row).

    Infeasible candidates have an empty cost. Deterministic for the same result.
    """
    k_count, _, p_count, _ = result.coefficients.shape
    names = coefficient_names(p_count)
    buf = io.StringIO()
    header = ["candidate", *names, "cost", *METRIC_COLUMNS, "tracking", "feasible", "reason"]
    header.append("generation")
    if reference_sha256 is not None:
        header.append("reference_sha256")
    buf.write(",".join(header) + "\n")
    for k in range(k_count):
        coeffs = [f"{v:.9g}" for v in result.coefficients[k].reshape(-1)]
        cost = _num(result.cost[k]) if result.feasible[k] else ""
        reason = result.reason[k].replace(",", ";").replace("\n", " ")
        extra = [
            _num(result.metrics[key][k]) if key in result.metrics and result.feasible[k] else ""
            for key in METRIC_COLUMNS.values()
        ]
        row = [str(k), *coeffs, cost, *extra, _num(result.tracking[k])]
        row += ["true" if result.feasible[k] else "false", reason, str(result.generation[k])]
        if reference_sha256 is not None:
            row.append(reference_sha256)
        buf.write(",".join(row) + "\n")
    return buf.getvalue()


def task_warning(result: PlanResult) -> str | None:
    """The warning when no candidate beats flying the task again, else None (said by
    the terminal, the --json ``warnings`` and the plan report alike)."""
    best_cost = float(result.cost[result.best])
    if best_cost < result.task_cost:
        return None
    searched = result.generation.size and result.generation.max() > 0
    return (
        f"no candidate is more informative than flying the task again (best "
        f"{result.versus_task(best_cost):+.1f}% vs the task): fly the task, or try more "
        f"--candidates{'' if searched else ' or --search cem'}"
    )


def rejection_tally(result: PlanResult) -> str:
    """'N reason, M reason' over the rejected candidates, most frequent first."""
    tally = Counter(r for reason in result.reason for r in reason.split(", ") if r)
    return ", ".join(f"{n} {r}" for r, n in tally.most_common())


def no_feasible_candidate(result: PlanResult, task: Path, scores: Path | None) -> OmavctlError:
    """The error of a plan none of whose candidates is feasible (``result.best`` < 0),
    after writing the scores (every candidate's reason) when asked for: how many
    candidates broke which limit, and whether the task itself does."""
    if scores is not None:
        with atomic_paths(scores) as (tmp,):
            tmp.write_text(format_scores(result))
    text = (
        f"no feasible candidate for this task ({len(result.reason)} candidates: "
        f"{rejection_tally(result)})"
    )
    task_notes = [n for n in result.notes if n.startswith("the task itself")]
    if task_notes:
        text += f"; {task_notes[0]}: are the model and --vehicle this vehicle's?"
    text += (
        f"; every candidate's reason is in {scores}"
        if scores is not None
        else "; --scores FILE lists every candidate's reason"
    )
    remedy = ": lower --amplitude or --max-freq"
    if result.tilt_by_margin and any("attitude limit" in r for r in result.reason):
        remedy += (
            f" (or raise --tilt-margin: the attitude limit was {result.max_tilt_deg:.0f} deg, "
            "the task's largest tilt plus the margin)"
        )
    return OmavctlError(text + remedy, task)


def write_plan(out: Path, best: Trajectory, result: PlanResult, scores: Path | None) -> None:
    """Write the planned reference and (optionally) the scores together.

    The scores name the sha256 of the reference CSV in every row; both files are
    renamed into place together (reference first), so a pair from different runs
    can only be left by ``kill -9`` between two renames, and is then recognisable.
    """
    if not np.all(np.isfinite(best.data)) or not np.all(np.isfinite(result.coefficients)):
        raise OmavctlError("the planned reference is not finite; try a smaller --amplitude")
    text = format_trajectory(best)
    if scores is None:
        with atomic_paths(out) as (tmp,):
            tmp.write_text(text)
        return
    digest = hashlib.sha256(text.encode()).hexdigest()
    with atomic_paths(out, scores) as (tmp, tmp_scores):
        tmp.write_text(text)
        tmp_scores.write_text(format_scores(result, digest))
