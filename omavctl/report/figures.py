"""Figures of the report that explain rather than list (matplotlib, Agg, PNG bytes).

- :func:`error_figure`: model error over time per axis, the worst segments shaded,
  numbered and labelled with what the vehicle was doing;
- :func:`signature_figure`: an effect's signature, the model's error against that
  effect's regressor per axis with the fitted line through the origin;
- :func:`candidates_figure`: held-out explained variance of every candidate effect,
  the threshold, which are missing and which are ambiguous with which;
- :func:`before_after_figure`: model RMSE per axis per file with the % change.

Legends sit outside the axes (above them) so that they never hide a line; every
figure has a fixed size and dpi so that the same inputs give the same bytes.
"""

from __future__ import annotations

import io
import itertools
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from omavctl.diagnose.verdict import activity

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "before_after_figure",
    "candidates_figure",
    "error_figure",
    "error_limits",
    "png",
    "runs",
    "signature_figure",
    "signature_slopes",
    "style",
]

AXES = ("x", "y", "z")
DPI = 100
#: Colours of the three body axes.
AXIS_COLOURS = ("#1f77b4", "#d62728", "#2ca02c")
#: Colour of an effect named missing (not an axis colour).
MISSING_COLOUR = "#7b4fa6"


def png(fig: Figure) -> bytes:
    """The figure as PNG bytes without metadata that changes between runs.

    Drawn once: ``savefig`` on a figure with a layout engine first draws the whole
    figure with rendering switched off (to run the layout) and then again with it on;
    ``FigureCanvasAgg.draw`` runs the layout engine and draws in one pass, and the
    PNG is written as ``savefig`` writes it (the same bytes, checked on the figures of
    three reports, docs/testing.md "Session 19").
    """
    import matplotlib.image
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if fig.dpi != DPI:
        fig.set_dpi(DPI)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    buf = io.BytesIO()
    no_software: dict[str, Any] = {"Software": None}  # as savefig: no version stamp
    matplotlib.image.imsave(
        buf, canvas.buffer_rgba(), format="png", origin="upper", dpi=DPI,
        metadata=no_software,
    )  # fmt: skip
    return buf.getvalue()


def style() -> Any:
    """matplotlib's default style, whatever the user's matplotlibrc says."""
    import matplotlib.style

    return matplotlib.style.context("default")


def runs(t: np.ndarray, dt: float) -> list[slice]:
    """Contiguous stretches of ``t`` (breaks where the step exceeds 1.5 dt)."""
    if t.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(t) > 1.5 * dt) + 1
    edges = [0, *cuts.tolist(), t.size]
    return [slice(a, b) for a, b in itertools.pairwise(edges)]


def _segment_note(rank: int, seg: Mapping[str, Any]) -> str:
    rmse = seg.get("rmse") or {}
    worst = max(AXES, key=lambda a: float(rmse.get(a, 0.0) or 0.0))
    return (
        f"#{rank}  {float(seg.get('start', 0)):.1f}–{float(seg.get('end', 0)):.1f} s: "
        f"{worst} error {float(rmse.get(worst, 0.0)):.3g} rad/s², {activity(seg)}"
    )


def error_figure(
    t: np.ndarray,
    err: np.ndarray,
    std: np.ndarray,
    segments: Sequence[Mapping[str, Any]],
    dt: float,
    title: str,
) -> bytes:
    """Model error (measured − predicted) per axis over time, ±2σ, worst segments shaded.

    ``segments`` are the worst segments of this log (with their rank in ``"rank"``).
    """
    with style():
        return png(_error_fig(t, err, std, segments, dt, title))


