"""Fit flight logs into a model file (``omavctl fit``): file names in, model file out.

Two steps, so that a caller can show progress only while the model is fitted:
:func:`prepare_fit` refuses a bad output before any work and reads the time
window and the vehicle; :meth:`FitJob.run` fits the model
(:func:`omavctl.learn.fit.fit_model`, which reads the logs) and writes it
(:func:`omavctl.learn.model.save_model`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from omavctl.base.atomic import check_outputs
from omavctl.base.errors import OutputError
from omavctl.base.replace import is_npz_with, refuse_replacing
from omavctl.learn.fit import FitResult, Progress, fit_model
from omavctl.learn.model import SCHEMA_NAME
from omavctl.learn.model_file import check_model_paths, save_model
from omavctl.logs import parse_time_window
from omavctl.sim.trajectory import refuse_as_logs
from omavctl.vehicle import Vehicle, load_vehicle

__all__ = ["FitJob", "effect_names", "is_model_file", "prepare_fit"]


def is_model_file(path: Path) -> bool:
    """Whether ``path`` is a model file ``fit`` wrote (its ``schema`` array names
    ``omavctl.model``): what ``fit --out`` may replace."""
    return is_npz_with(path, {"schema"}, SCHEMA_NAME)


def effect_names(text: str | None) -> list[str] | None:
    """The effect names of a comma-separated ``--effects`` value (None: not given)."""
    return None if text is None else [e.strip() for e in text.split(",") if e.strip()]


@dataclass(frozen=True)
class FitJob:
    """A fit ready to run: the output checked, the vehicle and the time window read.

    The options are those of :func:`omavctl.learn.fit.fit_model`.
    """

    logs: Sequence[Path]
    out: Path
    vehicle: Vehicle
    time_window: tuple[float | None, float | None] | None
    effects: Sequence[str] | None
    prior: Path | None
    points: int
    sg_window: int
    sg_order: int
    features: str
    restarts: int
    seed: int

    def run(self, progress: Progress | None = None) -> FitResult:
        """Fit the model and write it to ``out`` (.npz); ``progress`` gets (stage, fraction)."""
        result = fit_model(
            self.logs,
            vehicle=self.vehicle,
            effects=self.effects,
            points=self.points,
            prior=self.prior,
            sg_window=self.sg_window,
            sg_order=self.sg_order,
            features=self.features,
            seed=self.seed,
            restarts=self.restarts,
            progress=progress,
            time_window=self.time_window,
        )
        save_model(self.out, result.model)
        return result


def prepare_fit(
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
) -> FitJob:
    """Refuse a bad ``out``, parse ``time_window`` (the ``START:END`` text of
    ``--time-window``, :func:`omavctl.logs.parse_time_window`) and read the vehicle."""
    check_model_paths([prior])
    check_outputs([*logs, vehicle, prior], [out])
    refuse_replacing(out, is_model_file, "an omavctl model")
    if Path(out).suffix.lower() != ".npz":  # evaluate, plan and simulate read MODEL.npz
        raise OutputError("a model is written as .npz: give a name ending in .npz", out)
    refuse_as_logs(list(logs))
    window = parse_time_window(time_window) if time_window else None
    veh = load_vehicle(vehicle)
    return FitJob(
        logs=logs,
        out=out,
        vehicle=veh,
        time_window=window,
        effects=effects,
        prior=prior,
        points=points,
        sg_window=sg_window,
        sg_order=sg_order,
        features=features,
        restarts=restarts,
        seed=seed,
    )
