"""How the actuators follow their commands, read from their own feedback.

The omav's log may record where the arms are (role ``tilt``, the servos' positions) and
how fast the rotors spin (role ``rotor``, rad/s). Beside the commanded tilts and rotor
thrusts (the allocation of the logged wrench command, the setpoints the controller
sent), they show the actuators' timing directly, without the angular acceleration:

- a tilt servo that lags (``servo_lag``): the tilts follow their commands with a
  first-order lag, the rotors do not;
- a motor that lags (``motor_lag``): the rotors' thrusts (``k omega^2``) lag, the tilts
  do not;
- a delay of the applied command (``command_delay``): both are late by the same time.

The angular acceleration alone often cannot tell these apart on a smooth flight (their
torques look alike); the feedback can. Each kind is fitted with a pure delay ``tau``
followed by a first-order lag ``T`` of the held commands (:func:`delayed_lag`: the
log's row k holds the command sent at t_k and the actuator's state at t_k, which the
commands before t_k made), by least squares over a grid refined by Nelder-Mead; the
95 % interval of each parameter is where the mean square stays within the chi-square
bound of its minimum (the other parameter held), with the residual's autocorrelation
counted in the effective number of rows (:func:`_interval`).

A controller faster than the log (1 kHz logged at 100 Hz) leaves in each row one sample
of a command that varies between rows; its row-to-row jitter is noise in the fit's
input, which the actuators average and a lag averages too: a 50 ms delay reads as a
48 ms lag (own-invent draw 4). Such a log's commands hardly cohere with the actuators'
states over the top fifth of its band (coherence 0.04-0.12 on the own tune draws at
1 kHz, 0.86-1.00 at 100 Hz, a 0.1 s servo lag included), while the commands' power there
is not small beside what the fit leaves (a smooth command beside noisy states coheres as
little): :attr:`ActuatorFit.undersampled`.
There the split between delay and lag is not read from the log, only how late the
actuators are in all (``late`` = tau + T, the low-frequency lateness both share, with
its interval along the fitted split, widened by half the log's period each way: the
command between two rows is not in the log; 52 (45-58) and 53 (46-61) ms for that
50 ms delay behind the 5 ms default lags).

Measured on the project's simulator (20 s figure-8 flights of the own tune draws, flown
again with the fixed log instant; docs/concepts.md §6): a 0.1 s servo lag gives the tilts
T = 97 ms (95 %: 95 to 100, a 1 kHz controller) and the rotors 22 ms; a 0.12 s motor lag
the rotors 120 ms; a 50 ms command delay tau = 51 and 50 ms. In-process flights
(tests/test_actuator_timing.py): 79.5 ms for 80, 60.0 for 60, 50.0 for 50.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.signal import coherence, lfilter, welch

from omavctl.logs.types import FlightLog
from omavctl.physics.allocation import Allocation
from omavctl.vehicle import Vehicle

__all__ = ["SHOWN_BY", "ActuatorFit", "actuator_timing", "delayed_lag", "fit_timing"]

#: Delays (s) searched, and lags (s): beyond them a vehicle is not flying on its commands.
MAX_DELAY, MAX_LAG = 0.2, 0.5
#: Fewest valid rows for a fit, and rows dropped at the start (the states before the
#: first command are unknown).
MIN_ROWS, SETTLE = 200, 20
_CHI2_95 = 3.841458820694124
#: Mean coherence of commands and states over the top fifth of the log's band under which
#: the log's commands are samples of a faster controller (module docstring), when the
#: commands' power there is at least ``ROUGH_MIN`` of the fit's mean square residual
#: (``roughness``: a smooth command beside noisy states coheres as little, and its
#: input noise biases nothing; own tune draws at 1 kHz: 0.19-4.3, two smooth sines 2e-4).
COHERENCE_MIN, ROUGH_MIN = 0.5, 0.05
#: which actuators show each timing effect, and by what: (kinds, "T" lag or "tau" delay)
SHOWN_BY = {
    "servo_lag": (("tilt",), "T"),
    "motor_lag": (("rotor",), "T"),
    "command_delay": (("tilt", "rotor"), "tau"),
}


@dataclass
class ActuatorFit:
    """One kind of actuator (``tilt`` or ``rotor``): its fitted delay ``tau`` and lag
    ``T`` (s) with 95 % intervals, and the RMS mismatch (rad or N) with no timing, with
    the fit, and with each alone (the lag with tau = 0, the delay with T = 0)."""

    kind: str
    unit: str
    tau: float
    T: float
    tau_ci95: tuple[float, float]
    T_ci95: tuple[float, float]
    rms_none: float
    rms_fit: float
    rms_lag_only: float
    rms_delay_only: float
    rows: int
    late: float = 0.0
    late_ci95: tuple[float, float] = (0.0, 0.0)
    coherence: float = 1.0
    roughness: float = 0.0
    period: float = 0.0

    @property
    def undersampled(self) -> bool:
        """Whether the log's commands are samples of a faster controller: the delay and
        the lag are not told apart, only ``late`` (module docstring)."""
        return self.coherence < COHERENCE_MIN and self.roughness > ROUGH_MIN

    def timing(self, what: str) -> tuple[float, tuple[float, float]]:
        """The delay (``what`` "tau") or the lag ("T") this fit shows, with its 95 %
        interval: how late in all (``late``) where the commands are undersampled (the
        split between them is not read from such a log)."""
        if self.undersampled:
            return self.late, self.late_range
        return (self.tau, self.tau_ci95) if what == "tau" else (self.T, self.T_ci95)

    @property
    def late_range(self) -> tuple[float, float]:
        """The 95 % interval of ``late`` as reported: ``late_ci95`` (the fit's, along its
        split) widened by half the log's period each way where the commands are
        undersampled (the command between two rows is not in the log)."""
        pad = self.period / 2.0 if self.undersampled else 0.0
        return max(self.late_ci95[0] - pad, 0.0), self.late_ci95[1] + pad

    def late_than(self, other: ActuatorFit) -> float:
        """Upper 95 % bound (s) of how much later this kind is than ``other`` (the fits'
        own intervals: the half period both would carry cancels in the difference)."""
        return self.late_ci95[1] - other.late_ci95[0]

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "unit": self.unit,
            "tau": self.tau,
            "T": self.T,
            "tau_ci95": list(self.tau_ci95),
            "T_ci95": list(self.T_ci95),
            "rms_none": self.rms_none,
            "rms_fit": self.rms_fit,
            "rms_lag_only": self.rms_lag_only,
            "rms_delay_only": self.rms_delay_only,
            "rows": self.rows,
            "late": self.late,
            "late_ci95": list(self.late_range),
            "coherence": self.coherence,
            "roughness": self.roughness if math.isfinite(self.roughness) else None,
            "undersampled": self.undersampled,
            "period": self.period,
        }


def delayed_lag(command: np.ndarray, tau: float, lag: float, dt: float) -> np.ndarray:
    """The actuator's state (N, k) at each row's instant t_i: the commands (N, k), held
    from t_j to t_j + dt, applied ``tau`` s late, followed with the first-order lag
    ``lag`` s; the state before the first command is the first command."""
    n = command.shape[0]
    steps = max(tau, 0.0) / dt
    q = math.floor(steps)
    f = steps - q
    idx = np.arange(n)
    late = command[np.clip(idx - q - 1, 0, n - 1)]  # applied over the first f of a period
    now = command[np.clip(idx - q, 0, n - 1)]
    if lag <= 1e-6:  # no lag: the state is the setpoint applied last
        x_next = now
    else:
        a = math.exp(-dt / lag)
        beta = 1.0 - math.exp(-(1.0 - f) * dt / lag)
        alpha = (1.0 - a) - beta
        u = alpha * late + beta * now
        c0 = command[0]
        x_next = lfilter([1.0], [1.0, -a], u - (1.0 - a) * c0, axis=0) + c0
    out = np.empty_like(command)
    out[0] = command[0]
    out[1:] = x_next[:-1]  # the state at t_i follows the commands applied before t_i
    return out


def _effective(residual: np.ndarray) -> float:
    """Effective number of independent rows of a residual (m, k): its lag-1
    autocorrelation (pooled over columns) counted as an AR(1) process's."""
    r = residual - residual.mean(axis=0)
    den = float((r**2).sum())
    rho = float((r[1:] * r[:-1]).sum() / den) if den > 0 else 0.0
    rho = min(max(rho, 0.0), 0.99)
    return residual.shape[0] * (1.0 - rho) / (1.0 + rho)


