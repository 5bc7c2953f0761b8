"""Task generators, trajectory CSV contract, vehicle YAML."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.base.errors import ConfigError, TrajectoryError
from omavctl.physics.rigid_body import euler_rates
from omavctl.sim.tasks import TASKS, chirp, circle, fig8, heave, pitch, steps, yaw
from omavctl.sim.trajectory import (
    COLUMNS,
    Trajectory,
    format_trajectory,
    read_trajectory,
    write_trajectory,
)
from omavctl.vehicle import default_vehicle, load_vehicle


@pytest.mark.parametrize("name", sorted(TASKS))
def test_task_derivatives_are_consistent(name):
    # 400 Hz: finite differences err by O(dt^2 x third derivative), which the
    # multi-sine wobble (up to 0.8 Hz) makes 8e-4 rad/s at 100 Hz
    traj = TASKS[name](rate=400.0)
    dt = traj.dt
    inner = slice(2, -2)
    fd = lambda y: np.gradient(y, dt, axis=0)[inner]  # noqa: E731
    # second-order finite differences at 100 Hz: errors O(dt^2 * third derivative)
    np.testing.assert_allclose(
        euler_rates(traj.euler, traj.body_rate)[inner], fd(traj.euler), atol=2e-4
    )
    np.testing.assert_allclose(traj.angular_acceleration[inner], fd(traj.body_rate), atol=2e-2)
    np.testing.assert_allclose(traj.velocity[inner], fd(traj.position), atol=2e-4)
    # the envelope's jerk has kinks at the ends of the ramps: there the finite
    # difference errs by O(dt x jerk step), 0.4 % of a 2 Hz heave's acceleration
    acc_tol = max(2e-4, 5e-3 * np.abs(traj.acceleration).max())
    np.testing.assert_allclose(traj.acceleration[inner], fd(traj.velocity), atol=acc_tol)
    # starts and ends at rest
    for row in (traj.data[0], traj.data[-1]):
        np.testing.assert_allclose(row[7:], 0.0, atol=1e-12)


def test_yaw_and_heave_identification_tasks():
    tr = yaw(amplitude_deg=30, period=4, duration=20, ramp=2)
    assert np.rad2deg(np.abs(tr.euler[:, 2]).max()) == pytest.approx(30, abs=0.05)
    np.testing.assert_allclose(tr.euler[:, :2], 0.0)
    np.testing.assert_allclose(tr.body_rate[:, :2], 0.0, atol=1e-12)
    hv = heave(amplitude=0.3, period=2, duration=16, ramp=2)
    assert np.abs(hv.position[:, 2] - 1.0).max() == pytest.approx(0.3, abs=1e-3)
    steady = (hv.t > 2.0) & (hv.t < 14.0)  # the ramps add envelope terms
    assert np.abs(hv.acceleration[steady, 2]).max() == pytest.approx(0.3 * np.pi**2, rel=0.01)
    np.testing.assert_allclose(hv.euler, 0.0)
    with pytest.raises(ConfigError, match="must be > 0"):
        heave(amplitude=0.0)


def test_chirp_sweeps_its_band_on_every_axis():
    tr = chirp(amplitude_deg=10, f_start=0.2, f_end=1.0, duration=30, ramp=2, rate=200.0)
    inner = (tr.t > 2.5) & (tr.t < 27.5)
    assert np.rad2deg(np.abs(tr.euler[inner, :2]).max()) == pytest.approx(10, abs=0.05)
    assert np.rad2deg(np.abs(tr.euler[inner, 2]).max()) == pytest.approx(5, abs=0.05)
    # the instantaneous frequency (zero crossings of roll) rises from 0.2 to 1.0 Hz
    roll = tr.euler[:, 0]
    cross = tr.t[1:][(roll[:-1] < 0) & (roll[1:] >= 0)]
    freq = 1.0 / np.diff(cross)
    mid = 0.5 * (cross[1:] + cross[:-1])
    np.testing.assert_allclose(freq, 0.2 + 0.8 * mid / 30, rtol=0.03)
    # pitch lags roll by a quarter period: they are not the same signal
    assert abs(np.corrcoef(tr.euler[inner, 0], tr.euler[inner, 1])[0, 1]) < 0.2
    with pytest.raises(ConfigError, match="0 < start < end"):
        chirp(f_start=1.0, f_end=0.5)


def test_steps_hold_random_levels_and_are_seeded():
    tr = steps(amplitude_deg=20, hold=3.0, transition=1.0, duration=20, ramp=2, seed=4)
    again = steps(amplitude_deg=20, hold=3.0, transition=1.0, duration=20, ramp=2, seed=4)
    np.testing.assert_array_equal(tr.data, again.data)
    other = steps(amplitude_deg=20, hold=3.0, transition=1.0, duration=20, ramp=2, seed=5)
    assert not np.allclose(tr.euler, other.euler)
    # between transitions the attitude holds still at a level within the amplitude
    held = ((tr.t - 2.0) % 3.0 > 1.05) & (tr.t > 2.0) & (tr.t < 17.0)
    np.testing.assert_allclose(tr.body_rate[held], 0.0, atol=1e-12)
    assert np.rad2deg(np.abs(tr.euler[:, :2]).max()) <= 20.0
    assert np.rad2deg(np.abs(tr.euler[:, 2]).max()) <= 10.0
    levels = np.unique(np.round(tr.euler[held, 0], 9))
    assert levels.size >= 4  # a new roll level after each step
    # flyable: a quintic step's peak acceleration is 10/sqrt(3) x jump / transition^2
    roll_acc = np.gradient(np.gradient(tr.euler[:, 0], tr.dt), tr.dt)
    settled = np.interp(2.0 + 3.0 * np.arange(6) - 0.5, tr.t, tr.euler[:, 0])  # in time order
    jump = np.abs(np.diff(settled)).max()
    assert np.abs(roll_acc).max() == pytest.approx(10 / np.sqrt(3) * jump, rel=0.05)
    with pytest.raises(ConfigError, match="--hold must be > 0 and below --duration"):
        steps(hold=0.0)
    with pytest.raises(ConfigError, match="at most --hold"):
        steps(hold=1.0, transition=1.5)
    with pytest.raises(ConfigError, match="no room for two steps"):
        steps(duration=6, ramp=2)


def test_fig8_amplitudes_and_shape():
    traj = fig8(roll_deg=26, pitch_deg=20, period=8, duration=24, ramp=2)
    assert np.rad2deg(np.abs(traj.euler[:, 0]).max()) == pytest.approx(26, abs=0.05)
    assert np.rad2deg(np.abs(traj.euler[:, 1]).max()) == pytest.approx(20, abs=0.05)
    np.testing.assert_allclose(traj.position, np.tile([0, 0, 1.0], (traj.t.size, 1)))
    assert traj.t[-1] == pytest.approx(24.0) and traj.dt == pytest.approx(0.01)


def test_pitch_manoeuvre_reaches_sixty_degrees():
    traj = pitch()
    assert np.rad2deg(np.abs(traj.euler[:, 1]).max()) == pytest.approx(60, abs=0.5)


def test_circle_radius():
    traj = circle(radius=1.5)
    centre = np.array([0.0, 1.5])
    middle = traj.t > 5
    np.testing.assert_allclose(
        np.linalg.norm(traj.position[middle, :2] - centre, axis=1), 1.5, atol=1e-9
    )


def test_task_rejects_impossible_options():
    with pytest.raises(ConfigError, match="at least twice --ramp"):
        fig8(duration=3, ramp=2)
    with pytest.raises(ConfigError, match="below 90 deg"):
        pitch(amplitude_deg=95)


def test_trajectory_csv_round_trip_is_byte_stable(tmp_path):
    traj = fig8(duration=6, ramp=1)
    path = tmp_path / "t.csv"
    write_trajectory(path, traj)
    back = read_trajectory(path)
    np.testing.assert_allclose(back.data, traj.data, rtol=1e-11, atol=1e-14)
    assert format_trajectory(back) == path.read_text()
    assert path.read_text().splitlines()[0] == ",".join(COLUMNS)


def _csv(tmp_path, header, rows):
    path = tmp_path / "bad.csv"
    path.write_text(header + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return path


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        ("drop_dwz", "missing columns: dwz"),
        ("extra", "unexpected columns: foo"),
        ("nonuniform", "non-uniform time grid: step 0.02 s at row 4, expected 0.01 s"),
        ("nan", "row 3, column 'x': not finite"),
        ("text", "row 2, column 'y': not a number: 'abc'"),
        ("decreasing", "time not increasing at row 3"),
        ("empty", "empty file"),
    ],
)
def test_bad_trajectory_csv_is_one_clear_error(tmp_path, mutate, message):
    data = fig8(duration=6, ramp=1).data[:5].copy()
    header = ",".join(COLUMNS)
    rows = data.tolist()
    if mutate == "drop_dwz":
        header = ",".join(COLUMNS[:-1])
        rows = [r[:-1] for r in rows]
    elif mutate == "extra":
        header += ",foo"
        rows = [[*r, 0] for r in rows]
    elif mutate == "nonuniform":
        rows[2][0] = 0.03
        rows[3][0], rows[4][0] = 0.04, 0.05
    elif mutate == "nan":
        rows[1][1] = "nan"
    elif mutate == "text":
        rows[0][2] = "abc"
    elif mutate == "decreasing":
        rows[1][0] = 0.0
    path = _csv(tmp_path, header, rows)
    if mutate == "empty":
        path.write_text("")
    before = path.read_bytes()
    with pytest.raises(TrajectoryError) as err:
        read_trajectory(path)
    assert str(err.value) == f"{path}: {message}" or str(err.value).startswith(f"{path}: {message}")
    assert path.read_bytes() == before


def test_trajectory_from_parts_orders_columns():
    t = np.arange(3) * 0.1
    parts = [np.full((3, 3), k) for k in range(6)]
    traj = Trajectory.from_parts(t, *parts)
    assert traj.data.shape == (3, 19)
    np.testing.assert_array_equal(traj.angular_acceleration, 5)


def test_partial_vehicle_yaml_overrides_default(tmp_path):
    path = tmp_path / "v.yaml"
    path.write_text("mass: 5.0\ninertia: [[0.1, 0, 0], [0, 0.11, 0], [0, 0, 0.2]]\n")
    v = load_vehicle(path)
    d = default_vehicle()
    assert v.mass == 5.0
    np.testing.assert_allclose(np.diag(v.inertia), [0.1, 0.11, 0.2])
    assert v.max_thrust == d.max_thrust and v.topics == d.topics
    np.testing.assert_allclose(v.arm_angles, np.deg2rad([30, 90, 150, 210, 270, 330]))


def test_default_vehicle_matches_the_documented_omav():
    v = default_vehicle()
    assert v.mass == 4.0 and v.max_thrust == 20.0 and v.arm_length == 0.3
    np.testing.assert_allclose(np.diag(v.inertia), [0.09, 0.09, 0.17])


def test_vehicle_topics_and_effects(tmp_path):
    path = tmp_path / "v.yaml"
    path.write_text("topics: {imu: /my/imu}\neffects: [rotational_drag]\n")
    v = load_vehicle(path)
    assert v.topics["imu"] == "/my/imu" and v.topics["odometry"] == "/omav/odometry"
    assert v.effects == ("rotational_drag",)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("mass: 4\nwingspan: 2\n", "unknown key 'wingspan'"),
        ("rotor: {max_trust: 3}\n", "unknown key 'rotor.max_trust'"),
        ("mass: -1\n", "key 'mass' must be > 0"),
        ("inertia: [1, 2]\n", "key 'inertia' must be 3 diagonal values or a 3x3 matrix"),
        ("inertia: [[1, 2, 0], [0, 1, 0], [0, 0, 1]]\n", "symmetric positive definite"),
        ("effects: [wind]\n", "unknown effect 'wind'"),
        ("mass: [\n", "invalid YAML"),
        ("geometry: 3\n", "key 'geometry' must be a mapping"),
    ],
)
def test_bad_vehicle_yaml_names_the_key(tmp_path, text, message):
    path = tmp_path / "v.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert str(err.value).startswith(f"{path}: ")
    assert message in str(err.value)


def test_missing_vehicle_file(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        load_vehicle(tmp_path / "nope.yaml")
