"""Real and real-like logs end to end: the px4tools octocopter flight through fit,
evaluate and report; one simulated flight written in FRD and in FLU gives the same
model; a normalised torque command's gain is recovered; command units and rates."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rich.console import Console
from typer.testing import CliRunner

from omavctl.base.errors import ConfigError, ModelError
from omavctl.cli import app
from omavctl.learn.effect_fit import GAIN_EFFECT, torque_gain
from omavctl.learn.fit import fit_model
from omavctl.learn.flights import upsampling_note
from omavctl.learn.model_file import check_vehicle, load_model
from omavctl.logs import RawLog, RawSeries, align, read_vehicle_log, write_log
from omavctl.logs.contract import quaternion_from_euler
from omavctl.logs.frames import FRD_TO_FLU
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle, load_vehicle

REPO = Path(__file__).parents[1]
PX4_CSV = Path(__file__).parents[2] / "shared/data/real/px4tools_octocopter/01_07_59.csv"
PX4_VEHICLE = REPO / "examples/px4tools-octocopter.yaml"
needs_px4 = pytest.mark.skipif(
    not PX4_CSV.exists(),
    reason=f"real PX4 log not available at {PX4_CSV} (shared test data not mounted)",
)
runner = CliRunner()
#: Small fits keep this file fast; the example (examples/Makefile) uses the defaults.
SMALL_FIT = ["--points", "60", "--restarts", "0"]


def _ok(result: Any) -> str:
    assert result.exit_code == 0, result.output
    return str(result.output)


# --- the real px4tools octocopter ----------------------------------------------------


@needs_px4
def test_px4tools_column_map_and_in_flight_detection() -> None:
    vehicle = load_vehicle(PX4_VEHICLE)
    assert vehicle.command_units == {"torque": "normalised", "force": "normalised"}
    log = read_vehicle_log(PX4_CSV, vehicle, rate=vehicle.gains.rate_hz)
    assert set(log.signals) >= {"body_rate", "attitude", "force_command", "torque_command"}
    # normalised commands: thrust 0..~0.5 (up after FRD -> FLU), torques within -1..1
    f, tau = log.signals["force_command"], log.signals["torque_command"]
    assert 0.0 <= f[:, 2].min() and f[:, 2].max() < 0.6 and np.abs(tau).max() <= 1.0
    # the ground segment (idle, then spool-up below hover thrust) is excluded: one
    # in-flight segment from ~5.3 s to the end of the log
    ((a, b),) = log.segments
    assert 5.0 < log.t[a] < 5.6 and b == log.t.size
    assert not log.valid[log.t < 5.0].any() and log.valid[log.t >= 5.6].all()
    hover = np.median(f[a:b, 2])
    assert 0.40 < hover < 0.45
    assert np.all(f[: a - 30, 2] < 0.9 * hover)  # before take-off thrust (0.2 s margin)
    assert any(n.startswith("ground/idle: 0.00-") for n in log.notes)
    # 83 Hz body rate on the 100 Hz grid: fit notes the upsampling
    note = upsampling_note(log, vehicle)
    assert note is not None and note.startswith("body rate logged at 83.3 Hz")
    assert "controller.rate_hz to at most 83 Hz" in note


@needs_px4
def test_a_time_column_scaled_to_a_split_second_points_at_the_time_column(
    tmp_path: Path,
) -> None:
    """Microseconds read as nanoseconds: the whole flight lasts 0.02 s, too short to fit,
    and the refusal says why that is suspicious."""
    wrong = tmp_path / "v.yaml"
    wrong.write_text(PX4_VEHICLE.read_text().replace("scale: 1.0e-6", "scale: 1.0e-9"))
    args = ["fit", str(PX4_CSV), "--vehicle", str(wrong), "--out", str(tmp_path / "m.npz")]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    line = result.output.strip()
    assert line.startswith(f"error: {PX4_CSV}: too little data: the signals overlap for 0.021 s")
    assert line.endswith("samples: check the time column and its scale")


@needs_px4
def test_inspect_says_its_ranges_are_in_the_logs_frame() -> None:
    """The px4 vehicle's log is FRD: inspect lists the columns as read (thrust negative,
    pointing down) and says fit converts them."""
    out = _ok(runner.invoke(app, ["inspect", str(PX4_CSV), "--vehicle", str(PX4_VEHICLE)]))
    assert (
        "note: column ranges in the log's FRD frame (scaled, not yet converted: fit and "
        "evaluate work in FLU, where y and z change sign)"
    ) in " ".join(out.split())


@needs_px4
def test_a_time_column_in_the_wrong_unit_is_refused_by_fit(tmp_path: Path) -> None:
    """Microseconds read as milliseconds: a 21 000 s flight whose body rate seems logged
    at 0.08 Hz. fit refuses it in one line, as evaluate does, and writes nothing."""
    wrong = tmp_path / "v.yaml"
    wrong.write_text(PX4_VEHICLE.read_text().replace("scale: 1.0e-6", "scale: 1.0e-3"))
    out = tmp_path / "m.npz"
    args = ["fit", str(PX4_CSV), "--vehicle", str(wrong), "--out", str(out), *SMALL_FIT]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert result.output.strip() == (
        f"error: {PX4_CSV}: body rate logged at 0.0833 Hz, below half the 100 Hz grid "
        "(controller.rate_hz): check the time column's unit first (the time column's scale "
        "under columns: in the vehicle YAML; a ms clock read as s gives a rate 1000x too low)"
    )
    assert not out.exists()


CF_LOG10 = Path(__file__).parents[2] / "shared/data/real/arpl_crazyflie/log10"


@pytest.mark.skipif(not CF_LOG10.exists(), reason=f"no Crazyflie log at {CF_LOG10}")
def test_a_ms_clock_read_as_seconds_is_named_before_the_rate(tmp_path: Path) -> None:
    """A new user's Crazyflie YAML with the time scale 1.0 for a ms clock: "body rate
    logged at 1.01 Hz ...: set controller.rate_hz to at most 1 Hz in the vehicle YAML"."""
    yaml = Path(__file__).parents[1] / "examples/crazyflie.yaml"
    wrong = tmp_path / "cf.yaml"
    wrong.write_text(yaml.read_text().replace("scale: 1.0e-3}", "scale: 1.0}"))
    out = tmp_path / "m.npz"
    result = runner.invoke(app, ["fit", str(CF_LOG10), "--vehicle", str(wrong), "--out", str(out)])
    assert result.exit_code == 2 and not out.exists()
    assert result.output.strip() == (
        f"error: {CF_LOG10}: body rate logged at 1.01 Hz, below half the 500 Hz grid "
        "(controller.rate_hz): check the time column's unit first (the time column's scale "
        "under columns: in the vehicle YAML; a ms clock read as s gives a rate 1000x too "
        "low); if it is right, set controller.rate_hz to at most 1 Hz"
    )


