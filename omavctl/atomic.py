"""Atomic output: write to a temporary sibling, then rename over the target.

A crash or an error never leaves a half-written artifact; an existing output
is replaced only once the new one is complete.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from omavctl.errors import OmavctlError

__all__ = ["atomic_dir", "atomic_path", "write_text_atomic"]


def _check_parent(target: Path) -> None:
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise OmavctlError("output directory does not exist", parent)


@contextmanager
def atomic_path(target: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary file path next to ``target``; rename it on success.

    The temporary name keeps ``target``'s suffix (or ``suffix``) so libraries
    that dispatch on extensions behave the same.
    """
    target = Path(target)
    _check_parent(target)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=suffix or target.suffix, dir=target.parent or "."
    )
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp creates 0600; give the artifact the permissions of a normal file
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, target)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_dir(target: str | Path) -> Iterator[Path]:
    """Yield a path (not yet existing) for a directory to be created next to
    ``target``; on success it replaces ``target``."""
    target = Path(target)
    _check_parent(target)
    base = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent or "."))
    inner = base / target.name
    try:
        yield inner
        if target.exists():
            old = base / ".old"
            os.replace(target, old)
        os.replace(inner, target)
    finally:
        shutil.rmtree(base, ignore_errors=True)


def write_text_atomic(target: str | Path, text: str) -> None:
    """Write ``text`` to ``target`` atomically."""
    with atomic_path(target) as tmp:
        tmp.write_text(text)
