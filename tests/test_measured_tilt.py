"""The arms' measured tilts: the interference's wake follows where the arms are.

A servo that lags moves the arms away from their setpoints, and the rotors' wake
with them. With the interference at the commanded tilts the cross term of the lag
and the wake is left to neither effect: on a figure-8 the servo lag's exact form then
made the fit worse on x and y (report15's servo-lag misses, docs/scorecard.md).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from omavctl.learn.flights import log_samples
from omavctl.learn.savgol import SavitzkyGolay
from omavctl.learn.signal import measured_tilt, residual_samples
from omavctl.logs import align
from omavctl.physics.allocation import Allocation
from omavctl.physics.effect_base import EffectContext
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from tests.conftest import NO_NOISE

T_S = 0.1
#: a servo lag and the interference, no other actuator imperfection, no noise
TRUTH = {
    "seed": 4,
    "actuators": {"servo_backlash_deg": 0.0, "motor_time_constant": 0.0, "thrust_spread": 0.0},
    "effects": {"servo_lag": {"T_s": T_S}},
    "noise": NO_NOISE,
}
LOOK_ALIKES = ("com_offset", "rotor_interference")


@pytest.fixture(scope="module")
def lagging(vehicle):
    task = fig8(roll_deg=18, pitch_deg=18, period=5.0, duration=10.0, ramp=1.5)
    res = simulate(task, vehicle, truth_from_tree(TRUTH, vehicle), seed=4, physics_rate=400.0)
    return align(res.log)


def _left(samples, with_servo: bool) -> np.ndarray:
    """RMS per axis (3,) of the residual the look-alikes (and the servo lag's exact form
    at the truth) leave, fitted by least squares."""
    x = np.concatenate([samples.regressors[n] for n in LOOK_ALIKES], axis=2)
    y = samples.residual - (samples.exact("servo_lag", T_S) if with_servo else 0.0)
    theta = np.linalg.lstsq(x.reshape(-1, x.shape[2]), y.reshape(-1), rcond=None)[0]
    return np.sqrt(((y - x @ theta) ** 2).mean(axis=0))


def test_interference_at_the_measured_tilts_leaves_the_servo_lag_its_own(lagging, vehicle):
    sg = SavitzkyGolay(11, 2, 0.01)
    effects = (*LOOK_ALIKES, "servo_lag")
    measured = residual_samples(lagging, vehicle, sg, effects)
    signals = {k: v for k, v in lagging.signals.items() if k != "tilt"}
    commanded = residual_samples(replace(lagging, signals=signals), vehicle, sg, effects)
    physics = np.sqrt((measured.residual**2).mean(axis=0))
    with_lag = _left(measured, True)
    at_commanded = _left(commanded, True)
    # the lag's exact form and the wake where the arms are explain the flight ...
    assert np.all(with_lag < 0.05 * physics[:2].max())
    assert np.all(with_lag < 0.4 * _left(measured, False))
    # ... while at the commanded tilts the lag's exact form leaves x and y 3x as much
    assert np.all(with_lag[:2] < at_commanded[:2] / 3.0)
    assert measured.tilt_note is None


def test_tilts_of_another_convention_are_set_aside_with_a_note(lagging, vehicle):
    flipped = replace(lagging, signals={**lagging.signals, "tilt": -lagging.signals["tilt"]})
    tilt, note = measured_tilt(flipped, vehicle, Allocation(vehicle))
    assert tilt is None and note is not None
    assert note.startswith("tilt: the logged arm tilts are a median ")
    assert note.endswith(
        " deg from the commanded ones (another sign or zero?): the effects use the commanded tilts"
    )
    samples, summary = log_samples(flipped, vehicle, SavitzkyGolay(11, 2, 0.01))
    assert note in summary.notes and samples.tilt_note == note
    kept, none = measured_tilt(lagging, vehicle, Allocation(vehicle))
    assert none is None and kept is lagging.signals["tilt"]


def test_arm_tilt_takes_the_commanded_branch(vehicle):
    alloc = Allocation(vehicle)
    hover = np.zeros((5, 6))
    hover[:, 2] = vehicle.mass * 9.81
    hover[:, 0] = np.linspace(0.0, 4.0, 5)  # a sideways force: tilted arms
    commanded = alloc.allocate(hover).tilt
    ctx = EffectContext(
        omega=np.zeros((5, 3)),
        force=hover[:, :3],
        torque=hover[:, 3:],
        omega_dot_nominal=np.zeros((5, 3)),
        inertia=vehicle.inertia,
        dt=0.01,
        allocation=alloc,
        derivative=np.zeros_like,
        measured_tilt=commanded + 2.0 * np.pi + 0.01,
    )
    # the arms while sample i's command acts: the tilts logged at sample i + 1
    ahead = np.unwrap(commanded, axis=0)[[1, 2, 3, 4, 4]]
    np.testing.assert_allclose(ctx.arm_tilt, ahead + 0.01, atol=1e-12)
    assert np.array_equal(replace(ctx, measured_tilt=None).arm_tilt, ctx.allocated[0])


def test_the_arms_while_a_command_acts_are_those_of_the_next_sample(vehicle):
    """A tilt logged at t_i is where the arms were when command i was sent; with servos
    faster than the log period they are at the next sample's tilts while it acts. On an
    ideal plant (no lag, spread or noise) with a strong interference, the
    interference's regressor at the truth explains the figure-8's residual to 1 % with
    those tilts; with the tilts of sample i it left 0.038, 0.066 rad/s^2 on a scorecard
    draw's figure-8 (docs/effects.md, rotor_interference)."""
    truth = {
        "seed": 4,
        "ideal": True,
        "noise": NO_NOISE,
        "effects": {"rotor_interference": {"rotor_rotor": 0.6, "rotor_arm": 0.15}},
    }
    task = fig8(roll_deg=18, pitch_deg=18, period=5.0, duration=6.0, ramp=1.5)
    res = simulate(task, vehicle, truth_from_tree(truth, vehicle), seed=4, physics_rate=400.0)
    log = align(res.log)
    sg = SavitzkyGolay(11, 2, 0.01)
    theta = np.array([0.6, 0.15])
    left = {}
    behind = np.concatenate([log.signals["tilt"][:1], log.signals["tilt"][:-1]])
    for name, flight in (
        ("next", log),
        ("own", replace(log, signals={**log.signals, "tilt": behind})),
    ):
        s = residual_samples(flight, vehicle, sg, ("rotor_interference",))
        y = s.residual - s.regressors["rotor_interference"] @ theta
        left[name] = np.sqrt((y**2).mean(axis=0))
        physics = np.sqrt((s.residual**2).mean(axis=0))
    assert np.all(left["next"][:2] < 0.01 * physics[:2]), (left, physics)
    assert np.all(left["own"][:2] > 3 * left["next"][:2]), left
