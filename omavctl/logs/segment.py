"""Flight segmentation and time windows on an aligned :class:`FlightLog`.

Flight segmentation (:func:`segment_flight`) marks samples on the ground or
with motors idle as invalid, from the thrust command alone, in whatever unit
it is logged (N, or normalised 0..1):

1. ``thrust = |force_command|`` per grid sample; the *in-flight level* is its
   90th percentile over the valid samples (robust to the idle part, which is
   normally well under 10 % of a log worth fitting) where the vehicle does not
   tumble (body rate up to :data:`MAX_BODY_RATE` on every axis, when logged): a log that ends
   in a crash holds the controller's wound-up commands, which set the level
   otherwise (a simulated omav hovering at 40 N for 8.7 s, then 200-845 N for
   0.6 s while falling: level 285 N, the whole flight "idle" below 71 N). With
   the vehicle's weight in the thrust command's unit (N), the level is at most
   :data:`LEVEL_OVER_WEIGHT` x the weight: a struggling vehicle's commands
   (an omav with strong rotor interference, 40 N to hover, level 174 N) no
   longer make its hover "idle".
2. *Idle*: ``thrust < 0.25 x level`` (motors off, idling or spooling up).
3. *Before take-off / after landing*: a vehicle cannot leave the ground before
   its thrust reaches roughly its weight. ``hover`` is the median of the
   non-idle thrust. If the log *starts* on the ground (first sample below
   ``0.5 x hover``: idle, or armed with the motors at minimum), samples up to
   the first one where ``thrust >= 0.9 x hover`` are ground too; likewise
   after the last such sample if the log *ends* below ``0.5 x hover``.
4. Excluded runs are widened by 0.2 s on both sides so the take-off and
   landing transients go too.

A log that never idles (every simulated flight, thrust about ``m g``
throughout) loses nothing. Windows (:func:`restrict_window`) keep only the
samples with ``start <= t < end`` (s from the log start).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from omavctl.base.errors import ConfigError, LogError
from omavctl.logs.align import segments_of
from omavctl.logs.types import FlightLog

__all__ = [
    "GROUND_FRACTION",
    "IDLE_FRACTION",
    "LEVEL_OVER_WEIGHT",
    "LEVEL_PERCENTILE",
    "MARGIN",
    "MAX_BODY_RATE",
    "TAKEOFF_FRACTION",
    "ground_mask",
    "parse_time_window",
    "restrict_window",
    "segment_flight",
]

#: Thrust below this fraction of the in-flight level is idle.
IDLE_FRACTION = 0.25
#: Percentile of ``|force_command|`` over the log that defines the in-flight level.
LEVEL_PERCENTILE = 90.0
#: A log whose first (last) sample is below this fraction of the median
#: non-idle thrust starts (ends) on the ground.
GROUND_FRACTION = 0.5
#: Before take-off (after landing) lasts until thrust reaches this fraction of
#: the median non-idle thrust.
TAKEOFF_FRACTION = 0.9
#: Excluded runs are widened by this much on each side, s.
MARGIN = 0.2
#: With the weight known (thrust in N), the in-flight level is at most this multiple of
#: it (a flight's 90th percentile is 1.1-1.5x its weight; idle is then below half of it).
LEVEL_OVER_WEIGHT = 2.0
#: rad/s, body rate beyond which the vehicle is taken to be out of control (here: its
#: thrust commands do not set the in-flight level; omavctl.learn.control_loss: its
#: samples are not fitted).
MAX_BODY_RATE = 10.0


def _dilate(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` shape (N,) widened by ``n`` samples on both sides."""
    if n <= 0 or not mask.any():
        return mask.copy()
    c = np.concatenate([[0], np.cumsum(mask, dtype=np.int64)])
    idx = np.arange(mask.size)
    lo = np.clip(idx - n, 0, mask.size)
    hi = np.clip(idx + n + 1, 0, mask.size)
    return (c[hi] - c[lo]) > 0


