"""Claims the flight backs: an effect is claimed only where its interval excludes its null.

Both selections of the diagnosis (the ranking on the model's remaining error and the
joint selection on the held-out physics-only error) can name an effect that explains
a few per cent of what is left without the flight determining it: on the report2
split, 11 of 40 draws ended with an effect the vehicle lacked, mostly an
``inertia_error`` a joint step added whose scale could as well have been 1 (issue 26).
:func:`guard_claims` estimates the claimed effects as the printed ``fit --effects``
would (its first pass on the evaluated flight, with the model's effects and every
claimed one together: the numbers the verdict quotes) and keeps a claim only when
the 95 % interval of at least one component it is claimed on excludes the effect's
null (:meth:`omavctl.physics.effect_base.Effect.null_parameters`: scale 1, lag 0,
drag 0, ...). What is dropped is said to be one that "cannot be pinned down from this
flight", with its interval, and stays in the ambiguous set of a claimed look-alike.

:func:`learned_claim` turns an effect the GP learned into a claim of its own when the
flight pins it down and, estimated from the fit flight's training points by least
squares (``fit``'s first pass, before the GP), it lowers the held-out physics-only
error by the joint selection's test (:func:`omavctl.diagnose.joint.learned_step`):
otherwise the verdict would say "Nothing missing", print no fit command, and a loop
that follows it would stop with the physics-only error where it was.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from omavctl.diagnose.estimate_text import AXIS_CLAIM
from omavctl.diagnose.joint import JointStep, learned_step
from omavctl.learn.effect_fit import merged_estimates
from omavctl.learn.fit_steps import first_pass
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = ["Guarded", "claimed_axes", "excludes_null", "guard_claims", "learned_claim"]

AXES = ("x", "y", "z")


def claimed_axes(per_axis: Mapping[str, Any] | None) -> set[str] | None:
    """The axes a claim of the ranking is made on (its share of the axis's error at
    least :data:`AXIS_CLAIM`, as the verdict quotes them); None (every axis) without
    per-axis shares (a claim of the joint selection)."""
    if not isinstance(per_axis, Mapping):
        return None
    return {a for a in AXES if isinstance(v := per_axis.get(a), int | float) and v >= AXIS_CLAIM}


def excludes_null(name: str, estimate: Mapping[str, Any], axes: Collection[str] | None) -> bool:
    """Whether the 95 % interval (``P_ci95`` of an estimate's JSON) of at least one
    component of ``name``'s parameters that the claim is made on excludes the effect's
    null. A per-axis parameter (three components) counts only on ``axes`` (None: all);
    an interval that is not finite excludes nothing."""
    null = get_effect(name).null_parameters()
    for param, value in null.items():
        rows = estimate.get(f"{param}_ci95")
        if not isinstance(rows, list):
            continue
        for i, row in enumerate(rows):
            if axes is not None and len(rows) == 3 and AXES[i] not in axes:
                continue
            if not isinstance(row, list) or len(row) != 2 or None in row:
                continue
            at = float(value[i] if value.size == len(rows) else value.flat[0])
            if row[0] > at or row[1] < at:
                return True
    return False


def _estimates(
    samples: Sequence[ResidualSamples], model_effects: Sequence[str], names: Sequence[str]
) -> dict[str, dict[str, Any]]:
    """Every one of ``names`` estimated as ``fit --effects <model's>,<names>`` first
    estimates them (one first pass, all together), as JSON."""
    every = [*model_effects, *(n for n in names if n not in model_effects)]
    res = first_pass(list(samples), every)
    merged = merged_estimates(list(names), res.first_pass.estimates, res.found)
    return {n: merged[n].to_json() for n in names}


@dataclass
class Guarded:
    """What :func:`guard_claims` keeps and holds back."""

    kept: list[str]
    #: per kept claim, its estimate's JSON (all kept claims estimated together)
    estimates: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: each held-back claim: name, units, estimate (JSON), axes it was claimed on
    held_back: list[dict[str, Any]] = field(default_factory=list)


def guard_claims(
    samples: Sequence[ResidualSamples],
    model_effects: Sequence[str],
    names: Sequence[str],
    axes_of: Mapping[str, set[str] | None],
) -> Guarded:
    """Keep the claims of ``names`` whose interval excludes their null on an axis they
    are claimed on (``axes_of``: name -> axes, None or absent: all); the others are
    held back, and the rest estimated again without them, until all kept pass.

    ``samples`` must carry every named effect's regressor and context."""
    out = Guarded(kept=list(names))
    while out.kept:
        est = _estimates(samples, model_effects, out.kept)
        drop = [n for n in out.kept if not excludes_null(n, est[n], axes_of.get(n))]
        if not drop:
            out.estimates = est
            break
        for n in drop:
            axes = axes_of.get(n)
            out.held_back.append(
                {
                    "name": n,
                    "units": {p.name: p.unit for p in get_effect(n).parameters},
                    "estimate": est[n],
                    "axes": None if axes is None else sorted(axes),
                }
            )
        out.kept = [n for n in out.kept if n not in drop]
    return out


def learned_claim(
    pool: Sequence[Mapping[str, Any]],
    model: ResidualGP,
    physics: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    blocks: np.ndarray,
    floor: float,
) -> tuple[JointStep, Mapping[str, Any]] | None:
    """The effect the GP learned that becomes a claim when nothing is missing: among
    ``pool`` (ranking entries with an ``estimate``, claimed on the physics-only residual,
    not in the model, no look-alike of an effect the model holds), the one whose
    estimate excludes its null and that passes :func:`omavctl.diagnose.joint.learned_step`
    on the held-out physics-only error ``physics`` (n, 3) with the largest gain, with its
    entry; None when none does. ``regressors``: name -> (n, 3, p) on the held-out
    samples."""
    best: tuple[JointStep, Mapping[str, Any]] | None = None
    for entry in pool:
        name = str(entry.get("name"))
        if entry.get("missing") is not True or name in model.effects or name not in regressors:
            continue
        if set(entry.get("ambiguous_with") or []) & set(model.effects):
            continue  # what the model's own effects already explain
        axes = claimed_axes(entry.get("explained_variance_per_axis"))
        if not excludes_null(name, entry.get("estimate") or {}, axes):
            continue
        step = learned_step(model, name, physics, regressors[name], blocks, floor)
        if step is not None and (best is None or step.share > best[0].share):
            best = step, entry
    return best
