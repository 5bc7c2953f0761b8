"""Render evaluation files (``omavctl evaluate`` output) as one report.

The report is a single self-contained HTML file: figures are embedded as
base64 PNG (matplotlib, Agg, fixed size and dpi, no metadata that changes
between runs), the CSS is inline, and nothing refers to the network. The same
inputs give the same bytes. ``--format md`` renders the same content as
Markdown (tables; the figures are left out and say so).

Sections, per evaluation file where that applies:

1. summary: logs, models, samples, per-axis metrics of the nominal model,
   nominal + fitted effects and the full model; tracking error; units;
2. measured vs predicted angular acceleration over time, with a +-2 sigma band;
3. residual vs feature (binned mean and RMS) for the model and the nominal model;
4. the worst time windows;
5. the diagnosis: the ranking of candidate missing effects, the effects named
   missing, unexplained structure, the ``omavctl fit`` command that adds the
   top effect, and what the GP has learned in physical terms;
6. with several files: model RMSE per axis before/after, % change from the first.

The document is first built as a list of format-neutral blocks (headings,
paragraphs, tables, figures, code) and then written out as HTML or Markdown,
so both formats carry the same content. Every string that comes from an
evaluation file is escaped.
"""

from __future__ import annotations

import base64
import html
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np

from omavctl.base.atomic import atomic_path
from omavctl.base.errors import OmavctlError
from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.figures import AXIS_COLOURS
from omavctl.report.figures import png as _png
from omavctl.report.figures import runs as _runs
from omavctl.report.figures import style as _style

__all__ = [
    "FORMATS",
    "Evaluation",
    "EvaluationSummary",
    "ReportSummary",
    "check_evaluation",
    "format_from_suffix",
    "load_for_report",
    "percent_change",
    "render_report",
    "write_report",
]

#: Output formats of :func:`render_report`.
FORMATS = ("html", "md")
AXES = ("x", "y", "z")
#: One evaluation to report: (JSON tree, time series, label shown in the report).
Evaluation = tuple[dict[str, Any], Mapping[str, np.ndarray], str]

#: Figure resolution (dots per inch) of every embedded PNG.
DPI = 100
#: Series every evaluation must carry, with their number of columns (0: 1-D).
REQUIRED_SERIES = {"t": 0, "log": 0, "measured": 3, "nominal": 3, "mean_0": 3, "std_0": 3}
#: Prediction kinds of the metrics tables, with their titles.
PREDICTIONS = (
    ("nominal", "nominal"),
    ("effects", "nominal + effects"),
    ("model", "model"),
)
#: Metrics of the summary table: key, title.
METRICS = (
    ("rmse", "RMSE"),
    ("mae", "MAE"),
    ("r2", "R² (of the nominal residual)"),
    ("mean_std", "mean predicted std"),
    ("coverage_2sigma", "within 2σ (fraction)"),
    ("nlpd", "NLPD (nats/sample)"),
)
#: Metrics in rad/s^2 (the others are dimensionless or nats).
ACCEL_METRICS = {"rmse", "mae", "mean_std"}


# ------------------------------------------------------------------ blocks
@dataclass(frozen=True)
class Span:
    """Inline text with a style: '' plain, 'code', 'strong' or 'em'."""

    text: str
    style: str = ""


Inline = str | Span
#: A table cell or a paragraph: one inline or a sequence of them; a cell may
#: also be a list of lines (:class:`Lines`).
Content = Inline | tuple[Inline, ...]


@dataclass(frozen=True)
class Lines:
    """A table cell of several lines."""

    lines: tuple[Content, ...]


Cell = Content | Lines


@dataclass
class Heading:
    """A heading of ``level`` 1-4; ``anchor`` its id for in-page links."""

    level: int
    text: str
    anchor: str | None = None


@dataclass
class Para:
    """A paragraph; ``note`` paragraphs are shown muted."""

    content: Content
    note: bool = False


@dataclass
class Bullets:
    """A bulleted list."""

    items: list[Content]


@dataclass
class Table:
    """A table; ``groups`` (title, span) is an optional header row above ``columns``.
    ``align`` has one letter per column, 'l' (text) or 'r' (numbers); default: the
    first column left, the others right."""

    columns: list[str]
    rows: list[list[Cell]]
    groups: list[tuple[str, int]] | None = None
    align: str | None = None

    def right(self, i: int) -> bool:
        """Whether column ``i`` is right-aligned."""
        return self.align[i] == "r" if self.align else i > 0

    caption: str | None = None


@dataclass
class FigureBlock:
    """An embedded PNG figure with its alt text and caption."""

    png: bytes
    alt: str
    caption: str


@dataclass
class Code:
    """A preformatted block (a command to copy)."""

    text: str


Block = Heading | Para | Bullets | Table | FigureBlock | Code


@dataclass
class Document:
    """The report: a title and its blocks in order."""

    title: str
    blocks: list[Block] = field(default_factory=list)

    def add(self, *blocks: Block) -> None:
        self.blocks.extend(blocks)


