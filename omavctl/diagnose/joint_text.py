"""The verdict's sentences about the joint claim (:mod:`omavctl.diagnose.joint`): how
much of the held-out physics-only error the missing effects remove together, and why
effects the model's remaining error shows are not claimed when the held-out test
does not confirm them."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["joint_text", "physics_rejected"]


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


def physics_rejected(diag: Mapping[str, Any]) -> tuple[str, str | None] | None:
    """The sentence for the effects that explain the model's remaining error on the
    held-out flight but, estimated from the fit flight as fit --effects would, do not
    lower its physics-only error enough to be claimed (``physics_rejected``), with the
    command that tests the first; None when there are none."""
    held = diag.get("physics_rejected")
    if not isinstance(held, Mapping) or not held.get("names"):
        return None
    names = [str(n) for n in held["names"]]
    share = _num(held.get("share"))
    change = (
        "would not change it"
        if share is None
        else f"would lower it by {_pct(share)}"
        if share > 0
        else f"would make it grow by {_pct(-share)}"
    )
    text = (
        f"{', '.join(names)} explain{'s' if len(names) == 1 else ''} part of the model's "
        "remaining error on held-out data, but estimated from the fit flight as fit "
        f"--effects would {'it' if len(names) == 1 else 'they'} {change} of the held-out "
        "physics-only error (squared); a claim needs 15 % of it, consistently over the "
        "flight's 2 s blocks, and a part above the claim floor: not claimed. To test it, "
        "fit with it and compare both models on a flight neither saw."
    )
    commands = diag.get("effect_commands") or {}
    command = commands.get(names[0]) if isinstance(commands, Mapping) else None
    return text, command if isinstance(command, str) and command else None
