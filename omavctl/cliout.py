"""Terminal output of the CLI: consoles that never wrap tables in pipes, and ``--json``.

Human text goes to stderr (``inspect``'s listing to stdout, so that it can be
grepped); with ``--json`` a command prints exactly one JSON object on stdout.
When the console's stream is not a terminal, its width is unlimited so that a
table row stays one line (``omavctl inspect LOG | grep TOPIC`` finds the row).
JSON never holds NaN or Infinity: non-finite numbers become ``null``.

Light on imports: ``--help`` must not load the numerics.
"""

from __future__ import annotations

import json
import math
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omavctl.base.shell import display_path, shell_join

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["console", "display_path", "emit_json", "jsonable", "reader_gone", "shell_join"]

#: Width of a console whose stream is not a terminal: wide enough that no table wraps.
PIPE_WIDTH = 100_000


def console(quiet: bool = False, stdout: bool = False) -> Console:
    """A rich console on stderr (or stdout); unlimited width when not a terminal; a
    reader that closes the pipe early (``| head -2``) silences it, and the command
    goes on to its end and its exit status (:func:`reader_gone`)."""
    from rich.console import Console

    class _Console(Console):
        def on_broken_pipe(self) -> None:  # rich's default exits 1 (and only mutes stdout)
            self.quiet = True
            reader_gone(self.file)

    stream = sys.stdout if stdout else sys.stderr
    tty = _isatty(stream)
    return _Console(
        stderr=not stdout,
        quiet=quiet,
        highlight=False,
        soft_wrap=True,
        width=None if tty else PIPE_WIDTH,
    )


def _isatty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON types: numpy scalars and arrays to lists, paths to
    strings, non-finite floats to None, dataclass-free mappings and sequences."""
    if obj is None or isinstance(obj, bool | str | int):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if hasattr(obj, "tolist"):  # numpy array or scalar
        return jsonable(obj.tolist())
    if isinstance(obj, Sequence | set | frozenset):
        return [jsonable(v) for v in obj]
    return str(obj)


def emit_json(obj: Mapping[str, Any]) -> None:
    """Print one JSON object (one line) on stdout."""
    text = json.dumps(jsonable(obj), allow_nan=False, sort_keys=False)
    try:
        sys.stdout.write(text + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        reader_gone(sys.stdout)


def reader_gone(stream: Any) -> None:
    """The reader of ``stream``'s pipe closed it (``omavctl inspect LOG | head -2``):
    what is left to write goes to /dev/null, so that neither a later write nor the
    flush at exit fails, and the command ends as it would have (exit 0 when it
    succeeded: a reader that stopped reading is not a failure of the command; the
    files it writes are written). Python's advice on SIGPIPE
    (https://docs.python.org/3/library/signal.html#note-on-sigpipe) without its
    exit 1. A stream without a file descriptor (a test's buffer) is left as it is."""
    try:
        fd = stream.fileno()
    except (AttributeError, ValueError, OSError):
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)
