"""The verdict's sentence about the joint claim (:mod:`omavctl.diagnose.joint`): how
much of the held-out physics-only error the missing effects remove together."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["joint_share", "joint_text", "min_explained"]


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


def joint_share(diag: Mapping[str, Any], name: str) -> float | None:
    """``name``'s share of the held-out physics-only error in the joint selection."""
    for e in diag.get("joint_steps") or []:
        if isinstance(e, Mapping) and e.get("name") == name:
            return _num(e.get("share"))
    return None


def min_explained(diag: Mapping[str, Any]) -> float:
    """The share of the model's remaining error a claim of the ranking needs."""
    method = diag.get("method")
    value = _num(method.get("min_explained_variance")) if isinstance(method, Mapping) else None
    return value if value is not None else 0.15
