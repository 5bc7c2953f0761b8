"""A candidate that explains a material share of one axis's error but is not claimed.

The claim floor is on the total (``min_explained_variance``, 15 % of the model's
remaining error over all axes): on the Betaflight tunes ``command_delay`` explained
34 % of the y error on held-out blocks (1-3 % on x and z) and the verdict named it
nowhere, claimed or held back (docs/real-data-check.md item 14). :func:`axis_held`
finds such candidates with the test that held each back; :func:`axis_held_line` says
it. Works on the evaluation JSON only.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

from omavctl.diagnose.activity import finite as _num
from omavctl.diagnose.scoring import MIN_T
from omavctl.diagnose.verdict_lines import AXES, Line, _pct, get_path

__all__ = ["axis_held", "axis_held_line", "failed_test", "named_effects"]


def named_effects(diag: Mapping[str, Any]) -> list[str]:
    """The effects the verdict names already, in its order: missing, claimed as
    learned, held back (``not_pinned``, the noise floor's, the refit test's)."""
    names = [*map(str, diag.get("missing") or []), *map(str, diag.get("learned_claims") or [])]
    names += [str(e.get("name")) for e in diag.get("not_pinned") or [] if isinstance(e, Mapping)]
    names += [str(n) for n in (diag.get("below_noise"), diag.get("refit_rejected")) if n]
    return list(dict.fromkeys(names))


def failed_test(entry: Mapping[str, Any], floor: float) -> str:
    """The first test ``entry`` (a ``missing_effects`` entry) fails, in words; under the
    share floor, also whether its estimate is not significant or not plausible (a new
    user read only the share for a negative delay at t 0, offered to be tested)."""
    ev = _num(entry.get("explained_variance"))
    if ev is not None and ev < floor:
        text = (
            f"over all axes it explains {_pct(max(ev, 0.0))}, under the {_pct(floor)} of "
            "the total a claim needs"
        )
        weak = [w for w in (_not_significant(entry), _implausible(entry)) if w]
        both = " and ".join(weak).replace(" and its estimate is ", " and ")
        return text + (f", and {both}" if weak else "")
    return _not_significant(entry) or _implausible(entry) or _other_test(entry)


def _not_significant(entry: Mapping[str, Any]) -> str:
    """'its estimate is not significant (t = 0.3, under the 4 a claim needs)' for such an
    entry, else ''. (A t of 3.96 printed as "t = 4" read as significant to a new user.)"""
    if entry.get("significant") is not False:
        return ""
    t = _num(entry.get("t_value"))
    if t is None:
        return "its estimate is not significant"
    # enough digits that a t under the bar never prints as the bar
    shown = next(s for d in (2, 3, 4, 6) if (s := f"{t:.{d}g}") != f"{MIN_T:g}" or d == 6)
    return f"its estimate is not significant (t = {shown}, under the {MIN_T:g} a claim needs)"


def _implausible(entry: Mapping[str, Any]) -> str:
    """'its estimate is outside the effect's plausible range' for such an entry, else ''."""
    if entry.get("plausible") is not False:
        return ""
    return "its estimate is outside the effect's plausible range"


def _other_test(entry: Mapping[str, Any]) -> str:
    """The noise floor's or the refit test's reason, else the claims guard's."""
    if entry.get("above_noise") is False:
        return "its part of the error is under the claim floor (three times the log's noise)"
    refit = _num(entry.get("refit_explained_variance"))
    if refit is not None and refit <= 0:
        return "estimated as fit --effects would from the fit flight, it does not lower the error"
    return "it does not pass the claims guard"


def axis_held(diag: Mapping[str, Any], effects: Sequence[str] = ()) -> list[dict[str, Any]]:
    """``{name, axes: {axis: share}, why, weak}`` of every candidate (``missing_effects``)
    that explains at least the claim floor's share of some axis's error but that the
    verdict does not name otherwise; not the model's own ``effects``."""
    floor = _num(get_path(diag, "method", "min_explained_variance"))
    if floor is None:
        return []
    said = {*named_effects(diag), *effects}
    out = []
    for e in diag.get("missing_effects") or []:
        if not isinstance(e, Mapping) or str(e.get("name")) in said:
            continue
        per_axis = e.get("explained_variance_per_axis") or {}
        axes = {a: v for a in AXES if (v := _num(per_axis.get(a))) is not None and v >= floor}
        if axes:
            weak = bool(_not_significant(e) or _implausible(e))
            out.append(
                {
                    "name": str(e.get("name")),
                    "axes": axes,
                    "why": failed_test(e, floor),
                    "weak": weak,
                }
            )
    return out


def axis_held_line(tree: Mapping[str, Any], said: Collection[str] = ()) -> Line | None:
    """'Not claimed although it explains 34 % of the y error: command_delay (over all
    axes it explains 4 %, ...)' with the command that tests it; None when none is.
    ``said``: effects another verdict line discusses already (the one the GP learned: a
    new user read it "pinned down away from its null" there and "not significant" here)."""
    diag = get_path(tree, "diagnosis", default={}) or {}
    effects = [str(e) for e in get_path(tree, "models", 0, "effects", default={}) or {}]
    held = [h for h in axis_held(diag, effects) if h["name"] not in said]
    if not held:
        return None
    first = held[0]
    text = (
        f"Not claimed although it explains {_shares(first)} on held-out blocks: "
        f"{first['name']}, because {first['why']}."
    )
    command = (diag.get("effect_commands") or {}).get(first["name"])
    cmd = command if isinstance(command, str) and command else None
    if first["weak"]:  # an estimate at t 0 or out of range: nothing for a fit to test
        cmd = None
    if len(held) > 1:  # each with its share, as the first (a bare name said nothing)
        text += " Likewise: " + ", ".join(f"{h['name']} ({_shares(h)})" for h in held[1:])
        text += "."
        # and how to test them: the command below names the first (a new user found
        # no command for the others; evaluate --json has each in effect_commands)
        if cmd and any(not h["weak"] for h in held[1:]):
            text += f" Test each the same way, its name in place of {first['name']}."
    return Line("axis", text, command=cmd, subject=first["name"], test=cmd is not None)


def _shares(held: Mapping[str, Any]) -> str:
    """'34 % of the y error' (and ', 18 % of the x error' per further axis) of one
    :func:`axis_held` entry."""
    return ", ".join(f"{_pct(v)} of the {a} error" for a, v in held["axes"].items())
