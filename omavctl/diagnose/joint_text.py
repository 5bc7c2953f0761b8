"""The verdict's sentence about the joint claim (:mod:`omavctl.diagnose.joint`): how
much of the held-out physics-only error the missing effects remove together."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = [
    "beside_timing_sentence",
    "joint_left_words",
    "joint_share",
    "joint_text",
    "linear_words",
    "min_explained",
    "named_later",
    "replaced_step",
    "replaced_text",
]


#: The look-alikes of every rotorcraft's imperfections (omavctl.diagnose.joint's
#: DEFAULT_LOOK_ALIKES, not imported: this module stays free of numpy).
_LOOK_ALIKES = ("com_offset", "rotor_interference")


def _num(v: Any) -> float | None:
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def _pct(v: float) -> str:
    return f"{100 * v:.0f} %"


def _entries(diag: Mapping[str, Any], key: str) -> list[Mapping[str, Any]]:
    items = diag.get(key)
    return [e for e in items if isinstance(e, Mapping)] if isinstance(items, list) else []


def replaced_step(diag: Mapping[str, Any], name: str) -> str | None:
    """The joint step ``name`` took the place of (:mod:`omavctl.diagnose.joint_timing`):
    a lag or delay the step accepted first, held back by the claims guard and replaced by
    ``name``, one of its ``timing_rivals``; None when ``name`` is a step of its own."""
    steps = _entries(diag, "joint_steps")
    if any(e.get("name") == name for e in steps):
        return None
    said = set(map(str, diag.get("missing") or []))
    # a claim the others' exact forms replaced (timing_claimed.py) is said on its own
    said |= {str(e.get("name")) for e in _entries(diag, "not_pinned") if "beside_timing" in e}
    for e in steps:
        held = str(e.get("name"))
        if name in map(str, e.get("timing_rivals") or []) and held not in said:
            return held
    return None


def replaced_text(diag: Mapping[str, Any], name: str) -> str:
    """Why ``name``'s share is another effect's, '' when it is its own: the joint step
    it answers accepted a look-alike first, which the exact estimate did not pin down."""
    held = replaced_step(diag, name)
    if held is None:
        return ""
    return (
        f"{name}'s share is that of the joint step {held} passed first: a lag and a delay "
        f"look alike to first order, both passed it, and estimated exactly on this flight "
        f"{held} could not be pinned down while {name} was, so {name} takes its place"
    )


def joint_text(diag: Mapping[str, Any], missing: Sequence[str]) -> str:
    """How much of the held-out physics-only error the missing effects remove when
    estimated together (``joint_steps``), '' when the joint selection did not name them
    all; the fit command adds them all at once. An effect that took a held-back lag's or
    delay's step (:func:`replaced_step`) is given that step's share, and says so."""
    steps = {str(e.get("name")): e for e in _entries(diag, "joint_steps")}
    shares = [
        _num(steps.get(replaced_step(diag, m) or m, {}).get("share_of_total")) for m in missing
    ]
    together = together_words(diag)
    if any(v is None for v in shares):
        return f" ({together})"
    parts = ", ".join(f"{m} {_pct(v)}" for m, v in zip(missing, shares, strict=True) if v)
    why = "".join(f"; {clause}" for m in missing if (clause := replaced_text(diag, m)))
    return (
        f" ({together}: estimated jointly from the fit flight as "
        f"fit --effects would, they remove {_pct(sum(v for v in shares if v))} of the "
        f"squared physics-only error on held-out data, {parts}{why})"
    )


def together_words(diag: Mapping[str, Any]) -> str:
    """'the fit command adds them together', or without a printed command (several
    models evaluated, a model whose fit flight is unknown) 'fit them together'."""
    cmd = diag.get("fit_command")
    return (
        "the fit command adds them together"
        if isinstance(cmd, str) and cmd
        else ("fit them together")
    )


def joint_share(diag: Mapping[str, Any], name: str) -> float | None:
    """``name``'s share of the held-out physics-only error in the joint selection (the
    share of the step it took, :func:`replaced_step`)."""
    step = replaced_step(diag, name) or name
    for e in diag.get("joint_steps") or []:
        if isinstance(e, Mapping) and e.get("name") == step:
            return _num(e.get("share"))
    return None


def joint_left_words(diag: Mapping[str, Any], name: str, in_model: Sequence[str] = ()) -> str:
    """What ``name``'s joint share (:func:`joint_share`) is a share of, when not of the
    whole physics-only error, with its share of the whole: ' that com_offset leaves, 2 %
    of the whole'; '' when the two agree to the percent.

    A new user read "it removes 71 % of the squared physics-only error" beside "they
    remove 99 %, command_delay 2 %, com_offset 98 %": the 71 % was of what the
    look-alikes left. A lag or delay judged beside the look-alikes
    (:mod:`omavctl.diagnose.timing_beside`) stands first in ``joint_steps``, its share of
    what their least-squares fit on this flight leaves; a later step of the forward
    selection, of what the steps before it leave. ``in_model``: the model's effects (the
    look-alikes fitted beside it are those the model lacks)."""
    step = replaced_step(diag, name) or name
    steps = _entries(diag, "joint_steps")
    at = next((i for i, e in enumerate(steps) if e.get("name") == step), None)
    if at is None:
        return ""
    share, total = _num(steps[at].get("share")), _num(steps[at].get("share_of_total"))
    if share is None or total is None or round(100 * share) == round(100 * total):
        return ""
    whole = f", {_pct(total)} of the whole"
    if at == 0:
        alikes = [n for n in _LOOK_ALIKES if n not in in_model] or list(_LOOK_ALIKES)
        who = (
            f"{alikes[0]}, the look-alike of a rotorcraft's imperfections, leaves at its"
            if len(alikes) == 1
            else f"{' and '.join(alikes)}, the look-alikes of every rotorcraft's "
            "imperfections, leave at their"
        )
        return f" that {who} least-squares fit there{whole}"
    before = [str(e.get("name")) for e in steps[:at]]
    return f" that {' and '.join(before)} leave{'s' if len(before) == 1 else ''}{whole}"


def min_explained(diag: Mapping[str, Any]) -> float:
    """The share of the model's remaining error a claim of the ranking needs."""
    method = diag.get("method")
    value = _num(method.get("min_explained_variance")) if isinstance(method, Mapping) else None
    return value if value is not None else 0.15


