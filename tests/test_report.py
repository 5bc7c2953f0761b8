"""omavctl report: a self-contained HTML report (and Markdown) of evaluation files, made
here from short simulated flights: valid HTML with embedded figures and no network
references, the summary and diagnosis tables, the before/after comparison, determinism,
the CLI and its one-line errors."""

from __future__ import annotations

import base64
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.base.errors import OmavctlError
from omavctl.cli import app
from omavctl.diagnose.evalio import write_evaluation
from omavctl.diagnose.evaluate import evaluate
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.logs import write_log
from omavctl.report.evaluation import render_report, write_report
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree

runner = CliRunner()

#: A hidden effect in the truth plant; the first model lacks it, the second has it.
HIDDEN = {"rotational_drag": {"D": [0.03, 0.03, 0.02]}}
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "wbr"}


@pytest.fixture(scope="module")
def evals(tmp_path_factory, vehicle) -> Path:
    """Two evaluation files of one held-out flight: a model without the hidden effect
    (before.json) and one that estimates it (after.json)."""
    d = tmp_path_factory.mktemp("report")
    truth = truth_from_tree({"seed": 1, "effects": HIDDEN}, vehicle)
    train = simulate(fig8(20, 20, 4.0, 8.0, ramp=1.0), vehicle, truth, seed=0).log
    held = simulate(fig8(15, 25, 5.0, 8.0, ramp=1.0), vehicle, truth, seed=1).log
    write_log(d / "train.csv", train, topics=vehicle.topics)
    write_log(d / "held <out>.mcap", held, topics=vehicle.topics)
    # the plant's rotor interference is known physics (as in the demo): the hidden
    # drag is then what the diagnosis names
    known = ["rotor_interference"]
    for name, effects in (("before", known), ("after", [*known, "rotational_drag"])):
        fit = fit_model(
            [d / "train.csv"], vehicle, effects=effects, points=40, restarts=0, features="wrench"
        )
        save_model(d / f"{name}.npz", fit.model)
        write_evaluation(d / f"{name}.json", evaluate([d / f"{name}.npz"], [d / "held <out>.mcap"]))
    return d


class Structure(HTMLParser):
    """Collects start tags and the errors of an unbalanced document."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.tags: list[str] = []
        self.errors: list[str] = []
        self.srcs: list[str] = []
        self.ids: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        a = dict(attrs)
        if a.get("src") is not None:
            self.srcs.append(a["src"] or "")
        if a.get("id"):
            self.ids.append(a["id"] or "")
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
        else:
            self.stack.pop()


def parse(text: str) -> Structure:
    p = Structure()
    p.feed(text)
    p.close()
    return p


def table_after(text: str, anchor: str) -> str:
    """The first <table> after the element with id ``anchor``."""
    start = text.index(f'id="{anchor}"')
    return text[text.index("<table>", start) : text.index("</table>", start)]


def _signatures(path) -> int:
    """Effect-signature figures of an evaluation: one per missing effect (the fit
    command adds them together), else the top candidate's."""
    diag = json.loads(path.read_text())["diagnosis"]
    return len(diag["missing"]) or min(1, len(diag["missing_effects"]))


@pytest.fixture(scope="module")
def single(evals, tmp_path_factory):
    """before.json's HTML report, rendered once: checked, and compared with a second
    rendering for determinism (each rendering takes seconds: its figures)."""
    out = tmp_path_factory.mktemp("single") / "report.html"
    return out, write_report([evals / "before.json"], out)


