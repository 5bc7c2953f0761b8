"""kill -9 at any moment of every writing command (issue #18): each output is the
old one or the new one, whole; an evaluation JSON and its series, a planned
reference and its scores, are never taken from different runs (a pair mixed by a
kill between its two renames is recognised: report refuses it, the scores name
another reference's sha256). Temporary files a kill leaves are hidden and never read.
"""

from __future__ import annotations

import hashlib
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omavctl.base.errors import OmavctlError
from omavctl.cli import app
from omavctl.diagnose.evalio import load_evaluation

try:  # tests/ as a package or as a rootdir on sys.path
    from .fuzzkit.cases import FIT, PLAN
except ImportError:
    from fuzzkit.cases import FIT, PLAN

OMAVCTL = str(Path(sys.executable).with_name("omavctl"))

#: command -> (old run, new run, outputs); both runs write the same outputs.
COMMANDS = {
    "task": (
        ["task", "fig8", "--duration", "4", "--ramp", "1", "--out", "t.csv", "-q"],
        ["task", "circle", "--duration", "6", "--out", "t.csv", "-q"],
        ["t.csv"],
    ),
    "simulate": (
        ["simulate", "-r", "task.csv", "--seed", "1", "--out", "s.bag", "-q"],
        ["simulate", "-r", "task.csv", "--seed", "2", "--out", "s.bag", "-q"],
        ["s.bag"],
    ),
    "fit": (
        ["fit", "log.csv", "--out", "f.npz", *FIT],
        ["fit", "log.csv", "--out", "f.npz", "--seed", "3", *FIT],
        ["f.npz"],
    ),
    "evaluate": (
        ["evaluate", "log.csv", "--model", "m.npz", "--time-window", "0:4", "--out", "e.json"],
        ["evaluate", "log.csv", "--model", "m.npz", "--time-window", "1:5", "--out", "e.json"],
        ["e.json", "e.series.npz", "e.series.mcap"],
    ),
    "plan": (
        ["plan", "--task", "task.csv", "--model", "m.npz", *PLAN, "--seed", "1"],
        ["plan", "--task", "task.csv", "--model", "m.npz", *PLAN, "--seed", "2"],
        ["p.csv", "scores.csv"],
    ),
    "report": (
        ["report", "a.json", "--out", "r.md", "-q"],
        ["report", "b.json", "--out", "r.md", "-q"],
        ["r.md"],
    ),
}
COMMANDS["plan"][0].extend(["--out", "p.csv", "--scores", "scores.csv"])
COMMANDS["plan"][1].extend(["--out", "p.csv", "--scores", "scores.csv"])


def _run(argv: list[str], cwd: Path) -> float:
    start = time.monotonic()
    proc = subprocess.run([OMAVCTL, *argv], cwd=cwd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return time.monotonic() - start


def _run_here(argv: list[str], cwd: Path) -> None:
    """``omavctl ARGV`` in this process (typer's test runner), from ``cwd``: the inputs
    are made as the child processes would make them, without a Python start each."""
    before = Path.cwd()
    os.chdir(cwd)
    try:
        result = CliRunner().invoke(app, argv)
    finally:
        os.chdir(before)
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("kill9")
    _run_here(
        ["task", "fig8", "--duration", "6", "--period", "3", "--ramp", "1", "--out", "task.csv"], d
    )
    _run_here(["simulate", "-r", "task.csv", "--seed", "1", "--out", "log.csv", "-q"], d)
    _run_here(["fit", "log.csv", "--out", "m.npz", *FIT], d)
    for name, window in (("a", "0:4"), ("b", "1:5")):
        _run_here(["evaluate", "log.csv", "--model", "m.npz", "--time-window", window, "-q",
                   "--out", f"{name}.json"], d)  # fmt: skip
    return d


def _snapshot(d: Path, outputs: list[str]) -> dict[str, bytes]:
    return {o: (d / o).read_bytes() for o in outputs}


def _consistent_pair(d: Path, outputs: list[str], old: dict, new: dict) -> None:
    """Every output is the old or the new one; the first two (a pair) are from one run
    or recognisably not. (evaluate's MCAP export is written after the pair, on its own.)"""
    now = _snapshot(d, outputs)
    states = ["old" if now[o] == old[o] else "new" if now[o] == new[o] else "?" for o in outputs]
    assert "?" not in states, f"an output is neither the old nor the new one: {states}"
    if len(set(states[:2])) == 1:
        return
    # two renames apart: the mix must be recognisable
    if outputs[0].endswith(".json"):
        with pytest.raises(OmavctlError, match="belongs to another run of evaluate"):
            load_evaluation(d / outputs[0])
    else:
        digest = hashlib.sha256(now[outputs[0]]).hexdigest()
        rows = now[outputs[1]].decode().splitlines()[1:]
        assert all(not r.endswith(digest) for r in rows)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_kill9_leaves_old_or_new_output(inputs: Path, tmp_path: Path, command: str) -> None:
    old_argv, new_argv, outputs = COMMANDS[command]
    d = tmp_path / "w"
    shutil.copytree(inputs, d)
    _run_here(old_argv, d)  # the old outputs: any run makes them, no process needed
    old = _snapshot(d, outputs)
    seconds = _run(new_argv, d)
    new = _snapshot(d, outputs)
    assert old != new
    rng = random.Random(command)
    for fraction in (rng.uniform(0.5, 0.8), rng.uniform(0.8, 1.05)):
        for o in outputs:
            (d / o).write_bytes(old[o])
        proc = subprocess.Popen([OMAVCTL, *new_argv], cwd=d, stderr=subprocess.DEVNULL)
        time.sleep(seconds * fraction)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        _consistent_pair(d, outputs, old, new)
        visible = {p.name for p in d.iterdir() if not p.name.startswith(".")}
        assert visible == {p.name for p in inputs.iterdir()} | set(outputs)
    leftovers = [p.name for p in d.iterdir() if p.name.startswith(".")]
    assert all(name.startswith(tuple(f".{o}." for o in outputs)) for name in leftovers)
    if len(outputs) >= 2:  # a later run is not confused by the leftovers of killed runs
        _run_here(new_argv, d)
        assert _snapshot(d, outputs) == new
