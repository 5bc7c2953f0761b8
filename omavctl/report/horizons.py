"""Open-loop prediction over horizons in the report, the terminal and ``--json``.

The ``horizons`` section of an evaluation (:mod:`omavctl.diagnose.horizons`) as

- :func:`horizon_figure`: the mean body-rate error against the horizon per axis
  (and the attitude error), one line per predictor, the full model's 2σ band
  shaded from zero to its mean half-width;
- :func:`horizons_section`: the report's section: per evaluation a table
  (predictor x horizon), the figure and the findings; with several evaluation
  files their full models side by side, and where one that wins at the
  shortest horizon loses at the longest;
- :func:`render_horizons` and :func:`horizons_json`: the terminal table and the
  ``--json`` object's ``horizons``.

Evaluations written before the horizons existed have none: nothing is shown.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.horizon_band import narrow_axes
from omavctl.diagnose.horizon_findings import SIGNIFICANT, label, paired_se
from omavctl.report.document import (
    Block,
    Bullets,
    Cell,
    Content,
    FigureBlock,
    Lines,
    Para,
    Table,
)
from omavctl.report.figures import DPI, png, style
from omavctl.report.load import Evaluation
from omavctl.report.numfmt import num

__all__ = [
    "horizon_figure",
    "horizons_json",
    "horizons_of",
    "horizons_section",
    "render_horizons",
]

#: The horizon table's columns with their units (the Markdown report read "0.01 s ahead
#: rate" with the unit only in the paragraph above: a new user asked which); the per-axis
#: column is the rate's, beside it ("per axis, rad/s" wrapped its cells at 800 px).
RATE, PER_AXIS, ATTITUDE = "rate, rad/s", "per axis", "attitude, rad"

AXES = ("x", "y", "z")
#: line colours per predictor kind
COLOURS = {"naive": "#7f7f7f", "nominal": "#ff7f0e", "effects": "#2ca02c", "model": "#1f77b4"}


def horizons_of(tree: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The evaluation's ``horizons`` section, or None (older files, ``--horizons none``)."""
    h = tree.get("horizons")
    return h if isinstance(h, Mapping) and h.get("table") else None


def _floats(values: Any) -> np.ndarray | None:
    """A curve as floats (null, written for a number that was not finite: NaN)."""
    if values is None:
        return None
    return np.array([np.nan if v is None else float(v) for v in values])


#: what the 2σ figure of the horizon tables is, said the same in the terminal and report
COVERAGE_WORDS = (
    "the share of windows whose body-rate error lies inside the full model's 2σ band, "
    "over the three axes, with an axis under 85 % named"
)


def coverage_cell(cov: Mapping[str, Any], gap: str = "") -> str:
    """'95%' (``gap`` before the %), or '91%, y 74%' with the axes under 85 %: the
    pooled share hides an axis the band fails (a Crazyflie window printed 85 % with y at
    74.5 %)."""
    low = narrow_axes({"coverage": cov})
    text = f"{100 * float(cov['all']):.0f}{gap}%"
    return ", ".join([text, *(f"{a} {100 * float(cov[a]):.0f}{gap}%" for a in low)])


def _n_models(h: Mapping[str, Any]) -> int:
    return 1 + max((p.get("model") or 0) for p in h["predictors"])