# ------------------------------------------------------------------ numbers
def _finite(v: Any) -> TypeGuard[int | float]:
    """A finite int or float (not a bool)."""
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _g(v: Any, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; 'n/a' for anything else."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return "n/a"
    if math.isnan(v):
        return "n/a"
    if math.isinf(v):
        return "∞" if v > 0 else "-∞"
    return f"{v:.{digits}g}"


def _pct(v: Any) -> str:
    return f"{100 * v:.1f} %" if _finite(v) else "n/a"


def percent_change(new: Any, old: Any) -> str:
    """``(new - old) / old`` in percent, signed, one decimal ('n/a' if undefined)."""
    if not (_finite(new) and _finite(old)) or old <= 0:
        return "n/a"
    return f"{100 * (new - old) / old:+.1f} %"


def _axes_of(d: Any) -> list[Any]:
    return [_get(d, a) for a in AXES]


def _torque_unknown(tree: Mapping[str, Any]) -> bool:
    return _get(tree, "units", "torque") == "unknown"


def _unit(unit: str, torque_unknown: bool) -> str:
    """A parameter unit for display ('' for dimensionless)."""
    if unit == "1":
        return ""
    if torque_unknown and "N m" in unit:
        return unit.replace("N m", "[torque unit]")
    return unit


# ---------------------------------------------------------------- validation
def _bad_metric(block: Any, where: str) -> str | None:
    """Path of the first metric value in ``block`` ({prediction: {metric: {axis: value}}})
    that is neither a number nor null, else None."""
    if not isinstance(block, Mapping):
        return where
    for pred, metrics in block.items():
        if not isinstance(metrics, Mapping):
            return f"{where}.{pred}"
        for name, axes in metrics.items():
            if not isinstance(axes, Mapping):
                return f"{where}.{pred}.{name}"
            for axis, value in axes.items():
                if value is not None and not _finite(value):
                    return f"{where}.{pred}.{name}.{axis}"
    return None


def check_evaluation(tree: Any, series: Mapping[str, np.ndarray], path: str | Path) -> None:
    """Raise :class:`OmavctlError` naming ``path`` unless ``tree`` and ``series``
    carry what the report needs (the ``load_evaluation`` schema check comes first)."""
    for pred in ("nominal", "model"):
        for axis in AXES:
            if not _finite(_get(tree, "metrics", pred, "rmse", axis)):
                raise OmavctlError(
                    f"not an evaluation JSON: no number at 'metrics.{pred}.rmse.{axis}'", path
                )
    bad = _bad_metric(tree.get("metrics"), "metrics")
    for i, block in enumerate(_as_list(tree.get("metrics_by_model") or [])):
        bad = bad or _bad_metric(block, f"metrics_by_model[{i}]")
    if bad:
        raise OmavctlError(f"not an evaluation JSON: '{bad}' is not a number", path)
    logs = tree.get("logs")
    if not isinstance(logs, list) or not logs or not all(isinstance(lg, Mapping) for lg in logs):
        raise OmavctlError("not an evaluation JSON: 'logs' is not a list of logs", path)
    n = None
    for key, cols in REQUIRED_SERIES.items():
        if key not in series:
            raise OmavctlError(f"its time series file lacks '{key}'", path)
        arr = np.asarray(series[key])
        shape_ok = arr.ndim == 1 if cols == 0 else (arr.ndim == 2 and arr.shape[1] == cols)
        if not shape_ok or not np.issubdtype(arr.dtype, np.number):
            raise OmavctlError(f"time series '{key}' has shape {arr.shape}", path)
        n = arr.shape[0] if n is None else n
        if arr.shape[0] != n:
            raise OmavctlError(f"time series '{key}' has {arr.shape[0]} samples, not {n}", path)
        if not np.all(np.isfinite(arr)):
            raise OmavctlError(f"time series '{key}' has non-finite values", path)
    log_id = np.asarray(series["log"])
    if n and (log_id.min() < 0 or log_id.max() >= len(logs)):
        raise OmavctlError("time series 'log' refers to logs the JSON does not list", path)


def load_for_report(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Load an evaluation JSON and its series and check them for the report."""
    from omavctl.diagnose.evalio import load_evaluation

    tree, series = load_evaluation(path)
    check_evaluation(tree, series, path)
    return tree, series


def format_from_suffix(out: str | Path) -> str:
    """'md' for a .md/.markdown output name, 'html' for .html/.htm or no suffix;
    any other suffix (.pdf, ...) is refused, naming the formats that exist."""
    suffix = Path(out).suffix.lower()
    if suffix in (".md", ".markdown"):
        return "md"
    if suffix in ("", ".html", ".htm"):
        return "html"
    raise OmavctlError(
        f"cannot write a '{suffix}' report: the formats are html (.html) and md (.md) "
        "(or choose one with --format)",
        out,
    )


# ------------------------------------------------------------------- figures
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


# ------------------------------------------------------------------ sections
def _summary_overview(evals: Sequence[Evaluation]) -> list[Block]:
    rows: list[list[Cell]] = []
    for tree, series, label in evals:
        logs = tree.get("logs", [])
        models = tree.get("models", [])
        missing = _get(tree, "diagnosis", "missing", default=[]) or []
        rows.append(
            [
                label,
                Lines(tuple(str(_get(lg, "name", default="?")) for lg in logs)),
                Lines(tuple(_model_title(m) for m in models)) if models else "n/a",
                str(int(np.asarray(series["t"]).size)),
                *(_g(v) for v in _axes_of(_get(tree, "metrics", "nominal", "rmse"))),
                *(_g(v) for v in _axes_of(_get(tree, "metrics", "model", "rmse"))),
                (Span(str(missing[0]), "code"),) if missing else "none",
            ]
        )
    return [
        Table(
            columns=["evaluation", "logs", "models", "samples", *AXES, *AXES, "top missing effect"],
            groups=[("", 4), ("nominal RMSE, rad/s²", 3), ("model RMSE, rad/s²", 3), ("", 1)],
            rows=rows,
            align="lllrrrrrrrl",
        )
    ]


def _model_title(m: Mapping[str, Any]) -> str:
    effects = list((m.get("effects") or {}).keys())
    eff = ", ".join(effects) if effects else "no effects"
    return f"{m.get('name', '?')} ({eff})"


def _effect_units(tree: Mapping[str, Any]) -> dict[str, dict[str, str]]:
    """Parameter units per effect name, from the diagnosis entries."""
    out: dict[str, dict[str, str]] = {}
    for key in ("learned", "missing_effects"):
        for entry in _get(tree, "diagnosis", key, default=[]) or []:
            if isinstance(entry, Mapping) and isinstance(entry.get("units"), Mapping):
                out.setdefault(str(entry.get("name")), {}).update(
                    {str(k): str(v) for k, v in entry["units"].items()}
                )
    return out


def _param_lines(
    params: Mapping[str, Any], units: Mapping[str, str], torque_unknown: bool
) -> tuple[Content, ...]:
    """'name_axis = value ± stderr unit' per parameter component; components whose
    ``excited`` flag is false are left out (and named as such)."""
    names = [k for k in params if k != "excited" and not str(k).endswith("_stderr")]
    values = {k: _as_list(params[k]) for k in names}
    excited = params.get("excited")
    total = sum(len(v) for v in values.values())
    if not (isinstance(excited, list) and len(excited) == total):
        excited = [True] * total
    lines: list[Content] = []
    skipped: list[str] = []
    offset = 0
    for k in names:
        vals = values[k]
        errs = _as_list(params.get(f"{k}_stderr", []))
        if len(vals) == 3:
            labels = [f"{k}_{a}" for a in AXES]
        elif len(vals) == 1:
            labels = [str(k)]
        else:
            labels = [f"{k}_{i}" for i in range(len(vals))]
        unit = _unit(str(units.get(k, "")), torque_unknown)
        for i, v in enumerate(vals):
            if not excited[offset + i]:
                skipped.append(labels[i])
                continue
            err = f" ± {_g(errs[i], 2)}" if i < len(errs) else ""
            note = ""
            if i < len(errs) and _finite(errs[i]) and errs[i] == 0 and _finite(v) and v != 0:
                # the jackknife spread collapses at a bound of the plausible range
                err, note = "", " (at its bound: no std. error)"
            lines.append(f"{labels[i]} = {_g(v)}{err}{' ' + unit if unit else ''}{note}".rstrip())
        offset += len(vals)
    if skipped:
        lines.append(Span(f"not excited: {', '.join(skipped)}", "em"))
    return tuple(lines)


def _as_list(v: Any) -> list[Any]:
    return list(v) if isinstance(v, list | tuple) else [v]


def _metrics_table(tree: Mapping[str, Any]) -> Table:
    """Metric rows; per prediction (nominal, + effects, model [per model]) x, y, z."""
    by_model = tree.get("metrics_by_model")
    if not isinstance(by_model, list) or not by_model:
        by_model = [tree.get("metrics", {})]
    models = tree.get("models", []) or []
    cols: list[tuple[str, Mapping[str, Any]]] = [("nominal", _get(by_model[0], "nominal"))]
    for j, metrics in enumerate(by_model):
        suffix = ""
        if len(by_model) > 1:
            suffix = f" [{_get(models, j, 'name', default=f'model {j + 1}')}]"
        for key, title in PREDICTIONS[1:]:
            if _get(metrics, key) is not None:
                cols.append((title + suffix, metrics[key]))
    rows: list[list[Cell]] = []
    for key, title in METRICS:
        name = f"{title}, rad/s²" if key in ACCEL_METRICS else title
        row: list[Cell] = [name]
        for _, m in cols:
            row += [_g(v) for v in _axes_of(_get(m, key))]
        rows.append(row)
    return Table(
        columns=["metric", *(a for _ in cols for a in AXES)],
        groups=[("", 1), *((title, 3) for title, _ in cols)],
        rows=rows,
    )


def _summary_of(
    tree: Mapping[str, Any], series: Mapping[str, np.ndarray], k: int, label: str
) -> list[Block]:
    blocks: list[Block] = [Heading(3, label, f"summary-{k}")]
    logs = tree.get("logs", [])
    items: list[Content] = []
    for lg in logs:
        text = (
            f"{lg.get('name', '?')} ({lg.get('format', '?')}, {_g(lg.get('duration'))} s, "
            f"{lg.get('samples', '?')} of {lg.get('samples_total', '?')} samples used)"
        )
        items.append(("log ", Span(str(lg.get("path", lg.get("name", "?"))), "code"), ": " + text))
        for note in lg.get("notes", []) or []:
            items.append(f"note on {lg.get('name', '?')}: {note}")
    for m in tree.get("models", []) or []:
        effects = ", ".join((m.get("effects") or {}).keys()) or "none"
        items.append(
            (
                "model ",
                Span(str(m.get("path", m.get("name", "?"))), "code"),
                f": effects {effects}; GP inputs {m.get('features', '?')}; "
                f"{m.get('n_train', '?')} training points",
            )
        )
    sg = tree.get("savitzky_golay") or {}
    items.append(
        f"{int(np.asarray(series['t']).size)} samples on a {_g(tree.get('grid_rate_hz'))} Hz grid; "
        f"angular acceleration by Savitzky-Golay (window {sg.get('window', '?')}, "
        f"order {sg.get('order', '?')})"
    )
    acc = _get(tree, "units", "acceleration", default="rad/s^2")
    if _torque_unknown(tree):
        items.append(
            f"units: angular accelerations in {acc}; torques are in unknown units (the "
            "log's torque scale is not known), so parameters involving torque are shown "
            "in [torque unit] instead of N·m"
        )
    else:
        items.append(f"units: angular accelerations in {acc}, torques in N·m")
    blocks.append(Bullets(items))
    blocks.append(_metrics_table(tree))
    tracking = tree.get("tracking")
    if isinstance(tracking, Mapping):
        blocks.append(
            Table(
                columns=["tracking error", *AXES, "mean"],
                rows=[
                    [
                        "mean |a* − measured|, rad/s²",
                        *(_g(v) for v in _axes_of(tracking)),
                        _g(tracking.get("mean")),
                    ]
                ],
            )
        )
    else:
        blocks.append(Para("No desired acceleration in the logs: no tracking error.", note=True))
    by_log = tree.get("metrics_by_log") or []
    if len(by_log) > 1:
        blocks.append(
            Table(
                columns=["log", *AXES, *AXES],
                groups=[("", 1), ("nominal RMSE, rad/s²", 3), ("model RMSE, rad/s²", 3)],
                rows=[
                    [
                        str(entry.get("log", "?")),
                        *(_g(v) for v in _axes_of(_get(entry, "nominal", "rmse"))),
                        *(_g(v) for v in _axes_of(_get(entry, "model", "rmse"))),
                    ]
                    for entry in by_log
                ],
            )
        )
    return blocks


def _time_section(
    tree: Mapping[str, Any],
    series: Mapping[str, np.ndarray],
    k: int,
    label: str,
    figures: bool,
) -> list[Block]:
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
    if _finite(rate) and rate > 0:
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
                + ", ".join(f"{a} {_g(v)}" for a, v in zip(AXES, _axes_of(rmse), strict=True))
                + " rad/s²)"
            )
        png = _time_figure(series, sel, dt, f"{label} — {name}") if figures else b""
        blocks.append(
            FigureBlock(png, f"{name}: measured vs predicted angular acceleration", caption)
        )
    return blocks


def _binned_section(tree: Mapping[str, Any], k: int, label: str, figures: bool) -> list[Block]:
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


def _worst_section(tree: Mapping[str, Any], k: int, label: str) -> list[Block]:
    from omavctl.diagnose.verdict import activity

    blocks: list[Block] = [Heading(3, label, f"worst-{k}")]
    segs = tree.get("worst_segments") or []
    if not segs:
        return [*blocks, Para("No worst segments in this evaluation.", note=True)]
    rows: list[list[Cell]] = [
        [
            str(i + 1),
            str(s.get("log", "?")),
            f"{_g(s.get('start'), 3)}–{_g(s.get('end'), 3)}",
            *(_g(v, 3) for v in _axes_of(s.get("rmse"))),
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


def _flag(v: Any) -> str:
    return "yes" if v is True else "no" if v is False else "n/a"


def _ranking_table(entries: Sequence[Any], torque_unknown: bool, what: str) -> Table:
    rows: list[list[Cell]] = []
    for i, e in enumerate(entries):
        if not isinstance(e, Mapping):
            continue
        ev_axis = e.get("explained_variance_per_axis")
        per_axis = (
            Lines(tuple(f"{a} {_pct(v)}" for a, v in zip(AXES, _axes_of(ev_axis), strict=True)))
            if isinstance(ev_axis, Mapping)
            else "n/a"
        )
        name: tuple[Inline, ...] = (Span(str(e.get("name", "?")), "code"),)
        if e.get("identifiable") is False:
            name = (*name, Span(" (not identifiable)", "em"))
        missing = e.get("missing")
        rows.append(
            [
                str(i + 1),
                name,
                _pct(e.get("explained_variance")),
                per_axis,
                Lines(
                    _param_lines(e.get("parameters") or {}, e.get("units") or {}, torque_unknown)
                ),
                _g(e.get("t_value"), 3),
                _flag(e.get("significant")),
                _flag(e.get("plausible")),
                (Span(what.upper(), "strong"),) if missing is True else _flag(missing),
                ", ".join(str(x) for x in e.get("ambiguous_with", []) or []) or "–",
            ]
        )
    return Table(
        columns=[
            "#",
            "effect",
            "explained variance",
            "per axis",
            "parameters ± std. error",
            "t value",
            "significant",
            "plausible",
            what,
            "ambiguous with",
        ],
        rows=rows,
        align="rlrrrrllll",
    )


def _unexplained_items(items: Sequence[Any]) -> list[Content]:
    out: list[Content] = []
    for it in items:
        if not isinstance(it, Mapping):
            continue
        kind = str(it.get("kind", "structure"))
        axis = it.get("axis", "?")
        if kind == "feature correlation":
            out.append(
                f"axis {axis}: correlation {_g(it.get('correlation'), 3)} with feature "
                f"{it.get('feature', '?')}"
            )
        elif kind == "spectral peak":
            out.append(
                f"axis {axis}: spectral peak at {_g(it.get('frequency_hz'), 3)} Hz "
                f"({_pct(it.get('power_share'))} of the power, "
                f"{_g(it.get('power_ratio'), 3)}× the median)"
            )
        else:
            rest = ", ".join(f"{k} {_fmt_any(v)}" for k, v in it.items() if k != "kind")
            out.append(f"{kind}: {rest}")
    return out


def _fmt_any(v: Any) -> str:
    return _g(v) if isinstance(v, int | float) and not isinstance(v, bool) else str(v)


def _diagnosis_section(
    tree: Mapping[str, Any], k: int, label: str, learned_as: str | None = None
) -> list[Block]:
    blocks: list[Block] = [Heading(3, label, f"diagnosis-{k}")]
    diag = tree.get("diagnosis")
    if not isinstance(diag, Mapping):
        return [*blocks, Para("No diagnosis in this evaluation.", note=True)]
    torque_unknown = _torque_unknown(tree)
    method = diag.get("method") or {}
    if method:
        blocks.append(
            Para(
                "Every registered effect not in the model is fitted to the model's remaining "
                f"error and scored on held-out data ({method.get('split', 'held-out blocks')}; "
                f"standard errors: {method.get('standard_errors', 'n/a')}). An effect is "
                "missing when it explains at least "
                f"{_pct(method.get('min_explained_variance'))} of the held-out error, its "
                f"estimate is significant (t ≥ {_g(method.get('min_t_value'), 3)}) and "
                "physically plausible."
            )
        )
    missing = [str(x) for x in diag.get("missing", []) or []]
    if missing:
        blocks.append(
            Para(("Missing: ", *(s for name in missing for s in (Span(name, "strong"), " ")))[:-1])
        )
    else:
        blocks.append(Para("No registered effect is missing from this model."))
    entries = diag.get("missing_effects") or []
    if entries:
        blocks.append(Heading(4, "Candidate missing effects, best first"))
        blocks.append(_ranking_table(entries, torque_unknown, "missing"))
    command = diag.get("fit_command")
    if isinstance(command, str) and command:
        top = missing[0] if missing else "the top effect"
        blocks.append(Heading(4, f"Command that adds {top}"))
        blocks.append(Code(command))
    unexplained = _unexplained_items(diag.get("unexplained") or [])
    blocks.append(Heading(4, "Unexplained structure"))
    if unexplained:
        blocks.append(
            Para(
                "Structure the model's error keeps after the top missing effect, which no "
                "registered effect explains:"
            )
        )
        blocks.append(Bullets(unexplained))
    else:
        blocks.append(Para("None found (no feature correlation, no spectral peak)."))
    learned = diag.get("learned") or []
    if learned and learned_as is not None:
        blocks.append(Heading(4, "What the nominal model's residual resembles"))
        blocks.append(
            Para(
                f"Same as for {learned_as}: this ranking is fitted to the nominal model's "
                "residual on the same logs, so it does not depend on the model.",
                note=True,
            )
        )
    elif learned:
        blocks.append(Heading(4, "What the nominal model's residual resembles"))
        found = [
            str(e.get("name"))
            for e in learned
            if isinstance(e, Mapping) and e.get("missing") is True
        ]
        text = (
            "The same ranking on the nominal model's residual (measured − rigid body): which "
            "physical effects the data shows beyond the nominal model, whatever the model "
            "learned. A high rank is not proof that the effect is present: effects whose "
            "signatures look alike stand in for one another."
        )
        if found:
            text += " Resembles most: " + ", ".join(found) + "."
        blocks.append(Para(text))
        blocks.append(_ranking_table(learned, torque_unknown, "learned"))
    return blocks


def _comparison_section(evals: Sequence[Evaluation], figures: bool) -> list[Block]:
    labels = [label for _, _, label in evals]
    rmse = [
        [float(v) for v in _axes_of(_get(tree, "metrics", "model", "rmse"))] for tree, _, _ in evals
    ]
    nominal = [
        [float(v) for v in _axes_of(_get(tree, "metrics", "nominal", "rmse"))]
        for tree, _, _ in evals
    ]
    blocks: list[Block] = [
        Para(
            f"Model RMSE per axis of each evaluation file, and its change relative to the first "
            f"({labels[0]}). Nominal RMSE shows whether the files were evaluated on the same data."
        )
    ]
    logsets = [
        tuple(sorted(str(lg.get("sha256", lg.get("name"))) for lg in tree.get("logs", [])))
        for tree, _, _ in evals
    ]
    if len(set(logsets)) > 1:
        blocks.append(
            Para(
                "The evaluation files were made on different logs: the changes mix model and data.",
                note=True,
            )
        )
    rows: list[list[Cell]] = []
    for j, (tree, _, label) in enumerate(evals):
        models = tree.get("models", []) or []
        row: list[Cell] = [
            label,
            Lines(tuple(_model_title(m) for m in models)) if models else "n/a",
        ]
        for i in range(3):
            row += [
                _g(rmse[j][i]),
                "reference" if j == 0 else percent_change(rmse[j][i], rmse[0][i]),
            ]
        mean_j, mean_0 = sum(rmse[j]) / 3, sum(rmse[0]) / 3
        row += [_g(mean_j), "reference" if j == 0 else percent_change(mean_j, mean_0)]
        row += [_g(v) for v in nominal[j]]
        rows.append(row)
    blocks.append(
        Table(
            columns=[
                "evaluation",
                "models",
                *(c for a in AXES for c in ("RMSE", "change")),
                "RMSE",
                "change",
                *AXES,
            ],
            groups=[
                ("", 2),
                *((f"axis {a}, rad/s²", 2) for a in AXES),
                ("mean of axes", 2),
                ("nominal RMSE, rad/s²", 3),
            ],
            rows=rows,
            align="llrrrrrrrrrrr",
        )
    )
    return blocks


def build_document(evals: Sequence[Evaluation], figures: bool = True) -> Document:
    """The report as format-neutral blocks; ``figures`` False leaves the PNGs empty
    (for formats that cannot show them)."""
    from omavctl.report.top import figure_sections, verdict_section

    doc = Document("omavctl report")
    names = ", ".join(label for _, _, label in evals)
    doc.add(Heading(1, "omavctl report"))
    doc.add(*verdict_section(evals))
    doc.add(Para(f"Evaluation files: {names}. Angular accelerations in rad/s²."))
    sections = [
        ("verdict", "Verdict"),
        *([("figures", "What the figures show")] if figures else []),
        ("summary", "1. Summary"),
        ("time", "2. Measured vs predicted angular acceleration"),
        ("binned", "3. Residual vs feature"),
        ("worst", "4. Worst segments"),
        ("diagnosis", "5. Diagnosis"),
    ]
    if len(evals) > 1:
        sections.append(("comparison", "6. Before/after comparison"))
    doc.add(Bullets([Span(f"#{anchor}|{title}", "link") for anchor, title in sections]))
    doc.add(*figure_sections(evals, figures))
    sections = sections[2 if figures else 1 :]

    doc.add(Heading(2, sections[0][1], "summary"))
    doc.add(*_summary_overview(evals))
    for k, (tree, series, label) in enumerate(evals):
        doc.add(*_summary_of(tree, series, k, label))
    doc.add(Heading(2, sections[1][1], "time"))
    for k, (tree, series, label) in enumerate(evals):
        doc.add(*_time_section(tree, series, k, label, figures))
    doc.add(Heading(2, sections[2][1], "binned"))
    for k, (tree, _, label) in enumerate(evals):
        doc.add(*_binned_section(tree, k, label, figures))
    doc.add(Heading(2, sections[3][1], "worst"))
    for k, (tree, _, label) in enumerate(evals):
        doc.add(*_worst_section(tree, k, label))
    doc.add(Heading(2, sections[4][1], "diagnosis"))
    for k, (tree, _, label) in enumerate(evals):
        same = k > 0 and _get(tree, "diagnosis", "learned") == _get(
            evals[0][0], "diagnosis", "learned"
        )
        doc.add(*_diagnosis_section(tree, k, label, evals[0][2] if same else None))
    if len(evals) > 1:
        doc.add(Heading(2, sections[5][1], "comparison"))
        doc.add(*_comparison_section(evals, figures))
    return doc


# -------------------------------------------------------------------- HTML
CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
margin:0 auto;max-width:1240px;padding:1em 1.5em;color:#222;line-height:1.4;
overflow-wrap:break-word}
@media (max-width:900px){body{padding:.5em .8em}}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}h3{margin-top:1.5em}
div.tw{max-width:100%;overflow-x:auto}
table{border-collapse:collapse;margin:.6em 0;font-size:.85em}
th,td{border:1px solid #ccc;padding:.2em .5em;vertical-align:top;text-align:left}
th{background:#f2f2f2}td.n{text-align:right;font-variant-numeric:tabular-nums}
pre{background:#f6f6f6;border:1px solid #ddd;padding:.6em;white-space:pre-wrap;
overflow-wrap:anywhere}
code{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.95em}
figure{margin:1em 0}figure img{max-width:100%;height:auto}
figcaption{font-size:.85em;color:#555}p.note{color:#555;font-style:italic}
""".strip()


def _html_inline(c: Content) -> str:
    if isinstance(c, tuple):
        return "".join(_html_inline(x) for x in c)
    if isinstance(c, str):
        return html.escape(c)
    text = html.escape(c.text)
    if c.style == "code":
        return f"<code>{text}</code>"
    if c.style == "strong":
        return f"<strong>{text}</strong>"
    if c.style == "em":
        return f"<em>{text}</em>"
    if c.style == "link":
        anchor, _, title = c.text.partition("|")
        return f'<a href="{html.escape(anchor)}">{html.escape(title)}</a>'
    return text


def _html_cell(c: Cell) -> str:
    if isinstance(c, Lines):
        return "<br>".join(_html_inline(x) for x in c.lines)
    return _html_inline(c)


def _html_table(t: Table) -> str:
    out = ['<div class="tw"><table>']
    if t.caption:
        out.append(f"<caption>{html.escape(t.caption)}</caption>")
    out.append("<thead>")
    if t.groups:
        cells = "".join(
            f'<th colspan="{span}">{html.escape(title)}</th>'
            if span > 1
            else f"<th>{html.escape(title)}</th>"
            for title, span in t.groups
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in t.columns) + "</tr>")
    out.append("</thead><tbody>")
    for row in t.rows:
        cells = "".join(
            f'<td class="n">{_html_cell(c)}</td>' if t.right(i) else f"<td>{_html_cell(c)}</td>"
            for i, c in enumerate(row)
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


def _html(doc: Document) -> str:
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(doc.title)}</title>",
        f"<style>\n{CSS}\n</style>",
        "</head>",
        "<body>",
    ]
    for b in doc.blocks:
        if isinstance(b, Heading):
            anchor = f' id="{html.escape(b.anchor)}"' if b.anchor else ""
            parts.append(f"<h{b.level}{anchor}>{html.escape(b.text)}</h{b.level}>")
        elif isinstance(b, Para):
            cls = ' class="note"' if b.note else ""
            parts.append(f"<p{cls}>{_html_inline(b.content)}</p>")
        elif isinstance(b, Bullets):
            items = "".join(f"<li>{_html_inline(i)}</li>" for i in b.items)
            parts.append(f"<ul>{items}</ul>")
        elif isinstance(b, Table):
            parts.append(_html_table(b))
        elif isinstance(b, FigureBlock):
            data = base64.b64encode(b.png).decode("ascii")
            parts.append(
                f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(b.alt)}">'
                f"<figcaption>{html.escape(b.caption)}</figcaption></figure>"
            )
        elif isinstance(b, Code):
            parts.append(f"<pre><code>{html.escape(b.text)}</code></pre>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


# ---------------------------------------------------------------- Markdown
_MD_SPECIAL = re.compile(r"([\\`*_\[\]#|])")


def _md_text(s: str, in_table: bool = False) -> str:
    s = _MD_SPECIAL.sub(r"\\\1", html.escape(s, quote=False))
    return s.replace("\n", " ") if in_table else s


def _md_code(s: str, in_table: bool) -> str:
    fence = "``" if "`" in s else "`"
    s = s.replace("|", "\\|") if in_table else s
    return f"{fence}{s}{fence}" if fence == "`" else f"{fence} {s} {fence}"


def _md_inline(c: Content, in_table: bool = False) -> str:
    if isinstance(c, tuple):
        return "".join(_md_inline(x, in_table) for x in c)
    if isinstance(c, str):
        return _md_text(c, in_table)
    if c.style == "code":
        return _md_code(c.text, in_table)
    if c.style in ("strong", "em"):
        # emphasis markers must touch the text: keep surrounding spaces outside
        core = c.text.strip()
        lead, trail = c.text[: len(c.text) - len(c.text.lstrip())], c.text[len(c.text.rstrip()) :]
        mark = "**" if c.style == "strong" else "*"
        return f"{lead}{mark}{_md_text(core, in_table)}{mark}{trail}" if core else c.text
    if c.style == "link":
        anchor, _, title = c.text.partition("|")
        return f"[{_md_text(title)}]({anchor})"
    return _md_text(c.text, in_table)


def _md_cell(c: Cell) -> str:
    if isinstance(c, Lines):
        return "<br>".join(_md_inline(x, True) for x in c.lines)
    return _md_inline(c, True)


def _md_table(t: Table) -> str:
    columns = list(t.columns)
    if t.groups:
        titles = [title for title, span in t.groups for _ in range(span)]
        columns = [f"{g} {c}".strip() for g, c in zip(titles, columns, strict=True)]
    lines = ["| " + " | ".join(_md_text(c, True) for c in columns) + " |"]
    lines.append("|" + "|".join("---:" if t.right(i) else "---" for i in range(len(columns))) + "|")
    for row in t.rows:
        lines.append("| " + " | ".join(_md_cell(c) for c in row) + " |")
    return "\n".join(lines)


def _md(doc: Document) -> str:
    parts: list[str] = []
    for b in doc.blocks:
        if isinstance(b, Heading):
            anchor = f'<a id="{html.escape(b.anchor)}"></a>\n' if b.anchor else ""
            parts.append(f"{anchor}{'#' * b.level} {_md_text(b.text)}")
            if b.level == 1:
                parts.append(
                    "*Markdown version: the figures are only in the HTML report "
                    "(`omavctl report ... --format html`).*"
                )
        elif isinstance(b, Para):
            text = _md_inline(b.content)
            parts.append(f"*{text}*" if b.note else text)
        elif isinstance(b, Bullets):
            parts.append("\n".join(f"- {_md_inline(i)}" for i in b.items))
        elif isinstance(b, Table):
            parts.append(_md_table(b))
        elif isinstance(b, FigureBlock):
            caption = _md_text(b.caption.rstrip("."))
            parts.append(f"*Figure not available in Markdown: {caption}.*")
        elif isinstance(b, Code):
            fence = "````" if "```" in b.text else "```"
            parts.append(f"{fence}\n{b.text}\n{fence}")
    return "\n\n".join(parts) + "\n"


# ---------------------------------------------------------------------- API
def render_report(evals: Sequence[Evaluation], fmt: str = "html") -> str:
    """The report of ``evals`` (JSON tree, series, label) as an HTML or Markdown string.

    Pure: the same input gives the same string. With several evaluations the
    last section compares them (relative to the first).
    """
    if fmt not in FORMATS:
        raise OmavctlError(f"unknown report format '{fmt}' (use html or md)")
    if not evals:
        raise OmavctlError("give at least one evaluation file")
    doc = build_document(evals, figures=fmt == "html")
    return _html(doc) if fmt == "html" else _md(doc)


@dataclass
class EvaluationSummary:
    """What the terminal summary shows of one evaluation file."""

    label: str
    path: str
    model_rmse: dict[str, float]
    nominal_rmse: dict[str, float]
    missing: list[str]
    fit_command: str | None


@dataclass
class ReportSummary:
    """What :func:`write_report` wrote, for the terminal."""

    out: Path
    fmt: str
    figures: int
    evaluations: list[EvaluationSummary]
    verdict: list[Any] = field(default_factory=list)

    def change(self) -> dict[str, str]:
        """Per-axis % change of the model RMSE from the first file to the last."""
        first, last = self.evaluations[0].model_rmse, self.evaluations[-1].model_rmse
        return {a: percent_change(last[a], first[a]) for a in AXES}


def _labels(paths: Sequence[str | Path]) -> list[str]:
    names = [Path(p).name for p in paths]
    if len(set(names)) == len(names):
        return names
    return [str(p) for p in paths]


#: What rendering raises on an evaluation whose keys hold values of unexpected types
#: (files written before run ids are checked field by field, not as a whole).
_STRUCTURE_ERRORS = (TypeError, AttributeError, KeyError, IndexError, ValueError)


def _render_checked(evals: Sequence[Evaluation], fmt: str, paths: Sequence[str | Path]) -> str:
    """:func:`render_report`, naming the evaluation file whose structure it cannot read."""
    try:
        return render_report(evals, fmt)
    except _STRUCTURE_ERRORS:
        culprit = paths[0]
        for ev, p in zip(evals, paths, strict=True):
            try:
                render_report([ev], "md")
            except _STRUCTURE_ERRORS:
                culprit = p
                break
        raise OmavctlError(
            "not an evaluation JSON this omavctl can read: a key holds a value of another type",
            culprit,
        ) from None


def write_report(
    paths: Sequence[str | Path], out: str | Path, fmt: str | None = None
) -> ReportSummary:
    """Load the evaluation files, render the report and write it atomically to ``out``.

    ``fmt`` None follows ``out``'s suffix (.md -> Markdown, else HTML).
    """
    from omavctl.diagnose.evalio import series_path

    out = Path(out)
    fmt = format_from_suffix(out) if fmt is None else fmt
    if fmt not in FORMATS:
        raise OmavctlError(f"unknown report format '{fmt}' (use html or md)")
    if not paths:
        raise OmavctlError("give at least one evaluation file")
    if not (out.parent if str(out.parent) else Path(".")).is_dir():
        raise OmavctlError("output directory does not exist", out.parent)
    inputs = {Path(p).resolve() for p in paths} | {series_path(p).resolve() for p in paths}
    if out.resolve() in inputs:
        raise OmavctlError("the report would overwrite one of its inputs", out)
    loaded = [load_for_report(p) for p in paths]
    labels = _labels(paths)
    evals = [(tree, series, label) for (tree, series), label in zip(loaded, labels, strict=True)]
    text = _render_checked(evals, fmt, paths)
    with atomic_path(out) as tmp:
        tmp.write_bytes(text.encode("utf-8"))
    summaries = [
        EvaluationSummary(
            label=label,
            path=str(p),
            model_rmse={a: float(tree["metrics"]["model"]["rmse"][a]) for a in AXES},
            nominal_rmse={a: float(tree["metrics"]["nominal"]["rmse"][a]) for a in AXES},
            missing=[str(x) for x in _get(tree, "diagnosis", "missing", default=[]) or []],
            fit_command=_get(tree, "diagnosis", "fit_command"),
        )
        for (tree, _, label), p in zip(evals, paths, strict=True)
    ]
    from omavctl.diagnose.verdict import report_verdict

    lines = report_verdict([(tree, label) for tree, _, label in evals])
    return ReportSummary(out, fmt, text.count("data:image/png;base64,"), summaries, lines)
