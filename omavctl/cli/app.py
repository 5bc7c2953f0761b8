"""The typer applications of the CLI: ``omavctl`` and its ``task`` group.

The command modules (:mod:`omavctl.cli.simulate` ...) register their commands
on :data:`app` and :data:`task_app`; :mod:`omavctl.cli` imports them in the
order the commands are listed by ``omavctl --help``.
"""

from __future__ import annotations

from typing import Annotated, Any

import typer

from omavctl import __version__

__all__ = ["app", "task_app"]


def _arguments_by_metavar() -> None:
    """Show an argument with a metavar as just that, e.g. ``LOG...``: typer would add its
    Python type (``LOG... <list[Path]>``) and wrap it in the usage line (``{LOG...}...``)."""
    from typer.core import TyperArgument

    type_rich = TyperArgument.display_type_rich
    usage_name = TyperArgument._usage_display_name

    def display_type_rich(self: TyperArgument, ctx: Any) -> str | None:
        return None if self.metavar else type_rich(self, ctx)

    def usage_display_name(self: TyperArgument) -> str:
        return str(self.metavar) if self.metavar else usage_name(self)

    TyperArgument.display_type_rich = display_type_rich  # type: ignore[method-assign,assignment]
    TyperArgument._usage_display_name = usage_display_name  # type: ignore[method-assign]


_arguments_by_metavar()
app = typer.Typer(
    name="omavctl",
    help="Learn residual models of an omnidirectional aerial vehicle from flight logs, "
    "diagnose missing physics, and plan informative next flights.\n\n"
    "Tables, verdicts and notes go to stderr (inspect's listing excepted); stdout holds "
    "only what --json asks for (one JSON object), so a command can sit in a pipeline.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)
task_app = typer.Typer(
    help="Write a task trajectory as contract CSV (t, x..z, roll..yaw, vx..vz, wx..wz, "
    "ax..az, dwx..dwz; SI units).",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(
    task_app,
    name="task",
    short_help="Task CSV (fig8, circle, pitch, yaw, heave, wobble, chirp, steps).",
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"omavctl {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Print the version."),
    ] = False,
) -> None:
    """omavctl: flight logs -> better models -> better next flights."""
