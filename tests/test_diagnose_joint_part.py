"""The joint step's part judged against the claim floor by its 95 % interval, and a lag
or delay held back by the claims guard replaced by the next lag or delay of its step
(omavctl/diagnose/joint.py, joint_timing.py; issue 26, docs/effects.md)."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.diagnose.joint import Z95, joint_selection, part_high
from omavctl.diagnose.joint_timing import with_timing_rivals
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import feature_names
from omavctl.vehicle import default_vehicle
from tests.test_diagnose_guard_order import _least_squares_guard
from tests.test_diagnose_joint import FLOOR, N_TRAIN, NOISE, _case


def test_the_part_interval_of_one_parameter_is_its_value_plus_two_sd_times_the_regressor():
    rng = np.random.default_rng(0)
    reg = rng.normal(size=(500, 3, 1))
    rms = float(np.sqrt(np.mean(reg**2)))
    for theta in (0.02, -0.02):
        high = part_high(reg, np.array([theta]), np.array([[0.005**2]]))
        assert high == pytest.approx((0.02 + Z95 * 0.005) * rms, rel=1e-9)
    # at a part of 0 the interval is 1.96 sd of the part wide
    assert part_high(reg, np.zeros(1), np.array([[0.005**2]])) == pytest.approx(
        Z95 * 0.005 * rms, rel=1e-9
    )
    # three parameters: the delta method along the part's direction
    cov = np.diag([1e-4, 4e-4, 9e-4])
    theta = np.array([0.1, 0.0, 0.0])
    x = reg[:, :, [0, 0, 0]] * np.eye(3)[None]  # one component per axis
    own_rms = float(np.sqrt(np.mean((x @ theta) ** 2)))
    assert part_high(x, theta, cov) == pytest.approx(own_rms * (1 + Z95 * 0.01 / 0.1), rel=1e-6)


def _shrunk(signal_variance: float):
    """A hidden command delay whose held-out part is 1.3x the floor while the fit flight's
    targets hold 0.6 of it (as the kernel's GLS shrinks what the GP represents); the
    model's GP has ``signal_variance`` on inputs that are the delay's regressor."""
    truth = {"command_delay": np.array([0.0165])}
    m0, physics, regs, blocks = _case(truth, seed=7)
    train = m0.train_regressors["command_delay"]
    targets = m0.targets - 0.4 * train @ truth["command_delay"]
    names = feature_names("wrench")
    inputs = np.random.default_rng(2).normal(size=(N_TRAIN, len(names)))
    inputs[:, :3] = train[:, :, 0] / 10
    model = ResidualGP(
        vehicle=default_vehicle(),
        features="wrench",
        input_names=names,
        inputs=inputs,
        targets=targets,
        input_mean=np.zeros(len(names)),
        input_scale=np.ones(len(names)),
        target_mean=np.zeros(3),
        signal_variance=np.full(3, signal_variance),
        length_scales=np.full((3, len(names)), 3.0),
        noise_variance=np.full(3, NOISE**2),
        train_regressors=m0.train_regressors,
    )
    true_part = float(np.sqrt(np.mean((regs["command_delay"] @ truth["command_delay"]) ** 2)))
    return model, physics, regs, blocks, true_part


def test_a_part_under_the_floor_whose_interval_reaches_it_is_claimed():
    model, physics, regs, blocks, true_part = _shrunk(0.1)
    assert true_part > FLOOR
    steps = joint_selection(model, physics, regs, blocks, FLOOR)
    assert [s.name for s in steps] == ["command_delay"]
    step = steps[0]
    assert step.contribution_rms < FLOOR <= step.contribution_high  # the point alone: not
    assert step.to_json()["contribution_high"] == step.contribution_high


def test_a_part_whose_whole_interval_is_under_the_floor_is_not():
    model, physics, regs, blocks, _ = _shrunk(0.0)  # the GP off: a narrow interval
    assert joint_selection(model, physics, regs, blocks, FLOOR) == []


def test_a_lag_and_a_delay_that_both_pass_a_step_are_timing_rivals_not_ambiguous():
    truth = {"command_delay": np.array([0.03]), "motor_lag": None}
    model, physics, regs, blocks = _case(truth, seed=8, alike={"motor_lag": "command_delay"})
    steps = joint_selection(model, physics, regs, blocks, FLOOR)
    assert len(steps) == 1
    (step,) = steps
    assert {step.name, *step.timing_rivals} == {"command_delay", "motor_lag"}
    assert step.ambiguous_with == []


def _columns(seed: int = 0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 400)
    offset = np.sin(1.3 * t) + 0.5 * np.sin(0.4 * t)
    delay = np.cos(2.1 * t)
    lag = rng.normal(size=t.size)  # the linearised stand-in the exact estimate rejects
    y = 0.3 * offset + 0.2 * delay + 0.3 * rng.normal(size=t.size)
    return {"offset": offset, "delay": delay, "lag": lag, "none": np.sin(0.05 * t + 1)}, y


def test_a_held_back_lag_gives_way_to_the_delay_that_passed_its_step():
    columns, y = _columns()
    guard, calls = _least_squares_guard(columns, y)
    alone = with_timing_rivals(guard, ["offset", "lag"], {})
    assert alone.kept == ["offset"] and [h["name"] for h in alone.held_back] == ["lag"]
    calls.clear()
    out = with_timing_rivals(guard, ["offset", "lag"], {"lag": ["none", "delay"]})
    assert out.kept == ["offset", "delay"] and out.held_back == []
    # each rival in turn, in the held-back claim's place, until one is kept
    assert calls == [["offset", "lag"], ["offset", "none"], ["offset", "delay"]]


def test_a_rival_the_guard_also_holds_back_leaves_the_first_answer():
    columns, y = _columns(1)
    guard, calls = _least_squares_guard(columns, y)
    out = with_timing_rivals(guard, ["offset", "lag"], {"lag": ["none"]})
    assert out.kept == ["offset"] and [h["name"] for h in out.held_back] == ["lag"]
    assert calls == [["offset", "lag"], ["offset", "none"]]
