"""An output replaces only a file of the kind its command writes (omavctl/base/replace.py):
``fit --out flight.bag`` replaced a recorded flight with a model and exited 0, as did
``evaluate --out``, ``report --out`` and ``plan --report`` onto any file (a new user's
trial, 2026-11-27). Each is now refused with one line before any work, the file left as
it was; the command's own earlier output is still replaced."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from omavctl.base.replace import is_mcap_from, is_report_file
from omavctl.cli import app
from omavctl.diagnose.evalio import is_evaluation_file, is_series_file
from omavctl.learn.run import is_model_file
from omavctl.planning.report import is_scores_file
from omavctl.report.series_mcap import is_series_mcap

runner = CliRunner()


def _ok(args: list[str]) -> None:
    result = runner.invoke(app, [*args, "-q"])
    assert result.exit_code == 0, result.output


def _evaluate(d: Path) -> None:
    """``held.bag`` evaluated with ``m.npz`` into ``e.json`` (no horizons: not tested here)."""
    model, out = str(d / "m.npz"), str(d / "e.json")
    _ok(["evaluate", str(d / "held.bag"), "--model", model, "--out", out, "--horizons", "none"])


@pytest.fixture(scope="module")
def flown(tmp_path_factory) -> Path:
    """A 4 s figure-8, flown into an MCAP log and a ROS 1 bag, a model fitted on the
    first, evaluated on the second and reported: every kind of output once."""
    d = tmp_path_factory.mktemp("replace")
    _ok(["task", "fig8", "--duration", "4", "--ramp", "1", "--out", str(d / "fig8.csv")])
    for log, seed in (("fit.mcap", "1"), ("held.bag", "2")):
        _ok(["simulate", "-r", str(d / "fig8.csv"), "--seed", seed, "-o", str(d / log)])
    _ok(["fit", str(d / "fit.mcap"), "--out", str(d / "m.npz"), "--points", "40"])
    _evaluate(d)
    _ok(["report", str(d / "e.json"), "--out", str(d / "r.html")])
    _ok(["report", str(d / "e.json"), "--out", str(d / "r.md")])
    return d


def test_each_output_is_recognised_as_its_kind_and_nothing_else(flown):
    d = flown
    kinds = {
        is_model_file: "m.npz",
        is_evaluation_file: "e.json",
        is_series_file: "e.series.npz",
        is_series_mcap: "e.series.mcap",
        is_report_file: ("r.html", "r.md"),
    }
    files = ["fig8.csv", "fit.mcap", "m.npz", "e.json", "e.series.npz", "e.series.mcap", "r.html"]
    for ours, names in kinds.items():
        names = (names,) if isinstance(names, str) else names
        for f in [*files, "r.md"]:
            assert ours(d / f) == (f in names), (ours.__name__, f)
    # simulate's MCAP log is no series MCAP: the same library, the ros2 profile
    assert is_mcap_from(d / "fit.mcap", "omavctl", "ros2")
    assert not is_scores_file(d / "fig8.csv")


@pytest.mark.parametrize(
    ("option", "target", "what"),
    [
        ("fit", "held.bag", "an omavctl model"),
        ("fit", "fig8.csv", "an omavctl model"),
        ("fit", "e.json", "an omavctl model"),
        ("evaluate", "held.bag", "an omavctl evaluation"),
        ("evaluate", "m.npz", "an omavctl evaluation"),
        ("--mcap", "fit.mcap", "an evaluation's series MCAP"),
        ("report", "fig8.csv", "an omavctl report"),
        ("report", "e.json", "an omavctl report"),
        ("--report", "fig8.csv", "an omavctl report"),
        ("--scores", "fig8.csv", "a plan's scores CSV"),
    ],
)
def test_an_output_onto_another_kind_of_file_is_refused_and_the_file_kept(
    flown, tmp_path, option, target, what
):
    d = flown
    victim = tmp_path / ("x" + Path(target).suffix)
    victim.write_bytes((d / target).read_bytes())
    before = victim.read_bytes()
    args = {
        "fit": ["fit", str(d / "fit.mcap"), "--out", str(victim)],
        "evaluate": ["evaluate", str(d / "held.bag"), "--model", str(d / "m.npz")],
        "--mcap": ["evaluate", str(d / "held.bag"), "--model", str(d / "m.npz")],
        "report": ["report", str(d / "e.json"), "--out", str(victim)],
        "--report": ["plan", "--task", str(d / "fig8.csv"), "--model", str(d / "m.npz")],
        "--scores": ["plan", "--task", str(d / "fig8.csv"), "--model", str(d / "m.npz")],
    }[option]
    if option == "evaluate":
        args += ["--out", str(victim)]
    elif option == "--mcap":
        args += ["--out", str(tmp_path / "new.json"), "--mcap", str(victim)]
    elif option.startswith("--"):
        args += ["--out", str(tmp_path / "next.csv"), option, str(victim)]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert result.output.strip() == (
        f"error: {victim}: exists and is not {what}; choose another name (or remove it)"
    )
    assert victim.read_bytes() == before
    assert not (tmp_path / "new.json").exists() and not (tmp_path / "next.csv").exists()


def test_a_commands_own_earlier_output_is_replaced(flown):
    d = flown
    stamps = {n: (d / n).stat().st_mtime_ns for n in ("m.npz", "e.json", "r.md")}
    _ok(["fit", str(d / "fit.mcap"), "--out", str(d / "m.npz"), "--points", "30"])
    _evaluate(d)
    _ok(["report", str(d / "e.json"), "--out", str(d / "r.md")])
    assert all((d / n).stat().st_mtime_ns != t for n, t in stamps.items())
    assert is_model_file(d / "m.npz") and is_report_file(d / "r.md")
