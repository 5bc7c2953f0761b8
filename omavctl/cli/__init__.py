"""Command-line interface: parse, call one library function, render.

One module per command (:mod:`omavctl.cli.simulate`, ``fit``, ``evaluate``,
``plan``, ``inspect``, ``report``, ``task``); what they share is in
:mod:`omavctl.cli.common`, the typer applications in :mod:`omavctl.cli.app`.
Library errors (:class:`omavctl.base.errors.OmavctlError`) become one line
``error: <file>: <problem>`` on stderr and exit status 2, as usage errors
(:mod:`omavctl.guard`); other failures exit 1. Heavy modules are imported
inside the commands so that ``--help`` and ``--version`` stay fast.
"""

from __future__ import annotations

from omavctl.cli.app import app

# the command modules register their commands on ``app`` when imported, in the
# order ``omavctl --help`` lists them
# isort: off
from omavctl.cli import simulate, fit, evaluate, plan, inspect, report, task  # noqa: F401
# isort: on

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point."""
    from omavctl.guard import run_app

    run_app(app, "omavctl")


if __name__ == "__main__":  # pragma: no cover
    main()
