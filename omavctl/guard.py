"""How commands fail: one line on stderr, a fixed exit status, nothing left behind.

:func:`guarded` wraps every subcommand of the CLI:

- option values are checked first: a float option that is NaN or infinite is
  refused (typer parses ``nan`` and ``inf`` as floats);
- Python warnings (numerical ones from numpy/scipy among them) are never
  printed: a non-finite intermediate must surface as an error or a note;
- :class:`OmavctlError` (bad input, bad option value, unusable output) becomes
  ``error: <file>: <problem>`` and exit status 2 (:data:`EXIT_BAD_INPUT`,
  the status of usage errors); an operating-system error while writing becomes
  one line and exit status 1; any other exception is an internal error: one
  line, exit status 1 (``OMAVCTL_DEBUG=1`` shows the traceback);
- SIGINT exits 130 and SIGTERM 143, after temporary files are removed;
- with ``--json`` the failure is also one JSON object on stdout,
  ``{"command": ..., "error": "<file>: <problem>", "exit_code": N}``, so a
  pipeline that parses stdout reads why instead of nothing; so is a usage error
  (an unknown option, a bad value, a missing argument) of a command line that
  holds ``--json``, with the command its words name.

:func:`run_app` is the console-script entry: SIGTERM cleanup and one-line
usage errors.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections.abc import Callable
from typing import Any

import typer

from omavctl.base.atomic import Terminated, install_signal_cleanup
from omavctl.base.errors import EXIT_BAD_INPUT, EXIT_FAILURE, OmavctlError

__all__ = ["check_finite_options", "guarded", "run_app"]


def _fail(line: str, code: int, json_of: str | None = None) -> typer.Exit:
    """Print ``line`` on stderr (and, for a ``--json`` run of command ``json_of``, the
    failure as one JSON object on stdout); the exit with ``code``."""
    typer.echo(line, err=True)
    if json_of is not None:
        from omavctl.cliout import emit_json

        emit_json({"command": json_of, "error": line.removeprefix("error: "), "exit_code": code})
    return typer.Exit(code)


def check_finite_options(kwargs: dict[str, Any]) -> None:
    """Refuse NaN or infinite float option values and negative seeds, naming the option."""
    for name, value in kwargs.items():
        option = "--" + name.replace("_", "-")
        if isinstance(value, float) and not math.isfinite(value):
            raise OmavctlError(f"{option} must be a finite number, got {value}")
        if name == "seed" and isinstance(value, int) and not 0 <= value < 2**63:
            raise OmavctlError(f"{option} must be a non-negative integer, got {value}")


def _first_line(err: BaseException) -> str:
    lines = str(err).strip().splitlines()
    return lines[0][:200] if lines else ""


def guarded(func: Callable[..., Any], args: Any, kwargs: dict[str, Any]) -> Any:
    """Run a command body with the failure rules of the module docstring."""
    as_json = func.__name__.replace("_", " ") if kwargs.get("as_json") else None
    try:
        check_finite_options(kwargs)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return func(*args, **kwargs)
    except OmavctlError as err:
        raise _fail(f"error: {err}", EXIT_BAD_INPUT, as_json) from None
    except KeyboardInterrupt:
        raise _fail("error: interrupted", 130, as_json) from None
    except Terminated:
        raise _fail("error: terminated", 143, as_json) from None
    except (typer.Exit, typer.Abort):
        raise
    except OSError as err:
        where = f"{err.filename}: " if err.filename else ""
        line = f"error: {where}{err.strerror or _first_line(err)}"
        raise _fail(line, EXIT_FAILURE, as_json) from None
    except MemoryError:
        raise _fail("error: out of memory", EXIT_FAILURE, as_json) from None
    except Exception as err:
        if os.environ.get("OMAVCTL_DEBUG"):
            raise
        name = type(err).__name__
        raise _fail(
            f"error: internal error ({name}); please report it with the command line "
            "(OMAVCTL_DEBUG=1 shows the traceback)",
            EXIT_FAILURE,
            as_json,
        ) from None


def run_app(app: typer.Typer, prog_name: str) -> None:
    """Run ``app``: SIGTERM removes temp files, usage errors are one line (exit 2)."""
    from typer.exceptions import TyperException

    install_signal_cleanup()
    warnings.simplefilter("ignore")  # also at exit (ResourceWarning), outside any command
    try:
        code = app(prog_name=prog_name, standalone_mode=False)
    except TyperException as err:
        message = err.format_message()
        if type(err).__name__ == "NoArgsIsHelpError":
            typer.echo(message, err=True)
        elif "--json" in sys.argv[1:]:
            ctx = getattr(err, "ctx", None)
            words = ctx.command_path.split()[1:] if ctx is not None else []
            _fail(f"error: {message}", err.exit_code, " ".join(words) or prog_name)
        else:
            typer.echo(f"error: {message}", err=True)
        sys.exit(err.exit_code)
    except (typer.Abort, KeyboardInterrupt):
        typer.echo("error: interrupted", err=True)
        sys.exit(130)
    except Terminated:
        typer.echo("error: terminated", err=True)
        sys.exit(143)
    sys.exit(code if isinstance(code, int) else 0)
