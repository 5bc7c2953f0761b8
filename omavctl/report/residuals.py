"""Sections 2-4 of the report: where and when the model errs.

2. measured vs predicted angular acceleration over time (one figure per log,
   the model's +-2 sigma band);
3. the residual's mean per quantile bin of each input and state feature
   (the model's and the nominal model's);
4. the worst time windows, with what the vehicle was doing there.

Figures are matplotlib (Agg), fixed size and dpi, as PNG bytes; with
``figures`` False the sections carry empty PNGs (for Markdown).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.document import Block, Cell, FigureBlock, Heading, Para, Table
from omavctl.report.figures import AXIS_COLOURS
from omavctl.report.figures import png as _png
from omavctl.report.figures import runs as _runs
from omavctl.report.figures import style as _style
from omavctl.report.numfmt import AXES, axes_of, finite, num

__all__ = ["binned_section", "time_section", "worst_section"]


#: Figure resolution (dots per inch) of every embedded PNG.
DPI = 100


def _time_figure(series: Mapping[str, np.ndarray], sel: np.ndarray, dt: float, title: str) -> bytes:
    """Measured vs predicted angular acceleration of one log, one panel per axis."""
    from matplotlib.figure import Figure

    t = np.asarray(series["t"], float)[sel]
    measured = np.asarray(series["measured"], float)[sel]
    nominal = np.asarray(series["nominal"], float)[sel]
    pred = nominal + np.asarray(series["mean_0"], float)[sel]
    std = np.asarray(series["std_0"], float)[sel]
    with _style():
        fig = Figure(figsize=(10, 7.2), dpi=DPI, layout="constrained")
        axs = fig.subplots(3, 1, sharex=True)
        for i, ax in enumerate(axs):
            for k, run in enumerate(_runs(t, dt)):
                first = k == 0
                ax.fill_between(
                    t[run],
                    pred[run, i] - 2 * std[run, i],
                    pred[run, i] + 2 * std[run, i],
                    color="C0",
                    alpha=0.25,
                    linewidth=0,
                    label="model ±2σ" if first else None,
                )
                ax.plot(
                    t[run], measured[run, i], color="k", lw=0.8, label="measured" if first else None
                )
                ax.plot(
                    t[run],
                    nominal[run, i],
                    color="0.55",
                    lw=0.8,
                    ls="--",
                    label="nominal" if first else None,
                )
                ax.plot(t[run], pred[run, i], color="C0", lw=1.0, label="model" if first else None)
            ax.set_ylabel(rf"$\dot\omega_{AXES[i]}$, rad/s²")
            ax.grid(True, lw=0.3, alpha=0.6)
        fig.legend(*axs[0].get_legend_handles_labels(), loc="outside upper center", ncol=4,
                   fontsize=8, frameon=False)  # fmt: skip
        axs[0].set_title(title, fontsize=10)
        axs[-1].set_xlabel("time, s")
        return _png(fig)


def time_section(
    tree: Mapping[str, Any],
    series: Mapping[str, np.ndarray],
    k: int,
    label: str,
    figures: bool,
) -> list[Block]:
    """One figure per log of evaluation ``k``: measured vs predicted angular acceleration.
    ``series``: ``t`` and ``log`` (n,), ``measured``, ``nominal``, ``mean_0``, ``std_0``
    (n, 3); with ``figures`` False the figures are left empty."""
    blocks: list[Block] = [Heading(3, label, f"time-{k}")]
    models = tree.get("models", []) or []
    model_name = _get(models, 0, "name", default="the model")
    text = (
        f"Measured angular acceleration (black), the nominal model (grey, dashed) and "
        f"{model_name} (blue, nominal + effects + GP mean, with its ±2σ band)."
    )
    if len(models) > 1:
        text += " Only the first model is plotted; the others are in the summary table."
    blocks.append(Para(text))
    t = np.asarray(series["t"], float)
    log_id = np.asarray(series["log"]).astype(int)
    rate = tree.get("grid_rate_hz")
    if finite(rate) and rate > 0:
        dt = 1.0 / float(rate)
    else:
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    logs = tree.get("logs", [])
    by_log = tree.get("metrics_by_log") or []
    for i, lg in enumerate(logs):
        sel = np.flatnonzero(log_id == i)
        if sel.size == 0:
            continue
        name = str(lg.get("name", f"log {i}"))
        rmse = _get(by_log, i, "model", "rmse")
        caption = f"{name}: measured vs predicted angular acceleration"
        if rmse is not None:
            caption += (
                " (model RMSE "
                + ", ".join(f"{a} {num(v)}" for a, v in zip(AXES, axes_of(rmse), strict=True))
                + " rad/s²)"
            )
        png = _time_figure(series, sel, dt, f"{label} — {name}") if figures else b""
        blocks.append(
            FigureBlock(png, f"{name}: measured vs predicted angular acceleration", caption)
        )
    return blocks


def _feature_unit(name: str) -> str:
    if name.startswith("(I^-1 tau)"):
        return "rad/s²"
    if name.startswith("f") and name.endswith("/m"):
        return "m/s²"
    if re.fullmatch(r"w[xyz]", name):
        return "rad/s"
    if name in ("roll", "pitch", "yaw"):
        return "rad"
    return ""


def _binned_figure(binned: Mapping[str, Any], which: str, title: str) -> bytes | None:
    """Residual mean per quantile bin of each feature, every panel on the same scale."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    names = [n for n, e in binned.items() if isinstance(e, Mapping) and f"{which}_mean" in e]
    if not names:
        return None
    ncols = 4
    nrows = math.ceil(len(names) / ncols)
    with _style():
        height = 2.3 * nrows + 0.9
        fig = Figure(figsize=(12, height), dpi=DPI)
        fig.subplots_adjust(
            left=0.05,
            right=0.99,
            bottom=0.5 / height,
            top=1 - 0.75 / height,
            wspace=0.22,
            hspace=0.5,
        )
        axs = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False, sharey=True)).ravel()
        for ax, name in zip(axs, names, strict=False):
            entry = binned[name]
            x = np.asarray(entry.get("centers", []), float)
            for i, axis in enumerate(AXES):
                mean = np.asarray(_get(entry, f"{which}_mean", axis, default=[]), float)
                if mean.shape == x.shape:
                    ax.plot(x, mean, "-o", color=AXIS_COLOURS[i], ms=2.5, lw=1.0)
            ax.axhline(0.0, color="0.6", lw=0.5)
            unit = _feature_unit(name)
            ax.set_xlabel(f"{name}, {unit}" if unit else name, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, lw=0.3, alpha=0.6)
        for ax in axs[::ncols]:
            ax.set_ylabel("residual, rad/s²", fontsize=8)
        for ax in axs[len(names) :]:
            ax.set_visible(False)
        handles = [
            Line2D([], [], color=AXIS_COLOURS[i], lw=1.5, label=f"axis {a}")
            for i, a in enumerate(AXES)
        ]
        handles += [
            Line2D([], [], color="k", ls="-", marker="o", ms=2.5, label="mean per bin"),
        ]
        fig.legend(
            handles=handles,
            loc="upper center",
            bbox_to_anchor=(0.5, 1 - 0.3 / height),
            ncol=5,
            fontsize=8,
            frameon=False,
        )
        fig.suptitle(title, fontsize=10, y=1 - 0.05 / height, va="top")
        return _png(fig)