def horizon_figure(h: Mapping[str, Any]) -> bytes:
    """Mean |body-rate error| (rad/s) per axis and the attitude error (rad) against the
    horizon (s), one line per predictor; the full models' 2σ band half-width shaded."""
    from matplotlib.figure import Figure

    n_models = _n_models(h)
    panels = [*AXES, "attitude"] if h.get("attitude") else list(AXES)
    with style():
        fig = Figure(figsize=(10, 3.2), dpi=DPI, layout="constrained")
        axs = fig.subplots(1, len(panels))
        for p in h["predictors"]:
            curve = h["curves"][p["key"]]
            t = np.arange(len(curve["norm"])) * float(h["seconds"][-1]) / int(h["steps"][-1])
            dashed = (p.get("model") or 0) > 0
            colour = COLOURS.get(p["kind"], "k")
            for ax, panel in zip(axs, panels, strict=True):
                values = _floats(curve.get(panel))
                if values is None:
                    continue
                ax.plot(
                    t,
                    values,
                    color=colour,
                    ls="--" if dashed else "-",
                    lw=1.2,
                    label=label(p, n_models) if panel == panels[0] else None,
                )
                band = curve.get("band")
                if band is not None and panel in AXES and not dashed:
                    ax.fill_between(
                        t,
                        0,
                        _floats(band[panel]),
                        color=colour,
                        alpha=0.12,
                        lw=0,
                        label=f"{label(p, n_models)}: 2σ band" if panel == panels[0] else None,
                    )
        for ax, panel in zip(axs, panels, strict=True):
            ax.set_title(f"body rate {panel}" if panel in AXES else "attitude", fontsize=9)
            ax.set_xlabel("horizon, s")
            ax.set_ylabel("mean |error|, " + ("rad/s" if panel in AXES else "rad"))
            for s in h["seconds"]:
                ax.axvline(float(s), color="k", lw=0.3, alpha=0.4)
            ax.grid(True, lw=0.3, alpha=0.6)
            ax.set_xlim(0, float(h["seconds"][-1]))
            ax.set_ylim(bottom=0)
        fig.legend(loc="outside upper center", ncol=5, fontsize=8, frameon=False)
        return png(fig)


def _table(h: Mapping[str, Any]) -> Table:
    """Predictor x horizon: mean body-rate error norm, attitude error, coverage."""
    n_models = _n_models(h)
    rows: list[list[Cell]] = []
    for p in h["predictors"]:
        row: list[Cell] = [label(p, n_models)]
        for entry in h["table"][p["key"]]:
            cov = entry.get("coverage")
            row += [
                num(entry["rate_error"]["norm"], 3),
                # one axis a line: three numbers joined by '/' made the table wider
                # than the page, its last column behind a scroll bar
                Lines(tuple(f"{a} {num(entry['rate_error'][a], 3)}" for a in AXES)),
                num(entry.get("attitude_error"), 3),
                coverage_cell(cov, " ") if cov else "",
            ]
        rows.append(row)
    secs = [float(s) for s in h["seconds"]]
    if not h.get("attitude"):  # no attitude in the log: no column of empty cells
        rows = [[r[0], *(c for i, c in enumerate(r[1:]) if i % 4 != 2)] for r in rows]
        return Table(
            columns=["predictor", *(c for _ in secs for c in (RATE, PER_AXIS, "2σ"))],
            groups=[("", 1), *((f"{s:g} s ahead", 3) for s in secs)],
            rows=rows,
            align="l" + "rlr" * len(secs),
        )
    return Table(
        columns=["predictor", *(c for _ in secs for c in (RATE, PER_AXIS, ATTITUDE, "2σ"))],
        groups=[("", 1), *((f"{s:g} s ahead", 4) for s in secs)],
        rows=rows,
        align="l" + "rlrr" * len(secs),
    )


def _evaluation_blocks(tree: Mapping[str, Any], label_: str, figures: bool) -> list[Block]:
    h = horizons_of(tree)
    if h is None:
        raw = tree.get("horizons")
        said = raw.get("findings") if isinstance(raw, Mapping) else None
        why = (
            str(said[0].get("message"))
            if said and isinstance(said[0], Mapping)
            else "written before evaluate had one, or with --horizons none"
        )
        return [Para(f"{label_}: no horizon table ({why}).", note=True)]
    blocks: list[Block] = [
        Para(
            f"{label_}: {h['windows']} windows (a start every {h['stride']} sample(s)); mean "
            "|error| of the body rate (norm, rad/s; then per axis)"
            + (" and of the attitude (geodesic angle, rad)" if h.get("attitude") else "")
            + " when each predictor is rolled forward open loop over the logged commands; "
            f"2σ: {COVERAGE_WORDS}."
            + (f" Models: {legend}." if (legend := models_legend(tree, _n_models(h))) else "")
        ),
        _table(h),
    ]
    blocks.append(
        FigureBlock(
            horizon_figure(h) if figures else b"",
            f"{label_}: error against the horizon",
            "Mean error against the prediction horizon; shaded: the full model's 2σ band "
            "(mean half-width; with several models, the first model's). Only the full "
            "model's line (blue, solid) is judged by it: above the band, the band is too "
            "narrow there. The other predictors have no band.",
        )
    )
    found: list[Content] = [str(f["message"]) for f in h.get("findings") or []]
    if found:
        blocks.append(Bullets([*found]))
    return blocks


