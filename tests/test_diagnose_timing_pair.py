"""Two lags or delays profiled together with their exact forms (omavctl/diagnose/
timing_pair.py; issue 26 "pair", docs/scorecard.md session 15): a delay and a servo lag
hidden together are both found, at their time constants; one lag alone is not made a
pair; noise claims nothing; the claims guard decides what is kept."""

from __future__ import annotations

from collections.abc import Sequence
from types import SimpleNamespace

import numpy as np
import pytest

from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.joint import MIN_HAC_T, MIN_SHARE
from omavctl.diagnose.timing_pair import timing_fits, with_timing_pair
from omavctl.physics.actuator_effects import first_order_lag

DT = 0.01  # a 100 Hz controller
FLOOR = 0.05
N = 2000


def _steps(rng: np.random.Generator) -> np.ndarray:
    """Steps of a commanded angular acceleration (n, 3), rad/s², every 0.3-1 s."""
    edges = np.cumsum(rng.integers(30, 100, size=80))
    level = rng.normal(0.0, 3.0, size=(edges.size + 1, 3))
    return level[np.searchsorted(edges, np.arange(N), side="right")]


def quiet_regressors(n: int) -> dict[str, np.ndarray]:
    """Regressors (n, 3, p) of the look-alikes and the lags and delays, none excited (the
    lags' and delays' exact forms carry them)."""
    zeros = np.zeros((n, 3, 1))
    return {
        "com_offset": np.zeros((n, 3, 3)),
        "rotor_interference": np.zeros((n, 3, 2)),
        "command_delay": zeros,
        "motor_lag": zeros,
        "servo_lag": zeros,
    }


class _Samples:
    """Held-out samples: the delay and the motor lag act on the command ``u``, the servo
    lag on a second command ``v`` (the tilt's share of the torque); the look-alikes'
    regressors are not excited."""

    def __init__(self, u: np.ndarray, v: np.ndarray) -> None:
        self.u, self.v = u, v
        self.sg = SimpleNamespace(dt=DT)
        self.regressors = quiet_regressors(N)

    def exact(self, name: str, value: float) -> np.ndarray:
        if name == "command_delay":
            t = np.arange(N) * DT
            late = np.stack([np.interp(t - value, t, self.u[:, i]) for i in range(3)], axis=1)
            return late - self.u
        if name == "motor_lag":
            return first_order_lag(self.u, value, DT) - self.u
        assert name == "servo_lag"
        return first_order_lag(self.v, value, DT) - self.v


def _flight(hidden: dict[str, float], seed: int = 0) -> tuple[_Samples, np.ndarray]:
    """The samples and the physics-only error of the ``hidden`` lags and delays (name ->
    time constant, s) with noise 10x under the claim floor."""
    rng = np.random.default_rng(seed)
    s = _Samples(_steps(rng), 0.5 * _steps(rng))
    physics = sum((s.exact(n, t) for n, t in hidden.items()), np.zeros((N, 3)))
    return s, physics + rng.normal(0.0, FLOOR / 10, size=(N, 3))


MODEL = SimpleNamespace(effects={})


def test_a_delay_and_a_servo_lag_hidden_together_are_both_found():
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10})
    (fit,) = timing_fits([s], MODEL, physics, FLOOR, DT)  # type: ignore[arg-type]
    assert fit.names == ("command_delay", "servo_lag")
    assert fit.values == pytest.approx((0.05, 0.10), abs=0.002)
    # each member removes most of what the other alone leaves, far above every bar
    assert min(fit.member_share) > 0.9 > MIN_SHARE
    assert min(fit.hac) > MIN_HAC_T
    assert min(fit.part) > 10 * FLOOR
    assert fit.ambiguous_with == []


