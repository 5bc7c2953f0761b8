"""Loss of control: the samples of a log where the vehicle was not flying under control.

Real flights end in crashes: a payload the controller does not know, a motor
that fails, a hard landing. There the vehicle tumbles, rates and angular
accelerations reach values no model of controlled flight is about, and a
single such second dominates any RMSE (or overflows a variance). ``fit`` and
``evaluate`` keep those samples out and name their time spans.

Control is judged by what the controller achieves and what the actuators can
give, **never by the residual** (measured minus nominal acceleration): an
aggressive manoeuvre the vehicle follows has a large residual exactly where a
missing effect (a drag, a lag) shows, and those are the samples the diagnosis
needs. A sample is out of control when

- **tracking is lost** (logs with ``attitude`` and ``reference_attitude``): the
  attitude error (the angle of the rotation from the vehicle to its reference)
  exceeds what the controller explains -- :data:`TRACKING_FLOOR` plus the angle
  the reference itself moved within the attitude loop's settling time before
  that sample (:func:`settling_time`, from the gains ``kp``, ``kd``: a vehicle
  may lag a fast reference by that long) -- for at least
  :data:`PERSIST_SECONDS` in a row (the error persists or grows instead of
  decaying as a controlled loop's does), or
- **the actuators saturate**: the commanded wrench is beyond what the rotors
  can give (a rotor of the allocation beyond ``max_thrust``) for at least
  :data:`SATURATION_SECONDS` in a row (commands in N and N m only: a normalised
  command's scale, and so its limit, is unknown), or
- its body rate exceeds :data:`MAX_BODY_RATE` on any axis (an omav flies well
  below 3 rad/s; a tumbling multirotor spins at tens to hundreds), or
- its measured angular acceleration exceeds :data:`ACCELERATION_MARGIN` times
  the largest the vehicle's rotors can produce on that axis (every rotor at
  ``max_thrust`` on the arm's full lever: an upper bound), which only an
  impact or a broken log does, or
- a value is not finite.

**Logs without a reference** (an IMU and the commands only, as most real logs
are): tracking cannot be judged, so only the actuator and physical limits
apply (saturation when the commands are in N and N m, body rate, angular
acceleration, finiteness). A motor that fails there is caught once the remaining
rotors saturate or the vehicle spins up; a loss that stays within all limits is
not flagged, and its samples stay in (the evaluation's metrics then show it).

Each span is widened by :data:`ONSET_SECONDS` before (the loss starts before
the limits are crossed) and runs to the end of the valid data after the last
flagged sample within :data:`MERGE_SECONDS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omavctl.logs.segment import MAX_BODY_RATE
from omavctl.logs.types import FlightLog
from omavctl.physics.allocation import Allocation
from omavctl.physics.rigid_body import rotation_matrix
from omavctl.vehicle import Vehicle

__all__ = [
    "ACCELERATION_MARGIN",
    "MAX_BODY_RATE",
    "PERSIST_SECONDS",
    "SATURATION_SECONDS",
    "TRACKING_FLOOR",
    "ControlLoss",
    "flight_control_loss",
    "max_angular_acceleration",
    "out_of_control",
    "settling_time",
    "tracking_allowance",
    "tracking_error",
    "wrench_saturated",
]

#: Measured angular acceleration beyond this multiple of the vehicle's maximum.
ACCELERATION_MARGIN = 2.0
#: rad, attitude error a controlled vehicle may show whatever its reference does
#: (30 deg: a disturbance of kp x 0.52 rad/s^2 the controller does not know,
#: 33 rad/s^2 at the omav's gains, before the error alone is a loss).
TRACKING_FLOOR = float(np.deg2rad(30.0))
#: s, tracking beyond its allowance for this long in a row is a loss.
PERSIST_SECONDS = 0.2
#: s, a wrench command beyond the actuators' limits for this long in a row is a loss.
SATURATION_SECONDS = 0.3
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


def settling_time(vehicle: Vehicle) -> float:
    """s, the attitude loop's 2 % settling time on its slowest axis.

    The loop ``e'' + kd e' + kp e = 0`` has ``wn = sqrt(kp)``, ``zeta = kd / (2 wn)``;
    settling takes about ``4 / (zeta wn) = 8 / kd`` when under-damped and
    ``5.8 / wn`` when critically damped or over-damped (the slow pole then
    dominates: ``4 / (wn (zeta - sqrt(zeta^2 - 1)))``, capped at 5 s).
    """
    kp = np.maximum(np.asarray(vehicle.gains.att_kp, float), 1e-9)
    kd = np.maximum(np.asarray(vehicle.gains.att_kd, float), 1e-9)
    wn = np.sqrt(kp)
    zeta = kd / (2 * wn)
    slow = np.where(
        zeta < 0.95,
        4.0 / (zeta * wn),
        np.maximum(5.8 / wn, 4.0 / (wn * (zeta - np.sqrt(np.maximum(zeta**2 - 1, 0.0))))),
    )
    return float(min(np.max(slow), 5.0))


def _angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle (n,) rad from rotation matrices a (n, 3, 3) to b (n, 3, 3)."""
    trace = np.einsum("nji,nji->n", a, b)  # trace(a^T b)
    return np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))


