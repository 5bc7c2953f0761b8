"""The verdict's sentences about the claims guard (:mod:`omavctl.diagnose.claims`): a
claim held back because its interval holds the effect's null, and an effect the GP
learned that the held-out flight confirms (``learned_claims``)."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from typing import Any

from omavctl.diagnose.estimate_text import estimate_sentence
from omavctl.diagnose.joint_text import beside_timing_sentence

__all__ = [
    "beside_lag_sentence",
    "claim_estimate",
    "effect_to_test",
    "large_cut_sentence",
    "learned_claim_text",
    "not_pinned_names",
    "not_pinned_text",
]


def _num(v: Any) -> float | None:
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else None


def _pct(v: float) -> str:
    return f"{100 * v:.0f} %"


def _held(diag: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    items = diag.get("not_pinned")
    return [e for e in items if isinstance(e, Mapping)] if isinstance(items, list) else []


def not_pinned_names(diag: Mapping[str, Any]) -> list[str]:
    """The effects held back because their interval holds their null."""
    return [str(e.get("name")) for e in _held(diag)]


def effect_to_test(diag: Mapping[str, Any]) -> str | None:
    """The effect whose fit the verdict offers as a test ("test it with") when it holds
    a claim back: the one under the noise floor (``below_noise``); with nothing claimed
    (no ``missing``, no ``learned_claims``), the one the refit test held back (with both
    of its shares, as the verdict says them), else the first whose interval holds its
    null (``not_pinned``); None otherwise. ``diagnosis.test_command`` is that effect's
    command, the one the terminal prints."""
    if near := diag.get("below_noise"):
        return str(near)
    if diag.get("missing") or diag.get("learned_claims"):
        return None
    if name := diag.get("refit_rejected"):
        entry: Mapping[str, Any] = next(
            (e for e in diag.get("missing_effects") or [] if e.get("name") == name), {}
        )
        shares = (entry.get("explained_variance"), entry.get("refit_explained_variance"))
        if all(_num(v) is not None for v in shares):
            return str(name)
    unpinned = not_pinned_names(diag)
    return unpinned[0] if unpinned else None


def _null_words(name: str) -> str:
    """'scale = 1' / 'D = 0': the effect's null, as the interval is compared with it."""
    from omavctl.physics.effects import EFFECTS

    effect = EFFECTS.get(name)
    if effect is None:
        return "the value of no effect"
    nulls = effect.null_parameters()
    return ", ".join(f"{k} = {float(v.flat[0]):g}" for k, v in nulls.items())


def _fit_side_words(name: str, fit: Mapping[str, Any], here: Any) -> str:
    """Why the fit flight's interval does not confirm this flight's estimate, for a
    one-component effect: 'holds tau_d = 0 ...' or 'lies wholly on the other side of
    tau_d = 0 ...' (this flight puts it above, the fit flight below, or the reverse);
    with several components both cases in one phrase."""
    null = _null_words(name)
    absent = f"{null} (the value at which it is absent)"
    generic = f"does not lie wholly on the side of {absent} where this flight puts it"
    keys = [k for k in fit if f"{k}_ci95" in fit]
    if len(keys) != 1 or not isinstance(here, Mapping):
        return generic
    key = keys[0]
    try:
        lo, hi = (float(x) for x in fit[f"{key}_ci95"][0])
        value = float(here[key][0])
        zero = float(null.split("=")[-1])
    except (KeyError, IndexError, TypeError, ValueError):
        return generic
    if lo <= zero <= hi:
        return f"holds {absent}"
    if (value - zero) * (lo - zero) < 0:
        return f"lies wholly on the other side of {absent} than this flight's estimate"
    return generic


def _bound_words(name: str) -> str:
    """'its physical bound 0' for an effect whose parameters have one."""
    from omavctl.learn.intervals import PHYSICAL_BOUNDS

    bounds = {b for (effect, _), b in PHYSICAL_BOUNDS.items() if effect == name}
    return f"its physical bound {min(bounds):g}" if bounds else "its physical bound"


