"""Loss of control judged by tracking and actuator limits, not by the residual:
aggressive controlled flights keep their samples (where a missing drag shows),
flights that lose control are still cut at the loss."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from benchmarks.never_hurts import attitude_steps
from omavctl.cli import app
from omavctl.learn.control_loss import (
    PERSIST_SECONDS,
    TRACKING_FLOOR,
    flight_control_loss,
    out_of_control,
    settling_time,
    tracking_allowance,
    wrench_saturated,
)
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs import align, write_log
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8, wobble
from omavctl.sim.truth import truth_from_tree

runner = CliRunner()
DRAG = {"effects": {"rotational_drag": {"D": [0.05, 0.05, 0.03]}}}


def _loss(vehicle, log):
    s = residual_samples(log, vehicle, SavitzkyGolay(11, 2, 0.01))
    return flight_control_loss(log, s.index, s.omega, s.omega_dot, vehicle), s


def test_settling_time_and_allowance_follow_the_gains_and_the_reference(vehicle):
    # kp 64, kd 16: critically damped at 8 rad/s, 5.8 / 8 s
    assert settling_time(vehicle) == pytest.approx(5.8 / 8.0)
    slow = replace(vehicle, gains=replace(vehicle.gains, att_kp=np.full(3, 16.0)))
    assert settling_time(slow) > settling_time(vehicle)  # softer loop: longer lag allowed
    # a 40 deg roll step at 1 s: right after it the vehicle may be 40 deg behind,
    # after the settling time only the floor remains
    t = np.arange(300) / 100.0
    ref = np.zeros((300, 3))
    ref[t >= 1.0, 0] = np.deg2rad(40.0)
    allowed = tracking_allowance(ref, 0.01, vehicle)
    assert allowed[50] == pytest.approx(TRACKING_FLOOR)
    assert allowed[100] == pytest.approx(TRACKING_FLOOR + np.deg2rad(40.0))
    assert allowed[100 + 71] == pytest.approx(TRACKING_FLOOR + np.deg2rad(40.0))
    assert allowed[100 + 72] == pytest.approx(TRACKING_FLOOR)


def test_a_tracking_error_must_persist_to_be_a_loss(vehicle):
    t = np.arange(500) / 100.0
    zeros = np.zeros((500, 3))
    allowance = np.full(500, TRACKING_FLOOR)
    error = np.zeros(500)
    error[100:110] = 1.0  # 0.1 s beyond: a glitch the loop recovers from
    assert not out_of_control(t, zeros, zeros, vehicle, (error, allowance)).any
    error[300 : 300 + round(PERSIST_SECONDS * 100) + 5] = 1.0  # persists
    loss = out_of_control(t, zeros, zeros, vehicle, (error, allowance))
    ((start, end, why),) = loss.spans
    assert start == pytest.approx(2.5)  # onset 0.5 s before
    assert end == pytest.approx(t[300 + round(PERSIST_SECONDS * 100) + 4])
    assert why.startswith("attitude error beyond what the controller's gains")
    assert loss.mask.sum() == 50 + round(PERSIST_SECONDS * 100) + 5  # onset + the run
    error[440:] = 1.0  # a loss within MERGE_SECONDS of the end: the rest of the log is the crash
    (_, (_, end, _)) = out_of_control(t, zeros, zeros, vehicle, (error, allowance)).spans
    assert end == pytest.approx(t[-1])


def test_saturation_is_judged_on_commands_in_newtons_only(vehicle, short_fig8):
    """A normalised command's scale is unknown (a PX4 torque in +-1, or tau / 0.002):
    no limit is judged on it; the same numbers in N m are far beyond the rotors."""
    log = align(simulate(short_fig8, vehicle, truth_from_tree({}, vehicle), seed=0).log)
    signals = dict(log.signals)
    signals["torque_command"] = signals["torque_command"] / 0.002
    scaled = replace(log, signals=signals)
    s = residual_samples(log, vehicle, SavitzkyGolay(11, 2, 0.01))
    args = (s.index, s.omega, s.omega_dot)
    normalised = replace(vehicle, command_units={"torque": "normalised", "force": "N"})
    assert not flight_control_loss(scaled, *args, normalised).any
    (span,) = flight_control_loss(scaled, *args, vehicle).spans
    assert "actuators' limits" in span[2]


def test_wrench_saturation_is_the_allocations_thrust_limit(vehicle):
    hover = np.array([[0.0, 0.0, vehicle.mass * 9.81]])
    assert not wrench_saturated(hover, np.zeros((1, 3)), vehicle).any()
    torque = 2 * vehicle.n_arms * vehicle.max_thrust * vehicle.arm_length
    assert wrench_saturated(hover, np.array([[torque, 0.0, 0.0]]), vehicle).all()
    # saturation flags a loss only when it lasts
    t = np.arange(200) / 100.0
    zeros = np.zeros((200, 3))
    sat = np.zeros(200, dtype=bool)
    sat[50:70] = True
    assert not out_of_control(t, zeros, zeros, vehicle, saturated=sat).any
    sat[120:160] = True
    (span,) = out_of_control(t, zeros, zeros, vehicle, saturated=sat).spans
    assert "actuators' limits" in span[2] and span[0] == pytest.approx(0.7)


@pytest.mark.parametrize(
    ("ref", "residual_rule_flagged"),
    [
        (attitude_steps(20, move=0.4, hold=1.5, duration=16.0, seed=0), True),
        (attitude_steps(25, move=0.3, hold=1.2, duration=16.0, seed=3), True),
        (wobble(25, bandwidth=1.2, duration=12.0), False),
    ],
    ids=["steps20", "steps25", "wobble-fast"],
)
def test_aggressive_controlled_flights_lose_no_samples(vehicle, ref, residual_rule_flagged):
    """The residual of a hidden drag in fast transitions is 12x the log's robust
    scale and was taken for a loss (spans over a tenth of the flight); the vehicle
    follows its reference throughout, so nothing is cut."""
    log = align(simulate(ref, vehicle, truth_from_tree(DRAG, vehicle), seed=1).log)
    loss, s = _loss(vehicle, log)
    assert not loss.any, loss.spans
    scale = 1.4826 * np.median(np.abs(s.residual - np.median(s.residual, axis=0)), axis=0)
    # the former rule: 12x the log's robust residual scale
    assert (np.abs(s.residual) > 12 * scale).any() == residual_rule_flagged


def test_an_aggressive_flight_that_diverges_is_cut_where_it_does(vehicle):
    """Steps too fast for the servos: the vehicle diverges (simulator: attitude error
    beyond 80 deg); the span starts before that, by tracking, and runs to the end."""
    ref = attitude_steps(25, move=0.25, hold=1.0, duration=8.0, seed=0)
    result = simulate(ref, vehicle, truth_from_tree(DRAG, vehicle), seed=1)
    assert result.diverged_at is not None
    log = align(result.log)
    loss, s = _loss(vehicle, log)
    ((start, end, why),) = loss.spans
    assert result.diverged_at - 1.0 <= start <= result.diverged_at
    assert end == pytest.approx(s.t[-1])
    assert "no longer follows its reference" in why
    assert not loss.mask[s.t < result.diverged_at - 1.0].any()


def test_a_motor_failure_is_caught_without_a_reference(vehicle):
    """A log of an IMU and the commands only (no reference attitude): the fallback
    of actuator and physical limits still cuts the tumble after three arms fail."""
    ref = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=12.0, ramp=1.0)
    failure = {"failure": {"time": 8.0, "arms": [0, 1, 2], "thrust_factor": 0.0}}
    log = align(simulate(ref, vehicle, truth_from_tree(failure, vehicle), seed=1).log)
    with_ref, _ = _loss(vehicle, log)
    signals = {k: v for k, v in log.signals.items() if k != "reference_attitude"}
    without, s = _loss(vehicle, replace(log, signals=signals))
    for loss in (with_ref, without):
        ((start, end, _),) = loss.spans
        assert 7.0 <= start <= 8.6 and end == pytest.approx(s.t[-1])
    assert "reference" in with_ref.spans[0][2]
    assert "reference" not in without.spans[0][2]


def test_a_hidden_drag_in_steps_keeps_its_samples_and_is_identified(vehicle, tmp_path):
    """Aggressive attitude steps with a hidden drag (rotor interference off, so the
    drag is what the residual holds): the residual rule cut 1410 of 1601 samples here
    and left a drag of -0.04 +- 0.09 on x; judged by tracking every sample is kept,
    ``evaluate`` excludes no span, and ``fit --effects rotational_drag`` on the flight
    finds a positive drag on x and y, on one of them at more than 2 (autocorrelation-
    robust) standard errors (measured: 0.020 +- 0.037 and 0.023 +- 0.011 for 0.05;
    the GP absorbs part of it)."""
    truth = truth_from_tree(
        {"actuators": {"interference": {"rotor_rotor": 0.0, "rotor_arm": 0.0}}, **DRAG}, vehicle
    )
    steps = tmp_path / "steps.csv"
    ref = attitude_steps(25, move=0.3, hold=1.2, duration=16.0, seed=3)
    write_log(steps, simulate(ref, vehicle, truth, seed=2).log)
    result = fit_model([steps], effects=["rotational_drag"], points=80, restarts=0)
    (log,) = result.summary.logs
    assert log.used >= 0.99 * log.samples - log.in_gaps - log.edge_dropped
    assert not any("out of control" in n for n in log.notes)
    est = result.model.effects["rotational_drag"]
    d, se = est.values["D"][:2], est.stderr["D"][:2]
    print("D", d, "+-", se)
    assert np.all(d > 0) and np.max(d / se) > 2 and np.min(se) < 0.02
    model = tmp_path / "m.npz"
    save_model(model, result.model)
    # the excluded spans and the flags are read, not the horizons table (open-loop
    # rollouts, which neither depends on: metrics.py's out_of_control flag is of the spans)
    out = tmp_path / "e.json"
    r = runner.invoke(
        app,
        [
            "evaluate",
            "--model",
            str(model),
            str(steps),
            "--out",
            str(out),
            "--horizons",
            "none",
            "-q",
        ],
    )
    assert r.exit_code == 0, r.output
    tree = json.loads(out.read_text())
    assert tree["excluded_spans"] == []
    assert not any(f["code"] == "out_of_control" for f in tree["flags"])
