"""What the vehicle was doing in a worst segment, in words (for the verdict and the
report; no heavy imports)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["activity", "fails_text", "finite"]


def finite(v: Any) -> float | None:
    """``v`` as a float when it is a finite number (not a bool), else None."""
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def activity(seg: Mapping[str, Any]) -> str:
    """What the vehicle was doing in a worst segment, in words: tilt, the fastest
    rotation, thrust (from the segment's mean |attitude|, |rate|, |wrench|; no thrust
    when the segment says its force command is normalised, ``thrust_known``; the tilt
    said unknown when its ``attitude_deg`` is None: the log has no attitude)."""
    att = [finite(v) or 0.0 for v in (seg.get("attitude_deg") or [])][:3]
    rate = [finite(v) or 0.0 for v in (seg.get("rate") or [])][:3]
    u = [finite(v) or 0.0 for v in (seg.get("u") or [])]
    parts: list[str] = []
    if len(att) >= 2:
        roll, pitch = att[0], att[1]
        if max(roll, pitch) >= 5.0:  # a mean of 4-6 deg is not what "tilted" brings to mind
            how = "tilted" if max(roll, pitch) >= 15.0 else "slightly tilted"
            parts.append(f"{how} (|roll| {roll:.0f}°, |pitch| {pitch:.0f}°)")
        else:
            parts.append("near level")
    if len(rate) == 3 and max(rate) >= 0.2:
        k = max(range(3), key=lambda i: rate[i])
        parts.append(f"{('rolling', 'pitching', 'yawing')[k]} at {rate[k]:.2f} rad/s")
    elif rate:
        parts.append("barely rotating")
    if len(u) >= 3 and u[2] > 0 and seg.get("thrust_known", True) is not False:
        g = u[2] / 9.81
        if abs(g - 1.0) >= 0.15:
            parts.append(f"thrust {g:.2f} g")
    if seg.get("attitude_deg", []) is None:  # an IMU-only log: the tilt is unknown
        return ", ".join([*parts, "tilt unknown (no attitude in the log)"])
    return ", ".join(parts) if parts else "no state recorded"


def fails_text(tree: Mapping[str, Any]) -> str | None:
    """The verdict's "Fails most at ..." sentence: the evaluation's worst segment, its
    worst axis against that axis's overall error, and what the vehicle was doing."""
    segs = tree.get("worst_segments") or []
    if not segs or not isinstance(segs[0], Mapping):
        return None
    seg = segs[0]
    rmse = seg.get("rmse") or {}
    vals = {a: v for a in ("x", "y", "z") if (v := finite(rmse.get(a))) is not None}
    if not vals:
        return None
    axis = max(vals, key=lambda a: vals[a])
    model = ((tree.get("metrics") or {}).get("model") or {}).get("rmse") or {}
    overall = finite(model.get(axis)) if isinstance(model, Mapping) else None
    ratio = f", {vals[axis] / overall:.1f}× its overall" if overall else ""
    start, end = finite(seg.get("start")), finite(seg.get("end"))
    when = f"{start:.1f}–{end:.1f} s" if start is not None and end is not None else "?"
    return (
        f"Fails most at {when} of {seg.get('log', '?')}: {axis} error "
        f"{vals[axis]:.3g} rad/s² RMS{ratio}, while {activity(seg)}."
    )
