"""What the effects objective forecasts for ``fit``'s standard errors after a flight.

The planner's standard errors are white generalised least squares at the GP's training
points (:mod:`omavctl.planning.effects_objective`); ``fit``'s allow for autocorrelated
residuals (a HAC sandwich over every sample, :mod:`omavctl.learn.intervals`) and, for a
lag or a delay found by a 1-D search, for a form that may be wrong. The forecast is the
planner's times a factor:

* **the task flown again**: each parameter's own factor, ``fit``'s standard error over
  the planner's now (the same flight again keeps its residuals' correlation and any
  allowance for the form): on ``make bench-effects`` (3 seeds, a drag and a 30 ms
  delay) fit's standard errors after it were 0.86-1.15x this forecast;
* **the planned flight**: one factor for every parameter, the median of the linear
  effects' own factors over the parameters the fit flight determined (the data's
  information above the prior's); a lag's or a delay's own factor, from its 1-D search
  and its allowance for a form that may be wrong, is used only when no linear effect
  has one. A parameter's own factor does not carry over to a
  flight unlike the fit flight: a drag component the figure-8 left at its prior had a
  factor of 1 (0.08 now, 0.08 from the prior) and the planned flight's fit then gave
  4-15x the forecast; a delay whose interval allowed 213 ms for a lag's form had a
  factor of 37 and the planned flight, which told the forms apart, gave 0.06-0.22x.
  With the median the same seeds gave 0.51-3.3x, two fresh seeds 0.29-1.09x
  (docs/plan-effects.md, "Forecasts against fit").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from omavctl.physics.effects import get_effect
from omavctl.planning.effects_objective import (
    EffectsPrior,
    max_cross_correlation,
    parameter_labels,
)

__all__ = [
    "DETERMINED",
    "STRONG_CORRELATION",
    "correlation_remark",
    "effects_summary",
    "forecast_factors",
    "geometric_mean",
]

#: A parameter the fit flight determined: the planner's standard error now below this
#: fraction of the prior's (the data's information above the prior's).
DETERMINED = 0.5**0.5


def forecast_factors(
    before: np.ndarray, fit_se: np.ndarray, prior_std: np.ndarray, searched: np.ndarray
) -> tuple[np.ndarray, float]:
    """Per parameter (p,) ``fit``'s standard error over the planner's now (at least 1;
    1 where fit has none), and the planned flight's one factor: their median over the
    determined parameters (:data:`DETERMINED`) of the linear effects (``searched``
    (p,) true for a lag's or a delay's), else over every parameter fit measured, 1
    without any."""
    before = np.asarray(before, float)
    fit_se = np.asarray(fit_se, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        own = np.where(np.isfinite(fit_se) & (before > 0), fit_se / before, np.nan)
    measured = np.isfinite(own)
    own = np.maximum(np.where(measured, own, 1.0), 1.0)
    linear = measured & ~np.asarray(searched, bool)
    determined = linear & (before < DETERMINED * np.asarray(prior_std, float))
    pool = own[determined] if determined.any() else own[measured]
    return own, float(np.median(pool)) if pool.size else 1.0


def geometric_mean(values: np.ndarray) -> float:
    """Geometric mean of positive values (nan when empty)."""
    v = np.asarray(values, float)
    return float(np.exp(np.mean(np.log(v)))) if v.size else math.nan


def _finite(values: np.ndarray) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, float).ravel()]


def _headline(result, names: Sequence[str], rel: dict, corr: dict) -> str:
    """The summary's first line: what the flight is expected to do for ``names``.

    "separate" only when the largest cross-effect correlation falls as printed and ends
    below :data:`STRONG_CORRELATION`; a flight that narrows the parameters while
    correlating them more, or leaves them as correlated, says "narrow" and why (a new
    user read "expected to separate and pin down com_offset, rotor_interference" beside
    "largest cross-effect correlation 0.76 now, 0.76 after it").
    """
    separates = (
        len(names) > 1
        and round(corr["after"], 2) < round(corr["before"], 2)
        and corr["after"] < STRONG_CORRELATION
    )
    # "pin down" beside "it does not tell them apart" read as a contradiction: with
    # more than one effect and a correlation that grows, the flight only narrows them
    # a relative standard error above 1 after the flight is not pinned down (a new user:
    # "expected to pin down rotor_interference: ... 2.92 now, 2.26 after it")
    unpinned = not rel["after_forecast"] < 1.0
    pin = "narrow" if unpinned or len(names) > 1 else "pin down"
    kind = f"separate and {'narrow' if unpinned else 'pin down'}" if separates else pin
    line = (
        f"effects: the flight (candidate {result.best}, ranked by --objective "
        f"{result.objective}) is expected to {kind} {', '.join(names)}: relative standard "
        f"error (geometric mean, fit's and its forecasts) {rel['now']:.3g} now, "
        f"{rel['after_forecast']:.3g} after it, {rel['task_forecast']:.3g} after flying the "
        "task again"
    )
    them = "them" if len(names) > 1 else "it"
    if unpinned:
        line += (
            " (not pinned down after it: the standard error stays above the size it is "
            "relative to, the value or, where that is small or not fitted, the effect's "
            "typical size)"
        )
    if rel["task_forecast"] < rel["after_forecast"]:
        line += f" (flying the task again is forecast to narrow {them} more)"
    if len(names) > 1:
        line += (
            f"; largest cross-effect correlation {corr['before']:.2f} now, "
            f"{corr['after']:.2f} after it, {corr['task']:.2f} after the task"
        )
        line += correlation_remark(corr["before"], corr["after"])
    return line


#: A cross-effect correlation from which two effects are hard to tell apart.
STRONG_CORRELATION = 0.7


def correlation_remark(before: float, after: float) -> str:
    """What the largest cross-effect correlation before and after a flight says ('' when
    it falls): only a strong one means the flight does not tell the effects apart."""
    if not after > before:
        if after >= STRONG_CORRELATION:  # falls a little or not at all, stays strong
            return " (still too correlated after it to tell them apart)"
        return ""
    if after >= STRONG_CORRELATION:
        return " (the flight correlates them more: it does not tell them apart)"
    return " (a little more correlated after it, still told apart)"


#: Why a planned flight does not narrow an interval below the spread.
_SPREAD_STAYS = (
    "the rotors' thrust spread as the fit flight passes it on (more of that flight does not "
    "average it away; a flight that excites the effect more passes less of it on: fit on "
    "both flights says how much)"
)


def theta_units(names: Sequence[str]) -> list[str]:
    """The unit of each label of :func:`parameter_labels` ('' for a ``theta`` that is not
    its physical parameter, and for a dimensionless one): a new user read 'not in the
    model (prior ± 0.00195)' without knowing it was seconds."""
    from omavctl.physics.effect_base import Effect

    out: list[str] = []
    for name in names:
        eff = get_effect(name)
        physical = type(eff).to_theta is Effect.to_theta
        for p in eff.parameters:
            out += [p.unit if physical and p.unit != "1" else ""] * p.size
    return out


