"""Rolling out a model with a motor lag (#28): its first step is the one-step physics.

A Crazyflie-like quadrotor (the ``quad-x-crazyflie`` preset, fixed rotors, 500 Hz)
whose torque command carries a rate controller's fast content, and whose body
rate is the exact integral of that command through a 60 ms first-order motor
lag. A model holding exactly that lag (no GP) must roll out with ~zero error at
every horizon: the lag's state at each period comes from the logged command
history, the rollout adds the lag as each period's own mean (not the
Savitzky-Golay hold of the one-step residual, which averages ten periods), and
the lag is counted once (the rotor list's linear lag regressor once also entered
the rollout through ``effects_mean``, lagging one window's row behind the other).
Both parts failed before the fix (docs/horizons.md, 2026-11-26).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omavctl.diagnose.horizons import horizon_table
from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.rollout_residual import GridSignals, gather, residual_function
from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs.types import FlightLog
from omavctl.physics.actuator_effects import first_order_lag
from omavctl.physics.open_loop import rollout
from omavctl.vehicle import load_vehicle
from tests.test_horizons import _model

RATE = 500.0
T_M = 0.06


def _flight(vehicle, n: int = 1500) -> FlightLog:
    """Roll torque only (the gyroscopic term vanishes): slow sines plus held random
    steps (a D-term's fast content, 2x the slow part), body rate the exact integral
    of the lagged command."""
    dt = 1.0 / RATE
    t = np.arange(n) * dt
    rng = np.random.default_rng(4)
    slow = 2e-4 * np.sin(2 * np.pi * 1.3 * t)
    fast = 4e-4 * np.repeat(rng.standard_normal(n // 3 + 1), 3)[:n]
    torque = np.zeros((n, 3))
    torque[:, 0] = slow + fast
    applied = first_order_lag(torque, T_M, dt) @ vehicle.inertia_inv.T  # period means
    omega = np.zeros((n, 3))
    omega[1:] = np.cumsum(applied[:-1], axis=0) * dt
    signals = {
        "body_rate": omega,
        "torque_command": torque,
        "force_command": np.tile([0.0, 0.0, vehicle.mass * 9.81], (n, 1)),
    }
    return FlightLog(Path("lagged.csv"), "csv", t, signals, np.ones(n, bool), [(0, n)], RATE)


def test_a_motor_lag_model_rolls_out_as_its_one_step_physics(tmp_path):
    (tmp_path / "cf.yaml").write_text("preset: quad-x-crazyflie\n")
    vehicle = load_vehicle(tmp_path / "cf.yaml")
    flight = _flight(vehicle)
    sg = SavitzkyGolay(11, 2, 1.0 / RATE)
    s = residual_samples(flight, vehicle, sg, effects=("motor_lag",))
    s.rate_noise = np.zeros(3)
    sig = flight.signals
    g = GridSignals(sig["body_rate"][s.index], sig["torque_command"][s.index], None)
    lag = EffectEstimate("motor_lag", {"T_m": np.array([T_M])}, {"T_m": np.zeros(1)})
    m = _model(vehicle, {"motor_lag": lag})

    # an instant has no history: the lag adds nothing to the model's pointwise mean
    assert np.all(m.effects_mean(s.u[:50], s.omega[:50]) == 0.0)

    # one step ahead the model is exact on the held residual (Savitzky-Golay) ...
    one_step = s.nominal + m.effects_samples(s)
    scale = np.abs(s.omega_dot[:, 0]).max()
    assert np.abs(one_step - s.omega_dot).max() < 1e-6 * scale
    # ... and its rollout's first step on the period's own increment, where the held
    # command differs from the logged one by a third of the acceleration
    win = gather([s], [g], 1, 1)
    residual = residual_function(m, win, [s], True)
    v = vehicle
    start = (win.omega[:, 0], np.zeros((win.count, 3)), win.torque[:, :1])
    om, _ = rollout(*start, v.inertia, v.inertia_inv, 1.0 / RATE, residual)
    step = (om[:, 1, 0] - om[:, 0, 0]) * RATE
    logged = (win.omega[:, 1, 0] - win.omega[:, 0, 0]) * RATE
    assert np.abs(step - logged).max() < 1e-6 * scale
    held_gap = (g.torque - s.u[:, 3:] @ v.inertia.T) @ v.inertia_inv.T
    assert np.sqrt(np.mean(held_gap[:, 0] ** 2)) > 0.3 * np.sqrt(np.mean(logged**2))

    # and over every horizon up to 0.5 s: ~zero error, far below physics only, and no
    # finding that the lag hurts at 0.5 s (#28: adding the effect lowers the 0.5 s error
    # where it lowers the one-step error)
    h = horizon_table([m], [s], [g], RATE, horizons=(0.002, 0.01, 0.1, 0.5), stride=7)
    assert h["windows"] > 150
    for full, nominal in zip(h["table"]["model"], h["table"]["nominal"], strict=True):
        assert full["rate_error"]["norm"] < 1e-6 * max(1.0, nominal["rate_error"]["norm"]), full
        assert nominal["rate_error"]["norm"] > 0.01 * full["steps"] * (1.0 / RATE) * scale
    nominal, effects = h["table"]["nominal"][-1], h["table"]["effects"][-1]
    assert h["table"]["nominal"][0]["rate_error"]["norm"] > 0.0
    assert effects["rate_error"]["norm"] < 1e-6 * nominal["rate_error"]["norm"]
    assert not {f["code"] for f in h["findings"]} & {"effects_hurt_long", "gp_hurts_long"}
