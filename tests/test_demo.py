"""The demo pipeline of examples/Makefile (make demo) on short flights, through the CLI.

task -> simulate -> fit -> simulate another trajectory -> evaluate -> report ->
fit --effects (the effect the diagnosis names) -> evaluate -> report with both
evaluations -> plan. Same truth file and log kinds as the demo; 8 s flights,
40 training points and a tiny plan so that it runs in seconds.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omavctl.cli import app

ROOT = Path(__file__).resolve().parent.parent
TRUTH = ROOT / "examples" / "truth-drag.yaml"
HIDDEN = "rotational_drag"

runner = CliRunner()


def omavctl(command: str, b: Path):
    """Run one omavctl command line; ``{b}`` in a word is the demo folder, ``{truth}`` the
    demo's truth file. Fails the test with the command's output on a non-zero exit;
    returns the runner's result."""
    args = [w.format(b=b, truth=TRUTH) for w in command.split()]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, f"omavctl {command}:\n{result.output}"
    return result


PIPELINE = """
task fig8 --roll 26 --pitch 26 --period 4 --duration 8 --ramp 1 --out {b}/fig8.csv -q
task fig8 --roll 20 --pitch 30 --period 3 --duration 8 --ramp 1 --out {b}/fig8-other.csv -q
simulate --reference {b}/fig8.csv --truth {truth} --seed 1 --out {b}/flight-01 -q
simulate --reference {b}/fig8-other.csv --truth {truth} --seed 2 --out {b}/flight-02.bag -q
fit {b}/flight-01 --effects rotor_interference --points 40 --restarts 1 --out {b}/gp.npz -q
evaluate {b}/flight-02.bag --model {b}/gp.npz --out {b}/eval.json -q
report {b}/eval.json --out {b}/report-first.html -q
fit {b}/flight-01 --effects rotor_interference,rotational_drag --points 40 --restarts 1
    --out {b}/gp-drag.npz -q
evaluate {b}/flight-02.bag --model {b}/gp-drag.npz --out {b}/eval-drag.json -q
report {b}/eval.json {b}/eval-drag.json --out {b}/report.html -q
plan --task {b}/fig8.csv --model {b}/gp-drag.npz --candidates 2 --sims 1 --test-points 100
    --scores {b}/scores.csv --report {b}/plan.html --out {b}/informative.csv --json -q
"""


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> Path:
    """The demo's folder after the whole pipeline (first flight a ROS 2 bag directory,
    held-out flight a ROS 1 bag, as in examples/Makefile); the plan's --json in
    plan.json, as the Makefile writes it (one plan, not a second one for the JSON)."""
    b = tmp_path_factory.mktemp("demo")
    for command in PIPELINE.replace("\n    --", " --").strip().splitlines():
        result = omavctl(command, b)
    (b / "plan.json").write_text(result.stdout)  # the last command: plan --json
    return b


def test_diagnosis_names_the_hidden_effect(demo):
    diag = json.loads((demo / "eval.json").read_text())["diagnosis"]
    assert diag["missing"][:1] == [HIDDEN]
    # with the thrust spread's look-alike when the held-out flight confirms it
    assert set(diag["missing"]) <= {HIDDEN, "com_offset"}
    words = diag["fit_command"].split()
    added = ",".join(diag["missing"])
    assert words[words.index("--effects") + 1] == f"rotor_interference,{added}"
    first = (demo / "report-first.html").read_text()
    assert 'id="diagnosis"' in first and HIDDEN in first


def test_adding_the_effect_removes_it_and_lowers_the_error(demo):
    before = json.loads((demo / "eval.json").read_text())
    after = json.loads((demo / "eval-drag.json").read_text())
    assert HIDDEN in after["models"][0]["effects"]
    assert HIDDEN not in after["diagnosis"]["missing"]

    def mean_rmse(tree: dict) -> float:
        return sum(tree["metrics"]["model"]["rmse"][a] for a in "xyz") / 3

    assert mean_rmse(after) < mean_rmse(before)


def test_report_compares_both_evaluations(demo):
    html = (demo / "report.html").read_text()
    assert html.startswith("<!DOCTYPE html>") or html.lstrip().lower().startswith("<!doctype")
    assert 'id="comparison"' in html and "Before/after comparison" in html
    assert "eval.json" in html and "eval-drag.json" in html
    assert "http://" not in html and "https://" not in html  # self-contained


def test_plan_writes_the_next_reference(demo):
    header = (demo / "informative.csv").read_text().splitlines()[0]
    assert header.startswith("t,x,y,z,roll,pitch,yaw")
    rows = (demo / "scores.csv").read_text().splitlines()
    assert rows[0].startswith("candidate,") and len(rows) == 3
    plan = (demo / "plan.html").read_text()
    assert plan.count("data:image/png;base64,") == 2 and "Most informative reference" in plan


def test_the_signature_figure_plots_what_the_diagnosis_scores(demo):
    """The series holds the named effect's fitted part of the model's error (rad/s²),
    and the error follows it with slope ~1 on the axis the diagnosis says it explains."""
    import numpy as np

    from omavctl.report.figures import signature_slopes

    tree = json.loads((demo / "eval.json").read_text())
    series = np.load(demo / "eval.series.npz")
    part = series[f"contribution_{HIDDEN}"]
    error = series["measured"] - series["nominal"] - series["mean_0"]
    entry = next(e for e in tree["diagnosis"]["missing_effects"] if e["name"] == HIDDEN)
    per_axis = entry["explained_variance_per_axis"]
    top = max("xyz", key=lambda a: per_axis[a])
    assert per_axis[top] > 0.3
    assert 0.8 < signature_slopes(part, error)["xyz".index(top)] < 1.25


def test_the_getting_started_numbers_tool_reads_the_demo_outputs(demo):
    """tools/demo_numbers.py computes every value docs/getting-started.md quotes from
    the demo's files (here the short pipeline's): the page's markers all get one."""
    import importlib.util

    assert "best_cost" in json.loads((demo / "plan.json").read_text())
    spec = importlib.util.spec_from_file_location(
        "demo_numbers", ROOT / "tools" / "demo_numbers.py"
    )
    assert spec is not None and spec.loader is not None
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    values = tool.numbers(demo)
    doc = (ROOT / "docs" / "getting-started.md").read_text()
    assert {m[1] for m in tool.MARKER.finditer(doc)} == set(values)
    assert values["verdict"].startswith(f"\n```text\nMissing: {HIDDEN} — it explains ")
    # the verdict's own words: "add them with" when it names more than one effect
    words = "add them with" if " Also: " in values["verdict"] else "add it with"
    assert f"  {words}: omavctl fit {demo}/flight-01 --effects " in values["verdict"]
    assert values["fall"].endswith(" %") and values["plan_cem"].endswith(("better", "worse"))