@needs_px4
def test_px4tools_fit_evaluate_report_through_the_cli(tmp_path: Path) -> None:
    model, ev, rep = tmp_path / "gp.npz", tmp_path / "eval.json", tmp_path / "report.md"
    before = PX4_CSV.stat().st_mtime_ns
    args = ["fit", str(PX4_CSV), "--vehicle", str(PX4_VEHICLE), "--time-window", "6.5:15"]
    args += ["--effects", "rotational_drag", *SMALL_FIT, "--out", str(model)]
    out = _ok(runner.invoke(app, args))
    text = " ".join(out.split())
    # inertia_error added for the normalised torque, said so; units unknown, not N m
    assert "inertia_error added to estimate its per-axis gain" in text
    assert "torque command gain" in text and "[torque unit] s^2" in text
    assert "N m s^2" not in text
    # no gain is pinned down (the scales it inverts are not, below): the table says so
    gain_rows = [ln for ln in out.splitlines() if "= 1/scale_" in ln]
    assert len(gain_rows) == 3
    assert all("cannot be pinned down from this flight" in ln for ln in gain_rows), gain_rows
    assert "body rate logged at 83.3 Hz" in text
    assert "time window 6.5:15 s" in text

    m = load_model(model)
    assert sorted(m.effects) == [GAIN_EFFECT, "rotational_drag"]
    assert m.vehicle.torque_normalised and m.provenance["command_units"]["torque"] == "normalised"
    assert m.provenance["time_window"] == [6.5, 15.0]
    assert m.provenance["vehicle_path"] == str(PX4_VEHICLE)
    gain, se = torque_gain(m.effects[GAIN_EFFECT])
    assert np.all(np.isfinite(gain)) and np.all(np.isfinite(se))
    np.testing.assert_allclose(m.provenance["torque_gain"]["values"], gain)
    # roll and pitch gains: the least-squares gain is positive, of the order found on
    # this flight (docs/logs.md); the joint estimate with a 12-input GP (body rates and
    # the command's rate among them, which also explain a linear trend in the torque)
    # is weakly determined on 60 points and agrees with it within 2 standard errors
    ls_gain = np.array(m.provenance["torque_gain"]["first_pass_least_squares"])
    assert np.all((ls_gain[:2] > 0.02) & (ls_gain[:2] < 1.0)), ls_gain
    assert np.all(np.abs(gain - ls_gain) <= 2 * se + 1e-9), (gain, ls_gain, se)
    assert m.n_train == 60

    out = _ok(
        runner.invoke(
            app, ["evaluate", str(PX4_CSV), "-m", str(model), "--time-window", "15:", "-o", str(ev)]
        )
    )
    tree = json.loads(ev.read_text())
    assert tree["units"] == {"acceleration": "rad/s^2", "torque": "unknown", "force": "unknown"}
    (log,) = tree["logs"]
    assert 600 < log["samples"] < 650  # 15 <= t < 21.44 s at 100 Hz, minus filter edges
    for pred in ("nominal", "effects", "model"):
        for metric in ("rmse", "mae", "r2", "coverage_2sigma"):
            values = tree["metrics"][pred][metric].values()
            assert all(math.isfinite(v) for v in values), (pred, metric)
    # the fitted gain explains part of the nominal model's error on the held-out part
    for axis in "xyz":
        assert tree["metrics"]["effects"]["rmse"][axis] < tree["metrics"]["nominal"]["rmse"][axis]
    # what predicting no acceleration at all scores, and a flag where the model does not
    # beat it (on this flight it does not, on some axes: docs/logs.md)
    with np.load(tmp_path / "eval.series.npz", allow_pickle=False) as series:
        rms = np.sqrt((series["measured"] ** 2).mean(axis=0))
    zero = tree["metrics"]["zero"]["rmse"]
    np.testing.assert_allclose([zero[a] for a in "xyz"], rms, rtol=1e-9)
    flagged = {f["axis"] for f in tree["flags"] if f["code"] == "no_better_than_zero"}
    assert flagged == {a for a in "xyz" if tree["metrics"]["model"]["rmse"][a] >= zero[a]}
    printed = " ".join(out.split())
    for axis in flagged:
        assert f"axis {axis}: the model's error" in printed and "would do as well" in printed
    print(
        "no better than predicting zero on", sorted(flagged), zero, tree["metrics"]["model"]["rmse"]
    )

    # every learned effect carries its estimate as fit --effects makes it, with 95 %
    # intervals; the model's gain too (and, here, none of the gains is pinned down)
    for entry in tree["diagnosis"]["learned"]:
        est = entry["estimate"]
        for p in entry["units"]:
            assert len(est[f"{p}_ci95"]) == len(est[p]) == len(est[f"{p}_pinned"])
    scale = tree["models"][0]["effects"]["inertia_error"]
    assert scale["stderr_method"] == "hac" and scale["scale_pinned"] == [False] * 3

    _ok(runner.invoke(app, ["report", str(ev), "--out", str(rep), "-q"]))
    assert "torques are in unknown units" in rep.read_text()
    assert "fitted inertia\\_error: scale\\_x = " in rep.read_text()
    assert "cannot be pinned down from this flight" in rep.read_text()
    assert PX4_CSV.stat().st_mtime_ns == before


