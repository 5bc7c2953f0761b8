"""An effect linear in its parameters, estimated on the held-out flight itself (issue 26,
"linear").

The joint selection (:mod:`omavctl.diagnose.joint`) judges a drag, an inertia error, a
gyro bias ... on the held-out flight at its *fit-flight* estimate, and the Newey-West
bars judge a gain per sample. Two ways a large effect slips through both (the own tune
splits, docs/scorecard.md "session 23"): the fit flight barely excites it (own-fig8 draw
10: an inertia scale 0.74, 14x the claim floor; the fit flight's estimate removes 20 %
of what the look-alikes leave of the held-out physics-only error, refitted on the
held-out flight 61 %), or the held-out flight's gain sits in a few transitions of
attitude steps, where a t on the squared error is weak however consistent the gain
(own-inertia draw 18: a 0.8 drag, 13.6x the floor, planned -> steps; on the steps beside
the look-alikes D = 0.785 / 0.785 / 1.07, 98 % of what they leave, lower in 10 of 10
blocks, Newey-West t 1.9; "Nothing missing").

So when nothing but the defaults' look-alikes is claimed, each linear effect the model
lacks is fitted on the held-out flight beside the look-alikes (least squares, its null
bounds held as in :func:`~omavctl.diagnose.timing_profile.profile_for`) and judged
*cross-fitted*: fitted on alternate 2 s blocks, the error judged on the others, both
ways, against the look-alikes cross-fitted alike. The best is claimed when

- its cross-fitted share of what the look-alikes leave is at least
  :data:`~omavctl.diagnose.joint.MIN_SHARE`;
- it lowers the cross-fitted error in more 2 s blocks than a one-sided sign test allows
  at 0.05 / 8 (:data:`SIGN_P`; the 8 effects a default fit can test, as
  :data:`~omavctl.diagnose.joint.MIN_HAC_T`): a consistent gain, whatever its spread
  over blocks;
- its part (RMS of its fitted contribution) is at least :data:`PART_FLOOR` times the
  claim floor: an effect found and judged on one flight must stand clear of the floor
  (on the tune splits the two effects this rule would have invented, an inertia error
  for a command delay and for the rotors' interference, stood at 1.1x and 1.5x; the
  four it found at 2.2-8x);
- its estimate is plausible, and the claims guard then keeps it, estimated as the
  printed fit command does.

Others that pass with at least :data:`~omavctl.diagnose.joint.AMBIGUOUS_RATIO` of its
cross-fitted share are its look-alikes on this flight (named ambiguous with it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.joint import (
    AMBIGUOUS_RATIO,
    DEFAULT_LOOK_ALIKES,
    MIN_SHARE,
    SIGN_P,
    block_sums,
    plausible_theta,
)
from omavctl.diagnose.scoring import BLOCK_SECONDS, EffectScore, sign_p, time_blocks
from omavctl.diagnose.timing_mixed import linear_partners
from omavctl.diagnose.timing_profile import profile_for
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples

__all__ = ["PART_FLOOR", "SIGN_P", "LinearFit", "linear_fits", "with_linear"]

#: the part must reach this many claim floors (module docstring)
PART_FLOOR = 2.0

#: The guard: (names, the names found here) -> Guarded (as the timing profiles').
LinearGuard = Callable[[list[str], Sequence[str]], Guarded]


@dataclass
class LinearFit:
    """One linear effect fitted on the held-out flight beside the look-alikes."""

    name: str
    theta: np.ndarray
    #: share of what the look-alikes leave: in sample, cross-fitted
    share: float
    cross_share: float
    #: RMS (rad/s^2) of its fitted contribution
    part: float
    #: 2 s blocks whose cross-fitted error it lowers, of ``blocks``
    better: int
    blocks: int
    #: (p,) the components whose own part reaches the claim floor: the others (an axis the
    #: flight hardly excites) are not judged for plausibility (0, the linear effects'
    #: null, stands in for them)
    judged: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    ambiguous_with: list[str] = field(default_factory=list)

    @property
    def sign_p(self) -> float:
        """One-sided sign-test p of ``better`` of ``blocks``."""
        return sign_p(self.better, self.blocks)

    def passes(self, floor: float) -> bool:
        return (
            self.cross_share >= MIN_SHARE
            and self.sign_p <= SIGN_P
            and self.part >= PART_FLOOR * floor
            and plausible_theta(self.name, np.where(self.judged, self.theta, 0.0))
        )

    def to_json(self) -> dict[str, Any]:
        """As ``timing_claims`` holds a profile (docs/schemas.md): no time constant."""
        return {
            "kind": "linear",
            "names": [self.name],
            "values_s": [],
            "share": float(self.cross_share),
            "share_in_sample": float(self.share),
            "part": [float(self.part)],
            "blocks_better": int(self.better),
            "blocks": int(self.blocks),
            "sign_p": float(self.sign_p),
            "ambiguous_with": list(self.ambiguous_with),
            "alike_of": {self.name: list(self.ambiguous_with)} if self.ambiguous_with else {},
            "bars": {"min_share": MIN_SHARE, "sign_p": SIGN_P, "part_floor": PART_FLOOR},
        }


def _cross(physics: np.ndarray, design: np.ndarray | None, half: np.ndarray) -> np.ndarray:
    """Per-sample squared error (n,) of the columns ``design`` (n, 3, k) fitted on one
    half of the blocks and judged on the other, both ways (no columns: the error)."""
    out = np.empty(physics.shape[0])
    for h in (0, 1):
        fit, judged = half == h, half != h
        if design is None:
            out[judged] = (physics[judged] ** 2).sum(axis=1)
            continue
        a = design[fit].reshape(-1, design.shape[2])
        coef = np.linalg.lstsq(a, physics[fit].reshape(-1), rcond=None)[0]
        pred = np.einsum("nak,k->na", design[judged], coef)
        out[judged] = ((physics[judged] - pred) ** 2).sum(axis=1)
    return out


def linear_fits(
    samples: Sequence[ResidualSamples], model: ResidualGP, physics: np.ndarray, floor: float
) -> list[LinearFit]:
    """The linear effect to claim (a list of at most one, its look-alikes in
    ``ambiguous_with``; module docstring). ``physics`` (n, 3): the held-out
    physics-only error (rad/s²); ``floor`` the claim floor (RMS)."""
    names = linear_partners(samples, model) if samples else []
    if not names:
        return []
    t = np.concatenate([s.t for s in samples])
    log = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    blocks = time_blocks(t, log, BLOCK_SECONDS)  # the diagnosis's 2 s blocks
    half = blocks % 2
    alikes = [a for a in sorted(DEFAULT_LOOK_ALIKES) if a not in model.effects]
    alikes = [a for a in alikes if a in samples[0].regressors]

    def design(extra: Sequence[str]) -> np.ndarray | None:
        cols = [np.concatenate([s.regressors[n] for s in samples]) for n in [*alikes, *extra]]
        return np.concatenate(cols, axis=2) if cols else None

    before = profile_for(samples, model, physics).left([], [])
    cross_before = _cross(physics, design([]), half)
    if before.sum() <= 0 or cross_before.sum() <= 0:
        return []
    fits = []
    for name in names:
        after, coef = profile_for(samples, model, physics, [name]).left_coef([], [])
        theta = coef[coef.size - samples[0].regressors[name].shape[2] :]
        reg = np.concatenate([s.regressors[name] for s in samples])
        cross = _cross(physics, design([name]), half)
        own = np.sqrt((reg**2).mean(axis=(0, 1))) * np.abs(theta)  # (p,) each component's part
        gains = block_sums(cross_before, blocks) - block_sums(cross, blocks)
        fits.append(
            LinearFit(
                name=name,
                theta=theta,
                share=1.0 - float(after.sum() / before.sum()),
                cross_share=1.0 - float(cross.sum() / cross_before.sum()),
                part=float(np.sqrt((np.einsum("nap,p->na", reg, theta) ** 2).mean())),
                better=int(np.sum(gains > 0)),
                blocks=int(gains.size),
                judged=own >= floor,
            )
        )
    passing = [f for f in fits if f.passes(floor)]
    if not passing:
        return []
    best = max(passing, key=lambda f: f.cross_share)
    best.ambiguous_with = sorted(
        f.name
        for f in passing
        if f is not best and f.cross_share >= AMBIGUOUS_RATIO * best.cross_share
    )
    return [best]


def with_linear(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    guarded: Guarded,
    floor: float,
    guard: LinearGuard,
    scores: Sequence[EffectScore] = (),
) -> Guarded:
    """``guarded`` with the linear effect of :func:`linear_fits` added to its claims and
    guarded again by ``guard`` (names, the names found here -> Guarded) when nothing but
    the look-alikes is claimed; kept only when the guard keeps it. Its look-alikes join
    the ``ambiguous_with`` of its score in ``scores`` (in place)."""
    if any(n not in DEFAULT_LOOK_ALIKES for n in guarded.kept):
        return guarded
    fits = linear_fits(samples, model, physics, floor)
    if not fits:
        return guarded
    fit = fits[0]
    trial = guard([*guarded.kept, fit.name], [fit.name])
    if fit.name not in trial.kept:
        return guarded
    known = {str(h["name"]) for h in trial.held_back}
    trial.held_back += [h for h in guarded.held_back if str(h["name"]) not in known]
    trial.profiles = {**guarded.profiles, fit.name: fit.to_json()}
    for s in scores:
        if s.name == fit.name:
            s.ambiguous_with += [n for n in fit.ambiguous_with if n not in s.ambiguous_with]
    return trial
