"""``omavctl simulate``: fly a reference through the truth plant, write a flight log."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from omavctl.cli.app import app
from omavctl.cli.common import Json, Quiet, VehicleOpt, console, emit, progress_bar, reports_errors

Reference = Annotated[
    Path, typer.Option("--reference", "-r", metavar="CSV", help="Reference trajectory CSV.")
]
LogOut = Annotated[
    Path,
    typer.Option(
        "--out",
        "-o",
        metavar="LOG",
        help="Output log; its kind follows the name: a directory (no suffix) -> ROS 2 bag "
        "(mcap storage), .bag -> ROS 1 bag, .mcap -> standalone MCAP, .csv -> wide CSV. "
        "An existing LOG is replaced only when omavctl wrote it (never a recorded flight "
        "or another file).",
    ),
]
Truth = Annotated[
    Path | None,
    typer.Option(
        "--truth",
        metavar="TRUTH.yaml",
        help="Truth YAML: actuator imperfections, hidden effects, sensor noise, seed "
        "(default: documented imperfections, no hidden effect, seed 0). The truth's seed "
        "draws the vehicle itself (rotor thrust spread): fly every flight of one vehicle "
        "with the same truth file.",
    ),
]
Seed = Annotated[
    int | None,
    typer.Option(
        help="Sensor-noise seed (default: the truth file's seed, which also draws "
        "the vehicle's rotor thrust spread)."
    ),
]
PhysicsRate = Annotated[float, typer.Option(help="Integration rate of the truth plant, Hz.")]
ModelIn = Annotated[
    Path | None,
    typer.Option(
        "--model",
        metavar="MODEL.npz",
        help="Residual model (.npz written by fit) that the controller inverts, "
        "u + mu(u) = a* (default: the nominal model, mu = 0).",
    ),
]


@app.command(short_help="Fly a reference through the truth plant, write a flight log.")
@reports_errors
def simulate(
    reference: Reference,
    out: LogOut,
    truth: Truth = None,
    vehicle: VehicleOpt = None,
    seed: Seed = None,
    physics_rate: PhysicsRate = 1000.0,
    model: ModelIn = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Fly a reference in closed loop through the truth plant and write a flight log."""
    from omavctl.learn.fly import prepare_simulation

    job = prepare_simulation(
        reference,
        out,
        truth=truth,
        vehicle=vehicle,
        model=model,
        seed=seed,
        physics_rate=physics_rate,
    )
    con = console(quiet)
    with progress_bar(con, quiet, "simulating") as progress:
        result = job.run(progress)
    _render_simulation(con, result, out)
    emit(as_json, _simulation_json(result, out))


def _render_simulation(con: Any, result: Any, out: Path) -> None:
    """Print what was written and how the flight went (a warning if it lost control)."""
    import math

    con.print(
        f"wrote {out}: {result.duration:.2f} s flown, "
        f"max attitude error {math.degrees(result.max_attitude_error):.2f} deg, "
        f"{result.infeasible_steps}/{result.steps} steps beyond actuator limits"
        + (" (thrust or tilt rate: the wrench clipped there)" if result.infeasible_steps else "")
    )
    if result.steps and result.infeasible_steps > 0.05 * result.steps:
        con.print(
            f"note: {100 * result.infeasible_steps / result.steps:.0f} % of the steps asked "
            "for more than the actuators give (thrust or tilt-rate limit): there the applied "
            "wrench differs from the command and the vehicle may not follow its reference",
            markup=False,
        )
    if result.diverged:
        con.print(
            f"[bold red]warning:[/] the vehicle lost control at {result.diverged_at:.2f} s; "
            "the log goes on through the tumble for 1 s, then ends"
        )


def _simulation_json(result: Any, out: Path) -> dict[str, Any]:
    """The --json object of simulate: the log written and the flight's key figures."""
    import math

    return {
        "command": "simulate",
        "files": {"log": str(out)},
        "duration": result.duration,
        "max_attitude_error_deg": math.degrees(result.max_attitude_error),
        "infeasible_steps": int(result.infeasible_steps),
        "steps": int(result.steps),
        "diverged": bool(result.diverged),
        "diverged_at": result.diverged_at,
    }
