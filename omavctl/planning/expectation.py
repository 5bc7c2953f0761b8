"""What the model expects the planned flight to bring, before it is flown.

The variance objective's cost of a flight is the mean variance of the model's band
over the region's test points once the flight's points are in: for a calibrated
band, the expected squared error of the refitted model's mean there. Its square
root is the RMS error the model expects after that flight, so the model expects the
planned flight to lower the error, against another flight, by ``1 - sqrt(cost_plan /
cost_other)``:

* against flying the task again: the task's own cost (its simulations scored like a
  candidate);
* against a random candidate of the same pool: every other feasible candidate is
  such a draw, so the gains against them are the distribution of that gain; the
  median and the 10-90 % range are stated, and "cannot tell" below
  :data:`MIN_OTHERS` feasible others.

These are the model's expectations: they hold as far as its band is calibrated and
the refit keeps the flight's points as the objective assumes (what a refit realised
on the informative-flight benchmark: docs/informative.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["MIN_OTHERS", "expectation", "expectation_lines"]

#: Fewest other feasible candidates for a statement against a random one
MIN_OTHERS = 5


def _gain(plan_cost: float, other: np.ndarray) -> np.ndarray:
    """Per cent by which the expected RMS error falls: 100 (1 - sqrt(plan / other))."""
    return 100.0 * (1.0 - np.sqrt(plan_cost / np.asarray(other, float)))


def expectation(result: Any) -> dict[str, Any] | None:
    """The model's expected error fall of the planned flight (module docstring), for
    the variance objective with a feasible best candidate (else None):
    ``error_now``, ``error_task_again``, ``error_planned`` (RMS, rad/s^2, over the
    region's test points), ``vs_task_again`` (%), ``vs_random`` {median, low, high}
    (%; None: cannot tell) and ``others`` (feasible candidates it is drawn from)."""
    if result.objective != "variance" or result.best < 0:
        return None
    best = float(result.cost[result.best])
    if not (best > 0 and result.task_cost > 0):
        return None
    others = np.flatnonzero(result.feasible & np.isfinite(result.cost))
    others = others[(others != result.best) & (result.cost[others] > 0)]
    vs_random = None
    if others.size >= MIN_OTHERS:
        g = _gain(best, result.cost[others])
        vs_random = {
            "median": float(np.median(g)),
            "low": float(np.percentile(g, 10)),
            "high": float(np.percentile(g, 90)),
        }
    return {
        "error_now": math.sqrt(max(result.prior_variance, 0.0)),
        "error_task_again": math.sqrt(result.task_cost),
        "error_planned": math.sqrt(best),
        "vs_task_again": float(_gain(best, np.array([result.task_cost]))[0]),
        "vs_random": vs_random,
        "others": int(others.size),
    }


def expectation_lines(result: Any) -> list[str]:
    """The expectation as the terminal says it (empty when there is none)."""
    e = expectation(result)
    if e is None:
        return []
    r = e["vs_random"]
    if r is None:
        random = f"against a random candidate: cannot tell ({e['others']} other feasible)"
    else:
        # the table's sign (- better): a fall of the error is negative here too
        random = (
            f"against a random candidate of the pool {-r['median']:+.0f} % (median; 80 % "
            f"of the {e['others']} others between {-r['high']:+.0f} and {-r['low']:+.0f} %)"
        )
    return [
        "expected by the model: RMS error of its mean over the region (against the true "
        "acceleration: evaluate's RMSE adds the log's measurement noise) "
        f"{e['error_now']:.3g} rad/s^2 now, "
        f"{e['error_task_again']:.3g} after flying the task again, {e['error_planned']:.3g} "
        f"after the planned flight: {-e['vs_task_again']:+.0f} % (- better, as in the "
        "table, whose cost is the square of this error: its figure is larger) against the "
        "task again; "
        f"{random}. The model's band, not a promise: what refits realised is in "
        "docs/informative.md"
    ]
