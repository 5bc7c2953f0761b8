"""simulate -> write -> read gives the same aligned signals in every log kind."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fly

from omavctl.logs import read_log, write_log


@pytest.fixture(scope="module")
def simulated(vehicle, short_fig8):
    return fly(vehicle, short_fig8, {"effects": {"rotational_drag": {"D": [0.03, 0.03, 0.02]}}})


def test_every_log_kind_reads_back_the_same_aligned_signals(simulated, tmp_path):
    logs = {}
    for name in ("flight.csv", "flight.bag", "flight.mcap", "flight"):
        path = tmp_path / name
        write_log(path, simulated.log)
        logs[name] = read_log(path)
    ref = logs["flight"]
    assert ref.valid.all() and ref.segments == [(0, ref.t.size)]
    assert ref.t.size == simulated.steps
    for name, log in logs.items():
        np.testing.assert_allclose(log.t, ref.t, atol=1e-9, err_msg=name)
        assert set(log.signals) == set(ref.signals), name
        for role, values in ref.signals.items():
            np.testing.assert_allclose(
                log.signals[role], values, atol=1e-9, err_msg=f"{name} {role}"
            )


def test_aligned_signals_equal_what_was_simulated(simulated, tmp_path):
    path = tmp_path / "flight.mcap"
    write_log(path, simulated.log)
    log = read_log(path)
    series = simulated.log.series
    # every controller-rate role is on the grid itself
    for role in ("torque_command", "force_command", "desired_acceleration", "position", "tilt"):
        np.testing.assert_allclose(log.signals[role], series[role].values, atol=1e-9, err_msg=role)
    # the 200 Hz gyro is sampled at every other stamp
    np.testing.assert_allclose(
        log.signals["body_rate"], series["body_rate"].values[::2], atol=1e-12
    )