def beside_lag_sentence(name: str, lag: Mapping[str, Any], held: Collection[str] = ()) -> str:
    """' Not claimed: inertia_error, which this flight cannot tell from the motor lag's
    time constant: ...' for a claim :mod:`omavctl.diagnose.joint_lag` held back;
    ``held``: every effect held back (a rival among them is not "claimed instead")."""
    which = str(lag.get("lag", "the lag"))
    value, share = _num(lag.get("value")), _num(lag.get("share"))
    part, floor = _num(lag.get("part")), _num(lag.get("floor"))
    at = f" at {1000 * value:.1f} ms" if value is not None else ""
    cut = f" removes {_pct(share)} of what is left" if share is not None else " adds nothing"
    if part is not None and floor:
        cut += f", a part {part / floor:.2f}x the claim floor"
    there = _fitted_so(lag.get("values"))
    said = (
        f" Not claimed: {name}, which this flight does not tell from {which}: with {which}'s "
        f"exact form{at} and the default look-alikes, {name}{cut}{there}"
    )
    rival = lag.get("rival")
    if isinstance(rival, Mapping) and rival.get("name"):
        return f"{said}; {_rival_words(which, rival, str(rival['name']) in held)}"
    said += ", short of a claim's bars (15 % of what is left and a part at the claim floor)"
    instead = lag.get("claimed_instead")
    if instead is True:
        return f"{said}; {which}, which every rotorcraft's motors have, is claimed in its place."
    if instead is False:
        return f"{said}; {which} cannot be pinned down in its place either."
    return (
        f"{said}: a lag estimated too short leaves a loss of gain and phase that {name} "
        f"absorbs. Fit {which} first; judge {name} on the next flight."
    )


def _fitted_so(values: Any) -> str:
    """' (fitted so: D = 0.229, 0.18, 0.108)' of a profile's ``values`` (name -> list),
    '' when none is finite."""
    if not isinstance(values, Mapping):
        return ""
    there = "; ".join(
        f"{k} = {', '.join(f'{x:.3g}' for x in v)}"
        for k, v in values.items()
        if isinstance(v, list) and all(_num(x) is not None for x in v)
    )
    return f" (fitted so: {there})" if there else ""


def _rival_words(which: str, rival: Mapping[str, Any], held: bool = False) -> str:
    """'rotational_drag, in its place, removes 88 % of what is left with motor_lag at
    119.0 ms (fitted so: D = ...), is claimed instead.'; when the rival was held back
    too (``held``), '..., would take its place but cannot be pinned down either (said
    below).' (a new user read "drag_moment ... is claimed instead" between two "Not
    claimed: drag_moment")."""
    value, share = _num(rival.get("value_with")), _num(rival.get("share"))
    at = f" with {which} at {1000 * value:.1f} ms" if value is not None else ""
    cut = f" removes {_pct(share)} of what is left" if share is not None else ""
    there = _fitted_so(rival.get("values"))
    if held:
        return (
            f"{rival['name']}{cut}{at}{there} and would take its place, but cannot be "
            "pinned down either (said below)."
        )
    return f"{rival['name']}, in its place,{cut}{at}{there}, is claimed instead."


def not_pinned_text(diag: Mapping[str, Any]) -> str:
    """' Not claimed: inertia_error, which cannot be pinned down from this flight: ...'
    for every claim held back ('' when none was), with the interval that holds the
    null and the look-alike it stays ambiguous with."""
    out = ""
    acts = diag.get("actuators")
    ruled = set(acts.get("ruled_out") or []) if isinstance(acts, Mapping) else set()
    for e in _held(diag):
        name = str(e.get("name"))
        if e.get("actuators") == "ruled out" or name in ruled:
            continue  # the actuators' sentence says it (omavctl.diagnose.actuators)
        axes = e.get("axes")
        entry = {"name": name, "estimate": e.get("estimate"), "units": e.get("units")}
        said = estimate_sentence(entry, axes if isinstance(axes, list) and axes else None)
        fit = e.get("fit_flight")
        if isinstance(fit, Mapping):
            there = estimate_sentence({"estimate": fit, "units": e.get("units")}).replace(
                "Estimated on this flight as fit would:", "On the fit flight:", 1
            )
            out += (
                f" Not claimed: {name}, which the fit flight does not confirm: estimated "
                "there from the model's training points together with the other claims, its "
                f"95 % interval {_fit_side_words(name, fit, e.get('estimate'))}.{there}{said}"
            )
            continue
        lag = e.get("beside_lag")
        if isinstance(lag, Mapping):
            out += beside_lag_sentence(name, lag, not_pinned_names(diag)) + said
            continue
        beside = e.get("beside_timing")
        if isinstance(beside, Mapping):
            out += beside_timing_sentence(name, beside)
            continue
        beyond = e.get("not_physical")
        if isinstance(beyond, list) and beyond:
            out += (
                f" Not claimed: {name}, which is not physical here: the 95 % interval of "
                f"{', '.join(str(b) for b in beyond)} lies wholly below "
                f"{_bound_words(name)}, where it cannot be (something else on this axis "
                f"looks like it), and no other component it is claimed on excludes "
                f"{_null_words(name)}.{said}"
            )
            continue
        out += (
            f" Not claimed: {name}, which cannot be pinned down from this flight: its 95 % "
            f"interval holds {_null_words(name)} (the value at which it is absent) on every "
            "axis that matters, or excludes it only where its part of the error is under "
            f"the claim floor or the fit flight's estimate does not confirm it.{said}"
        )
    return out


