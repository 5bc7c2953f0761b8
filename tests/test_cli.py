"""The command line: help, version, task, simulate, inspect, error lines."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from omavctl import __version__
from omavctl.cli import app
from omavctl.logs import read_log
from omavctl.sim.trajectory import read_trajectory

runner = CliRunner()


def _all_commands(cmd, prefix: tuple[str, ...] = ()):
    yield prefix
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from _all_commands(sub, (*prefix, name))


def test_version():
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == f"omavctl {__version__}"


def test_every_command_has_help_with_units_and_defaults():
    paths = list(_all_commands(typer.main.get_command(app)))
    assert ("simulate",) in paths and ("task", "fig8") in paths and ("inspect",) in paths
    for path in paths:
        result = runner.invoke(app, [*path, "--help"])
        assert result.exit_code == 0, path
        assert "Usage:" in result.output
    sim = " ".join(runner.invoke(app, ["simulate", "--help"]).output.split())
    assert "Integration rate of the truth plant, Hz. [default: 1000.0]" in sim


def test_the_top_level_help_says_where_the_output_goes():
    """A new user piped `omavctl evaluate` and found stdout empty: the human text is on
    stderr, which only each command's --json option said."""
    text = " ".join(runner.invoke(app, ["--help"]).output.split())
    assert "Tables, verdicts and notes go to stderr (inspect's listing excepted); stdout " in text


def test_the_task_summary_names_every_task():
    """The top-level help lists the task generators by name (written out: the help
    must not import the numerics that define them)."""
    from omavctl.sim.tasks import TASKS

    line = next(ln for ln in runner.invoke(app, ["--help"]).output.splitlines() if "task " in ln)
    assert line.split("(", 1)[1].rstrip(").").split(", ") == list(TASKS)