def _interval(
    cost: Any, best: np.ndarray, which: int, grid: np.ndarray, limit: float
) -> tuple[float, float]:
    """95 % interval of parameter ``which`` of ``best`` (tau, T), the other held at its
    estimate: the span of ``grid`` (and the estimate) whose mean square stays under
    ``limit``, widened by half a grid step (the search's resolution: a delay without a
    lag is known to the log's period only, as its rows are)."""
    values = np.union1d(grid, [best[which]])
    inside = []
    for v in values:
        p = best.copy()
        p[which] = v
        if cost(p) <= limit:
            inside.append(float(v))
    step = float(np.max(np.diff(grid))) / 2.0 if grid.size > 1 else 0.0
    lo, hi = min(inside, default=float(best[which])), max(inside, default=float(best[which]))
    return max(lo - step, 0.0), hi + step


def _late_interval(cost: Any, best: np.ndarray, limit: float, dt: float) -> tuple[float, float]:
    """95 % interval of the lateness tau + T along the fitted split (both scaled together):
    from the estimate outwards in steps of a quarter period while the mean square stays
    under ``limit`` (the connected region around it; a few evaluations, not a scan)."""
    total = float(best.sum())
    share = best / total if total > 0 else np.array([0.0, 1.0])
    step, top = dt / 4.0, MAX_DELAY + MAX_LAG
    lo = total
    while lo - step >= 0.0 and cost(share * (lo - step)) <= limit:
        lo -= step
    hi = total
    while hi + step <= top and cost(share * (hi + step)) <= limit:
        hi += step
    return max(lo - dt / 8.0, 0.0), hi + dt / 8.0


