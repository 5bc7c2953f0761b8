"""The flights ``fit`` learns from: read, aligned, and turned into residual samples.

:func:`read_flights` reads and aligns every log on the controller-rate grid
(optionally restricted to a time window; a note when the body rate was logged
slower than the grid, :func:`upsampling_note`). :func:`read_samples` builds
each log's residual (:func:`omavctl.learn.signal.residual_samples`), drops the
spans where the vehicle was out of control and refuses logs without usable
samples. :func:`source_of` is what a model's provenance records of a log.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import LogError
from omavctl.learn.control_loss import flight_control_loss
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay, residual_samples
from omavctl.logs.align import slow_log_message
from omavctl.logs.types import FlightLog
from omavctl.physics.effects import EFFECTS
from omavctl.vehicle import Vehicle

__all__ = [
    "RATE_TOLERANCE",
    "REQUIRED_ROLES",
    "LogSummary",
    "body_rate_rate",
    "log_samples",
    "read_flights",
    "read_samples",
    "sha256_of",
    "source_of",
    "training_logs",
    "upsampling_note",
]

#: Roles fit needs from every log of a vehicle with a rotor list (the others need
#: the attitude too: :func:`omavctl.physics.mixer.required_roles`).
REQUIRED_ROLES = ("body_rate", "force_command", "torque_command")
#: A body rate logged below this fraction of the grid rate is noted as upsampled
#: (the tolerance absorbs jitter in the median step).
RATE_TOLERANCE = 0.95


@dataclass
class LogSummary:
    """What one log contributed: grid samples, samples used, and what was dropped."""

    path: Path
    samples: int
    used: int
    in_gaps: int
    edge_dropped: int
    short_dropped: int
    notes: list[str] = field(default_factory=list)
    #: samples in out-of-control spans (not used; the spans are in ``notes``)
    out_of_control: int = 0


def read_flights(
    logs: Sequence[str | Path | FlightLog],
    vehicle: Vehicle,
    time_window: tuple[float | None, float | None] | None = None,
) -> list[FlightLog]:
    """Read and align every log on the controller-rate grid (``read_vehicle_log``:
    the vehicle's topics, column map and frame; ground and idle time excluded;
    only ``start <= t < end`` s from each log's start with ``time_window``).

    A log whose body rate was recorded below the grid rate gets a note (its grid
    samples are interpolated, see :func:`upsampling_note`). Already aligned
    :class:`FlightLog` objects are passed through (the window still applies).
    A vehicle with a rotor list (``motors:``) and a log with motor outputs and
    no torque command gets its wrench command from the mixer
    (:mod:`omavctl.physics.mixer`). Raises LogError for an unreadable log, one
    lacking the body rate or the wrench command, or an empty window.
    """
    from omavctl.logs import read_vehicle_log, restrict_window
    from omavctl.physics.mixer import required_roles, wrench_hook

    out = []
    for item in logs:
        if isinstance(item, FlightLog):
            flight = item if time_window is None else restrict_window(item, time_window)
        else:
            flight = read_vehicle_log(
                item,
                vehicle,
                rate=vehicle.gains.rate_hz,
                required=required_roles(vehicle),
                time_window=time_window,
                wrench=wrench_hook(vehicle),
                weight=vehicle.weight,
            )
        _check_body_rate(flight, vehicle)
        note = upsampling_note(flight, vehicle)
        if note is not None:
            flight = replace(flight, notes=[*flight.notes, note])
        out.append(flight)
    return out


def body_rate_rate(flight: FlightLog, vehicle: Vehicle) -> float | None:
    """Median rate (Hz) at which the log recorded the body rate, if the reader saw it.

    The source is the ``body_rate`` column group of a CSV or the vehicle's
    ``imu`` topic of a bag (:attr:`FlightLog.topics`).
    """
    names = {"body_rate", vehicle.topics.get("imu", "")}
    rates = [info.rate for info in flight.topics if info.name in names and info.rate > 0]
    return min(rates) if rates else None


def _command_rate(flight: FlightLog, vehicle: Vehicle) -> float | None:
    """Median rate (Hz) of the slowest command the log holds (torque or motor columns
    of a CSV, the vehicle's wrench-command and actuator topics of a bag), if seen."""
    names = {"torque_command", "motor_command"}
    names |= {vehicle.topics.get(k, "") for k in ("wrench_command", "actuators")}
    rates = [info.rate for info in flight.topics if info.name in names and info.rate > 0]
    return min(rates) if rates else None


def _check_body_rate(flight: FlightLog, vehicle: Vehicle) -> None:
    """Refuse a log whose body rate was recorded below half the grid rate, as
    ``evaluate`` does: most of its grid samples would be interpolated (a time column
    in the wrong unit looks like this too)."""
    rate = body_rate_rate(flight, vehicle)
    grid = flight.rate
    if rate is None or rate >= 0.5 * grid:
        return
    raise LogError(slow_log_message(rate, grid), flight.path)


def check_model_rate(flight: FlightLog, vehicle: Vehicle, rate: float) -> None:
    """Refuse a log, evaluated with a model, whose body rate was recorded at less than
    half the model's grid ``rate`` (Hz): its Savitzky-Golay settings do not apply (one
    under 20 Hz, a time column in the wrong unit, was refused by the aligner already:
    :func:`omavctl.logs.align.slow_log_message`)."""
    logged = body_rate_rate(flight, vehicle)
    if logged is not None and logged < 0.5 * rate:
        raise LogError(
            f"body rate logged at {logged:.1f} Hz, below half the model's grid rate "
            f"({rate:g} Hz): its Savitzky-Golay settings do not apply",
            flight.path,
        )


#: A log whose body rate is recorded this many times faster than the grid gets a note:
#: the grid keeps one sample in this many (a 30 ms motor lag fitted on the 100 Hz grid
#: of a 500 Hz log came out 26.4 ± 0.5 ms, at 500 Hz 28.2 [25.8, 30.6]).
FAST_LOG = 2.0


def upsampling_note(flight: FlightLog, vehicle: Vehicle) -> str | None:
    """A note when the body rate was logged below the grid rate, or (with the
    command) at :data:`FAST_LOG` times it or faster, else None.

    Below :data:`RATE_TOLERANCE` x the grid rate the aligned body rate is
    mostly linear interpolation between logged samples: the Savitzky-Golay
    derivative then differentiates the interpolant (piecewise constant slopes),
    the window spans fewer real samples than it says, and the residual's noise
    level is not the one the defaults were chosen for (docs/fit.md).
    """
    rate = body_rate_rate(flight, vehicle)
    grid = flight.rate
    # the grid throws samples away when the body rate and the command are both faster
    # (a simulated omav logs its IMU at 200 Hz but commands at the 100 Hz grid)
    command = _command_rate(flight, vehicle)
    fast = min(rate, command) if rate is not None and command is not None else rate
    if rate is not None and fast is not None and fast >= FAST_LOG * grid:
        rate = fast
        return (
            f"body rate and command logged at {rate:.0f} Hz, {rate / grid:.1f}× the "
            f"{grid:g} Hz grid "
            f"(controller.rate_hz): the fit sees one sample in {rate / grid:.0f} and "
            f"resolves timing effects (motor_lag, command_delay) on a {1e3 / grid:.3g} ms "
            f"grid; set controller: {{rate_hz: {round(rate):d}}} in the vehicle YAML "
            "to fit at the log's own rate, with --sg-window about "
            f"{rate / grid:.0f}× as many samples, so that the derivative's filter spans the "
            "same time (the same samples at the faster rate span less of it: on the "
            "Crazyflie at 1011 Hz the held-out GP error on y rose 11.7 -> 15.1 rad/s² "
            "with the window left at 11)"
        )
    if rate is None or rate >= RATE_TOLERANCE * grid:
        return None
    return (
        f"body rate logged at {rate:.1f} Hz (median step), below the {grid:g} Hz grid "
        f"(controller.rate_hz): {1 - rate / grid:.0%} of the grid samples are interpolated "
        "between logged samples and the Savitzky-Golay derivative sees the interpolation; "
        f"set controller.rate_hz to at most {math.floor(rate):d} Hz in the vehicle YAML to "
        "fit at the log's own rate"
    )


def sha256_of(path: Path) -> str:
    """sha256 of a file, or of a directory's files (relative names and contents, sorted)."""
    h = hashlib.sha256()
    if path.is_dir():
        for f in sorted(p for p in path.rglob("*") if p.is_file()):
            h.update(str(f.relative_to(path)).encode())
            h.update(b"\0")
            h.update(hashlib.sha256(f.read_bytes()).digest())
        return h.hexdigest()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def training_logs(provenance: Mapping[str, Any]) -> list[dict[str, Any]]:
    """``{sha256, time_window}`` of every log whose points a model holds, from its
    ``provenance``: its own sources (with its time window) and those of the prior it
    was fitted on (``prior.training``, written by ``fit --prior``)."""
    own = [
        {"sha256": src.get("sha256"), "time_window": provenance.get("time_window")}
        for src in provenance.get("sources") or []
        if isinstance(src, Mapping)
    ]
    prior = provenance.get("prior")
    earlier = (prior.get("training") or []) if isinstance(prior, Mapping) else []
    return [dict(t) for t in own + earlier if isinstance(t, Mapping) and t.get("sha256")]


def source_of(item: str | Path | FlightLog) -> dict[str, Any]:
    """Name, path (as given and absolute) and sha256 of a log (or model) for provenance."""
    path = item.path if isinstance(item, FlightLog) else Path(item)
    digest = sha256_of(path) if path.exists() else None
    # the path as given and absolute: evaluate prints the fit command that refits
    # with another effect from the same logs, with paths valid where it runs
    return {
        "name": path.name,
        "path": str(path),
        "abspath": str(path.resolve()),
        "sha256": digest,
    }


def log_samples(
    item: str | Path | FlightLog,
    vehicle: Vehicle,
    sg: SavitzkyGolay,
    time_window: tuple[float | None, float | None] | None = None,
) -> tuple[ResidualSamples, LogSummary]:
    """One log's residual samples (out-of-control spans removed) and its summary.

    Every registered effect's regressor is built: the fitted ones are
    estimated, all are stored at the training points for evaluate's diagnosis.
    Raises LogError for a log without usable samples or with non-finite values.
    """
    flight = read_flights([item], vehicle, time_window)[0]
    s = residual_samples(flight, vehicle, sg, tuple(EFFECTS))
    loss = flight_control_loss(flight, s.index, s.omega, s.omega_dot, vehicle)
    lost = int(loss.mask.sum()) if loss.any else 0
    if loss.any and lost == s.n:
        a, b, why = loss.spans[0]
        raise LogError(
            f"no usable samples: every in-flight sample is out of control ({a:.2f}-{b:.2f} "
            f"s: {why}{', and more spans' if len(loss.spans) > 1 else ''}); fly a "
            "reference the vehicle can follow",
            flight.path,
        )
    if loss.any:
        s = s.select(~loss.mask)
        flight = replace(
            flight,
            notes=[
                *flight.notes,
                *(
                    f"{a:.2f}-{b:.2f} s out of control ({why}): not used"
                    for a, b, why in loss.spans
                ),
            ],
        )
    if s.tilt_note is not None:
        flight = replace(flight, notes=[*flight.notes, s.tilt_note])
    s.flight = flight  # for what the actuators' own feedback says (fit's notes)
    if s.n == 0:
        longest = max((b - a for a, b in flight.segments), default=0)
        raise LogError(
            f"no usable samples: --sg-window {sg.window} needs a valid segment of at "
            f"least {sg.window} samples, the longest has {longest}",
            flight.path,
        )
    arrays = [s.residual, s.u, s.omega, *s.regressors.values()]
    if not all(np.all(np.isfinite(a)) for a in arrays):
        raise LogError("non-finite values in the residual or the wrench command", flight.path)
    summary = LogSummary(
        flight.path, s.total, s.n, s.in_gaps, s.edge_dropped, s.short_dropped,
        list(flight.notes), lost,
    )  # fmt: skip
    return s, summary


def read_samples(
    logs: Sequence[str | Path | FlightLog],
    vehicle: Vehicle,
    sg: SavitzkyGolay,
    time_window: tuple[float | None, float | None] | None,
    points: int,
    report: Callable[[str, float], None],
) -> tuple[list[ResidualSamples], list[LogSummary]]:
    """Every log's samples and summary (:func:`log_samples`), reporting progress per log.

    Raises LogError when all logs together have fewer than ``points`` samples.
    """
    samples: list[ResidualSamples] = []
    summaries: list[LogSummary] = []
    for i, item in enumerate(logs):
        s, summary = log_samples(item, vehicle, sg, time_window)
        samples.append(s)
        summaries.append(summary)
        report("reading logs", (i + 1) / len(logs))
    n_total = sum(s.n for s in samples)
    if n_total < points:
        where = summaries[0].path if len(summaries) == 1 else None
        raise LogError(
            f"too few samples for --points {points}: {n_total} usable "
            f"sample{'s' if n_total != 1 else ''} after dropping gaps and filter edges",
            where,
        )
    return samples, summaries
