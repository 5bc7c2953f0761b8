"""Flags about the model files themselves, before any number of an evaluation.

A model with an effect of the measured force (``drag_moment``) records the
accelerometer lever arm its fit logs' force was taken less of
(``provenance.imu_lever``, docs/schemas.md; :mod:`omavctl.learn.imu_lever`). A file
written by an omavctl that did not record it may have fitted that effect on the raw
force, lever term and all (docs/horizons.md, "The accelerometer's lever arm"):
evaluated as it is, its effect and its open-loop horizons are of that force.
:func:`lever_flags` says so, one flag per such file, naming it and what to do (refit);
the file is still evaluated.

A file written before the rotors' thrust tolerance (vehicle ``rotor.thrust_tolerance``,
session 19) holds a vehicle without it, read as 0: every 95 % interval the diagnosis
quotes for it (estimated as ``fit --effects`` would, with the model's vehicle) then has
no systematic part, narrower than a refit's. :func:`spread_flags` says so, one flag per
such file whose vehicle has rotor thrusts to spread.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omavctl.learn.model import ResidualGP
from omavctl.physics.effects import get_effect

__all__ = ["file_flags", "lever_flags", "spread_flags"]


def file_flags(models: Sequence[ResidualGP], paths: Sequence[str | Path]) -> list[dict[str, Any]]:
    """Every flag about the model files: :func:`lever_flags`, then :func:`spread_flags`."""
    return lever_flags(models, paths) + spread_flags(models, paths)


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


def spread_flags(models: Sequence[ResidualGP], paths: Sequence[str | Path]) -> list[dict[str, Any]]:
    """A ``no_thrust_tolerance`` flag (``axis`` and ``value`` null) per model read from
    ``paths`` (as given) whose vehicle tree has no ``rotor.thrust_tolerance`` (a file
    written before session 19) and has rotor thrusts the spread acts through (a rotor
    list, or the omav's commands in N and N m); none for every other model, nor for a
    vehicle that sets the tolerance, to 0 included."""
    out: list[dict[str, Any]] = []
    for model, path in zip(models, paths, strict=True):
        vehicle = model.vehicle
        rotor = vehicle.tree.get("rotor") if isinstance(vehicle.tree, dict) else None
        if isinstance(rotor, dict) and "thrust_tolerance" in rotor:
            continue
        if vehicle.motors is None and (vehicle.torque_normalised or vehicle.force_normalised):
            continue  # no thrusts to spread: no systematic part on any version
        out.append(
            {
                "code": "no_thrust_tolerance",
                "axis": None,
                "value": None,
                "message": (
                    f"{path}: written before omavctl read the rotors' thrust tolerance (its "
                    "vehicle has no rotor.thrust_tolerance), so the 95 % intervals quoted "
                    "for it hold no thrust-spread part and may be too narrow: refit the "
                    "model (omavctl fit on the same logs) to add it"
                ),
            }
        )
    return out