# --- one simulated flight, FRD and FLU -----------------------------------------------


@pytest.fixture(scope="module")
def flight(vehicle) -> dict[str, np.ndarray]:
    """A short simulated figure-8 (default imperfections) on the 100 Hz grid: ``t``
    shape (n,) and the contract roles in FLU, shape (n, 3) each."""
    ref = fig8(roll_deg=20, pitch_deg=20, period=3.0, duration=5.0, ramp=1.0)
    log = align(simulate(ref, vehicle, truth_from_tree({}, vehicle), seed=0).log)
    assert log.valid.all()
    return {"t": log.t, **log.signals}


def _write_rows(path: Path, header: list[str], columns: list[np.ndarray]) -> Path:
    rows = np.column_stack(columns)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows([[repr(float(x)) for x in row] for row in rows])
    return path


ROLES = ("body_rate", "attitude", "position", "force_command", "torque_command")


def _fit_flu_and(tmp_path: Path, flight, other: Path, vehicle: Path) -> tuple[Any, Any]:
    """Models fitted (drag, 50 points) on the flight as the wide contract CSV (FLU, no
    column map) and on ``other``, the same flight in another layout read with
    ``vehicle``'s column map."""
    t = flight["t"]
    flu_raw = RawLog(
        path=Path("sim"),
        format="synthetic",
        t0=0.0,
        series={r: RawSeries(t, flight[r]) for r in ROLES},
    )
    flu_path = tmp_path / "flu.csv"
    write_log(flu_path, flu_raw)
    common = ["--effects", "rotational_drag", "--points", "50", "--restarts", "0", "-q"]
    outs = {}
    for name, path, extra in (("flu", flu_path, []), ("other", other, ["--vehicle", str(vehicle)])):
        outs[name] = tmp_path / f"{name}.npz"
        _ok(runner.invoke(app, ["fit", str(path), *extra, *common, "--out", str(outs[name])]))
    return load_model(outs["flu"]), load_model(outs["other"])


