"""The PX4 accelerometer end to end (#28, session 15): ``inspect`` suggests the
``specific_force`` role on the shared real logs that have an accelerometer, in m/s^2
(scaled from g where the log records g), and a ULog's
``sensor_combined.accelerometer_m_s2`` is read through that map and the FRD -> FLU
frame as the body specific force (gravity's reaction, +z up when level)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from omavctl.base.errors import LogError
from omavctl.logs import inspect_log, read_raw, read_vehicle_log
from omavctl.logs.frames import convert_frame
from omavctl.vehicle import load_vehicle
from tests.test_readers import CF, REAL, needs_real

ULOG = REAL / "pyulog_bench" / "sample.ulg"
ACC = "sensor_combined.accelerometer_m_s2"


@needs_real
@pytest.mark.parametrize(
    ("path", "want"),
    [
        (ULOG, {a: f"{ACC}[{i}]" for i, a in enumerate("xyz")}),
        (
            REAL / "px4tools_octocopter" / "01_07_59.csv",
            {a: f"IMU_Acc{a.upper()}" for a in "xyz"},
        ),
        (CF / "log16", {"x": "acc.x", "y": "acc.y", "z": "acc.z", "scale": 9.80665}),
    ],
)
def test_inspect_suggests_the_accelerometer_as_specific_force(path, want) -> None:
    ins = inspect_log(path)
    assert ins.suggested_columns is not None
    assert ins.suggested_columns["specific_force"] == want
    assert ins.suggestion is not None and "specific_force:" in ins.suggestion


@needs_real
def test_a_ulog_accelerometer_reads_as_the_body_specific_force(tmp_path) -> None:
    ins = inspect_log(ULOG)
    assert ins.suggested_columns is not None
    tree = {
        "mass": 0.8,
        "inertia": [0.005, 0.005, 0.009],
        "frame": "FRD",
        "command_units": {"torque": "normalised", "force": "normalised"},
        "columns": ins.suggested_columns,
    }
    (tmp_path / "v.yaml").write_text(yaml.safe_dump(tree))
    vehicle = load_vehicle(tmp_path / "v.yaml")
    raw = read_raw(ULOG, vehicle.topics, vehicle.columns)
    frd = raw.series["specific_force"].values
    assert frd.shape == (17070, 3)  # sensor_combined at 250 Hz over 69 s
    flu = convert_frame(raw, "FRD").series["specific_force"].values
    np.testing.assert_allclose(flu, frd * np.array([1.0, -1.0, -1.0]))
    # the board lies about level, moved by hand: gravity's reaction reads +9.6 m/s^2 up
    med = np.median(flu, axis=0)
    assert 9.4 < med[2] < 9.9 and np.hypot(med[0], med[1]) < 1.5
    # the sample never arms (its README): no flight to fit drag_moment on, said in a line
    with pytest.raises(LogError, match="no flight: the thrust command"):
        read_vehicle_log(ULOG, vehicle, rate=100.0)
