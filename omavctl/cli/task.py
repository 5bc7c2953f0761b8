"""``omavctl task ...``: write a task trajectory as contract CSV."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from omavctl.base.atomic import check_outputs
from omavctl.cli.app import task_app
from omavctl.cli.common import Json, Quiet, console, emit, reports_errors

Out = Annotated[Path, typer.Option("--out", "-o", metavar="CSV", help="Output trajectory CSV.")]
Rate = Annotated[float, typer.Option(help="Sample rate of the CSV, Hz.")]
Height = Annotated[float, typer.Option(help="Hover height (z), m.")]
Duration = Annotated[float, typer.Option(help="Total duration, s.")]
Ramp = Annotated[float, typer.Option(help="Smooth start/stop ramp, s.")]


def _write_task(traj: Any, out: Path, quiet: bool, as_json: bool = False, name: str = "") -> None:
    """Write ``traj`` to ``out`` (contract CSV), say so, and with --json print the figures."""
    from omavctl.sim.trajectory import check_replaceable, write_trajectory

    check_outputs([], [out])
    check_replaceable(out)
    write_trajectory(out, traj)
    if not quiet:
        console().print(f"wrote {out} ({traj.data.shape[0]} samples, {traj.duration:.2f} s)")
    emit(
        as_json,
        {
            "command": f"task {name}".strip(),
            "files": {"trajectory": str(out)},
            "samples": int(traj.data.shape[0]),
            "duration": float(traj.duration),
        },
    )


@task_app.command("fig8", short_help="Attitude figure-8 at constant position (the paper's task).")
@reports_errors
def task_fig8(
    out: Out,
    roll: Annotated[float, typer.Option(help="Roll amplitude, deg.")] = 26.0,
    pitch: Annotated[float, typer.Option(help="Pitch amplitude, deg.")] = 26.0,
    period: Annotated[float, typer.Option(help="Period of one figure-8, s.")] = 8.0,
    duration: Duration = 24.0,
    ramp: Ramp = 2.0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Attitude figure-8 at constant position: roll = A_r sin(wt), pitch = A_p sin(2wt)."""
    from omavctl.sim.tasks import fig8

    _write_task(
        fig8(roll, pitch, period, duration, rate, ramp, height), out, quiet, as_json, "fig8"
    )


