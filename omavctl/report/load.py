"""Reading evaluation files (``omavctl evaluate`` output) for the report.

:func:`load_for_report` loads an evaluation JSON and its time series and
:func:`check_evaluation` refuses, naming the file, what the report could not
show: missing or non-numeric metrics, no logs, missing or ragged series.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import OmavctlError
from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.numfmt import AXES, as_list, finite

__all__ = ["REQUIRED_SERIES", "Evaluation", "check_evaluation", "load_for_report"]

#: One evaluation to report: (JSON tree, time series, label shown in the report).
Evaluation = tuple[dict[str, Any], Mapping[str, np.ndarray], str]
#: Series every evaluation must carry, with their number of columns (0: 1-D).
REQUIRED_SERIES = {"t": 0, "log": 0, "measured": 3, "nominal": 3, "mean_0": 3, "std_0": 3}


def _bad_metric(block: Any, where: str) -> str | None:
    """Path of the first metric value in ``block`` ({prediction: {metric: {axis: value}}})
    that is neither a number nor null, else None."""
    if not isinstance(block, Mapping):
        return where
    for pred, metrics in block.items():
        if not isinstance(metrics, Mapping):
            return f"{where}.{pred}"
        for name, axes in metrics.items():
            if not isinstance(axes, Mapping):
                return f"{where}.{pred}.{name}"
            for axis, value in axes.items():
                if value is not None and not finite(value):
                    return f"{where}.{pred}.{name}.{axis}"
    return None


def check_evaluation(tree: Any, series: Mapping[str, np.ndarray], path: str | Path) -> None:
    """Raise :class:`OmavctlError` naming ``path`` unless ``tree`` and ``series``
    carry what the report needs (the ``load_evaluation`` schema check comes first)."""
    for pred in ("nominal", "model"):
        for axis in AXES:
            if not finite(_get(tree, "metrics", pred, "rmse", axis)):
                raise OmavctlError(
                    f"not an evaluation JSON: no number at 'metrics.{pred}.rmse.{axis}'", path
                )
    bad = _bad_metric(tree.get("metrics"), "metrics")
    for i, block in enumerate(as_list(tree.get("metrics_by_model") or [])):
        bad = bad or _bad_metric(block, f"metrics_by_model[{i}]")
    if bad:
        raise OmavctlError(f"not an evaluation JSON: '{bad}' is not a number", path)
    logs = tree.get("logs")
    if not isinstance(logs, list) or not logs or not all(isinstance(lg, Mapping) for lg in logs):
        raise OmavctlError("not an evaluation JSON: 'logs' is not a list of logs", path)
    n = None
    for key, cols in REQUIRED_SERIES.items():
        if key not in series:
            raise OmavctlError(f"its time series file lacks '{key}'", path)
        arr = np.asarray(series[key])
        shape_ok = arr.ndim == 1 if cols == 0 else (arr.ndim == 2 and arr.shape[1] == cols)
        if not shape_ok or not np.issubdtype(arr.dtype, np.number):
            raise OmavctlError(f"time series '{key}' has shape {arr.shape}", path)
        n = arr.shape[0] if n is None else n
        if arr.shape[0] != n:
            raise OmavctlError(f"time series '{key}' has {arr.shape[0]} samples, not {n}", path)
        if not np.all(np.isfinite(arr)):
            raise OmavctlError(f"time series '{key}' has non-finite values", path)
    log_id = np.asarray(series["log"])
    if n and (log_id.min() < 0 or log_id.max() >= len(logs)):
        raise OmavctlError("time series 'log' refers to logs the JSON does not list", path)


def load_for_report(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Load an evaluation JSON and its series and check them for the report."""
    from omavctl.diagnose.evalio import load_evaluation

    tree, series = load_evaluation(path)
    check_evaluation(tree, series, path)
    return tree, series