def _spread(prior: EffectsPrior, size: int) -> np.ndarray:
    """The rotors' thrust spread (size,) beside each standard error (0 where none)."""
    spread = np.zeros(size) if prior.fit_systematic is None else prior.fit_systematic
    return np.nan_to_num(spread, nan=0.0, posinf=0.0)


def _parameter_lines(
    prior: EffectsPrior,
    before: np.ndarray,
    fit_se: np.ndarray,
    forecasts: tuple[np.ndarray, np.ndarray],
    factors: tuple[np.ndarray, float],
    capped: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[str]:
    """One line per parameter: its value and standard error now, the forecasts (p,)
    after the flight and after the task with their factors, the spread beside them;
    then how the forecasts are made. ``capped`` (p,) each: where the factor's forecast
    was above the standard error now and the line shows now's (a new user multiplied
    the planner's 1.76e-05 by ×2.8 and did not get the printed 4.81e-05)."""
    owner = np.concatenate([np.full(get_effect(n).n_theta, n) for n in prior.names])
    spread = _spread(prior, before.size)
    (after, task), (allowance, factor) = forecasts, factors
    cap_after, cap_task = capped if capped is not None else (np.zeros(after.size, bool),) * 2
    lines = []
    units = theta_units(prior.names)
    for i, label in enumerate(parameter_labels(prior.names)):
        u = f" {units[i]}" if units[i] else ""
        now = (
            f"{prior.values[i]:.4g} ± {fit_se[i]:.3g}{u} now (fit's)"
            if owner[i] in prior.fitted and np.isfinite(fit_se[i])
            else f"{prior.values[i]:.4g} ± {before[i]:.3g}{u} now"
            if owner[i] in prior.fitted
            else f"not in the model (prior ± {before[i]:.3g}{u})"
        )
        held = ", no better than now" if cap_after[i] else ""
        held_task = ", no better than now" if cap_task[i] else ""
        lines.append(
            f"  {label}: {now}, ± {after[i]:.3g} after the flight (planner's ×{factor:.2g}"
            f"{held}), ± {task[i]:.3g} after the task (×{allowance[i]:.2g}{held_task})"
            + (f"; ± {spread[i]:.3g} spread beside each: {_SPREAD_STAYS}" if spread[i] > 0 else "")
        )
    if not np.isfinite(fit_se).any():  # nothing fitted to calibrate the planner's against
        lines.append(
            "  (forecasts: the planner's white linearisation, ×1, uncalibrated: no effect "
            "planned for is fitted in the model with a standard error that says how far it "
            "is off, and fit's "
            "have been several-fold larger (6–8x for a centre-of-mass offset on a figure-8, "
            "docs/plan-effects.md): read them as lower bounds)"
        )
        return lines
    lines.append(
        "  (forecasts of fit's standard errors: the planner's white linearisation times "
        "fit's allowance for autocorrelation, after the task each parameter's own, after "
        f"the flight the median over the parameters the fit flight determined, ×{factor:.2g}; "
        "never above the standard error now, as a flight adds information ('no better "
        "than now' where the product was above it); a flight unlike the fit flight has "
        "its own: docs/plan-effects.md says how far they held)"
    )
    return lines


def effects_summary(result) -> dict | None:
    """What a plan (:class:`~omavctl.planning.planner.PlanResult`) expects for the
    effects: per parameter the standard errors before, after the chosen flight and
    after flying the task again; geometric-mean relative standard errors and largest
    cross-effect correlations; ``lines`` for the terminal. None without effects numbers.
    """
    prior = result.effects
    if prior is None or result.best < 0 or "effects_se" not in result.metrics:
        return None
    k = result.best
    groups = np.concatenate([np.full(get_effect(n).n_theta, i) for i, n in enumerate(prior.names)])
    before = prior.standard_errors(prior.information)
    after, task = result.metrics["effects_se"][k], result.task_metrics["effects_se"]
    rel = {
        "before": geometric_mean(before / prior.scale),
        "after": float(result.metrics["effects_rel_se"][k]),
        "task": float(result.task_metrics["effects_rel_se"]),
    }
    corr = {
        "before": float(max_cross_correlation(prior.information, groups)),
        "after": float(result.metrics["effects_correlation"][k]),
        "task": float(result.task_metrics["effects_correlation"]),
    }
    labels = parameter_labels(prior.names)
    owner = np.concatenate([np.full(get_effect(n).n_theta, n) for n in prior.names])
    fit_se = prior.fit_stderr if prior.fit_stderr is not None else np.full(before.size, np.nan)
    std = np.concatenate(
        [np.full(get_effect(n).n_theta, get_effect(n).prior_std) for n in prior.names]
    )
    # fit's standard errors allow for autocorrelated residuals (and a lag's come from its
    # 1-D search over every sample); the planner's are white GLS at the training points,
    # several-fold smaller: the forecasts carry a factor (effects_forecast)
    searched = np.concatenate(  # a lag's or a delay's 1-D search
        [np.full(get_effect(n).n_theta, get_effect(n).search is not None) for n in prior.names]
    )
    allowance, factor = forecast_factors(before, fit_se, std, searched)
    shown_now = np.where(np.isin(owner, prior.fitted) & np.isfinite(fit_se), fit_se, before)
    # a flight adds information: no forecast above what is shown now (a delay not in the
    # model, prior +- 2.02 ms, was forecast +- 3.04 ms after the flight with the factor)
    after_fc = np.minimum(after * factor, shown_now)
    task_fc = np.minimum(task * allowance, shown_now)
    capped = (after * factor > shown_now, task * allowance > shown_now)
    rel.update(
        now=geometric_mean(shown_now / prior.scale),
        after_forecast=geometric_mean(after_fc / prior.scale),
        task_forecast=geometric_mean(task_fc / prior.scale),
    )
    lines = [_headline(result, prior.names, rel, corr)]
    lines += _parameter_lines(
        prior, before, fit_se, (after_fc, task_fc), (allowance, factor), capped
    )
    return {
        "names": list(prior.names),
        "parameters": labels,
        "values": _finite(prior.values),
        "stderr_before": _finite(before),
        "stderr_fit": _finite(fit_se),
        # the planner's own (white GLS at the training points), which rank the candidates
        "stderr_after": _finite(after),
        "stderr_task": _finite(task),
        # what the lines show: the forecasts of fit's standard errors (effects_forecast)
        "stderr_after_forecast": _finite(after_fc),
        "stderr_task_forecast": _finite(task_fc),
        "autocorrelation_factor": _finite(allowance),
        "forecast_factor": factor,
        # the rotors' thrust spread as the fit flight passes it on, beside every standard
        # error above (a flight that excites the effect more passes less of it on)
        "systematic": _finite(_spread(prior, before.size)),
        "relative_stderr": {key: v if math.isfinite(v) else None for key, v in rel.items()},
        "max_correlation": {key: v if math.isfinite(v) else None for key, v in corr.items()},
        "lines": lines,
    }