def test_single_report_is_valid_self_contained_html(evals, single):
    out, summary = single
    text = out.read_text(encoding="utf-8")
    doc = parse(text)
    assert doc.errors == [] and doc.stack == []
    assert doc.tags.count("html") == 1 and doc.tags.count("body") == 1
    assert text.startswith("<!DOCTYPE html>")
    # figures: error over time with the worst segments, the signature of each missing
    # effect, the candidates' explained variance; measured vs predicted for the one log;
    # model and nominal residual vs feature; the error against the horizon
    n = 6 + _signatures(evals / "before.json")
    pngs = [s for s in doc.srcs if s.startswith("data:image/png;base64,")]
    assert len(pngs) == len(doc.srcs) == summary.figures == n
    assert text.count("data:image/png;base64,") == n
    assert base64.b64decode(pngs[0].split(",", 1)[1]).startswith(b"\x89PNG\r\n\x1a\n")
    # nothing fetched from anywhere
    for bad in ("http://", "https://", 'src="//', "<script", "<link", "@import", "url("):
        assert bad not in text.lower(), bad
    # the summary: model RMSE of the JSON, logs and units
    tree = json.loads((evals / "before.json").read_text())
    summary_table = table_after(text, "summary")
    for axis in "xyz":
        assert f"{tree['metrics']['model']['rmse'][axis]:.4g}" in summary_table
    assert "held &lt;out&gt;.mcap" in text and "held <out>" not in text  # escaped
    assert "torques in N·m" in text or "torques are in unknown units" in text
    assert {"summary", "time", "binned", "worst", "diagnosis"} <= set(doc.ids)
    assert "comparison" not in doc.ids
    # the diagnosis ranking: every candidate effect, the hidden one first and missing
    diag = tree["diagnosis"]
    ranking = table_after(text, "diagnosis-0")
    assert len(re.findall(r"<tr>", ranking)) == 1 + len(diag["missing_effects"])
    for entry in diag["missing_effects"]:
        assert f"<code>{entry['name']}</code>" in ranking
    assert diag["missing"][:1] == ["rotational_drag"]
    assert "MISSING" in ranking and "D_x = " in ranking
    import html

    assert f"<pre><code>{html.escape(diag['fit_command'])}</code></pre>" in text
    assert "What the nominal model&#x27;s residual resembles" in text


def test_two_file_report_compares(evals, tmp_path):
    out = tmp_path / "both.html"
    files = [evals / "before.json", evals / "after.json"]
    summary = write_report(files, out)
    text = out.read_text(encoding="utf-8")
    assert parse(text).errors == []
    assert 'id="comparison"' in text
    comparison = text[text.index('id="comparison"') :]
    figures = text[text.index('id="figures"') : text.index('id="summary"')]
    assert 'alt="model RMSE per axis before and after"' in figures  # the bar figure
    table = comparison[comparison.index("<table>") : comparison.index("</table>")]
    before, after = (json.loads(f.read_text())["metrics"]["model"]["rmse"] for f in files)
    for axis in "xyz":
        change = 100 * (after[axis] - before[axis]) / before[axis]
        assert f"{change:+.1f} %" in table
        assert summary.change()[axis] == pytest.approx(change / 100, rel=1e-12)
    # the hidden effect drives x and y: adding it makes the error fall there
    assert after["x"] < before["x"] and after["y"] < before["y"]
    # the before/after bars + 2 evaluations x (error over time, effect signatures,
    # candidates; measured vs predicted, 2 binned; error against the horizon)
    assert summary.figures == 1 + 2 * 6 + sum(_signatures(f) for f in files)
    # the horizon tables side by side, the full model's error falls at every horizon
    horizons = text[text.index('id="horizons"') : text.index('id="comparison"')]
    assert "The files side by side" in horizons
    rows = [json.loads(f.read_text())["horizons"]["table"]["model"] for f in files]
    for b, a in zip(*rows, strict=True):
        assert a["rate_error"]["norm"] < b["rate_error"]["norm"]
    # the verdict comes first: the missing effect and the % change per axis
    first = _text_lines(text)[:6]
    assert first[0] == "omavctl report" and first[1] == "Verdict"
    head = " ".join(first[2:5])
    assert "Missing: rotational_drag" in head
    assert "With rotational_drag added" in head and "falls by" in head
    for axis in "xyz":
        change = 100 * (after[axis] / before[axis] - 1)
        assert f"{axis} {change:+.1f} %".replace("-", "−") in head
    # the nominal residual's ranking does not depend on the model: shown once
    assert text.count("Same as for before.json") == 1


def _text_lines(html_text: str) -> list[str]:
    """The visible text of an HTML document, one line per block element."""
    body = html_text[html_text.index("<body>") :]
    body = re.sub(r"</(h[1-6]|p|li|tr|figcaption|pre)>", "\n", body)
    body = re.sub(r"<[^>]+>", "", body)
    import html as html_mod

    return [ln.strip() for ln in html_mod.unescape(body).splitlines() if ln.strip()]


def test_markdown_and_determinism(evals, single, tmp_path):
    write_report([evals / "before.json"], tmp_path / "b.html")
    assert single[0].read_bytes() == (tmp_path / "b.html").read_bytes()
    files = [evals / "before.json", evals / "after.json"]
    summary = write_report(files, tmp_path / "r.md")
    assert summary.fmt == "md" and summary.figures == 0
    md = (tmp_path / "r.md").read_text(encoding="utf-8")
    write_report(files, tmp_path / "r2.txt", fmt="md")
    assert (tmp_path / "r2.txt").read_text(encoding="utf-8") == md
    assert "data:image" not in md and "<table" not in md
    assert "Figure not available in Markdown" in md
    assert "| evaluation | logs |" in md and "`rotational_drag`" in md
    assert "## 7. Before/after comparison" in md
    tree = json.loads(files[0].read_text())
    assert f"```\n{tree['diagnosis']['fit_command']}\n```" in md
    assert "held &lt;out&gt;.mcap" in md


