"""A lag or delay the held-out flight cannot pin down, judged on what its fit-flight
estimate explains of the held-out physics-only error beside the look-alikes (issue 26,
"smooth").

A fit flight of attitude steps shows a lag or delay in its sharp transitions; a smooth
held-out flight (a figure-8, a planned flight) hardly does, and the GP fitted on the
steps has absorbed most of it. The joint selection then takes the lag, but the claims
guard estimates it on the held-out flight beside the fit's GP, which the smooth flight
cannot pin down, and holds it back; what is claimed is a look-alike. The retired report8
draw 41 (a hidden 120 ms motor lag, steps -> figure-8, 100 Hz): the guard's estimate
on the figure-8 was 109 ± 111 ms (held back), the claim the learned ``com_offset``; yet
the motor lag estimated from the steps jointly with the look-alikes (51 ms, its interval
excluding 0) removes 60 % of what the look-alikes leave of the figure-8's physics-only
error at their least-squares fit, its part 1.7x the claim floor, Newey-West t 3.9
(``command_delay`` 48 %, ambiguous with it).

So when nothing is missing, a lag or delay the guard held back only because its
held-out estimate is not pinned down (not one held back beside another lag, see
:mod:`omavctl.diagnose.joint_lag`) is claimed as learned when its fit-flight estimate
(GLS with the look-alikes, as :mod:`omavctl.diagnose.timing_beside`) is pinned down
(its 95 % interval excludes 0) and passes that module's bars beside the look-alikes on
the held-out flight: plausible, at least one sample of the log, its part at least the
claim floor, at least :data:`~omavctl.diagnose.joint.MIN_SHARE` of what the look-alikes
leave, Newey-West t at least :data:`~omavctl.diagnose.joint.MIN_HAC_T`. The other lags
and delays that pass there with at least :data:`~omavctl.diagnose.joint.AMBIGUOUS_RATIO`
of its gain are named ambiguous with it (the verdict prints the flight that separates
them). No bar is new.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.joint import (
    AMBIGUOUS_RATIO,
    Z95,
    JointStep,
    joint_theta,
    look_alike_regressors,
    without_fit,
)
from omavctl.diagnose.timing_beside import beside_trials, trial_step
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = ["held_timing_beside"]


def _timing(name: str) -> bool:
    return get_effect(name).search is not None


def _unpinned_here(entry: Mapping[str, Any]) -> bool:
    """A held-back lag or delay whose held-out estimate was made and is not pinned down
    (not one held back beside another lag: ``beside_lag``)."""
    est = entry.get("estimate")
    if entry.get("beside_lag") is not None or not isinstance(est, Mapping):
        return False
    flags = [v for k, v in est.items() if str(k).endswith("_pinned")]
    return bool(flags) and not any(any(f) if isinstance(f, list) else f for f in flags)


def _fit_interval(model: ResidualGP, alikes: list[str], name: str) -> tuple[float, float]:
    """``name``'s value and 95 % interval half-width from the training points (GLS with
    the look-alikes)."""
    thetas, cov = joint_theta(model, [*alikes, name])
    return float(thetas[name][0]), Z95 * float(np.sqrt(max(float(cov[0, 0]), 0.0)))


def held_timing_beside(
    held_back: Sequence[Mapping[str, Any]],
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    blocks: np.ndarray,
    judge: tuple[float, float],
) -> tuple[JointStep, dict[str, Any]] | None:
    """The learned claim described in the module docstring, with its JSON entry.

    held_back: the claims guard's held-back entries; samples: the held-out samples (exact
    forms); physics (n, 3) their physics-only error; regressors: name -> (n, 3, p) for
    the effects the model lacks; blocks (n,) the 2 s blocks; judge: (the claim floor,
    rad/s² RMS; the log's sample period, s)."""
    floor, dt = judge
    held = {str(h.get("name")): h for h in held_back if _timing(str(h.get("name")))}
    held = {n: h for n, h in held.items() if _unpinned_here(h)}
    if not held or model.n_train == 0:
        return None
    usable, alikes, x = look_alike_regressors(regressors, model, physics)
    sq_before = (without_fit(x, physics) ** 2).sum(axis=1)
    left = float(sq_before.sum())
    if left <= 0:
        return None
    beside = (samples, model, physics, regressors, alikes, x, floor, dt)
    trials = beside_trials(beside, [n for n in usable if _timing(n)], sq_before)
    ok = []
    for trial in trials:
        value, half = _fit_interval(model, alikes, trial[1]) if trial[1] in held else (0.0, 0.0)
        if trial[1] in held and value - half > 0:
            ok.append((trial, value, half))
    if not ok:
        return None
    trial, value, half = max(ok, key=lambda o: o[0][0])
    gain, name = trial[:2]
    rivals = [t[1] for t in trials if t[1] != name and t[0] >= AMBIGUOUS_RATIO * gain]
    step = trial_step(trial, (left, physics, sq_before, blocks), rivals)
    entry = {
        "name": name,
        "units": held[name].get("units"),
        "ambiguous_with": rivals,
        "beside_look_alikes": True,
        "held_out_not_pinned": True,
        "fit_flight_value": value,
        "fit_flight_ci95": [value - half, value + half],
    }
    return step, entry
