"""Timing statistics of one stream of stamps: rate, gaps, duplicates, disorder.

One definition, used by the readers (:class:`TopicInfo` of every topic) and by
the aligner (which drops duplicates, sorts and masks gaps).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from omavctl.logs.types import TopicInfo

__all__ = ["GAP_FACTOR", "MIN_GAP", "StampStats", "find_gaps", "stamp_stats", "topic_info"]

#: A step between consecutive stamps is a gap when it exceeds
#: ``max(GAP_FACTOR * median step, MIN_GAP)``.
GAP_FACTOR = 5.0
MIN_GAP = 0.05  # s


@dataclass
class StampStats:
    """What :func:`stamp_stats` finds in stamps shape (n,) (s).

    ``order`` sorts the stamps stably; ``keep`` (indices into the sorted
    stamps) drops exact duplicates, keeping the last; ``gaps`` are
    ``(start, end)`` stamps of the steps longer than the gap threshold.
    """

    count: int
    out_of_order: int
    duplicates: int
    median_dt: float
    order: np.ndarray
    keep: np.ndarray
    gaps: list[tuple[float, float]] = field(default_factory=list)

    @property
    def rate(self) -> float:
        """Median rate (Hz), 0 when there are fewer than two distinct stamps."""
        return 1.0 / self.median_dt if self.median_dt > 0 else 0.0


def _median_dt(u: np.ndarray) -> float:
    return float(np.median(np.diff(u))) if u.size > 1 else 0.0


def find_gaps(u: np.ndarray, median_dt: float | None = None) -> list[tuple[float, float]]:
    """``(start, end)`` of the steps of sorted distinct stamps ``u`` shape (n,)
    longer than ``max(GAP_FACTOR * median step, MIN_GAP)``."""
    if u.size < 2:
        return []
    dt = np.diff(u)
    med = float(np.median(dt)) if median_dt is None else median_dt
    idx = np.flatnonzero(dt > max(GAP_FACTOR * med, MIN_GAP))
    return [(float(u[i]), float(u[i + 1])) for i in idx]


def stamp_stats(stamps: np.ndarray) -> StampStats:
    """Sort, deduplicate and find gaps in ``stamps`` shape (n,) (s, as recorded).

    ``out_of_order`` counts stamps earlier than their predecessor in recorded
    order; ``duplicates`` counts stamps equal to another one (after sorting).
    """
    stamps = np.asarray(stamps, dtype=float)
    n = int(stamps.size)
    out_of_order = int(np.count_nonzero(np.diff(stamps) < 0)) if n > 1 else 0
    order = np.argsort(stamps, kind="stable")
    s = stamps[order]
    if n > 1:
        # keep the last of each run of equal stamps
        last = np.append(s[1:] != s[:-1], True)
        keep = np.flatnonzero(last)
    else:
        keep = np.arange(n)
    duplicates = n - int(keep.size)
    u = s[keep]
    median_dt = _median_dt(u)
    gaps = find_gaps(u, median_dt)
    return StampStats(n, out_of_order, duplicates, median_dt, order, keep, gaps)


def topic_info(name: str, msgtype: str, stamps: np.ndarray) -> TopicInfo:
    """:class:`TopicInfo` of one topic (or CSV column group) from its stamps shape (n,)."""
    st = stamp_stats(stamps)
    duration = float(np.max(stamps) - np.min(stamps)) if st.count else 0.0
    return TopicInfo(
        name=name,
        msgtype=msgtype,
        count=st.count,
        duration=duration,
        rate=st.rate,
        gaps=st.gaps,
        duplicates=st.duplicates,
        out_of_order=st.out_of_order,
    )