def _timing_fit_words(fit: Mapping[str, Any]) -> str:
    """'motor_lag and servo_lag (32.4 ms, 74.5 ms)' of a profiled fit's JSON."""
    names = [str(n) for n in fit.get("names") or []]
    values = [v for v in (_num(x) for x in fit.get("values_s") or []) if v is not None]
    at = f" ({', '.join(f'{1000 * v:.1f} ms' for v in values)})" if values else ""
    return f"{' and '.join(names)}{at}"


def beside_timing_sentence(name: str, beside: Mapping[str, Any]) -> str:
    """' Not claimed: command_delay, which the held-out flight tells from motor_lag and
    servo_lag: ...' for a lag or delay that :mod:`omavctl.diagnose.timing_claimed`
    replaced by a better pair or single."""
    claim, instead = beside.get("claim"), beside.get("instead")
    if not isinstance(claim, Mapping) or not isinstance(instead, Mapping):
        return f" Not claimed: {name}, which another lag or delay explains better."
    share, t = _num(beside.get("share")), _num(beside.get("hac_t"))
    cut = f" remove {_pct(share)} of what" if share is not None else " explain more than"
    by = f" (a gain of {t:.1f} Newey-West standard errors per sample)" if t is not None else ""
    return (
        f" Not claimed: {name}, which the held-out flight tells from "
        f"{_timing_fit_words(instead)}: with their exact forms and the default look-alikes "
        f"refitted, they{cut} {_timing_fit_words(claim)} alone leaves{by}. A lag and a delay "
        "look alike to first order; what is claimed in its place is what the flight shows."
    )


def named_later(diag: Mapping[str, Any]) -> dict[str, tuple[str, str]]:
    """Each effect of ``missing`` that the ranking of effects one at a time
    (``missing_effects``, where it is not ``missing``) does not name, with how a later
    step named it: name -> (a few words for a table cell or a figure label, a clause
    with the step's numbers). The report shows the ranking; without this a claimed
    effect stands there as "no" (the demo's motor lag at 0 %, named by the joint
    selection on the physics-only error)."""
    alone = {
        str(e.get("name")) for e in _entries(diag, "missing_effects") if e.get("missing") is True
    }
    steps = [str(e.get("name")) for e in _entries(diag, "missing_steps")]
    step_ev = {
        str(e.get("name")): _num(e.get("explained_variance"))
        for e in _entries(diag, "missing_steps")
    }
    out: dict[str, tuple[str, str]] = {}
    for name in map(str, diag.get("missing") or []):
        if name in alone:
            continue
        if name in steps and steps.index(name) > 0:
            k = steps.index(name)
            ev = step_ev.get(name)
            share = f"it explains {_pct(ev)} of" if ev is not None else "it explains a share of"
            leave = "leaves" if k == 1 else "leave"
            out[name] = (
                f"step {k + 1}",
                f"{name}: step {k + 1} of the forward selection: {share} the model's "
                f"remaining error that {' and '.join(steps[:k])} {leave}",
            )
            continue
        out[name] = _joint_words(diag, name)
    return out


