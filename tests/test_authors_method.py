"""benchmarks/authors_method.py (the authors' motor time constant) on synthetic signals."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.signal import lfilter

from benchmarks.authors_method import (
    ACC_Z_SCALE,
    MASS,
    ROTORS,
    Segment,
    bootstrap,
    cut,
    ema,
    read_log,
    scan_roll_pitch,
)

RATE = 1000.0  # Hz, as the Crazyflie logs
TRUE_TM = 0.04  # s
TRUE_I = np.array([1.4e-5, 1.7e-5])  # kg m^2, roll and pitch
CURVE = 0.15  # N per unit rpm^2


def synthetic(seconds: float, seed: int, tm: float = TRUE_TM, gyro_noise: float = 0.02) -> Segment:
    """Motor set-points wandering about hover, the rotors lagging them by
    ``tm``, thrust ``0.15 rpm^2``, body rates integrated from the torque
    over ``TRUE_I`` plus gyro noise; the accelerometer's z reads the thrust."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = 100.0 + np.arange(n) / RATE
    wander = lfilter([0.02], [1.0, -0.98], rng.standard_normal((n, 4)), axis=0)
    u = 0.5 + 0.6 * wander
    thrust = CURVE * ema(u, tm, 1.0 / RATE) ** 2
    tau = np.c_[thrust @ ROTORS[:, 1], -(thrust @ ROTORS[:, 0])]
    # trapezoidal: its central difference is a symmetric average of the torque, no shift
    omega = cumulative_trapezoid(tau / TRUE_I, dx=1.0 / RATE, axis=0, initial=0.0)
    omega = np.c_[omega, np.zeros(n)] + gyro_noise * rng.standard_normal((n, 3))
    acc = np.zeros((n, 3))
    acc[:, 2] = thrust.sum(axis=1) / MASS
    return Segment(t, u, omega, acc)


def test_the_lag_filter_is_first_order_and_starts_at_the_first_sample() -> None:
    step = np.r_[np.zeros(1), np.ones(200)][:, None]
    out = ema(step, 0.05, 0.001)[:, 0]
    assert out[0] == 0.0
    # after 50 ms (one time constant) a first-order lag has risen 1 - 1/e
    assert out[50] == pytest.approx(1.0 - np.exp(-1.0), abs=1e-12)
    assert np.array_equal(ema(step, 0.0, 0.001), step)


def test_the_method_recovers_a_known_time_constant_and_inertia() -> None:
    thrust = [synthetic(6.0, seed=1)]
    roll_pitch = [synthetic(12.0, seed=2)]
    scan = scan_roll_pitch(thrust, roll_pitch, (2,), block=1.0)
    loss = scan.loss()
    i = int(np.argmin(loss))
    assert scan.coefs[i][0] == pytest.approx(CURVE, rel=1e-3)
    assert abs(0.001 + i * 0.001 - TRUE_TM) <= 0.001
    assert 1.0 / scan.inverse_inertia(i) == pytest.approx(TRUE_I, rel=0.03)
    # a lag 20 ms off explains clearly less than the right one
    assert loss[i + 20] > 1.05 * loss[i] and loss[i - 20] > 1.05 * loss[i]
    draws = bootstrap(scan, 50)
    low, high = np.percentile(draws, [2.5, 97.5])
    assert TRUE_TM - 0.002 <= low <= high <= TRUE_TM + 0.002


def test_without_a_lag_the_method_finds_none() -> None:
    seg = synthetic(8.0, seed=3, tm=0.0)
    scan = scan_roll_pitch([seg], [seg], (2,), block=1.0)
    assert int(np.argmin(scan.loss())) == 0  # the grid's first point, 1 ms


def test_a_log_is_read_in_the_units_of_the_method(tmp_path: Path) -> None:
    header = (
        "timestamp,acc.x,acc.y,acc.z,gyro.x,gyro.y,gyro.z,motor.m1,motor.m2,motor.m3,motor.m4\n"
    )
    ms = np.r_[np.arange(0, 200), np.arange(260, 400)] + 1000.0  # a 60 ms gap at 1.2 s
    rows = "".join(f"{m},0,0,1,180,0,-90,65536,32768,0,16384\n" for m in ms)
    path = tmp_path / "log.csv.gz"
    with gzip.open(path, "wt") as f:
        f.write(header + rows)
    segments = cut(read_log(path), [(1.0, 1.4)])
    assert [s.t.size for s in segments] == [199, 140]  # strictly inside, split at the gap
    s = segments[0]
    assert s.u[0] == pytest.approx([1.0, 0.5, 0.0, 0.25])
    assert s.omega[0] == pytest.approx([np.pi, 0.0, -np.pi / 2])
    assert s.acc[0, 2] == ACC_Z_SCALE
