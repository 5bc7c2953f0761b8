"""Atomic output: write to a temporary sibling, then rename over the target.

A crash or an error never leaves a half-written artifact; an existing output
is replaced only once the new one is complete. Temporary files are hidden
siblings (``.<name>.<random><suffix>``) that no command ever reads, and they are
removed when a run fails or is interrupted (SIGINT, and SIGTERM once
:func:`install_signal_cleanup` ran). Outputs written together
(:func:`atomic_paths`) are renamed one after the other with SIGINT/SIGTERM
blocked, so an interruption never leaves one new and one old.

:func:`check_outputs` is the one check every command runs before it reads
anything: no output may be one of the inputs (also through another path or a
hard link), a directory (unless the output is a directory) or unwritable.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from omavctl.base.errors import OutputError

__all__ = [
    "Terminated",
    "atomic_dir",
    "atomic_path",
    "atomic_paths",
    "check_outputs",
    "install_signal_cleanup",
    "write_text_atomic",
]


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM so that temporary files are removed."""


def _on_sigterm(signum: int, frame: object) -> None:
    raise Terminated()


def install_signal_cleanup() -> None:
    """Make SIGTERM unwind the stack like SIGINT does (temp files are removed)."""
    signal.signal(signal.SIGTERM, _on_sigterm)


def _parent(target: Path) -> Path:
    return target.parent if str(target.parent) else Path(".")


def _check_parent(target: Path) -> None:
    parent = _parent(target)
    if not parent.is_dir():
        raise OutputError("output directory does not exist", parent)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError("output directory is not writable", parent)


def _mkstemp(target: Path, suffix: str | None) -> Path:
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.", suffix=suffix or target.suffix, dir=_parent(target)
        )
    except OSError as err:
        raise OutputError(f"cannot write: {err.strerror or err}", target) from None
    os.close(fd)
    return Path(tmp)


def _publish(tmp: Path, target: Path) -> None:
    """Give ``tmp`` the permissions of a normal file (mkstemp makes 0600), rename it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


@contextmanager
def _signals_blocked() -> Iterator[None]:
    """Hold SIGINT/SIGTERM back while a group of renames runs (main thread only)."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    except (AttributeError, OSError, ValueError):  # pragma: no cover - not POSIX
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextmanager
def atomic_path(target: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary file path next to ``target``; rename it on success.

    The temporary name keeps ``target``'s suffix (or ``suffix``) so libraries
    that dispatch on extensions behave the same.
    """
    target = Path(target)
    _check_parent(target)
    tmp_path = _mkstemp(target, suffix)
    try:
        yield tmp_path
        _publish(tmp_path, target)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_paths(*targets: str | Path) -> Iterator[list[Path]]:
    """Temporary paths for outputs that belong together, committed together.

    Every target is written under its temporary name first; only when all are
    complete are they renamed, in the order given, with SIGINT/SIGTERM held back.
    The first target should be the one that records what the others hold (a
    content hash), so that a pair left by ``kill -9`` between two renames is
    recognisably inconsistent.
    """
    paths = [Path(t) for t in targets]
    for p in paths:
        _check_parent(p)
    tmps: list[Path] = []
    try:
        for p in paths:
            tmps.append(_mkstemp(p, None))
        yield tmps
        with _signals_blocked():
            for tmp, p in zip(tmps, paths, strict=True):
                _publish(tmp, p)
    except BaseException:
        for tmp in tmps:
            tmp.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_dir(target: str | Path) -> Iterator[Path]:
    """Yield a path (not yet existing) for a directory to be created next to
    ``target``; on success it replaces ``target``."""
    target = Path(target)
    _check_parent(target)
    try:
        base = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=_parent(target)))
    except OSError as err:
        raise OutputError(f"cannot write: {err.strerror or err}", target) from None
    inner = base / target.name
    try:
        yield inner
        with _signals_blocked():
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


# ------------------------------------------------------------ output checks
def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` lies inside the directory ``folder`` (resolved)."""
    try:
        return folder.is_dir() and path.resolve().is_relative_to(folder.resolve())
    except OSError:  # pragma: no cover - unresolvable paths
        return False


def _clash(out: Path, inputs: Sequence[Path]) -> Path | None:
    """The input ``out`` would overwrite (the same file, or a file inside an input
    directory such as a ROS 2 bag), else None."""
    for inp in inputs:
        if out.exists() and inp.exists() and _same(out, inp):
            return inp
        if out.resolve() == inp.resolve() or _inside(out, inp):
            return inp
    return None


def check_outputs(
    inputs: Iterable[str | Path | None],
    outputs: Iterable[str | Path | None],
    directory_ok: bool = False,
) -> None:
    """Refuse, with one :class:`OutputError` naming the output, before any work:

    - an output that is one of ``inputs`` (same path, another path to the same
      file, a hard link) or lies inside an input directory;
    - two outputs naming the same file;
    - an output that is an existing directory (unless ``directory_ok``: outputs
      that are directories, such as ROS 2 bags), whose parent does not exist or
      is not writable.
    """
    ins = [Path(p) for p in inputs if p is not None]
    outs = [Path(p) for p in outputs if p is not None]
    for i, out in enumerate(outs):
        inp = _clash(out, ins)
        if inp is not None:
            shown = "" if str(inp) == str(out) else f" {inp}"
            raise OutputError(f"output would overwrite the input{shown}; choose another name", out)
        for other in outs[:i]:
            if _same(out, other) or out.resolve() == other.resolve():
                raise OutputError(f"the same file is given for two outputs ({other})", out)
        if out.is_dir() and not directory_ok:
            raise OutputError("output is a directory; give a file name", out)
        _check_parent(out)
