"""Scripting the CLI: --json on stdout, tables that do not wrap in pipes, evaluate's
default output, a fit command that runs as printed from another directory, the MCAP
series on the log's own stamps, argument names in --help."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.logs import read_raw

ROOT = Path(__file__).resolve().parent.parent
TRUTH = ROOT / "examples" / "truth-drag.yaml"
runner = CliRunner()


def _run(args: list[str], cwd: Path | None = None) -> tuple[str, str]:
    """Invoke omavctl in-process (optionally from ``cwd``); returns (stdout, stderr)."""
    old = Path.cwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        result = runner.invoke(app, args)
    finally:
        os.chdir(old)
    assert result.exit_code == 0, f"omavctl {' '.join(args)}:\n{result.output}"
    return result.stdout, result.stderr


def _one_json(stdout: str) -> dict:
    lines = [ln for ln in stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, stdout
    obj = json.loads(lines[0])
    assert isinstance(obj, dict)
    assert "NaN" not in lines[0] and "Infinity" not in lines[0]
    return obj


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """A project folder: logs in logs/ (a ROS 1 bag with a hidden drag and a held-out
    MCAP), a model fitted from the folder with relative paths."""
    w = tmp_path_factory.mktemp("work")
    (w / "logs").mkdir()
    (w / "models").mkdir()
    for args in (
        "task fig8 --roll 26 --pitch 26 --period 4 --duration 8 --ramp 1 --out logs/a.csv -q",
        "task fig8 --roll 20 --pitch 30 --period 3 --duration 8 --ramp 1 --out logs/b.csv -q",
        f"simulate -r logs/a.csv --truth {TRUTH} --seed 1 --out logs/train.bag -q",
        f"simulate -r logs/b.csv --truth {TRUTH} --seed 2 --out logs/held.mcap -q",
    ):
        _run(shlex.split(args), cwd=w)
    stdout, _ = _run(
        shlex.split(
            "fit logs/train.bag --effects rotor_interference --points 40 --restarts 0 "
            "--out models/gp.npz --json"
        ),
        cwd=w,
    )
    fit = _one_json(stdout)
    assert fit["files"] == {"model": "models/gp.npz"}
    assert set(fit["axes"]) == {"x", "y", "z"} and fit["points"] == 40
    # the held-out verdict per axis, for a script to act on
    for axis in fit["axes"].values():
        coverage = axis["held_out_coverage_2sigma_before_widening"]
        assert isinstance(axis["gp_on"], bool) and 0.0 <= coverage <= 1
        assert axis["held_out_rmse_gp"] > 0 and axis["held_out_rmse_physics"] > 0
        assert axis["std_factor"] >= 1 and axis["beyond_scale"] >= (0.5 if axis["gp_on"] else 0)
    # the band inside the fit inputs, as the model file holds it
    with np.load(w / "models/gp.npz", allow_pickle=False) as z:
        assert [a["band_scale"] for a in fit["axes"].values()] == pytest.approx(z["band_scale"])
        assert [a["band_slope"] for a in fit["axes"].values()] == pytest.approx(z["band_slope"])
    return w


def test_inspect_pipes_into_grep(work):
    """A real pipe: stdout is not a terminal, each topic stays on one line (its type and
    rate beside it on the row grep finds). (One run: the listing captured before the
    pipe checked the same row, and a second Python start pays for the closed-pipe test.)"""
    env = {**os.environ, "COLUMNS": "60"}
    grep = subprocess.run(  # pipefail: inspect's own status too
        f"set -o pipefail; {shlex.quote(sys.executable)} -m omavctl inspect logs/train.bag "
        "| grep /omav/wrench_command",
        shell=True,
        executable="/bin/bash",
        cwd=work,
        capture_output=True,
        text=True,
        env=env,
    )
    rows = grep.stdout.splitlines()
    assert grep.returncode == 0 and len(rows) == 1, grep.stdout
    assert "geometry_msgs/msg/WrenchStamped" in rows[0] and "100.0" in rows[0]


def test_a_reader_that_closes_the_pipe_is_not_a_failure(work):
    """``omavctl inspect LOG | head -2`` exited 1, silently (rich's
    Console.on_broken_pipe): a real pipe whose reader is gone before the first write
    (head after two lines, as surely): exit 0, nothing on stderr."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "omavctl", "inspect", "logs/train.bag"],
        cwd=work,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the only reader of the child's stdout: its writes fail (EPIPE)
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0 and err == b""