def _spans(t: np.ndarray, mask: np.ndarray) -> str:
    """``"0.00-4.31 s, 20.10-21.40 s"``: times of the first and last sample of each run."""
    return ", ".join(f"{t[a]:.2f}-{t[b - 1]:.2f} s" for a, b in segments_of(mask))


def ground_mask(
    thrust: np.ndarray,
    valid: np.ndarray,
    rate: float,
    idle_fraction: float = IDLE_FRACTION,
    takeoff_fraction: float = TAKEOFF_FRACTION,
    margin: float = MARGIN,
    percentile: float = LEVEL_PERCENTILE,
    ground_fraction: float = GROUND_FRACTION,
    weight: float | None = None,
) -> tuple[np.ndarray, float, float]:
    """Samples on the ground or idle by the rule of the module docs.

    Args:
        thrust: ``|force_command|`` shape (N,), any unit.
        valid: shape (N,), samples the level is computed on.
        rate: grid rate, Hz (for the margin).

    Returns:
        ``(ground, level, hover)``: ground shape (N,) bool, the in-flight level
        and the median non-idle thrust (0 when everything is idle).
    """
    use = valid & np.isfinite(thrust)
    if not use.any():
        return np.zeros(thrust.size, dtype=bool), 0.0, 0.0
    level = float(np.percentile(thrust[use], percentile))
    if weight is not None and weight > 0:
        level = min(level, LEVEL_OVER_WEIGHT * weight)
    if not level > 0:
        return np.ones(thrust.size, dtype=bool), level, 0.0
    idle = ~(thrust >= idle_fraction * level)  # NaN counts as idle
    ground = idle.copy()
    active = use & ~idle
    hover = float(np.median(thrust[active])) if active.any() else 0.0
    reached = np.flatnonzero(use & (thrust >= takeoff_fraction * hover) & ~idle)
    used = np.flatnonzero(use)
    low = ~(thrust >= ground_fraction * hover)
    if reached.size:
        if low[used[0]]:  # starts on the ground: wait for take-off thrust
            ground[: reached[0]] = True
        if low[used[-1]]:  # ends on the ground: from the last take-off-level thrust
            ground[reached[-1] + 1 :] = True
    return _dilate(ground, round(margin * rate)), level, hover


def segment_flight(
    log: FlightLog,
    idle_fraction: float = IDLE_FRACTION,
    takeoff_fraction: float = TAKEOFF_FRACTION,
    margin: float = MARGIN,
    percentile: float = LEVEL_PERCENTILE,
    ground_fraction: float = GROUND_FRACTION,
    weight: float | None = None,
) -> FlightLog:
    """``log`` with ground / motors-idle samples invalid (rule in the module docs);
    ``weight``: the vehicle's weight in the thrust command's unit (N), or None.

    Segments are recomputed and the excluded spans noted, e.g.
    ``"ground/idle: 0.00-5.31 s excluded (...)"``. A log without
    ``force_command`` is returned with a note.

    Raises:
        LogError: no valid sample is left (thrust zero or idle throughout).
    """
    if "force_command" not in log.signals:
        return replace(log, notes=[*log.notes, "no force_command: flight segmentation skipped"])
    thrust = np.linalg.norm(log.signals["force_command"], axis=1)
    steady = log.valid.copy()
    if "body_rate" in log.signals:  # a tumble's wound-up commands set no level
        with np.errstate(invalid="ignore"):
            steady &= ~(np.abs(log.signals["body_rate"]).max(axis=1) > MAX_BODY_RATE)
    ground, level, hover = ground_mask(
        thrust,
        steady if steady.any() else log.valid,
        log.rate,
        idle_fraction,
        takeoff_fraction,
        margin,
        percentile,
        ground_fraction,
        weight,
    )
    if not (ground & log.valid).any():
        return log
    if not level > 0:
        raise LogError(
            "no flight: the thrust command (|force_command|) is zero throughout", log.path
        )
    valid = log.valid & ~ground
    capped = (
        f", at most {LEVEL_OVER_WEIGHT:g}x the weight {weight:.4g}"
        if weight is not None and level == LEVEL_OVER_WEIGHT * weight
        else ""
    )
    # the thrust in N when the vehicle's weight is known, else in the log's command units
    unit = " N" if weight is not None else " [force unit]"
    note = (
        f"ground/idle: {_spans(log.t, ground)} excluded (thrust command |force_command| "
        f"below {idle_fraction:.0%} of the in-flight level {level:.4g}{unit} "
        f"[{percentile:g}th percentile{capped}], or before reaching / after leaving "
        f"{takeoff_fraction:.0%} of the hover thrust {hover:.4g}{unit} [median] at a start / "
        f"end on the ground; {margin:g} s margin)"
    )
    if not valid.any():
        raise LogError(f"no in-flight samples left: {note}", log.path)
    return replace(log, valid=valid, segments=segments_of(valid), notes=[*log.notes, note])


