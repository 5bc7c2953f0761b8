"""Loss of control: the samples of a log where the vehicle was not flying under control.

Real flights end in crashes: a payload the controller does not know, a motor
that fails, a hard landing. There the vehicle tumbles, rates and angular
accelerations reach values no model of controlled flight is about, and a
single such second dominates any RMSE (or overflows a variance). ``fit`` and
``evaluate`` keep those samples out and name their time spans.

A sample is out of control when

- its body rate exceeds :data:`MAX_BODY_RATE` on any axis (an omav flies well
  below 3 rad/s; a tumbling multirotor spins at tens to hundreds), or
- its measured angular acceleration exceeds :data:`ACCELERATION_MARGIN` times
  the largest the vehicle's rotors can produce on that axis (every rotor at
  ``max_thrust`` on the arm's full lever: an upper bound), which only an
  impact or a broken log does, or
- its residual (measured minus nominal angular acceleration) exceeds
  :data:`RESIDUAL_FACTOR` times the log's own robust residual scale (1.4826 x
  the median absolute deviation per axis): the rotors no longer do what was
  commanded, long before the rates grow (a failed motor, a collision), or
- a value is not finite.

Each span is widened by :data:`ONSET_SECONDS` before (the loss starts before
the limits are crossed) and runs to the end of the valid data after the last
flagged sample within :data:`MERGE_SECONDS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omavctl.vehicle import Vehicle

__all__ = [
    "ACCELERATION_MARGIN",
    "MAX_BODY_RATE",
    "ControlLoss",
    "max_angular_acceleration",
    "out_of_control",
]

#: rad/s, body rate beyond which the vehicle is taken to be out of control.
MAX_BODY_RATE = 10.0
#: Measured angular acceleration beyond this multiple of the vehicle's maximum.
ACCELERATION_MARGIN = 2.0
#: Residual beyond this multiple of the log's robust residual scale.
RESIDUAL_FACTOR = 12.0
#: s, flagged spans start this much earlier.
ONSET_SECONDS = 0.5
#: s, flagged samples closer than this form one span.
MERGE_SECONDS = 1.0


@dataclass(frozen=True)
class ControlLoss:
    """Out-of-control samples of one log.

    mask (n,) True where out of control; spans: (start, end, reason) in s of
    the log's time axis.
    """

    mask: np.ndarray
    spans: list[tuple[float, float, str]]

    @property
    def any(self) -> bool:
        return bool(self.mask.any())


def max_angular_acceleration(vehicle: Vehicle) -> np.ndarray:
    """Upper bound (3,) rad/s^2 of the angular acceleration the rotors can produce.

    Every one of the ``2 n_arms`` rotors at ``max_thrust`` on the full arm
    length, about each axis, through the inverse inertia's diagonal.
    """
    torque = 2 * vehicle.n_arms * vehicle.max_thrust * vehicle.arm_length
    return np.abs(np.diag(vehicle.inertia_inv)) * torque


def out_of_control(
    t: np.ndarray,
    omega: np.ndarray,
    omega_dot: np.ndarray,
    vehicle: Vehicle,
    residual: np.ndarray | None = None,
) -> ControlLoss:
    """Flag the samples of one log that are out of control (see module docstring).

    t (n,) s; omega (n, 3) body rate rad/s; omega_dot (n, 3) measured angular
    acceleration rad/s^2; residual (n, 3) measured minus nominal, rad/s^2.
    """
    finite = np.isfinite(omega).all(axis=1) & np.isfinite(omega_dot).all(axis=1)
    with np.errstate(invalid="ignore"):
        rate = np.where(finite, np.abs(omega).max(axis=1), np.inf)
        acc = np.where(finite[:, None], np.abs(omega_dot), np.inf)
    limit = ACCELERATION_MARGIN * max_angular_acceleration(vehicle)
    reasons = np.full(t.size, "", dtype=object)
    if residual is not None and t.size > 0:
        ok = residual[finite]
        if ok.shape[0] > 0:
            centre = np.median(ok, axis=0)
            scale = 1.4826 * np.median(np.abs(ok - centre), axis=0)
            with np.errstate(invalid="ignore"):
                big = np.abs(np.where(finite[:, None], residual, 0.0) - centre) > (
                    RESIDUAL_FACTOR * np.maximum(scale, 1e-9)
                )
            reasons[big.any(axis=1)] = (
                f"residual beyond {RESIDUAL_FACTOR:g}x the log's typical size: the rotors "
                "no longer follow the command"
            )
    reasons[(acc > limit).any(axis=1)] = (
        f"angular acceleration beyond {ACCELERATION_MARGIN:g}x what the rotors can produce"
    )
    reasons[rate > MAX_BODY_RATE] = f"body rate beyond {MAX_BODY_RATE:g} rad/s"
    reasons[~finite] = "non-finite values"
    flagged = np.flatnonzero(reasons != "")
    mask = np.zeros(t.size, dtype=bool)
    spans: list[tuple[float, float, str]] = []
    if flagged.size == 0:
        return ControlLoss(mask, spans)
    groups = np.split(flagged, np.flatnonzero(np.diff(t[flagged]) > MERGE_SECONDS) + 1)
    for g in groups:
        start = float(t[g[0]] - ONSET_SECONDS)
        end = float(t[g[-1]])
        if g[-1] >= t.size - 1 or t[-1] - t[g[-1]] <= MERGE_SECONDS:
            end = float(t[-1])  # a loss at the end of a log: the rest is the crash
        mask |= (t >= start) & (t <= end)
        first = next(r for r in reasons[g] if r)
        spans.append((max(start, float(t[0])), end, str(first)))
    return ControlLoss(mask, spans)
