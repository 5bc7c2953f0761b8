"""Effect parameters as text: 'r_x = 0.0155 ± 0.0011 (± 0.0019 spread) m [0.011,
0.02]' with why an interval does not pin its parameter down, the fitted effects of a
model, and what "± spread" means (the report's overview and diagnosis use these).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.estimate_text import unpinned_text
from omavctl.report.document import Content, Span
from omavctl.report.numfmt import AXES, as_list, finite, num

__all__ = ["entry_parameters", "fitted_effect_items", "spread_legend"]


def _unit(unit: str, torque_unknown: bool) -> str:
    """A parameter unit for display ('' for dimensionless)."""
    if unit == "1":
        return ""
    if torque_unknown and "N m" in unit:
        return unit.replace("N m", "[torque unit]")
    return unit


def _param_lines(
    params: Mapping[str, Any], units: Mapping[str, str], torque_unknown: bool, effect: str = ""
) -> tuple[Content, ...]:
    """'name_axis = value ± stderr unit [95 % interval]' per parameter component (with
    why it is not pinned down where ``P_pinned`` says so, in words that follow the
    interval: :func:`omavctl.learn.intervals.unpinned_words`); components
    whose ``excited`` flag is false are left out, and named as such with why they may
    be where the effect says (:attr:`~omavctl.physics.effect_base.Effect.unexcited_why`),
    except those the vehicle does not have (``absent_when_unexcited``: a quad's
    motor_loss l_4 .. l_11)."""
    derived = ("_stderr", "_ci95", "_pinned", "_systematic", "_ci95_statistical")
    # not parameters: the flags and the coefficients the model predicts with
    # (``theta_fitted``, printed as "theta_fitted_x = ..." under r_x before)
    other = ("excited", "stderr_method", "theta_fitted")
    names = [k for k in params if k not in other and not str(k).endswith(derived)]
    values = {k: as_list(params[k]) for k in names}
    excited = params.get("excited")
    total = sum(len(v) for v in values.values())
    if not (isinstance(excited, list) and len(excited) == total):
        excited = [True] * total
    known = _effect(effect)
    if known is not None and known.n_theta == total:
        # per parameter component; idempotent, so a file written before (motor_loss's
        # contrast flags, which hid l_0 as 'not excited') reads alike
        excited = known.excited_parameters(np.asarray(excited, bool)).tolist()
    absent = known.absent_when_unexcited if known is not None else ()
    lines: list[Content] = []
    skipped: list[str] = []
    offset = 0
    for k in names:
        vals = values[k]
        errs = as_list(params.get(f"{k}_stderr", []))
        if len(vals) == 3:
            labels = [f"{k}_{a}" for a in AXES]
        elif len(vals) == 1:
            labels = [str(k)]
        else:
            labels = [f"{k}_{i}" for i in range(len(vals))]
        unit = _unit(str(units.get(k, "")), torque_unknown)
        for i, v in enumerate(vals):
            if not excited[offset + i]:
                if k not in absent:  # a rotor the vehicle lacks is no parameter of it
                    skipped.append(labels[i])
                continue
            err = f" ± {num(errs[i], 2)}" if i < len(errs) else ""
            spread = as_list(params.get(f"{k}_systematic", []))
            if err and i < len(spread) and finite(spread[i]) and spread[i] > 0:
                err += f" (± {num(spread[i], 2)} spread)"
            note = ""
            if i < len(errs) and finite(errs[i]) and finite(v) and errs[i] <= 1e-9 * max(1, abs(v)):
                # the jackknife spread collapses (to 0 or rounding) at a bound of the
                # plausible range, 0 included (drag, lags)
                err, note = "", " (at its bound: no std. error)"
            if not note:
                note = _interval_note(params, k, i, effect)
            lines.append(f"{labels[i]} = {num(v)}{err}{' ' + unit if unit else ''}{note}".rstrip())
        offset += len(vals)
    if skipped:
        why = known.unexcited_why if known is not None else {}
        said = [f"{lb} ({why[lb]})" if lb in why else lb for lb in skipped]
        lines.append(Span(f"not excited: {', '.join(said)}", "em"))
    return tuple(lines)


def _effect(name: str) -> Any:
    """The registered effect ``name``, or None (a name this version does not know)."""
    from omavctl.physics.effects import EFFECTS

    return EFFECTS.get(name)


def fitted_effect_items(
    effects: Mapping[str, Any], torque_unknown: bool, force_unknown: bool = False
) -> list[Content]:
    """One item per effect a model fitted: its parameters ± standard errors and 95 %
    intervals (the model file's ``P``, ``P_stderr``, ``P_ci95``, ``P_pinned``), in the
    units ``fit`` shows for the commands' units (:func:`omavctl.learn.fit_notes.effect_unit`)."""
    from omavctl.learn.fit_notes import effect_unit
    from omavctl.physics.effects import EFFECTS
    from omavctl.vehicle import NORMALISED

    command_units = {
        k: NORMALISED
        for k, unknown in (("torque", torque_unknown), ("force", force_unknown))
        if unknown
    }
    out: list[Content] = []
    for name, params in effects.items():
        if not isinstance(params, Mapping) or name not in EFFECTS:
            continue
        units = {p.name: effect_unit(name, p.unit, command_units) for p in EFFECTS[name].parameters}
        lines = _param_lines(params, units, torque_unknown, name)
        out.append(f"fitted {name}: " + "; ".join(str(x) for x in lines if isinstance(x, str)))
    return out


def spread_legend(param_sets: Sequence[Any]) -> list[str]:
    """What "(± 0.0019 spread)" means, once, where one of ``param_sets`` (effect
    parameter mappings) shows a spread; else nothing."""
    from omavctl.learn.intervals import SPREAD_MEANING

    shown = any(
        isinstance(v, int | float) and finite(v) and v > 0
        for p in param_sets
        if isinstance(p, Mapping)
        for k, vs in p.items()
        if str(k).endswith("_systematic")
        for v in as_list(vs)
    )
    return [SPREAD_MEANING + "."] if shown else []


def _estimates(entries: Sequence[Any]) -> list[Any]:
    """The parameter mappings of ranking ``entries``, as :func:`_ranking_table` shows them."""
    return [entry_parameters(e) for e in entries if isinstance(e, Mapping)]


def entry_parameters(e: Mapping[str, Any], *others: Any) -> Mapping[str, Any]:
    """A ranking entry's parameters as shown: its ``estimate`` (fit's) where it has
    one, else its ``parameters``; with the ``excited`` flags of its own or ``others``'
    ``parameters`` for the same effect where the estimate has none (the flight's
    regressors decide them, not the residual): a quad's r_z, which no force along z
    excites, read 'r_z = 0 m (at its bound: no std. error)'."""
    est = e.get("estimate") or e.get("parameters") or {}
    if not isinstance(est, Mapping) or "excited" in est:
        return est
    for o in (e, *others):
        if isinstance(o, Mapping) and o.get("name") == e.get("name"):
            flags = (o.get("parameters") or {}).get("excited")
            if isinstance(flags, list):
                return {**est, "excited": flags}
    return est


def _interval_note(params: Mapping[str, Any], k: str, i: int, effect: str = "") -> str:
    """' [low, high]' of component i's 95 % interval, and whether it pins it down."""
    ci = as_list(params.get(f"{k}_ci95", []))
    pinned = as_list(params.get(f"{k}_pinned", []))
    if i >= len(ci) or not isinstance(ci[i], list) or len(ci[i]) != 2:
        return ""
    lo, hi = ci[i]
    text = (
        f" [{_ends(lo, hi, effect, k, i)}]"
        if finite(lo) and finite(hi)
        else f" [{float(lo):.3g}, ∞)"  # an inertia scale whose gain is not told from 0
        if finite(lo) and hi is None
        else " [unbounded]"
    )
    values = as_list(params.get(k, []))
    value = values[i] if i < len(values) and finite(values[i]) else None
    if note := _bound_note(effect, k, lo, value):
        text += f" ({note})"
    if i < len(pinned) and pinned[i] is False:
        text += f": {unpinned_text(effect, k, ci[i], i, params)}"
    return text


def _ends(lo: float, hi: float, effect: str, param: str, i: int) -> str:
    """'low, high' with the digits the verdict and ``fit`` print (3 significant, more
    where these print the ends alike or an end as the effect's null that it is not:
    :func:`omavctl.learn.intervals.interval_ends`); 2 digits printed scale [0.957, 1.076]
    as "0.96, 1.1", and two different intervals alike; 'below high' where cut at the
    parameter's physical bound: :func:`omavctl.learn.intervals.interval_span`)."""
    from omavctl.diagnose.estimate_text import null_component
    from omavctl.learn.intervals import interval_span

    span, _ = interval_span(
        effect, param, float(lo), float(hi), null_component(effect, param, i), ", "
    )
    return span


def _bound_note(effect: str, param: str, low: Any, value: Any = None) -> str:
    """'cut at T_m ≥ 0' where the interval ends at the parameter's physical bound (and
    '; the estimate is below it' where ``value`` is)."""
    from omavctl.learn.intervals import bound_note

    return bound_note(effect, param, float(low), value) if finite(low) else ""