def test_help_does_not_import_the_numerics():
    code = (
        "import sys, omavctl.cli\n"
        "heavy = ['numpy', 'scipy', 'rosbags', 'mcap', 'matplotlib', 'sklearn']\n"
        "print(','.join(m for m in heavy if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


@pytest.fixture(scope="module")
def task_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("task") / "fig8.csv"
    result = runner.invoke(
        app, ["task", "fig8", "--duration", "4", "--ramp", "1", "--out", str(path)]
    )
    assert result.exit_code == 0, result.output
    return path


def test_task_writes_contract_csv(task_csv):
    traj = read_trajectory(task_csv)
    assert traj.data.shape == (401, 19)


def test_task_replaces_a_trajectory_but_not_a_log_or_other_file(task_csv, tmp_path):
    """`task`/`plan` replaced whatever --out named, a flight log included (the printed
    separating command wrote fig8.csv and next.csv into the user's directory)."""
    log = tmp_path / "flight.csv"
    log.write_text("t,roll\n0,1\n")
    for name in ("task", "plan"):
        args = ["task", "fig8", "--duration", "4", "--out", str(log)]
        if name == "plan":  # refused before the model is even read
            args = ["plan", "--task", str(task_csv), "--model", "no.npz", "--out", str(log)]
        result = runner.invoke(app, args)
        assert result.exit_code == 2, result.output
        assert result.output.strip() == (
            f"error: {log}: exists and is not a trajectory CSV; choose another name (or remove it)"
        )
        assert log.read_text() == "t,roll\n0,1\n"
    again = tmp_path / "again.csv"
    again.write_bytes(task_csv.read_bytes())
    args = ["task", "fig8", "--duration", "2", "--ramp", "0.5", "--out", str(again), "-q"]
    assert runner.invoke(app, args).exit_code == 0
    assert read_trajectory(again).data.shape == (201, 19)


def test_simulate_is_deterministic_and_does_not_touch_inputs(task_csv, tmp_path):
    before = task_csv.read_bytes()
    outs = []
    for name in ("a.csv", "b.csv"):
        out = tmp_path / name
        result = runner.invoke(
            app, ["simulate", "-r", str(task_csv), "--seed", "3", "-o", str(out), "-q"]
        )
        assert result.exit_code == 0, result.output
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    assert task_csv.read_bytes() == before
    log = read_log(tmp_path / "a.csv")
    np.testing.assert_allclose(log.t[-1], 4.0)


@pytest.mark.parametrize("name", ["flight.bag", "flight.mcap", "flight"])
def test_simulate_writes_every_log_kind(task_csv, tmp_path, name):
    out = tmp_path / name
    result = runner.invoke(app, ["simulate", "-r", str(task_csv), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    log = read_log(out)
    assert {"body_rate", "torque_command", "desired_acceleration", "tilt", "rotor"} <= set(
        log.signals
    )
    inspect = runner.invoke(app, ["inspect", str(out)])
    assert inspect.exit_code == 0
    assert "/omav/imu" in inspect.output


def _error_line(result) -> str:
    text = result.output.strip()
    assert result.exit_code == 2, text
    assert "Traceback" not in text
    assert len(text.splitlines()) == 1, text
    return text


def test_simulate_missing_reference(tmp_path):
    missing = tmp_path / "nope.csv"
    result = runner.invoke(app, ["simulate", "-r", str(missing), "-o", str(tmp_path / "x.csv")])
    assert _error_line(result) == f"error: {missing}: file not found"
    assert not (tmp_path / "x.csv").exists()


def test_simulate_bad_truth_leaves_nothing(task_csv, tmp_path):
    truth = tmp_path / "truth.yaml"
    truth.write_text("effects: {rotational_drag: {D: [1]}}\n")
    out = tmp_path / "x.bag"
    result = runner.invoke(
        app, ["simulate", "-r", str(task_csv), "--truth", str(truth), "-o", str(out)]
    )
    line = _error_line(result)
    assert line == f"error: {truth}: 'effects.rotational_drag.D' must be 3 finite number(s)"
    assert not out.exists() and list(tmp_path.iterdir()) == [truth]


def test_simulate_unknown_vehicle_key(task_csv, tmp_path):
    vehicle = tmp_path / "v.yaml"
    vehicle.write_text("mass: 4\narms: 6\n")
    result = runner.invoke(
        app,
        ["simulate", "-r", str(task_csv), "--vehicle", str(vehicle), "-o", str(tmp_path / "x.csv")],
    )
    assert _error_line(result) == f"error: {vehicle}: unknown key 'arms'"


def test_simulate_output_directory_missing(task_csv, tmp_path):
    out = tmp_path / "no" / "such" / "x.csv"
    result = runner.invoke(app, ["simulate", "-r", str(task_csv), "-o", str(out)])
    assert _error_line(result) == f"error: {out.parent}: output directory does not exist"


def test_simulate_replaces_its_own_log_and_never_another_file(task_csv, tmp_path):
    """``simulate --out`` used to overwrite whatever was there, a user's flight log
    too: it now replaces only a log omavctl wrote (as ``task`` and ``plan`` replace
    only a trajectory CSV), refusing anything else in one line, untouched."""
    import shutil

    import yaml

    short = tmp_path / "short.csv"  # a 1 s flight: eight of them fly in a few seconds
    task = ["task", "fig8", "--duration", "1", "--ramp", "0.25", "--out", str(short), "-q"]
    assert runner.invoke(app, task).exit_code == 0

    def sim(out, seed: str = "1"):
        return runner.invoke(app, ["simulate", "-r", str(short), "--seed", seed, "-o", str(out)])

    for name in ("own.csv", "own.bag", "own.mcap", "own"):  # its own output: replaced
        assert sim(tmp_path / name).exit_code == 0
        result = sim(tmp_path / name, "2")
        assert result.exit_code == 0, result.output
    # a ROS 2 bag a recorder wrote (no omavctl mark in its metadata), a trajectory CSV,
    # a ROS 1 bag and an MCAP file omavctl did not write, and a user's directory
    recorded = tmp_path / "recorded"
    shutil.copytree(tmp_path / "own", recorded)
    meta = yaml.safe_load((recorded / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"]["custom_data"] = None
    (recorded / "metadata.yaml").write_text(yaml.safe_dump(meta))
    reference = tmp_path / "reference.csv"
    shutil.copy(task_csv, reference)
    (tmp_path / "other.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(64))
    other = (tmp_path / "own.mcap").read_bytes().replace(b"omavctl", b"recordr", 1)
    (tmp_path / "other.mcap").write_bytes(other)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "a.txt").write_text("mine")
    for name in ("recorded", "reference.csv", "other.bag", "other.mcap", "notes"):
        out = tmp_path / name
        before = sorted((p.name, p.read_bytes()) for p in [out, *out.rglob("*")] if p.is_file())
        assert _error_line(sim(out)) == (
            f"error: {out}: exists and is not a log omavctl simulate wrote; "
            "choose another name (or remove it)"
        )
        assert sorted((p.name, p.read_bytes()) for p in [out, *out.rglob("*")] if p.is_file()) == (
            before
        )


@pytest.mark.parametrize("name", ["x.txt", "flight.cvs", "log.db3"])
def test_simulate_unknown_log_kind_is_refused_before_flying(task_csv, tmp_path, name):
    """A mistyped extension is not written as a ROS 2 bag directory of that name."""
    out = tmp_path / name
    result = runner.invoke(app, ["simulate", "-r", str(task_csv), "-o", str(out)])
    suffix = out.suffix
    assert _error_line(result) == (
        f"error: {out}: unknown log kind '{suffix}': write a directory (ROS 2 bag), "
        ".bag (ROS 1), .mcap or .csv"
    )
    assert result.exit_code == 2 and not out.exists()


def test_task_bad_option_is_one_line(tmp_path):
    result = runner.invoke(
        app, ["task", "fig8", "--duration", "1", "--out", str(tmp_path / "t.csv")]
    )
    assert _error_line(result) == "error: --duration (1.0 s) must be at least twice --ramp (2.0 s)"
    result = runner.invoke(
        app, ["task", "fig8", "--duration", "-5", "--out", str(tmp_path / "t.csv")]
    )
    assert _error_line(result) == "error: --duration must be > 0 s, got -5"


def test_inspect_missing_log(tmp_path):
    missing = tmp_path / "nope.bag"
    result = runner.invoke(app, ["inspect", str(missing)])
    assert _error_line(result) == f"error: {missing}: file not found"


def test_simulate_says_when_the_actuators_could_not_follow(task_csv, tmp_path):
    """A reference the actuators cannot fly is named as such; a normal one is not."""
    calm = runner.invoke(app, ["simulate", "-r", str(task_csv), "-o", str(tmp_path / "a.csv")])
    assert calm.exit_code == 0 and "more than the actuators give" not in calm.output
    wild = tmp_path / "wild.csv"
    args = ["task", "fig8", "--roll", "60", "--pitch", "60", "--period", "2", "--duration", "6"]
    assert runner.invoke(app, [*args, "--ramp", "1", "--out", str(wild), "-q"]).exit_code == 0
    result = runner.invoke(app, ["simulate", "-r", str(wild), "-o", str(tmp_path / "w.csv")])
    assert result.exit_code == 0, result.output
    assert "% of the steps asked for more than the actuators give" in result.output


def test_simulate_says_what_the_steps_beyond_the_limits_are():
    """'49/2401 steps beyond actuator limits' said nothing of what that means (eyes4)."""
    import io
    from types import SimpleNamespace

    from rich.console import Console

    from omavctl.cli.simulate import _render_simulation

    def said(infeasible: int) -> str:
        con = Console(file=io.StringIO(), width=300)
        run = SimpleNamespace(
            duration=24.0, max_attitude_error=0.01, infeasible_steps=infeasible, steps=2401,
            diverged=False,
        )  # fmt: skip
        _render_simulation(con, run, "f.csv")
        return con.file.getvalue()

    assert "49/2401 steps beyond actuator limits (thrust or tilt rate: the wrench clipped" in (
        said(49)
    )
    assert "0/2401 steps beyond actuator limits\n" in said(0)