def test_one_lag_alone_is_not_made_a_pair():
    s, physics = _flight({"motor_lag": 0.08}, seed=1)
    (fit,) = timing_fits([s], MODEL, physics, FLOOR, DT)  # type: ignore[arg-type]
    assert fit.names == ("motor_lag",)
    assert fit.values[0] == pytest.approx(0.08, abs=0.002)


def test_noise_alone_claims_no_lag_or_delay():
    s, physics = _flight({}, seed=2)
    assert timing_fits([s], MODEL, physics, FLOOR, DT) == []  # type: ignore[arg-type]


def _guard(pinned: set[str]):
    def guard(names: list[str], found: Sequence[str]) -> Guarded:
        assert set(found) <= set(names)
        held = [{"name": n, "estimate": {}} for n in names if n not in pinned]
        return Guarded([n for n in names if n in pinned], {}, held)

    return guard


@pytest.mark.parametrize("pinned", [{"command_delay", "servo_lag"}, {"servo_lag"}])
def test_the_guard_decides_and_what_it_holds_back_is_said(pinned):
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10})
    before = Guarded(["com_offset"], {}, [])
    out = with_timing_pair([s], MODEL, physics, before, FLOOR, _guard({"com_offset", *pinned}))  # type: ignore[arg-type]
    if len(pinned) == 2:
        assert out.kept == ["com_offset", "command_delay", "servo_lag"]
        assert out.held_back == []
    else:  # one member not pinned down: neither is claimed, both are said with the profile
        assert out.kept == ["com_offset"]
        (held,) = out.held_back
        assert held["name"] == "command_delay"
        assert held["timing_pair"]["names"] == ["command_delay", "servo_lag"]


def test_a_lag_claimed_already_is_left_as_it_is():
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10})
    before = Guarded(["motor_lag"], {}, [])
    out = with_timing_pair([s], MODEL, physics, before, FLOOR, _guard(set()))  # type: ignore[arg-type]
    assert out is before


def test_a_member_held_back_twice_is_said_once():
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10})

    def guard(names: list[str], found: Sequence[str]) -> Guarded:
        held = [{"name": "servo_lag", "estimate": {"T_s": [0.2]}}, {"name": "servo_lag"}]
        return Guarded([n for n in names if n != "servo_lag"], {}, held)

    out = with_timing_pair([s], MODEL, physics, Guarded([], {}, []), FLOOR, guard)  # type: ignore[arg-type]
    assert out.kept == []
    assert [h["name"] for h in out.held_back] == ["servo_lag"]
    assert out.held_back[0]["estimate"] == {"T_s": [0.2]}  # the first entry


def test_a_claim_of_the_profile_is_not_also_said_not_claimed():
    """report8 draw 37: the first guard held the servo lag back on the fit flight's
    first-order estimate, the profile then claimed it: the verdict said "Missing:
    servo_lag" and "Not claimed: servo_lag" one after the other."""
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10})
    before = Guarded(["com_offset"], {}, [{"name": "servo_lag", "fit_flight": {}}])
    pinned = {"com_offset", "command_delay", "servo_lag"}
    out = with_timing_pair([s], MODEL, physics, before, FLOOR, _guard(pinned))  # type: ignore[arg-type]
    assert out.kept == ["com_offset", "command_delay", "servo_lag"]
    assert out.held_back == []


def test_held_back_before_and_by_the_profile_is_said_once_with_the_profile():
    """report8 draw 41 listed the motor lag twice in not_pinned."""
    s, physics = _flight({"command_delay": 0.05, "servo_lag": 0.10})
    before = Guarded(["com_offset"], {}, [{"name": "command_delay"}, {"name": "inertia_error"}])
    out = with_timing_pair([s], MODEL, physics, before, FLOOR, _guard({"com_offset"}))  # type: ignore[arg-type]
    assert out.kept == ["com_offset"]
    assert [h["name"] for h in out.held_back] == ["command_delay", "inertia_error", "servo_lag"]
    assert out.held_back[0]["timing_pair"]["names"] == ["command_delay", "servo_lag"]
