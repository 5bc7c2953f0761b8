"""A default look-alike the GP learned, claimed beside a missing effect.

When an effect is missing, the learned claims (:func:`omavctl.diagnose.diagnosis.
diagnose`'s, made only when nothing is) were not judged, so a centre-of-mass offset or a
rotor interference the GP had absorbed went unnamed until the missing effects were in
the model. On a held-out flight of attitude steps those look-alikes of every rotorcraft's
imperfections (the simulator's thrust spread and interference) can be most of the
physics-only error, and the loop's two rounds ended with it barely lower. report21 draw
60 (a 50 ms delay and a drag, fit on a figure-8 at 1 kHz): the delay and then the drag
were named and fitted at their true values, yet the physics-only y error on the steps
flight went 1.26 -> 1.20 rad/s²; a CoM offset the GP held was 80 % of the squared
error, and with it and the interference the error is 0.06. report21 draw 53 (a servo
lag and a drag) ended the same way (x 0.77 -> 0.73; 0.069 with them).

So beside a missing effect, a default look-alike (:data:`omavctl.diagnose.joint.
DEFAULT_LOOK_ALIKES`) that the learned pool claims is named too, by the rules the
learned claim uses when nothing is missing (pinned down on the held-out flight, or on the
fit flight when the held-out flight does not pin it down; alone or the look-alikes
together), and only when, estimated from the fit flight, it removes at least half of
the held-out physics-only error by itself (:data:`omavctl.diagnose.claims.LARGE_CUT`).
Never one ambiguous with a missing effect: the missing effect's fit decides that.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.claims import LARGE_CUT, learned_claim
from omavctl.diagnose.joint import DEFAULT_LOOK_ALIKES, JointStep
from omavctl.diagnose.learned_alikes import learned_look_alikes
from omavctl.diagnose.learned_fit_pinned import learned_fit_pinned
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples

__all__ = ["learned_beside_missing"]


def _alike_pool(
    pool: Sequence[Mapping[str, Any]], missing: Sequence[Mapping[str, Any]], names: Sequence[str]
) -> list[Mapping[str, Any]]:
    """The default look-alikes of ``pool`` that are neither named (``names``) nor
    ambiguous with a named effect, in either ranking (``missing``: the missing ranking's
    entries)."""
    named = set(names)
    near = {
        str(a) for e in missing if e.get("name") in named for a in e.get("ambiguous_with") or []
    }
    return [
        e for e in pool
        if e.get("name") in DEFAULT_LOOK_ALIKES and e.get("name") not in named | near
        and not set(e.get("ambiguous_with") or []) & named
    ]  # fmt: skip


def learned_beside_missing(
    pool: Sequence[Mapping[str, Any]],
    missing: Sequence[Mapping[str, Any]],
    names: Sequence[str],
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    held: tuple[np.ndarray, Mapping[str, np.ndarray], np.ndarray, float],
) -> tuple[JointStep, Mapping[str, Any]] | None:
    """The default look-alike (or the look-alikes together) the GP learned that is
    claimed beside the missing effects ``names`` (module docstring), with its pool
    entry; None when none removes at least half of the held-out physics-only error.

    pool: the learned ranking's entries with an ``estimate``; missing: the missing
    ranking's entries; held: (the held-out physics-only error (n, 3), name -> regressor
    (n, 3, p) on the held-out ``samples``, the 2 s blocks (n,), the claim floor)."""
    physics, raw, blocks, floor = held
    alikes = _alike_pool(pool, missing, names)
    if not alikes:
        return None
    found = [
        learned_claim(alikes, samples, model, physics, raw, blocks, floor),
        learned_fit_pinned(alikes, model, physics, raw, blocks, floor),
        learned_look_alikes(alikes, model, physics, raw, blocks, floor),
    ]
    steps = [s for s in found if s is not None and s[0].share >= LARGE_CUT]
    return max(steps, key=lambda s: s[0].share) if steps else None
