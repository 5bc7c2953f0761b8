"""Paths and command lines as a user types them (in suggested commands and messages)."""

from __future__ import annotations

import os
import shlex
from collections.abc import Sequence
from pathlib import Path

__all__ = ["display_path", "shell_join"]


def display_path(path: str | Path, cwd: str | Path | None = None) -> str:
    """``path`` as the user in ``cwd`` (default: the current directory) should type it:
    relative when it lies below ``cwd`` or near it, else absolute."""
    p = Path(path)
    base = (Path(cwd) if cwd is not None else Path.cwd()).resolve()
    absolute = p if p.is_absolute() else (base / p)
    absolute = Path(os.path.normpath(absolute))
    try:
        rel = os.path.relpath(absolute, base)
        common = Path(os.path.commonpath([absolute, base.resolve()]))
    except ValueError:  # another drive (Windows)
        return str(absolute)
    # a few '..' within one tree are easier to read than a long absolute path;
    # climbing to the file-system root is not
    near = rel.count("..") <= 2 and common != Path(common.anchor)
    return rel if near else str(absolute)


def shell_join(words: Sequence[str]) -> str:
    """Words as one shell command line, each quoted when it needs to be."""
    return " ".join(shlex.quote(str(w)) for w in words)
