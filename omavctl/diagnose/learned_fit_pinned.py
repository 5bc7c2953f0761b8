"""A learned effect the fit flight pins down and the held-out flight confirms.

:func:`omavctl.diagnose.claims.learned_claim` claims an effect the GP learned only when its
estimate on the evaluated (held-out) flight excludes its null. There it is estimated as
``fit --effects`` would, jointly with a GP fitted to that flight, and the GP takes what
varies slowly: a centre-of-mass offset's torque (the thrust's moment about the offset)
changes little over a flight, so the held-out flight may not pin it down while the fit
flight's training points do. Own tune draw own-inertia 4 (a drag at 5.2x the claim floor, 1
kHz controller): after the drag was added, the physics-only error on the held-out flight
stayed at x 0.50, y 0.45 rad/s² RMS and the verdict said "Nothing missing" (the error fell
27 % over the loop); the offset's fit-flight estimate removes 94 % of that error, with every
2 s block better by a consistent fraction (t 11), but its held-out interval held 0.

So a look-alike of every rotorcraft's imperfections (:data:`omavctl.diagnose.joint.
DEFAULT_LOOK_ALIKES`: a CoM offset, a rotor interference) that the learned pool claims and
the held-out flight does not pin down is judged on the fit flight: estimated there as fit's
first pass would (least squares at the model's training points, with a sandwich standard
error, :func:`omavctl.diagnose.claims.fit_flight_estimate`), its 95 % interval must exclude
the null on an axis it is claimed on, and its fit-flight estimate must remove at least half
of the held-out physics-only error, by the joint selection's test
(:func:`omavctl.diagnose.joint.learned_step`) or the large cut
(:func:`omavctl.diagnose.claims.large_cut_step`: consistently over the blocks), its part at
least the claim floor. Only those: on own tune draws own-fig8 7 and 22 (no inertia error;
steps fit flights at 100 Hz) the same rule claimed a yaw inertia scale of 1.24 and 1.26,
pinned down on the fit flight and removing 54 and 60 % of the figure-8's physics-only error
after the look-alikes: a yaw torque the rotors' spread makes, which an inertia scale mimics.
Lags and delays have their own rule (:mod:`omavctl.diagnose.held_beside`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.claims import (
    LARGE_CUT,
    claimed_axes,
    excludes_null,
    fit_flight_estimate,
    large_cut_step,
    theta_json,
)
from omavctl.diagnose.joint import DEFAULT_LOOK_ALIKES, JointStep, learned_step
from omavctl.learn.model import ResidualGP

__all__ = ["fit_flight_pinned", "learned_fit_pinned"]


def fit_flight_pinned(model: ResidualGP, name: str, axes: set[str] | None) -> dict[str, Any] | None:
    """``name``'s fit-flight estimate (JSON, as an estimate's) when its 95 % interval
    excludes the null on one of ``axes`` (None: any), else None."""
    theta, se = fit_flight_estimate(model, [name])
    if name not in theta or not np.all(np.isfinite(se[name])):
        return None
    est = theta_json(name, theta[name], se[name])
    return est if excludes_null(name, est, axes) else None


def learned_fit_pinned(
    pool: Sequence[Mapping[str, Any]],
    model: ResidualGP,
    physics: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    blocks: np.ndarray,
    floor: float,
) -> tuple[JointStep, Mapping[str, Any]] | None:
    """The default look-alike of ``pool`` (the ranking's learned entries with an
    ``estimate`` on the held-out flight) not pinned down there that the fit flight pins
    down and whose fit-flight estimate removes at least half of the held-out physics-only
    error ``physics`` (n, 3), the largest share first; its entry gains ``held_out_not_pinned``
    and ``fit_flight`` (the fit-flight estimate's JSON). None when none does.
    ``regressors``: name -> (n, 3, p) on the held-out samples; ``blocks`` (n,) the 2 s
    blocks; ``floor`` the claim floor (rad/s² RMS)."""
    best: tuple[JointStep, Mapping[str, Any]] | None = None
    for entry in pool:
        name = str(entry.get("name"))
        if entry.get("missing") is not True or name in model.effects or name not in regressors:
            continue
        if name not in DEFAULT_LOOK_ALIKES or name not in model.train_regressors:
            continue  # an inertia scale pinned on the fit flight only was invented
        if set(entry.get("ambiguous_with") or []) & set(model.effects):
            continue  # what the model's own effects already explain
        axes = claimed_axes(entry.get("explained_variance_per_axis"))
        if excludes_null(name, entry.get("estimate") or {}, axes):
            continue  # pinned down here: learned_claim judges it
        there = fit_flight_pinned(model, name, axes)
        if there is None:
            continue
        step: JointStep | None = learned_step(model, name, physics, regressors[name], blocks, floor)
        if step is None or step.share < LARGE_CUT:
            step = large_cut_step(model, name, physics, regressors[name], blocks, floor)
        if step is not None and (best is None or step.share > best[0].share):
            best = step, {**entry, "held_out_not_pinned": True, "fit_flight": there}
    return best