def error_limits(err: np.ndarray) -> np.ndarray:
    """Each axis's y half-range (3,) of the error-over-time figure: 1.25 × the 99.5th
    percentile of its own |error| (n, 3). One scale for all three axes drew a
    Crazyflie's yaw error (1.5 rad/s² RMS) as a flat line under roll's and pitch's
    (26 and 40 rad/s²), eyes6."""
    import warnings

    if not err.size:
        return np.ones(3)
    with warnings.catch_warnings():  # an axis of NaN only: its limit is the floor
        warnings.simplefilter("ignore", RuntimeWarning)
        lim = np.nanpercentile(np.abs(err), 99.5, axis=0) * 1.25
    return np.where(np.isfinite(lim) & (lim > 1e-6), lim, 1e-6)


def _error_fig(
    t: np.ndarray,
    err: np.ndarray,
    std: np.ndarray,
    segments: Sequence[Mapping[str, Any]],
    dt: float,
    title: str,
) -> Figure:
    """The figure of :func:`error_figure` (drawn under :func:`style`); each axis on its
    own y scale (:func:`error_limits`), the time axis shared."""
    from matplotlib.figure import Figure

    n_notes = len(segments)
    height = 6.0 + 0.2 * n_notes
    fig = Figure(figsize=(10, height), dpi=DPI, layout="constrained")
    ratios = [1.0, 1.0, 1.0] + ([0.1 + 0.075 * n_notes] if n_notes else [])
    grid = fig.add_gridspec(len(ratios), 1, height_ratios=ratios)
    axs = [fig.add_subplot(grid[0])]
    axs += [fig.add_subplot(grid[i], sharex=axs[0]) for i in (1, 2)]
    lims = error_limits(err)
    for i, ax in enumerate(axs):
        for k, run in enumerate(runs(t, dt)):
            ax.fill_between(
                t[run],
                -2 * std[run, i],
                2 * std[run, i],
                color="0.85",
                linewidth=0,
                label="predicted ±2σ" if k == 0 else None,
            )
            ax.plot(
                t[run],
                err[run, i],
                color=AXIS_COLOURS[i],
                lw=0.8,
                label="measured − predicted" if k == 0 else None,
            )
        for seg in segments:
            a, b = float(seg.get("start", 0)), float(seg.get("end", 0))
            ax.axvspan(a, b, color="#ff7f0e", alpha=0.18, lw=0)
            if i == 0:
                ax.text(
                    (a + b) / 2, 0.97, f"#{seg.get('rank')}",
                    transform=ax.get_xaxis_transform(), ha="center", va="top",
                    fontsize=8, color="#b35900", fontweight="bold",
                )  # fmt: skip
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_ylim(-float(lims[i]), float(lims[i]))
        ax.set_ylabel(f"error {AXES[i]}, rad/s²")
        ax.grid(True, lw=0.3, alpha=0.6)
    axs[-1].set_xlabel("time, s")
    handles, labels = axs[0].get_legend_handles_labels()
    from matplotlib.patches import Patch

    handles.append(Patch(color="#ff7f0e", alpha=0.3))
    labels.append("worst segment")
    fig.legend(handles, labels, loc="outside upper center", ncol=3, fontsize=8, frameon=False)
    axs[0].set_title(title, fontsize=10)
    for ax in axs[:2]:
        ax.tick_params(labelbottom=False)
    if n_notes:
        notes = fig.add_subplot(grid[3])
        notes.axis("off")
        text = "\n".join(_segment_note(int(s.get("rank", 0)), s) for s in segments)
        notes.text(0.0, 1.0, text, fontsize=8.5, va="top", ha="left", transform=notes.transAxes)
    return fig


