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


def test_a_delay_behind_a_faster_controller_than_the_log_shows_as_the_command_late(vehicle, task):
    """A 1 kHz controller logged at 100 Hz: each row holds one sample of a command that
    jitters between rows; fitted as if held, the 50 ms delay reads as a lag of both kinds
    (and the fitted delay rules the delay out). The log is told by its commands'
    incoherence with the actuators; only how late they are in all is read, and both
    kinds late by one time show the command late, not two lags."""
    from pathlib import Path
    from types import SimpleNamespace

    from omavctl.diagnose.actuators import ruled_out, shown_timing
    from omavctl.learn.fit_notes import actuator_notes

    tree = {"ideal": True, "effects": {"command_delay": {"tau_d": 0.05}}}
    fast = truth_from_tree({**tree, "timing": {"controller_rate_hz": 1000.0}}, vehicle)
    flight = align(simulate(task, vehicle, fast, seed=3, physics_rate=1000.0).log)
    fits = actuator_timing(flight, vehicle)
    for fit in fits.values():
        assert fit.undersampled, fit.coherence
        assert fit.tau < 0.03 and fit.T > 0.02  # the shape the jitter gives it
        assert _inside(0.05, fit.timing("tau")[1]), fit
    assert list(shown_timing(fits)) == ["command_delay"]
    assert _inside(0.05, shown_timing(fits)["command_delay"]["ci95"])
    assert ruled_out(fits) == {"servo_lag", "motor_lag"}
    # fit's note beside a fitted delay reads the same lateness, not the split's 4-15 ms
    sample = SimpleNamespace(flight=flight, path=Path("fit.csv"))
    (note,) = actuator_notes({"command_delay": None}, [sample], vehicle)  # type: ignore[dict-item]
    value = float(note.split("gives ")[1].split(" ms late in all")[0])
    assert _inside(value / 1e3, shown_timing(fits)["command_delay"]["ci95"]), note
    assert abs(value - 50.0) < 5.0, note
    # the same delay behind a controller at the log's rate: its commands cohere
    held = _timing(vehicle, task, tree)
    assert all(not f.undersampled and f.coherence > 0.8 for f in held.values()), held


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


# ----------------------------------------------------------- in the diagnosis
def _fit(kind: str, tau: float, lag: float, none: float = 0.05, left: float = 0.002):
    from omavctl.learn.actuator_timing import ActuatorFit

    return ActuatorFit(
        kind=kind, unit="rad" if kind == "tilt" else "N", tau=tau, T=lag,
        tau_ci95=(max(tau - 0.002, 0.0), tau + 0.002), T_ci95=(max(lag - 0.002, 0.0), lag + 0.002),
        rms_none=none, rms_fit=left, rms_lag_only=left, rms_delay_only=left, rows=1000,
    )  # fmt: skip


def test_what_the_actuators_show_and_rule_out() -> None:
    from omavctl.diagnose.actuators import ruled_out, shown_timing

    servo = {"tilt": _fit("tilt", 0.0, 0.09), "rotor": _fit("rotor", 0.0, 0.005)}
    assert list(shown_timing(servo)) == ["servo_lag"]
    assert ruled_out(servo) == {"motor_lag", "command_delay"}
    delay = {"tilt": _fit("tilt", 0.05, 0.005), "rotor": _fit("rotor", 0.05, 0.004)}
    assert list(shown_timing(delay)) == ["command_delay"]
    assert shown_timing(delay)["command_delay"]["value"] == pytest.approx(0.05)
    assert ruled_out(delay) == {"servo_lag", "motor_lag"}
    # late by different times: no one delay; a fit that leaves most of the mismatch: none
    assert shown_timing({"tilt": _fit("tilt", 0.05, 0.0), "rotor": _fit("rotor", 0.02, 0.0)}) == {}
    assert shown_timing({"tilt": _fit("tilt", 0.0, 0.09, none=0.003)}) == {}


