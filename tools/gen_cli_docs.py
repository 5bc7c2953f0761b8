"""Write docs/cli.md, the CLI reference, from the ``--help`` of every command.

Run: python tools/gen_cli_docs.py            (rewrites docs/cli.md)
     python tools/gen_cli_docs.py --check    (exit 1 if docs/cli.md is stale)

The help is produced by ``typer.testing.CliRunner`` on ``omavctl.cli.app`` with
``COLUMNS=100`` so that the text does not depend on the terminal it runs in.
``tests/test_docs.py`` regenerates it in memory and fails when the file is stale.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "cli.md"
COLUMNS = "100"

HEADER = """\
# CLI reference

Generated from `omavctl --help` and every subcommand's `--help` by
`python tools/gen_cli_docs.py`; do not edit by hand (`tests/test_docs.py` fails when
this file is stale). Conventions: every command reads files and writes files; exit
code 0 on success, 2 with one line `error: <file>: <problem>` on bad input (a
file that is unreadable, corrupt, implausible or of another format, a bad option
value, an output that is one of the inputs, a directory, unwritable or an existing
file of another kind than the command writes: `fit` replaces only a model, `evaluate`
an evaluation and its series, `report` a report, `task` and `plan` a trajectory,
`simulate` a log omavctl wrote, never a recorded flight) and on a
usage error, 1 on any other failure (a reader that closes the pipe early, as
`omavctl inspect LOG | head -2` does, is not one: the output stops, the command
runs to its end, its files are written); `--seed` makes sampling commands
reproducible byte for byte; `-q` silences progress bars and the summary; `--json`
prints one JSON object on stdout (the files written and the key figures) while the
human text stays on stderr; a failed `--json` run (a usage error too) prints
`{"command": ..., "error": "<file>: <problem>", "exit_code": N}` there as well.
The human text (verdict, tables, notes) is on stderr with or without `--json`
(stdout is kept for what a script reads: the JSON, `inspect`'s listing), so to page
or search it redirect stderr: `omavctl evaluate LOG --model M 2>&1 | less`.
See [getting-started.md](getting-started.md) for a walk-through and
[design.md](design.md) §5 for the conventions.
"""


def _commands(cmd, path: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Every command path of a click command tree, depth first, sorted by name."""
    yield path
    subs = getattr(cmd, "commands", {})
    for name in sorted(subs):
        yield from _commands(subs[name], (*path, name))


def render() -> str:
    """The text of docs/cli.md for the installed omavctl."""
    import typer
    from typer.testing import CliRunner

    from omavctl.cli import app

    os.environ["COLUMNS"] = COLUMNS
    runner = CliRunner()
    parts = [HEADER]
    root = typer.main.get_command(app)
    paths = list(_commands(root))
    parts.append("Commands: " + ", ".join(f"[`{' '.join(p)}`](#{_anchor(p)})" for p in paths[1:]))
    parts.append("")
    for path in paths:
        result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": COLUMNS})
        if result.exit_code != 0:
            raise RuntimeError(f"omavctl {' '.join(path)} --help failed: {result.output}")
        text = "\n".join(line.rstrip() for line in result.output.strip().splitlines())
        parts.append(f"## {' '.join(('omavctl', *path))}\n\n```text\n{text}\n```\n")
    return "\n".join(parts)


def _anchor(path: tuple[str, ...]) -> str:
    """GitHub-style anchor of the heading ``## omavctl <path>``."""
    return "-".join(("omavctl", *path))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/cli.md is stale")
    ap.add_argument("--out", type=Path, default=OUT, help="output file (default docs/cli.md)")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        current = args.out.read_text() if args.out.exists() else ""
        if current != text:
            print(f"{args.out} is stale: run python tools/gen_cli_docs.py", file=sys.stderr)
            return 1
        return 0
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
