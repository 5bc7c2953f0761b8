"""One sentence for a diagnosis estimate and its 95 % interval (no heavy imports:
the verdict and the report use it)."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

__all__ = ["estimate_sentence"]


def estimate_sentence(entry: Mapping[str, Any], axes: Collection[str] | None = None) -> str:
    """' Estimated as fit would: T_m = 0.027 s (95 %: -0.10 to 0.16, cannot be pinned
    down from this flight).' for a diagnosis ``learned`` entry with an ``estimate``
    ('' without one).

    ``axes``: the axes the claim is made on; a per-axis component (D_z) on another
    axis is not quoted as an estimate ("D_z not claimed: ..."): where the effect
    explains none of an axis's error, its component there is whatever else that
    axis's residual holds, and its interval would not hold the truth."""
    est = entry.get("estimate")
    if not isinstance(est, Mapping):
        return ""
    units = entry.get("units") if isinstance(entry.get("units"), Mapping) else {}
    parts, unclaimed = [], []
    for name, unit in (units or {}).items():
        values, intervals = est.get(name), est.get(f"{name}_ci95")
        pinned = est.get(f"{name}_pinned")
        if not isinstance(values, list) or not isinstance(intervals, list):
            continue
        labels = [f"{name}_{a}" for a in "xyz"] if len(values) == 3 else [name] * len(values)
        for i, (v, ci) in enumerate(zip(values, intervals, strict=False)):
            if not isinstance(ci, list) or None in ci or ci[0] == ci[1]:
                continue  # not excited (no spread) or not finite
            if axes is not None and len(values) == 3 and "xyz"[i] not in axes:
                unclaimed.append(labels[i])
                continue
            u = "" if unit == "1" else f" {unit}"
            text = f"{labels[i]} = {v:.3g}{u} (95 %: {ci[0]:.3g} to {ci[1]:.3g}"
            if isinstance(pinned, list) and i < len(pinned) and pinned[i] is False:
                text += ", cannot be pinned down from this flight"
            parts.append(text + ")")
    text = f" Estimated as fit would: {'; '.join(parts)}." if parts else ""
    if unclaimed:
        which = ", ".join(label[-1] for label in unclaimed)
        text += (
            f" {', '.join(unclaimed)} not claimed: the effect explains none of the "
            f"{which} error{'s' if len(unclaimed) > 1 else ''} here."
        )
    return text
