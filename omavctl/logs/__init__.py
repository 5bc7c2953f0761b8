"""Flight logs: read ROS 1/ROS 2 bags, MCAP files and wide CSV; align; write; inspect.

The contract (topics, message types, CSV columns) is DESIGN.md section 3.

- :func:`read_raw` reads a log as recorded into a :class:`RawLog`;
- :func:`align` puts it on one uniform grid (:class:`FlightLog`), handling
  gaps, duplicated and out-of-order stamps; :func:`read_log` does both;
- :func:`write_log` writes a :class:`RawLog` in any of the formats;
- :func:`inspect_log` / :func:`render_inspect` summarise a log.

Importing this package is cheap: rosbags, mcap and rich are imported only
when a function needs them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from omavctl.logs.align import DEFAULT_REQUIRED, align
from omavctl.logs.contract import DEFAULT_TOPICS
from omavctl.logs.inspection import Inspection, inspect_log, render_inspect
from omavctl.logs.read import read_raw
from omavctl.logs.types import (
    ANGLE_ROLES,
    ROLE_COLUMNS,
    ROLE_TOPIC,
    FlightLog,
    RawLog,
    RawSeries,
    TopicInfo,
)
from omavctl.logs.write import write_log

__all__ = [
    "ANGLE_ROLES",
    "DEFAULT_REQUIRED",
    "DEFAULT_TOPICS",
    "ROLE_COLUMNS",
    "ROLE_TOPIC",
    "FlightLog",
    "Inspection",
    "RawLog",
    "RawSeries",
    "TopicInfo",
    "align",
    "inspect_log",
    "read_log",
    "read_raw",
    "render_inspect",
    "write_log",
]


def read_log(
    path: str | Path,
    topics: Mapping[str, str] | None = None,
    rate: float = 100.0,
    required: Sequence[str] = DEFAULT_REQUIRED,
    columns: Mapping[str, Any] | None = None,
) -> FlightLog:
    """Read a log and align it on a uniform grid: ``align(read_raw(path, topics), ...)``.

    Returns a :class:`FlightLog` with ``t`` shape (N,), ``signals[role]`` shape
    (N, k), ``valid`` shape (N,). ``columns`` is the column map for CSVs of other
    layouts (see :func:`read_raw`). Raises :class:`LogError` (see
    :func:`read_raw` and :func:`align`).
    """
    return align(read_raw(path, topics, columns=columns), rate=rate, required=required)
