"""Flight logs: read ROS 1/ROS 2 bags, MCAP files and wide CSV; align; write; inspect.

The contract (topics, message types, CSV columns) is DESIGN.md section 3.

- :func:`read_raw` reads a log as recorded into a :class:`RawLog`;
- :func:`align` puts it on one uniform grid (:class:`FlightLog`), handling
  gaps, duplicated and out-of-order stamps; :func:`read_log` does both;
- :func:`read_vehicle_log` is the entry point for ``fit``/``evaluate``: it
  applies a vehicle's topics, column map and frame, aligns, restricts to a
  time window and excludes ground/idle time (:func:`segment_flight`);
- :func:`write_log` writes a :class:`RawLog` in any of the formats;
- :func:`inspect_log` / :func:`render_inspect` summarise a log.

Importing this package is cheap: rosbags, mcap and rich are imported only
when a function needs them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from omavctl.logs.align import DEFAULT_REQUIRED, align
from omavctl.logs.columnmap import flatten_column_map, parse_column_map
from omavctl.logs.contract import DEFAULT_TOPICS
from omavctl.logs.frames import FRAMES, convert_frame
from omavctl.logs.inspection import Inspection, inspect_log, render_inspect
from omavctl.logs.read import read_raw
from omavctl.logs.segment import (
    parse_time_window,
    restrict_window,
    segment_flight,
)
from omavctl.logs.types import (
    ANGLE_ROLES,
    ROLE_COLUMNS,
    ROLE_TOPIC,
    FlightLog,
    LogLayout,
    RawLog,
    RawSeries,
    TopicInfo,
)
from omavctl.logs.write import write_log

__all__ = [
    "ANGLE_ROLES",
    "DEFAULT_REQUIRED",
    "DEFAULT_TOPICS",
    "FRAMES",
    "ROLE_COLUMNS",
    "ROLE_TOPIC",
    "FlightLog",
    "Inspection",
    "RawLog",
    "RawSeries",
    "TopicInfo",
    "align",
    "convert_frame",
    "flatten_column_map",
    "inspect_log",
    "parse_column_map",
    "parse_time_window",
    "read_log",
    "read_raw",
    "read_vehicle_log",
    "render_inspect",
    "restrict_window",
    "segment_flight",
    "write_log",
]


#: Given the roles a raw log holds: the role to mix and the function adding the
#: force and torque commands to the aligned log, or None (no mixing).
WrenchHook = Callable[[set[str]], "tuple[str, Callable[[FlightLog], FlightLog]] | None"]


def read_log(
    path: str | Path,
    topics: Mapping[str, str] | None = None,
    rate: float = 100.0,
    required: Sequence[str] = DEFAULT_REQUIRED,
    columns: Mapping[str, Any] | None = None,
    frame: str = "FLU",
) -> FlightLog:
    """Read a log and align it on a uniform grid: ``align(read_raw(path, topics), ...)``.

    Returns a :class:`FlightLog` with ``t`` shape (N,), ``signals[role]`` shape
    (N, k), ``valid`` shape (N,). ``columns`` is the column map for CSVs of other
    layouts (see :func:`read_raw`); ``frame`` the frame the log is in
    (:func:`convert_frame`). No flight segmentation (see
    :func:`read_vehicle_log`). Raises :class:`LogError` (see :func:`read_raw`
    and :func:`align`).
    """
    raw = convert_frame(read_raw(path, topics, columns=columns), frame)
    return align(raw, rate=rate, required=required)


def read_vehicle_log(
    path: str | Path,
    vehicle: LogLayout,
    rate: float = 100.0,
    required: Sequence[str] = DEFAULT_REQUIRED,
    time_window: tuple[float | None, float | None] | None = None,
    trim: bool = True,
    wrench: WrenchHook | None = None,
    weight: float | None = None,
) -> FlightLog:
    """Read a flight log of ``vehicle`` the way ``fit`` and ``evaluate`` need it.

    Steps: read with the vehicle's ``topics`` (bags) or ``columns`` (CSV of
    another layout; a wide contract CSV when empty); convert from the
    vehicle's ``frame`` to FLU body / z-up world; align on a uniform grid at
    ``rate`` Hz (linear interpolation at ``start + k / rate``, gaps split
    segments); with ``trim``, mark ground / motors-idle samples invalid
    (:func:`segment_flight`, level computed over the whole log, at most twice the
    vehicle's ``weight`` in the thrust command's unit when given); with
    ``wrench`` (a vehicle with a rotor list, :func:`omavctl.physics.mixer.wrench_hook`)
    and a log whose roles it can mix (``motor_command``), that role replaces the
    force and torque commands in ``required`` and the hook adds them after
    alignment, before trimming; with
    ``time_window`` ``(start, end)`` in s from the log start (``None`` = open
    end), mark samples outside invalid (:func:`restrict_window`).

    Returns:
        A :class:`FlightLog`: ``t`` shape (N,), ``signals[role]`` shape (N, k),
        ``valid`` shape (N,), ``segments`` the valid runs, ``notes`` with what
        was converted, excluded and why.

    Raises:
        LogError: unreadable log, missing or non-numeric column, missing role,
            an empty time window, nothing left in flight.
        ConfigError: invalid column map or frame.
    """
    columns = vehicle.columns or None
    raw = convert_frame(read_raw(path, vehicle.topics, columns=columns), vehicle.frame)
    mix = wrench(set(raw.series)) if wrench is not None else None
    if mix is None:
        log = align(raw, rate=rate, required=required)
    else:
        source, add = mix
        need = [r for r in required if r not in ("force_command", "torque_command")]
        log = add(align(raw, rate=rate, required=[*need, source]))
    if trim:
        log = segment_flight(log, weight=weight)
    if time_window is not None:
        log = restrict_window(log, time_window)
    return log
