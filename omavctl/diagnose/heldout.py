"""Whether an evaluation's logs are held out: the ``training_data`` flags of a model
evaluated on (part of) a log it was fitted on."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from omavctl.learn.flights import training_logs
from omavctl.learn.model import ResidualGP

__all__ = ["on_what", "overlap", "training_data_flags"]


def overlap(fitted: Any, window: tuple[float | None, float | None] | None) -> bool:
    """Whether a fit's time window (list [start, end] or None) and an evaluation's
    overlap (None: the whole log)."""
    fit_lo, fit_hi = fitted if isinstance(fitted, list) and len(fitted) == 2 else (None, None)
    lo, hi = window if window is not None else (None, None)
    start = max(float(fit_lo or 0.0), float(lo or 0.0))
    end = min(math.inf if fit_hi is None else float(fit_hi), math.inf if hi is None else hi)
    return start < end


def training_data_flags(
    model: ResidualGP,
    logs_json: Sequence[Mapping[str, Any]],
    time_window: tuple[float | None, float | None] | None,
) -> list[dict[str, Any]]:
    """A ``training_data`` flag per log the first model holds points of (the same file,
    by sha256, in an overlapping time window; also a prior's): not held out."""
    out = []
    trained = training_logs(model.provenance)
    for lj in logs_json:
        windows = [t["time_window"] for t in trained if t["sha256"] == lj.get("sha256")]
        hits = [w for w in windows if overlap(w, time_window)]
        if not hits:
            continue
        whole = all(w is None for w in hits) and time_window is None
        out.append(
            {
                "code": "training_data",
                "axis": None,
                "value": None,
                "message": f"{lj['name']}: the model was fitted on this log"
                + ("" if whole else " in an overlapping time window")
                + ": its errors here are not those of a flight it has not seen",
            }
        )
    return out


def on_what(tree: Mapping[str, Any]) -> str:
    """Where the diagnosis measured the model's error: held-out data, or (the
    ``training_data`` flag) held-out blocks of a log the model was fitted on."""
    flags = [f for f in tree.get("flags") or [] if isinstance(f, Mapping)]
    if any(f.get("code") == "training_data" for f in flags):
        return "on this log, which it was fitted on (training data, not held out)"
    return "on held-out data"