def test_render_report_escapes_and_handles_unknown_torque_units(evals):
    from omavctl.diagnose.evalio import load_evaluation

    tree, series = load_evaluation(evals / "before.json")
    tree["units"]["torque"] = "unknown"
    tree["logs"][0]["name"] = '<img src="https://x">'
    text = render_report([(tree, series, "a<b>")], "html")
    assert '<img src="https' not in text and "a&lt;b&gt;" in text
    assert "&lt;img src=&quot;https://x&quot;&gt;" in text
    assert "torques are in unknown units" in text
    with pytest.raises(OmavctlError, match="unknown report format"):
        render_report([(tree, series, "a")], "pdf")


def _error_line(result) -> str:
    text = result.output.strip()
    assert result.exit_code == 2, text
    assert "Traceback" not in text and len(text.splitlines()) == 1, text
    return text


def test_report_json_gives_the_change_as_numbers(evals, tmp_path):
    """`report --json`'s change per axis was a string ("-14.1 %"): a fraction now, null
    (never NaN) where the first file's error is not a positive number."""
    files = [evals / "before.json", evals / "after.json"]
    ok = runner.invoke(app, ["report", *map(str, files), "--out", str(tmp_path / "r.md"), "--json"])
    assert ok.exit_code == 0, ok.output
    change = json.loads(ok.stdout)["change"]
    before, after = (json.loads(f.read_text())["metrics"]["model"]["rmse"] for f in files)
    assert change == {a: pytest.approx(after[a] / before[a] - 1.0, rel=1e-12) for a in "xyz"}
    assert f"x {100 * change['x']:+.1f} %" in ok.stderr  # the terminal's line unchanged
    from omavctl.cli.report import _report_json
    from omavctl.report.evaluation import EvaluationSummary, ReportSummary

    def ev(x: float) -> EvaluationSummary:
        return EvaluationSummary("e", "e.json", {"x": x, "y": 1.0, "z": 2.0}, {}, [], None)

    summary = ReportSummary(tmp_path / "r.md", "md", 0, [ev(0.0), ev(0.5)])
    text = json.dumps(_report_json(summary, summary.out), allow_nan=False)
    assert json.loads(text)["change"] == {"x": None, "y": 0.0, "z": 0.0}
    # one file evaluated with two --model: the change from its first model to its last
    # (it was null while the verdict printed the change; docs/real-data-check.md item 17)
    two = EvaluationSummary("e", "e.json", {"x": 2.0, "y": 1.0, "z": 2.0}, {}, [], None)
    two.models_rmse = [{"x": 2.0, "y": 1.0, "z": 2.0}, {"x": 1.0, "y": 1.5, "z": 2.0}]
    one = ReportSummary(tmp_path / "r.md", "md", 0, [two])
    assert _report_json(one, one.out)["change"] == {"x": -0.5, "y": 0.5, "z": 0.0}
    # a file of one model, then one of two (base.json, both.json): from the first file's
    # model to the last file's last model (it compared both.json's first model, the
    # same base model, with itself: +0.0 % on every axis)
    base = EvaluationSummary("base.json", "base.json", {"x": 2.0, "y": 1.0, "z": 2.0}, {}, [], None)
    two.label, two.model_names = "both.json", ["base.npz", "lag.npz"]
    pair = ReportSummary(tmp_path / "r.md", "md", 0, [base, two])
    assert _report_json(pair, pair.out)["change"] == {"x": -0.5, "y": 0.5, "z": 0.0}
    assert pair.change_labels() == ("base.json", "both.json: lag.npz")
    two.models_rmse = two.models_rmse[:1]
    assert _report_json(one, one.out)["change"] is None


