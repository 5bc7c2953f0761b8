"""The verdict's sentence about the joint claim (:mod:`omavctl.diagnose.joint`): how
much of the held-out physics-only error the missing effects remove together."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["joint_text"]


def _num(v: Any) -> float | None:
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def _pct(v: float) -> str:
    return f"{100 * v:.0f} %"


def _entries(diag: Mapping[str, Any], key: str) -> list[Mapping[str, Any]]:
    items = diag.get(key)
    return [e for e in items if isinstance(e, Mapping)] if isinstance(items, list) else []


def joint_text(diag: Mapping[str, Any], missing: Sequence[str]) -> str:
    """How much of the held-out physics-only error the missing effects remove when
    estimated together (``joint_steps``), '' when the joint selection did not name them
    all; the fit command adds them all at once."""
    steps = {str(e.get("name")): e for e in _entries(diag, "joint_steps")}
    shares = [_num(steps.get(m, {}).get("share_of_total")) for m in missing]
    if any(v is None for v in shares):
        return " (the fit command adds them together)"
    parts = ", ".join(f"{m} {_pct(v)}" for m, v in zip(missing, shares, strict=True) if v)
    return (
        " (the fit command adds them together: estimated jointly from the fit flight as "
        f"fit --effects would, they remove {_pct(sum(v for v in shares if v))} of the "
        f"squared physics-only error on held-out data, {parts})"
    )
