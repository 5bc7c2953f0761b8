"""A lag or delay estimated together with an effect linear in its parameters (issue 26,
"mixed").

A lag or delay and a rotational drag (or an inertia error) can cancel on one flight: a
torque that arrives late and a torque that opposes the body rate both shift the
measured acceleration's phase, in opposite directions. On report13 draw 11 (a hidden
50 ms command delay and a drag of 0.11, 8x and 3.8x the claim floor; attitude steps ->
a chirp, 1 kHz) beside the defaults' look-alikes the delay's exact form at 50 ms
raised the held-out physics-only error 2.5-fold, so its profile found 8 ms (7 % of the
error); the linearised joint selection found neither, and the verdict named only the
look-alike ``com_offset``. With the drag's regressor among the nuisance parameters,
the delay at 50 ms removes 79 % of what is left.

Here every lag or delay is profiled (:mod:`omavctl.diagnose.timing_profile`'s grid and
refinement) beside each effect that is linear in its parameters, is neither a lag nor
a delay nor a look-alike, is excited and the model lacks; the partner's regressor
columns are fitted by least squares with the look-alikes' at each time constant, held
to the partner's null bounds (:func:`~omavctl.diagnose.joint.null_bounds`: a drag is not
negative). The two are
claimed together only when each passes, beside the other, the bars a single claim
passes: it removes at least :data:`~omavctl.diagnose.joint.MIN_SHARE` of what the
other (at its own best fit) leaves, its part reaches the claim floor, its per-sample
gain reaches :data:`~omavctl.diagnose.joint.MIN_HAC_T` Newey-West standard errors;
the time constant is at least the log's sample period and the partner's parameters
lie in their plausible range. Such a fit competes with the pairs of lags and delays
(:func:`omavctl.diagnose.timing_pair.timing_fits`) and is guarded as they are.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from omavctl.diagnose.joint import DEFAULT_LOOK_ALIKES, MIN_HAC_T, MIN_SHARE, hac_t
from omavctl.diagnose.joint import plausible_theta as _plausible
from omavctl.diagnose.timing_profile import TIMING, TimingFit, profile_for
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = ["MixedFit", "linear_partners", "mixed_fits"]


@dataclass
class MixedFit(TimingFit):
    """A lag or delay (``names[0]``, time constant ``values[0]``) with a linear effect
    (``names[1]``, parameters ``theta``), profiled on the held-out flight; the other
    fields mean what a :class:`~omavctl.diagnose.timing_profile.TimingFit`'s do."""

    theta: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def passes(self, floor: float, dt: float) -> bool:
        """Each member's bars (module docstring)."""
        bars = zip(self.member_share, self.part, self.hac, strict=True)
        members = all(s >= MIN_SHARE and p >= floor and t >= MIN_HAC_T for s, p, t in bars)
        return members and self.values[0] >= dt

    def plausible(self) -> bool:
        """The time constant and the partner's parameters within their ranges."""
        timing = _plausible(self.names[0], np.array([self.values[0]]))
        return timing and _plausible(self.names[1], self.theta)

    def to_json(self) -> dict[str, Any]:
        return {**super().to_json(), "theta": [float(x) for x in self.theta]}


def linear_partners(samples: Sequence[ResidualSamples], model: ResidualGP) -> list[str]:
    """The effects a lag or delay is profiled beside: linear in their parameters, not a
    look-alike, not in the model, with a regressor the flight excites (not all zero)."""
    regs = samples[0].regressors
    out = []
    for n in sorted(regs):
        if n in model.effects or n in DEFAULT_LOOK_ALIKES or get_effect(n).search is not None:
            continue
        if any(np.any(s.regressors[n]) for s in samples):
            out.append(n)
    return out


def mixed_fits(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    singles: dict[str, TimingFit],
) -> list[MixedFit]:
    """Every lag or delay beside every linear partner (:func:`linear_partners`),
    profiled on the held-out physics-only error ``physics`` (n, 3) with the look-alikes
    the model lacks. ``singles``: each lag or delay's own profile beside the look-alikes
    (a :class:`~omavctl.diagnose.timing_profile.TimingFit` per name), the yardstick of
    the partner's share."""
    timing = [n for n in TIMING if n in samples[0].regressors and n in singles]
    partners = linear_partners(samples, model) if timing else []
    out: list[MixedFit] = []
    if not partners:
        return out
    base = profile_for(samples, model, physics)
    left = float(base.left([], []).sum())
    for lin in partners:
        prof = profile_for(samples, model, physics, [lin])
        prof.cache = base.cache  # the exact forms do not depend on the nuisance effects
        k = prof.a.shape[1] if prof.a is not None else 0
        p = samples[0].regressors[lin].shape[2]
        reg = np.concatenate([s.regressors[lin] for s in samples])  # (n, 3, p)
        lin_alone = prof.left([], [])
        for t in timing:
            (v,) = prof.best([t])
            after, coef = prof.left_coef([t], [v])
            theta = coef[k - p :]
            alone = singles[t].after
            parts = (
                float(np.sqrt((prof.exact(t, v) ** 2).mean())),
                float(np.sqrt((np.einsum("nap,p->na", reg, theta) ** 2).mean())),
            )
            shares = tuple(
                1 - float(after.sum()) / max(float(b.sum()), 1e-300) for b in (lin_alone, alone)
            )
            out.append(
                MixedFit(
                    (t, lin),
                    (v,),
                    1 - float(after.sum()) / max(left, 1e-300),
                    shares,
                    parts,
                    (hac_t(lin_alone, after), hac_t(alone, after)),
                    theta=theta,
                    after=after,
                )
            )
    return out