def test_cli(evals, tmp_path):
    out = tmp_path / "cli.html"
    ok = runner.invoke(
        app, ["report", str(evals / "before.json"), str(evals / "after.json"), "--out", str(out)]
    )
    assert ok.exit_code == 0, ok.output
    assert out.is_file() and "wrote" in ok.output and "change" in ok.output
    assert "diagnosis: top missing" in " ".join(ok.output.split())
    # before.json lacks the hidden effect: the summary gives the command that adds it
    md = tmp_path / "cli.md"
    ok = runner.invoke(app, ["report", str(evals / "before.json"), "--out", str(md)])
    assert ok.exit_code == 0, ok.output
    assert "to add rotational_drag" in ok.output and "omavctl fit" in ok.output
    assert md.read_text(encoding="utf-8").startswith("# omavctl report")
    quiet = runner.invoke(
        app, ["report", str(evals / "after.json"), "--out", str(out), "--format", "md", "-q"]
    )
    assert quiet.exit_code == 0 and quiet.output == ""
    assert out.read_text(encoding="utf-8").startswith("# omavctl report")

    bad = tmp_path / "bad.html"
    missing = tmp_path / "nothere.json"
    line = _error_line(runner.invoke(app, ["report", str(missing), "--out", str(bad)]))
    assert line == f"error: {missing}: file not found"
    other = tmp_path / "model.json"
    other.write_text(json.dumps({"schema": "omavctl.model/1"}))
    line = _error_line(runner.invoke(app, ["report", str(other), "--out", str(bad)]))
    assert line == (
        f"error: {other}: schema 'omavctl.model/1' is not supported (expected omavctl.eval/1)"
    )
    # right schema, wrong content; and a JSON whose series file is gone
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({"schema": "omavctl.eval/1", "series": {"file": "x.npz"}}))
    line = _error_line(runner.invoke(app, ["report", str(broken), "--out", str(bad)]))
    assert line == f"error: {broken}: its time series file x.npz is missing"
    tree = json.loads((evals / "before.json").read_text())
    tree["series"]["file"] = "before.series.npz"
    moved = tmp_path / "moved.json"
    moved.write_text(json.dumps(tree))
    line = _error_line(runner.invoke(app, ["report", str(moved), "--out", str(bad)]))
    assert line == f"error: {moved}: its time series file before.series.npz is missing"
    (tmp_path / "moved.series.npz").write_bytes((evals / "before.series.npz").read_bytes())
    tree["series"]["file"] = "moved.series.npz"
    del tree["metrics"]["model"]
    moved.write_text(json.dumps(tree))
    line = _error_line(runner.invoke(app, ["report", str(moved), "--out", str(bad)]))
    assert line == (
        f"error: {moved}: changed after evaluate wrote it (its content does not match its "
        "run id): run evaluate again"
    )
    # a file without run id and content hash (older omavctl) is checked field by field
    del tree["series"]["sha256"], tree["series"]["run_id"]
    moved.write_text(json.dumps(tree))
    line = _error_line(runner.invoke(app, ["report", str(moved), "--out", str(bad)]))
    assert line == f"error: {moved}: not an evaluation JSON: no number at 'metrics.model.rmse.x'"
    # the report never overwrites its inputs
    before = (evals / "before.json").read_bytes()
    line = _error_line(
        runner.invoke(
            app, ["report", str(evals / "before.json"), "--out", str(evals / "before.json")]
        )
    )
    assert line.endswith("output would overwrite the input; choose another name")
    assert (evals / "before.json").read_bytes() == before
    # no output (nor temporary file) left behind by any failure
    assert not bad.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    # a format that does not exist is refused, naming those that do
    pdf = tmp_path / "report.pdf"
    line = _error_line(
        runner.invoke(app, ["report", str(evals / "before.json"), "--out", str(pdf)])
    )
    assert line == (
        f"error: {pdf}: cannot write a '.pdf' report: the formats are html (.html) and md (.md) "
        "(or choose one with --format)"
    )
    assert not pdf.exists()


def test_report_names_a_model_file_or_a_json_summary_given_for_an_evaluation(tmp_path):
    """A new user passed the model (.npz) and the piped --json summary to report and read
    "it is not UTF-8 text" and "no 'schema' key"; nothing is written."""
    model = tmp_path / "gp.npz"
    np.savez(model, a=np.zeros(2))
    summary = tmp_path / "stdout.json"
    summary.write_text(json.dumps({"command": "evaluate", "exit_code": 0, "metrics": {}}))
    out = tmp_path / "r.html"
    line = _error_line(runner.invoke(app, ["report", str(model), "--out", str(out)]))
    assert line == (
        f"error: {model}: not an evaluation JSON: a NumPy .npz archive (a model or a series "
        "file); report reads the JSON that `omavctl evaluate --out FILE.json` writes"
    )
    line = _error_line(runner.invoke(app, ["report", str(summary), "--out", str(out)]))
    assert line == (
        f"error: {summary}: not an evaluation JSON: the --json summary `omavctl evaluate` "
        "prints; report reads the file that `omavctl evaluate --out FILE.json` writes"
    )
    assert not out.exists()
