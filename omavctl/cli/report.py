"""``omavctl report``: render evaluations as one HTML/Markdown report, verdict first."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from omavctl.cli.app import app
from omavctl.cli.common import Json, Quiet, console, emit, reports_errors

Evaluations = Annotated[
    list[Path],
    typer.Argument(
        metavar="EVAL.json...",
        help="Evaluation files (.json written by evaluate, with their .series.npz next "
        "to them); with several, the report compares them, relative to the first.",
    ),
]
ReportOut = Annotated[
    Path,
    typer.Option(
        "--out",
        "-o",
        metavar="REPORT",
        help="Output report (one self-contained .html, or .md).",
    ),
]
Format = Annotated[
    str | None,
    typer.Option(
        "--format",
        help="'html' (figures embedded, no network) or 'md' (tables only, no figures). "
        "Default: from --out's suffix (.md -> md, else html).",
    ),
]


@app.command(short_help="Render evaluations as one HTML/Markdown report, verdict first.")
@reports_errors
def report(
    evaluations: Evaluations,
    out: ReportOut,
    fmt: Format = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Render evaluation files as one report, verdict first.

    The verdict (what is missing, how much the error falls with it added, where the
    model fails, whether its uncertainty can be trusted), then figures: error over time
    with the worst segments labelled, measured vs predicted with the 2σ band, effect
    signatures, candidate effects' explained variance, before/after per axis; then the
    summary tables, residual vs feature, the diagnosis with the fit command.
    """
    from omavctl.report.run import run_report

    con = console(quiet)
    with con.status("rendering report"):
        summary = run_report(evaluations, out, fmt)
    _render_report(con, summary, out)
    emit(as_json, _report_json(summary, out))


def _render_report(con: Any, summary: Any, out: Path) -> None:
    """Print the verdict, the RMSE per axis of each evaluation, the change and the fit
    command that adds the top missing effect."""
    from rich.table import Table
    from rich.text import Text

    con.print(Text("verdict", style="bold"))
    for line in summary.verdict:  # as evaluate prints it: the command on a line of its own
        con.print(Text(f"  {line.who}: {line.text}" if line.who else f"  {line.text}"))
        if line.command:
            con.print(Text(f"    {line.add_words.lower()}: {line.command}"))
    table = Table(title="model RMSE per axis, rad/s^2", title_justify="left")
    table.add_column("evaluation")
    for axis in "xyz":
        table.add_column(axis, justify="right")
    table.add_column("diagnosis: top missing")
    for ev in summary.evaluations:
        several = len(ev.models_rmse) > 1 and len(ev.model_names) == len(ev.models_rmse)
        if not several:
            table.add_row(
                Text(ev.label),
                *(f"{ev.model_rmse[a]:.4g}" for a in "xyz"),
                Text(ev.missing[0] if ev.missing else "none"),
            )
            continue
        # one row per --model (the row said the first model's numbers under the file's
        # name alone); the diagnosis, its top missing effect, is the first model's
        for k, (name, rmse) in enumerate(zip(ev.model_names, ev.models_rmse, strict=True)):
            top = (ev.missing[0] if ev.missing else "none") if k == 0 else ""
            table.add_row(
                Text(f"{ev.label}: {name}"), *(f"{rmse[a]:.4g}" for a in "xyz"), Text(top)
            )
    con.print(table)
    change = summary.change() if len(summary.evaluations) > 1 else None
    if change is not None:
        first, last = summary.change_labels()
        con.print(
            f"change {first} -> {last}: "
            + ", ".join(f"{a} {_signed_pct(change[a])}" for a in "xyz"),
            markup=False,
        )
    last = summary.evaluations[-1]
    if last.missing and last.fit_command:
        names = ", ".join(last.missing)  # the fit command adds every missing effect
        con.print(f"to add {names} to {last.label}'s model:", markup=False)
        con.print(f"  {last.fit_command}", markup=False)
    figures = f", {summary.figures} figures" if summary.fmt == "html" else ""
    con.print(f"wrote {out} ({summary.fmt}{figures})", markup=False)


def _signed_pct(change: float | None) -> str:
    """A relative change (fraction) as '-14.1 %', 'n/a' where undefined."""
    return "n/a" if change is None else f"{100 * change:+.1f} %"


def _report_json(summary: Any, out: Path) -> dict[str, Any]:
    """The --json object of report: the file, its format, each evaluation, the verdict."""
    return {
        "command": "report",
        "files": {"report": str(out)},
        "format": summary.fmt,
        "figures": summary.figures,
        "evaluations": [
            {
                "label": ev.label,
                "path": ev.path,
                "model_rmse": ev.model_rmse,
                # each --model's, for a file that holds several (model_rmse is the first's)
                "models": [
                    {"name": name, "model_rmse": rmse}
                    for name, rmse in zip(ev.model_names, ev.models_rmse, strict=False)
                ],
                "missing": ev.missing,
                "fit_command": ev.fit_command,
            }
            for ev in summary.evaluations
        ],
        "change": summary.change(),
        "verdict": [
            {
                "key": ln.key,
                "about": ln.who,
                "text": ln.text,
                "command": ln.command,
                "test": ln.test,
            }
            for ln in summary.verdict
        ],
    }