def test_a_timing_claim_the_actuators_rule_out_gives_way_to_the_one_they_show() -> None:
    from types import SimpleNamespace

    from omavctl.diagnose.actuators import actuator_sentence, with_actuators
    from omavctl.diagnose.claims import Guarded

    samples = [SimpleNamespace(exact=lambda name, v: np.full((50, 3), 10.0 * v))]
    delay = {"tilt": _fit("tilt", 0.05, 0.005), "rotor": _fit("rotor", 0.05, 0.004)}
    before = Guarded(kept=["com_offset", "motor_lag"], estimates={"motor_lag": {"T_m": [0.04]}})
    model = SimpleNamespace(effects={})
    after, info = with_actuators(samples, model, before, delay, floor=0.1)  # type: ignore[arg-type]
    assert after.kept == ["com_offset", "command_delay"]
    assert [h["name"] for h in after.held_back] == ["motor_lag"]
    assert info is not None and info["claimed"] == ["command_delay"]
    assert actuator_sentence({"actuators": info}) == (
        " The actuators' own feedback (the logged tilts and rotor speeds): the tilts follow "
        "their commands 50 ms late (95 %: 48 ms to 52 ms); the rotors' thrusts follow their "
        "commands 50 ms late (95 %: 48 ms to 52 ms): they show command_delay (tau_d 50 ms); "
        "claimed from them: command_delay; they rule out motor_lag, claimed from the torque "
        "alone: held back."
    )
    # under the claim floor in this flight's torque: said, not claimed
    low, info = with_actuators(samples, model, before, delay, floor=10.0)  # type: ignore[arg-type]
    assert low.kept == ["com_offset"] and info is not None and info["claimed"] == []
    assert "under the claim floor in this flight's torque: command_delay" in actuator_sentence(
        {"actuators": info}
    )


def test_evaluate_names_the_servo_lag_its_tilts_show(vehicle, tmp_path) -> None:
    """A 0.1 s servo lag on the default vehicle, fit on attitude sines, judged on a
    figure-8: the verdict names it from the logged tilts and says how they follow."""
    from test_fit import attitude_sines

    from omavctl.diagnose.evaluate import evaluate
    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model
    from omavctl.logs import write_log

    truth = truth_from_tree({"seed": 2, "effects": {"servo_lag": {"T_s": 0.1}}}, vehicle)
    fit_ref = attitude_sines((18, 18, 25), (2.2, 2.9, 3.7), duration=10.0)
    held_ref = fig8(roll_deg=18, pitch_deg=18, period=5.0, duration=10.0, ramp=1.5)
    fit_log, held_log = tmp_path / "fit.csv", tmp_path / "held.csv"
    write_log(fit_log, simulate(fit_ref, vehicle, truth, seed=5).log)
    write_log(held_log, simulate(held_ref, vehicle, truth, seed=6).log)
    model = tmp_path / "m0.npz"
    save_model(model, fit_model([fit_log], vehicle, points=40, restarts=0).model)
    diag = evaluate([model], [held_log], horizons=()).tree["diagnosis"]
    shown = diag["actuators"]["shown"]
    assert list(shown) == ["servo_lag"]
    assert shown["servo_lag"]["value"] == pytest.approx(0.1, rel=0.05)
    assert _inside(0.1, shown["servo_lag"]["ci95"])
    assert "servo_lag" in diag["missing"]
    assert "motor_lag" in diag["actuators"]["ruled_out"]
    assert "--effects" in diag["fit_command"] and "servo_lag" in diag["fit_command"]
    # fit says beside its torque estimate what the tilts of its log show
    notes = fit_model(
        [fit_log], vehicle, effects=["servo_lag"], points=40, restarts=0
    ).summary.notes
    said = [n for n in notes if n.startswith("servo_lag: the actuators' own feedback of fit.csv")]
    assert len(said) == 1, notes
    value = float(said[0].split("T_s = ")[1].split(" ms")[0])
    assert value == pytest.approx(100.0, rel=0.05)


def test_a_gaps_commands_hold_the_last_valid_row() -> None:
    from omavctl.learn.actuator_timing import _held_over_gaps

    values = np.arange(6.0)[:, None]
    rows = np.array([False, True, True, False, False, True])
    assert _held_over_gaps(values, rows)[:, 0].tolist() == [1.0, 1.0, 2.0, 2.0, 2.0, 5.0]


