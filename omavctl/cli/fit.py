"""``omavctl fit``: learn a residual model (effects + GP) from flight logs."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from omavctl.cli.app import app
from omavctl.cli.common import (
    LOG_FORMATS,
    Json,
    Quiet,
    VehicleOpt,
    console,
    emit,
    reports_errors,
    transient_progress,
)

Logs = Annotated[
    list[Path],
    typer.Argument(
        metavar="LOG...",
        help=f"Flight logs, each a {LOG_FORMATS}.",
    ),
]
ModelOut = Annotated[
    Path,
    typer.Option(
        "--out",
        "-o",
        metavar="MODEL.npz",
        help="Output model file (.npz, schema omavctl.model/2, or /3 with physical-unit pairs).",
    ),
]
Effects = Annotated[
    str | None,
    typer.Option(
        help="Physical effects to estimate by least squares and subtract before the GP: "
        "comma-separated registry names, e.g. rotational_drag,com_offset (an unknown name "
        "lists the known ones). Default: the vehicle YAML's 'effects:' list.",
    ),
]
Points = Annotated[
    int,
    typer.Option(
        help="GP training points chosen from the new logs by k-medoids; with several "
        "logs, each log's own (two logs: this many each; more: twice this many shared)."
    ),
]
Prior = Annotated[
    Path | None,
    typer.Option(
        help="Earlier model (.npz): its training points are kept and the new ones added "
        "(hyperparameters are re-fitted). Needs the same --features and effects.",
    ),
]
SgWindow = Annotated[
    int,
    typer.Option(
        help="Savitzky-Golay window for the body-rate derivative, samples at the "
        "controller rate (odd; window//2 samples are dropped at each segment edge).",
    ),
]
SgOrder = Annotated[int, typer.Option(help="Savitzky-Golay polynomial order.")]
Features = Annotated[
    str,
    typer.Option(
        help="GP inputs: 'wrench' (scaled commanded wrench [f/m, I^-1 tau], 6-D, the "
        "paper's), 'wrench+rate' (adds body rates), 'wrench+dtorque' (adds the torque "
        "command's rate of change) or 'wrench+rate+dtorque' (both, 12-D: the default, "
        "chosen on held-out flights, docs/generalisation.md).",
    ),
]
Restarts = Annotated[
    int, typer.Option(help="Extra starts of the marginal-likelihood optimiser per axis.")
]
Seed = Annotated[int, typer.Option(help="Random seed (k-medoids subsampling, optimiser restarts).")]
TimeWindow = Annotated[
    str | None,
    typer.Option(
        help="Only samples with START <= t < END (s from each log's start), as START:END "
        "(either may be empty, e.g. 6.5:15 or 15:). Default: the whole flight.",
    ),
]


@app.command(short_help="Learn a residual model (effects + GP) from flight logs.")
@reports_errors
def fit(
    logs: Logs,
    out: ModelOut,
    vehicle: VehicleOpt = None,
    effects: Effects = None,
    points: Points = 200,
    prior: Prior = None,
    sg_window: SgWindow = 11,
    sg_order: SgOrder = 2,
    features: Features = "wrench+rate+dtorque",
    restarts: Restarts = 3,
    seed: Seed = 0,
    time_window: TimeWindow = None,
    quiet: Quiet = False,
    as_json: Json = False,
) -> None:
    """Learn the residual model from flight logs: physical effects by least squares, then
    one Gaussian process per body axis on what remains.

    Angular accelerations come from the body rates by a Savitzky-Golay derivative; the
    residual is measured minus nominal (rigid body) angular acceleration, rad/s^2. The
    model file (.npz) is what evaluate, simulate --model and plan read.
    """
    from omavctl.learn.run import effect_names, prepare_fit
    from omavctl.report.summary import fit_json

    job = prepare_fit(
        logs,
        out,
        vehicle=vehicle,
        effects=effect_names(effects),
        prior=prior,
        time_window=time_window,
        points=points,
        sg_window=sg_window,
        sg_order=sg_order,
        features=features,
        restarts=restarts,
        seed=seed,
    )
    con = console(quiet)
    with _stage_bar(con, quiet) as progress:
        result = job.run(progress)
    _render_fit(con, result.summary, out)
    emit(as_json, fit_json(result.summary, out))


@contextmanager
def _stage_bar(con: Any, quiet: bool) -> Iterator[Callable[[str, float], None]]:
    """One transient progress bar whose label is the current stage of the fit."""
    with transient_progress(con, quiet) as bar:
        job = bar.add_task("fitting", total=1.0)
        yield lambda stage, f: bar.update(job, description=stage, completed=f)


def samples_line(log: Any) -> str:
    """One log's samples, used and not, adding up to its grid samples (a
    :class:`~omavctl.learn.flights.LogSummary`)."""
    dropped = log.edge_dropped + log.short_dropped
    lost = f"; {log.out_of_control} out of control" if log.out_of_control else ""
    return (
        f"{log.path}: {log.used} of {log.samples} samples used "
        f"({log.in_gaps} invalid: in gaps, on the ground or outside the time window; "
        f"{dropped} at segment edges or in short segments{lost})"
    )


def _render_fit(con: Any, summary: Any, out: Path) -> None:
    """Print the fit summary: data used, effects, GP hyperparameters, training fit."""
    for log in summary.logs:
        con.print(samples_line(log), markup=False)
        for note in log.notes:
            con.print(f"  note: {note}", markup=False)
    prior = f" + {summary.points_prior} from the prior" if summary.points_prior else ""
    con.print(
        f"training points: {summary.points_new} new{prior} ({summary.kmedoids}); "
        f"Savitzky-Golay window {summary.sg_window}, order {summary.sg_order}"
    )
    if summary.effects:
        con.print(_effects_table(summary))
    con.print(_gp_table(summary))
    for note in summary.notes:
        con.print(f"note: {note}", markup=False)
    con.print(f"wrote {out} ({summary.points} training points, {summary.samples} samples)")


def _effects_table(summary: Any) -> Any:
    """The estimated effect parameters (and torque command gains) with standard errors."""
    import numpy as np
    from rich.table import Table
    from rich.text import Text

    from omavctl.learn.fit_notes import effect_unit
    from omavctl.learn.intervals import SPREAD_MEANING, SPREAD_WORDS, interval95
    from omavctl.physics.effects import get_effect

    units = summary.command_units
    has_spread = any(est.systematic is not None for est in summary.effects.values())
    eff = Table(
        title="effects (value ± standard error, robust to autocorrelated residuals"
        + (f"; {SPREAD_MEANING})" if has_spread else ")"),
        title_justify="left",
    )
    for col in ("effect", "parameter", "value ± std. error", "95 % interval", "unit"):
        eff.add_column(col)
    for name, est in summary.effects.items():
        intervals, pinned, by_flight = est.interval95(), est.pinned(), est.pinned(False)
        effect = get_effect(name)
        for p in effect.parameters:
            labels = "xyz" if p.size == 3 else [str(i) for i in range(p.size)]
            for i, (v, e) in enumerate(zip(est.values[p.name], est.stderr[p.name], strict=True)):
                label = p.name if p.size == 1 else f"{p.name}_{labels[i]}"
                unit = effect_unit(name, p.unit, units)
                # exactly 0: its regressor is zero on these logs (motor_loss beyond the
                # vehicle's rotors, com_offset r_z of a thrust along z): never excited;
                # a rotor the vehicle lacks is no row of it (eyes6: a quad's l_4 .. l_11)
                if v == 0.0 and e == 0.0 and p.name in effect.absent_when_unexcited:
                    continue
                why = effect.unexcited_why.get(label)
                interval = (
                    "not excited by these logs" + (f": {why}" if why else "")
                    if v == 0.0
                    else _interval_text(
                        intervals[p.name][i],
                        bool(pinned[p.name][i]),
                        (name, p.name, i),
                        v,
                        SPREAD_WORDS if by_flight[p.name][i] else None,
                    )
                )
                spread = est.systematic[p.name][i] if est.systematic is not None else 0.0
                value = f"{v:.4g} ± {e:.2g}" + (f" (± {spread:.2g} spread)" if spread > 0 else "")
                # a lag or a delay also in ms, as fit's notes and the docs give it (a new
                # user compared 'T_m 0.06375 ± 0.0097 s' with '63.8 ± 9.7 ms')
                value += f" = {v * 1e3:.3g} ± {e * 1e3:.2g} ms" if p.unit == "s" else ""
                # Text: rich reads '[below 0.0457]' as a markup tag and drops it
                eff.add_row(name, label, value, Text(_flights(interval, summary)), Text(unit))
    if summary.torque_gain is not None and summary.torque_gain_stderr is not None:
        gains = zip("xyz", summary.torque_gain, summary.torque_gain_stderr, strict=True)
        scale = summary.effects.get("inertia_error")
        for i, (axis, g, e) in enumerate(gains):
            if scale is not None:  # one parameter, one interval: the scale's, inverted
                lo, hi = gain_interval(*scale.interval95()["scale"][i])
                pinned = lo > 0.0 and bool(scale.pinned()["scale"][i])
            else:  # a gain is positive: cut at 0 (interval95)
                lo, hi = interval95(np.asarray([g]), np.asarray([e]), 0.0)[0]
                pinned = lo > 0.0
            eff.add_row(
                "torque command gain",
                f"gain_{axis} = 1/scale_{axis}",
                f"{g:.4g} ± {e:.2g}",
                # Text: rich reads '[0, 1.51]' as a markup tag and drops it
                Text(
                    f"[{lo:.3g}, {hi:.3g}]".replace("inf]", "∞)")
                    + (" (cut at gain ≥ 0)" if lo == 0.0 else "")
                    # Betaflight: gain_x -0.126 beside [0, 1.51]
                    + (" (the estimate is below it)" if g < lo else "")
                    + (
                        ""
                        if pinned
                        else _flights(": cannot be pinned down from this flight", summary)
                    )
                ),
                Text("N m per command unit (assumed inertia)"),
            )
    return eff


def _flights(text: str, summary: Any) -> str:
    """``text`` with "this flight" as "these flights" for a fit on several logs (a new
    user's fit on two flights: "cannot be pinned down from this flight")."""
    return text.replace("this flight", "these flights") if len(summary.logs) > 1 else text


def gain_interval(low: float, high: float) -> tuple[float, float]:
    """The 95 % interval of a torque command gain ``1 / scale`` from its inertia scale's
    (low, high): ``1 / x`` maps an interval on one side of 0 onto one, ends swapped
    (scale [0.663, inf), a gain not told from 0, is gain [0, 1.51]; scale [0, 51.9] of
    an older file is gain [0.0193, inf)); one across 0 maps onto two rays, shown as
    all gains (-inf, inf)."""
    if math.isnan(low) or math.isnan(high):
        return math.nan, math.nan
    if low > 0.0 or high < 0.0:  # 1/inf = 0: scale [0.663, inf) is gain [0, 1.51]
        return 1.0 / high, 1.0 / low
    if low == 0.0:
        return (1.0 / high if high > 0.0 else math.inf), math.inf
    return -math.inf, math.inf


def _interval_text(
    interval: Any,
    pinned: bool,
    which: tuple[str, str, int],
    value: float | None = None,
    why: str | None = None,
) -> str:
    """'[low, high]' of a 95 % interval (and '(cut at T_m ≥ 0)' where it ends at the
    parameter's physical bound), and, when it does not pin the parameter (effect,
    parameter, component) down, why, in words that follow the interval (``why``, or
    :func:`omavctl.learn.intervals.unpinned_words`)."""
    from omavctl.diagnose.estimate_text import null_component
    from omavctl.learn.intervals import bound_note, interval_span, unpinned_words

    lo, hi = (float(x) for x in interval)
    span, _ = interval_span(which[0], which[1], lo, hi, null_component(*which), ", ")
    text = (
        f"[{span}]"
        if math.isfinite(lo) and math.isfinite(hi)
        else f"[{lo:.3g}, ∞)"
        if math.isfinite(lo) and hi == math.inf
        else "unbounded"
    )
    if note := bound_note(which[0], which[1], lo, value, hi):
        text += f" ({note})"
    if pinned:
        return text
    return f"{text}: {why or unpinned_words(*which[:2], (lo, hi), which[2])}"


def _gp_table(summary: Any) -> Any:
    """The GP of each axis: hyperparameters, training and held-out errors."""
    from rich.table import Table

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
    gp.add_row(
        "held-out RMSE physics, rad/s^2", *(f"{a.cv_rmse_physics:.4g}" for a in summary.axes)
    )
    gp.add_row(
        "held-out within 2σ, before widening", *(f"{a.cv_coverage:.0%}" for a in summary.axes)
    )
    gp.add_row(
        "band growth beyond the inputs, × the GP variance",
        *(f"{a.beyond_scale:.2g}" if a.gp_on else "—" for a in summary.axes),
    )
    return gp
