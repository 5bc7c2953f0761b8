"""Flags about the model files themselves, before any number of an evaluation.

A model with an effect of the measured force (``drag_moment``) records the
accelerometer lever arm its fit logs' force was taken less of
(``provenance.imu_lever``, docs/schemas.md; :mod:`omavctl.learn.imu_lever`). A file
written by an omavctl that did not record it may have fitted that effect on the raw
force, lever term and all (docs/horizons.md, "The accelerometer's lever arm"):
evaluated as it is, its effect and its open-loop horizons are of that force.
:func:`lever_flags` says so, one flag per such file, naming it and what to do (refit);
the file is still evaluated.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omavctl.learn.model import ResidualGP
from omavctl.physics.effects import get_effect

__all__ = ["lever_flags"]


def lever_flags(models: Sequence[ResidualGP], paths: Sequence[str | Path]) -> list[dict[str, Any]]:
    """A ``no_imu_lever`` flag (``axis`` and ``value`` null) per model read from
    ``paths`` (as given) whose effects hold an effect of the measured force and whose
    provenance has no ``imu_lever`` record; none for every other model."""
    out: list[dict[str, Any]] = []
    for model, path in zip(models, paths, strict=True):
        names = list(model.effects)
        measured = [n for n in names if get_effect(n).measured_state]
        if not measured or "imu_lever" in model.provenance:
            continue
        which = ", ".join(measured)
        out.append(
            {
                "code": "no_imu_lever",
                "axis": None,
                "value": None,
                "message": (
                    f"{path}: {which} was fitted before omavctl recorded the accelerometer's "
                    "lever arm (no provenance.imu_lever), so it may hold the lever's "
                    "α × r + ω × (ω × r) as well as the force's moment: refit the model "
                    f"(omavctl fit on the same logs with --effects {','.join(names)}), which "
                    "removes the lever where the log pins it down, before trusting its numbers"
                ),
            }
        )
    return out
