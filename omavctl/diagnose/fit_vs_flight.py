"""Where the model's fitted effect and this flight's estimate of it disagree.

A model's effect parameters are estimated on its fit flight; the diagnosis
estimates every effect on the evaluated flight as ``fit --effects`` would
(``diagnosis.learned``, each entry's ``estimate``, with the model's effects): for an
effect the model holds, that is the number the verdict of a model without it quoted.
On the Crazyflie the verdict of a model fitted on the hover logs quoted T_m = 60.7
ms (95 %: 24 to 97) on log15's roll/pitch window, and the printed command then
fitted 9.5 +- 16.1 ms on the hover logs, 2.1 combined standard errors apart, with
nothing on the page saying so (docs/real-data-check.md, item 10). Where the two
differ by more than :data:`APART` combined standard errors, :func:`disagree_line`
says so, with the flight each comes from. Works on the evaluation JSON only.

An effect's estimate is made with the first model's effects (with the effect added
when the first model lacks it): a parameter of a model with other effects is compared
only where that is the model's own set (``--model a --model a+X``: X's parameters, not
a's shared ones, which the model fitted beside X and the estimate without it). On the
Crazyflie halves the lag model's inertia scale_z (1.51 +- 0.29, beside the lag) was
said to disagree with 3.56 +- 0.63, the estimate without the lag: the two models, not
the two flights, differed.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

from omavctl.diagnose.activity import finite as _num
from omavctl.diagnose.estimate_text import AXIS_CLAIM
from omavctl.diagnose.verdict_lines import AXES, Line, get_path

__all__ = [
    "APART",
    "disagree_line",
    "disagreeing",
    "elsewhere_clause",
    "flight_words",
    "pinned_here_line",
]

#: Combined standard errors (``|a - b| / sqrt(se_a^2 + se_b^2)``) from which the fitted
#: and this flight's estimates of one parameter are said to disagree (issue 26: the
#: diagnosis's and fit's estimates of one effect on one log differ by less than 2).
APART = 2.0


def flight_words(logs: Sequence[Any], window: Any) -> str:
    """'log10, log16' or 'log15, 15.76-50.76 s' (the window in s from each log's first
    sample, as ``--time-window`` counts); '' without logs."""
    names = ", ".join(str(n) for n in logs)
    if not names:
        return ""
    if not isinstance(window, list) or len(window) != 2:
        return names
    a, b = (_num(w) for w in window)
    if a is None and b is None:
        return names
    start = f"{a:g}" if a is not None else "the start"
    end = f"{b:g} s" if b is not None else "the end"
    return f"{names}, {start}–{end}" if b is not None else f"{names}, {start} s to the end"


def _apart(
    fitted: Mapping[str, Any], here: Mapping[str, Any], key: str, i: int
) -> tuple[float, float, float, float, float] | None:
    """(fitted value, its se, this flight's value, its se, combined standard errors
    apart) of component ``i`` of parameter ``key``; None where a number is missing or
    not finite, or the component was not excited (a value of exactly 0)."""
    v, se = _num(get_path(fitted, key, i)), _num(get_path(fitted, f"{key}_stderr", i))
    d, dse = _num(get_path(here, key, i)), _num(get_path(here, f"{key}_stderr", i))
    if v is None or se is None or d is None or dse is None or v == 0.0 or d == 0.0:
        return None
    return v, se, d, dse, abs(v - d) / max(math.hypot(se, dse), 1e-300)


def _components(
    fitted: Mapping[str, Any], entry: Mapping[str, Any], beside: str
) -> Iterator[tuple[str, int, str, str]]:
    """(key, i, label, unit text) of each component of a fitted effect's parameters that
    carry ``key + beside`` (their standard errors, their pinned flags): a per-axis
    component (label ``D_z``) only on an axis where the effect explains at least
    :data:`AXIS_CLAIM` of this flight's error (elsewhere its estimate is whatever else
    that axis holds); a parameter of another size by its key."""
    units = entry.get("units") if isinstance(entry.get("units"), Mapping) else {}
    shares = entry.get("explained_variance_per_axis") or {}
    for key, values in fitted.items():
        if not isinstance(values, list) or not isinstance(fitted.get(f"{key}{beside}"), list):
            continue
        unit = str((units or {}).get(key, ""))
        u = "" if unit in ("", "1") else f" {unit}"
        for i in range(len(values)):
            share = _num(shares.get(AXES[i])) if len(values) == 3 else None
            if len(values) == 3 and (share is None or share < AXIS_CLAIM):
                continue
            yield key, i, f"{key}_{AXES[i]}" if len(values) == 3 else key, u


def _parts(name: str, fitted: Mapping[str, Any], entry: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(label, 'T_m = 0.0095 ± 0.016 s fitted, 0.0607 ± 0.019 s here (2.1 apart)') for
    each component of effect ``name`` more than :data:`APART` apart (label ``D_z``, or
    the key of a one-component parameter); a per-axis component only on an axis where
    the effect explains at least :data:`AXIS_CLAIM` of this flight's error (elsewhere
    its estimate is whatever else that axis holds)."""
    here = entry.get("estimate")
    if not isinstance(here, Mapping):
        return []
    out = []
    for key, i, label, u in _components(fitted, entry, "_stderr"):
        got = _apart(fitted, here, key, i)
        if got is None or got[4] <= APART:
            continue
        v, se, d, dse, z = got
        out.append(
            (
                label,
                f"{name}'s {label} = {v:.3g} ± {se:.2g}{u} as fitted, {d:.3g} ± "
                f"{dse:.2g}{u} on this flight ({z:.1f} combined standard errors apart)",
            )
        )
    return out