def fast_coherence(
    command: np.ndarray, measured: np.ndarray, rows: np.ndarray, dt: float
) -> tuple[float, float]:
    """Over the top fifth of the log's band (gaps held): the mean coherence of
    ``command`` and ``measured`` (N, k), and the command's power there (its mean power
    spectral density times the band's width, per column); (1.0, 0.0) with too few rows."""
    if command.shape[0] < 4 * 64:
        return 1.0, 0.0
    c = _held_over_gaps(command, rows)
    m = _held_over_gaps(measured, rows)
    f, coh = coherence(c, m, fs=1.0 / dt, nperseg=128, axis=0)
    band = f >= 0.4 / dt
    _, p_c = welch(c, fs=1.0 / dt, nperseg=128, axis=0)
    value = float(np.nanmean(coh[band]))
    power = float(p_c[band].mean()) * 0.1 / dt
    return (value if math.isfinite(value) else 1.0), power


def fit_timing(
    kind: str, unit: str, command: np.ndarray, measured: np.ndarray, rows: np.ndarray,
    dt: float, angle: bool = False,
) -> ActuatorFit | None:  # fmt: skip
    """Delay and lag of ``measured`` (N, k) following ``command`` (N, k) on the valid
    ``rows`` (N,) bool; angles (``angle``) compared on the circle. None with too few rows."""
    keep = rows.copy()
    keep[:SETTLE] = False
    if int(keep.sum()) < MIN_ROWS:
        return None

    def mismatch(tau: float, lag: float) -> np.ndarray:
        d = measured - delayed_lag(command, tau, lag, dt)
        d = (d + np.pi) % (2.0 * np.pi) - np.pi if angle else d
        return np.asarray(d[keep])

    def cost(p: np.ndarray) -> float:
        tau, lag = float(p[0]), float(p[1])
        if not (0.0 <= tau <= MAX_DELAY and 0.0 <= lag <= MAX_LAG):
            return math.inf
        return float((mismatch(tau, lag) ** 2).mean())

    taus = np.arange(0.0, MAX_DELAY + 1e-9, dt / 4.0)
    lags = np.concatenate([[0.0], np.geomspace(1e-3, MAX_LAG, 40)])
    tau_only = min(taus[::2], key=lambda v: cost(np.array([v, 0.0])))
    lag_only = min(lags, key=lambda v: cost(np.array([0.0, v])))
    coarse = min(((t, g) for t in taus[::16] for g in lags[::8]), key=lambda p: cost(np.array(p)))
    start = min((np.array(coarse), np.array([tau_only, 0.0]), np.array([0.0, lag_only])), key=cost)
    res = minimize(cost, start, method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-12})
    best = np.asarray(res.x if res.fun <= cost(start) else start, float)
    resid = mismatch(float(best[0]), float(best[1]))
    limit = float((resid**2).mean()) * math.exp(_CHI2_95 / max(_effective(resid), 1.0))
    tau_ci = _interval(cost, best, 0, taus, limit)
    lag_ci = _interval(cost, best, 1, np.linspace(0.0, MAX_LAG, 101), limit)
    if best[1] < dt:  # no lag to smooth it: a delay is known to the log's period only
        tau_ci = (max(min(tau_ci[0], best[0] - dt), 0.0), max(tau_ci[1], best[0] + dt))
    # the measured angles beside their commands, not a turn away
    near = command + ((measured - command + np.pi) % (2.0 * np.pi) - np.pi) if angle else measured
    fast, power = fast_coherence(command, near, keep, dt)
    left = float((resid**2).mean())
    rough = power / left if left > 0 else math.inf
    late_ci = _late_interval(cost, best, limit, dt)
    return ActuatorFit(
        kind=kind,
        unit=unit,
        tau=float(best[0]),
        T=float(best[1]),
        tau_ci95=tau_ci,
        T_ci95=lag_ci,
        rms_none=math.sqrt(cost(np.zeros(2))),
        rms_fit=math.sqrt(float(cost(best))),
        rms_lag_only=math.sqrt(cost(np.array([0.0, lag_only]))),
        rms_delay_only=math.sqrt(cost(np.array([tau_only, 0.0]))),
        rows=int(keep.sum()),
        late=float(best.sum()),
        late_ci95=late_ci,
        coherence=fast,
        roughness=rough,
        period=dt,
    )


