"""``omavctl evaluate``: compare models with a flight: verdict, errors, missing physics."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omavctl.cli.app import app
from omavctl.cli.common import LOG_FORMATS, Json, Quiet, console, emit, reports_errors

Logs = Annotated[
    list[Path],
    typer.Argument(
        metavar="LOG...",
        help=f"Flight logs to compare the models with, each a {LOG_FORMATS}; best not the "
        "ones the model was fitted on.",
    ),
]
Models = Annotated[
    list[Path],
    typer.Option(
        "--model",
        "-m",
        metavar="MODEL.npz",
        help="Model written by fit; its vehicle and column map read the logs (repeat to "
        "compare several models side by side; the first one is diagnosed, and no fit "
        "command is suggested for an effect a later one already has; the change is "
        "read from the model with fewer effects to the one with more, in either order).",
    ),
]
EvalOut = Annotated[
    Path | None,
    typer.Option(
        "--out",
        "-o",
        metavar="EVAL.json",
        help="Evaluation JSON (schema omavctl.eval/1); time series go to "
        "<stem>.series.npz beside it. Default: <model stem>.eval.json beside the first "
        "model.",
    ),
]
Mcap = Annotated[
    Path | None,
    typer.Option(
        "--mcap",
        metavar="SERIES.mcap",
        help="MCAP file of the time series for Foxglove/PlotJuggler (measured, predicted, "
        "2σ band, nominal, physics-only, worst-segment markers; JSON channels on the log's "
        "own time stamps). Default: <stem>.series.mcap beside the evaluation JSON.",
    ),
]
TimeWindow = Annotated[
    str | None,
    typer.Option(
        metavar="START:END",
        help="Only samples with START <= t < END (s from log start), e.g. 15: or 2.5:10.",
    ),
]
Horizons = Annotated[
    str | None,
    typer.Option(
        metavar="S,S,...",
        help="Open-loop prediction horizons in seconds (default 0.01,0.1,0.5; 'none': no "
        "horizon table): from each start the body rate and attitude are rolled forward "
        "over the logged commands and compared with the log, for holding the state, "
        "nominal physics, nominal + the model's effects and each model.",
    ),
]
NoVehicle = Annotated[
    Path | None,
    typer.Option(
        "--vehicle",
        hidden=True,
        help="Not an option of evaluate: the vehicle and its column map come from the model.",
    ),
]
HorizonStride = Annotated[
    int,
    typer.Option(
        metavar="N",
        help="Samples between the starts of the horizon windows (at least: a log with more "
        "windows than memory allows gets a larger stride, which the table says).",
    ),
]


@app.command(short_help="Compare models with a flight: verdict, errors, missing physics.")
@reports_errors
def evaluate(
    logs: Logs,
    model: Models,
    out: EvalOut = None,
    mcap: Mcap = None,
    time_window: TimeWindow = None,
    horizons: Horizons = None,
    horizon_stride: HorizonStride = 1,
    vehicle: NoVehicle = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Compare models with measured angular accelerations, find where they fail, and
    diagnose which physical effect is missing.

    Prints the verdict first (what is missing and the fit command that adds it, where
    the model fails and what the vehicle was doing, whether its 2σ band can be trusted),
    then the RMSE (rad/s^2) of the nominal model, nominal + effects and each model side
    by side, then the open-loop body-rate and attitude errors over the horizons. Writes
    the evaluation JSON, its .series.npz and an MCAP of the series.

    There is no --vehicle: the vehicle (and its column map, which reads the logs)
    comes from the first model file, as fit recorded it.

    With two or more --model: the verdict's change line compares the first and the
    last (with three or more, each step first); when one's effects are a subset of the
    other's, it is the "before" whatever the order ("With motor_lag added (a.npz →
    b.npz)"), otherwise the given order ("From a.npz to b.npz, X added, Y removed").
    The lines after it diagnose the first --model.
    """
    if vehicle is not None:
        from omavctl.base.errors import OmavctlError

        raise OmavctlError(
            "evaluate takes no --vehicle: the vehicle and its column map come from the "
            "model file (the --vehicle given to fit); to read the logs with another one, "
            "fit a model with it"
        )
    from omavctl.report.run import run_evaluation
    from omavctl.report.summary import evaluation_json, render_evaluation

    run = run_evaluation(logs, model, out, mcap, time_window, horizons, horizon_stride)
    render_evaluation(console(quiet), run.result.tree, run.files)
    emit(as_json, evaluation_json(run.result.tree, run.files))