def signature_slopes(contribution: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Per axis (3,), the least-squares slope through the origin of the model's error
    (n, 3) on an effect's fitted part of it (n, 3), both rad/s²: 1 where the error
    follows the effect at the size the diagnosis estimated, 0 where it does not
    follow it at all; NaN on an axis the effect does not reach."""
    xx = np.einsum("na,na->a", contribution, contribution)
    xy = np.einsum("na,na->a", contribution, error)
    scale = np.maximum(np.abs(contribution).max(axis=0, initial=0.0), 1e-300)
    return np.where(xx > 1e-18 * scale**2 * max(len(error), 1), xy / np.maximum(xx, 1e-300), np.nan)


def signature_figure(
    contribution: np.ndarray,
    error: np.ndarray,
    name: str,
    explained: Mapping[str, Any] | None,
    title: str,
) -> bytes | None:
    """The model's error (n, 3) against an effect's fitted part of it (n, 3), per axis,
    both in rad/s²: the quantity the diagnosis scores, on the same samples.

    The line is the least-squares fit through the origin (:func:`signature_slopes`;
    1 = the diagnosis' estimate explains the error at its size), the dots bin means;
    ``explained`` the held-out explained variance per axis (``x``, ``y``, ``z``).
    """
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    if contribution.ndim != 2 or contribution.shape != error.shape or error.shape[1] != 3:
        return None
    slopes = signature_slopes(contribution, error)
    with style():
        fig = Figure(figsize=(10, 3.6), dpi=DPI, layout="constrained")
        axs = fig.subplots(1, 3)  # each axis on its own scale, as the error over time
        lims = error_limits(error)
        for i, ax in enumerate(axs):
            x, y = contribution[:, i], error[:, i]
            ax.scatter(x, y, s=2, color=AXIS_COLOURS[i], alpha=0.25, lw=0, rasterized=True)
            if np.isfinite(slopes[i]):
                xs = np.linspace(x.min(), x.max(), 2)
                ax.plot(xs, slopes[i] * xs, color="k", lw=1.2)
                ev = (explained or {}).get(AXES[i])
                held = (
                    f", explains {100 * ev:.0f} % held out" if isinstance(ev, int | float) else ""
                )
                ax.set_title(f"axis {AXES[i]}: slope {slopes[i]:.2f}{held}", fontsize=9)
                edges = np.unique(np.quantile(x, np.linspace(0, 1, 11)))
                which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
                count = np.bincount(which, minlength=edges.size - 1)
                means = np.bincount(which, y, edges.size - 1) / np.maximum(count, 1)
                centres = np.bincount(which, x, edges.size - 1) / np.maximum(count, 1)
                ax.plot(centres[count > 0], means[count > 0], "o", color="k", ms=3.5, mfc="w")
            else:
                ax.text(0.5, 0.5, "no fitted part here", transform=ax.transAxes, ha="center")
            ax.axhline(0.0, color="0.6", lw=0.5)
            ax.set_ylim(-float(lims[i]), float(lims[i]))
            ax.set_xlabel(f"fitted {name}, axis {AXES[i]}, rad/s²", fontsize=9)
            # at most 5 ticks: a third of the figure's width held "−0.100−0.075−0.050..."
            # run together (a new user)
            ax.xaxis.set_major_locator(MaxNLocator(nbins=5))
            ax.grid(True, lw=0.3, alpha=0.6)
        for ax in axs:
            ax.set_ylabel("model error, rad/s²", fontsize=9)
        fig.suptitle(title, fontsize=10)
        return png(fig)


def candidates_figure(
    entries: Sequence[Mapping[str, Any]],
    threshold: float | None,
    later: Mapping[str, str] | None = None,
) -> bytes:
    """Held-out explained variance of every candidate effect, best first; ``later``:
    effect -> the later selection step that claimed it (coloured missing, labelled with
    the step, though its bar alone is short)."""
    from matplotlib.figure import Figure

    rows = [e for e in entries if isinstance(e, Mapping)][:10]
    names = [str(e.get("name", "?")) for e in rows]
    ev = np.array([max(float(e.get("explained_variance") or 0.0), 0.0) for e in rows])
    with style():
        fig = Figure(figsize=(9, 0.5 * len(rows) + 1.4), dpi=DPI, layout="constrained")
        ax = fig.subplots()
        y = np.arange(len(rows))[::-1]
        for k, e in enumerate(rows):
            step = (later or {}).get(names[k])
            missing = e.get("missing") is True or step is not None
            amb = e.get("ambiguous_with") or []
            ax.barh(
                y[k],
                ev[k],
                color=MISSING_COLOUR if missing else "0.7",
                hatch="//" if amb else None,
                edgecolor="k" if amb else "none",
                height=0.6,
            )
            per_axis = e.get("explained_variance_per_axis") or {}
            for i, a in enumerate(AXES):
                v = per_axis.get(a)
                if isinstance(v, int | float):
                    ax.plot(max(float(v), 0.0), y[k], "|", ms=12, mew=2, color=AXIS_COLOURS[i])
            text = f"{100 * ev[k]:.0f} %" + ("  missing" if missing else "")
            text += f" ({step})" if step is not None else ""
            if amb:
                text += f"  ambiguous with {', '.join(map(str, amb))}"
            axis_ev = [float(v) for v in per_axis.values() if isinstance(v, int | float)]
            right = max([ev[k], *axis_ev, threshold or 0.0])
            ax.text(right + 0.02, y[k], text, va="center", fontsize=8)
        if threshold is not None:
            ax.axvline(threshold, color="k", ls="--", lw=0.8)
        ax.set_yticks(y, names)
        ax.set_xlim(0, 1.35)  # room right of 1 for the labels, but no scale there
        ticks = np.linspace(0.0, 1.0, 6)
        ax.set_xticks(ticks, [f"{100 * v:.0f} %" for v in ticks])
        ax.axvline(1.0, color="0.6", lw=0.8)
        ax.set_xlabel("explained variance of the model's error, held-out blocks")
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        handles: list[Any] = [
            Patch(color=MISSING_COLOUR, label="missing"),
            Patch(color="0.7", label="not missing"),
        ]
        handles += [
            Line2D([], [], ls="none", marker="|", ms=10, mew=2, color=c, label=f"axis {a}")
            for a, c in zip(AXES, AXIS_COLOURS, strict=True)
        ]
        if threshold is not None:
            handles.append(Line2D([], [], color="k", ls="--", label="threshold"))
        fig.legend(handles=handles, loc="outside upper center", ncol=6, fontsize=8, frameon=False)
        return png(fig)


def before_after_figure(labels: Sequence[str], rmse: Sequence[Sequence[float]]) -> bytes:
    """Model RMSE per axis (panels) per evaluation file (bars), % change from the first."""
    with style():
        return png(_before_after_fig(labels, rmse))


def _before_after_fig(labels: Sequence[str], rmse: Sequence[Sequence[float]]) -> Figure:
    """The figure of :func:`before_after_figure` (under :func:`style`): one panel per
    body axis on its own y scale, as the error over time (on one scale the Crazyflie
    halves' z, 1.46 -> 2.07 rad/s² and 42 % worse, was a sliver under y's 39.9)."""
    from matplotlib.figure import Figure

    k = len(labels)
    fig = Figure(figsize=(9, 4.0), dpi=DPI, layout="constrained")
    axs = fig.subplots(1, len(AXES))
    for i, ax in enumerate(axs):
        vals = [float(v[i]) for v in rmse]
        top = max(max(vals, default=0.0), 1e-12)
        for j, (label, v) in enumerate(zip(labels, vals, strict=True)):
            ax.bar(j, v, 0.8, label=label, color=f"C{j % 10}")
            text = f"{v:.3g}"
            if j > 0 and vals[0] > 0:
                text += f"\n{100 * (v / vals[0] - 1):+.1f} %"
            ax.text(j, v + 0.01 * top, text, ha="center", va="bottom", fontsize=8)
        ax.set_ylim(0, top * 1.3)
        ax.set_xticks([])
        ax.set_title(f"axis {AXES[i]}", fontsize=10)
        ax.grid(True, axis="y", lw=0.3, alpha=0.6)
    axs[0].set_ylabel("model RMSE, rad/s²")
    handles, names = axs[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside upper center", ncol=min(k, 4), fontsize=8,
               frameon=False)  # fmt: skip
    return fig
