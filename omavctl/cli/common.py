"""What every command shares: the error wrapper, the consoles, ``--json``, and the
option types used by several commands (declared once as ``Annotated`` aliases).

Light on imports: ``--help`` must not load the numerics.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer

__all__ = [
    "Json",
    "Quiet",
    "VehicleOpt",
    "console",
    "emit",
    "progress_bar",
    "reports_errors",
]

F = TypeVar("F", bound=Callable[..., Any])

#: Every log format the readers take (omavctl.logs.read.detect_format), as the help
#: of fit, evaluate and inspect lists them.
LOG_FORMATS = (
    "ROS 1 .bag, ROS 2 bag directory, .mcap, .csv or .csv.gz, PX4 .ulg, "
    "Crazyflie SD-card log or Betaflight blackbox CSV"
)


def reports_errors(func: F) -> F:
    """Bad input: one line and exit status 2; see :mod:`omavctl.guard`."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from omavctl.guard import guarded

        return guarded(func, args, kwargs)

    return wrapper  # type: ignore[return-value]


def console(quiet: bool = False) -> Any:
    """Human text on stderr; no wrapping when stderr is not a terminal."""
    from omavctl.cliout import console as make

    return make(quiet)


def emit(as_json: bool, obj: dict[str, Any]) -> None:
    """With --json, print ``obj`` as one JSON object on stdout."""
    if as_json:
        from omavctl.cliout import emit_json

        emit_json(obj)


def transient_progress(con: Any, quiet: bool) -> Any:
    """A transient rich ``Progress`` on ``con``: disabled with --quiet or when ``con`` is
    not a terminal (a log file gets no bar and no blank line before an error)."""
    from rich.progress import Progress

    return Progress(console=con, transient=True, disable=quiet or not con.is_terminal)


@contextmanager
def progress_bar(con: Any, quiet: bool, label: str) -> Iterator[Callable[[float], None]]:
    """One transient progress bar (:func:`transient_progress`): yields ``update(fraction)``."""
    with transient_progress(con, quiet) as bar:
        job = bar.add_task(label, total=1.0)
        yield lambda fraction: bar.update(job, completed=fraction)


Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bars or summary.")]
Json = Annotated[
    bool,
    typer.Option(
        "--json",
        help="Print one JSON object on stdout (files written, key figures); "
        "human text stays on stderr.",
    ),
]
VehicleOpt = Annotated[
    Path | None,
    typer.Option(
        "--vehicle",
        metavar="VEHICLE.yaml",
        help="Vehicle YAML (mass, inertia, geometry, limits, gains, topics, effects); "
        "keys not given keep the built-in omav's values.",
    ),
]