def disagree_line(tree: Mapping[str, Any]) -> Line | None:
    """The effects of each model whose fitted parameters and the diagnosis's estimate
    of them on the evaluated flight (``diagnosis.learned``, as fit --effects with the
    first model's effects would make it) are more than :data:`APART` combined standard
    errors apart, naming the flight each comes from (and the model, when there are
    several); None when none is (or the file predates the estimates)."""
    models = [m for m in tree.get("models") or [] if isinstance(m, Mapping)]
    learned = get_path(tree, "diagnosis", "learned", default=[]) or []
    entries = {str(e.get("name")): e for e in learned if isinstance(e, Mapping)}
    here = flight_words([n for n in _logs(tree) if n], tree.get("time_window")) or "this flight"
    said = []
    for model in models:
        parts = [text for _, _, text in _model_parts(model, entries, models[0])]
        if not parts:
            continue
        there = _fit_flight_words(model)
        who = f"With {model.get('name')}: t" if len(models) > 1 else "T"
        said.append(
            f"{who}he fit flight and this one disagree: {'; '.join(parts)}. Fitted on "
            f"{there}; estimated on {here} as fit --effects would (the number a verdict "
            "on this flight quotes)."
        )
    if not said:
        return None
    return Line(
        "disagree",
        " ".join(said) + " One of the flights does not pin the value down, or the effect is "
        "not the same on both: fit on both flights together, or plan a flight that pins it "
        "down (plan --objective effects), before trusting either number.",
    )


def _pinned_here(name: str, fitted: Mapping[str, Any], entry: Mapping[str, Any]) -> list[str]:
    """'rotational_drag's D_z = -0.0074 ± 0.086 N m s^2 as fitted (95 %: 0 to 0.379), 0.12 ±
    0.011 N m s^2 here (95 %: 0.0963 to 0.145)' for each component of ``name`` the fit
    flight did not pin down (``P_pinned`` false) and this flight does, away from the
    model's value (outside this flight's 95 % interval), on an axis where the effect
    explains at least :data:`AXIS_CLAIM` of this flight's error, and not already
    :data:`APART` combined standard errors apart (:func:`_parts` says those)."""
    here = entry.get("estimate")
    if not isinstance(here, Mapping):
        return []
    out = []
    for key, i, label, u in _components(fitted, entry, "_pinned"):
        pinned = [get_path(d, f"{key}_pinned", i) for d in (fitted, here)]
        got = _apart(fitted, here, key, i)
        if pinned != [False, True] or got is None or got[4] > APART:
            continue
        fit_ci, here_ci = (get_path(d, f"{key}_ci95", i) or [None] for d in (fitted, here))
        if len(fit_ci) != 2 or len(here_ci) != 2 or None in (*fit_ci, *here_ci):
            continue
        v, se, d, dse, _ = got
        if here_ci[0] <= v <= here_ci[1]:
            continue  # this flight's interval holds the model's value: nothing to say
        out.append(
            f"{name}'s {label} = {v:.3g} ± {se:.2g}{u} as fitted (95 %: {fit_ci[0]:.3g} "
            f"to {fit_ci[1]:.3g}), {d:.3g} ± {dse:.2g}{u} here (95 %: {here_ci[0]:.3g} to "
            f"{here_ci[1]:.3g})"
        )
    return out


