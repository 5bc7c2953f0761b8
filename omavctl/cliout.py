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
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omavctl.base.shell import display_path, shell_join

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["console", "display_path", "emit_json", "jsonable", "shell_join"]

#: Width of a console whose stream is not a terminal: wide enough that no table wraps.
PIPE_WIDTH = 100_000


def console(quiet: bool = False, stdout: bool = False) -> Console:
    """A rich console on stderr (or stdout); unlimited width when not a terminal."""
    from rich.console import Console

    stream = sys.stdout if stdout else sys.stderr
    tty = _isatty(stream)
    return Console(
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
    sys.stdout.write(text + "\n")
    sys.stdout.flush()