def test_a_closed_stderr_pipe_silences_the_console_and_the_command_goes_on(monkeypatch):
    """The human text goes to stderr (``evaluate ... 2>&1 | head -1``): once its reader
    is gone, what is left goes nowhere, without an exception or an exit."""
    from omavctl.cliout import console

    read, write = os.pipe()
    os.close(read)
    stream = os.fdopen(write, "w")
    monkeypatch.setattr(sys, "stderr", stream)
    con = console()
    con.print("the verdict")  # EPIPE: rich called on_broken_pipe, which did not exit
    con.print("and the rest")
    assert con.quiet
    stream.write("a later write and the flush at exit go to /dev/null\n")
    stream.flush()
    monkeypatch.undo()
    stream.close()


def test_inspect_json(work):
    stdout, stderr = _run(["inspect", "logs/train.bag", "--json"], cwd=work)
    obj = _one_json(stdout)
    names = {t["name"] for t in obj["topics"]}
    assert "/omav/wrench_command" in names and obj["format"] == "ros1"
    assert obj["required_missing"] == []
    assert "/omav/wrench_command" in stderr  # the human listing moved to stderr


def test_evaluate_default_out_json_and_fit_command_from_a_subdirectory(work):
    sub = work / "analysis"
    sub.mkdir()
    stdout, stderr = _run(
        ["evaluate", "../logs/held.mcap", "--model", "../models/gp.npz", "--json"], cwd=sub
    )
    obj = _one_json(stdout)
    # no --out: beside the model, and it says where
    assert obj["files"]["evaluation"] == "../models/gp.eval.json"
    assert (work / "models" / "gp.eval.json").is_file()
    assert (work / "models" / "gp.eval.series.npz").is_file()
    assert "wrote ../models/gp.eval.json" in stderr
    assert stderr.lstrip().startswith("verdict")
    # the drag, with the thrust spread's look-alike when the held-out flight confirms it
    assert obj["missing"][:1] == ["rotational_drag"]
    assert set(obj["missing"]) <= {"rotational_drag", "com_offset"}
    assert obj["verdict"][0]["key"] == "missing"
    assert set(obj["models"][0]["rmse"]) == {"x", "y", "z"}
    # the printed command runs as printed from here, adds every missing effect in one
    # fit, and writes beside the model
    command = obj["fit_command"]
    added = ",".join(obj["missing"])
    assert command.startswith(
        f"omavctl fit ../logs/train.bag --effects rotor_interference,{added} "
    )
    words = shlex.split(command)
    out = _run([*words[1:], "--restarts", "0", "-q"], cwd=sub)
    assert out == ("", "")
    assert (work / "models" / f"gp+{'+'.join(obj['missing'])}.npz").is_file()


def test_fit_command_is_shell_quoted(work, tmp_path):
    odd = tmp_path / "my flights"
    odd.mkdir()
    (odd / "train it.bag").write_bytes((work / "logs" / "train.bag").read_bytes())
    _run(["fit", str(odd / "train it.bag"), "--effects", "rotor_interference", "--points", "30",
          "--restarts", "0", "--out", str(odd / "m 1.npz"), "-q"])  # fmt: skip
    stdout, _ = _run(
        ["evaluate", str(work / "logs" / "held.mcap"), "--model", str(odd / "m 1.npz"), "--json"]
    )
    obj = _one_json(stdout)
    command = obj["fit_command"]
    if command:  # the diagnosis may or may not name the drag from 30 points
        words = shlex.split(command)
        stem = f"m 1+{'+'.join(obj['missing'])}.npz"
        # valid from the directory evaluate ran in (relative when it is near, absolute
        # when a relative path would climb to /)
        assert any(Path(w).resolve() == (odd / "train it.bag").resolve() for w in words), words
        assert str(odd / stem) in words or any(w.endswith(stem) for w in words)