def tracking_error(attitude: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Attitude tracking error (n,) rad: the angle of the rotation from the vehicle's
    attitude to its reference, both (n, 3) roll, pitch, yaw in rad (NaN stays NaN)."""
    return _angle_between(rotation_matrix(attitude), rotation_matrix(reference))


def tracking_allowance(reference: np.ndarray, dt: float, vehicle: Vehicle) -> np.ndarray:
    """The attitude error (n,) rad a controlled vehicle may show at each sample.

    :data:`TRACKING_FLOOR` plus the largest angle the reference (n, 3) rad on a
    uniform grid of step ``dt`` s moved from any sample within the attitude
    loop's :func:`settling_time` before to this one.
    """
    r = rotation_matrix(reference)
    n = r.shape[0]
    moved = np.zeros(n)
    lags = min(max(1, round(settling_time(vehicle) / dt)), n - 1)
    for k in range(1, lags + 1):
        angle = _angle_between(r[:-k], r[k:])
        moved[k:] = np.fmax(moved[k:], angle)
    return TRACKING_FLOOR + moved


def wrench_saturated(force: np.ndarray, torque: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """Whether each commanded wrench is beyond the actuators' limits (n,) bool.

    force (n, 3) N, torque (n, 3) N m as logged: a rotor thrust of the
    allocation above ``max_thrust``.
    """
    wrench = np.nan_to_num(np.concatenate([force, torque], axis=1))
    return np.asarray(Allocation(vehicle).allocate(wrench).thrust_high.any(axis=1))


def _persistent(t: np.ndarray, flags: np.ndarray, seconds: float) -> np.ndarray:
    """The flags (n,) that belong to a run of consecutive flagged samples lasting at
    least ``seconds`` (t (n,) s; a gap over 1.5 grid steps ends a run)."""
    out = np.zeros(flags.size, dtype=bool)
    idx = np.flatnonzero(flags)
    if idx.size == 0:
        return out
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    breaks = (np.diff(idx) > 1) | (np.diff(t[idx]) > 1.5 * step)
    for run in np.split(idx, np.flatnonzero(breaks) + 1):
        if t[run[-1]] - t[run[0]] + step >= seconds - 1e-9:
            out[run] = True
    return out


def _limit_reasons(
    t: np.ndarray,
    omega: np.ndarray,
    omega_dot: np.ndarray,
    vehicle: Vehicle,
    tracking: tuple[np.ndarray, np.ndarray] | None,
    saturated: np.ndarray | None,
) -> np.ndarray:
    """Per sample (n,) the first limit it breaks ('' for none); later rules win ties."""
    finite = np.isfinite(omega).all(axis=1) & np.isfinite(omega_dot).all(axis=1)
    with np.errstate(invalid="ignore"):
        rate = np.where(finite, np.abs(omega).max(axis=1), np.inf)
        acc = np.where(finite[:, None], np.abs(omega_dot), np.inf)
    reasons = np.full(t.size, "", dtype=object)
    if saturated is not None:
        reasons[_persistent(t, saturated, SATURATION_SECONDS)] = (
            f"wrench command beyond the actuators' limits for {SATURATION_SECONDS:g} s or more"
        )
    if tracking is not None:
        error, allowance = tracking
        with np.errstate(invalid="ignore"):
            lost = error > allowance
        reasons[_persistent(t, lost, PERSIST_SECONDS)] = (
            "attitude error beyond what the controller's gains and the reference's own "
            f"motion explain for {PERSIST_SECONDS:g} s or more: the vehicle no longer "
            "follows its reference"
        )
    limit = ACCELERATION_MARGIN * max_angular_acceleration(vehicle)
    reasons[(acc > limit).any(axis=1)] = (
        f"angular acceleration beyond {ACCELERATION_MARGIN:g}x what the rotors can produce"
    )
    reasons[rate > MAX_BODY_RATE] = f"body rate beyond {MAX_BODY_RATE:g} rad/s"
    reasons[~finite] = "non-finite values"
    return reasons


def out_of_control(
    t: np.ndarray,
    omega: np.ndarray,
    omega_dot: np.ndarray,
    vehicle: Vehicle,
    tracking: tuple[np.ndarray, np.ndarray] | None = None,
    saturated: np.ndarray | None = None,
) -> ControlLoss:
    """Flag the samples of one log that are out of control (see module docstring).

    t (n,) s; omega (n, 3) body rate rad/s; omega_dot (n, 3) measured angular
    acceleration rad/s^2; tracking: (error, allowance), each (n,) rad
    (:func:`tracking_error`, :func:`tracking_allowance`), None for a log without
    a reference; saturated (n,) bool (:func:`wrench_saturated`), None when the
    commands are not known.
    """
    reasons = _limit_reasons(t, omega, omega_dot, vehicle, tracking, saturated)
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


def flight_control_loss(
    flight: FlightLog,
    index: np.ndarray,
    omega: np.ndarray,
    omega_dot: np.ndarray,
    vehicle: Vehicle,
) -> ControlLoss:
    """:func:`out_of_control` for the samples at grid indices ``index`` (n,) of an
    aligned ``flight``: tracking from its ``attitude`` and ``reference_attitude``
    when it has both, saturation from its wrench command when in N and N m; omega,
    omega_dot (n, 3)."""
    t = flight.t[index]
    tracking = None
    if flight.has("attitude") and flight.has("reference_attitude"):
        reference = flight.signals["reference_attitude"]
        error = tracking_error(flight.signals["attitude"], reference)
        tracking = (error[index], tracking_allowance(reference, flight.dt, vehicle)[index])
    saturated = None
    physical = not (vehicle.torque_normalised or vehicle.force_normalised)
    if physical and flight.has("force_command") and flight.has("torque_command"):
        force, torque = flight.signals["force_command"], flight.signals["torque_command"]
        saturated = wrench_saturated(force[index], torque[index], vehicle)
    return out_of_control(t, omega, omega_dot, vehicle, tracking, saturated)
