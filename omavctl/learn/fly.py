"""Fly a reference through the truth plant and write the flight log (``omavctl simulate``).

The lowest layer that can do it whole: the flight may have a learned residual
model in the loop (the controller inverts ``u + mu(u) = a*``), and reading that
model file belongs to :mod:`omavctl.learn`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from omavctl.base.atomic import check_outputs
from omavctl.base.errors import OmavctlError
from omavctl.learn.model import check_vehicle, load_model
from omavctl.logs import write_log
from omavctl.sim.plant import SimulationResult, load_truth, simulate
from omavctl.sim.trajectory import read_trajectory
from omavctl.vehicle import load_vehicle

__all__ = ["PHYSICS_RATES", "run_simulation"]

#: Integration rates of the truth plant that are accepted, Hz (lowest, highest).
PHYSICS_RATES = (1000.0, 100_000.0)


def run_simulation(
    reference: Path,
    out: Path,
    *,
    truth: Path | None = None,
    vehicle: Path | None = None,
    model: Path | None = None,
    seed: int | None = None,
    physics_rate: float = 1000.0,
    progress: Callable[[float], None] | None = None,
) -> SimulationResult:
    """Read the inputs, check them, fly ``reference`` and write the log to ``out``.

    The log's kind follows ``out``'s name (:func:`omavctl.logs.write_log`); a
    directory is allowed as output when ``out`` has no suffix (a ROS 2 bag).
    ``progress`` gets the flown fraction of the reference.
    """
    check_outputs([reference, truth, vehicle, model], [out], directory_ok=not out.suffix)
    veh = load_vehicle(vehicle)
    ref = read_trajectory(reference)
    plant = load_truth(truth, veh)
    residual = None
    if model is not None:
        residual = load_model(model)
        check_vehicle(residual, veh, model)
    low, high = PHYSICS_RATES
    if not low <= physics_rate <= high:
        raise OmavctlError(f"--physics-rate must be 1000 to 100000 Hz, got {physics_rate:g}")
    result = simulate(
        ref, veh, plant, model=residual, seed=seed, physics_rate=physics_rate, progress=progress
    )
    write_log(out, result.log, topics=veh.topics)
    return result
