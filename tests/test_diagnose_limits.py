"""What keeps a hidden effect from being claimed when the verdict would say "Nothing
missing" (issue 26): the ranking's plausibility at a range's outer bound
(omavctl/diagnose/scoring.py: an estimate at a plausibility limit is implausible, one at
a physical limit is not) and a claim the guard holds back alone (selection.py: the
selection is made again without it)."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.diagnose import selection
from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.scoring import PHYSICAL_LIMIT, EffectScore, score_effects
from omavctl.physics.effects import get_effect


def _data(p: int, theta: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth regressor (n, 3, p), a residual (n, 3) it explains with ``theta`` (p,)
    plus noise, and 2 s blocks (n,)."""
    rng = np.random.default_rng(seed)
    t = np.arange(2000) * 0.01
    f = rng.uniform(0.2, 1.5, (1, 3, p))
    phase = rng.uniform(0, 2 * np.pi, (1, 3, p))
    x = np.sin(2 * np.pi * f * t[:, None, None] + phase)
    residual = x @ theta + rng.normal(0.0, 0.05, (t.size, 3))
    return x, residual, (t // 2.0).astype(int)


def test_an_interference_at_its_physical_limit_is_claimed():
    """own2 draws 5 and 7: a hidden interference of rotor_rotor 0.95 came out at 1.0 (all
    thrust of a pair lost: the physical limit) from the model's remaining error, was
    called implausible, and the verdict said "Nothing missing" with the interference 10x
    the claim floor."""
    assert get_effect("rotor_interference").theta_range[1] == 1.0
    assert "rotor_interference" in PHYSICAL_LIMIT
    x, residual, blocks = _data(2, np.array([1.04, 0.3]))
    (score,) = score_effects(residual, {"rotor_interference": x}, blocks)
    assert score.parameters["rotor_rotor"][0] == 1.0  # at the bound
    assert score.plausible and score.significant and score.missing


def test_a_lag_at_its_plausibility_limit_is_not():
    """A servo lag at its range's 0.5 s says the error asks for more than any vehicle
    has: implausible, not claimed (the rule the physical limit is exempt from)."""
    assert "servo_lag" not in PHYSICAL_LIMIT
    hi = get_effect("servo_lag").theta_range[1]
    x, residual, blocks = _data(1, np.array([1.2 * hi]))
    (score,) = score_effects(residual, {"servo_lag": x}, blocks)
    assert score.parameters["T_s"][0] == hi
    assert not score.plausible and not score.missing


def _score(name: str, missing: bool, contribution: np.ndarray) -> EffectScore:
    return EffectScore(
        name=name,
        explained_variance=0.6 if missing else 0.0,
        explained_per_axis={"x": 0.6, "y": 0.6, "z": 0.6},
        parameters={},
        units={},
        t_value=10.0 if missing else 0.0,
        significant=missing,
        plausible=True,
        contribution=contribution,
        contribution_rms=1.0,
    )


def _selection(monkeypatch: pytest.MonkeyPatch, first: list[str], held: str):
    """The claims of the guarded selection (selection.select_guarded) when the ranking
    holds ``first`` and a look-alike ``rotor_interference`` that explains the same
    error (missing only while ``com_offset`` is not accepted), and the guard holds
    back ``held`` whenever it is claimed."""
    err = np.ones((40, 3))

    def rescore(rem: np.ndarray, pool: dict[str, np.ndarray]) -> list[EffectScore]:
        # the look-alike explains what is left only while the offset has not
        lookalike = "com_offset" in pool or "com_offset" not in first
        out = [_score(n, n != "rotor_interference" or lookalike, err) for n in pool]
        return sorted(out, key=lambda s: (not s.missing, s.name != first[0]))

    def guard(samples, model, names, ranking, stage, rivals=None) -> Guarded:
        return Guarded(
            kept=[n for n in names if n != held],
            held_back=[{"name": held}] if held in names else [],
        )

    monkeypatch.setattr(selection, "_guard", guard)
    candidates = {n: err[:, :, None] for n in [*first, "rotor_interference"]}
    ranking = rescore(err, dict(candidates))
    return selection.select_guarded([], None, (ranking, err, candidates, []), rescore, (0.1, None))


def test_a_claim_held_back_alone_lets_the_effect_it_displaced_be_judged(monkeypatch):
    """own2 draw 5: the ranking took a `com_offset` first, the guard held it back (its
    interval held 0) and nothing was claimed, although the interference it displaced
    explained the error too: the selection is made again without the held-back claim."""
    accepted, _, guarded = _selection(monkeypatch, ["com_offset"], "com_offset")
    assert [a["name"] for a in accepted] == ["rotor_interference"]
    assert guarded.kept == ["rotor_interference"]
    assert [h["name"] for h in guarded.held_back] == ["com_offset"]


def test_a_claim_held_back_beside_a_kept_one_changes_nothing_else(monkeypatch):
    """With a claim kept, the selection is not made again (the rule acts only where the
    verdict would otherwise say nothing is missing)."""
    accepted, _, guarded = _selection(monkeypatch, ["inertia_error", "com_offset"], "com_offset")
    assert guarded.kept == [a["name"] for a in accepted if a["name"] != "com_offset"]
    assert "com_offset" in [a["name"] for a in accepted]
    assert [h["name"] for h in guarded.held_back] == ["com_offset"]