def _held_over_gaps(values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``values`` (N, k) with the rows not in ``rows`` holding the last row before them
    (the first valid row before any): a gap's commands are not zero."""
    idx = np.where(rows, np.arange(rows.size), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(rows)) if rows.any() else 0
    return np.asarray(values[np.where(idx >= 0, idx, first)])


def actuator_timing(flight: FlightLog, vehicle: Vehicle) -> dict[str, ActuatorFit]:
    """The tilts' and the rotors' timing (:func:`fit_timing`) of a log of the omav's
    allocation that records them (roles ``tilt``, ``rotor``); empty for a rotor list, a
    command in unknown units, or a log without them."""
    if vehicle.motors is not None or vehicle.torque_normalised or vehicle.force_normalised:
        return {}
    if not (flight.has("tilt") or flight.has("rotor")):
        return {}
    dt = float(np.median(np.diff(flight.t))) if flight.t.size > 1 else 0.0
    if dt <= 0:
        return {}
    wrench = np.concatenate([flight.signals["force_command"], flight.signals["torque_command"]], 1)
    rows = flight.valid & np.all(np.isfinite(wrench), axis=1)
    wrench = _held_over_gaps(wrench, rows)
    res = Allocation(vehicle).allocate(wrench)
    out: dict[str, ActuatorFit] = {}
    if flight.has("tilt") and flight.signals["tilt"].shape[1] == vehicle.n_arms:
        tilt = flight.signals["tilt"]
        ok = rows & np.all(np.isfinite(tilt), axis=1)
        fit = fit_timing(
            "tilt", "rad", np.unwrap(res.tilt, axis=0), np.nan_to_num(tilt), ok, dt, True
        )
        if fit is not None:
            out["tilt"] = fit
    if flight.has("rotor") and flight.signals["rotor"].shape[1] == 2 * vehicle.n_arms:
        speed = flight.signals["rotor"]
        ok = rows & np.all(np.isfinite(speed), axis=1)
        thrust = vehicle.thrust_coefficient * np.nan_to_num(speed) ** 2
        cmd = np.clip(res.rotor_thrust, vehicle.min_thrust, vehicle.max_thrust)
        fit = fit_timing("rotor", "N", cmd, thrust, ok, dt)
        if fit is not None:
            out["rotor"] = fit
    return out
