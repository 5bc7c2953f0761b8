"""Vehicles described by their rotors (``motors:``) and logs of motor outputs.

A hexa-X described by a YAML file alone: its motor log is synthesised here with
numpy (per-rotor first-order thrust lag, rigid body integrated at 1 kHz), then
``fit`` recovers the motor time constant, ``evaluate`` on another flight
names it when it is left out, and ``report`` renders the evaluation.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.base.errors import ConfigError
from omavctl.cli import app
from omavctl.learn.fit import fit_model
from omavctl.physics.actuator_effects import first_order_lag
from omavctl.physics.allocation import Allocation
from omavctl.vehicle import Vehicle, load_vehicle, preset_names

HEXA_YAML = """preset: hexa-x
columns:
  time: {column: time}
  body_rate: {x: gx, y: gy, z: gz}
  motor_command: [m0, m1, m2, m3, m4, m5]
"""


def _vehicle(tmp_path: Path, text: str, name: str = "v.yaml") -> tuple[Vehicle, Path]:
    path = tmp_path / name
    path.write_text(text)
    return load_vehicle(path), path


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, the same products and differences (bit for bit)
    without its axis handling, which took two thirds of a 20 s flight's synthesis."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def synthesise(
    vehicle: Vehicle, seed: int, lag: float, duration: float = 20.0, rate: float = 100.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A motor log of ``vehicle``: t (n,), gyro (n, 3) rad/s, PWM commands (n, rotors) us.

    Each rotor's command is hover plus four random sines (0.2-3 Hz); the thrust
    follows its setpoint with a first-order lag ``lag`` s (exact, at 1 kHz) and
    the body rate integrates ``I w' = tau - w x I w``; gyro noise 2 mrad/s.
    """
    motors = vehicle.motors
    assert motors is not None
    rng = np.random.default_rng(seed)
    n, sub = int(duration * rate), 10
    t = np.arange(n) / rate
    x_hover = np.sqrt(vehicle.mass * vehicle.gravity / motors.n_rotors / motors.rotors[0].curve[2])
    x = np.full((n, motors.n_rotors), x_hover)
    for j in range(motors.n_rotors):
        for f, ph in zip(rng.uniform(0.2, 3.0, 4), rng.uniform(0, 2 * np.pi, 4), strict=True):
            x[:, j] += 0.03 * np.sin(2 * np.pi * f * t + ph)
    cmd = 1000.0 + 1000.0 * x
    dt = 1.0 / (rate * sub)
    thrust = first_order_lag(np.repeat(motors.thrust(cmd), sub, axis=0), lag, dt)
    _, tau = motors.wrench(thrust)
    inertia, inv = vehicle.inertia, vehicle.inertia_inv
    w = np.zeros(3)
    gyro = np.zeros((n, 3))
    for k in range(n * sub):
        if k % sub == 0:
            gyro[k // sub] = w
        w = w + dt * inv @ (tau[k] - _cross(w, inertia @ w))
    return t, gyro + 0.002 * rng.standard_normal(gyro.shape), cmd


def write_motor_csv(path: Path, t: np.ndarray, gyro: np.ndarray, cmd: np.ndarray) -> Path:
    header = "time,gx,gy,gz," + ",".join(f"m{i}" for i in range(cmd.shape[1]))
    np.savetxt(path, np.c_[t, gyro, cmd], delimiter=",", header=header, comments="")
    return path


# --- the rotor list ---------------------------------------------------------------


def test_every_preset_loads_with_its_rotor_count(tmp_path: Path) -> None:
    rotors = {
        "quad-x-betaflight": 4,
        "quad-x-crazyflie": 4,
        "quad-x-px4": 4,
        "hexa-x": 6,
        "octo-x": 8,
        "coax-x8": 8,
        "omav": 12,
        "omav-rotors": 12,
    }
    assert set(preset_names()) == set(rotors)
    for name, count in rotors.items():
        veh, _ = _vehicle(tmp_path, f"preset: {name}\n")
        assert veh.motors is not None and veh.motors.n_rotors == count, name
        # a hover: equal thrusts give no torque (the layout is balanced)
        force, torque = veh.motors.wrench(np.ones((1, count)), np.zeros((1, 6)))
        np.testing.assert_allclose(torque, 0.0, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(force[0], [0.0, 0.0, count], atol=1e-9, err_msg=name)


def test_the_omav_preset_mixes_as_the_allocation(tmp_path: Path) -> None:
    veh, _ = _vehicle(tmp_path, "preset: omav\n")
    assert veh.motors is not None and veh.motors.tilting
    rng = np.random.default_rng(0)
    tilt = rng.uniform(-1.5, 1.5, (20, 6))
    thrust = rng.uniform(0.0, 15.0, (20, 12))
    force, torque = veh.motors.wrench(thrust, tilt)
    expected = Allocation(veh).forward(tilt, thrust)
    np.testing.assert_allclose(np.c_[force, torque], expected, atol=1e-4)


def test_crazyflie_yaw_and_roll_signs(tmp_path: Path) -> None:
    """m2 and m4 push +yaw (reaction +1 in the authors' table); m3, m4 (left) roll right."""
    veh, _ = _vehicle(tmp_path, "preset: quad-x-crazyflie\n")
    assert veh.motors is not None
    _, yaw = veh.motors.wrench(np.array([[0.0, 1.0, 0.0, 1.0]]))
    assert yaw[0, 2] > 0 and abs(yaw[0, 0]) < 1e-12
    _, roll = veh.motors.wrench(np.array([[0.0, 0.0, 1.0, 1.0]]))
    assert roll[0, 0] > 0  # thrust on the left (+y) rolls right-side down: +x in FLU
    # PWM 0..65535 -> thrust 0.15 x^2 N
    np.testing.assert_allclose(veh.motors.thrust(np.array([[65535.0, 0, 32767.5, 0]]))[0],
                               [0.15, 0.0, 0.0375, 0.0], rtol=1e-9)  # fmt: skip


@pytest.mark.parametrize(
    ("preset", "left", "rear", "cw"),
    [
        ("quad-x-betaflight", [2, 3], [0, 2], [0, 3]),  # motors 1 RR, 2 FR, 3 RL, 4 FL
        ("quad-x-px4", [1, 2], [1, 3], [2, 3]),  # 1 FR, 2 RL, 3 FL, 4 RR
        ("quad-x-crazyflie", [2, 3], [1, 2], [1, 3]),  # m1 FR, m2 RR, m3 RL, m4 FL
    ],
)
def test_quad_presets_turn_the_way_their_flight_controllers_mix(
    tmp_path: Path, preset: str, left: list[int], rear: list[int], cw: list[int]
) -> None:
    """Raising the left motors rolls right side down (+x in FLU), the rear ones pitches
    nose down (+y), the clockwise ones yaws nose left (+z): Betaflight's mixerQuadX,
    PX4's quad-X and the Crazyflie's yaw reaction table."""
    veh, _ = _vehicle(tmp_path, f"preset: {preset}\n")
    assert veh.motors is not None
    for axis, motors in enumerate((left, rear, cw)):
        thrust = np.zeros((1, 4))
        thrust[0, motors] = 1.0
        thrust[0, [i for i in range(4) if i not in motors]] = -1.0
        _, torque = veh.motors.wrench(thrust)
        assert torque[0, axis] > 0, (preset, axis)
        others = [a for a in range(3) if a != axis]
        np.testing.assert_allclose(torque[0, others], 0.0, atol=1e-12)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("preset: quad-x-nope\n", "unknown preset 'quad-x-nope' in 'preset' (known: coax-x8"),
        (
            "motors: {unit: pwm_us, thrust_curve: [0, 0, 1], rotors: [{position: [1, 0, 0]}]}\n",
            "key 'motors.rotors[0].spin' is missing",
        ),
        (
            "motors: {unit: volts, thrust_curve: [0, 1], rotors: [{position: [1, 0, 0], "
            "spin: cw}]}\n",
            "key 'motors.unit' must be one of pwm_us, dshot, pwm16, normalised, rad/s, rpm, "
            "got 'volts'",
        ),
        (
            "preset: hexa-x\nmotors: {unit: dshot, thrust_curve: [0, 1], rotors: "
            "[{position: [1, 0], spin: cw}]}\n",
            "key 'motors.rotors[0].position' must be 3 numbers",
        ),
        (
            "motors: {unit: rpm, wrench_from: cmd, thrust_curve: {k: 1.0e-7}, rotors: "
            "[{position: [1, 0, 0], spin: cw}]}\n",
            "key 'motors.wrench_from' must be log or rotors, got 'cmd'",
        ),
        (
            "motors: {unit: pwm16, thrust_curve: [1.0], rotors: [{position: [1, 0, 0], "
            "spin: cw}]}\n",
            "key 'motors.thrust_curve' gives no thrust change with the command",
        ),
        (
            "motors: {unit: pwm16, thrust_curve: [0, 1], rotors: [{position: [1, 0, 0], "
            "spin: cw}, {position: [0, 1, 0], spin: ccw, output: 0}]}\n",
            "key 'motors.rotors[1].output' = 0 is also rotor 0's",
        ),
        (
            "motors: {unit: pwm16, thrust_curve: [0, 1], rotors: [{position: [1, 0, 0], "
            "spin: left}]}\n",
            "key 'motors.rotors[0].spin' must be cw or ccw, got 'left'",
        ),
    ],
)
def test_a_bad_rotor_list_is_one_line_naming_the_file_and_key(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert str(err.value).startswith(f"{path}: {message}")
    assert "\n" not in str(err.value)


# --- inspect suggests the map and the preset --------------------------------------------


def _table(path: Path, header: list[str], columns: dict[str, np.ndarray]) -> Path:
    n = len(next(iter(columns.values())))
    rows = [",".join(repr(float(columns[h][i])) if h in columns else "0" for h in header)
            for i in range(n)]  # fmt: skip
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize(
    ("header", "time", "gyro", "motors", "scale", "preset", "unit"),
    [
        (
            "timestamp,acc.x,acc.y,acc.z,gyro.x,gyro.y,gyro.z,motor.m1,motor.m2,motor.m3,motor.m4",
            ("timestamp", 1.0),
            ["gyro.x", "gyro.y", "gyro.z"],
            ["motor.m1", "motor.m2", "motor.m3", "motor.m4"],
            30000.0,
            "quad-x-crazyflie",
            "pwm16",
        ),
        (
            "loopIteration,time,axisP[0],axisP[1],axisP[2],rcCommand[0],rcCommand[1],"
            "rcCommand[2],rcCommand[3],vbatLatest,gyroADC[0],gyroADC[1],gyroADC[2],"
            "motor[0],motor[1],motor[2],motor[3]",
            ("time", 500.0),
            ["gyroADC[0]", "gyroADC[1]", "gyroADC[2]"],
            ["motor[0]", "motor[1]", "motor[2]", "motor[3]"],
            300.0,
            "quad-x-betaflight",
            "dshot",
        ),
        (
            "timestamp,gyro_x,gyro_y,gyro_z,actuator_outputs.output[0],"
            "actuator_outputs.output[1],actuator_outputs.output[2],actuator_outputs.output[3],"
            "actuator_outputs.output[4],actuator_outputs.output[5]",
            ("timestamp", 4000.0),
            ["gyro_x", "gyro_y", "gyro_z"],
            [f"actuator_outputs.output[{i}]" for i in range(4)],
            1500.0,
            "quad-x-px4",
            "pwm_us",
        ),
    ],
)
def test_inspect_suggests_motor_outputs_and_the_preset(
    tmp_path: Path,
    header: str,
    time: tuple[str, float],
    gyro: list[str],
    motors: list[str],
    scale: float,
    preset: str,
    unit: str,
) -> None:
    """Header names as the loggers write them; gyro in deg/s, outputs 5 and 6 unused."""
    rng = np.random.default_rng(0)
    n = 300
    cols = {time[0]: np.arange(n) * time[1]}
    for g in gyro:
        cols[g] = rng.normal(0.0, 80.0, n)
    for m in motors:
        cols[m] = scale + 0.1 * scale * rng.random(n)
    log = _table(tmp_path / "log.csv", header.split(","), cols)
    res = CliRunner().invoke(app, ["inspect", str(log), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    columns = out["suggested_columns"]
    assert columns["motor_command"] == motors
    assert columns["body_rate"]["x"] == gyro[0]
    assert "torque_command" not in columns and "force_command" not in columns
    assert preset in preset_names()
    text = res.stderr
    assert f"preset: {preset}" in text and f"motor commands look like {unit}" in text
    # the preset already declares the unit: the user is told there is nothing to add
    assert f"preset {preset} declares that" in text and "nothing to add" in text
    # the suggestion, pasted into a vehicle file, reads the log and mixes its outputs
    suggestion = text[text.index("# Column map GUESSED") :]
    vfile = tmp_path / "v.yaml"
    vfile.write_text(suggestion.replace("frame: FLU", "frame: FLU\n", 1))
    veh = load_vehicle(vfile)
    assert veh.motors is not None and len(veh.columns["motor_command"]) == len(motors)
    res = CliRunner().invoke(app, ["inspect", str(log), "--vehicle", str(vfile), "--json"])
    assert res.exit_code == 0, res.output
    roles = json.loads(res.stdout)["roles_found"]
    assert "computed from motor_command" in roles["torque_command"]


# --- a hexa-X from its YAML alone: fit, evaluate, report --------------------------------


def test_hexa_fit_recovers_the_motor_time_constant_from_a_motor_log(tmp_path: Path) -> None:
    veh, _ = _vehicle(tmp_path, HEXA_YAML)
    log = write_motor_csv(tmp_path / "a.csv", *synthesise(veh, seed=1, lag=0.04))
    result = fit_model([log], veh, effects=["motor_lag"], points=60, restarts=0)
    est = result.model.effects["motor_lag"]
    t_m = float(np.asarray(est.values["T_m"])[0])
    assert abs(t_m - 0.04) < 0.002, t_m
    # with the lag the physics explains the flight: what is left is gyro noise
    assert all(a.cv_rmse_physics < 0.05 for a in result.summary.axes)


def test_hexa_evaluate_names_the_lag_and_report_renders(tmp_path: Path) -> None:
    veh, vfile = _vehicle(tmp_path, HEXA_YAML)
    a = write_motor_csv(tmp_path / "a.csv", *synthesise(veh, seed=1, lag=0.04))
    b = write_motor_csv(tmp_path / "b.csv", *synthesise(veh, seed=2, lag=0.04))
    runner = CliRunner()
    model = tmp_path / "m.npz"
    fit = ["fit", str(a), "--vehicle", str(vfile), "--out", str(model)]
    res = runner.invoke(app, [*fit, "--points", "60", "--restarts", "0"])
    assert res.exit_code == 0, res.output
    out = tmp_path / "e.json"
    res = runner.invoke(app, ["evaluate", str(b), "--model", str(model), "--out", str(out)])
    assert res.exit_code == 0, res.output
    evaluation = json.loads(out.read_text())
    diag = evaluation["diagnosis"]
    assert any("no attitude in the log" in n for n in evaluation["logs"][0]["notes"])
    # missing (its remaining error) or learned by the GP, and not taken for a delay
    entries = [e for e in diag["missing_effects"] if e["name"] in diag["missing"]]
    entries += diag["learned"]
    named = [e["name"] for e in entries if e["missing"]]
    assert "motor_lag" in named, diag
    entry = next(e for e in entries if e["name"] == "motor_lag")
    assert "command_delay" not in entry["ambiguous_with"]
    assert abs(entry["parameters"]["T_m"][0] - 0.04) < 0.012
    html = tmp_path / "r.html"
    res = runner.invoke(app, ["report", str(out), "--out", str(html)])
    assert res.exit_code == 0, res.output
    assert "motor_lag" in html.read_text()


def test_a_log_with_motor_outputs_needs_a_rotor_list(tmp_path: Path) -> None:
    veh, _ = _vehicle(tmp_path, HEXA_YAML)
    log = write_motor_csv(tmp_path / "a.csv", *synthesise(veh, seed=1, lag=0.0, duration=2.0))
    plain = tmp_path / "plain.yaml"
    plain.write_text(HEXA_YAML.replace("preset: hexa-x\n", ""))
    res = CliRunner().invoke(app, ["fit", str(log), "--vehicle", str(plain), "--out", "m.npz"])
    assert res.exit_code == 2
    assert "motor_command cannot be mixed without the vehicle's rotors" in res.output


def test_simulate_and_plan_refuse_a_vehicle_of_fixed_rotors(tmp_path: Path) -> None:
    veh, vfile = _vehicle(tmp_path, HEXA_YAML)
    runner = CliRunner()
    task = tmp_path / "t.csv"
    assert runner.invoke(app, ["task", "fig8", "--out", str(task)]).exit_code == 0
    res = runner.invoke(
        app, ["simulate", "--reference", str(task), "--vehicle", str(vfile), "--out", "s.csv"]
    )
    assert res.exit_code == 2
    assert res.output.strip().splitlines()[-1] == (
        f"error: {vfile}: simulate flies only the omav (six tilting arms); this vehicle's "
        "6 fixed rotors (motors:) are for fit, evaluate and report"
    )
    log = write_motor_csv(tmp_path / "a.csv", *synthesise(veh, seed=1, lag=0.0, duration=4.0))
    model = fit_model([log], veh, points=20, restarts=0).model
    from omavctl.learn.model_file import save_model

    path = tmp_path / "m.npz"
    save_model(path, model)
    res = runner.invoke(app, ["plan", "--task", str(task), "--model", str(path), "--out", "p.csv"])
    assert res.exit_code == 2
    assert "plan flies only the omav (six tilting arms)" in res.output
    assert not (tmp_path / "p.csv").exists()


def test_the_omav_preset_mixes_measured_rotor_speeds_into_the_logged_wrench(
    tmp_path: Path,
) -> None:
    """A simulated omav flight with ideal actuators, written without its wrench command:
    the omav preset gets it back from the rotor speeds and tilts (its /omav/actuators).
    A row records the actuators where they are at its instant: ideal actuators there
    hold the command of the row before (the row's own command acts from its instant on)."""
    from test_fit import attitude_sines

    from omavctl.logs import read_vehicle_log, write_log
    from omavctl.physics.mixer import wrench_hook
    from omavctl.sim.plant import simulate
    from omavctl.sim.truth import truth_from_tree

    omav, _ = _vehicle(tmp_path, "preset: omav\n")
    ref = attitude_sines((20, 20, 30), (2, 2.6, 3), duration=3.0)
    log = simulate(ref, omav, truth_from_tree({"ideal": True}, omav), seed=0).log
    wrench = {k: log.series.pop(k) for k in ("force_command", "torque_command")}
    path = tmp_path / "actuators.csv"
    write_log(path, log)
    flight = read_vehicle_log(path, omav, required=("body_rate",), wrench=wrench_hook(omav))
    assert any("computed from rotor" in n for n in flight.notes)
    # the logged command at the grid times (the CSV's rows are the controller's)
    stamps = wrench["torque_command"].stamps - wrench["torque_command"].stamps[0]
    for role in ("force_command", "torque_command"):
        want = np.array([np.interp(flight.t, stamps, c) for c in wrench[role].values.T]).T
        got = flight.signals[role]
        mid = slice(10, -10)
        err = np.abs(got[1:][mid] - want[:-1][mid]).max()
        assert err < 0.02 * np.abs(want[mid]).max() + 1e-6, (role, err)
        # not the row's own command: on these sines that is a row of change away
        assert np.abs(got[mid] - want[mid]).max() > 2 * err, role


def test_motor_command_round_trips_through_the_wide_csv(tmp_path: Path) -> None:
    from omavctl.logs import RawLog, RawSeries, read_log, write_log

    t = np.arange(50) / 100.0
    cmd = np.zeros((50, 18))
    cmd[:, :4] = 1000.0 + np.random.default_rng(0).uniform(0, 1000, (50, 4))
    series = {
        "body_rate": RawSeries(t, np.zeros((50, 3))),
        "motor_command": RawSeries(t, cmd),
    }
    path = tmp_path / "m.csv"
    write_log(path, RawLog(tmp_path / "src", "synthetic", 0.0, series))
    header = path.read_text().splitlines()[0].split(",")
    assert header[-18:] == [f"motor_command_{i}" for i in range(18)]
    log = read_log(path, required=("body_rate", "motor_command"))
    np.testing.assert_array_equal(log.signals["motor_command"], cmd)


REAL = Path(__file__).parents[2] / "shared/data/real"
CF_LOG15 = REAL / "arpl_crazyflie/log15"
needs_crazyflie = pytest.mark.skipif(
    not CF_LOG15.exists(),
    reason=f"real Crazyflie log not available at {CF_LOG15} (shared test data not mounted)",
)


@needs_crazyflie
def test_the_crazyflie_roll_pitch_window_shows_a_motor_lag_of_tens_of_ms() -> None:
    """log15's roll/pitch window through examples/crazyflie.yaml: the mixed torque
    explains almost none of the roll and pitch acceleration as commanded, most of it
    through a 60 ms first-order lag (docs/real-motors.md, benchmarks/motor_lag_scan.py)."""
    from omavctl.learn.flights import read_flights
    from omavctl.learn.signal import SavitzkyGolay

    veh = load_vehicle(Path(__file__).parents[1] / "examples/crazyflie.yaml")
    flight = read_flights([CF_LOG15], veh, (15.76, 50.76))[0]
    assert flight.rate == 500.0 and "attitude" not in flight.signals
    sg = SavitzkyGolay(11, 2, flight.dt)

    def r2(lag: float) -> np.ndarray:
        xs, ys = [], []
        for a, b in flight.segments:
            if b - a < 5 * sg.window:
                continue
            torque = first_order_lag(flight.signals["torque_command"][a:b], lag, flight.dt)
            xs.append(sg.hold(torque @ veh.inertia_inv.T)[5:-5, :2])
            ys.append(sg.derivative(flight.signals["body_rate"][a:b])[5:-5, :2])
        x, y = np.concatenate(xs), np.concatenate(ys)
        gain = (x * y).sum(0) / (x * x).sum(0)
        return np.asarray(1.0 - ((y - gain * x) ** 2).sum(0) / (y**2).sum(0))

    assert np.all(r2(0.0) < 0.1)
    assert np.all(r2(0.06) > 0.75)
