"""Section 1 of the report, the summary: what was evaluated and how well.

An overview table (one row per evaluation file: logs, models, samples, nominal
and model RMSE per axis, the top missing effect), then per file its logs and
models, the grid and units, the metrics of every prediction (nominal, nominal +
effects, model) per axis, the tracking error and the RMSE per log.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.diagnosis import fitted_effect_items, spread_legend
from omavctl.report.document import Block, Bullets, Cell, Content, Heading, Lines, Para, Span, Table
from omavctl.report.load import Evaluation
from omavctl.report.numfmt import AXES, axes_of, force_unit_unknown, num, torque_unit_unknown

__all__ = ["ACCEL_METRICS", "METRICS", "PREDICTIONS", "model_title", "overview_table", "summary_of"]


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
    ("r2", "R² (share of the nominal error removed)"),
    ("mean_std", "mean predicted std"),
    ("coverage_2sigma", "within 2σ (fraction)"),
    ("nlpd", "NLPD (nats/sample)"),
)
#: Metrics in rad/s^2 (the others are dimensionless or nats).
ACCEL_METRICS = {"rmse", "mae", "mean_std"}
#: Metrics of a predictive band: shown for the models only (the nominal and nominal +
#: effects predictions have none; their JSON entries use the GP's prior std).
BAND_METRICS = {"mean_std", "coverage_2sigma", "nlpd"}


def overview_table(evals: Sequence[Evaluation]) -> list[Block]:
    """One table, a row per evaluation: its logs, models, number of samples, nominal and
    model RMSE per axis and the top missing effect."""
    rows: list[list[Cell]] = []
    for tree, series, label in evals:
        logs = tree.get("logs", [])
        models = tree.get("models", [])
        missing = _get(tree, "diagnosis", "missing", default=[]) or []
        # one row per --model: its own RMSE (the first model's stood beside both names)
        for k, (model, metrics) in enumerate(per_model(tree)):
            shown = [model] if model is not None else models
            top: Cell = "none" if not missing else (Span(str(missing[0]), "code"),)
            rows.append(
                [
                    label,
                    Lines(tuple(str(_get(lg, "name", default="?")) for lg in logs)),
                    Lines(tuple(model_title(m) for m in shown)) if shown else "n/a",
                    str(int(np.asarray(series["t"]).size)),
                    *(num(v) for v in axes_of(_get(tree, "metrics", "nominal", "rmse"))),
                    *(num(v) for v in axes_of(_get(metrics, "model", "rmse"))),
                    top if k == 0 else "",  # the diagnosis is the first model's
                ]
            )
    return [
        Table(
            columns=[
                "evaluation",
                "logs",
                "models",
                "samples",
                *AXES,
                *AXES,
                "diagnosis: top missing",
            ],
            groups=[("", 4), ("nominal RMSE, rad/s²", 3), ("model RMSE, rad/s²", 3), ("", 1)],
            rows=rows,
            align="lllrrrrrrrl",
        )
    ]


def per_model(tree: Mapping[str, Any]) -> list[tuple[Any, Any]]:
    """(model entry, its metrics) per ``--model`` of an evaluation file that holds several
    with their ``metrics_by_model``; else one (None, the file's ``metrics``)."""
    models, by_model = tree.get("models") or [], tree.get("metrics_by_model") or []
    if len(models) > 1 and len(by_model) == len(models):
        return list(zip(models, by_model, strict=True))
    return [(None, tree.get("metrics"))]


def model_title(m: Mapping[str, Any]) -> str:
    """'name (effect, effect)' of a model entry of an evaluation JSON."""
    effects = list((m.get("effects") or {}).keys())
    eff = ", ".join(effects) if effects else "no effects"
    return f"{m.get('name', '?')} ({eff})"


def _metrics_table(tree: Mapping[str, Any]) -> Table:
    """Metric rows; per prediction (nominal, + effects, model [per model]) x, y, z."""
    by_model = tree.get("metrics_by_model")
    if not isinstance(by_model, list) or not by_model:
        by_model = [tree.get("metrics", {})]
    models = tree.get("models", []) or []
    cols: list[tuple[str, Mapping[str, Any]]] = [("nominal", _get(by_model[0], "nominal"))]
    zero = _get(by_model[0], "zero")
    if isinstance(zero, Mapping):  # RMSE only: the error of predicting no acceleration
        cols.insert(0, ("zero (no acceleration)", zero))
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
        for col, m in cols:
            if key in BAND_METRICS and not col.startswith("model"):
                row += ["–"] * 3  # no band of its own (the JSON holds the GP prior's)
            else:
                row += [num(v) for v in axes_of(_get(m, key))]
        rows.append(row)
        if key == "r2" and isinstance(zero, Mapping):
            rows.append(_signal_r2_row(cols, zero))
    return Table(
        columns=["metric", *(a for _ in cols for a in AXES)],
        groups=[("", 1), *((title, 3) for title, _ in cols)],
        rows=rows,
    )


def _signal_r2_row(
    cols: Sequence[tuple[str, Mapping[str, Any]]], zero: Mapping[str, Any]
) -> list[Cell]:
    """R² against the measured signal, 1 - (RMSE / RMS of the angular acceleration)²,
    per prediction and axis: the share of the measurement explained. The R² above is
    against the nominal model, which can look good where the nominal model is far
    worse than predicting no acceleration (a new user read 0.81 on an axis the
    verdict called no better than predicting none)."""
    row: list[Cell] = ["R² (share of the measured acceleration explained)"]
    for _, m in cols:
        for a, z in zip(AXES, axes_of(_get(zero, "rmse")), strict=True):
            r = _get(m, "rmse", a)
            ok = isinstance(r, int | float) and isinstance(z, int | float) and z > 0
            row.append(num(1.0 - (float(r) / float(z)) ** 2) if ok else "–")
    return row


def _units_unknown(tree: Mapping[str, Any]) -> tuple[bool, bool]:
    """Whether the evaluation's torque and force commands are in unknown units."""
    return torque_unit_unknown(tree), force_unit_unknown(tree)


def _model_items(tree: Mapping[str, Any]) -> list[Content]:
    """Per model its file, effects, GP inputs and fitted parameters; then what their
    "± spread" means where one shows it."""
    items: list[Content] = []
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
        items += fitted_effect_items(m.get("effects") or {}, *_units_unknown(tree))
    items += spread_legend(
        [p for m in tree.get("models") or [] for p in (m.get("effects") or {}).values()]
    )
    return items


def summary_of(
    tree: Mapping[str, Any], series: Mapping[str, np.ndarray], k: int, label: str
) -> list[Block]:
    """The summary of evaluation ``k`` (``label``): its logs and models, grid and units,
    the metrics table, the tracking error and the RMSE per log. ``series`` maps names to
    arrays of one row per sample (``t``: (n,)); only the number of samples is shown."""
    blocks: list[Block] = [Heading(3, label, f"summary-{k}")]
    logs = tree.get("logs", [])
    items: list[Content] = []
    for lg in logs:
        text = (
            f"{lg.get('name', '?')} ({lg.get('format', '?')}, {num(lg.get('duration'))} s, "
            f"{lg.get('samples', '?')} of {lg.get('samples_total', '?')} samples used)"
        )
        items.append(("log ", Span(str(lg.get("path", lg.get("name", "?"))), "code"), ": " + text))
        for note in lg.get("notes", []) or []:
            items.append(f"note on {lg.get('name', '?')}: {note}")
    items += _model_items(tree)
    sg = tree.get("savitzky_golay") or {}
    items.append(
        f"{int(np.asarray(series['t']).size)} samples on a "
        f"{num(tree.get('grid_rate_hz'))} Hz grid; "
        f"angular acceleration by Savitzky-Golay (window {sg.get('window', '?')}, "
        f"order {sg.get('order', '?')})"
    )
    acc = _get(tree, "units", "acceleration", default="rad/s^2")
    if torque_unit_unknown(tree):
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
                        "mean |a* − measured| of the flight's own controller, rad/s²",
                        *(num(v) for v in axes_of(tracking)),
                        num(tracking.get("mean")),
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
                        *(num(v) for v in axes_of(_get(entry, "nominal", "rmse"))),
                        *(num(v) for v in axes_of(_get(entry, "model", "rmse"))),
                    ]
                    for entry in by_log
                ],
            )
        )
    return blocks
