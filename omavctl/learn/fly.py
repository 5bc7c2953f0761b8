"""Fly a reference through the truth plant and write the flight log (``omavctl simulate``).

The lowest layer that can do it whole: the flight may have a learned residual
model in the loop (the controller inverts ``u + mu(u) = a*``), and reading that
model file belongs to :mod:`omavctl.learn`.

Two steps, so that a caller can show progress only while the flight is flown:
:func:`prepare_simulation` refuses bad outputs and reads and checks every input;
:meth:`SimulationJob.run` flies and writes the log.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from omavctl.base.atomic import check_outputs
from omavctl.base.errors import OmavctlError
from omavctl.learn.model import ResidualGP
from omavctl.learn.model_file import check_model_paths, check_vehicle, load_model
from omavctl.logs import write_log
from omavctl.logs.write import check_log_replaceable, output_kind
from omavctl.sim.plant import SimulationResult, simulate
from omavctl.sim.trajectory import Trajectory, read_trajectory
from omavctl.sim.truth import TruthParameters, load_truth
from omavctl.vehicle import Vehicle, load_vehicle

__all__ = ["PHYSICS_RATES", "SimulationJob", "prepare_simulation"]

#: Integration rates of the truth plant that are accepted, Hz (lowest, highest).
PHYSICS_RATES = (1000.0, 100_000.0)


@dataclass(frozen=True)
class SimulationJob:
    """A flight ready to be flown: every input read and checked."""

    reference: Trajectory
    vehicle: Vehicle
    truth: TruthParameters
    model: ResidualGP | None
    seed: int | None
    physics_rate: float
    out: Path

    def run(self, progress: Callable[[float], None] | None = None) -> SimulationResult:
        """Fly the reference and write the log; ``progress`` gets the flown fraction."""
        result = simulate(
            self.reference,
            self.vehicle,
            self.truth,
            model=self.model,
            seed=self.seed,
            physics_rate=self.physics_rate,
            progress=progress,
        )
        write_log(self.out, result.log, topics=self.vehicle.topics)
        return result


def prepare_simulation(
    reference: Path,
    out: Path,
    *,
    truth: Path | None = None,
    vehicle: Path | None = None,
    model: Path | None = None,
    seed: int | None = None,
    physics_rate: float = 1000.0,
) -> SimulationJob:
    """Refuse a bad ``out``, read the reference, vehicle, truth and model, check them.

    The log's kind follows ``out``'s name (:func:`omavctl.logs.write_log`); a
    directory is allowed as output when ``out`` has no suffix (a ROS 2 bag). An
    existing ``out`` is replaced only when it is a log omavctl wrote
    (:func:`omavctl.logs.write.check_log_replaceable`).
    """
    check_model_paths([model])
    check_outputs([reference, truth, vehicle, model], [out], directory_ok=not out.suffix)
    output_kind(out)  # an unknown extension is refused before the flight is flown
    check_log_replaceable(out)  # a log simulate wrote may be replaced, no other file
    veh = load_vehicle(vehicle)
    veh.check_flyable("simulate", vehicle)
    ref = read_trajectory(reference)
    plant = load_truth(truth, veh)
    residual = None
    if model is not None:
        residual = load_model(model)
        check_vehicle(residual, veh, model)
    low, high = PHYSICS_RATES
    if not low <= physics_rate <= high:
        raise OmavctlError(f"--physics-rate must be 1000 to 100000 Hz, got {physics_rate:g}")
    return SimulationJob(ref, veh, plant, residual, seed, physics_rate, out)
