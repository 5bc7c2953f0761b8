"""Command-line interface: parse, call one library function, render.

Library errors (:class:`omavctl.base.errors.OmavctlError`) become one line
``error: <file>: <problem>`` on stderr and exit status 2, as usage errors
(:mod:`omavctl.guard`); other failures exit 1. Heavy modules are imported
inside the commands so that ``--help`` and ``--version`` stay fast.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer

from omavctl import __version__
from omavctl.base.atomic import check_outputs
from omavctl.base.errors import OmavctlError


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
    "diagnose missing physics, and plan informative next flights.",
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
    task_app, name="task", short_help="Write a task trajectory (fig8, circle, pitch, yaw, heave)."
)

F = TypeVar("F", bound=Callable[..., Any])


def _reports_errors(func: F) -> F:
    """Bad input: one line and exit status 2; see :mod:`omavctl.guard`."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from omavctl.guard import guarded

        return guarded(func, args, kwargs)

    return wrapper  # type: ignore[return-value]


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


def _console(quiet: bool = False):
    """Human text on stderr; no wrapping when stderr is not a terminal."""
    from omavctl.cliout import console

    return console(quiet)


def _emit(as_json: bool, obj: dict[str, Any]) -> None:
    """With --json, print ``obj`` as one JSON object on stdout."""
    if as_json:
        from omavctl.cliout import emit_json

        emit_json(obj)


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


# --------------------------------------------------------------------------- task
Out = Annotated[Path, typer.Option("--out", "-o", metavar="CSV", help="Output trajectory CSV.")]
Rate = Annotated[float, typer.Option(help="Sample rate of the CSV, Hz.")]
Height = Annotated[float, typer.Option(help="Hover height (z), m.")]


def _write_task(traj: Any, out: Path, quiet: bool, as_json: bool = False, name: str = "") -> None:
    from omavctl.sim.trajectory import write_trajectory

    check_outputs([], [out])
    write_trajectory(out, traj)
    if not quiet:
        _console().print(f"wrote {out} ({traj.data.shape[0]} samples, {traj.duration:.2f} s)")
    _emit(
        as_json,
        {
            "command": f"task {name}".strip(),
            "files": {"trajectory": str(out)},
            "samples": int(traj.data.shape[0]),
            "duration": float(traj.duration),
        },
    )


