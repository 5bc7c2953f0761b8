"""An effect the GP learned, judged beside the default imperfections' look-alikes
refitted on the held-out flight (issue 26, "steps7").

With nothing missing, the diagnosis claims an effect the GP learned when its fit-flight
estimate lowers the held-out physics-only error (:func:`omavctl.diagnose.claims.
learned_claim`). That error also holds the imperfections every rotorcraft has (a thrust
spread's CoM offset, the rotors' interference: :data:`~omavctl.diagnose.joint.
DEFAULT_LOOK_ALIKES`), which a flight of attitude steps shows strongly. Judged against
the whole error, a hidden drag the fit flight estimates well failed on the retired
report7 draws: 35 (drag 8.4x the floor, figure-8 -> steps) removed 67 % of it with a
per-2 s-block fraction t of 2.3 (the bar 2.50), 0 (drag 2.4x, steps -> figure-8) 13 %.
Against what the look-alikes leave at their least-squares fit on the held-out flight
(nuisance parameters, as :mod:`omavctl.diagnose.timing_beside` judges a lag or delay),
the same estimates remove 99 % (t 6.9) and 86 % (t 27), every block better.

So the learned claim's large-cut test is made there first: among the ranking's learned
effects that are not look-alikes (claimed, estimate excluding its null, as
:func:`~omavctl.diagnose.claims.learned_claim` asks), the one whose fit-flight estimate
(bounded least squares, as :func:`~omavctl.diagnose.claims.large_cut_step`) has a part
at least the claim floor and removes at least :data:`~omavctl.diagnose.claims.LARGE_CUT`
of what the look-alikes leave, by a fraction consistent over the 2 s blocks (mean of
-log(after / before) at least :data:`~omavctl.diagnose.joint.MIN_HAC_T` standard errors),
with the largest share; None when none does (the whole-error tests then decide).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.claims import (
    LARGE_CUT,
    LargeCutStep,
    claimed_axes,
    excludes_null,
    log_ratio_t,
    training_estimate,
)
from omavctl.diagnose.joint import (
    DEFAULT_LOOK_ALIKES,
    MIN_HAC_T,
    block_t,
    without_fit,
)
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = ["BesideCutStep", "learned_beside_look_alikes"]


class BesideCutStep(LargeCutStep):
    """A learned claim accepted on its large cut beside the look-alikes: its ``share`` is
    of what they leave at their held-out fit, ``share_of_total`` of the whole error."""

    def to_json(self) -> dict[str, Any]:
        return {**super().to_json(), "beside_look_alikes": True}


def _trial(
    model: ResidualGP,
    name: str,
    own_of: Any,
    physics: np.ndarray,
    beside: tuple[np.ndarray, np.ndarray],
    blocks: np.ndarray,
) -> BesideCutStep:
    """``name``'s bounded least-squares estimate on the training points, its part
    ``own_of(theta)`` (n, 3) on the held-out samples judged beside the look-alikes
    (``beside``: their stacked regressor x (n, 3, p) and what they leave, squared (n,))."""
    x, before = beside
    theta = training_estimate(model, name)
    own = own_of(theta)
    after = (without_fit(x, physics - own) ** 2).sum(axis=1)
    log_t, better, n_blocks = log_ratio_t(before, after, blocks)
    left, total = float(before.sum()), float((physics**2).sum())
    gain = left - float(after.sum())
    return BesideCutStep(
        name=name,
        share=gain / left if left > 0 else 0.0,
        share_of_total=gain / total if total > 0 else 0.0,
        contribution_rms=float(np.sqrt((own**2).mean())),
        block_t=min(block_t(before, after, blocks), 1e6),
        theta=theta,
        log_ratio_t=min(log_t, 1e6),
        blocks_better=better,
        blocks=n_blocks,
    )


def learned_beside_look_alikes(
    pool: Sequence[Mapping[str, Any]],
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    blocks: np.ndarray,
    floor: float,
) -> tuple[BesideCutStep, Mapping[str, Any]] | None:
    """The learned claim described in the module docstring, with its pool entry.

    pool: the ranking's learned entries with an ``estimate``; samples: the held-out
    samples (exact forms of lags and delays); physics (n, 3) their physics-only error;
    regressors: name -> (n, 3, p) on them for the effects the model lacks; blocks (n,)
    the 2 s blocks; floor: the claim floor (rad/s² RMS)."""
    alikes = [n for n in sorted(DEFAULT_LOOK_ALIKES) if n in regressors]
    if model.n_train == 0 or not alikes or not (physics**2).sum() > 0:
        return None
    x = np.concatenate([regressors[n] for n in alikes], axis=2)
    beside = (x, (without_fit(x, physics) ** 2).sum(axis=1))
    best: tuple[BesideCutStep, Mapping[str, Any]] | None = None
    for entry in pool:
        name = str(entry.get("name"))
        if name in DEFAULT_LOOK_ALIKES or entry.get("missing") is not True:
            continue
        if name in model.effects or name not in regressors or name not in model.train_regressors:
            continue
        if set(entry.get("ambiguous_with") or []) & set(model.effects):
            continue
        if not excludes_null(
            name,
            entry.get("estimate") or {},
            claimed_axes(entry.get("explained_variance_per_axis")),
        ):
            continue
        reg = regressors[name]
        if get_effect(name).search is not None:
            own_of = lambda th, n=name: np.concatenate([s.exact(n, float(th[0])) for s in samples])  # noqa: E731
        else:
            own_of = lambda th, r=reg: r @ th  # noqa: E731
        step = _trial(model, name, own_of, physics, beside, blocks)
        ok = (
            step.contribution_rms >= floor
            and step.share >= LARGE_CUT
            and step.log_ratio_t >= MIN_HAC_T
        )
        if ok and (best is None or step.share > best[0].share):
            best = step, entry
    return best
