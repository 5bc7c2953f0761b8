"""Truth plant: closed-loop flight, nominal consistency, hidden effects, truth YAML."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import NO_NOISE, fly, on_grid
from scipy.signal import savgol_coeffs, savgol_filter

from omavctl.base.errors import ConfigError
from omavctl.logs.types import ROLE_COLUMNS
from omavctl.physics.allocation import Allocation
from omavctl.physics.effects import EFFECTS, EffectContext
from omavctl.physics.rigid_body import angular_acceleration
from omavctl.sim.truth import load_truth, truth_from_tree

WINDOW, ORDER, DT = 5, 2, 0.01


def _residual(vehicle, result, inertia=None):
    """SG derivative of the gyro minus the nominal model on the 100 Hz controller grid.

    The torque command is held over each 10 ms control period, so the centred
    derivative at t_k is compared with the mean of the nominal accelerations of
    the periods before and after t_k.
    """
    s = result.log.series
    tc = s["torque_command"]
    w = on_grid(s["body_rate"], tc.stamps)
    d = savgol_filter(w, WINDOW, ORDER, deriv=1, delta=DT, axis=0)
    nominal = angular_acceleration(w, tc.values, vehicle.inertia, vehicle.inertia_inv)
    nominal[1:] = 0.5 * (nominal[1:] + nominal[:-1])
    keep = slice(WINDOW, -WINDOW)
    return w[keep], d[keep] - nominal[keep], s["force_command"].values[keep], tc.values[keep]


def test_closed_loop_tracks_the_task_through_imperfect_actuators(vehicle, short_fig8):
    result = fly(vehicle, short_fig8, {})
    assert not result.diverged
    assert np.rad2deg(result.max_attitude_error) < 3.0
    att = result.log.series["attitude"].values
    assert np.rad2deg(np.abs(att[:, :2]).max()) == pytest.approx(20.0, abs=2.0)


def test_a_faster_controller_is_not_called_infeasible_for_its_step(vehicle):
    """The same figure-8 under a 100 Hz and a 1 kHz controller: the share of flight
    time spent beyond the actuator limits is about the same. Judged per 1 ms step,
    the tilt's noise jitter read as an impossible tilt rate and 96 % of the 1 kHz
    steps were counted infeasible (9 of 1201 at 100 Hz)."""
    from omavctl.sim.tasks import fig8

    ref = fig8(duration=12.0)
    seconds = {}
    for hz in (100.0, 1000.0):
        result = fly(vehicle, ref, {"timing": {"controller_rate_hz": hz}}, seed=1)
        assert np.rad2deg(result.max_attitude_error) < 3.0
        seconds[hz] = result.infeasible_steps / hz
    assert 0.0 < seconds[100.0] < 0.5
    assert seconds[1000.0] < 2.0 * seconds[100.0]


def test_log_has_every_role_at_contract_rates(vehicle, short_fig8):
    log = fly(vehicle, short_fig8, {}).log
    # every contract role, none left out, but the raw motor outputs (a column-map role
    # of CSV and ULog logs, no bag topic): the omav logs its actuators as rotor speeds
    # and tilt angles, and its battery voltage (/omav/battery)
    # (nor an accelerometer: the plant has no translational drag to measure)
    expected = set(ROLE_COLUMNS) - {"motor_command", "specific_force"}
    assert set(log.series) == expected
    volts = log.series["battery_voltage"].values[:, 0]
    assert volts.shape == log.series["attitude"].stamps.shape and volts[-1] < volts[0]
    assert np.median(np.diff(log.series["body_rate"].stamps)) == pytest.approx(0.005)
    assert np.median(np.diff(log.series["attitude"].stamps)) == pytest.approx(0.01)
    assert log.series["rotor"].values.shape[1] == 12 and log.series["tilt"].values.shape[1] == 6


def test_ideal_plant_matches_nominal_model_within_the_noise(vehicle, short_fig8):
    gyro_noise = 0.003
    result = fly(vehicle, short_fig8, {"ideal": True, "noise": {**NO_NOISE, "gyro": gyro_noise}})
    _, res, _, _ = _residual(vehicle, result)
    expected = gyro_noise * np.linalg.norm(savgol_coeffs(WINDOW, ORDER, deriv=1, delta=DT))
    rms = np.sqrt(np.mean(res**2, axis=0))
    assert np.all(rms < 1.15 * expected + 0.01), (rms, expected)
    # and without noise the residual is tiny compared with the accelerations flown
    _, res0, _, _ = _residual(vehicle, fly(vehicle, short_fig8, {"ideal": True, "noise": NO_NOISE}))
    assert np.sqrt(np.mean(res0**2)) < 0.01


def test_imperfections_create_a_residual(vehicle, short_fig8):
    _, res, _, _ = _residual(vehicle, fly(vehicle, short_fig8, {"noise": NO_NOISE}))
    assert np.sqrt(np.mean(res**2)) > 0.05


@pytest.mark.parametrize(
    ("name", "params", "axes"),
    [
        # the figure-8 has no yaw motion: D_z is not excited, only x and y are checked
        ("rotational_drag", {"D": [0.03, 0.03, 0.02]}, [0, 1]),
        ("com_offset", {"r": [0.01, -0.015, 0.0]}, [0, 1, 2]),
    ],
)
def test_hidden_torque_effect_is_recoverable_by_least_squares(
    vehicle, short_fig8, name, params, axes
):
    truth = {"ideal": True, "noise": NO_NOISE, "effects": {name: params}}
    w, res, force, torque = _residual(vehicle, fly(vehicle, short_fig8, truth))
    effect = EFFECTS[name]
    ctx = EffectContext(
        omega=w,
        force=force,
        torque=torque,
        omega_dot_nominal=angular_acceleration(w, torque, vehicle.inertia, vehicle.inertia_inv),
        inertia=vehicle.inertia,
        dt=DT,
        allocation=Allocation(vehicle),
        derivative=lambda y: np.gradient(y, DT, axis=0),
    )
    x = effect.regressor(ctx).reshape(-1, effect.n_theta)
    theta, *_ = np.linalg.lstsq(x, res.reshape(-1), rcond=None)
    true = np.asarray(next(iter(params.values())))
    np.testing.assert_allclose(theta[axes], true[axes], rtol=0.1, atol=1e-3)


def test_same_seed_same_flight_other_seed_other_noise(vehicle, short_fig8):
    a = fly(vehicle, short_fig8, {}, seed=4).log.series["body_rate"].values
    b = fly(vehicle, short_fig8, {}, seed=4).log.series["body_rate"].values
    c = fly(vehicle, short_fig8, {}, seed=5).log.series["body_rate"].values
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_truth_effects_change_the_plant(vehicle):
    truth = truth_from_tree(
        {
            "effects": {
                "inertia_error": {"scale": [1.2, 1.0, 0.8]},
                "servo_lag": {"T_s": 0.05},
                "motor_lag": {"T_m": 0.04},
            }
        },
        vehicle,
    )
    np.testing.assert_allclose(np.diag(truth.inertia), np.diag(vehicle.inertia) * [1.2, 1.0, 0.8])
    assert truth.servo_time_constant == 0.05 and truth.motor_time_constant == 0.04


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("foo: 1\n", "unknown key 'foo'"),
        ("actuators: {servo_lag: 1}\n", "unknown key 'actuators.servo_lag'"),
        ("effects: {wind: {v: 1}}\n", "unknown effect 'wind'"),
        (
            "effects: {rotational_drag: {D: [1, 2]}}\n",
            "'effects.rotational_drag.D' must be 3 finite number(s)",
        ),
        (
            "effects: {rotational_drag: {C: [1, 2, 3]}}\n",
            "unknown parameter 'effects.rotational_drag.C'",
        ),
        ("noise: {gyro: -1}\n", "'noise.gyro' must be >= 0"),
        ("- a\n- b\n", "top level must be a mapping"),
    ],
)
def test_bad_truth_yaml_is_one_clear_error(vehicle, tmp_path, text, message):
    path = tmp_path / "truth.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_truth(path, vehicle)
    assert str(err.value).startswith(f"{path}: ")
    assert message in str(err.value)


def test_the_plants_scalar_controller_is_the_batched_one(vehicle, short_fig8):
    """The truth plant's controller and allocation on Python floats give the batched
    Controller's and Allocation's commands (no model) to 1e-12, integrators and their
    anti-windup clamp included, over states that wander and saturate them."""
    from omavctl.physics.controller import Controller, ControllerState
    from omavctl.sim.scalar import ScalarAllocation, ScalarController

    rng = np.random.default_rng(7)
    alloc = Allocation(vehicle)
    batched, state = Controller(vehicle), ControllerState.zeros(1)
    scalar, scalar_alloc = ScalarController(vehicle), ScalarAllocation(alloc)
    refs = short_fig8.sample(np.linspace(short_fig8.t[0], short_fig8.t[-1], 300))
    x = np.zeros(12)
    prev = np.zeros(6)
    clamped = 0
    for ref in refs:
        x = x + rng.normal(0.0, [0.05] * 3 + [0.03] * 3 + [0.1] * 3 + [0.3] * 3)
        x[3:6] = np.clip(x[3:6], -0.8, 0.8)
        out = batched.step(state, x[None, :], ref[None, :], 0.01)
        one = scalar.step(x.tolist(), ref.tolist(), 0.01)
        for a, b in zip(
            (out.force, out.torque, out.desired_angular, out.desired_linear),
            (one.force, one.torque, one.desired_angular, one.desired_linear),
            strict=True,
        ):
            np.testing.assert_allclose(b, a[0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(scalar.att_integral, state.att_integral[0], atol=1e-15)
        np.testing.assert_allclose(scalar.pos_integral, state.pos_integral[0], atol=1e-15)
        clamped += int(np.any(np.abs(state.pos_integral) >= 0.5))
        wrench = np.concatenate([out.force[0], out.torque[0]])
        res = alloc.allocate(wrench[None, :], prev[None, :])
        tilt, rotor, ok = scalar_alloc.allocate(wrench.tolist(), prev.tolist())
        np.testing.assert_allclose(tilt, res.tilt[0], atol=1e-12)
        np.testing.assert_allclose(rotor, res.rotor_thrust[0], rtol=1e-12)
        assert ok == bool(res.feasible[0])
        too_fast = alloc.tilt_rate_exceeded(res.tilt[0], prev, 0.01).any()
        assert scalar_alloc.rate_exceeded(tilt, prev.tolist(), 0.01) == too_fast
        prev = res.tilt[0]
    assert clamped > 10  # the anti-windup clamp was exercised