def test_frd_and_flu_csvs_of_one_flight_give_the_same_model(tmp_path: Path, flight) -> None:
    roles = ROLES
    t = flight["t"]
    # FRD: body FRD / world NED, another layout, time in ms, attitude as a quaternion,
    # thrust logged as a positive magnitude, torques in N cm
    frd = {r: flight[r] * FRD_TO_FLU for r in roles}
    q = quaternion_from_euler(frd["attitude"])  # (x, y, z, w)
    assert (frd["force_command"][:, 2] < 0).all()
    frd_path = _write_rows(
        tmp_path / "frd.csv",
        "time_ms gx gy gz qw qx qy qz n e d fx fy thrust mx my mz".split(),
        [
            t * 1e3 + 2.5e4,
            *frd["body_rate"].T,
            q[:, 3],
            *q[:, :3].T,
            *frd["position"].T,
            frd["force_command"][:, 0],
            frd["force_command"][:, 1],
            -frd["force_command"][:, 2],
            *(frd["torque_command"] * 100.0).T,
        ],
    )
    frd_vehicle = tmp_path / "frd.yaml"
    frd_vehicle.write_text(
        yaml.safe_dump(
            {
                "frame": "FRD",
                "columns": {
                    "time": {"column": "time_ms", "scale": 1e-3},
                    "body_rate": {"x": "gx", "y": "gy", "z": "gz"},
                    "attitude": {"quaternion": {a: f"q{a}" for a in "wxyz"}},
                    "position": {"x": "n", "y": "e", "z": "d"},
                    "force_command": {"x": "fx", "y": "fy", "z": {"column": "thrust", "scale": -1}},
                    "torque_command": {"x": "mx", "y": "my", "z": "mz", "scale": 0.01},
                },
            }
        )
    )
    a, b = _fit_flu_and(tmp_path, flight, frd_path, frd_vehicle)
    # the same training points, targets, hyperparameters and effects (FLU inputs)
    np.testing.assert_allclose(b.inputs, a.inputs, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.targets, a.targets, rtol=1e-6, atol=1e-7)
    for key in ("signal_variance", "noise_variance", "length_scales", "target_mean"):
        np.testing.assert_allclose(getattr(b, key), getattr(a, key), rtol=1e-5, err_msg=key)
    d_a, d_b = a.effects["rotational_drag"].values["D"], b.effects["rotational_drag"].values["D"]
    np.testing.assert_allclose(d_b, d_a, rtol=1e-6, atol=1e-12)
    # and the same predictions anywhere near the flight
    rng = np.random.default_rng(0)
    u = a.inputs[rng.integers(0, a.n_train, 40), :6] + 0.1 * rng.standard_normal((40, 6))
    omega = 0.3 * rng.standard_normal((40, 3))
    du = rng.standard_normal((40, 6))
    np.testing.assert_allclose(
        b.predict(u, omega, du=du)[0], a.predict(u, omega, du=du)[0], rtol=1e-5, atol=1e-8
    )
    # a 100 Hz log on the 100 Hz grid: no upsampling note
    assert upsampling_note(read_vehicle_log(frd_path, load_vehicle(frd_vehicle)), a.vehicle) is None


