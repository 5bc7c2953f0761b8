"""The accelerometer (``specific_force`` role) and the moment of the force it measures
(``drag_moment``, #28): units through the example column maps of the shared real logs,
the bag round trip, the effect's regressor and truth torque, the refusal without an
accelerometer, and an open-loop rollout that holds the measured force at each
window's start (with a band that grows by how far that force moves)."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from omavctl.base.errors import LogError
from omavctl.diagnose.verdict_lines import flag_lines
from omavctl.learn import rollout_residual
from omavctl.learn.effect_fit import check_available
from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.rollout_residual import GridSignals, gather, held_spread, residual_function
from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs import read_raw
from omavctl.logs.types import FlightLog, RawSeries
from omavctl.physics.effects import EFFECTS, EffectContext
from omavctl.vehicle import load_vehicle
from tests.test_horizons import _model
from tests.test_readers import BF, CF, needs_real

EXAMPLES = Path(__file__).parents[1] / "examples"
G = 9.80665


@needs_real
def test_crazyflie_accelerometer_in_g_becomes_m_per_s2() -> None:
    vehicle = load_vehicle(EXAMPLES / "crazyflie.yaml")
    raw = read_raw(CF / "log15", vehicle.topics, vehicle.columns)
    with gzip.open(CF / "log15.csv.gz", "rt") as fh:
        names = fh.readline().strip().split(",")
        rows = np.loadtxt(fh, delimiter=",", max_rows=5)
    acc = rows[:, [names.index(f"acc.{a}") for a in "xyz"]]
    sf = raw.series["specific_force"].values
    assert sf.shape == (62774, 3)
    np.testing.assert_allclose(sf[:5], acc * G, rtol=1e-6)  # float32 cells, g -> m/s^2
    # body FLU, z up: the thrust's specific force reads +1.03 g in flight (README caveat)
    flying = raw.series["motor_command"].values[:, :4].mean(axis=1) > 20000
    assert 1.0 * G < np.median(sf[flying, 2]) < 1.08 * G


@needs_real
def test_betaflight_acc_smooth_in_acc_1g_units_becomes_m_per_s2() -> None:
    vehicle = load_vehicle(EXAMPLES / "betaflight-cs110.yaml")
    log = BF / "example_smooth_tune.csv.gz"  # a calm flight (better_tune punches to 3 g)
    assert "H acc_1G:2048" in (BF / "example_smooth_tune.headers.txt").read_text()
    raw = read_raw(log, vehicle.topics, vehicle.columns)
    sf = raw.series["specific_force"].values
    # the first row's accSmooth[0..2] (raw) are 67, 16, 2157: / acc_1G (the reader: g),
    # x the map's scale (m/s^2)
    np.testing.assert_allclose(sf[0], np.array([67.0, 16.0, 2157.0]) / 2048 * G, rtol=1e-15)
    flying = raw.series["motor_command"].values[:, :4].mean(axis=1) > 300
    assert 0.98 * G < np.median(sf[flying, 2]) < 1.1 * G


def _context(vehicle, force: np.ndarray | None) -> EffectContext:
    n = 4
    return EffectContext(
        omega=np.zeros((n, 3)),
        force=np.zeros((n, 3)),
        torque=np.zeros((n, 3)),
        omega_dot_nominal=np.zeros((n, 3)),
        inertia=vehicle.inertia,
        dt=0.002,
        allocation=None,  # type: ignore[arg-type]
        derivative=np.zeros_like,
        measured_force=force,
    )


def test_drag_moment_regressor_is_the_truth_torque_through_the_inertia(tmp_path) -> None:
    (tmp_path / "cf.yaml").write_text("preset: quad-x-crazyflie\n")
    vehicle = load_vehicle(tmp_path / "cf.yaml")
    effect = EFFECTS["drag_moment"]
    f = np.array([[0.01, 0.0, 0.3], [0.0, -0.02, 0.3], [0.005, 0.005, 0.0], [0, 0, 0]])
    x = effect.regressor(_context(vehicle, f))
    assert x.shape == (4, 3, 1)
    # h e_z x f = h (-f_y, f_x, 0): a forward force pitches, a force to the left rolls
    tau = effect.body_torque({"h": np.array([0.013])}, np.zeros((4, 3)), f)
    np.testing.assert_allclose(tau[0], [0.0, 0.013 * 0.01, 0.0], atol=1e-15)
    np.testing.assert_allclose(tau[1], [-0.013 * -0.02, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(x[:, :, 0] * 0.013, tau @ vehicle.inertia_inv.T, rtol=1e-12)
    assert not effect.simulated and effect.measured_state
    # without an accelerometer: zeros, and fit refuses it naming what to map
    assert np.all(effect.regressor(_context(vehicle, None)) == 0.0)


def _flight(vehicle, with_accelerometer: bool, n: int = 600) -> FlightLog:
    """A hovering quadrotor at 500 Hz whose lateral specific force ramps: roll torque
    commands, body rate their integral, a_y rising by 2 m/s^2 per s from 0.3 m/s^2."""
    rate = 500.0
    t = np.arange(n) / rate
    torque = np.zeros((n, 3))
    torque[:, 0] = 2e-4 * np.sin(2 * np.pi * 1.3 * t)
    omega = np.zeros((n, 3))
    omega[1:] = np.cumsum(torque[:-1] @ vehicle.inertia_inv.T, axis=0) / rate
    signals = {
        "body_rate": omega,
        "torque_command": torque,
        "force_command": np.tile([0.0, 0.0, vehicle.mass * 9.81], (n, 1)),
    }
    if with_accelerometer:
        sf = np.zeros((n, 3))
        sf[:, 1] = 0.3 + 2.0 * t
        sf[:, 2] = 9.81
        signals["specific_force"] = sf
    return FlightLog(Path("ramp.csv"), "csv", t, signals, np.ones(n, bool), [(0, n)], rate)


def test_fit_refuses_drag_moment_without_an_accelerometer(tmp_path) -> None:
    (tmp_path / "cf.yaml").write_text("preset: quad-x-crazyflie\n")
    vehicle = load_vehicle(tmp_path / "cf.yaml")
    sg = SavitzkyGolay(11, 2, 1.0 / 500.0)
    s = residual_samples(_flight(vehicle, False), vehicle, sg, effects=("drag_moment",))
    with pytest.raises(LogError) as err:
        check_available([s], ["drag_moment"])
    assert str(err.value) == (
        "ramp.csv: drag_moment needs the accelerometer: map the log's specific force "
        "(m/s^2, body) as the specific_force role (docs/logs.md)"
    )


def test_a_rollout_holds_the_measured_force_at_the_window_start(tmp_path, monkeypatch) -> None:
    (tmp_path / "cf.yaml").write_text("preset: quad-x-crazyflie\n")
    vehicle = load_vehicle(tmp_path / "cf.yaml")
    flight = _flight(vehicle, True)
    sg = SavitzkyGolay(11, 2, 1.0 / 500.0)
    s = residual_samples(flight, vehicle, sg, effects=("drag_moment",))
    check_available([s], ["drag_moment"])
    # the force is m (a - median a): the ramp about its middle
    (ctx, _), *_ = s.contexts
    a_y = flight.signals["specific_force"][:, 1]
    assert ctx.measured_force is not None
    np.testing.assert_allclose(ctx.measured_force[:, 1], vehicle.mass * (a_y - np.median(a_y)))
    h = 0.015
    est = EffectEstimate("drag_moment", {"h": np.array([h])}, {"h": np.zeros(1)})
    m = _model(vehicle, {"drag_moment": est})
    sig = flight.signals
    g = GridSignals(sig["body_rate"][s.index], sig["torque_command"][s.index], None)
    k = 25
    win = gather([s], [g], k, 7)
    per_step = -h * vehicle.mass * vehicle.inertia_inv[0, 0]  # roll acceleration per a_y
    at = a_y[s.index][win.pos] - np.median(a_y)  # (W, K + 1)
    residual = residual_function(m, win, [s], True)
    for step in (0, 10, k - 1):
        np.testing.assert_allclose(residual(step, win.omega[:, step])[:, 0], per_step * at[:, 0])
    # the band's share: the term moves by its slope times k steps on this ramp
    spread = held_spread(m, win, [s])
    assert spread is not None
    moved = np.abs(per_step) * 2.0 * np.arange(k + 1) / 500.0
    np.testing.assert_allclose(spread[:, :, 0], np.broadcast_to(moved, (win.count, k + 1)))
    # the oracle (benchmarks only) reads the window's future instead
    monkeypatch.setattr(rollout_residual, "HOLD_MEASURED", False)
    oracle = residual_function(m, win, [s], True)
    np.testing.assert_allclose(oracle(10, win.omega[:, 10])[:, 0], per_step * at[:, 10])
    assert held_spread(m, win, [s]) is None


def test_evaluate_refuses_a_drag_moment_model_on_a_log_without_an_accelerometer(
    tmp_path, vehicle, short_fig8
) -> None:
    """A model whose effect needs a signal the evaluated log lacks is refused in one line
    naming the log (before, the effect's regressor was zeros there and the model was
    scored as if it had no such effect); the same model on a log with it is evaluated."""
    from omavctl.diagnose.evaluate import evaluate
    from omavctl.learn.model_file import save_model
    from omavctl.logs import write_log
    from tests.conftest import fly

    log = tmp_path / "held.csv"
    flown = fly(vehicle, short_fig8, {"effects": {}}, seed=0).log
    write_log(log, flown)
    est = EffectEstimate("drag_moment", {"h": np.array([0.01])}, {"h": np.zeros(1)})
    model = tmp_path / "m.npz"
    save_model(model, _model(vehicle, {"drag_moment": est}))
    with pytest.raises(LogError) as err:
        evaluate([model], [log], horizons=())
    assert str(err.value) == (
        f"{log}: drag_moment needs the accelerometer: map the log's specific force "
        "(m/s^2, body) as the specific_force role (docs/logs.md)"
    )
    # the same flight with an accelerometer: evaluated; this model, like a file written
    # before fit recorded the lever arm (provenance.imu_lever), gets one warning naming
    # the file and saying to refit; one that records it, none (#28)
    rate = flown.series["body_rate"]
    level = np.tile([0.0, 0.0, G], (rate.stamps.size, 1))
    flown.series["specific_force"] = RawSeries(rate.stamps, level)
    write_log(imu := tmp_path / "imu.csv", flown)
    tree = evaluate([model], [imu], with_diagnosis=False, horizons=()).tree
    (flag,) = [f for f in tree["flags"] if f["code"] == "no_imu_lever"]
    assert flag["message"] == (
        f"{model}: drag_moment was fitted before omavctl recorded the accelerometer's lever "
        "arm (no provenance.imu_lever), so it may hold the lever's α × r + ω × (ω × r) as "
        "well as the force's moment: refit the model (omavctl fit on the same logs with "
        "--effects drag_moment), which removes the lever where the log pins it down, before "
        "trusting its numbers"
    )
    assert [ln.text for ln in flag_lines(tree) if ln.text == flag["message"]]
    recorded = _model(vehicle, {"drag_moment": est})
    recorded.provenance["imu_lever"] = [{"log": "fit.csv", "r": None, "stderr": None}]
    save_model(current := tmp_path / "current.npz", recorded)
    tree = evaluate([current], [imu], with_diagnosis=False, horizons=()).tree
    assert not [f for f in tree["flags"] if f["code"] == "no_imu_lever"]