@task_app.command("circle", short_help="Horizontal circle at level attitude, from rest to rest.")
@reports_errors
def task_circle(
    out: Out,
    radius: Annotated[float, typer.Option(help="Circle radius, m.")] = 1.0,
    period: Annotated[float, typer.Option(help="Time per lap at full speed, s.")] = 6.0,
    duration: Duration = 24.0,
    ramp: Annotated[float, typer.Option(help="Smooth speed-up/slow-down ramp, s.")] = 3.0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Horizontal circle at level attitude, starting and ending at rest."""
    from omavctl.sim.tasks import circle

    _write_task(circle(radius, period, duration, rate, ramp, height), out, quiet, as_json, "circle")


@task_app.command("pitch", short_help="The paper's pitching manoeuvre (60 deg, 1 rad/s^2).")
@reports_errors
def task_pitch(
    out: Out,
    amplitude: Annotated[float, typer.Option(help="Pitch amplitude, deg (< 90).")] = 60.0,
    max_acceleration: Annotated[
        float, typer.Option(help="Pitch acceleration amplitude A w^2, rad/s^2 (sets the period).")
    ] = 1.0,
    duration: Duration = 30.0,
    ramp: Ramp = 3.0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Pitching manoeuvre as in the paper (60 deg, 1 rad/s^2 by default)."""
    from omavctl.sim.tasks import pitch

    _write_task(
        pitch(amplitude, max_acceleration, duration, rate, ramp, height),
        out,
        quiet,
        as_json,
        "pitch",
    )


@task_app.command("yaw", short_help="Yaw oscillation at level attitude (identifies servo_lag).")
@reports_errors
def task_yaw(
    out: Out,
    amplitude: Annotated[float, typer.Option(help="Yaw amplitude, deg.")] = 30.0,
    period: Annotated[float, typer.Option(help="Period of the oscillation, s.")] = 4.0,
    duration: Duration = 20.0,
    ramp: Ramp = 2.0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Yaw oscillation at level attitude (identifies servo_lag: small tilts, fast tilt rates)."""
    from omavctl.sim.tasks import yaw

    _write_task(yaw(amplitude, period, duration, rate, ramp, height), out, quiet, as_json, "yaw")


@task_app.command(
    "heave", short_help="Vertical oscillation at level attitude (identifies com_offset)."
)
@reports_errors
def task_heave(
    out: Out,
    amplitude: Annotated[float, typer.Option(help="Vertical amplitude, m.")] = 0.2,
    period: Annotated[float, typer.Option(help="Period of the oscillation, s.")] = 3.0,
    duration: Duration = 20.0,
    ramp: Ramp = 2.0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Vertical oscillation at level attitude (identifies com_offset: thrust varies, no tilt)."""
    from omavctl.sim.tasks import heave

    _write_task(
        heave(amplitude, period, duration, rate, ramp, height), out, quiet, as_json, "heave"
    )


@task_app.command(
    "wobble",
    short_help="Multi-sine roll/pitch/yaw wobble (a second trajectory to test a model on).",
)
@reports_errors
def task_wobble(
    out: Out,
    amplitude: Annotated[
        float, typer.Option(help="Sum of the sine amplitudes per axis, deg (yaw half).")
    ] = 15.0,
    bandwidth: Annotated[float, typer.Option(help="Highest sine frequency, Hz.")] = 0.8,
    duration: Duration = 20.0,
    ramp: Ramp = 2.0,
    seed: Annotated[int, typer.Option(help="Draws the frequencies and phases.")] = 0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Multi-sine attitude wobble: roll, pitch and yaw each a sum of three sines
    (frequencies 0.15-1 x bandwidth, random phases). Not periodic: fit on a figure-8,
    evaluate on a wobble to see whether a model holds on a flight it has not seen."""
    from omavctl.sim.tasks import wobble

    _write_task(
        wobble(amplitude, bandwidth, duration, rate, ramp, height, seed),
        out,
        quiet,
        as_json,
        "wobble",
    )


@task_app.command(
    "chirp", short_help="Roll/pitch/yaw frequency sweep (lags and delays show as growing phase)."
)
@reports_errors
def task_chirp(
    out: Out,
    amplitude: Annotated[
        float, typer.Option(help="Roll and pitch amplitude, deg (yaw half).")
    ] = 12.0,
    f_start: Annotated[float, typer.Option(help="Sweep start frequency, Hz.")] = 0.1,
    f_end: Annotated[float, typer.Option(help="Sweep end frequency, Hz.")] = 0.8,
    duration: Duration = 24.0,
    ramp: Ramp = 2.0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Linear frequency sweep on roll, pitch (a quarter period apart) and yaw (half
    amplitude): every axis sees every frequency from --f-start to --f-end once."""
    from omavctl.sim.tasks import chirp

    _write_task(
        chirp(amplitude, f_start, f_end, duration, rate, ramp, height), out, quiet, as_json, "chirp"
    )


@task_app.command("steps", short_help="Random smoothed roll/pitch/yaw steps (seeded).")
@reports_errors
def task_steps(
    out: Out,
    amplitude: Annotated[
        float, typer.Option(help="Largest level per axis, deg (yaw half).")
    ] = 15.0,
    hold: Annotated[float, typer.Option(help="Time between steps, s.")] = 2.0,
    transition: Annotated[float, typer.Option(help="Duration of one smoothed step, s.")] = 1.0,
    duration: Duration = 20.0,
    ramp: Annotated[float, typer.Option(help="Rest at level at start and end, s.")] = 2.0,
    seed: Annotated[int, typer.Option(help="Draws the levels.")] = 0,
    rate: Rate = 100.0,
    height: Height = 1.0,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Random attitude steps: every --hold seconds roll, pitch and yaw move to new
    levels drawn within +-amplitude, each move a quintic smoothstep of --transition
    seconds (continuous rates and accelerations); level at both ends."""
    from omavctl.sim.tasks import steps

    _write_task(
        steps(amplitude, hold, transition, duration, rate, ramp, height, seed),
        out,
        quiet,
        as_json,
        "steps",
    )
