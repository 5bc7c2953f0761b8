"""``omavctl inspect``: list a log's topics, rates, gaps and contract roles."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omavctl.cli.app import app
from omavctl.cli.common import LOG_FORMATS, Json, Quiet, VehicleOpt, emit, reports_errors

Log = Annotated[
    Path,
    typer.Argument(
        metavar="LOG",
        help=f"Flight log: {LOG_FORMATS}.",
    ),
]


@app.command(short_help="List a log's topics, rates, gaps and contract roles.")
@reports_errors
def inspect(
    log: Log, vehicle: VehicleOpt = None, quiet: Quiet = False, as_json: Json = False
) -> None:
    """List topics, types, counts, rates, duration, gaps and contract roles of a log.

    The listing goes to stdout (one row per topic, never wrapped in a pipe, so
    `omavctl inspect LOG | grep TOPIC` works); with --json it goes to stderr and stdout
    holds one JSON object. -q is accepted as by every command: with --json it drops
    the listing on stderr; without, the listing is the output and is printed.

    A CSV of another layout, a ULog, a Crazyflie SD-card log or a Betaflight blackbox
    CSV without a column map in --vehicle: list its columns with ranges (and, where the
    format tells, rates and units) and suggest a column map.
    """
    from omavctl.cliout import console
    from omavctl.logs import inspect_log, render_inspect
    from omavctl.physics.mixer import mixed_inspection
    from omavctl.report.summary import inspect_json
    from omavctl.vehicle import load_vehicle

    veh = load_vehicle(vehicle)
    ins = mixed_inspection(inspect_log(log, topics=veh.topics, columns=veh.columns or None), veh)
    if veh.frame != "FLU" and ins.column_ranges:
        # ranges are of the columns as read (scaled), before fit turns them into FLU
        ins.notes.append(
            f"column ranges in the log's {veh.frame} frame (scaled, not yet converted: fit "
            "and evaluate work in FLU, where y and z change sign)"
        )
    if not (quiet and as_json):
        render_inspect(ins, console(stdout=not as_json))
    emit(as_json, inspect_json(ins))
