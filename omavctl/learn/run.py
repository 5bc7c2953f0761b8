"""Fit flight logs into a model file (``omavctl fit``): file names in, model file out.

:func:`run_fit` does the command's work in the order the command checks it:
the outputs are refused before any work, then the time window, the vehicle and
the logs are read, the model is fitted (:func:`omavctl.learn.fit.fit_model`)
and written (:func:`omavctl.learn.model.save_model`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from omavctl.base.atomic import check_outputs
from omavctl.learn.fit import FitResult, Progress, fit_model
from omavctl.learn.model import save_model
from omavctl.logs import parse_time_window
from omavctl.vehicle import load_vehicle

__all__ = ["effect_names", "run_fit"]


def effect_names(text: str | None) -> list[str] | None:
    """The effect names of a comma-separated ``--effects`` value (None: not given)."""
    return None if text is None else [e.strip() for e in text.split(",") if e.strip()]


def run_fit(
    logs: Sequence[Path],
    out: Path,
    *,
    vehicle: Path | None = None,
    effects: Sequence[str] | None = None,
    prior: Path | None = None,
    time_window: str | None = None,
    points: int,
    sg_window: int,
    sg_order: int,
    features: str,
    restarts: int,
    seed: int,
    progress: Progress | None = None,
) -> FitResult:
    """Fit a model from ``logs`` and write it to ``out`` (.npz); returns the fit.

    ``time_window`` is the ``START:END`` text of ``--time-window``
    (:func:`omavctl.logs.parse_time_window`); the other options are those of
    :func:`omavctl.learn.fit.fit_model`.
    """
    check_outputs([*logs, vehicle, prior], [out])
    window = parse_time_window(time_window) if time_window else None
    veh = load_vehicle(vehicle)
    result = fit_model(
        logs,
        vehicle=veh,
        effects=effects,
        points=points,
        prior=prior,
        sg_window=sg_window,
        sg_order=sg_order,
        features=features,
        seed=seed,
        restarts=restarts,
        progress=progress,
        time_window=window,
    )
    save_model(out, result.model)
    return result
