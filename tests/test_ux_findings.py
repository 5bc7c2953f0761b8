"""A new user's findings: the verdict with several models and on a model's own
training log, and fit, inspect and evaluate agreeing on what a log must hold."""

from __future__ import annotations

import io
import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.diagnose.given import withhold_given
from omavctl.diagnose.verdict import verdict
from omavctl.report.summary import render_evaluation

FIT = (
    "omavctl fit flight-01 --effects rotor_interference,{name} --out {stem}+{name}.npz "
    "--points 200 --seed 0"
)


def _missing_drag(second: str, second_effects: dict[str, Any]) -> dict[str, Any]:
    """evaluate flight-02.bag --model gp.npz --model SECOND: rotational_drag is
    missing from gp.npz, command_delay is ambiguous with it."""
    diagnosis = {
        "method": {"min_explained_variance": 0.15},
        "missing": ["rotational_drag"],
        "missing_effects": [
            {
                "name": "rotational_drag",
                "explained_variance": 0.33,
                "ambiguous_with": ["command_delay"],
            }
        ],
        "fit_command": FIT.format(name="rotational_drag", stem="gp"),
        "test_command": None,
        "effect_commands": {
            "rotational_drag": FIT.format(name="rotational_drag", stem="gp"),
            "command_delay": FIT.format(name="command_delay", stem="gp"),
        },
    }
    models = [
        SimpleNamespace(effects={"rotor_interference": {}}),
        SimpleNamespace(effects=second_effects),
    ]
    withhold_given(diagnosis, models, ["gp.npz", second])  # type: ignore[arg-type]
    return {
        "models": [
            {"name": "gp.npz", "effects": {"rotor_interference": {}}},
            {"name": Path(second).name, "effects": second_effects},
        ],
        "metrics": {"model": {"rmse": {"x": 0.1, "y": 0.2, "z": 0.1}}},
        "diagnosis": diagnosis,
    }


def _terminal(tree: dict[str, Any]) -> str:
    con = Console(width=400, record=True, file=io.StringIO())
    render_evaluation(con, tree, {})
    return con.export_text()


def test_no_fit_is_suggested_for_an_effect_a_later_model_already_has() -> None:
    effects = {"rotor_interference": {}, "rotational_drag": {}}
    tree = _missing_drag("gp+rotational_drag.npz", effects)
    missing = verdict(tree)[0]
    assert missing.text.startswith("Missing: rotational_drag")
    assert missing.command is None
    assert missing.text.endswith(
        " gp+rotational_drag.npz, also given with --model, already has it."
    )
    assert tree["diagnosis"]["given"] == {
        "rotational_drag": {"model": "gp+rotational_drag.npz", "has_it": True}
    }
    # the fit of the look-alike is still offered: no given model has command_delay
    assert set(tree["diagnosis"]["effect_commands"]) == {"command_delay"}
    shown = _terminal(tree)
    assert "--out gp+rotational_drag.npz" not in shown
    assert "--out gp+command_delay.npz" in shown


