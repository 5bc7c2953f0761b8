"""Which reader turns a log of each kind into named columns (:class:`~.tables.ColumnTable`)."""

from __future__ import annotations

from pathlib import Path

from omavctl.base.errors import LogError
from omavctl.logs.betaflight import betaflight_table, sidecar_error, sniff_betaflight
from omavctl.logs.cfusdlog import cfusdlog_table, looks_like_cfusdlog
from omavctl.logs.tables import ColumnTable

__all__ = ["TABLE_KINDS", "content_kind", "load_table"]

#: The kinds of :func:`~.read.detect_format` read as a :class:`ColumnTable`.
TABLE_KINDS = ("cfusdlog", "betaflight")


def load_table(path: Path, kind: str) -> ColumnTable:
    """The :class:`ColumnTable` of a log of ``kind`` ``"cfusdlog"`` or ``"betaflight"``
    (as :func:`~.read.detect_format` names them).

    Raises:
        LogError: see :func:`~.cfusdlog.read_cfusdlog`, :func:`~.betaflight.betaflight_table`.
    """
    if kind == "cfusdlog":
        return cfusdlog_table(path)
    if kind == "betaflight":
        return betaflight_table(path)
    raise ValueError(f"no column table reader for {kind!r}")


def content_kind(path: Path) -> str | None:
    """The kind of a file whose name says none, from its first bytes: ``"cfusdlog"``
    (the cfusdlog header), ``"betaflight"`` (a blackbox CSV, plain or gzip), else None.

    Raises:
        LogError: a Betaflight header sidecar (:func:`~.betaflight.sidecar_error`).
    """
    if not path.is_file():
        return None
    try:
        with path.open("rb") as fh:
            head = fh.read(256)
    except OSError as err:
        raise LogError(f"cannot read: {err.strerror or err}", path) from None
    if looks_like_cfusdlog(head[:8]):
        return "cfusdlog"
    sidecar = sidecar_error(path, head)
    if sidecar is not None:
        raise sidecar
    return "betaflight" if sniff_betaflight(path) else None
