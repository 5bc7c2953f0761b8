"""The motor-level effects (thrust_curve, motor_loss, battery_sag) on synthetic motor logs.

The logs are synthesised here with numpy as in ``tests/test_motors.py`` (a vehicle
described by its YAML alone, each rotor's command hover plus random sines, the
rigid body integrated at 1 kHz), with the effect hidden in the true thrusts:
``fit --effects NAME`` must put the truth inside its 95 % interval, and
``evaluate`` of a model without it must name it (or an ambiguous set that holds
it) on another flight, and not on a flight without it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.base.errors import LogError
from omavctl.cli import app
from omavctl.learn.fit import fit_model
from omavctl.vehicle import Vehicle, load_vehicle

HEXA = """preset: hexa-x
columns:
  time: {column: time}
  body_rate: {x: gx, y: gy, z: gz}
  motor_command: [m0, m1, m2, m3, m4, m5]
"""
QUAD = """preset: quad-x-px4
columns:
  time: {column: time}
  body_rate: {x: gx, y: gy, z: gz}
  motor_command: [m0, m1, m2, m3]
"""
VBAT = "  battery_voltage: vbat\n"


def _vehicle(tmp_path: Path, text: str) -> tuple[Vehicle, Path]:
    path = tmp_path / "v.yaml"
    path.write_text(text)
    return load_vehicle(path), path


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, the same products and differences (bit for bit)
    without its axis handling, which took two thirds of a 20 s flight's synthesis."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def synthesise(
    vehicle: Vehicle,
    seed: int,
    curvature: float = 0.0,
    loss: tuple[float, ...] = (),
    sag: float = 0.0,
    damping: float = 8.0,
    duration: float = 20.0,
    rate: float = 100.0,
) -> dict[str, np.ndarray]:
    """A motor log: ``time`` (n,), ``gyro`` (n, 3) rad/s, ``cmd`` (n, R) PWM us, ``vbat`` (n,) V.

    Commands: hover, a collective swing (+-0.15 at 0.25 Hz, so that the thrust
    curve is seen at several operating points) and four random sines per rotor
    (0.2-3 Hz). True thrust per rotor: the curve's, bent by ``curvature``
    (``c T_full (x^2 - x)``), scaled by ``1 - loss_i`` and by
    ``1 + sag (V - 15.8 V)``; the voltage falls by 1.2 V over the flight and sags
    0.02 V per N of total thrust. A rate loop at ``rate`` adds to the commands
    the thrusts of the torque ``-damping I omega_measured`` (pseudo-inverse of the
    mixer), so that a weak motor does not spin the vehicle away. Gyro noise 2 mrad/s.
    """
    # the tests fly the same logs more than once (a fit's flight is the diagnosis's
    # training flight): each is synthesised once; the rotor list, not the columns, flies
    tree = {k: v for k, v in vehicle.tree.items() if k != "columns"}
    key = (json.dumps(tree, sort_keys=True, default=str), seed, curvature, tuple(loss), sag)
    key += (damping, duration, rate)
    if key not in _FLOWN:
        _FLOWN[key] = _synthesise(vehicle, seed, curvature, loss, sag, damping, duration, rate)
    return {k: v.copy() for k, v in _FLOWN[key].items()}


_FLOWN: dict[tuple[Any, ...], dict[str, np.ndarray]] = {}


def _synthesise(
    vehicle: Vehicle,
    seed: int,
    curvature: float,
    loss: tuple[float, ...],
    sag: float,
    damping: float,
    duration: float,
    rate: float,
) -> dict[str, np.ndarray]:
    motors = vehicle.motors
    assert motors is not None
    rng = np.random.default_rng(seed)
    n, sub, r = int(duration * rate), 10, motors.n_rotors
    t = np.arange(n) / rate
    k2 = motors.rotors[0].curve[2]
    x_hover = np.sqrt(vehicle.mass * vehicle.gravity / r / k2)
    x = np.full((n, r), x_hover) + 0.15 * np.sin(2 * np.pi * 0.25 * t)[:, None]
    for j in range(r):
        for f, ph in zip(rng.uniform(0.2, 3.0, 4), rng.uniform(0, 2 * np.pi, 4), strict=True):
            x[:, j] += 0.03 * np.sin(2 * np.pi * f * t + ph)
    mix = motors.wrench(np.eye(r))[1].T  # (3, R) torque per N of each rotor's thrust
    damp = -np.linalg.pinv(mix) @ (damping * vehicle.inertia) / (2.0 * k2 * x_hover)
    lost = 1.0 - np.pad(np.asarray(loss, float), (0, r - len(loss)))
    vbat = 16.4 - 1.2 * t / duration + 0.02 * r * k2 * x_hover**2
    dt = 1.0 / (rate * sub)
    inertia, inv = vehicle.inertia, vehicle.inertia_inv
    w = np.zeros(3)
    gyro, cmd = np.zeros((n, 3)), np.zeros((n, r))
    tau = np.zeros(3)
    for k in range(n * sub):
        if k % sub == 0:  # the rate loop: open-loop sines plus rate damping
            i = k // sub
            gyro[i] = w + 0.002 * rng.standard_normal(3)
            xi = x[i] + damp @ gyro[i]
            cmd[i] = 1000.0 + 1000.0 * xi
            thrust = motors.thrust(cmd[i : i + 1])[0] + curvature * k2 * (xi * xi - xi)
            vbat[i] -= 0.02 * thrust.sum()
            thrust *= lost * (1.0 + sag * (vbat[i] - 15.8))
            tau = motors.wrench(thrust[None])[1][0]
        w = w + dt * inv @ (tau - _cross(w, inertia @ w))
    return {"time": t, "gyro": gyro, "cmd": cmd, "vbat": vbat}


def write_log(path: Path, log: dict[str, np.ndarray]) -> Path:
    cmd = log["cmd"]
    header = "time,gx,gy,gz,vbat," + ",".join(f"m{i}" for i in range(cmd.shape[1]))
    data = np.c_[log["time"], log["gyro"], log["vbat"], cmd]
    np.savetxt(path, data, delimiter=",", header=header, comments="")
    return path


def _inside(value: np.ndarray, se: np.ndarray, truth: np.ndarray) -> bool:
    return bool(np.all(np.abs(np.asarray(value) - truth) <= 1.96 * np.asarray(se)))


def _diagnosis(tmp_path: Path, vfile: Path, train: Path, test: Path) -> dict:
    """``evaluate`` on ``test`` of a model fitted on ``train`` without effects."""
    runner = CliRunner()
    model = tmp_path / "m.npz"
    fit = ["fit", str(train), "--vehicle", str(vfile), "--out", str(model)]
    res = runner.invoke(app, [*fit, "--points", "60", "--restarts", "0"])
    assert res.exit_code == 0, res.output
    out = tmp_path / "e.json"
    # the diagnosis alone is read: no horizons table (open-loop rollouts), which it does
    # not depend on
    args = ["evaluate", str(test), "--model", str(model), "--horizons", "none"]
    res = runner.invoke(app, [*args, "--out", str(out)])
    assert res.exit_code == 0, res.output
    return dict(json.loads(out.read_text())["diagnosis"])


def _named(diag: dict) -> dict[str, list[str]]:
    """Effects the diagnosis names (missing, or learned by the GP and missing from the
    physics) and what each is ambiguous with."""
    entries = [e for e in diag["missing_effects"] if e["name"] in diag["missing"]]
    entries += [e for e in diag["learned"] if e["missing"]]
    return {e["name"]: list(e["ambiguous_with"]) for e in entries}


# --- thrust_curve ------------------------------------------------------------------


def test_thrust_curve_is_recovered_with_the_truth_in_its_interval(tmp_path: Path) -> None:
    veh, _ = _vehicle(tmp_path, HEXA)
    log = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, curvature=-0.4))
    est = fit_model([log], veh, effects=["thrust_curve"], points=60, restarts=0).model
    c = est.effects["thrust_curve"]
    value, se = c.values["c"], c.stderr["c"]
    assert _inside(value, se, np.array([-0.4])), (value, se)
    assert 0 < se[0] < 0.1, se
    # no curvature hidden: the estimate's interval holds 0
    clean = write_log(tmp_path / "b.csv", synthesise(veh, seed=2))
    c0 = fit_model([clean], veh, effects=["thrust_curve"], points=60, restarts=0).model
    est0 = c0.effects["thrust_curve"]
    assert _inside(est0.values["c"], est0.stderr["c"], np.array([0.0])), est0


def test_the_diagnosis_names_a_bent_thrust_curve_and_not_a_straight_one(tmp_path: Path) -> None:
    veh, vfile = _vehicle(tmp_path, HEXA)
    a = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, curvature=-0.4))
    b = write_log(tmp_path / "b.csv", synthesise(veh, seed=2, curvature=-0.4))
    named = _named(_diagnosis(tmp_path, vfile, a, b))
    assert "thrust_curve" in named or any("thrust_curve" in v for v in named.values()), named
    a0 = write_log(tmp_path / "a0.csv", synthesise(veh, seed=3))
    b0 = write_log(tmp_path / "b0.csv", synthesise(veh, seed=4))
    clean = _named(_diagnosis(tmp_path, vfile, a0, b0))
    assert "thrust_curve" not in clean, clean


# --- motor_loss --------------------------------------------------------------------


def test_a_weak_motor_is_recovered_with_the_truth_in_its_interval(tmp_path: Path) -> None:
    veh, _ = _vehicle(tmp_path, QUAD)
    loss = np.array([0.0, 0.15, 0.0, 0.0])
    truth = loss - loss.mean()  # relative to the rotors' mean: the mean is a gain
    log = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, loss=tuple(loss)))
    effects = ["inertia_error", "motor_loss"]
    model = fit_model([log], veh, effects=effects, points=60, restarts=0).model
    est = model.effects["motor_loss"]
    value, se = np.asarray(est.values["l"]), np.asarray(est.stderr["l"])
    assert _inside(value[:4], se[:4], truth), (value, se)
    # the mean loss is the torque gain's: inertia scale 1 / (1 - mean loss)
    gain = model.effects["inertia_error"]
    assert _inside(gain.values["scale"], gain.stderr["scale"], 1.0 / (1.0 - loss.mean())), gain
    assert int(np.argmax(value[:4])) == 1 and se[1] < 0.03, (value, se)
    assert abs(value.sum()) < 1e-9, value
    np.testing.assert_array_equal(value[4:], 0.0)  # a quad has 4 rotors of 12
    fit = ["fit", str(log), "--vehicle", str(tmp_path / "v.yaml"), "--effects", ",".join(effects)]
    out = ["--points", "60", "--restarts", "0", "--out", str(tmp_path / "m.npz")]
    res = CliRunner().invoke(app, [*fit, *out])
    assert res.exit_code == 0, res.output
    rows = [line for line in res.output.splitlines() if "motor_loss" in line and "│ l_" in line]
    # the quad's four rotors, not twelve (l_4 .. l_11 are rotors it lacks: eyes6)
    assert len(rows) == 4 and not any("not excited" in r for r in rows), rows


def test_a_weak_motor_of_a_quad_is_named_with_its_look_alikes(tmp_path: Path) -> None:
    """Near hover one weak motor of a quad is a constant torque: a centre-of-mass
    offset leaves the same on roll and pitch; the diagnosis names the loss or
    marks it ambiguous with what else explains it."""
    veh, vfile = _vehicle(tmp_path, QUAD)
    loss = (0.0, 0.15, 0.0, 0.0)
    a = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, loss=loss))
    b = write_log(tmp_path / "b.csv", synthesise(veh, seed=2, loss=loss))
    diag = _diagnosis(tmp_path, vfile, a, b)
    named = _named(diag)
    assert "motor_loss" in named or any("motor_loss" in v for v in named.values()), named
    scores = {e["name"]: e for e in diag["missing_effects"] + diag["learned"]}
    assert "com_offset" in scores["motor_loss"]["ambiguous_with"], scores["motor_loss"]
    a0 = write_log(tmp_path / "a0.csv", synthesise(veh, seed=3))
    b0 = write_log(tmp_path / "b0.csv", synthesise(veh, seed=4))
    assert "motor_loss" not in _named(_diagnosis(tmp_path, vfile, a0, b0))


# --- battery_sag -------------------------------------------------------------------


def test_battery_sag_is_recovered_with_the_truth_in_its_interval(tmp_path: Path) -> None:
    veh, _ = _vehicle(tmp_path, HEXA + VBAT)
    log = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, sag=0.12))
    model = fit_model([log], veh, effects=["battery_sag"], points=60, restarts=0).model
    est = model.effects["battery_sag"]
    assert _inside(est.values["k"], est.stderr["k"], np.array([0.12])), est
    assert est.stderr["k"][0] < 0.03, est


def test_the_diagnosis_names_battery_sag_only_where_it_is(tmp_path: Path) -> None:
    veh, vfile = _vehicle(tmp_path, HEXA + VBAT)
    a = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, sag=0.12))
    b = write_log(tmp_path / "b.csv", synthesise(veh, seed=2, sag=0.12))
    named = _named(_diagnosis(tmp_path, vfile, a, b))
    assert "battery_sag" in named, named
    a0 = write_log(tmp_path / "a0.csv", synthesise(veh, seed=3))
    b0 = write_log(tmp_path / "b0.csv", synthesise(veh, seed=4))
    assert "battery_sag" not in _named(_diagnosis(tmp_path, vfile, a0, b0))


def test_battery_sag_without_a_voltage_is_refused_in_one_line(tmp_path: Path) -> None:
    veh, vfile = _vehicle(tmp_path, HEXA)
    log = write_log(tmp_path / "a.csv", synthesise(veh, seed=1, duration=3.0))
    with pytest.raises(LogError) as err:
        fit_model([log], veh, effects=["battery_sag"], points=20, restarts=0)
    assert str(err.value) == (
        f"{log}: battery_sag needs the battery voltage: map the log's voltage column "
        "(e.g. Betaflight's vbatLatest) to battery_voltage in the vehicle's columns:"
    )
    fit = ["fit", str(log), "--vehicle", str(vfile), "--effects", "battery_sag", "--out"]
    res = CliRunner().invoke(app, [*fit, str(tmp_path / "m.npz")])
    assert res.exit_code == 2
    assert res.output.strip().splitlines()[-1].startswith(f"error: {log}: battery_sag needs")


def test_motor_effects_on_a_torque_level_log_are_refused(tmp_path: Path) -> None:
    """The omav's own logs hold a wrench command: nothing is mixed from motor outputs."""
    from test_fit import attitude_sines

    from omavctl.logs import write_log as write_contract_log
    from omavctl.sim.plant import simulate
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import default_vehicle

    omav = default_vehicle()
    ref = attitude_sines((10, 10, 10), (2, 2.6, 3), duration=2.0)
    path = tmp_path / "omav.csv"
    write_contract_log(path, simulate(ref, omav, truth_from_tree({"ideal": True}, omav)).log)
    for name in ("thrust_curve", "motor_loss"):
        with pytest.raises(LogError) as err:
            fit_model([path], omav, effects=[name], points=20, restarts=0)
        assert str(err.value) == (
            f"{path}: {name} needs a log of motor outputs mixed by the vehicle's rotor list "
            "(motors: in the vehicle, motor_command in the log)"
        )