def test_no_fit_is_suggested_that_would_overwrite_a_given_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The file the fit would write is a given model without the effect (another fit
    saved under that name): running the suggestion would destroy it."""
    other = tmp_path / "gp+rotational_drag.npz"
    other.write_bytes(b"a model")
    elsewhere = tmp_path / "sub"
    elsewhere.mkdir()
    monkeypatch.chdir(tmp_path)  # where the suggested fit would write
    tree = _missing_drag(str(other), {"rotor_interference": {}})
    missing = verdict(tree)[0]
    assert missing.command is None
    assert missing.text.endswith(
        f" Its fit command is not shown: its --out would overwrite {other}, given with --model."
    )
    # a model elsewhere of the same name is not the file the fit would write
    tree = _missing_drag(str(elsewhere / "gp+rotational_drag.npz"), {"rotor_interference": {}})
    assert verdict(tree)[0].command == FIT.format(name="rotational_drag", stem="gp")


def test_the_verdict_on_a_training_log_does_not_call_it_held_out() -> None:
    flag = {
        "code": "training_data",
        "axis": None,
        "value": None,
        "message": "flight-01: the model was fitted on this log: its errors here are not "
        "those of a flight it has not seen",
    }
    nothing = {
        "models": [{"name": "gp.npz", "effects": {}}],
        "diagnosis": {"method": {"min_explained_variance": 0.15}, "missing": []},
    }
    assert verdict(nothing)[0].text.endswith("remaining error on held-out data.")
    lines = verdict({**nothing, "flags": [flag]})
    assert lines[0].key == "training"
    assert lines[1].text == (
        "Nothing missing: no registered effect explains 15 % or more of the model's "
        "remaining error on this log, which it was fitted on (training data, not held out)."
    )
    missing = _missing_drag("other.npz", {})
    missing["flags"] = [flag]
    text = next(ln.text for ln in verdict(missing) if ln.key == "missing")
    assert "held-out data" not in text and "on this log, which it was fitted on" in text


# --- fit, inspect and evaluate agree on what a log must hold -------------------------

PLAIN_YAML = """columns:
  time: {column: time}
  body_rate: {x: gx, y: gy, z: gz}
  force_command: {x: fx, y: fy, z: fz}
  torque_command: {x: tx, y: ty, z: tz}
"""


def _wrench_csv(path: Path, seed: int, attitude: bool) -> Path:
    """10 s at 100 Hz of a body rate driven by random torques (force: hover),
    with or without a logged attitude (roll, pitch, yaw: zero)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1000) / 100.0
    torque = np.cumsum(rng.normal(0, 0.5, (1000, 3)), axis=0) * 0.1
    gyro = np.cumsum(torque, axis=0) * 0.01 + rng.normal(0, 0.002, (1000, 3))
    force = np.tile([0.0, 0.0, 40.0], (1000, 1))
    names = ["time", "gx", "gy", "gz", "fx", "fy", "fz", "tx", "ty", "tz"]
    cols = [t, gyro, force, torque]
    if attitude:
        names += ["roll", "pitch", "yaw"]
        cols.append(np.zeros((1000, 3)))
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(names), comments="")
    return path


