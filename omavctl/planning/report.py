"""Text outputs of the planner: the ``--scores`` CSV."""

from __future__ import annotations

import io

from omavctl.planning.candidates import coefficient_names
from omavctl.planning.planner import PlanResult

__all__ = ["format_scores"]


def format_scores(result: PlanResult) -> str:
    """CSV: candidate id, the 3*2*P coefficients (Hz and rad/s^2), cost, tracking,
    feasible, reason, generation (of the search that proposed it; 0 for random).

    Infeasible candidates have an empty cost. Deterministic for the same result.
    """
    k_count, _, p_count, _ = result.coefficients.shape
    names = coefficient_names(p_count)
    buf = io.StringIO()
    buf.write(
        ",".join(["candidate", *names, "cost", "tracking", "feasible", "reason", "generation"])
        + "\n"
    )
    for k in range(k_count):
        coeffs = [f"{v:.9g}" for v in result.coefficients[k].reshape(-1)]
        cost = f"{result.cost[k]:.9g}" if result.feasible[k] else ""
        reason = result.reason[k].replace(",", ";")
        row = [str(k), *coeffs, cost, f"{result.tracking[k]:.9g}"]
        row += ["true" if result.feasible[k] else "false", reason, str(result.generation[k])]
        buf.write(",".join(row) + "\n")
    return buf.getvalue()