def _logset(tree: Mapping[str, Any]) -> tuple[str, ...]:
    """The logs (and time window) an evaluation was made on, to tell comparable files."""
    logs = tree.get("logs") or []
    return tuple(sorted(f"{lg.get('sha256', lg.get('name'))}@{lg.get('t0')}" for lg in logs))


Full = tuple[str, tuple[str, ...], list[float], Mapping[str, Any]]
#: the findings the side-by-side repeats: a predictor that wins early and loses late,
#: and the axes whose GP mean the rollouts leave out
LOSSES = ("gp_hurts_long", "effects_hurt_long", "effect_added_hurts_long", "gp_left_out")


def _crossing_notes(full: Sequence[Full], secs: list[float]) -> list[Content]:
    """Pairs of full models on the same logs where one wins at the first horizon and
    loses at the last beyond its standard error (when the rows have chunk means):
    ``full`` (name, logs, error norm per horizon, the last horizon's row)."""
    notes: list[Content] = []
    for i, (na, la, a, ra) in enumerate(full):
        for nb, lb, b, rb in full[i + 1 :]:
            if la != lb or len(a) != len(b):
                continue
            for (win, w, rw), (lose, o, ro) in (
                ((na, a, ra), (nb, b, rb)),
                ((nb, b, rb), (na, a, ra)),
            ):
                se = paired_se(ro, rw, "norm")
                lost = w[-1] - o[-1] > (0.0 if se is None else SIGNIFICANT * se)
                if w[0] < o[0] and lost:
                    notes.append(
                        f"{win} wins at {secs[0]:g} s ({w[0]:.3g} vs {o[0]:.3g} rad/s) and "
                        f"loses at {secs[-1]:g} s ({w[-1]:.3g} vs {o[-1]:.3g}) to {lose}"
                    )
    return notes


def _side_by_side(evals: Sequence[Evaluation]) -> list[Block]:
    """Every file's nominal + effects and full models at each horizon; where a full
    model that wins at the first horizon loses at the last to another on the same
    logs; and the files whose GP helps at one step and hurts at the last horizon."""
    have = [(h, tree, lab) for tree, _, lab in evals if (h := horizons_of(tree)) is not None]
    if len(have) < 2:
        return []
    secs = [float(s) for s in have[0][0]["seconds"]]
    rows: list[list[Cell]] = []
    full: list[Full] = []
    notes: list[Content] = []
    for h, tree, lab in have:
        if [float(s) for s in h["seconds"]] != secs:
            continue
        n_models = _n_models(h)
        for p in h["predictors"]:
            if p["kind"] not in ("effects", "model"):
                continue
            errors = [float(e["rate_error"]["norm"]) for e in h["table"][p["key"]]]
            rows.append([lab, label(p, n_models), *(num(e, 3) for e in errors)])
            if p["kind"] == "model":
                last = h["table"][p["key"]][-1]
                full.append((f"{lab}: {label(p, n_models)}", _logset(tree), errors, last))
        notes += [f"{lab}: {f['message']}" for f in h.get("findings") or [] if f["code"] in LOSSES]
    notes = _crossing_notes(full, secs) + notes
    blocks: list[Block] = [
        Para("The files side by side: mean body-rate error norm (rad/s) at each horizon."),
        Table(
            columns=["evaluation", "predictor", *(f"{s:g} s" for s in secs)],
            rows=rows,
            align="ll" + "r" * len(secs),
        ),
    ]
    if notes:
        blocks.append(Bullets(list(notes)))
    else:
        blocks.append(
            Para(
                "No full model wins at the shortest horizon and loses at the longest (to "
                "another on the same logs, or to its own nominal + effects)."
            )
        )
    return blocks