def _span(log: FlightLog) -> str:
    """Where a time window is counted from, for its errors: the log's span from its
    first sample, that sample's time on the log's own clock when it is not 0, and the
    span of the valid (in-flight, not in gaps) samples."""
    text = f"the log spans 0.00-{log.t[-1]:.2f} s"
    if abs(log.t0) > 1e-6:
        text += f" from its first sample, at {log.t0:.2f} s on the log's own clock"
    text += "; windows count from that first sample"
    if log.valid.any():
        t = log.t[log.valid]
        text += f"; its valid samples span {t[0]:.2f}-{t[-1]:.2f} s"
    return text


def restrict_window(log: FlightLog, window: tuple[float | None, float | None]) -> FlightLog:
    """``log`` with samples outside ``window`` invalid and segments recomputed.

    ``window`` is ``(start, end)`` in s from the log start (``log.t``), half
    open: ``start <= t < end``, so ``(a, b)`` and ``(b, c)`` share no sample (fit
    on one part, evaluate on the other); ``None`` leaves that end open.

    Raises:
        LogError: the window is empty, has no grid sample, or no valid one.
    """
    start, end = window
    lo = -math.inf if start is None else float(start)
    hi = math.inf if end is None else float(end)
    shown = f"{'' if start is None else f'{lo:g}'}:{'' if end is None else f'{hi:g}'}"
    if math.isnan(lo) or math.isnan(hi) or lo >= hi:
        raise LogError(f"empty time window {shown} s: START must be below END", log.path)
    inside = (log.t >= lo - 1e-9) & (log.t < hi - 1e-9)
    if not inside.any():
        raise LogError(f"time window {shown} s has no samples: {_span(log)}", log.path)
    valid = log.valid & inside
    if not valid.any():
        raise LogError(
            f"time window {shown} s has no valid samples (all in gaps or on the ground): "
            f"{_span(log)}",
            log.path,
        )
    outside = int((~inside).sum())
    notes = list(log.notes)
    if outside:
        notes.append(f"time window {shown} s: {outside} of {log.t.size} samples outside excluded")
    return replace(log, valid=valid, segments=segments_of(valid), notes=notes)


def parse_time_window(text: str) -> tuple[float | None, float | None]:
    """``"START:END"`` (s, either may be empty) as ``(start, end)``.

    Raises:
        ConfigError: not of that form, not numbers, or ``START >= END``.
    """
    parts = text.split(":")
    usage = f"--time-window must be START:END in seconds (either may be empty), got '{text}'"
    if len(parts) != 2:
        raise ConfigError(usage)
    out: list[float | None] = []
    for part in parts:
        part = part.strip()
        if not part:
            out.append(None)
            continue
        try:
            x = float(part)
        except ValueError:
            raise ConfigError(usage) from None
        if not math.isfinite(x):
            raise ConfigError(usage)
        out.append(x)
    start, end = out
    if start is not None and end is not None and start >= end:
        raise ConfigError(f"--time-window START must be below END, got '{text}'")
    return start, end