def test_several_models_side_by_side(work):
    _run(
        shlex.split(
            "fit logs/train.bag --effects rotor_interference,rotational_drag --points 40 "
            "--restarts 0 "
            "--out models/drag.npz -q"
        ),
        cwd=work,
    )
    stdout, stderr = _run(
        shlex.split(
            "evaluate logs/held.mcap -m models/gp.npz -m models/drag.npz --out both.json --json"
        ),
        cwd=work,
    )
    obj = _one_json(stdout)
    assert [m["path"] for m in obj["models"]] == ["models/gp.npz", "models/drag.npz"]
    assert "gp.npz: model" in stderr and "drag.npz: model" in stderr
    change = [v["text"] for v in obj["verdict"] if v["key"] == "change"]
    assert change and change[0].startswith("With rotational_drag added")


def test_mcap_series_on_the_logs_stamps(work):
    from mcap.reader import make_reader

    _run(
        shlex.split("evaluate logs/held.mcap -m models/gp.npz --out e.json --mcap s.mcap -q"),
        cwd=work,
    )
    tree = json.loads((work / "e.json").read_text())
    with np.load(work / "e.series.npz") as data:
        n = data["t"].size
    with (work / "s.mcap").open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {
            "/omavctl/measured",
            "/omavctl/nominal",
            "/omavctl/physics",
            "/omavctl/predicted",
            "/omavctl/band_2sigma",
            "/omavctl/worst_segments",
        }
        for c in channels.values():
            assert c.message_encoding == "json"
            schema = summary.schemas[c.schema_id]
            assert schema.encoding == "jsonschema" and json.loads(schema.data)["type"] == "object"
        stamps: dict[str, list[int]] = {}
        first: dict[str, dict] = {}
        for _, channel, message in reader.iter_messages():
            stamps.setdefault(channel.topic, []).append(message.log_time)
            first.setdefault(channel.topic, json.loads(message.data))
    assert len(stamps["/omavctl/measured"]) == n
    assert set(first["/omavctl/measured"]) == {"x", "y", "z"}
    assert {"x_low", "x_high"} <= set(first["/omavctl/band_2sigma"])
    assert len(stamps["/omavctl/worst_segments"]) == 2 * len(tree["worst_segments"])
    # on the log's own clock: every stamp is a stamp of the log's IMU, to 1 us
    raw = read_raw(work / "logs" / "held.mcap")
    imu = np.round((raw.t0 + raw.series["body_rate"].stamps) * 1e6).astype(np.int64)
    ours = np.round(np.array(stamps["/omavctl/measured"]) / 1e3).astype(np.int64)
    assert np.isin(ours, imu).all()
    assert ours.min() > 1e15  # epoch microseconds, not seconds from the start


@pytest.mark.parametrize(
    "args",
    [
        ["task", "yaw", "--out", "t.csv"],
        ["simulate", "-r", "logs/a.csv", "--out", "s.csv", "--seed", "3"],
        ["report", "e.json", "--out", "r.html"],
    ],
)
def test_json_everywhere(work, args):
    if args[0] == "report" and not (work / "e.json").exists():
        _run(shlex.split("evaluate logs/held.mcap -m models/gp.npz --out e.json -q"), cwd=work)
    stdout, _ = _run([*args, "--json"], cwd=work)
    obj = _one_json(stdout)
    assert obj["command"].split()[0] == args[0]
    for path in obj["files"].values():
        assert (work / path).exists()