def test_a_px4_ulog_of_one_flight_gives_the_model_of_its_csv(tmp_path: Path, flight) -> None:
    """The flight of the FRD/FLU test written as a PX4 ULog (PX4's topic names, body
    FRD, attitude a quaternion, float32 fields, time in us since boot): ``inspect``
    names PX4's topics in its suggested map, and with that map (plus ``frame: FRD``)
    ``fit`` gives the model of the contract CSV, to float32 precision."""
    from omavctl.logs.inspection import inspect_log
    from tests.ulog_writer import write_ulog

    roles = ROLES
    t = flight["t"]
    frd = {r: flight[r] * FRD_TO_FLU for r in roles}
    q = quaternion_from_euler(frd["attitude"])  # (x, y, z, w)
    us = np.round(t * 1e6) + 25e6
    ulg = tmp_path / "flight.ulg"
    write_ulog(
        ulg,
        {
            "vehicle_angular_velocity": (us, {"xyz": frd["body_rate"]}),
            "vehicle_attitude": (us, {"q": np.column_stack([q[:, 3], q[:, :3]])}),
            "vehicle_local_position": (us, {k: frd["position"][:, i] for i, k in enumerate("xyz")}),
            "vehicle_thrust_setpoint": (us, {"xyz": frd["force_command"]}),
            "vehicle_torque_setpoint": (us, {"xyz": frd["torque_command"]}),
            "cpuload": (us[::50], {"load": np.full(us[::50].size, 0.3)}),
        },
    )
    ins = inspect_log(ulg)
    assert ins.format == "ulog" and ins.duration == pytest.approx(t[-1] - t[0])
    assert ins.suggested_columns is not None
    columns = ins.suggested_columns
    assert columns["time"] == {"column": "timestamp", "scale": 1e-6}
    assert columns["body_rate"] == {
        a: f"vehicle_angular_velocity.xyz[{i}]" for i, a in enumerate("xyz")
    }
    assert columns["attitude"] == {
        "quaternion": {a: f"vehicle_attitude.q[{i}]" for i, a in enumerate("wxyz")}
    }
    assert columns["torque_command"] == {
        a: f"vehicle_torque_setpoint.xyz[{i}]" for i, a in enumerate("xyz")
    }
    assert columns["force_command"] == {"z": "vehicle_thrust_setpoint.xyz[2]"}
    # the omav's force command has x and y too: map them like z
    columns["force_command"].update(
        {a: f"vehicle_thrust_setpoint.xyz[{i}]" for i, a in enumerate("xy")}
    )
    ulg_vehicle = tmp_path / "ulog.yaml"
    ulg_vehicle.write_text(yaml.safe_dump({"frame": "FRD", "columns": columns}))
    a, b = _fit_flu_and(tmp_path, flight, ulg, ulg_vehicle)
    np.testing.assert_allclose(b.inputs, a.inputs, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.targets, a.targets, rtol=1e-3, atol=1e-3)
    d_a, d_b = a.effects["rotational_drag"].values["D"], b.effects["rotational_drag"].values["D"]
    np.testing.assert_allclose(d_b, d_a, rtol=1e-3, atol=1e-5)
    assert b.provenance["sources"][0]["name"] == "flight.ulg"


