"""Section 6 of the report (several evaluation files): the before/after comparison.

Model RMSE per axis of each file's models (one row per ``--model``) and its change from
the first file's first model, the mean over the axes, and the nominal RMSE that shows
whether the files saw the same data.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.document import Block, Cell, Lines, Para, Table
from omavctl.report.load import Evaluation
from omavctl.report.numfmt import AXES, axes_of, num, percent_change
from omavctl.report.overview import model_title, per_model

__all__ = ["comparison_section", "model_rows"]


Row = tuple[int, str, list[Mapping[str, Any]], list[float]]


def model_rows(evals: Sequence[Evaluation]) -> list[Row]:
    """(the file's index in ``evals``, the row's label, models shown, model RMSE per
    axis) per ``--model`` of each file, in order: a file evaluated with several models
    gives one row each (``metrics_by_model``; "file: model" labels), else one row with
    its models. A new user's ``report
    base.json both.json``, both.json evaluated with the base model and the one with the
    effect, showed both.json's first model only, +0.0 % on every axis, while the
    terminal's change line read the last one's -52 %."""
    rows: list[Row] = []
    for k, (tree, _, label) in enumerate(evals):
        for model, metrics in per_model(tree):
            rmse = [float(v) for v in axes_of(_get(metrics, "model", "rmse"))]
            if model is None:  # one row for the file, beside all its models
                rows.append((k, label, list(tree.get("models") or []), rmse))
            else:
                rows.append((k, f"{label}: {model.get('name', '?')}", [model], rmse))
    return rows


def comparison_section(evals: Sequence[Evaluation], figures: bool) -> list[Block]:
    """Model RMSE per axis and its mean per evaluation file's model, with the % change
    from the first row, and the file's nominal RMSE (a note when the files were made on
    different logs)."""
    labels = [label for _, _, label in evals]
    nominal = [
        [float(v) for v in axes_of(_get(tree, "metrics", "nominal", "rmse"))]
        for tree, _, _ in evals
    ]
    blocks: list[Block] = [
        Para(
            f"Model RMSE per axis of each evaluation file (a row per model where it holds "
            f"several), and its change relative to the first ({labels[0]}). Nominal RMSE "
            "shows whether the files were evaluated on the same data."
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
    table = model_rows(evals)
    first = table[0][3]
    rows: list[list[Cell]] = []
    for j, (owner, _, models, rmse) in enumerate(table):
        row: list[Cell] = [
            labels[owner],
            Lines(tuple(model_title(m) for m in models)) if models else "n/a",
        ]
        for i in range(3):
            row += [num(rmse[i]), "reference" if j == 0 else percent_change(rmse[i], first[i])]
        mean_j, mean_0 = sum(rmse) / 3, sum(first) / 3
        row += [num(mean_j), "reference" if j == 0 else percent_change(mean_j, mean_0)]
        row += [num(v) for v in nominal[owner]]
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
