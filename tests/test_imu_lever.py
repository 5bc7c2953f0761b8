"""The accelerometer's lever arm (issue 28, session 16): estimated per log with its
interval, removed from the force drag_moment reads; a log without an accelerometer is
untouched."""

from __future__ import annotations

import json

import numpy as np
import pytest

from omavctl.learn.imu_lever import (
    estimate_lever,
    lever_matrix,
    lever_of,
    lever_provenance,
    without_lever,
)
from omavctl.learn.signal import SavitzkyGolay

R_TRUE = np.array([0.02, -0.01, 0.05])  # m, body FLU
SG = SavitzkyGolay(11, 3, 0.01)


def _flight_signals(seed: int, n: int = 3000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body rate (n, 3) rad/s of a brisk multi-sine, its exact derivative, and an
    accelerometer (n, 3) m/s^2 that reads a slow lateral drag, the thrust on z, the
    lever term at R_TRUE and white noise (0.05 m/s^2)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    freq = np.array([[0.7, 1.9, 3.1], [0.9, 2.3, 2.9], [0.5, 1.3, 2.7]])  # Hz per axis
    amp = np.array([0.6, 0.6, 0.3])
    phase = rng.uniform(0, 2 * np.pi, (3, 3))
    arg = 2 * np.pi * freq[None] * t[:, None, None] + phase[None]
    omega = amp * np.sin(arg).sum(axis=2)
    alpha = amp * (2 * np.pi * freq[None] * np.cos(arg)).sum(axis=2)
    drag = np.stack([0.3 * np.sin(0.2 * t), 0.3 * np.cos(0.15 * t), 9.8 + 0 * t], axis=1)
    accel = drag + lever_matrix(omega, alpha) @ R_TRUE + rng.normal(0, 0.05, (n, 3))
    return omega, alpha, accel


def _parts(omega: np.ndarray, accel: np.ndarray) -> list:
    n = omega.shape[0]
    return [(omega, SG.derivative(omega), accel, slice(SG.half, n - SG.half))]


def test_lever_matrix_is_the_rigid_body_kinematics() -> None:
    rng = np.random.default_rng(1)
    w, a = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    want = np.cross(a, R_TRUE) + np.cross(w, np.cross(w, R_TRUE))
    np.testing.assert_allclose(lever_matrix(w, a) @ R_TRUE, want, atol=1e-12)


@pytest.mark.parametrize("seed", [3, 4])
def test_lever_recovered_within_its_interval_and_removed(seed: int) -> None:
    omega, alpha, accel = _flight_signals(seed)
    lever = estimate_lever(_parts(omega, accel), SG)
    assert lever is not None and lever.pinned
    lo, hi = lever.interval().T
    assert np.all((lo <= R_TRUE) & (R_TRUE <= hi)), (lever.r, lever.stderr)
    assert np.all(lever.stderr < 0.005)  # pinned down to a few mm
    force = 1.5 * accel
    cleaned = without_lever(force, omega, alpha, lever, 1.5)
    assert cleaned is not None
    lateral = slice(0, 2)
    # what is left of the lever term is a few per cent of it
    left = cleaned[:, lateral] - 1.5 * (accel - lever_matrix(omega, alpha) @ R_TRUE)[:, lateral]
    term = 1.5 * (lever_matrix(omega, alpha) @ R_TRUE)[:, lateral]
    assert np.sqrt(np.mean(left**2)) < 0.1 * np.sqrt(np.mean(term**2))
    # what a model file records of it (provenance.imu_lever): removed; a log without an
    # estimate says so
    rec = lever_provenance([("fit.csv", lever), ("short.csv", None)])
    assert rec[0]["log"] == "fit.csv" and rec[0]["removed"] is True
    np.testing.assert_allclose(rec[0]["r"], lever.r)
    np.testing.assert_allclose(rec[0]["stderr"], lever.stderr)
    assert rec[1] == {"log": "short.csv", "r": None, "stderr": None, "removed": False}
    json.dumps(rec, allow_nan=False)


def test_no_lever_when_the_accelerometer_reads_none() -> None:
    omega, alpha, accel = _flight_signals(5)
    accel = accel - lever_matrix(omega, alpha) @ R_TRUE
    lever = estimate_lever(_parts(omega, accel), SG)
    assert lever is not None
    lo, hi = lever.interval().T
    assert np.all((lo <= 0) & (0 <= hi)), (lever.r, lever.stderr)
    assert not lever.pinned  # then the force is left as logged
    assert without_lever(accel, omega, alpha, lever, 1.0) is accel
    assert "not distinguishable from 0" in lever.note()
    assert lever_provenance([("a.csv", lever)])[0]["removed"] is False
    # fewer than 10 half-second blocks: no estimate
    assert estimate_lever(_parts(omega[:450], accel[:450]), SG) is None


class _Log:
    def __init__(self, signals: dict[str, np.ndarray]) -> None:
        self.signals, self.notes = signals, []

    def has(self, role: str) -> bool:
        return role in self.signals


def test_a_log_without_an_accelerometer_is_untouched() -> None:
    omega, alpha, accel = _flight_signals(6)
    n = omega.shape[0]
    segments = [(0, n, SG.half, n - SG.half)]
    assert lever_of(_Log({"body_rate": omega}), SG, segments) is None
    assert without_lever(None, omega, alpha, None, 1.0) is None
    log = _Log({"body_rate": omega, "specific_force": accel})
    lever = lever_of(log, SG, segments)
    assert lever is not None
    assert len(log.notes) == 1 and log.notes[0].startswith("accelerometer lever arm")
    lever_of(log, SG, segments)
    assert len(log.notes) == 1  # said once
