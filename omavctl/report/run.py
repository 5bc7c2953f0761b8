"""File-to-file runs of ``omavctl evaluate`` and ``omavctl report``.

Both live in the report layer because their outputs are written by it: the
MCAP of an evaluation's time series (:mod:`omavctl.report.series_mcap`) and the
HTML/Markdown report (:mod:`omavctl.report.evaluation`). Outputs are refused
before any work (:func:`omavctl.base.atomic.check_outputs`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from omavctl.base.atomic import check_outputs
from omavctl.base.errors import ConfigError
from omavctl.base.replace import is_report_file, refuse_replacing
from omavctl.diagnose.evalio import (
    is_evaluation_file,
    is_series_file,
    series_path,
    write_evaluation,
)
from omavctl.diagnose.evaluate import EvalResult, evaluate
from omavctl.diagnose.horizons import DEFAULT_HORIZONS, parse_horizons
from omavctl.learn.model_file import check_model_paths
from omavctl.logs import parse_time_window
from omavctl.logs.read import detect_format
from omavctl.report.evaluation import ReportSummary, write_report
from omavctl.report.series_mcap import is_series_mcap, mcap_path, write_series_mcap
from omavctl.sim.trajectory import refuse_as_logs

__all__ = ["EvaluationRun", "default_evaluation_path", "run_evaluation", "run_report"]


@dataclass(frozen=True)
class EvaluationRun:
    """An evaluation and the files it was written to (evaluation, series, mcap)."""

    result: EvalResult
    files: dict[str, Path]


def default_evaluation_path(models: Sequence[Path]) -> Path:
    """``<model stem>.eval.json`` beside the first model."""
    return models[0].with_name(models[0].with_suffix("").name + ".eval.json")


def run_evaluation(
    logs: Sequence[Path],
    models: Sequence[Path],
    out: Path | None = None,
    mcap: Path | None = None,
    time_window: str | None = None,
    horizons: str | None = None,
    horizon_stride: int = 1,
) -> EvaluationRun:
    """Evaluate ``models`` on ``logs`` and write the evaluation JSON, its series and MCAP.

    ``out`` None: :func:`default_evaluation_path`; ``mcap`` None: beside ``out``
    (:func:`omavctl.report.series_mcap.mcap_path`); ``time_window`` is the
    ``START:END`` text of ``--time-window``; ``horizons`` the text of ``--horizons``
    (None: 0.01, 0.1 and 0.5 s) and ``horizon_stride`` the samples between starts.
    """
    window = parse_time_window(time_window) if time_window else None
    spans = parse_horizons(horizons) if horizons is not None else DEFAULT_HORIZONS
    if horizon_stride < 1:
        raise ConfigError(f"--horizon-stride: {horizon_stride} is not a positive number of samples")
    check_model_paths(models)
    for log in logs:  # a folder that is no log is said as such, before its outputs
        if Path(log).is_dir():
            detect_format(Path(log))
    if out is None and models:
        out = default_evaluation_path(models)
    assert out is not None
    mcap_out = mcap if mcap is not None else mcap_path(out)
    check_outputs([*logs, *models], [out, series_path(out), mcap_out])
    refuse_replacing(out, is_evaluation_file, "an omavctl evaluation")
    refuse_replacing(series_path(out), is_series_file, "an evaluation's series")
    refuse_replacing(mcap_out, is_series_mcap, "an evaluation's series MCAP")
    refuse_as_logs(list(logs))
    result = evaluate(
        models, logs, time_window=window, horizons=spans, horizon_stride=horizon_stride
    )
    write_evaluation(out, result)
    write_series_mcap(mcap_out, result.tree, result.series)
    files = {"evaluation": out, "series": series_path(out), "mcap": mcap_out}
    return EvaluationRun(result, files)


def run_report(evaluations: Sequence[Path], out: Path, fmt: str | None = None) -> ReportSummary:
    """Render the evaluation files (with their series beside them) as one report at ``out``."""
    check_outputs([*evaluations, *(series_path(e) for e in evaluations)], [out])
    refuse_replacing(out, is_report_file, "an omavctl report")
    return write_report(evaluations, out, fmt)
