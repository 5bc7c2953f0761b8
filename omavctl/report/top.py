"""The top of the report: the verdict, then the figures that explain it.

Verdict sentences (:func:`omavctl.diagnose.change.report_verdict`), then per evaluation
file the model error over time with the worst segments labelled, the signature
of each named effect, the candidate effects' explained variance, and with
several files the before/after bars.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.change import report_verdict
from omavctl.diagnose.joint_text import named_later
from omavctl.report import figures as rf
from omavctl.report.comparison import model_rows
from omavctl.report.document import Block, Bullets, Content, FigureBlock, Heading, Inline, Span
from omavctl.report.load import Evaluation

__all__ = ["figure_sections", "verdict_section"]


def verdict_section(evals: Sequence[Evaluation]) -> list[Block]:
    """The verdict, as the first lines of the report."""
    lines = report_verdict([(tree, label) for tree, _, label in evals])
    titles = {
        "missing": "What is missing",
        "learned": "Not modelled as physics",
        "disagree": "Fit and flight disagree",
        "pinned_here": "Pinned down here, not by the fit flight",
        "unconfirmed": "Not confirmed by either flight",
        "axis": "Held back on one axis",
        "change": "Error change",
        "fails": "Where it fails",
        "uncertainty": "Uncertainty",
        "horizons": "Open loop",
        "envelope": "Outside the training inputs",
        "excluded": "Excluded",
        "flag": "Warning",
        "training": "Not held out",
        "underexcited": "Not excited by the fit flight",
        "mismatch": "Model and log",
        "worse": "No help",
    }
    commands = [
        c
        for tree, _, _ in evals
        if isinstance(c := (tree.get("diagnosis") or {}).get("separate_command"), str) and c
    ]
    items: list[Content] = []
    for ln in lines:
        # the sentences say what they are about; the bold head says which file(s)
        head = ln.who or titles.get(ln.key, ln.key)
        lead, sep, rest = ln.text.partition(": ")
        words = lead.lower().split()
        # a sentence that opens with its own head is not titled twice ("What is
        # missing: Missing: ...", "Uncertainty: Uncertainty can be trusted: ...")
        if (
            not ln.who
            and sep
            and len(lead) <= 60
            and words
            and (words[0] in head.lower() or "missing" in words)
        ):
            head, text = lead, rest
        else:
            text = ln.text
        parts: tuple[Inline, ...] = (Span(f"{head}: ", "strong"), *_with_code(text, commands))
        if _is_pointer(ln.key, ln.text):
            parts = _with_code(ln.text, commands)
        if ln.command:
            parts = (*parts, f" {ln.add_words}: ", Span(ln.command, "code"))
        items.append(parts)
    return [Heading(2, "Verdict", "verdict"), Bullets(items)]


def _is_pointer(key: str, text: str) -> bool:
    """The sentence that says which model the lines after it are about: no bold head
    (it is filed with the change lines, and "Error change: The lines below are about
    gp.npz" read as a change)."""
    return key == "change" and text.startswith("The lines below are about ")


def _with_code(text: str, commands: Sequence[str]) -> tuple[Inline, ...]:
    """``text`` with each of ``commands`` in it set in code font, and a full stop after
    one that ends the sentence (so that "Add it with:" does not run on from it)."""
    for cmd in commands:
        at = text.find(cmd)
        if at >= 0:
            tail = text[at + len(cmd) :]
            return (text[:at], Span(cmd, "code"), *(_with_code(tail, commands) if tail else (".",)))
    return (text,)


def _dt(tree: Mapping[str, Any], t: np.ndarray) -> float:
    rate = tree.get("grid_rate_hz")
    if isinstance(rate, int | float) and rate > 0:
        return 1.0 / float(rate)
    return float(np.median(np.diff(t))) if t.size > 1 else 1.0


def _error_blocks(
    tree: Mapping[str, Any], series: Mapping[str, np.ndarray], label: str, figures: bool
) -> list[Block]:
    t = np.asarray(series["t"], float)
    log_id = np.asarray(series["log"]).astype(int)
    err = (
        np.asarray(series["measured"], float)
        - np.asarray(series["nominal"], float)
        - np.asarray(series["mean_0"], float)
    )
    std = np.asarray(series["std_0"], float)
    segs = [
        {**s, "rank": k + 1}
        for k, s in enumerate(tree.get("worst_segments") or [])
        if isinstance(s, Mapping)
    ]
    out: list[Block] = []
    for i, lg in enumerate(tree.get("logs") or []):
        sel = np.flatnonzero(log_id == i)
        if sel.size == 0:
            continue
        name = str(lg.get("name", f"log {i}"))
        mine = [s for s in segs if s.get("log") == name]
        data = (
            rf.error_figure(t[sel], err[sel], std[sel], mine, _dt(tree, t), f"{label} — {name}")
            if figures
            else b""
        )
        out.append(
            FigureBlock(
                data,
                f"{name}: model error over time with the worst segments",
                f"{label}, {name}: model error (measured − predicted angular acceleration) "
                "per axis, the grey band the model's own ±2σ; the worst segments are shaded "
                "and numbered with what the vehicle was doing.",
            )
        )
    return out


def _signature_blocks(
    tree: Mapping[str, Any], series: Mapping[str, np.ndarray], label: str, figures: bool
) -> list[Block]:
    diag = tree.get("diagnosis") or {}
    entries = {str(e.get("name")): e for e in diag.get("missing_effects") or []}
    err = (
        np.asarray(series["measured"], float)
        - np.asarray(series["nominal"], float)
        - np.asarray(series["mean_0"], float)
    )
    out: list[Block] = []
    for key in sorted(k for k in series if k.startswith("contribution_")):
        name = key.removeprefix("contribution_")
        per_axis = entries.get(name, {}).get("explained_variance_per_axis")
        status = _signature_status(diag, name)
        data = (
            rf.signature_figure(
                np.asarray(series[key], float),
                err,
                name,
                per_axis if isinstance(per_axis, Mapping) else None,
                f"{label}: signature of {name} ({status})",
            )
            if figures
            else b""
        )
        if data is None:
            continue
        out.append(
            FigureBlock(
                data,
                f"signature of {name}",
                f"{label}: the model's error against the part of it {name} explains as the "
                "diagnosis fitted it (its regressor times the estimate in the diagnosis "
                "table, rad/s²), per axis, with the least-squares line through the origin "
                "and bin means: slope 1 is the effect at the estimated size, a flat cloud "
                "says it is not there.",
            )
        )
    return out


def _signature_status(diag: Mapping[str, Any], name: str) -> str:
    """What the verdict says of the effect whose signature is shown, in a few words."""
    if name in (diag.get("missing") or []):
        return "missing"
    if name in (diag.get("learned_claims") or []):
        return "learned by the GP, claimed"
    if any(isinstance(e, Mapping) and e.get("name") == name for e in diag.get("not_pinned") or []):
        return "not claimed: not pinned down"
    return "not claimed"


def _candidates_blocks(tree: Mapping[str, Any], label: str, figures: bool) -> list[Block]:
    diag = tree.get("diagnosis") or {}
    entries = [e for e in diag.get("missing_effects") or [] if isinstance(e, Mapping)]
    if not entries:
        return []
    threshold = (diag.get("method") or {}).get("min_explained_variance")
    thr = float(threshold) if isinstance(threshold, int | float) else None
    later = {name: words for name, (words, _) in named_later(diag).items()}
    data = rf.candidates_figure(entries, thr, later) if figures else b""
    return [
        FigureBlock(
            data,
            "explained variance of the candidate effects",
            f"{label}: how much of the model's remaining error each registered effect "
            "explains on held-out blocks (bar: all axes, ticks: per axis); hatched bars are "
            "ambiguous (their contributions look alike)"
            + (
                f"; {', '.join(later)} claimed by a later selection step (section 5)."
                if later
                else "."
            ),
        )
    ]


def figure_sections(evals: Sequence[Evaluation], figures: bool) -> list[Block]:
    """The figures under the verdict (none for formats without figures)."""
    if not figures:
        return []
    blocks: list[Block] = [Heading(2, "What the figures show", "figures")]
    if len(evals) > 1:
        rows = model_rows(evals)  # a row per model of a file that holds several
        labels, rmse = [r[1] for r in rows], [r[3] for r in rows]
        data = rf.before_after_figure(labels, rmse) if figures else b""
        blocks.append(
            FigureBlock(
                data,
                "model RMSE per axis before and after",
                "Model RMSE per axis per evaluation file (per model where a file holds several), "
                "with the change from the first; "
                "each axis on its own scale.",
            )
        )
    for tree, series, label in evals:
        blocks.append(Heading(3, label, None))
        blocks += _error_blocks(tree, series, label, figures)
        blocks += _signature_blocks(tree, series, label, figures)
        blocks += _candidates_blocks(tree, label, figures)
    return blocks
