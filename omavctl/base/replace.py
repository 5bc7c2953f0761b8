"""Which existing files an output may replace.

Every command writes atomically (:mod:`omavctl.base.atomic`) and refuses an output
that is one of its inputs, but ``fit --out flight.bag`` once replaced a recorded
flight that was not among the inputs with a model, and said nothing. An output may
replace only a file of the kind the command writes (its own earlier output), as
``task``, ``plan`` and ``simulate`` already do for trajectories and logs: the
recognisers here read a file's first bytes, its zip members or its MCAP header,
never the whole file, and take the mark of each kind from the module that writes it.
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from omavctl.base.errors import OutputError

__all__ = ["head_has", "is_mcap_from", "is_npz_with", "is_report_file", "refuse_replacing"]

#: bytes of a text file read to find its mark
HEAD_BYTES = 4096
#: the marks of a report (:mod:`omavctl.report.document`: an HTML page's title, the
#: note under a Markdown version's title); tests/test_replace.py writes both and reads
#: them back, so a change of either there fails there
REPORT_MARKS = ("<title>omavctl ", "*Markdown version: the figures are only in the HTML report")


def refuse_replacing(path: str | Path | None, ours: Callable[[Path], bool], what: str) -> None:
    """Refuse an existing, non-empty ``path`` that ``ours`` does not recognise as
    ``what`` (e.g. "an omavctl model"), with one :class:`OutputError` naming it; an
    absent or empty path, or one that cannot be read (the writer says why), passes."""
    if path is None:
        return
    p = Path(path)
    try:
        if not p.exists() or (p.is_file() and p.stat().st_size == 0):
            return
        if p.is_dir() and not any(p.iterdir()):
            return
        mine = p.is_file() and ours(p)
    except OSError:
        return
    if not mine:
        raise OutputError(f"exists and is not {what}; choose another name (or remove it)", p)


def head_has(path: Path, *needles: str) -> bool:
    """Whether the first :data:`HEAD_BYTES` of ``path`` hold any of ``needles``."""
    with path.open("rb") as fh:
        head = fh.read(HEAD_BYTES).decode("utf-8", errors="replace")
    return any(n in head for n in needles)


def is_npz_with(path: Path, members: set[str], schema_prefix: str | None = None) -> bool:
    """Whether ``path`` is a zip holding the arrays ``members`` (names without
    ``.npy``), and, with ``schema_prefix``, a ``schema`` text array starting with it."""
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
        if not {f"{m}.npy" for m in members} <= names:
            return False
        if schema_prefix is None:
            return True
        with np.load(path, allow_pickle=False) as arrays:
            return str(arrays["schema"]).startswith(schema_prefix)
    except (zipfile.BadZipFile, ValueError, KeyError, EOFError):
        return False


def is_mcap_from(path: Path, library: str, profile: str) -> bool:
    """Whether ``path`` is an MCAP file whose header names ``library`` (its first word)
    and ``profile``."""
    from mcap.reader import make_reader

    try:
        with path.open("rb") as fh:
            header = make_reader(fh).get_header()
    except Exception:  # any unreadable file is not ours
        return False
    return header.library.split(" ")[0] == library and header.profile == profile


def is_report_file(path: Path) -> bool:
    """Whether ``path`` is a report ``omavctl report`` or ``plan --report`` wrote: what
    their ``--out`` and ``--report`` may replace."""
    return head_has(path, *REPORT_MARKS)
