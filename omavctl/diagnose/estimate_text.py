"""One sentence for a diagnosis estimate and its 95 % interval (no heavy imports:
the verdict and the report use it)."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from typing import Any

__all__ = ["AXIS_CLAIM", "estimate_sentence", "unpinned_text"]

#: Share of an axis's error an effect must explain for its per-axis parameter on that
#: axis to be quoted as an estimate (below it: "D_z not claimed").
AXIS_CLAIM = 0.05


def estimate_sentence(entry: Mapping[str, Any], axes: Collection[str] | None = None) -> str:
    """' Estimated on this flight as fit would: T_m = 0.027 s (95 %: -0.10 to 0.16 s, cannot
    be pinned down from this flight).' for a diagnosis ``learned`` entry with an ``estimate``
    ('' without one).

    ``axes``: the axes the claim is made on; a per-axis component (D_z) on another
    axis is not quoted as an estimate ("D_z not claimed: ..."): where the effect
    explains none of an axis's error, its component there is whatever else that
    axis's residual holds, and its interval would not hold the truth.

    The interval is this flight's: another flight that excites a look-alike
    differently (the thrust spread beside a centre-of-mass offset) may move the
    estimate by more than it, which ``fit`` on both flights then shows. Its ends are
    printed with as many digits as it takes to tell them apart (3 to 6): "0.0123 to
    0.0123" read as an interval of zero width, nor an end as the effect's null that it
    is not (:func:`omavctl.learn.intervals.interval_ends`); one cut at a physical bound
    reads 'below 0.0457' (:func:`omavctl.learn.intervals.interval_span`)."""
    from omavctl.learn.intervals import interval_span

    est = entry.get("estimate")
    if not isinstance(est, Mapping):
        return ""
    units = entry.get("units") if isinstance(entry.get("units"), Mapping) else {}
    parts, unclaimed = [], []
    # the ranking's components the flight does not excite (a quadrotor's r_z: only a
    # force along x or y shows it): their "estimate" is the prior, 0 +- 0.098, which the
    # verdict quoted while fit said "not excited by these logs"
    excited = (
        (entry.get("parameters") or {}).get("excited")
        if isinstance(entry.get("parameters"), Mapping)
        else None
    )
    at = 0
    for name, unit in (units or {}).items():
        values, intervals = est.get(name), est.get(f"{name}_ci95")
        pinned = est.get(f"{name}_pinned")
        if not isinstance(values, list) or not isinstance(intervals, list):
            continue
        offset, at = at, at + len(values)
        # as fit's table and the report's ranking name them: motor_loss's l_0 .. l_3
        labels = (
            [f"{name}_{a}" for a in "xyz"]
            if len(values) == 3
            else [name]
            if len(values) == 1
            else [f"{name}_{i}" for i in range(len(values))]
        )
        for i, (v, ci) in enumerate(zip(values, intervals, strict=False)):
            if not isinstance(ci, list) or len(ci) != 2 or ci[0] is None or ci[0] == ci[1]:
                continue  # not excited (no spread) or not finite
            if isinstance(excited, list) and offset + i < len(excited):
                if excited[offset + i] is False:
                    continue
            # no high end: an inertia scale whose gain cannot be told from 0
            ci = [float(ci[0]), math.inf if ci[1] is None else float(ci[1])]
            if axes is not None and len(values) == 3 and "xyz"[i] not in axes:
                unclaimed.append(labels[i])
                continue
            u = "" if unit == "1" else f" {unit}"
            null = null_component(str(entry.get("name")), name, i)
            span, digits = interval_span(str(entry.get("name")), name, ci[0], ci[1], null)
            # the unit after the interval too: "0.0327 s (95 %: 0.0282 to 0.0372)" beside
            # the actuators' "30 ms" left a new user unsure what the ends were in
            text = f"{labels[i]} = {v:.{digits}g}{u} (95 %: {span}{u}"
            if note := _bound_note(str(entry.get("name")), name, ci[0], v):
                text += f", {note}"
            if isinstance(pinned, list) and i < len(pinned) and pinned[i] is False:
                text += f", {unpinned_text(str(entry.get('name')), name, ci, i, est)}"
            parts.append(text + ")")
    text = f" Estimated on this flight as fit would: {'; '.join(parts)}." if parts else ""
    if unclaimed:
        which = ", ".join(label[-1] for label in unclaimed)
        text += (
            f" {', '.join(unclaimed)} not claimed: the effect explains under "
            f"{100 * AXIS_CLAIM:.0f} % of the {which} error{'s' if len(unclaimed) > 1 else ''} "
            "here."
        )
    return text


def null_component(effect: str, param: str, i: int) -> float | None:
    """Component ``i`` of the value at which ``effect`` is absent (None: unknown)."""
    from omavctl.learn.intervals import null_values

    try:
        null = null_values(effect)[param].reshape(-1)
    except (KeyError, ValueError, AttributeError):  # an effect this version does not know
        return None
    return float(null[i] if i < null.size else null[0])


def _bound_note(effect: str, param: str, low: Any, value: Any = None) -> str:
    """'cut at T_m ≥ 0' where the interval ends at the parameter's physical bound
    (:func:`omavctl.learn.intervals.bound_note`; imported here, when needed)."""
    from omavctl.learn.intervals import bound_note

    try:
        return bound_note(effect, param, float(low), _value(value))
    except (TypeError, ValueError):
        return ""


def _value(v: Any) -> float | None:
    """``v`` as a float when it is a number, else None."""
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None


def unpinned_text(
    effect: str, param: str, ci: list[Any], i: int, est: Mapping[str, Any] | None = None
) -> str:
    """Why the interval does not pin the parameter down, in words that follow it
    (:func:`omavctl.learn.intervals.unpinned_words`; imported here, when needed): the
    rotors' spread where the flight's statistics alone (``P_ci95_statistical``) would."""
    import numpy as np

    from omavctl.learn.intervals import SPREAD_WORDS, pinned_down, unpinned_words

    try:
        flight = (est or {}).get(f"{param}_ci95_statistical")
        if isinstance(flight, list) and i < len(flight) and None not in (flight[i] or [None]):
            if pinned_down(effect, param, np.asarray([flight[i]], float))[0]:
                return SPREAD_WORDS
        return unpinned_words(effect, param, [float(v) for v in ci], i)
    except (KeyError, ValueError, TypeError):  # an effect or parameter this version does not know
        return "cannot be pinned down from this flight"
