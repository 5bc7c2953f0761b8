"""The actuators' timing from their own feedback: the logged tilts and rotor speeds
against the commanded ones tell a servo lag, a motor lag and a command delay apart."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.learn.actuator_timing import actuator_timing, delayed_lag
from omavctl.logs import align
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree


@pytest.fixture(scope="module")
def task():
    return fig8(roll_deg=18, pitch_deg=18, period=4.0, duration=8.0, ramp=1.5)


def _timing(vehicle, task, tree):
    res = simulate(task, vehicle, truth_from_tree(tree, vehicle), seed=3, physics_rate=1000.0)
    return actuator_timing(align(res.log), vehicle)


def _inside(value: float, ci) -> bool:
    return ci[0] <= value <= ci[1]


@pytest.mark.parametrize(
    ("effect", "params", "kind", "what"),
    [
        ("servo_lag", {"T_s": 0.08}, "tilt", "T"),
        ("motor_lag", {"T_m": 0.06}, "rotor", "T"),
        ("command_delay", {"tau_d": 0.05}, "both", "tau"),
    ],
)
def test_each_timing_effect_shows_in_its_own_actuators(vehicle, task, effect, params, kind, what):
    truth = float(next(iter(params.values())))
    fits = _timing(vehicle, task, {"ideal": True, "effects": {effect: params}})
    assert set(fits) == {"tilt", "rotor"}
    shown = ("tilt", "rotor") if kind == "both" else (kind,)
    for k, fit in fits.items():
        value, ci = (fit.T, fit.T_ci95) if what == "T" else (fit.tau, fit.tau_ci95)
        if k in shown:
            assert abs(value - truth) <= 0.05 * truth, (k, value)
            assert _inside(truth, ci), (k, ci)
            assert fit.rms_fit < 0.1 * fit.rms_none
        else:  # the other kind follows its commands at once
            assert fit.T < 0.005 and fit.tau < 0.01, (k, fit)


def test_the_default_actuators_lag_by_their_5_ms(vehicle, task):
    fits = _timing(vehicle, task, {})
    for kind in ("tilt", "rotor"):
        assert _inside(0.005, fits[kind].T_ci95), (kind, fits[kind])
        assert fits[kind].tau < 0.005


def test_the_model_state_at_a_row_is_what_the_commands_before_it_made() -> None:
    command = np.zeros((6, 1))
    command[2:] = 1.0  # a step sent at row 2
    np.testing.assert_allclose(delayed_lag(command, 0.0, 0.0, 0.01)[:, 0], [0, 0, 0, 1, 1, 1])
    np.testing.assert_allclose(delayed_lag(command, 0.02, 0.0, 0.01)[:, 0], [0, 0, 0, 0, 0, 1])
    lagged = delayed_lag(command, 0.0, 0.01, 0.01)[:, 0]
    np.testing.assert_allclose(lagged[3:], 1.0 - np.exp(-np.arange(1, 4)), rtol=1e-12)