def claim_estimate(diag: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    """The estimate the verdict quotes for a claim: the guard's (all claims estimated
    together, as the printed fit command does), else the learned entry's; with the
    units of ``name``'s parameters, as :func:`estimate_sentence` reads it."""
    learned: Mapping[str, Any] = next(
        (e for e in diag.get("learned") or [] if isinstance(e, Mapping) and e.get("name") == name),
        {},
    )
    ests = diag.get("claim_estimates")
    if isinstance(ests, Mapping) and isinstance(ests.get(name), Mapping):
        return {"name": name, "units": learned.get("units"), "estimate": ests[name]}
    return learned


def large_cut_sentence(step: Mapping[str, Any]) -> str:
    """What a learned claim accepted on its large cut (a learned step with
    ``log_ratio_t``, :func:`omavctl.diagnose.claims.large_cut_step`) rests on, and the
    look-alikes the data do not tell from it; '' for any other step."""
    log_t, block_t = _num(step.get("log_ratio_t")), _num(step.get("block_t"))
    better, blocks = _num(step.get("blocks_better")), _num(step.get("blocks"))
    if log_t is None or better is None or blocks is None:
        return ""
    uneven = f" (t {block_t:.1f} over its 2 s blocks, under 4)" if block_t is not None else ""
    text = (
        f" Its gain is uneven over the flight{uneven}, but it makes {better:.0f} of "
        f"{blocks:.0f} blocks better by a consistent fraction (t {log_t:.1f}) and removes at "
        "least half of the error: claimed on that large cut, for the next fit to test."
    )
    return text + _not_told_apart(step)


def learned_claim_text(diag: Mapping[str, Any], where: str) -> str:
    """The sentence of an effect the GP learned that the held-out flight confirms,
    '' when there is none: what it explains of the nominal residual, what its
    fit-flight estimate removes of the held-out physics-only error, its estimate."""
    names = [str(n) for n in diag.get("learned_claims") or []]
    if not names:
        return ""
    name = names[0]
    step: Mapping[str, Any] = next(
        (s for s in diag.get("learned_steps") or [] if isinstance(s, Mapping)), {}
    )
    ev, rms = _num(step.get("explained_variance")), _num(step.get("contribution_rms"))
    share = _num(step.get("share"))
    also = [str(n) for n in step.get("jointly_with") or []]
    text = f"Learned by the GP, not yet in the physics: {name}"
    if also:
        text += f" with {', '.join(also)}, the look-alikes of every rotorcraft's imperfections"
    if ev is not None and rms is not None:
        what = name if also else "it"
        text += (
            f" — the physics-only residual looks like {what} (it explains {_pct(ev)} of "
            f"it, {rms:.2g} rad/s² RMS)"
        )
    if share is not None:
        text += (
            "; estimated together from the fit flight by least squares, they remove "
            f"{_pct(share)} of the squared physics-only error {where}, where neither alone "
            "is confirmed"
            if also
            else "; estimated from the fit flight by least squares as fit's first pass "
            f"would, it removes {_pct(share)} of the squared physics-only error {where}"
        )
    text += "."
    text += beside_look_alikes_sentence(step)
    text += held_out_not_pinned_sentence(step)
    text += large_cut_sentence(step)
    text += estimate_sentence(step)
    return text + (
        " What the GP learned of it holds only where the fit flight went; fitted as a "
        "physical effect it is tested on every flight."
    )


def beside_look_alikes_sentence(step: Mapping[str, Any]) -> str:
    """What a learned claim's share is of when it was judged beside the default
    imperfections' look-alikes refitted on the held-out flight
    (:mod:`omavctl.diagnose.learned_beside`); '' otherwise."""
    total = _num(step.get("share_of_total"))
    if step.get("beside_look_alikes") is not True or total is None:
        return ""
    return (
        " That share is of what com_offset and rotor_interference, the look-alikes of every "
        "rotorcraft's imperfections, leave at their least-squares fit on this flight; of "
        f"the whole physics-only error it removes {_pct(total)}."
    )


def held_out_not_pinned_sentence(step: Mapping[str, Any]) -> str:
    """Why a lag or delay the held-out flight does not pin down is claimed on its
    fit-flight estimate (:mod:`omavctl.diagnose.held_beside`), and the lags and delays
    the data do not tell from it; a linear effect's (:mod:`omavctl.diagnose.
    learned_fit_pinned`); '' for any other step."""
    if step.get("held_out_not_pinned") is True and isinstance(step.get("fit_flight"), Mapping):
        return _fit_flight_words(step)
    value = _num(step.get("fit_flight_value"))
    if step.get("held_out_not_pinned") is not True or value is None:
        return ""
    fit = step.get("fit_flight_fit")
    if isinstance(fit, Mapping):  # checked as fit would estimate it on the fit logs
        there = estimate_sentence(
            {"name": step.get("name"), "estimate": fit, "units": step.get("units")}
        ).replace(" Estimated on this flight as fit would: ", "", 1)
        shown = f"estimated there as fit --effects would, {there.rstrip('.')}"
    elif step.get("fit_flight_checked") is False:
        shown = (
            f"{1e3 * value:.0f} ms by least squares at the model's training points, its 95 % "
            "interval excluding 0; the fit logs could not be read to estimate it as fit "
            "--effects would, whose interval, robust to the flight's autocorrelation, may "
            "be wider"
        )
    else:  # a file written before the check
        shown = f"{1e3 * value:.0f} ms, its 95 % interval excluding 0"
    text = (
        f" This flight alone does not pin its value down; the fit flight shows it ({shown}; "
        "the GP shrinks it, so fit --effects gives the value to trust), and at the "
        "training points' value it removes the share above beside the look-alikes."
    )
    return text + _not_told_apart(step)


def _fit_flight_words(step: Mapping[str, Any]) -> str:
    """The sentence of a linear learned claim the held-out flight does not pin down:
    its fit-flight values (no interval: the training points' sandwich leaves out what
    the GP and the rotors' spread add, so fit --effects gives the one to trust)."""
    fit, units = step["fit_flight"], step.get("units")
    values = []
    for param, unit in (units if isinstance(units, Mapping) else {}).items():
        row = fit.get(param)
        if not isinstance(row, list):
            continue
        labels = [f"{param}_{a}" for a in "xyz"] if len(row) == 3 else [param] * len(row)
        u = "" if unit == "1" else f" {unit}"
        values += [f"{lab} {v:.3g}{u}" for lab, v in zip(labels, row, strict=True)]
    return (
        " This flight alone does not pin its value down; the fit flight does (least squares "
        f"at the model's training points: {', '.join(values)}; fit --effects gives the "
        "value and interval to trust), and at that value it removes the share above."
    )


def _not_told_apart(step: Mapping[str, Any]) -> str:
    """' The data do not tell it from a, b: plan --objective effects designs a flight
    that does.' for a step with look-alikes in ``ambiguous_with``; '' without."""
    alike = [str(n) for n in step.get("ambiguous_with") or []]
    if not alike:
        return ""
    return (
        f" The data do not tell it from {', '.join(alike)}: plan --objective effects "
        "designs a flight that does."
    )
