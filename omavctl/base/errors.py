"""One error hierarchy: the CLI catches :class:`OmavctlError` only.

Each error carries the file it concerns (if any) so the CLI can print one line
``error: <file>: <problem>``. Subclasses also inherit the matching builtin so
callers may catch either.

Exit status (the CLI): every :class:`OmavctlError` (bad input, a bad option
value, an output that cannot be written) exits with :data:`EXIT_BAD_INPUT`
(2, the status of usage errors too); any other failure exits 1.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_FAILURE",
    "ConfigError",
    "LogError",
    "ModelError",
    "OmavctlError",
    "OutputError",
    "TrajectoryError",
    "library_reason",
]


#: Exit status of bad input, bad options and unusable outputs (as for usage errors).
EXIT_BAD_INPUT = 2
#: Exit status of any other failure (an operating-system error, an internal error).
EXIT_FAILURE = 1


class OmavctlError(Exception):
    """Base class of every error omavctl reports to the user."""

    def __init__(self, message: str, path: str | Path | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.path = None if path is None else Path(path)

    def __str__(self) -> str:
        if self.path is None:
            return self.message
        return f"{self.path}: {self.message}"


class ConfigError(OmavctlError, ValueError):
    """A vehicle or truth YAML (or a command-line value) is invalid."""


class LogError(OmavctlError, ValueError):
    """A flight log is missing, unreadable, corrupt or lacks what is needed."""


class TrajectoryError(OmavctlError, ValueError):
    """A trajectory CSV does not follow the contract."""


class ModelError(OmavctlError, ValueError):
    """A model artifact is unreadable or of an unsupported schema."""


class OutputError(OmavctlError):
    """An output path that cannot be used (an input, a directory, unwritable)."""


#: Library messages that describe Python internals rather than the file.
_INTERNAL = re.compile(
    r"codec|decode|NoneType|subscriptable|attribute|object|index|out of range|unpack|"
    r"buffer|struct|assert|magic|\(\d+, \d+|0x[0-9a-f]+|byte|position \d+|expected \d+|"
    r"reshape|broadcast|opcode|record has|exceeds limit|\d{10,}|[A-Z]\w*Error",
    re.IGNORECASE,
)


def library_reason(err: BaseException, default: str = "the file is damaged or truncated") -> str:
    """One line for the user about an exception raised by a library reading a file:
    its message when that speaks about the file, else ``default``."""
    text = str(err).strip().splitlines()
    line = text[0].strip() if text else ""
    if not line or _INTERNAL.search(line) or len(line) > 160:
        return default
    return line
