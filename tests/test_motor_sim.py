"""The truth plant hides the motor-level effects in the omav's rotors.

``thrust_curve``, ``motor_loss`` and ``battery_sag`` act on each rotor's thrust in
the simulator (:meth:`omavctl.sim.plant._Actuators.motor_level`); its logs carry
the rotor speeds (``/omav/actuators``) and the battery voltage they need, and the
``omav-rotors`` preset mixes the wrench from those speeds, so that ``fit`` sees them.
Short flights (8 s, physics at 400 Hz) keep each test near 10 s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_fit import attitude_sines

from omavctl.base.errors import ConfigError
from omavctl.learn.fit import fit_model
from omavctl.logs import write_log
from omavctl.logs.read import read_raw
from omavctl.physics.allocation import Allocation
from omavctl.physics.effects import SIMULATED_EFFECTS
from omavctl.sim.plant import _Actuators, simulate
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import Vehicle, default_vehicle, load_vehicle


def _rotors(tmp_path: Path) -> Vehicle:
    path = tmp_path / "omav-rotors.yaml"
    path.write_text("preset: omav-rotors\n")
    return load_vehicle(path)


def _fly(tmp_path: Path, veh: Vehicle, tree: dict, name: str) -> Path:
    ref = attitude_sines((15, 15, 15), (1.6, 2.1, 2.7), duration=8.0)
    res = simulate(ref, veh, truth_from_tree(tree, veh), physics_rate=400.0)
    path = tmp_path / f"{name}.csv"
    write_log(path, res.log)
    return path


def _inside(value, se, truth) -> bool:
    return bool(np.all(np.abs(np.asarray(value) - truth) <= 1.96 * np.asarray(se)))


def test_every_registered_effect_can_be_hidden() -> None:
    """The plant takes every effect; the draws leave out the motor-level ones, which
    the default vehicle's fit cannot see, drag_moment, which needs an accelerometer
    the plant does not log, and arm_thrust, which the plant's default thrust spread
    already gives every vehicle (docs/effects.md)."""
    from omavctl.physics.effects import EFFECTS

    for name, effect in EFFECTS.items():
        params = {p.name: [0.01] * p.size for p in effect.parameters}
        truth = truth_from_tree({"effects": {name: params}}, default_vehicle())
        assert [e.name for e, _ in truth.effects] == [name]
    motor_level = {"thrust_curve", "motor_loss", "battery_sag"}
    assert set(SIMULATED_EFFECTS) == set(EFFECTS) - motor_level - {"drag_moment", "arm_thrust"}


def test_the_motor_level_thrust_of_the_truth_plant() -> None:
    """Bend, loss and sag act on each rotor's thrust as their regressors assume."""
    veh = default_vehicle()
    loss = np.zeros(12)
    loss[3] = 0.2
    tree = {
        "effects": {
            "thrust_curve": {"c": -0.3},
            "motor_loss": {"l": loss.tolist()},
            "battery_sag": {"k": 0.1},
        },
        "battery": {"nominal": 20.0, "drop": 2.0, "sag": 0.01},
    }
    truth = truth_from_tree(tree, veh)
    act = _Actuators(veh, truth, Allocation(veh), np.random.default_rng(0), duration=10.0)
    full = veh.max_thrust
    x = np.array([0.0, 0.5, 1.0])  # speed over full speed: thrust full x^2
    thrusts = np.repeat((full * x**2)[:, None], 12, axis=1)
    volts = np.array([20.0, 20.0, 21.0])
    out = act.motor_level(thrusts, volts)
    bent = full * (x**2 - 0.3 * (x**2 - x))  # c T_full (x^2 - x), c = -0.3
    np.testing.assert_allclose(out[:, 0], bent * [1.0, 1.0, 1.1])
    np.testing.assert_allclose(out[:, 3], 0.8 * bent * [1.0, 1.0, 1.1])
    # the voltage: nominal at mid-flight hover, drop over the flight, sag with thrust
    hover = np.full((3, 12), veh.mass * veh.gravity / 12)
    np.testing.assert_allclose(act.battery(np.array([0.0, 5.0, 10.0]), hover), [21, 20, 19])
    np.testing.assert_allclose(act.battery(np.array([5.0]), hover[:1] + 1.0), [20 - 0.12])


def test_a_weak_rotor_of_the_omav_is_found_from_its_simulated_rotor_speeds(
    tmp_path: Path,
) -> None:
    veh = _rotors(tmp_path)
    loss = np.zeros(12)
    loss[2] = 0.3
    tree = {"effects": {"motor_loss": {"l": loss.tolist()}}, "actuators": {"thrust_spread": 0}}
    log = _fly(tmp_path, veh, tree, "loss")
    raw = read_raw(log)
    assert raw.series["rotor"].values.shape[1] == 12 and "battery_voltage" in raw.series
    model = fit_model([log], veh, effects=["rotor_interference", "motor_loss"], points=40)
    est = model.model.effects["motor_loss"]
    value, se = np.asarray(est.values["l"]), np.asarray(est.stderr["l"])
    assert _inside(value, se, loss - loss.mean()), (value, se)
    assert int(np.argmax(value)) == 2, value


def test_thrust_curve_and_battery_sag_hidden_in_the_omav_and_not_in_a_clean_one(
    tmp_path: Path,
) -> None:
    veh = _rotors(tmp_path)
    effects = ["rotor_interference", "thrust_curve", "battery_sag"]
    battery = {"drop": 3.0}
    hidden = {"thrust_curve": {"c": -0.2}, "battery_sag": {"k": 0.1}}
    bent = _fly(tmp_path, veh, {"effects": hidden, "battery": battery}, "bent")
    clean = _fly(tmp_path, veh, {"battery": battery}, "clean")
    for log, c, k in ((bent, -0.2, 0.1), (clean, 0.0, 0.0)):
        est = fit_model([log], veh, effects=effects, points=40).model.effects
        curve, sag = est["thrust_curve"], est["battery_sag"]
        assert _inside(curve.values["c"], curve.stderr["c"], c), (log, curve)
        assert _inside(sag.values["k"], sag.stderr["k"], k), (log, sag)
        assert curve.stderr["c"][0] < 0.2 and sag.stderr["k"][0] < 0.2, (curve, sag)


@pytest.mark.parametrize(
    ("effect", "params", "message"),
    [
        ("thrust_curve", {"c": 1.5}, "'effects.thrust_curve.c' must lie in -1 to 1"),
        ("battery_sag", {"k": -2.0}, "'effects.battery_sag.k' must lie in -1 to 2"),
        ("motor_loss", {"l": [1.0] + [0.0] * 11}, "'effects.motor_loss.l' must lie in -0.5 to 0.9"),
    ],
)
def test_implausible_motor_level_truths_are_refused(effect, params, message) -> None:
    with pytest.raises(ConfigError) as err:
        truth_from_tree({"effects": {effect: params}}, default_vehicle())
    assert str(err.value) == message
