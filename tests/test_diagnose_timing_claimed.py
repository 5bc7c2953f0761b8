"""The other lags and delays searched beside a claimed one (omavctl/diagnose/
timing_claimed.py; issue 26 "delaylag", docs/scorecard.md session 16): a delay claimed
where a motor lag and a servo lag are hidden gives way to the two lags at their time
constants; a delay hidden alone stays claimed; a lag hidden beside a claimed delay is
added to it; an alternative the guard cannot pin down leaves the claim, named
ambiguous with it; the verdict says why the delay is not claimed."""

from __future__ import annotations

from collections.abc import Sequence
from types import SimpleNamespace

import pytest

from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.joint_text import beside_timing_sentence, replaced_step, replaced_text
from omavctl.diagnose.timing_claimed import beside_claimed
from tests.test_diagnose_timing_pair import FLOOR, MODEL, _flight


def _guard(pinned: set[str], seen: list[list[str]] | None = None):
    """A claims guard that keeps ``pinned`` and records what it was asked."""

    def guard(names: list[str], found: Sequence[str]) -> Guarded:
        assert set(found) <= set(names)
        if seen is not None:
            seen.append(list(names))
        held = [{"name": n, "estimate": {}} for n in names if n not in pinned]
        return Guarded([n for n in names if n in pinned], {}, held)

    return guard


def _scores(*names: str) -> list[SimpleNamespace]:
    return [SimpleNamespace(name=n, ambiguous_with=[]) for n in names]


def test_a_delay_claimed_for_two_hidden_lags_gives_way_to_both():
    """report8 draw 25's case: motor and servo lags hidden, the joint step took the delay."""
    s, physics = _flight({"motor_lag": 0.04, "servo_lag": 0.07}, seed=3)
    before = Guarded(["com_offset", "command_delay"], {}, [])
    pinned = {"com_offset", "motor_lag", "servo_lag", "command_delay"}
    out = beside_claimed([s], MODEL, physics, before, FLOOR, _guard(pinned))  # type: ignore[arg-type]
    assert out.kept == ["com_offset", "motor_lag", "servo_lag"]
    (held,) = out.held_back
    assert held["name"] == "command_delay"
    beside = held["beside_timing"]
    assert beside["instead"]["names"] == ["motor_lag", "servo_lag"]
    assert beside["instead"]["values_s"] == pytest.approx([0.04, 0.07], abs=0.003)
    assert beside["share"] > 0.5 and beside["hac_t"] > 2.5
    text = beside_timing_sentence("command_delay", beside)
    assert text.startswith(" Not claimed: command_delay, which the held-out flight tells from")
    assert "motor_lag and servo_lag (40.0 ms, 70.0 ms)" in text


def test_a_delay_hidden_alone_stays_claimed():
    s, physics = _flight({"command_delay": 0.05}, seed=4)
    before = Guarded(["command_delay"], {}, [])
    scores = _scores("command_delay", "motor_lag")
    out = beside_claimed([s], MODEL, physics, before, FLOOR, _guard({"command_delay"}), scores)  # type: ignore[arg-type]
    assert out is before
    assert out.kept == ["command_delay"] and out.held_back == []
    assert scores[0].ambiguous_with == []  # a delay on steps is told from a lag


def test_a_servo_lag_hidden_beside_a_claimed_delay_is_added():
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10}, seed=5)
    before = Guarded(["command_delay"], {}, [])
    out = beside_claimed([s], MODEL, physics, before, FLOOR, _guard({"command_delay", "servo_lag"}))  # type: ignore[arg-type]
    assert out.kept == ["command_delay", "servo_lag"]
    assert out.held_back == []


def test_an_alternative_the_guard_cannot_pin_down_leaves_the_claim_named_ambiguous():
    s, physics = _flight({"motor_lag": 0.04, "servo_lag": 0.07}, seed=3)
    before = Guarded(["command_delay"], {}, [])
    scores = _scores("command_delay", "motor_lag", "servo_lag")
    seen: list[list[str]] = []
    guard = _guard({"command_delay"}, seen)
    out = beside_claimed([s], MODEL, physics, before, FLOOR, guard, scores)  # type: ignore[arg-type]
    assert seen == [["motor_lag", "servo_lag"]]
    assert out is before
    assert scores[0].ambiguous_with == ["motor_lag", "servo_lag"]


def test_a_model_with_a_lag_is_left_as_it_is():
    s, physics = _flight({"motor_lag": 0.04, "servo_lag": 0.07}, seed=3)
    model = SimpleNamespace(effects={"motor_lag": object()})
    before = Guarded(["command_delay"], {}, [])
    out = beside_claimed([s], model, physics, before, FLOOR, _guard(set()))  # type: ignore[arg-type]
    assert out is before


def test_lags_that_replaced_a_delay_are_not_said_to_take_its_joint_step():
    """report8 draw 25's verdict said the lags took the delay's joint step because the
    delay 'could not be pinned down', with the delay's share: the delay was pinned down
    and replaced by the lags' exact forms."""
    step = {"name": "command_delay", "timing_rivals": ["servo_lag", "motor_lag"]}
    diag = {"joint_steps": [step], "missing": ["motor_lag", "servo_lag"], "not_pinned": []}
    assert replaced_step(diag, "motor_lag") == "command_delay"  # the rivals' path
    diag["not_pinned"] = [{"name": "command_delay", "beside_timing": {}}]
    assert replaced_step(diag, "motor_lag") is None
    assert replaced_text(diag, "servo_lag") == ""
