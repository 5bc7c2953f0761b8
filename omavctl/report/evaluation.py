"""Render evaluation files (``omavctl evaluate`` output) as one report.

The report is a single self-contained HTML file: figures are embedded as
base64 PNG (matplotlib, Agg, fixed size and dpi, no metadata that changes
between runs), the CSS is inline, and nothing refers to the network. The same
inputs give the same bytes. ``--format md`` renders the same content as
Markdown (tables; the figures are left out and say so).

Sections, per evaluation file where that applies:

0. the verdict and the figures that explain it (:mod:`omavctl.report.top`);
1. summary: logs, models, samples, per-axis metrics of the nominal model,
   nominal + fitted effects and the full model; tracking error; units
   (:mod:`omavctl.report.overview`);
2. measured vs predicted angular acceleration over time, with a +-2 sigma band;
3. residual vs feature (binned mean and RMS) for the model and the nominal model;
4. the worst time windows (2-4: :mod:`omavctl.report.residuals`);
5. the diagnosis: the ranking of candidate missing effects, the effects named
   missing, unexplained structure, the ``omavctl fit`` command that adds the
   top effect, and what the GP has learned in physical terms
   (:mod:`omavctl.report.diagnosis`);
6. open-loop prediction over horizons: error against the horizon per predictor,
   the band's coverage, with several files side by side (:mod:`omavctl.report.horizons`);
7. with several files: model RMSE per axis before/after, % change from the first
   (:mod:`omavctl.report.comparison`).

The document is first built as a list of format-neutral blocks (headings,
paragraphs, tables, figures, code; :mod:`omavctl.report.document`) and then
written out as HTML or Markdown, so both formats carry the same content. Every
string that comes from an evaluation file is escaped. This module assembles the
sections and writes the report; :mod:`omavctl.report.load` reads and checks
the evaluation files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omavctl.base.atomic import atomic_path
from omavctl.base.errors import OmavctlError
from omavctl.diagnose.verdict import get_path as _get
from omavctl.report.comparison import comparison_section
from omavctl.report.diagnosis import diagnosis_section
from omavctl.report.document import Bullets, Document, Heading, Para, Span, to_html, to_markdown
from omavctl.report.horizons import horizons_section
from omavctl.report.load import Evaluation, load_for_report
from omavctl.report.numfmt import AXES, relative_change
from omavctl.report.overview import overview_table, summary_of
from omavctl.report.residuals import binned_section, time_section, worst_section
from omavctl.report.top import figure_sections, verdict_section

__all__ = [
    "FORMATS",
    "EvaluationSummary",
    "ReportSummary",
    "build_document",
    "format_from_suffix",
    "render_report",
    "write_report",
]

#: Output formats of :func:`render_report`.
FORMATS = ("html", "md")


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


def build_document(evals: Sequence[Evaluation], figures: bool = True) -> Document:
    """The report as format-neutral blocks; ``figures`` False leaves the PNGs empty
    (for formats that cannot show them)."""
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
        ("horizons", "6. Prediction over horizons"),
    ]
    if len(evals) > 1:
        sections.append(("comparison", "7. Before/after comparison"))
    doc.add(Bullets([Span(f"#{anchor}|{title}", "link") for anchor, title in sections]))
    doc.add(*figure_sections(evals, figures))
    sections = sections[2 if figures else 1 :]

    doc.add(Heading(2, sections[0][1], "summary"))
    doc.add(*overview_table(evals))
    for k, (tree, series, label) in enumerate(evals):
        doc.add(*summary_of(tree, series, k, label))
    doc.add(Heading(2, sections[1][1], "time"))
    for k, (tree, series, label) in enumerate(evals):
        doc.add(*time_section(tree, series, k, label, figures))
    doc.add(Heading(2, sections[2][1], "binned"))
    for k, (tree, _, label) in enumerate(evals):
        doc.add(*binned_section(tree, k, label, figures))
    doc.add(Heading(2, sections[3][1], "worst"))
    for k, (tree, _, label) in enumerate(evals):
        doc.add(*worst_section(tree, k, label))
    doc.add(Heading(2, sections[4][1], "diagnosis"))
    for k, (tree, _, label) in enumerate(evals):
        same = k > 0 and _ranking(tree) == _ranking(evals[0][0])
        doc.add(*diagnosis_section(tree, k, label, evals[0][2] if same else None))
    doc.add(Heading(2, sections[5][1], "horizons"))
    doc.add(*horizons_section(evals, figures))
    if len(evals) > 1:
        doc.add(Heading(2, sections[6][1], "comparison"))
        doc.add(*comparison_section(evals, figures))
    return doc


def _ranking(tree: Mapping[str, Any]) -> Any:
    """The diagnosis's ``learned`` ranking without each effect's ``estimate`` (made with
    the model's effects alongside, so it differs between models of one log)."""
    learned = _get(tree, "diagnosis", "learned")
    if not isinstance(learned, list):
        return learned
    return [
        {k: v for k, v in e.items() if k != "estimate"} if isinstance(e, Mapping) else e
        for e in learned
    ]


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
    return to_html(doc) if fmt == "html" else to_markdown(doc)


@dataclass
class EvaluationSummary:
    """What the terminal summary shows of one evaluation file."""

    label: str
    path: str
    model_rmse: dict[str, float]
    nominal_rmse: dict[str, float]
    missing: list[str]
    fit_command: str | None
    #: each ``--model``'s RMSE per axis, in the file's order (one entry for one model)
    models_rmse: list[dict[str, float]] = field(default_factory=list)
    #: each ``--model``'s file name, in the same order
    model_names: list[str] = field(default_factory=list)

    def _several(self) -> bool:
        return len(self.models_rmse) > 1

    def _named(self) -> bool:
        return self._several() and len(self.model_names) == len(self.models_rmse)

    def first_model(self) -> dict[str, float]:
        """The first ``--model``'s RMSE per axis (the file's model RMSE)."""
        return self.models_rmse[0] if self._several() else self.model_rmse

    def last_model(self) -> dict[str, float]:
        """The last ``--model``'s RMSE per axis (the file's, for one model)."""
        return self.models_rmse[-1] if self._several() else self.model_rmse

    def first_label(self) -> str:
        return f"{self.label}: {self.model_names[0]}" if self._named() else self.label

    def last_label(self) -> str:
        return f"{self.label}: {self.model_names[-1]}" if self._named() else self.label


@dataclass
class ReportSummary:
    """What :func:`write_report` wrote, for the terminal."""

    out: Path
    fmt: str
    figures: int
    evaluations: list[EvaluationSummary]
    verdict: list[Any] = field(default_factory=list)

    def change(self) -> dict[str, float | None] | None:
        """Per-axis relative change of the model RMSE from the first file's first model
        to the last file's last model (a file that holds several ``--model`` counts its
        last: a new user's ``report base.json both.json``, both.json evaluated with the
        base model and the one with the lag, said +0.0 % on every axis), as a fraction
        (-0.141: 14.1 % lower); None where undefined, and None in all for one file of
        one model."""
        if not self.evaluations:
            return None
        first, last = self.evaluations[0].first_model(), self.evaluations[-1].last_model()
        if len(self.evaluations) == 1 and len(self.evaluations[0].models_rmse) < 2:
            return None
        return {a: relative_change(last[a], first[a]) for a in AXES}

    def change_labels(self) -> tuple[str, str]:
        """What :meth:`change` compares: the first file (its first model's name where it
        holds several) and the last (its last model's)."""
        return self.evaluations[0].first_label(), self.evaluations[-1].last_label()


def _models_rmse(tree: Mapping[str, Any]) -> list[dict[str, float]]:
    """Each ``--model``'s model RMSE per axis (``metrics_by_model``); [] when the file
    has none or a value is not a number."""
    try:
        return [
            {a: float(m["model"]["rmse"][a]) for a in AXES}
            for m in tree.get("metrics_by_model") or []
        ]
    except (KeyError, TypeError, ValueError):
        return []


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
            models_rmse=_models_rmse(tree),
            model_names=[str(_get(m, "name", default="?")) for m in tree.get("models") or []],
        )
        for (tree, _, label), p in zip(evals, paths, strict=True)
    ]
    from omavctl.diagnose.change import report_verdict

    lines = report_verdict([(tree, label) for tree, _, label in evals])
    return ReportSummary(out, fmt, text.count("data:image/png;base64,"), summaries, lines)