def test_actuators_that_follow_at_once_are_not_said_unless_a_lag_is_in_question() -> None:
    from omavctl.diagnose.actuators import actuator_sentence

    quick = {k: _fit(k, 0.0, 0.005).to_json() for k in ("tilt", "rotor")}
    info = {"fits": quick, "shown": {}, "held_back": [], "claimed": []}
    assert actuator_sentence({"actuators": info, "missing": ["rotational_drag"]}) == ""
    said = actuator_sentence({"actuators": info, "missing": ["motor_lag"]})
    assert said.endswith("the rotors' thrusts follow their commands within 5.0 ms.")


def test_a_lag_the_actuators_rule_out_is_said_once() -> None:
    from omavctl.diagnose.actuators import actuator_sentence
    from omavctl.diagnose.claim_text import not_pinned_text

    servo = {
        "tilt": _fit("tilt", 0.0, 0.09).to_json(),
        "rotor": _fit("rotor", 0.0, 0.004).to_json(),
    }
    info = {
        "fits": servo,
        "shown": {"servo_lag": {"value": 0.09, "ci95": [0.088, 0.092], "parameter": "T_s",
                                "part_over_floor": 1.8}},
        "ruled_out": ["command_delay", "motor_lag"],
        "claimed": ["servo_lag"],
        "held_back": [],
    }  # fmt: skip
    held = [{"name": "motor_lag", "units": {"T_m": "s"}, "estimate": None}]
    diag = {"actuators": info, "missing": ["servo_lag"], "not_pinned": held}
    assert not_pinned_text(diag) == ""
    assert actuator_sentence(diag).endswith(
        "claimed from them: servo_lag; they rule out motor_lag, which the torque could not "
        "pin down."
    )


def test_a_faster_controllers_actuators_are_said_late_in_all() -> None:
    """The verdict says why a delay is named where a delay and a lag are not told apart."""
    from dataclasses import replace

    from omavctl.diagnose.actuators import actuator_sentence, shown_timing

    base = _fit("tilt", 0.004, 0.048)
    late = dict(late=0.052, late_ci95=(0.050, 0.053), coherence=0.06, roughness=1.0, period=0.01)
    fits = {k: replace(base, kind=k, **late) for k in ("tilt", "rotor")}  # type: ignore[arg-type]
    shown = shown_timing(fits)
    assert list(shown) == ["command_delay"]
    info = {
        "fits": {k: f.to_json() for k, f in fits.items()},
        "shown": {"command_delay": {**shown["command_delay"], "parameter": "tau_d",
                                    "part_over_floor": 2.0}},
        "claimed": ["command_delay"], "held_back": [], "ruled_out": ["motor_lag", "servo_lag"],
    }  # fmt: skip
    assert actuator_sentence({"actuators": info, "missing": ["command_delay"]}) == (
        " The actuators' own feedback (the logged tilts and rotor speeds): the tilts are 52 ms "
        "late in all (95 %: 45 ms to 58 ms); the rotors' thrusts are 52 ms late in all (95 %: "
        "45 ms to 58 ms) (the log's commands are samples of a faster controller: between its "
        "rows they move in ways the actuators do not follow, so a delay and a lag are not told "
        "apart from them; tilts and rotors late by one time are the command late): they show "
        "command_delay (tau_d 52 ms); claimed from them: command_delay."
    )


def test_the_lateness_interval_reaches_past_the_longest_delay() -> None:
    """A 0.3 s lag (beyond the 0.2 s delays searched): its lateness interval holds it."""
    from omavctl.learn.actuator_timing import fit_timing

    rng = np.random.default_rng(0)
    t = np.arange(2000) * 0.01
    command = np.sin(2 * np.pi * 0.3 * t)[:, None] + 0.3 * np.sin(2 * np.pi * 1.1 * t)[:, None]
    measured = delayed_lag(command, 0.0, 0.3, 0.01) + 1e-3 * rng.standard_normal(command.shape)
    fit = fit_timing("tilt", "rad", command, measured, np.ones(2000, bool), 0.01)
    assert fit is not None and not fit.undersampled
    assert fit.T == pytest.approx(0.3, rel=0.02)
    assert fit.late_ci95[0] <= 0.3 <= fit.late_ci95[1] and fit.late_ci95[1] > 0.2
