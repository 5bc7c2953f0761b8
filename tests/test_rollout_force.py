"""The measured force rolled forward from the rolled-out attitude (#28, session 15): a
tilt's gravity accelerates the body, a linear drag on that velocity is the lateral
specific force; its drag coefficient recovered from a log; the attitude's level bias
removed; and a rollout of a ``drag_moment`` model on a log with an attitude predicts
the force instead of holding it (the band's term is what the prediction errs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.fit_notes import effect_unit
from omavctl.learn.rollout_force import (
    ForceRollout,
    gravity_body,
    gravity_offset,
    lateral_drag,
    trailing_mean,
)
from omavctl.learn.rollout_residual import GridSignals, gather, held_spread, residual_function
from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs.types import FlightLog
from omavctl.physics.open_loop import AttitudeResidual, rollout
from omavctl.vehicle import load_vehicle
from tests.test_horizons import _model

G = 9.80665


def test_a_held_tilt_accelerates_the_body_until_the_drag_balances_it() -> None:
    """Constant roll phi from rest: dv/dt = g_y - d v, the force -m d v tends to -m g_y
    (the drag balances gravity's lateral part) as 1 - exp(-d t)."""
    phi, d, mass, dt = 0.1, 0.8, 1.5, 0.002
    eta = np.array([[phi, 0.0, 0.3]])
    g_y = gravity_body(eta)[0, 1]
    assert np.isclose(g_y, -G * np.sin(phi))  # rolled right (FLU): gravity points to -y
    roll = ForceRollout(np.zeros((1, 3)), np.zeros((1, 2)), d, mass, dt)
    steps = 500  # 1 s
    f = np.stack([roll.step(eta)[0] for _ in range(steps)])
    t_mid = (np.arange(steps) + 0.5) * dt
    want = -mass * g_y * (1.0 - np.exp(-d * t_mid))
    np.testing.assert_allclose(f[:, 1], want, rtol=2e-3, atol=1e-4)
    np.testing.assert_allclose(f[:, [0, 2]], 0.0, atol=1e-12)
    # no drag: the force stays at the start's, whatever the tilt
    still = ForceRollout(np.array([[0.2, -0.1, 0.0]]), np.zeros((1, 2)), 0.0, mass, dt)
    np.testing.assert_allclose(still.step(eta), [[0.2, -0.1, 0.0]])


def _drag_flight(d: float, bias: float, n: int = 2500, rate: float = 500.0):
    """Roll and pitch swinging (0.15 and 0.1 rad, median 0 plus a level ``bias`` of the
    attitude estimate), the body velocity of gravity's lateral part less a drag d, the
    specific force -d v plus vibration (0.05 m/s^2); exact Euler at 10x the rate."""
    rng = np.random.default_rng(3)
    t = np.arange(n) / rate
    att = np.zeros((n, 3))
    att[:, 0] = 0.15 * np.sin(2 * np.pi * 0.7 * t)
    att[:, 1] = 0.10 * np.sin(2 * np.pi * 0.45 * t + 1.0)
    fine = 10
    v = np.zeros(2)
    acc = np.zeros((n, 3))
    for i in range(n):
        g = gravity_body(att[i])[:2]
        for _ in range(fine):
            v = v + (g - d * v) / (rate * fine)
        acc[i, :2] = -d * v
    acc[:, 2] = G
    acc[:, :2] += 0.05 * rng.standard_normal((n, 2))
    logged = att.copy()
    logged[:, 0] += bias
    return t, logged, acc


def test_the_drag_is_recovered_from_a_log_and_the_level_bias_is_removed() -> None:
    mass, rate, k = 1.5, 500.0, 250
    for bias in (0.0, np.radians(2.0)):
        _, att, acc = _drag_flight(0.6, bias)
        pos = np.arange(0, att.shape[0] - k, 5)[:, None] + np.arange(k + 1)
        force = mass * (acc - np.median(acc, axis=0))[pos]
        offset = gravity_offset(att[pos], np.zeros(pos.shape[0], int))
        d = lateral_drag(force, att[pos], offset, mass, 1.0 / rate)
        assert abs(d - 0.6) < 0.03, (bias, d)  # 0.612 both
    # without removing the 2 degree level, gravity's constant part biases it low (0.53)
    biased = lateral_drag(force, att[pos], np.zeros((pos.shape[0], 2)), mass, 1.0 / rate)
    assert biased < 0.56


def test_trailing_mean_reads_the_past_only_and_not_across_a_gap() -> None:
    from types import SimpleNamespace

    from omavctl.learn.rollout_residual import _start_mean

    x = np.arange(6, dtype=float)[:, None]
    np.testing.assert_allclose(trailing_mean(x, 3)[:, 0], [0, 0.5, 1, 2, 3, 4])
    s = SimpleNamespace(sg=SimpleNamespace(window=3), index=np.array([0, 1, 2, 7, 8, 9]))
    np.testing.assert_allclose(_start_mean(x, s)[:, 0], [0, 0.5, 1, 3, 3.5, 4])  # type: ignore[arg-type]


def test_a_rollout_predicts_the_force_from_the_rolled_out_attitude(tmp_path) -> None:
    """A drag_moment model on a log with an attitude: the rollout gets the attitude, and
    the band's term (what the prediction errs, by the logged attitude) is a fraction of
    what holding the force errs."""
    (tmp_path / "cf.yaml").write_text("preset: quad-x-crazyflie\n")
    vehicle = load_vehicle(tmp_path / "cf.yaml")
    rate = float(vehicle.gains.rate_hz)
    t, att, acc = _drag_flight(0.6, 0.0, rate=rate)
    n = t.size
    omega = np.gradient(att, 1.0 / rate, axis=0)  # small angles: Euler rates ~ body rates
    omega[:, 2] = 0.0
    att[:, 2] = 0.0
    h = 0.015
    f = vehicle.mass * (acc - np.median(acc, axis=0))
    moment = h * np.column_stack([-f[:, 1], f[:, 0], np.zeros(n)])  # the command lacks it
    torque = np.gradient(omega, 1.0 / rate, axis=0) @ vehicle.inertia.T - moment
    signals = {
        "body_rate": omega,
        "torque_command": torque,
        "force_command": np.tile([0.0, 0.0, vehicle.mass * G], (n, 1)),
        "attitude": att,
        "specific_force": acc,
    }
    flight = FlightLog(Path("tilt.csv"), "csv", t, signals, np.ones(n, bool), [(0, n)], rate)
    s = residual_samples(flight, vehicle, SavitzkyGolay(11, 2, 1.0 / rate), ("drag_moment",))
    est = EffectEstimate("drag_moment", {"h": np.array([h])}, {"h": np.zeros(1)})
    m = _model(vehicle, {"drag_moment": est})
    g = GridSignals(omega[s.index], torque[s.index], att[s.index])
    k = round(0.5 * rate)
    win = gather([s], [g], k, 25)
    residual = residual_function(m, win, [s], True)
    assert isinstance(residual, AttitudeResidual)
    seen = []

    def spy(step: int, w: np.ndarray, eta: np.ndarray) -> np.ndarray:
        seen.append(eta)
        return residual(step, w, eta)

    rollout(win.omega[:, 0], win.attitude[:, 0], win.torque[:, :k], vehicle.inertia,
            vehicle.inertia_inv, 1.0 / rate, AttitudeResidual(spy))  # fmt: skip
    assert len(seen) == k + 1
    # the rollout's own attitude (it starts at the log's, then drifts from it)
    np.testing.assert_allclose(seen[0], win.attitude[:, 0])
    assert not np.allclose(seen[-1], win.attitude[:, -1])
    predicted = held_spread(m, win, [s])
    # the same windows without the attitude: the force is held, as before
    held_win = gather([s], [GridSignals(omega[s.index], torque[s.index], None)], k, 25)
    held = held_spread(m, held_win, [s])
    assert not isinstance(residual_function(m, held_win, [s], True), AttitudeResidual)
    assert predicted is not None and held is not None
    assert predicted.shape == held.shape == (win.count, k + 1, 3)
    ratio = predicted[:, -1, :2].mean(axis=0) / held[:, -1, :2].mean(axis=0)
    assert np.all(ratio < 0.35), ratio


def test_drag_moment_height_is_a_torque_unit_per_newton_with_normalised_torque() -> None:
    assert effect_unit("drag_moment", "m", {"torque": "normalised"}) == "[torque unit]/N"
    assert effect_unit("drag_moment", "m", {"force": "normalised"}) == "m"
    assert effect_unit("drag_moment", "m", {}) == "m"