def pinned_here_line(tree: Mapping[str, Any]) -> Line | None:
    """The models' effect parameters their fit flight did not pin down and this flight
    does (:func:`_pinned_here`; a later model's only where the estimate was made with its
    own set, as :func:`disagree_line`): the model holds a value the fit flight could not
    check (own tune draw own-inertia 12: a drag's D_z fitted on a steps flight that
    hardly yaws, -0.007 in [0, 0.38] N m s^2, pinned at 0.12 here, where the z error
    kept 0.51 rad/s^2 RMS and the verdict said "Nothing missing"; a new user's
    Crazyflie motor lag, 15.5 ms as fitted and 81 ms here, was said of the lag model
    evaluated alone, not beside the model it was added to); None when there is none."""
    models = [m for m in tree.get("models") or [] if isinstance(m, Mapping)]
    learned = get_path(tree, "diagnosis", "learned", default=[]) or []
    entries = {str(e.get("name")): e for e in learned if isinstance(e, Mapping)}
    basis = _names(models[0]) if models else set()
    said = []
    for model in models:
        effects, own = model.get("effects"), _names(model)
        parts = [
            text
            for name, fitted in (effects.items() if isinstance(effects, Mapping) else [])
            if own == basis | {str(name)}  # estimated beside this model's own effects
            and isinstance(fitted, Mapping) and isinstance(entries.get(str(name)), Mapping)
            for text in _pinned_here(str(name), fitted, entries[str(name)])
        ]  # fmt: skip
        if not parts:
            continue
        there = _fit_flight_words(model)
        who = f"With {model.get('name')}, this" if len(models) > 1 else "This"
        said.append(
            f"{who} flight pins down what the fit flight did not: {'; '.join(parts)}. Fitted "
            f"on {there}, which did not pin it down"
        )
    if not said:
        return None
    here = flight_words([n for n in _logs(tree) if n], tree.get("time_window")) or "this flight"
    return Line(
        "pinned_here",
        ". ".join(said) + f"; estimated on {here} as fit --effects would. The model's value "
        "is one the fit flight could not check: fit on both flights together (omavctl fit "
        "takes several logs) to pin it in the model.",
    )


def _fit_flight_words(model: Mapping[str, Any]) -> str:
    """The flight a model entry of the evaluation JSON was fitted on, in words."""
    fit: Mapping[str, Any] = model.get("fit_flight") or {}
    return flight_words(fit.get("logs") or [], fit.get("time_window")) or "its fit flight"


def _names(model: Any) -> set[str]:
    """The effects of a model entry of the evaluation JSON."""
    effects = model.get("effects") if isinstance(model, Mapping) else None
    return {str(n) for n in effects} if isinstance(effects, Mapping) else set()


def _model_parts(
    model: Mapping[str, Any], entries: Mapping[str, Any], first: Any = None
) -> list[tuple[str, str, str]]:
    """(effect, parameter label, words) of every parameter of ``model``'s effects that
    :func:`_parts` finds apart from its estimate in ``entries`` (name -> the
    diagnosis's ``learned`` entry), for the effects whose estimate was made with
    ``model``'s own set: ``first``'s effects, plus the effect where ``first`` lacks it
    (module docstring; ``first`` None: ``model`` is the first)."""
    effects = model.get("effects")
    own, basis = _names(model), _names(model if first is None else first)
    out: list[tuple[str, str, str]] = []
    for name, fitted in effects.items() if isinstance(effects, Mapping) else []:
        if own != basis | {str(name)}:
            continue  # estimated beside other effects than this model's
        if isinstance(fitted, Mapping) and isinstance(entries.get(str(name)), Mapping):
            out += [(str(name), lb, t) for lb, t in _parts(str(name), fitted, entries[str(name)])]
    return out


def disagreeing(tree: Mapping[str, Any], model: int) -> set[tuple[str, str]]:
    """(effect, parameter label, e.g. ``('rotational_drag', 'D_z')``) of every fitted
    parameter of the ``model``-th model that :func:`disagree_line` says disagrees with
    this flight's estimate: a sentence printed with that line need not say it again
    (the worse-axis reason of :mod:`omavctl.diagnose.change` did, with other numbers)."""
    models = tree.get("models") or []
    if not 0 <= model < len(models) or not isinstance(models[model], Mapping):
        return set()
    learned = get_path(tree, "diagnosis", "learned", default=[]) or []
    entries = {str(e.get("name")): e for e in learned if isinstance(e, Mapping)}
    parts = _model_parts(models[model], entries, models[0])
    return {(name, label) for name, label, _ in parts}


def elsewhere_clause(tree: Mapping[str, Any]) -> str:
    """' The command below estimates it on the fit flight (log10, log16), not on this
    one: ...' after the verdict's estimate of a missing effect on this flight, when the
    first model's fit flight (logs or time window) is not the evaluated one; ''
    otherwise or when the file does not say (older files)."""
    fit = get_path(tree, "models", 0, "fit_flight")
    if not isinstance(fit, Mapping) or not fit.get("logs"):
        return ""
    if list(fit.get("logs") or []) == _logs(tree):
        if fit.get("time_window") == tree.get("time_window"):
            return ""
    there = flight_words(fit.get("logs") or [], fit.get("time_window"))
    return (
        f" The command below estimates it on the fit flight ({there}), not on this one: "
        "its value there can differ; evaluated here, the new model says if it does."
    )


def _logs(tree: Mapping[str, Any]) -> list[Any]:
    """The evaluated logs' names, as the evaluation JSON records them."""
    return [get_path(lg, "name") for lg in tree.get("logs") or [] if isinstance(lg, Mapping)]
