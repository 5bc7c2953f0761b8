"""Text logs, plain or gzip-compressed: one way to open them and one set of errors.

A file whose first bytes are gzip's magic (``1f 8b``) is decompressed as it is
read (:mod:`gzip` streams it: the compressed bytes are never held whole beside
the text), whatever its name; any other file is read as it is. Either must be
UTF-8 text (a byte-order mark is dropped).
"""

from __future__ import annotations

import gzip
import zlib
from pathlib import Path

from omavctl.base.errors import LogError

__all__ = ["GZIP_MAGIC", "is_gzip", "read_head", "read_text"]

#: The first two bytes of every gzip file.
GZIP_MAGIC = b"\x1f\x8b"


def _raw_head(path: Path, size: int) -> bytes:
    try:
        with path.open("rb") as fh:
            return fh.read(size)
    except OSError as err:
        raise LogError(f"cannot read: {err.strerror or err}", path) from None


def is_gzip(path: Path) -> bool:
    """Whether ``path`` starts with gzip's magic bytes."""
    return _raw_head(path, 2) == GZIP_MAGIC


def _gzip_problem(err: BaseException) -> str:
    """What a failure of :mod:`gzip` means for the user, one line."""
    if isinstance(err, EOFError):
        return "the gzip stream ends before its end marker (truncated?)"
    text = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    if "CRC check failed" in text or "Incorrect length" in text:
        return f"the gzip data is corrupt ({text})"
    return f"not a readable gzip file ({text})"


def read_head(path: Path, size: int = 4096) -> bytes:
    """The first ``size`` bytes of the file's content (decompressed when gzip).

    Raises:
        LogError: unreadable file, or a gzip stream broken within those bytes.
    """
    if not is_gzip(path):
        return _raw_head(path, size)
    try:
        with gzip.open(path, "rb") as fh:
            return fh.read(size)
    except (OSError, EOFError, zlib.error) as err:
        raise LogError(_gzip_problem(err), path) from None


def read_text(path: Path, what: str = "CSV file") -> str:
    """The whole text of a plain or gzip-compressed UTF-8 file.

    Raises:
        LogError: unreadable, a corrupt or truncated gzip stream, or not UTF-8
            (``not a <what>: it is not UTF-8 text``).
    """
    try:
        if is_gzip(path):
            with gzip.open(path, "rt", encoding="utf-8-sig") as fh:
                return fh.read()
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise LogError(f"not a {what}: it is not UTF-8 text", path) from None
    except (EOFError, zlib.error, gzip.BadGzipFile) as err:
        raise LogError(_gzip_problem(err), path) from None
    except OSError as err:
        if err.strerror is None:  # raised by gzip on corrupt data, not by the system
            raise LogError(_gzip_problem(err), path) from None
        raise LogError(f"cannot read: {err.strerror}", path) from err
