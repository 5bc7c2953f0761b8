"""The other lags and delays searched beside a claimed one (issue 26, "delaylag").

A command delay, a motor lag and a servo lag coincide to first order, so the joint
selection accepts whichever of them its linearised test prefers by a few per cent, and
the profile of :mod:`omavctl.diagnose.timing_pair` runs only when none is claimed. On
report8 draw 25 (a 35.7 ms motor lag and a 66.8 ms servo lag hidden, a planned flight ->
attitude steps, 100 Hz) the joint step took ``command_delay``, the claims guard pinned it
at 42 +- 3 ms, and the loop ended with a delay the vehicle lacks. Profiled on the
held-out flight with their exact forms, beside the defaults' look-alikes, the two lags
together (32.4 and 74.5 ms) remove 65 % of what the delay alone (39 ms) leaves, with a
per-sample gain of 3.9 Newey-West standard errors, and each passes beside the other.

Here, when exactly one lag or delay is claimed and the model has none (and the profile
did not already choose it), every lag, delay and pair is profiled
(:func:`omavctl.diagnose.timing_pair.profile_fits`) and judged against the claim's own
exact form alone by the bars a single claim passes: an alternative (a pair, which may
hold the claim, or another single) that passes its own bars, removes at least
:data:`~omavctl.diagnose.joint.MIN_SHARE` of what the claim leaves and whose per-sample
gain over it reaches :data:`~omavctl.diagnose.joint.MIN_HAC_T` Newey-West standard
errors replaces the claim (the best such, by its error); the claims guard then estimates
it as the printed fit command does (searched together, profile intervals) and keeps it
only when it pins every member down. Alternatives with as many members that the chosen
one does not beat by the same t are named ambiguous with it. When nothing beats the
claim, the other single lags or delays that pass their bars and that the claim does not
beat by that t are named ambiguous with it, so the verdict prints the
``plan --objective effects`` command that tells them apart; so are the members of a
better alternative the guard cannot pin down.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.joint import MIN_HAC_T, MIN_SHARE, hac_t
from omavctl.diagnose.scoring import EffectScore
from omavctl.diagnose.timing_pair import TIMING, PairGuard, TimingFit, held_once, profile_fits
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = ["beside_claimed", "better_than"]


def better_than(
    base: TimingFit, fits: Sequence[TimingFit], floor: float, dt: float
) -> list[TimingFit]:
    """The fits (not ``base``) that pass their own bars, are plausible, remove at least
    MIN_SHARE of what ``base`` leaves and beat it by MIN_HAC_T Newey-West standard
    errors per sample; least error first."""
    left = float(base.after.sum())
    out = []
    for f in fits:
        if f is base or not f.passes(floor, dt) or not f.plausible() or left <= 0:
            continue
        share = 1.0 - float(f.after.sum()) / left
        if share >= MIN_SHARE and hac_t(base.after, f.after) >= MIN_HAC_T:
            out.append(f)
    return sorted(out, key=lambda f: float(f.after.sum()))


def _ties(best: TimingFit, fits: Sequence[TimingFit], floor: float, dt: float) -> list[str]:
    """Names of the fits with as many members as ``best`` that pass their bars and that
    ``best`` does not beat by MIN_HAC_T (the flight does not tell them apart), not in it."""
    out: list[str] = []
    for f in fits:
        if f is best or len(f.names) != len(best.names):
            continue
        if not f.passes(floor, dt) or not f.plausible():
            continue
        if hac_t(f.after, best.after) < MIN_HAC_T:
            out += [n for n in f.names if n not in best.names and n not in out]
    return out


def _mark(scores: Sequence[EffectScore], names: Sequence[str], alike: Sequence[str]) -> None:
    """``alike`` joins the ``ambiguous_with`` of the scores of ``names`` (in place)."""
    for s in scores:
        if s.name in names:
            s.ambiguous_with += [n for n in alike if n not in s.ambiguous_with and n != s.name]


def _held(claim: str, base: TimingFit, best: TimingFit) -> dict[str, Any]:
    """The replaced claim's ``not_pinned`` entry: its profile and what replaced it."""
    left = float(base.after.sum())
    share = 1.0 - float(best.after.sum()) / left if left > 0 else 0.0
    return {
        "name": claim,
        "units": {p.name: p.unit for p in get_effect(claim).parameters},
        "estimate": {},
        "axes": None,
        "beside_timing": {
            "claim": base.to_json(),
            "instead": best.to_json(),
            "share": share,
            "hac_t": min(hac_t(base.after, best.after), 1e6),
        },
    }


def beside_claimed(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    guarded: Guarded,
    floor: float,
    guard: PairGuard,
    scores: Sequence[EffectScore] = (),
) -> Guarded:
    """``guarded`` with its one lag or delay judged beside the others (module
    docstring): replaced by a better pair or single when the guard keeps that, else
    kept with its look-alikes named in its score's ``ambiguous_with`` (in place).
    ``physics`` (n, 3): the held-out physics-only error; ``guard``: (names, the names
    found on the held-out flight) -> Guarded."""
    claimed = [n for n in guarded.kept if n in TIMING]
    sg = getattr(samples[0], "sg", None) if samples else None
    if len(claimed) != 1 or sg is None:
        return guarded
    if any(get_effect(n).search is not None for n in model.effects):
        return guarded
    claim = claimed[0]
    fits = profile_fits(samples, model, physics)
    base = next((f for f in fits if f.names == (claim,)), None)
    if base is None:
        return guarded
    better = better_than(base, fits, floor, sg.dt)
    if not better:
        singles = [f for f in fits if len(f.names) == 1]
        _mark(scores, [claim], _ties(base, singles, floor, sg.dt))
        return guarded
    best = better[0]
    rest = [n for n in guarded.kept if n != claim]
    trial = guard([*rest, *best.names], best.names)
    if not all(n in trial.kept for n in best.names):
        _mark(scores, [claim], [n for n in best.names if n != claim])
        return guarded
    ties = _ties(best, fits, floor, sg.dt)
    _mark(scores, best.names, ties)
    if claim not in best.names:
        trial.held_back = [_held(claim, base, best), *trial.held_back]
    trial.held_back = held_once([*guarded.held_back, *trial.held_back], trial.kept)
    return trial