def test_every_command_has_json_and_named_arguments():
    root = typer.main.get_command(app)
    paths = [("task", n) for n in root.commands["task"].commands] + [  # type: ignore[attr-defined]
        (n,) for n in root.commands if n != "task"
    ]
    assert len(paths) == 14  # 8 tasks (fig8 ... wobble, chirp, steps) and 6 other commands
    for path in paths:
        text = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "100"}).output
        assert "--json" in text, path
        assert "<list[Path]>" not in text and "list[" not in text, path
    assert "LOG..." in runner.invoke(app, ["fit", "--help"]).output
    assert "EVAL.json..." in runner.invoke(app, ["report", "--help"]).output


def test_command_lists_are_not_cut():
    for path in ([], ["task"]):
        text = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "80"}).output
        commands = text[text.index("Commands:") :].splitlines()[1:]
        assert commands and all(not line.rstrip().endswith("...") for line in commands), text


def test_a_failing_json_run_says_why_on_stdout(tmp_path):
    """With --json a failure is one JSON object on stdout too (a new user's
    `omavctl fit nosuch.bag --json | python -m json.tool` read nothing and failed with
    'Expecting value'); stderr keeps its one line and the exit status is unchanged."""
    missing = tmp_path / "nosuch.bag"
    result = runner.invoke(app, ["fit", str(missing), "--out", str(tmp_path / "m.npz"), "--json"])
    assert result.exit_code == 2
    assert result.stderr.strip() == f"error: {missing}: file not found"
    assert _one_json(result.stdout) == {
        "command": "fit",
        "error": f"{missing}: file not found",
        "exit_code": 2,
    }
    assert not (tmp_path / "m.npz").exists()
    out = tmp_path / "no" / "t.csv"
    result = runner.invoke(app, ["task", "steps", "--out", str(out), "--json"])
    assert result.exit_code == 2
    assert _one_json(result.stdout)["command"] == "task steps"
    # without --json stdout stays empty
    result = runner.invoke(app, ["fit", str(missing), "--out", str(tmp_path / "m.npz")])
    assert result.exit_code == 2 and result.stdout == ""


@pytest.mark.parametrize(
    ("args", "command", "error"),
    [
        (["fit", "a.bag", "--out", "m.npz", "--effect", "drag"], "fit", "No such option: --effect"),
        (["task", "fig9"], "task", "No such command 'fig9'. Did you mean 'fig8'?"),
        (["fit", "--out", "m.npz"], "fit", "Missing argument 'LOG...'."),
    ],
)
def test_a_usage_error_of_a_json_run_says_why_on_stdout(tmp_path, args, command, error):
    """A usage error (found before the command runs) printed nothing on stdout with
    --json, so `| jq` read empty input (a new user's trial, 2026-11-27); the console
    script now prints the same JSON object as any other failure."""
    run = [sys.executable, "-m", "omavctl", *args, "--json"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this tree's omavctl, from any cwd
    result = subprocess.run(run, cwd=tmp_path, env=env, capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.strip().startswith(f"error: {error}")
    got = _one_json(result.stdout)
    assert got["command"] == command and got["exit_code"] == 2
    assert got["error"] == result.stderr.strip().removeprefix("error: ")
    assert not list(tmp_path.iterdir())


def test_inspect_takes_quiet_like_every_command(tmp_path):
    """`inspect -q` was refused ('No such option: -q') while every other command took
    it; with --json it drops the listing on stderr, without it the listing is kept."""
    path = tmp_path / "t.csv"
    runner.invoke(app, ["task", "fig8", "--duration", "6", "--ramp", "1", "--out", str(path)])
    result = runner.invoke(app, ["inspect", str(path), "-q", "--json"])
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    assert _one_json(result.stdout)["command"] == "inspect"
    result = runner.invoke(app, ["inspect", str(path), "-q"])
    assert result.exit_code == 0 and str(path.name) in result.stdout