def binned_section(tree: Mapping[str, Any], k: int, label: str, figures: bool) -> list[Block]:
    """The model's and the nominal model's residual per feature bin of evaluation ``k``
    (its 'binned' entry); a note when there is none."""
    blocks: list[Block] = [Heading(3, label, f"binned-{k}")]
    binned = tree.get("binned")
    if not isinstance(binned, Mapping) or not binned:
        return [*blocks, Para("No binned residuals in this evaluation.", note=True)]
    blocks.append(
        Para(
            "Residual (measured − predicted angular acceleration, rad/s²) in quantile bins "
            "of each input and state feature, all panels on one scale: a mean that moves "
            "away from 0 is structure a missing effect leaves (the RMS per bin is in the "
            "evaluation JSON, 'binned')."
        )
    )
    for which, title in (("model", "model residual"), ("nominal", "nominal residual")):
        png = _binned_figure(binned, which, f"{label}: {title} vs feature") if figures else b""
        if png is not None:
            blocks.append(FigureBlock(png, f"{title} vs feature", f"{title} per feature bin"))
    return blocks


def worst_section(tree: Mapping[str, Any], k: int, label: str) -> list[Block]:
    """The worst time windows of evaluation ``k``: RMSE per axis and what the vehicle
    was doing there."""
    from omavctl.diagnose.verdict import activity

    blocks: list[Block] = [Heading(3, label, f"worst-{k}")]
    segs = tree.get("worst_segments") or []
    if not segs:
        return [*blocks, Para("No worst segments in this evaluation.", note=True)]
    rows: list[list[Cell]] = [
        [
            str(i + 1),
            str(s.get("log", "?")),
            f"{num(s.get('start'), 3)}–{num(s.get('end'), 3)}",
            *(num(v, 3) for v in axes_of(s.get("rmse"))),
            activity(s),
        ]
        for i, s in enumerate(segs)
        if isinstance(s, Mapping)
    ]
    blocks.append(
        Para(
            "Time windows where the model's error is largest (RMSE per axis, rad/s²; numbered "
            "as in the error-over-time figures), with what the vehicle was doing there: its "
            "tilt (mean |roll|, |pitch|), its fastest rotation (mean |body rate|) and its "
            "thrust when far from hover. The mean |attitude|, |rate| and |scaled wrench| "
            "vectors are in the evaluation JSON ('worst_segments')."
        )
    )
    blocks.append(
        Table(
            columns=["#", "log", "time, s", *AXES, "what the vehicle was doing"],
            groups=[("", 3), ("RMSE, rad/s²", 3), ("", 1)],
            rows=rows,
            align="rlrrrrl",
        )
    )
    return blocks
