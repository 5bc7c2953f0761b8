"""Reading one log as ``evaluate`` reads it: on the model's grid and derivative filter,
every registry effect's regressor, out-of-control samples removed; and, for the
diagnosis, the model's own fit logs read the same way (:func:`fit_flight_reader`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omavctl.base.errors import LogError, OmavctlError
from omavctl.diagnose.horizons import GridSignals
from omavctl.learn.control_loss import flight_control_loss
from omavctl.learn.flights import check_model_rate, sha256_of
from omavctl.learn.model import ResidualGP
from omavctl.learn.recorded_noise import recorded_noise
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay, residual_samples
from omavctl.physics.effects import EFFECTS
from omavctl.vehicle import Vehicle

__all__ = ["FitFlight", "fit_flight_reader"]

#: Reads a model's fit flight on first call (its samples, or None when it cannot be read).
FitFlight = Callable[[], list[ResidualSamples] | None]


def _grid(model: ResidualGP) -> tuple[float, SavitzkyGolay]:
    """The grid rate (Hz) and Savitzky-Golay filter the model was fitted with."""
    prov = model.provenance
    rate = float(prov.get("grid_rate_hz", model.vehicle.gains.rate_hz))
    sg_cfg = prov.get("savitzky_golay", {})
    from omavctl.learn.signal import DEFAULT_SG_ORDER, DEFAULT_SG_WINDOW

    sg = SavitzkyGolay(
        int(sg_cfg.get("window", DEFAULT_SG_WINDOW)),
        int(sg_cfg.get("order", DEFAULT_SG_ORDER)),
        1.0 / rate,
    )
    return rate, sg


def _read_log(
    path: str | Path,
    vehicle: Vehicle,
    rate: float,
    sg: SavitzkyGolay,
    time_window: tuple[float | None, float | None] | None,
    effects: Sequence[str] = tuple(EFFECTS),
) -> tuple[ResidualSamples, GridSignals, dict[str, Any], list[dict[str, Any]]]:
    """One log's residual samples (every registry regressor, out-of-control samples
    removed), its unfiltered signals at them (attitude zero when not logged), its
    ``logs`` entry and its excluded spans."""
    from omavctl.logs import read_vehicle_log
    from omavctl.physics.mixer import required_roles, wrench_hook

    # the roles fit needed: a vehicle with a rotor list flies IMU-only logs too
    flight = read_vehicle_log(
        path,
        vehicle,
        rate=rate,
        time_window=time_window,
        required=required_roles(vehicle),
        wrench=wrench_hook(vehicle),
        weight=vehicle.weight,
    )
    check_model_rate(flight, vehicle, rate)
    extra = {"desired": "desired_acceleration"} if flight.has("desired_acceleration") else {}
    s = residual_samples(flight, vehicle, sg, effects=tuple(effects), extra=extra)
    loss = flight_control_loss(flight, s.index, s.omega, s.omega_dot, vehicle)
    p = Path(path)
    spans = [{"log": p.name, "start": a, "end": b, "reason": why} for a, b, why in loss.spans]
    if loss.any:
        s = s.select(~loss.mask)
    s.flight = flight  # the diagnosis reads the actuators' feedback from it
    if s.n < 10 * sg.window:
        raise LogError(
            f"only {s.n} usable samples after gaps, edges, ground time and loss of control "
            f"(need at least {10 * sg.window})",
            flight.path,
        )
    grid = GridSignals(
        body_rate=flight.signals["body_rate"][s.index],
        torque=flight.signals["torque_command"][s.index],
        attitude=flight.signals["attitude"][s.index] if flight.has("attitude") else None,
        noise=recorded_noise(flight, s.index, s.rate_noise),
    )
    notes = list(flight.notes)
    if not flight.has("attitude"):  # an IMU-only log (a vehicle with a rotor list)
        notes.append(
            "no attitude in the log: the tilt is unknown, and 'what the vehicle was doing' says so"
        )
    log_json = {
        "path": str(p),
        "name": p.name,
        "sha256": sha256_of(p),
        "format": flight.format,
        # absolute time of the series' t = 0 on the log's own clock
        "t0": float(flight.t0),
        "duration": float(flight.t[-1] - flight.t[0]),
        "samples": s.n,
        "samples_total": s.total,
        "notes": notes,
    }
    return s, grid, log_json, spans


def fit_flight_reader(model: ResidualGP) -> FitFlight:
    """A function that reads the logs ``model`` was fitted on (its provenance's absolute
    paths and time window) as :func:`_read_log` reads a held-out log, once, on its first
    call; it returns None when a log is gone, is not the file the model was fitted on
    (its sha256 differs) or cannot be read: the diagnosis then says what it could not
    check."""
    cache: dict[str, list[ResidualSamples] | None] = {}

    def read() -> list[ResidualSamples] | None:
        if "samples" not in cache:
            cache["samples"] = _read_fit_logs(model)
        return cache["samples"]

    return read


def _read_fit_logs(model: ResidualGP) -> list[ResidualSamples] | None:
    """The fit logs' samples (:func:`fit_flight_reader`), None when any cannot be read."""
    sources = [s for s in model.provenance.get("sources") or [] if isinstance(s, dict)]
    window = model.provenance.get("time_window")
    span = (window[0], window[1]) if isinstance(window, list | tuple) and len(window) == 2 else None
    if not sources:
        return None
    rate, sg = _grid(model)
    out = []
    for src in sources:
        path = Path(str(src.get("abspath") or ""))
        try:
            if not src.get("abspath") or not path.exists() or sha256_of(path) != src.get("sha256"):
                return None
            out.append(_read_log(path, model.vehicle, rate, sg, span)[0])
        except (OmavctlError, OSError, ValueError):  # gone, changed or unreadable: unchecked
            return None
    return out