def test_a_disarmed_bench_ulog_is_refused_as_no_flight(tmp_path: Path) -> None:
    """The shared PX4 ULog of a board moved by hand, never armed (a negative control):
    read through the PX4 map ``inspect`` suggests, ``fit`` refuses it in one line."""
    ulg = REPO.parent / "shared/data/real/pyulog_bench/sample.ulg"
    if not ulg.exists():
        pytest.skip(f"shared ULog not available at {ulg}")
    result = runner.invoke(app, ["inspect", str(ulg)])
    out = _ok(result)
    assert 'torque_command: {x: "actuator_controls_0.control[0]"' in out
    # PX4's thrust is 0..1 along -z whatever this log's values (all 0 here)
    assert 'force_command: {z: "actuator_controls_0.control[3]", scale: -1.0}' in out
    assert "control_state.{roll,pitch,yaw}_rate" not in out.split("torque_command:")[1]
    assert "frame: FRD  # sensor_combined.accelerometer_m_s2[2] reads -9.6" in out
    # 249 columns: the terminal lists the suggested map's (the accelerometer's three
    # among them: the specific_force role), --json every one
    assert "Columns of the suggested map" in out and "and 232 more columns" in out
    assert "estimator_status.states[0]" not in out.split("suggested column map")[0]
    result = runner.invoke(app, ["inspect", str(ulg), "--json"])
    _ok(result)
    assert len(json.loads(result.stdout)["column_ranges"]) == 249
    vehicle = REPO / "examples/pyulog-bench-quad.yaml"
    result = runner.invoke(app, ["inspect", str(ulg), "--vehicle", str(vehicle), "--json"])
    _ok(result)
    tree = json.loads(result.stdout)
    assert tree["roles_found"]["force_command"] == "columns actuator_controls_0.control[3]"
    assert (
        "the thrust command (force_command) is zero throughout: no flight in this log"
        in tree["notes"]
    )
    # a role's axes from two topics: said before any row is read
    mixed = yaml.safe_load(vehicle.read_text())
    mixed["columns"]["body_rate"]["x"] = "vehicle_attitude.rollspeed"
    (tmp_path / "mixed.yaml").write_text(yaml.safe_dump(mixed))
    result = runner.invoke(app, ["inspect", str(ulg), "--vehicle", str(tmp_path / "mixed.yaml")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines()[-1] == (
        f"error: {ulg}: the column map takes body_rate from 2 topics (sensor_combined, "
        "vehicle_attitude): a role's axes must come from one topic of a ULog"
    )
    result = runner.invoke(
        app, ["fit", str(ulg), "--vehicle", str(vehicle), "--out", str(tmp_path / "m.npz")]
    )
    assert result.exit_code == 2
    assert result.output.strip().splitlines()[-1] == (
        f"error: {ulg}: no flight: the thrust command (|force_command|) is zero throughout"
    )
    assert not (tmp_path / "m.npz").exists()


# --- normalised torque command -------------------------------------------------------


def test_gain_of_a_normalised_torque_command_is_recovered(tmp_path: Path, vehicle) -> None:
    """Ideal actuators, default sensor noise; the logged torque is tau / c per axis."""
    from test_fit import attitude_sines

    ref = attitude_sines((20, 20, 30), (2, 2.6, 3), duration=8.0)
    log = simulate(ref, vehicle, truth_from_tree({"ideal": True}, vehicle), seed=0).log
    gains = np.array([0.002, 25.0, 800.0])  # N m per command unit: 1e-3 .. 1e3
    torque = log.series["torque_command"]
    log.series["torque_command"] = RawSeries(torque.stamps, torque.values / gains)
    path = tmp_path / "normalised.csv"
    write_log(path, log)
    vfile = tmp_path / "v.yaml"
    vfile.write_text("command_units: {torque: normalised}\n")
    veh = load_vehicle(vfile)
    assert veh.torque_normalised and not veh.force_normalised

    # effects named without inertia_error: it is added, and said so
    result = fit_model([path], veh, effects=["rotational_drag"], points=40, restarts=0)
    assert result.summary.added_effects == (GAIN_EFFECT,)
    assert list(result.model.effects) == ["rotational_drag", GAIN_EFFECT]
    assert any("inertia_error added" in n for n in result.summary.notes)
    gain = result.summary.torque_gain
    assert gain is not None and result.summary.torque_gain_stderr is not None
    print(f"gain {gain}, true {gains}, ratio {gain / gains}")
    np.testing.assert_allclose(gain, gains, rtol=0.10)
    assert np.all(result.summary.torque_gain_stderr < 0.1 * gains)
    first = np.array(result.model.provenance["torque_gain"]["first_pass_least_squares"])
    np.testing.assert_allclose(first, gains, rtol=0.10)
    # recovered within 10 %: the fit's table gives each gain's interval, not pinned-down
    from omavctl.cli.fit import _effects_table

    con = Console(width=300, record=True, file=io.StringIO())
    con.print(_effects_table(result.summary))
    gain_rows = [ln for ln in con.export_text().splitlines() if "= 1/scale_" in ln]
    assert len(gain_rows) == 3 and not any("cannot be pinned" in ln for ln in gain_rows)

    # the model's pointwise prediction uses the gain regressor (no unit mixing)
    model = result.model
    u = np.zeros((1, 6))
    u[0, 3:] = np.linalg.solve(vehicle.inertia, [1.0, 0.0, 0.0])  # I^-1 tau for tau_x = 1
    eff = model.effects_mean(u, np.zeros((1, 3)))
    np.testing.assert_allclose(eff[0, 0], (gain[0] - 1.0) / vehicle.inertia[0, 0], rtol=1e-9)

    # a model for normalised commands is refused for a vehicle with N m commands
    with pytest.raises(ModelError, match=r"commands in torque normalised, force N; this"):
        check_vehicle(model, default_vehicle())


# --- vehicle key ---------------------------------------------------------------------


def test_command_units_key(tmp_path: Path) -> None:
    assert default_vehicle().command_units == {"torque": "N m", "force": "N"}
    path = tmp_path / "v.yaml"
    path.write_text("command_units: {torque: Normalized, force: N}\n")
    assert load_vehicle(path).command_units == {"torque": "normalised", "force": "N"}
    cases = {
        "command_units: {torque: percent}\n": (
            "key 'command_units.torque' must be 'N m' or 'normalised', got 'percent'"
        ),
        "command_units: {force: 1.0}\n": (
            "key 'command_units.force' must be 'N' or 'normalised', got 1.0"
        ),
        "command_units: {thrust: normalised}\n": "unknown key 'command_units.thrust'",
        "command_units: normalised\n": "key 'command_units' must be a mapping",
    }
    for text, message in cases.items():
        path.write_text(text)
        with pytest.raises(ConfigError) as err:
            load_vehicle(path)
        assert str(err.value) == f"{path}: {message}"
