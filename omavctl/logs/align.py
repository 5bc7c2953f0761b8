"""Put every signal role of a :class:`RawLog` on one uniform time grid.

Per role: stamps are sorted (out-of-order stamps counted), exact duplicates
dropped (the last one kept) and gaps found (a step longer than
``max(5 x median step, 0.05 s)``). The grid runs from the latest first stamp
to the earliest last stamp over the roles present, at ``start + k / rate``;
each column is linearly interpolated (angles unwrapped first and wrapped to
(-pi, pi] after). Grid points inside any role's gap are marked invalid.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from omavctl.base.errors import LogError
from omavctl.logs.contract import DEFAULT_TOPICS, wrap_angle
from omavctl.logs.stats import find_gaps, stamp_stats
from omavctl.logs.types import ANGLE_ROLES, ROLE_COLUMNS, ROLE_TOPIC, FlightLog, RawLog, RawSeries

__all__ = ["DEFAULT_REQUIRED", "MIN_SAMPLES", "align", "interpolate", "segments_of"]

#: Roles ``fit`` and ``evaluate`` cannot do without.
DEFAULT_REQUIRED: tuple[str, ...] = ("body_rate", "attitude", "force_command", "torque_command")

#: Roles whose recorded samples the aligned log keeps beside the grid
#: (:attr:`FlightLog.recorded`): the body rate's noise is estimated on them.
RECORDED_ROLES = ("body_rate",)

#: Fewest grid samples an aligned log may have.
MIN_SAMPLES = 10


def interpolate(stamps: np.ndarray, values: np.ndarray, t: np.ndarray, angle: bool) -> np.ndarray:
    """Linear interpolation of ``values`` shape (n, k) at stamps shape (n,)
    (sorted, distinct) onto ``t`` shape (m,); returns shape (m, k).

    Outside the stamps the end values are held. With ``angle`` the columns are
    unwrapped before and wrapped to (-pi, pi] after.
    """
    v = np.unwrap(values, axis=0) if angle else values
    out = np.empty((t.size, v.shape[1]))
    for j in range(v.shape[1]):
        out[:, j] = np.interp(t, stamps, v[:, j])
    return wrap_angle(out) if angle else out


def segments_of(valid: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges ``[start, stop)`` of the runs of True in ``valid`` shape (n,)."""
    padded = np.concatenate([[False], np.asarray(valid, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _label(raw: RawLog, role: str) -> str:
    """Where a role came from, for messages: its topic name, or "CSV" for CSV."""
    if raw.format == "csv":
        return "CSV"
    names = raw.topic_names or DEFAULT_TOPICS
    return names.get(ROLE_TOPIC[role], ROLE_TOPIC[role])


def _missing_error(raw: RawLog, role: str) -> LogError:
    if role in ("force_command", "torque_command") and "motor_command" in raw.series:
        return LogError(
            f"no {role}, and motor_command cannot be mixed without the vehicle's rotors: "
            "give a vehicle file with a rotor list (motors:, or preset: NAME, docs/logs.md)",
            raw.path,
        )
    if raw.mapped:  # a CSV read through a column map
        if role in raw.mapped:
            return LogError(f"no usable values for {role} in {raw.mapped[role]}", raw.path)
        return LogError(f"the column map has no entry for {role} (columns.{role})", raw.path)
    if raw.format == "csv":
        cols = ", ".join(f"{role}_{c}" for c in ROLE_COLUMNS[role])
        return LogError(
            f"missing columns for {role}: {cols} (omavctl inspect names columns that look "
            "like them)",
            raw.path,
        )
    return LogError(f"missing topic '{_label(raw, role)}' (role {role})", raw.path)


#: Largest plausible magnitude of a logged value per role (SI units; commands may
#: be normalised): beyond it a value is corrupt, not measured. Body rates: a
#: gyro saturates near 35 rad/s; a simulated tumble is cut at 200 rad/s.
ROLE_LIMITS = {
    "body_rate": 1e3,
    "attitude": 1e3,
    "reference_attitude": 1e3,
    "position": 1e5,
    "reference_position": 1e5,
    "velocity": 1e3,
    "force_command": 1e5,
    "torque_command": 1e5,
    "desired_acceleration": 1e5,
    "desired_linear_acceleration": 1e5,
}
#: Default limit of roles not listed (tilt angles, rotor speeds, ...).
DEFAULT_LIMIT = 1e6
#: Most grid samples of one aligned log (over 11 days at 100 Hz).
MAX_GRID = 100_000_000


def _plausible(
    raw: RawLog,
    role: str,
    s: np.ndarray,
    v: np.ndarray,
    required: bool,
    note: Callable[[str], None],
) -> tuple[np.ndarray, np.ndarray]:
    """Samples of ``role`` within :data:`ROLE_LIMITS`; a required role with a value
    beyond is an error, an optional role loses those samples (with a note)."""
    limit = ROLE_LIMITS.get(role, DEFAULT_LIMIT)
    big = (np.abs(v) > limit).any(axis=1) if v.size else np.zeros(s.size, dtype=bool)
    if not big.any():
        return s, v
    first = int(np.flatnonzero(big)[0])
    label = _label(raw, role)
    value = float(v[first][np.argmax(np.abs(v[first]))])
    if required:
        raise LogError(
            f"implausible value {value:.3g} in {label} (role {role}) at t={s[first]:.3f} s "
            f"(beyond ±{limit:g})",
            raw.path,
        )
    note(f"{label}: {int(big.sum())} samples of {role} beyond ±{limit:g} dropped")
    return s[~big], v[~big]


#: Hz: a body rate logged slower than this is more likely a time column in the wrong
#: unit than a slow logger (a Crazyflie's ms clock read as s: "1.01 Hz", and the advice
#: was to set controller.rate_hz to 1 Hz).
SLOW_LOG_HZ = 20.0
TIME_SCALE_HINT = (
    "the time column's scale under columns: in the vehicle YAML; a ms clock read as s "
    "gives a rate 1000x too low"
)


def slow_log_message(logged: float, grid: float) -> str:
    """The one line for a body rate logged at ``logged`` Hz, below half the ``grid``
    rate: below :data:`SLOW_LOG_HZ` the time column's unit first, then the rate."""
    rate_hint = f"set controller.rate_hz to at most {math.floor(logged):d} Hz"
    if logged >= SLOW_LOG_HZ:
        hint = f"{rate_hint} in the vehicle YAML"
    else:
        hint = f"check the time column's unit first ({TIME_SCALE_HINT})"
        hint += f"; if it is right, {rate_hint}" if logged >= 1.0 else ""
    return (
        f"body rate logged at {logged:.3g} Hz, below half the {grid:g} Hz grid "
        f"(controller.rate_hz): {hint}"
    )


def _refuse_slow_clock(raw: RawLog, rate: float) -> None:
    """Refuse, before the grid is built, a body rate logged below :data:`SLOW_LOG_HZ` and
    half the grid ``rate``: a ms clock read as s made a 50 000 s log whose 500 Hz grid
    took a minute and gigabytes before ``fit`` refused it."""
    series = raw.series.get("body_rate")
    if series is None or series.stamps.size < 3:
        return
    step = float(np.median(np.diff(series.stamps)))
    logged = 1.0 / step if step > 0 else math.inf
    if logged < min(SLOW_LOG_HZ, 0.5 * rate):
        raise LogError(slow_log_message(logged, rate), raw.path)


def align(
    raw: RawLog,
    rate: float = 100.0,
    required: Sequence[str] = DEFAULT_REQUIRED,
) -> FlightLog:
    """Resample every role of ``raw`` onto one uniform grid.

    Args:
        raw: the log as read (:func:`read_raw`).
        rate: grid rate (Hz).
        required: roles that must be present and finite; other roles are
            optional (non-finite samples of an optional role are dropped with a
            note; a role with fewer than 2 usable samples is dropped).

    Returns:
        A :class:`FlightLog`: ``t`` shape (N,) from 0 at step ``1/rate``,
        ``signals[role]`` shape (N, k), ``valid`` shape (N,), ``segments``, and
        ``notes`` with everything the reader and the aligner found.

    Raises:
        LogError: a required role is missing, has non-finite values or too few
            samples; the signals overlap on fewer than 10 grid samples.
    """
    if not (math.isfinite(rate) and rate > 0):
        raise LogError(f"grid rate must be a positive number of Hz, got {rate}", raw.path)
    unknown = [r for r in required if r not in ROLE_COLUMNS]
    if unknown:
        raise ValueError(f"unknown signal roles in required: {', '.join(unknown)}")
    for role in required:
        if role not in raw.series:
            raise _missing_error(raw, role)
    _refuse_slow_clock(raw, rate)

    notes: list[str] = []

    def note(text: str) -> None:
        if text not in notes:
            notes.append(text)

    clean: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for role, series in raw.series.items():
        if role not in ROLE_COLUMNS:
            note(f"unknown signal role '{role}' ignored")
            continue
        usable = _clean_series(raw, role, series, role in required, note)
        if usable is not None:
            clean[role] = usable
    if not clean:
        raise LogError("no usable signals in the log", raw.path)
    start, n = _common_grid(raw, clean, rate)
    t = np.arange(n) / rate
    grid = start + t
    signals = {role: interpolate(s, v, grid, role in ANGLE_ROLES) for role, (s, v) in clean.items()}
    valid = _outside_gaps(raw, clean, grid, start, note)
    invalid = int(n - valid.sum())
    if invalid:
        note(f"{invalid} of {n} grid samples inside gaps marked invalid")

    return FlightLog(
        path=raw.path,
        format=raw.format,
        t=t,
        signals=signals,
        valid=valid,
        segments=segments_of(valid),
        rate=float(rate),
        topics=list(raw.topics),
        notes=list(raw.notes) + notes,
        t0=float(raw.t0) + float(start),
        recorded={role: (s - start, v) for role, (s, v) in clean.items() if role in RECORDED_ROLES},
    )


def _clean_series(
    raw: RawLog, role: str, series: RawSeries, required: bool, note: Callable[[str], None]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Stamps (n,) and values (n, k) of one role, sorted, unique, finite and plausible.

    ``None`` when an optional role keeps fewer than 2 samples; a required role
    with non-finite values or too few samples raises :class:`LogError`.
    """
    label = _label(raw, role)
    stamps = np.asarray(series.stamps, dtype=float).reshape(-1)
    values = np.asarray(series.values, dtype=float).reshape(stamps.size, -1)
    st = stamp_stats(stamps)
    if st.out_of_order:
        note(f"{label}: {st.out_of_order} out-of-order stamps (sorted)")
    if st.duplicates:
        note(f"{label}: {st.duplicates} duplicated stamps dropped (last kept)")
    idx = st.order[st.keep]
    s, v = stamps[idx], values[idx]
    ok = np.isfinite(v).all(axis=1) & np.isfinite(s)
    if not ok.all():
        first = int(np.flatnonzero(~ok)[0])
        if required:
            raise LogError(
                f"non-finite value in {label} (role {role}) at t={s[first]:.3f} s",
                raw.path,
            )
        note(f"{label}: {int((~ok).sum())} samples of {role} with non-finite values dropped")
        s, v = s[ok], v[ok]
    s, v = _plausible(raw, role, s, v, required, note)
    if s.size < 2:
        if required:
            raise LogError(
                f"too few samples in {label} (role {role}): {s.size}, need at least 2",
                raw.path,
            )
        note(f"{label}: {role} has {s.size} usable samples; not used")
        return None
    return s, v


def _common_grid(
    raw: RawLog, clean: dict[str, tuple[np.ndarray, np.ndarray]], rate: float
) -> tuple[float, int]:
    """Start (s, raw stamps) and length of the grid where every role has data."""
    start = max(s[0] for s, _ in clean.values())
    end = min(s[-1] for s, _ in clean.values())
    # tolerance: a span of 3 s read as 2.99999999999997 s still has its last sample
    n = math.floor((end - start) * rate + 1e-6) + 1 if end >= start else 0
    if n < MIN_SAMPLES:
        span = max(end - start, 0.0)
        rows = min(s.size for s, _ in clean.values())
        # thousands of samples in a fraction of a second: a time column in the wrong unit
        hint = (
            f"; yet every signal has {rows} samples: check the time column and its scale"
            if rows >= MIN_SAMPLES * 10
            else ""
        )
        raise LogError(
            f"too little data: the signals overlap for {span:.3f} s, {max(n, 0)} samples "
            f"at {rate:g} Hz (need at least {MIN_SAMPLES}){hint}",
            raw.path,
        )
    if n > MAX_GRID:
        raise LogError(
            f"the signals span {end - start:.3g} s, over {MAX_GRID} samples at {rate:g} Hz "
            "(a corrupt time stamp?)",
            raw.path,
        )
    return float(start), int(n)


def _outside_gaps(
    raw: RawLog,
    clean: dict[str, tuple[np.ndarray, np.ndarray]],
    grid: np.ndarray,
    start: float,
    note: Callable[[str], None],
) -> np.ndarray:
    """Valid mask (n,) of the grid: False strictly inside a gap of any role."""
    n = grid.size
    # +1 where an invalid run starts, -1 where it ends; cumsum > 0 is invalid
    marks = np.zeros(n + 1, dtype=np.int64)
    for role, (s, _) in clean.items():
        gaps = find_gaps(s)
        if not gaps:
            continue
        a, b = np.array(gaps).T
        # grid points strictly inside (a, b): indices [lo, hi)
        lo = np.searchsorted(grid, a, side="right")
        hi = np.searchsorted(grid, b, side="left")
        for ga, gb, i0, i1 in zip(a, b, lo, hi, strict=True):
            if i1 <= i0:
                continue
            marks[i0] += 1
            marks[i1] -= 1
            note(
                f"gap of {gb - ga:.2f} s at t={ga - start:.2f} s in {_label(raw, role)}: "
                f"samples {i0}-{i1 - 1} excluded"
            )
    return np.cumsum(marks[:n]) == 0