def _profile_words(name: str, fit: Mapping[str, Any]) -> str:
    """:func:`named_later`'s clause for a claim a held-out profile found with a partner
    (``timing_claims``: :mod:`omavctl.diagnose.timing_pair`, ``timing_mixed``)."""
    names = [str(n) for n in fit.get("names") or []]
    values = [_num(v) for v in fit.get("values_s") or []]
    at = {
        n: f"{n} ({1000 * v:.1f} ms)" for n, v in zip(names, values, strict=False) if v is not None
    }
    together, shares = _num(fit.get("share")), fit.get("member_share") or []
    mine = _num(shares[names.index(name)]) if name in names and len(shares) == len(names) else None
    others = [at.get(n, n) for n in names if n != name]
    if others and mine is not None and name != names[0]:  # the first member said the rest
        return f"{at.get(name, name)}: in the same profile, {_pct(mine)} of what the other leaves"
    out = f"{at.get(name, name)}: profiled on this flight"
    out += f" together with {' and '.join(others)}" if others else ""
    if together is not None:
        out += f": {'together they remove' if others else 'it removes'} {_pct(together)} of"
        out += " the physics-only error the look-alikes leave"
    if mine is not None and others:
        out += f", {name} {_pct(mine)} of what the other alone leaves"
    alike_of = fit.get("alike_of")
    alike = alike_of.get(name) if isinstance(alike_of, Mapping) else None
    if isinstance(alike, list) and alike:
        out += f"; this flight does not tell it from {' or '.join(map(str, alike))}"
    return out


def _joint_words(diag: Mapping[str, Any], name: str) -> tuple[str, str]:
    """:func:`named_later`'s words for an effect the joint selection named."""
    profiles = diag.get("timing_claims")
    fit = profiles.get(name) if isinstance(profiles, Mapping) else None
    if isinstance(fit, Mapping):
        return ("held-out profile", _profile_words(name, fit))
    step = replaced_step(diag, name) or name
    joint = next((e for e in _entries(diag, "joint_steps") if e.get("name") == step), None)
    if joint is None:
        for e in _entries(diag, "not_pinned"):
            lag = e.get("beside_lag")
            rival = lag.get("rival") if isinstance(lag, Mapping) else None
            if isinstance(rival, Mapping) and rival.get("name") == name:
                which = lag.get("lag") if isinstance(lag, Mapping) else "the lag"
                said = f"{name}: in the place of {e.get('name')}, beside {which}'s exact form"
                return ("beside the lag", said)
        return ("a later step", f"{name}: named by a later step of the selection")
    removed, total = _num(joint.get("share")), _num(joint.get("share_of_total"))
    numbers = ""
    if removed is not None:
        numbers = (
            f": estimated from the fit flight as fit --effects would, it removes "
            f"{_pct(removed)} of the held-out physics-only error left before it"
        )
        numbers += f" ({_pct(total)} of the whole)" if total is not None else ""
    return ("joint selection", f"{name}: the joint selection{numbers}")


def linear_words(diag: Mapping[str, Any], name: str) -> str | None:
    """The verdict's clause for an effect linear in its parameters that the held-out
    flight itself found (``timing_claims`` of kind ``linear``:
    :mod:`omavctl.diagnose.linear_profile`); None for any other claim."""
    profiles = diag.get("timing_claims")
    fit = profiles.get(name) if isinstance(profiles, Mapping) else None
    if not isinstance(fit, Mapping) or fit.get("kind") != "linear":
        return None
    share = _num(fit.get("share"))
    better, blocks = fit.get("blocks_better"), fit.get("blocks")
    out = "estimated on this flight beside the look-alikes"
    if share is not None:
        out += f", it removes {_pct(share)} of the physics-only error they leave"
    if isinstance(better, int) and isinstance(blocks, int):
        out += f", judged on 2 s blocks it was not fitted on (lower in {better} of {blocks})"
    return out