def test_fit_inspect_and_evaluate_agree_a_vehicle_without_rotors_needs_the_attitude(
    tmp_path: Path,
) -> None:
    """fit took a log without attitude that inspect said fit needed it for, and that
    evaluate then refused: all three now refuse it, with the same words."""
    plain = tmp_path / "plain.yaml"
    plain.write_text(PLAIN_YAML)
    with_att = tmp_path / "with.yaml"
    with_att.write_text(PLAIN_YAML + "  attitude: {roll: roll, pitch: pitch, yaw: yaw}\n")
    log = _wrench_csv(tmp_path / "imu.csv", seed=1, attitude=False)
    runner = CliRunner()
    res = runner.invoke(app, ["inspect", str(log), "--vehicle", str(plain), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["required_missing"] == ["attitude"]
    expected = f"error: {log}: the column map has no entry for attitude (columns.attitude)\n"
    out = tmp_path / "m.npz"
    res = runner.invoke(app, ["fit", str(log), "--vehicle", str(plain), "--out", str(out)])
    assert (res.exit_code, res.stderr) == (2, expected)
    assert not out.exists()
    # a model of this vehicle fitted on a log with attitude: evaluate says the same
    good = _wrench_csv(tmp_path / "good.csv", seed=2, attitude=True)
    fit = ["fit", str(good), "--vehicle", str(with_att), "--out", str(out)]
    res = runner.invoke(app, [*fit, "--points", "30", "--restarts", "0"])
    assert res.exit_code == 0, res.output
    ev = ["evaluate", str(log), "--model", str(out), "--horizons", "none"]
    res = runner.invoke(app, ev)  # the model's column map names the attitude's columns
    assert (res.exit_code, res.stderr) == (
        2,
        f"error: {log}: missing column 'roll' (mapped to attitude.roll)\n",
    )


def test_inspect_of_motor_logs_does_not_ask_for_an_attitude(tmp_path: Path) -> None:
    """A Betaflight blackbox CSV without a column map: its suggested preset mixes the
    motor outputs, so fit and evaluate need the gyro and those outputs only."""
    rng = np.random.default_rng(0)
    rows = ["loopIteration, time (us), gyroADC[0] (deg/s), gyroADC[1] (deg/s), "
            "gyroADC[2] (deg/s), rcCommand[0], rcCommand[1], rcCommand[2], rcCommand[3], "
            "motor[0], motor[1], motor[2], motor[3]"]  # fmt: skip
    for i in range(400):
        gyro = rng.normal(0, 50, 3)
        rc = rng.integers(-500, 500, 3)
        motors = rng.integers(1100, 1900, 4)
        rows.append(", ".join(map(str, [i, 1000000 + 500 * i, *gyro, *rc, 1500, *motors])))
    log = tmp_path / "LOG00001.01.csv"
    log.write_text("\n".join(rows) + "\n")
    res = CliRunner().invoke(app, ["inspect", str(log), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["required_missing"] == ["body_rate", "motor_command"]
    assert set(out["suggested_columns"]) == {"time", "body_rate", "motor_command"}
    assert "fit and evaluate need: body_rate, motor_command\n" in res.stderr


def test_an_empty_time_window_says_where_windows_count_from(tmp_path: Path) -> None:
    """A log whose clock reads 39.2 s at its first sample (a Crazyflie's time since
    boot): a window on that clock is past the log's end, and the error says so."""
    vfile = tmp_path / "with.yaml"
    vfile.write_text(PLAIN_YAML + "  attitude: {roll: roll, pitch: pitch, yaw: yaw}\n")
    log = _wrench_csv(tmp_path / "boot.csv", seed=3, attitude=True)
    rows = np.loadtxt(log, delimiter=",", skiprows=1)
    rows[:, 0] += 39.2
    header = log.read_text().splitlines()[0]
    np.savetxt(log, rows, delimiter=",", header=header, comments="")
    res = CliRunner().invoke(
        app, ["fit", str(log), "--vehicle", str(vfile), "--time-window", "40:45", "--out", "m.npz"]
    )
    assert res.exit_code == 2
    assert res.stderr == (
        f"error: {log}: time window 40:45 s has no samples: the log spans 0.00-9.99 s from "
        "its first sample, at 39.20 s on the log's own clock; windows count from that first "
        "sample; its valid samples span 0.00-9.99 s\n"
    )


def test_a_betaflight_header_sidecar_is_named_with_the_csv_to_give(tmp_path: Path) -> None:
    side = tmp_path / "LOG00001.01.headers.txt"
    side.write_text(
        "H Product:Blackbox flight data recorder by Nicholas Sherlock\nH Data version:2\n"
        "H Field I name:loopIteration,time,gyroADC[0],gyroADC[1],gyroADC[2]\n"
        "H Field I signed:0,0,1,1,1\nH motorOutput:138,2047\n"
    )
    start = "a Betaflight blackbox header sidecar ('H name:value' lines), not a log: its "
    start += "values are read with the CSV they describe; "
    runner = CliRunner()
    res = runner.invoke(app, ["inspect", str(side)])
    assert (res.exit_code, res.stderr) == (
        2,
        f"error: {side}: {start}give the CSV blackbox_decode wrote beside it (LOG00001.01.csv)\n",
    )
    (tmp_path / "LOG00001.01.csv.gz").write_bytes(b"")
    res = runner.invoke(app, ["fit", str(side), "--out", str(tmp_path / "m.npz")])
    assert (res.exit_code, res.stderr) == (
        2,
        f"error: {side}: {start}give the CSV beside it: {tmp_path / 'LOG00001.01.csv.gz'}\n",
    )


# --- the command line says what it reads and where the vehicle comes from ------------


def test_fit_evaluate_and_inspect_help_list_every_format_read() -> None:
    """Each kind detect_format tells apart is in the LOG help of the three commands
    (and so in docs/cli.md, which tests/test_docs.py keeps equal to --help)."""
    from omavctl.logs.read import FORMAT_LABELS

    spelled = {
        "ros1": "ROS 1 .bag",
        "ros2": "ROS 2 bag directory",
        "mcap": ".mcap",
        "csv": ".csv or .csv.gz",
        "ulog": "PX4 .ulg",
        "cfusdlog": "Crazyflie SD-card log",
        "betaflight": "Betaflight blackbox CSV",
    }
    assert set(spelled) == set(FORMAT_LABELS)
    cli = (Path(__file__).parents[1] / "docs/cli.md").read_text()
    for command in ("fit", "evaluate", "inspect"):
        res = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "2000"})
        assert res.exit_code == 0
        text = " ".join(res.stdout.split())  # as wrapped for any terminal width
        assert all(words in text for words in spelled.values()), (command, text)
    assert " ".join(cli.split()).count("Crazyflie SD-card log or Betaflight blackbox CSV") >= 3


def test_evaluate_says_the_vehicle_comes_from_the_model() -> None:
    res = CliRunner().invoke(app, ["evaluate", "f.bag", "--model", "m.npz", "--vehicle", "v.yaml"])
    assert (res.exit_code, res.stderr) == (
        2,
        "error: evaluate takes no --vehicle: the vehicle and its column map come from the "
        "model file (the --vehicle given to fit); to read the logs with another one, fit a "
        "model with it\n",
    )
    res = CliRunner().invoke(app, ["evaluate", "--help"], env={"COLUMNS": "2000"})
    text = " ".join(res.stdout.split())
    assert "There is no --vehicle: the vehicle (and its column map, which reads the logs)" in text


def test_the_plan_report_carries_the_terminals_warnings(vehicle: Any) -> None:
    """No candidate beats the task (its cost set below theirs): the warning the
    terminal prints, and every envelope warning, is in plan.html too."""
    from dataclasses import replace

    from omavctl.learn.fit import fit_model
    from omavctl.logs import align
    from omavctl.planning import PlanSettings, plan
    from omavctl.planning.envelope import envelope_warnings
    from omavctl.planning.report import task_warning
    from omavctl.report.plan import plan_document
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8
    from omavctl.sim.truth import truth_from_tree

    task = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=6.0, ramp=1.5)
    flight = align(simulate(task, vehicle, truth_from_tree({"seed": 1}, vehicle), seed=1).log)
    model = fit_model([flight], vehicle, points=30, restarts=0).model
    settings = PlanSettings(candidates=3, sims=1, test_points=60, points=15, seed=0)
    result = plan(model, task, settings)
    result = replace(result, task_cost=0.5 * float(result.cost[result.feasible].min()))
    warning = task_warning(result)
    assert warning is not None and warning.startswith(
        "no candidate is more informative than flying the task again"
    )
    html = plan_document(task, result)
    import html as htmllib

    text = htmllib.unescape(html)
    for said in [warning, *envelope_warnings(result)]:
        assert f"warning: {said}" in text, said


def test_the_evaluation_tables_and_the_tracking_line_carry_their_units() -> None:
    tree = _missing_drag("gp+rotational_drag.npz", {"rotor_interference": {}})
    tree["tracking"] = {"x": 1.21, "y": 0.594, "z": 0.303, "mean": 0.7}
    text = _terminal(tree)
    assert "NLPD x/y/z, nats" in text
    assert (
        "tracking, mean |a* - w_dot| of the flight (its own controller, whatever model), "
        "rad/s^2: x 1.21, y 0.594, z 0.303"
    ) in text


def test_every_row_of_fits_gp_table_says_its_unit() -> None:
    from omavctl.cli.fit import _gp_table

    axis = SimpleNamespace(
        signal_std=0.02, noise_std=0.01, length_scales=[1.0], r2=0.5, rmse=0.01,
        rmse_nominal=0.02, gp_on=True, cv_rmse_gp=0.01, cv_rmse_physics=0.02,
        cv_coverage=0.95, beyond_scale=0.5,
    )  # fmt: skip
    summary = SimpleNamespace(features="wrench", input_names=["fx/m"], axes=[axis] * 3)
    labels = [str(c) for c in _gp_table(summary).columns[0].cells]
    units = ("rad/s^2", "(normalised)", "R^2", "(held-out blocks)", "2σ", "× the GP variance")
    assert [lab for lab in labels if not any(u in lab for u in units)] == []
    assert "held-out RMSE physics, rad/s^2" in labels
