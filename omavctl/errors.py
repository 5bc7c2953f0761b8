"""One error hierarchy: the CLI catches :class:`OmavctlError` only.

Each error carries the file it concerns (if any) so the CLI can print one line
``error: <file>: <problem>``. Subclasses also inherit the matching builtin so
callers may catch either.
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "ConfigError",
    "LogError",
    "ModelError",
    "OmavctlError",
    "TrajectoryError",
]


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