def horizons_section(evals: Sequence[Evaluation], figures: bool) -> list[Block]:
    """The report's horizon section (module docstring)."""
    blocks: list[Block] = []
    for tree, _, lab in evals:
        blocks += _evaluation_blocks(tree, lab, figures)
    return blocks + _side_by_side(evals)


def stride_words(h: Mapping[str, Any]) -> str:
    """', a start every 8 samples rather than at every one (memory bound)' when the
    table ran with a larger stride than ``--horizon-stride`` (its default 1 included:
    "not the 1 asked for" read as a request the user never made) ('' otherwise)."""
    stride, asked = h.get("stride"), h.get("stride_requested")
    if not isinstance(stride, int) or not isinstance(asked, int) or stride == asked:
        return ""
    every = "at every one" if asked == 1 else f"every {asked} (--horizon-stride)"
    return (
        f", a start every {stride} samples rather than {every}: the log is long "
        "and the windows are held in memory at once"
    )


def render_horizons(con: Any, tree: Mapping[str, Any]) -> None:
    """The horizon table in the terminal (nothing without one)."""
    from rich.table import Table as RichTable
    from rich.text import Text

    h = horizons_of(tree)
    if h is None:
        # asked for but not made (horizons longer than any stretch of the logs): say why,
        # as the JSON does (a new user's --horizons 30 on a 20 s log printed nothing)
        raw = tree.get("horizons")
        found = raw.get("findings") if isinstance(raw, Mapping) else None
        for f in found if isinstance(found, list) else []:
            if isinstance(f, Mapping) and f.get("code") == "no_windows":
                con.print(Text(f"open-loop error over horizons: {f.get('message')}"))
        return
    # a log without attitude has no attitude column: its title does not name one
    attitude = (
        " / mean geodesic attitude error, rad ("
        if h.get("attitude")
        else " (no attitude in the log; "
    )
    table = RichTable(
        title=f"open-loop error over horizons ({h['windows']} windows{stride_words(h)}): "
        f"mean norm of the body-rate error, rad/s{attitude}in brackets: {COVERAGE_WORDS})",
        title_justify="left",
    )
    table.add_column("predictor")
    for s in h["seconds"]:
        table.add_column(f"{float(s):g} s", justify="right")
    n_models = _n_models(h)
    for p in h["predictors"]:
        cells = []
        for e in h["table"][p["key"]]:
            text = f"{e['rate_error']['norm']:.3g}"
            if e.get("attitude_error") is not None:
                text += f" / {e['attitude_error']:.3g}"
            if e.get("coverage"):
                text += f" ({coverage_cell(e['coverage'])})"
            cells.append(text)
        table.add_row(Text(label(p, n_models)), *cells)
    con.print(table)
    if legend := models_legend(tree, n_models):  # every other table names the files
        con.print(Text(f"  {legend}"))
    for f in h.get("findings") or []:
        con.print(Text(f"  {f['message']}"))


def models_legend(tree: Mapping[str, Any], n_models: int) -> str:
    """'model 0: base.npz, model 1: base+motor_lag.npz' for the table's "(model j)" labels
    ('' for one model or a file that does not name them)."""
    names = [m.get("name") for m in tree.get("models") or [] if isinstance(m, Mapping)]
    if n_models < 2 or len(names) != n_models:
        return ""
    return ", ".join(f"model {j}: {n}" for j, n in enumerate(names))


def horizons_json(tree: Mapping[str, Any]) -> dict[str, Any] | None:
    """The ``--json`` object's ``horizons``: the table (without the chunk means) and
    findings, without the curves."""
    h = horizons_of(tree)
    if h is None:
        return None
    out = {k: v for k, v in h.items() if k != "curves"}
    out["table"] = {
        key: [{k: v for k, v in row.items() if k != "rate_error_chunks"} for row in rows]
        for key, rows in (h.get("table") or {}).items()
    }
    return out
