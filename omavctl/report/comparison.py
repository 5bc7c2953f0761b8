"""Section 6 of the report (several evaluation files): the before/after comparison.

Model RMSE per axis of each file and its change from the first, the mean over
the axes, and the nominal RMSE that shows whether the files saw the same data.
"""

from __future__ import annotations

from collections.abc import Sequence

from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.document import Block, Cell, Lines, Para, Table
from omavctl.report.load import Evaluation
from omavctl.report.numfmt import AXES, axes_of, num, percent_change
from omavctl.report.overview import model_title

__all__ = ["comparison_section"]


def comparison_section(evals: Sequence[Evaluation], figures: bool) -> list[Block]:
    """Model RMSE per axis and its mean per evaluation, with the % change from the first
    file, and the nominal RMSE (a note when the files were made on different logs)."""
    labels = [label for _, _, label in evals]
    rmse = [
        [float(v) for v in axes_of(_get(tree, "metrics", "model", "rmse"))] for tree, _, _ in evals
    ]
    nominal = [
        [float(v) for v in axes_of(_get(tree, "metrics", "nominal", "rmse"))]
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
            Lines(tuple(model_title(m) for m in models)) if models else "n/a",
        ]
        for i in range(3):
            row += [
                num(rmse[j][i]),
                "reference" if j == 0 else percent_change(rmse[j][i], rmse[0][i]),
            ]
        mean_j, mean_0 = sum(rmse[j]) / 3, sum(rmse[0]) / 3
        row += [num(mean_j), "reference" if j == 0 else percent_change(mean_j, mean_0)]
        row += [num(v) for v in nominal[j]]
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
