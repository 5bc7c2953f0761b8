"""An effect linear in its parameters estimated on the held-out flight itself
(omavctl/diagnose/linear_profile.py; issue 26, docs/scorecard.md session 23): a drag
whose gain sits in a few step transitions fails the Newey-West bar and is found by the
cross-fitted block sign test, at its value; noise alone, a drag under twice the claim
floor, and a drag implausible on an excited axis are not claimed; a component the flight
hardly excites is not judged; the claim is made only when nothing but the look-alikes is
claimed, kept only when the guard keeps it, and the verdict says how it was found."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.joint import MIN_HAC_T, hac_t
from omavctl.diagnose.joint_text import linear_words
from omavctl.diagnose.linear_profile import PART_FLOOR, SIGN_P, linear_fits, with_linear
from omavctl.diagnose.timing_profile import profile_for
from tests.test_diagnose_timing_pair import quiet_regressors

DT = 0.01
FLOOR = 0.05
N = 3000  # 30 s: 15 blocks of 2 s
T = np.arange(N) * DT
MODEL = SimpleNamespace(effects={})


class _Samples:
    """Held-out attitude steps: the body rate ``w`` (rad/s) is a short pulse at each
    step (one every 2 s, random sign, sizes spread over a factor of ~20 per axis, so a
    few steps carry most of the gain), zero between; the drag's
    regressor is -w per axis, the inertia error's a slow unrelated signal."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        w = np.zeros((N, 3))
        for start in range(50, N, 200):
            w[start : start + 30] = rng.choice([-1, 1], 3) * np.exp(rng.normal(0.0, 1.5, 3))
        self.t, self.n = T, N
        self.sg = SimpleNamespace(dt=DT)
        slow = np.sin(2 * np.pi * 0.05 * T)[:, None] * np.ones(3)
        self.regressors = {
            **quiet_regressors(N),
            "rotational_drag": -w[:, :, None] * np.eye(3)[None],
            "inertia_error": slow[:, :, None] * np.eye(3)[None],
        }


def _flight(drag: list[float], seed: int = 0, noise: float = FLOOR) -> tuple[_Samples, np.ndarray]:
    """The samples and the physics-only error of a drag (per axis) with white noise."""
    s = _Samples(seed)
    physics = np.einsum("nap,p->na", s.regressors["rotational_drag"], np.asarray(drag, float))
    rng = np.random.default_rng(seed + 100)
    return s, physics + rng.normal(0.0, noise, size=(N, 3))


def test_a_drag_in_a_few_transitions_is_found_by_its_blocks_not_its_t():
    s, physics = _flight([0.8, 0.8, 0.8])
    prof = profile_for([s], MODEL, physics, ["rotational_drag"])  # type: ignore[arg-type]
    before = profile_for([s], MODEL, physics).left([], [])  # type: ignore[arg-type]
    after = prof.left([], [])
    assert 1 - after.sum() / before.sum() > 0.9
    assert hac_t(before, after) < MIN_HAC_T  # the per-sample bar misses it
    (fit,) = linear_fits([s], MODEL, physics, FLOOR)  # type: ignore[arg-type]
    assert fit.name == "rotational_drag"
    assert fit.theta == pytest.approx([0.8, 0.8, 0.8], abs=0.02)
    assert fit.cross_share > 0.9 and fit.better == fit.blocks == 15
    assert fit.sign_p <= SIGN_P and fit.ambiguous_with == []


def test_noise_alone_and_a_drag_near_the_floor_are_not_claimed():
    s, physics = _flight([0.0, 0.0, 0.0], seed=1)
    assert linear_fits([s], MODEL, physics, FLOOR) == []  # type: ignore[arg-type]
    # a drag whose part is 1.5 claim floors: consistent, but not clear of the floor
    reg = _Samples(2).regressors["rotational_drag"]
    d = 1.5 * FLOOR / np.sqrt((reg**2).mean(axis=(0, 1)).sum())
    s, physics = _flight([d, d, d], seed=2, noise=FLOOR / 10)
    part = np.sqrt((np.einsum("nap,p->na", reg, [d] * 3) ** 2).mean())
    assert FLOOR < part < PART_FLOOR * FLOOR
    assert linear_fits([s], MODEL, physics, FLOOR) == []  # type: ignore[arg-type]


def test_plausibility_is_judged_on_the_axes_the_flight_excites():
    # 1.3 is beyond the drag's plausible range (at most 1): on an axis whose part is
    # under the claim floor it is not judged, on an excited axis it is
    s, physics = _flight([0.8, 0.8, 0.0], seed=3)
    s.regressors["rotational_drag"][:, 2, 2] *= 0.01  # yaw hardly excited
    physics[:, 2] += 1.3 * s.regressors["rotational_drag"][:, 2, 2]
    (fit,) = linear_fits([s], MODEL, physics, FLOOR)  # type: ignore[arg-type]
    assert fit.name == "rotational_drag" and not fit.judged[2]
    s, physics = _flight([1.3, 0.8, 0.8], seed=3)
    assert linear_fits([s], MODEL, physics, FLOOR) == []  # type: ignore[arg-type]


def _guard(keep: bool):
    def guard(names: list[str], found: object) -> Guarded:
        kept = list(names) if keep else [n for n in names if n not in ("rotational_drag",)]
        return Guarded(kept, {}, [])

    return guard


def test_claimed_only_beside_the_look_alikes_and_kept_by_the_guard():
    s, physics = _flight([0.8, 0.8, 0.8], seed=4)
    given = Guarded(["com_offset"], {}, [])
    out = with_linear([s], MODEL, physics, given, FLOOR, _guard(True))  # type: ignore[arg-type]
    assert out.kept == ["com_offset", "rotational_drag"]
    assert out.profiles["rotational_drag"]["kind"] == "linear"
    # held back by the guard: nothing changes
    out = with_linear([s], MODEL, physics, given, FLOOR, _guard(False))  # type: ignore[arg-type]
    assert out is given
    # another claim already made: not looked for
    other = Guarded(["motor_lag"], {}, [])
    assert with_linear([s], MODEL, physics, other, FLOOR, _guard(True)) is other  # type: ignore[arg-type]


def test_the_verdict_says_how_the_held_out_flight_found_it():
    s, physics = _flight([0.8, 0.8, 0.8], seed=5)
    out = with_linear([s], MODEL, physics, Guarded([], {}, []), FLOOR, _guard(True))  # type: ignore[arg-type]
    diag = {"missing": out.kept, "timing_claims": out.profiles}
    said = linear_words(diag, "rotational_drag")
    assert said == (
        "estimated on this flight beside the look-alikes, it removes 100 % of the "
        "physics-only error they leave, judged on 2 s blocks it was not fitted on "
        "(lower in 15 of 15)"
    )
    assert (
        linear_words({"timing_claims": {"motor_lag": {"names": ["motor_lag"]}}}, "motor_lag")
        is None
    )