@task_app.command("fig8", short_help="Attitude figure-8 at constant position (the paper's task).")
@_reports_errors
def task_fig8(
    out: Out,
    roll: Annotated[float, typer.Option(help="Roll amplitude, deg.")] = 26.0,
    pitch: Annotated[float, typer.Option(help="Pitch amplitude, deg.")] = 26.0,
    period: Annotated[float, typer.Option(help="Period of one figure-8, s.")] = 8.0,
    duration: Annotated[float, typer.Option(help="Total duration, s.")] = 24.0,
    ramp: Annotated[float, typer.Option(help="Smooth start/stop ramp, s.")] = 2.0,
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
@_reports_errors
def task_circle(
    out: Out,
    radius: Annotated[float, typer.Option(help="Circle radius, m.")] = 1.0,
    period: Annotated[float, typer.Option(help="Time per lap at full speed, s.")] = 6.0,
    duration: Annotated[float, typer.Option(help="Total duration, s.")] = 24.0,
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
@_reports_errors
def task_pitch(
    out: Out,
    amplitude: Annotated[float, typer.Option(help="Pitch amplitude, deg (< 90).")] = 60.0,
    max_acceleration: Annotated[
        float, typer.Option(help="Pitch acceleration amplitude A w^2, rad/s^2 (sets the period).")
    ] = 1.0,
    duration: Annotated[float, typer.Option(help="Total duration, s.")] = 30.0,
    ramp: Annotated[float, typer.Option(help="Smooth start/stop ramp, s.")] = 3.0,
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
@_reports_errors
def task_yaw(
    out: Out,
    amplitude: Annotated[float, typer.Option(help="Yaw amplitude, deg.")] = 30.0,
    period: Annotated[float, typer.Option(help="Period of the oscillation, s.")] = 4.0,
    duration: Annotated[float, typer.Option(help="Total duration, s.")] = 20.0,
    ramp: Annotated[float, typer.Option(help="Smooth start/stop ramp, s.")] = 2.0,
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
@_reports_errors
def task_heave(
    out: Out,
    amplitude: Annotated[float, typer.Option(help="Vertical amplitude, m.")] = 0.2,
    period: Annotated[float, typer.Option(help="Period of the oscillation, s.")] = 3.0,
    duration: Annotated[float, typer.Option(help="Total duration, s.")] = 20.0,
    ramp: Annotated[float, typer.Option(help="Smooth start/stop ramp, s.")] = 2.0,
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
@_reports_errors
def task_wobble(
    out: Out,
    amplitude: Annotated[
        float, typer.Option(help="Sum of the sine amplitudes per axis, deg (yaw half).")
    ] = 15.0,
    bandwidth: Annotated[float, typer.Option(help="Highest sine frequency, Hz.")] = 0.8,
    duration: Annotated[float, typer.Option(help="Total duration, s.")] = 20.0,
    ramp: Annotated[float, typer.Option(help="Smooth start/stop ramp, s.")] = 2.0,
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


# ----------------------------------------------------------------------- simulate
@app.command(short_help="Fly a reference through the truth plant, write a flight log.")
@_reports_errors
def simulate(
    reference: Annotated[
        Path, typer.Option("--reference", "-r", metavar="CSV", help="Reference trajectory CSV.")
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="LOG",
            help="Output log; its kind follows the name: a directory (no suffix) -> ROS 2 bag "
            "(mcap storage), .bag -> ROS 1 bag, .mcap -> standalone MCAP, .csv -> wide CSV.",
        ),
    ],
    truth: Annotated[
        Path | None,
        typer.Option(
            "--truth",
            metavar="TRUTH.yaml",
            help="Truth YAML: actuator imperfections, hidden effects, sensor noise, seed "
            "(default: documented imperfections, no hidden effect).",
        ),
    ] = None,
    vehicle: VehicleOpt = None,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Sensor-noise seed (default: the truth file's seed, which also draws "
            "the vehicle's rotor thrust spread)."
        ),
    ] = None,
    physics_rate: Annotated[
        float, typer.Option(help="Integration rate of the truth plant, Hz.")
    ] = 1000.0,
    model: Annotated[
        Path | None,
        typer.Option(
            "--model",
            metavar="MODEL.npz",
            help="Residual model (.npz written by fit) that the controller inverts, "
            "u + mu(u) = a* (default: the nominal model, mu = 0).",
        ),
    ] = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Fly a reference in closed loop through the truth plant and write a flight log."""
    from omavctl.logs import write_log
    from omavctl.sim.plant import load_truth
    from omavctl.sim.plant import simulate as run
    from omavctl.sim.trajectory import read_trajectory
    from omavctl.vehicle import load_vehicle

    check_outputs([reference, truth, vehicle, model], [out], directory_ok=not out.suffix)
    veh = load_vehicle(vehicle)
    ref = read_trajectory(reference)
    plant = load_truth(truth, veh)
    residual = None
    if model is not None:
        from omavctl.learn.model_file import check_vehicle, load_model

        residual = load_model(model)
        check_vehicle(residual, veh, model)
    if not 1000.0 <= physics_rate <= 100_000.0:
        raise OmavctlError(f"--physics-rate must be 1000 to 100000 Hz, got {physics_rate:g}")
    con = _console(quiet)
    from rich.progress import Progress

    with Progress(console=con, transient=True, disable=quiet) as bar:
        job = bar.add_task("simulating", total=1.0)
        result = run(
            ref,
            veh,
            plant,
            model=residual,
            seed=seed,
            physics_rate=physics_rate,
            progress=lambda f: bar.update(job, completed=f),
        )
    write_log(out, result.log, topics=veh.topics)
    import math

    con.print(
        f"wrote {out}: {result.duration:.2f} s flown, "
        f"max attitude error {math.degrees(result.max_attitude_error):.2f} deg, "
        f"{result.infeasible_steps}/{result.steps} steps beyond actuator limits"
    )
    if result.diverged:
        con.print(
            f"[bold red]warning:[/] the vehicle lost control at {result.diverged_at:.2f} s; "
            "the log goes on through the tumble for 1 s, then ends"
        )
    _emit(
        as_json,
        {
            "command": "simulate",
            "files": {"log": str(out)},
            "duration": result.duration,
            "max_attitude_error_deg": math.degrees(result.max_attitude_error),
            "infeasible_steps": int(result.infeasible_steps),
            "steps": int(result.steps),
            "diverged": bool(result.diverged),
            "diverged_at": result.diverged_at,
        },
    )


# ---------------------------------------------------------------------------- fit
@app.command(short_help="Learn a residual model (effects + GP) from flight logs.")
@_reports_errors
def fit(
    logs: Annotated[
        list[Path],
        typer.Argument(
            metavar="LOG...",
            help="Flight logs: ROS 1 .bag, ROS 2 bag directories, .mcap or wide .csv.",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="MODEL.npz",
            help="Output model file (.npz, schema omavctl.model/1).",
        ),
    ],
    vehicle: VehicleOpt = None,
    effects: Annotated[
        str | None,
        typer.Option(
            help="Physical effects to estimate by least squares and subtract before the GP: "
            "comma-separated registry names, e.g. rotational_drag,com_offset (an unknown name "
            "lists the known ones). Default: the vehicle YAML's 'effects:' list.",
        ),
    ] = None,
    points: Annotated[
        int, typer.Option(help="GP training points chosen from the new logs by k-medoids.")
    ] = 200,
    prior: Annotated[
        Path | None,
        typer.Option(
            help="Earlier model (.npz): its training points are kept and the new ones added "
            "(hyperparameters are re-fitted). Needs the same --features and effects.",
        ),
    ] = None,
    sg_window: Annotated[
        int,
        typer.Option(
            help="Savitzky-Golay window for the body-rate derivative, samples at the "
            "controller rate (odd; window//2 samples are dropped at each segment edge).",
        ),
    ] = 11,
    sg_order: Annotated[int, typer.Option(help="Savitzky-Golay polynomial order.")] = 2,
    features: Annotated[
        str,
        typer.Option(
            help="GP inputs: 'wrench' (scaled commanded wrench [f/m, I^-1 tau], 6-D, the "
            "paper's), 'wrench+rate' (adds body rates), 'wrench+dtorque' (adds the torque "
            "command's rate of change) or 'wrench+rate+dtorque' (both, 12-D: the default, "
            "chosen on held-out flights, docs/generalisation.md).",
        ),
    ] = "wrench+rate+dtorque",
    restarts: Annotated[
        int, typer.Option(help="Extra starts of the marginal-likelihood optimiser per axis.")
    ] = 3,
    seed: Annotated[
        int, typer.Option(help="Random seed (k-medoids subsampling, optimiser restarts).")
    ] = 0,
    time_window: Annotated[
        str | None,
        typer.Option(
            help="Only samples with START <= t < END (s from each log's start), as START:END "
            "(either may be empty, e.g. 6.5:15 or 15:). Default: the whole flight.",
        ),
    ] = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Learn the residual model from flight logs: physical effects by least squares, then
    one Gaussian process per body axis on what remains.

    Angular accelerations come from the body rates by a Savitzky-Golay derivative; the
    residual is measured minus nominal (rigid body) angular acceleration, rad/s^2. The
    model file (.npz) is what evaluate, simulate --model and plan read.
    """
    from rich.progress import Progress

    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model
    from omavctl.logs import parse_time_window
    from omavctl.vehicle import load_vehicle

    check_outputs([*logs, vehicle, prior], [out])
    window = parse_time_window(time_window) if time_window else None
    veh = load_vehicle(vehicle)
    names = None if effects is None else [e.strip() for e in effects.split(",") if e.strip()]
    con = _console(quiet)
    with Progress(console=con, transient=True, disable=quiet) as bar:
        job = bar.add_task("fitting", total=1.0)
        result = fit_model(
            logs,
            vehicle=veh,
            effects=names,
            points=points,
            prior=prior,
            sg_window=sg_window,
            sg_order=sg_order,
            features=features,
            seed=seed,
            restarts=restarts,
            progress=lambda stage, f: bar.update(job, description=stage, completed=f),
            time_window=window,
        )
    save_model(out, result.model)
    _render_fit(con, result.summary, out)
    from omavctl.report.summary import fit_json

    _emit(as_json, fit_json(result.summary, out))


def _render_fit(con: Any, summary: Any, out: Path) -> None:
    """Print the fit summary: data used, effects, GP hyperparameters, training fit."""
    from rich.table import Table
    from rich.text import Text

    from omavctl.learn.fit_notes import effect_unit
    from omavctl.physics.effects import get_effect

    units = summary.command_units
    for log in summary.logs:
        dropped = log.edge_dropped + log.short_dropped
        con.print(
            f"{log.path}: {log.used} of {log.samples} samples used "
            f"({log.in_gaps} invalid: in gaps, on the ground or outside the time window; "
            f"{dropped} at segment edges or in short segments)"
        )
        for note in log.notes:
            con.print(f"  note: {note}", markup=False)
    prior = f" + {summary.points_prior} from the prior" if summary.points_prior else ""
    con.print(
        f"training points: {summary.points_new} new{prior} ({summary.kmedoids}); "
        f"Savitzky-Golay window {summary.sg_window}, order {summary.sg_order}"
    )
    if summary.effects:
        eff = Table(title="effects (least squares, value ± standard error)", title_justify="left")
        for col in ("effect", "parameter", "value ± std. error", "unit"):
            eff.add_column(col)
        for name, est in summary.effects.items():
            for p in get_effect(name).parameters:
                labels = "xyz" if p.size == 3 else [str(i) for i in range(p.size)]
                for i, (v, e) in enumerate(
                    zip(est.values[p.name], est.stderr[p.name], strict=True)
                ):
                    label = p.name if p.size == 1 else f"{p.name}_{labels[i]}"
                    unit = effect_unit(name, p.unit, units)
                    eff.add_row(name, label, f"{v:.4g} ± {e:.2g}", Text(unit))
        if summary.torque_gain is not None and summary.torque_gain_stderr is not None:
            gains = zip("xyz", summary.torque_gain, summary.torque_gain_stderr, strict=True)
            for axis, g, e in gains:
                eff.add_row(
                    "torque command gain",
                    f"gain_{axis} = 1/scale_{axis}",
                    f"{g:.4g} ± {e:.2g}",
                    Text("N m per command unit (assumed inertia)"),
                )
        con.print(eff)
    gp = Table(title=f"GP per axis (inputs: {summary.features})", title_justify="left")
    gp.add_column("")
    for axis in "xyz":
        gp.add_column(axis, justify="right")
    gp.add_row("signal std, rad/s^2", *(f"{a.signal_std:.4g}" for a in summary.axes))
    gp.add_row("noise std, rad/s^2", *(f"{a.noise_std:.4g}" for a in summary.axes))
    for j, name in enumerate(summary.input_names):
        gp.add_row(
            f"length scale {name} (normalised)",
            *(f"{a.length_scales[j]:.3g}" for a in summary.axes),
        )
    gp.add_row("training R^2", *(f"{a.r2:.3f}" for a in summary.axes))
    gp.add_row("training RMSE, rad/s^2", *(f"{a.rmse:.4g}" for a in summary.axes))
    gp.add_row("RMS without model, rad/s^2", *(f"{a.rmse_nominal:.4g}" for a in summary.axes))
    gp.add_row("GP on (held-out blocks)", *("yes" if a.gp_on else "off" for a in summary.axes))
    gp.add_row("held-out RMSE GP, rad/s^2", *(f"{a.cv_rmse_gp:.4g}" for a in summary.axes))
    gp.add_row("held-out RMSE physics", *(f"{a.cv_rmse_physics:.4g}" for a in summary.axes))
    gp.add_row("held-out within 2σ", *(f"{a.cv_coverage:.0%}" for a in summary.axes))
    con.print(gp)
    for note in summary.notes:
        con.print(f"note: {note}", markup=False)
    con.print(f"wrote {out} ({summary.points} training points, {summary.samples} samples)")


# ----------------------------------------------------------------------- evaluate
@app.command(short_help="Compare models with a flight: verdict, errors, missing physics.")
@_reports_errors
def evaluate(
    logs: Annotated[
        list[Path],
        typer.Argument(
            metavar="LOG...",
            help="Flight logs to compare the models with (ROS 1 .bag, ROS 2 bag directory, "
            ".mcap or .csv); best not the ones the model was fitted on.",
        ),
    ],
    model: Annotated[
        list[Path],
        typer.Option(
            "--model",
            "-m",
            metavar="MODEL.npz",
            help="Model written by fit (repeat to compare several models side by side; the "
            "first one is diagnosed).",
        ),
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            metavar="EVAL.json",
            help="Evaluation JSON (schema omavctl.eval/1); time series go to "
            "<stem>.series.npz beside it. Default: <model stem>.eval.json beside the first "
            "model.",
        ),
    ] = None,
    mcap: Annotated[
        Path | None,
        typer.Option(
            "--mcap",
            metavar="SERIES.mcap",
            help="MCAP file of the time series for Foxglove/PlotJuggler (measured, predicted, "
            "2σ band, nominal, physics-only, worst-segment markers; JSON channels on the log's "
            "own time stamps). Default: <stem>.series.mcap beside the evaluation JSON.",
        ),
    ] = None,
    time_window: Annotated[
        str | None,
        typer.Option(
            metavar="START:END",
            help="Only samples with START <= t < END (s from log start), e.g. 15: or 2.5:10.",
        ),
    ] = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Compare models with measured angular accelerations, find where they fail, and
    diagnose which physical effect is missing.

    Prints the verdict first (what is missing and the fit command that adds it, where
    the model fails and what the vehicle was doing, whether its 2σ band can be trusted),
    then the RMSE (rad/s^2) of the nominal model, nominal + effects and each model side
    by side. Writes the evaluation JSON, its .series.npz and an MCAP of the series.
    """
    from omavctl.diagnose.evalio import series_path, write_evaluation
    from omavctl.diagnose.evaluate import evaluate as run
    from omavctl.logs import parse_time_window
    from omavctl.report.series_mcap import mcap_path, write_series_mcap
    from omavctl.report.summary import evaluation_json, render_evaluation

    window = parse_time_window(time_window) if time_window else None
    if out is None and model:
        out = model[0].with_name(model[0].with_suffix("").name + ".eval.json")
    assert out is not None
    mcap_out = mcap if mcap is not None else mcap_path(out)
    check_outputs([*logs, *model], [out, series_path(out), mcap_out])
    result = run(model, logs, time_window=window)
    write_evaluation(out, result)
    write_series_mcap(mcap_out, result.tree, result.series)
    files = {"evaluation": out, "series": series_path(out), "mcap": mcap_out}
    render_evaluation(_console(quiet), result.tree, files)
    _emit(as_json, evaluation_json(result.tree, files))


# --------------------------------------------------------------------------- plan
@app.command(short_help="Plan the most informative next reference for a task.")
@_reports_errors
def plan(
    task: Annotated[
        Path, typer.Option("--task", metavar="CSV", help="Task trajectory CSV to learn for.")
    ],
    model: Annotated[
        Path, typer.Option("--model", metavar="MODEL.npz", help="Current model (.npz from fit).")
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", metavar="CSV", help="Most informative reference, trajectory CSV."
        ),
    ],
    vehicle: VehicleOpt = None,
    candidates: Annotated[int, typer.Option(help="Candidate references K.")] = 20,
    sims: Annotated[
        int, typer.Option(help="Simulations M per candidate (one GP posterior sample each).")
    ] = 8,
    frequencies: Annotated[int, typer.Option(help="Frequencies P per axis.")] = 2,
    max_freq: Annotated[float, typer.Option(help="Highest deviation frequency, Hz.")] = 2.0,
    amplitude: Annotated[
        float, typer.Option(help="Largest angular-acceleration deviation, rad/s^2.")
    ] = 1.0,
    epsilon: Annotated[
        float | None,
        typer.Option(
            help="Radius of the task region around visited inputs, normalised input units "
            "(default: mean distance between commanded and achieved input, the paper's heuristic)."
        ),
    ] = None,
    test_points: Annotated[int, typer.Option(help="Test points S in the task region.")] = 500,
    points: Annotated[
        int, typer.Option(help="Training points a flight would add (k-medoids per simulation).")
    ] = 40,
    search: Annotated[
        str,
        typer.Option(
            help="How candidates are proposed: 'random' (all at once, the paper) or 'cem' "
            "(cross-entropy method over the Fourier coefficients in --generations "
            "generations, same number of simulations)."
        ),
    ] = "random",
    generations: Annotated[int, typer.Option(help="Generations of --search cem.")] = 5,
    selection: Annotated[
        str,
        typer.Option(
            help="How the points a flight would add are picked: 'batched' (farthest-point + "
            "k-medoids steps, all simulations at once) or 'kmedoids' (as fit, per "
            "simulation, slow)."
        ),
    ] = "batched",
    jobs: Annotated[
        int,
        typer.Option(
            help="Worker processes for the simulations (see docs/planning-performance.md)."
        ),
    ] = 1,
    scores: Annotated[
        Path | None,
        typer.Option(help="Write every candidate's coefficients, cost and feasibility as CSV."),
    ] = None,
    seed: Annotated[
        int, typer.Option(help="Random seed (deviations, GP samples, test points).")
    ] = 0,
    report_out: Annotated[
        Path | None,
        typer.Option(
            "--report",
            metavar="PLAN.html",
            help="Also write an HTML report: the task and the planned reference over time, "
            "and every candidate's cost.",
        ),
    ] = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Plan the most informative next reference: the task plus a sampled Fourier deviation.

    Each of K candidates is flown M times in closed-loop simulation with GP posterior
    samples; its cost is the mean posterior variance ((rad/s^2)^2) the GP would have at
    test points of the task region after adding its data (lower = more informative).
    """
    from rich.progress import Progress
    from rich.table import Table
    from threadpoolctl import threadpool_limits

    from omavctl.learn.model_file import check_vehicle, load_model
    from omavctl.planning import PlanSettings
    from omavctl.planning import plan as run
    from omavctl.planning.report import write_plan
    from omavctl.sim.trajectory import read_trajectory
    from omavctl.vehicle import load_vehicle

    check_outputs([task, model, vehicle], [out, scores, report_out])
    for name, value in (
        ("--candidates", candidates),
        ("--sims", sims),
        ("--points", points),
        ("--test-points", test_points),
        ("--frequencies", frequencies),
        ("--generations", generations),
        ("--jobs", jobs),
    ):
        if value < 1:
            raise OmavctlError(f"{name} must be at least 1, got {value}")
    if search not in ("random", "cem"):
        raise OmavctlError(f"--search must be 'random' or 'cem', got '{search}'")
    if selection not in ("batched", "kmedoids"):
        raise OmavctlError(f"--selection must be 'batched' or 'kmedoids', got '{selection}'")
    if not (0.1 < max_freq <= 50.0 and 0 < amplitude <= 100.0):
        raise OmavctlError("--max-freq must be in (0.1, 50] Hz and --amplitude in (0, 100] rad/s^2")
    if epsilon is not None and not 0 < epsilon <= 1000:
        raise OmavctlError(f"--epsilon must be in (0, 1000] normalised units, got {epsilon}")
    mdl = load_model(model)
    if vehicle is not None:
        check_vehicle(mdl, load_vehicle(vehicle), vehicle)
    ref = read_trajectory(task)
    settings = PlanSettings(
        candidates=candidates,
        sims=sims,
        frequencies=frequencies,
        max_freq=max_freq,
        amplitude=amplitude,
        epsilon=epsilon,
        test_points=test_points,
        points=points,
        seed=seed,
        search=search,
        generations=generations,
        selection=selection,
        jobs=jobs,
    )
    con = _console(quiet)
    # BLAS threads set once: one per process, so that worker processes (--jobs) and
    # BLAS do not fight over the cores and timings are stable (threadpoolctl)
    with (
        threadpool_limits(limits=1, user_api="blas"),
        Progress(console=con, transient=True, disable=quiet) as bar,
    ):
        stages: dict[str, Any] = {}

        def progress(stage: str, fraction: float) -> None:
            if stage not in stages:
                stages[stage] = bar.add_task(stage, total=1.0)
            bar.update(stages[stage], completed=fraction)

        result = run(mdl, ref, settings, progress)
    best = result.best_trajectory(task)
    write_plan(out, best, result, scores)
    table = Table(title="most informative candidates (lower cost = more informative)")
    for col in ("id", "cost", "vs task", "tracking rad/s^2"):
        table.add_column(col, justify="right")
    order = [int(k) for k in result.cost.argsort() if result.feasible[k]][:5]
    for k in order:
        table.add_row(
            str(k),
            f"{result.cost[k]:.4g}",
            f"{100 * (result.cost[k] / result.task_cost - 1):+.1f}%",
            f"{result.tracking[k]:.3f}",
        )
    con.print(table)
    rejected = int((~result.feasible).sum())
    con.print(
        f"task cost {result.task_cost:.4g} (prior {result.prior_variance:.4g}), "
        f"epsilon {result.epsilon:.3g}; {rejected}/{candidates} candidates rejected"
    )
    for note in result.notes:
        con.print(f"note: {note}", markup=False)
    best_cost = float(result.cost[result.best])
    if best_cost >= result.task_cost:
        con.print(
            f"warning: no candidate is more informative than flying the task again (best "
            f"{100 * (best_cost / result.task_cost - 1):+.1f}% vs the task): fly the task, "
            "or try more --candidates or --search cem",
            markup=False,
        )
    files = {"reference": str(out)}
    if scores is not None:
        files["scores"] = str(scores)
    if report_out is not None:
        from omavctl.report.plan import write_plan_report

        write_plan_report(report_out, ref, result)
        files["report"] = str(report_out)
        con.print(f"wrote {report_out} (plan report)")
    con.print(f"wrote {out} (candidate {result.best})")
    _emit(
        as_json,
        {
            "command": "plan",
            "files": files,
            "best": int(result.best),
            "best_cost": float(result.cost[result.best]),
            "task_cost": float(result.task_cost),
            "prior_variance": float(result.prior_variance),
            "epsilon": float(result.epsilon),
            "rejected": rejected,
            "candidates": [
                {
                    "id": k,
                    "cost": float(result.cost[k]),
                    "tracking": float(result.tracking[k]),
                    "feasible": bool(result.feasible[k]),
                }
                for k in range(len(result.cost))
            ],
            "notes": list(result.notes),
        },
    )


# ------------------------------------------------------------------------ inspect
@app.command(short_help="List a log's topics, rates, gaps and contract roles.")
@_reports_errors
def inspect(
    log: Annotated[
        Path,
        typer.Argument(
            metavar="LOG", help="Flight log: ROS 1 .bag, ROS 2 bag directory, .mcap or .csv."
        ),
    ],
    vehicle: VehicleOpt = None,
    as_json: Json = False,
) -> None:
    """List topics, types, counts, rates, duration, gaps and contract roles of a log.

    The listing goes to stdout (one row per topic, never wrapped in a pipe, so
    `omavctl inspect LOG | grep TOPIC` works); with --json it goes to stderr and stdout
    holds one JSON object.

    A CSV of another layout without a column map in --vehicle: list its columns with
    ranges and suggest a column map.
    """
    from omavctl.cliout import console
    from omavctl.logs import inspect_log, render_inspect
    from omavctl.vehicle import load_vehicle

    veh = load_vehicle(vehicle)
    ins = inspect_log(log, topics=veh.topics, columns=veh.columns or None)
    render_inspect(ins, console(stdout=not as_json))
    from omavctl.report.summary import inspect_json

    _emit(as_json, inspect_json(ins))


# ------------------------------------------------------------------------- report
@app.command(short_help="Render evaluations as one HTML/Markdown report, verdict first.")
@_reports_errors
def report(
    evaluations: Annotated[
        list[Path],
        typer.Argument(
            metavar="EVAL.json...",
            help="Evaluation files (.json written by evaluate, with their .series.npz next "
            "to them); with several, the report compares them, relative to the first.",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            metavar="REPORT",
            help="Output report (one self-contained .html, or .md).",
        ),
    ],
    fmt: Annotated[
        str | None,
        typer.Option(
            "--format",
            help="'html' (figures embedded, no network) or 'md' (tables only, no figures). "
            "Default: from --out's suffix (.md -> md, else html).",
        ),
    ] = None,
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
    from rich.table import Table
    from rich.text import Text

    from omavctl.diagnose.evalio import series_path
    from omavctl.report.evaluation import write_report

    check_outputs([*evaluations, *(series_path(e) for e in evaluations)], [out])
    con = _console(quiet)
    with con.status("rendering report"):
        summary = write_report(evaluations, out, fmt)
    con.print(Text("verdict", style="bold"))
    for line in summary.verdict:
        con.print(Text(f"  {line.plain()}"))
    table = Table(title="model RMSE per axis, rad/s^2", title_justify="left")
    table.add_column("evaluation")
    for axis in "xyz":
        table.add_column(axis, justify="right")
    table.add_column("top missing effect")
    for ev in summary.evaluations:
        table.add_row(
            Text(ev.label),
            *(f"{ev.model_rmse[a]:.4g}" for a in "xyz"),
            Text(ev.missing[0] if ev.missing else "none"),
        )
    con.print(table)
    if len(summary.evaluations) > 1:
        change = summary.change()
        con.print(
            f"change {summary.evaluations[0].label} -> {summary.evaluations[-1].label}: "
            + ", ".join(f"{a} {change[a]}" for a in "xyz"),
            markup=False,
        )
    last = summary.evaluations[-1]
    if last.missing and last.fit_command:
        con.print(f"to add {last.missing[0]} to {last.label}'s model:", markup=False)
        con.print(f"  {last.fit_command}", markup=False)
    figures = f", {summary.figures} figures" if summary.fmt == "html" else ""
    con.print(f"wrote {out} ({summary.fmt}{figures})", markup=False)
    _emit(
        as_json,
        {
            "command": "report",
            "files": {"report": str(out)},
            "format": summary.fmt,
            "figures": summary.figures,
            "evaluations": [
                {
                    "label": ev.label,
                    "path": ev.path,
                    "model_rmse": ev.model_rmse,
                    "missing": ev.missing,
                    "fit_command": ev.fit_command,
                }
                for ev in summary.evaluations
            ],
            "change": summary.change() if len(summary.evaluations) > 1 else None,
            "verdict": [
                {"key": ln.key, "about": ln.who, "text": ln.text, "command": ln.command}
                for ln in summary.verdict
            ],
        },
    )


def main() -> None:
    """Console-script entry point."""
    from omavctl.guard import run_app

    run_app(app, "omavctl")


if __name__ == "__main__":  # pragma: no cover
    main()
