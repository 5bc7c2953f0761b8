"""The default imperfections' look-alikes the GP learned, judged together.

A vehicle whose hidden effect is one of the look-alikes of every rotorcraft's
imperfections (:data:`~omavctl.diagnose.joint.DEFAULT_LOOK_ALIKES`: a larger rotor
interference, a CoM offset) shows it, after a first fit without effects, in what the GP
learned. Judged one at a time (:func:`omavctl.diagnose.claims.learned_claim`), neither may
pass: the interference's fit-flight estimate lowers the held-out physics-only error only
beside the CoM offset the thrust spread adds, and the offset alone is not pinned down.
Own tune draw own-inertia 9 (an interference at 2.4x the claim floor, steps -> wobble,
1 kHz): "nothing missing", while ``fit --effects rotor_interference,com_offset`` lowers the
held-out physics-only error from x 1.17, y 0.68, z 0.22 to 0.12, 0.14, 0.12 rad/s^2 RMS
(rotor_interference alone: 1.16, 0.51, 0.18).

So, when no single effect is claimed, the look-alikes the ranking claims on the learned
residual are estimated together from the fit flight's training points (bounded least
squares within their plausible ranges, as :func:`~omavctl.diagnose.claims.
training_estimate` does one) and claimed together when their part on the held-out flight
is at least the claim floor, removes at least :data:`~omavctl.diagnose.claims.LARGE_CUT`
of the physics-only error, by a fraction consistent over the 2 s blocks (mean of
-log(after / before) at least :data:`~omavctl.diagnose.joint.MIN_HAC_T` standard errors),
and one of them has an estimate that excludes its null. Naming them is naming what the
vehicle has (the documented default imperfections, or more of one of them).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear

from omavctl.diagnose.claims import (
    LARGE_CUT,
    LargeCutStep,
    claimed_axes,
    excludes_null,
    log_ratio_t,
)
from omavctl.diagnose.joint import DEFAULT_LOOK_ALIKES, MIN_HAC_T, block_t
from omavctl.learn.model import ResidualGP
from omavctl.physics.effects import get_effect

__all__ = ["LookAlikesStep", "learned_look_alikes"]


@dataclass
class LookAlikesStep(LargeCutStep):
    """The look-alikes claimed together: ``name`` the first (pinned down), ``also`` the
    others; ``share`` and ``share_of_total`` are of the whole physics-only error."""

    also: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {**super().to_json(), "jointly_with": list(self.also)}


def _joint_estimate(model: ResidualGP, names: Sequence[str]) -> list[np.ndarray]:
    """The parameters of ``names`` by bounded least squares together on the model's
    training points (their stored regressors against the GP's targets)."""
    train = [model.train_regressors[n] for n in names]
    a = np.concatenate(train, axis=2)
    k, _, p = a.shape
    lo, hi = (
        np.concatenate([np.broadcast_to(get_effect(n).theta_range[i], t.shape[2])
                        for n, t in zip(names, train, strict=True)])
        for i in (0, 1)
    )  # fmt: skip
    x = lsq_linear(
        a.reshape(3 * k, p), model.targets.reshape(3 * k), bounds=(lo, hi), method="bvls"
    ).x
    return list(np.split(np.asarray(x), np.cumsum([t.shape[2] for t in train])[:-1]))


def learned_look_alikes(
    pool: Sequence[Mapping[str, Any]],
    model: ResidualGP,
    physics: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    blocks: np.ndarray,
    floor: float,
) -> tuple[LookAlikesStep, Mapping[str, Any]] | None:
    """The look-alikes claimed together (module docstring), with the pool entry of the
    first; None when fewer than two are in question or they fail the test.

    pool: the ranking's learned entries with an ``estimate``; physics (n, 3) the held-out
    physics-only error; regressors: name -> (n, 3, p) on the held-out samples; blocks
    (n,) the 2 s blocks; floor: the claim floor (rad/s² RMS)."""
    entries = [
        e for e in pool
        if e.get("name") in DEFAULT_LOOK_ALIKES and e.get("missing") is True
        and e["name"] not in model.effects and e["name"] in regressors
        and e["name"] in model.train_regressors
    ]  # fmt: skip
    if len(entries) < 2 or model.n_train == 0 or not (physics**2).sum() > 0:
        return None
    pinned = [
        e for e in entries
        if excludes_null(str(e["name"]), e.get("estimate") or {},
                         claimed_axes(e.get("explained_variance_per_axis")))
    ]  # fmt: skip
    if not pinned:
        return None
    names = [str(e["name"]) for e in entries]
    thetas = _joint_estimate(model, names)
    part = sum(
        (regressors[n] @ th for n, th in zip(names, thetas, strict=True)), np.zeros_like(physics)
    )
    before = (physics**2).sum(axis=1)
    after = ((physics - part) ** 2).sum(axis=1)
    log_t, better, n_blocks = log_ratio_t(before, after, blocks)
    share = 1.0 - float(after.sum()) / float(before.sum())
    rms = float(np.sqrt((part**2).mean()))
    if rms < floor or share < LARGE_CUT or log_t < MIN_HAC_T:
        return None
    lead = max(pinned, key=lambda e: float(e.get("explained_variance") or 0.0))
    first = names.index(str(lead["name"]))
    step = LookAlikesStep(
        name=names[first],
        share=share,
        share_of_total=share,
        contribution_rms=rms,
        block_t=min(block_t(before, after, blocks), 1e6),
        theta=thetas[first],
        log_ratio_t=min(log_t, 1e6),
        blocks_better=better,
        blocks=n_blocks,
        also=[n for n in names if n != names[first]],
    )
    return step, lead
