"""What a horizon table says in words: where a model that wins at one step loses later.

Reads the ``horizons`` section of an evaluation (:mod:`omavctl.diagnose.horizons`,
docs/schemas.md) and lists findings ``{code, model, axis, value, message}``:

- ``gp_hurts_long``: the GP lowers the body-rate error at the shortest horizon
  and raises it at the longest (on ``axis``, of model ``model``) by more than
  ``SIGNIFICANT`` standard errors of the paired difference (chunk means of the
  windows' start times, :mod:`omavctl.diagnose.horizons`; a rise within them is
  not called a loss);
- ``gp_worse_long``: the full model's error at the longest horizon is above
  1.05x that of physics + effects;
- ``effects_hurt_long``: the effects lower the error at the shortest horizon and
  raise it at the longest, beyond its standard error (against physics only);
- ``effect_added_hurts_long``: model j (j >= 1) against model 0, physics +
  effects or full model: lower at the shortest horizon, higher at the longest
  beyond its standard error (adding the effect the verdict named, as ``fit
  --effects`` with one more name, wins at one step and loses later);
- ``band_narrow`` and ``band_wide``: the full model's band too narrow at a horizon,
  pooled or on an axis, or on an axis wider than its errors show
  (:mod:`omavctl.diagnose.horizon_band`);
- ``gp_left_out``: the full model's rollouts leave the GP mean out on ``axis``
  (``fit``'s check on held-out rollouts, :mod:`omavctl.learn.rollout_check`;
  one-step predictions keep it);
- ``ranking_changes``: the order of the predictors by the error norm differs
  between the shortest and the longest horizon.
- ``hold_beats_models``: holding the state predicts the body rates better (error norm,
  as printed) than every model at a horizon (``value`` the last such horizon, s).

(``no_windows``, a log without a stretch as long as the longest horizon, comes
from :func:`omavctl.diagnose.horizons.horizon_table` itself.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from omavctl.diagnose.horizon_band import (
    MIN_COVERAGE,
    WIDE_FACTOR,
    band_findings,
    open_loop_narrow,
    wide_factor,
)

__all__ = [
    "LABELS",
    "MIN_COVERAGE",
    "SIGNIFICANT",
    "TOLERANCE",
    "WIDE_FACTOR",
    "added_rollout_sentence",
    "files_rollout_sentence",
    "findings",
    "label",
    "open_loop_narrow",
    "paired_se",
    "wide_factor",
]

#: a longer-horizon rise is a loss only beyond this many standard errors
SIGNIFICANT = 2.0
#: the full model's longest-horizon error may exceed physics + effects by this factor
TOLERANCE = 1.05
LABELS = {
    "naive": "hold the state",
    # as the RMSE table names them: the verdict's "physics-only error" is the model
    # without its GP (nominal + its effects), and a new user read this table's "physics
    # only" (the rigid body alone) as the same thing
    "nominal": "nominal",
    "effects": "nominal + effects",
    "model": "full model",
}
AXES = ("x", "y", "z")


def label(predictor: Mapping[str, Any], n_models: int = 1) -> str:
    """A predictor's name for people; with several models the model's index."""
    text = LABELS.get(str(predictor.get("kind")), str(predictor.get("key")))
    j = predictor.get("model")
    return f"{text} (model {j})" if n_models > 1 and j is not None else text


def _err(row: Mapping[str, Any], axis: str) -> float:
    return float(row["rate_error"][axis])


def paired_se(a: Mapping[str, Any], b: Mapping[str, Any], axis: str) -> float | None:
    """Standard error of the difference b - a of two table entries' mean error on the
    same windows (``axis``: x, y, z or norm), from their chunk means; None without
    them (files written before them) or with fewer than 4 chunks."""
    ca = (a.get("rate_error_chunks") or {}).get(axis)
    cb = (b.get("rate_error_chunks") or {}).get(axis)
    if not ca or not cb or len(ca) != len(cb) or len(ca) < 4:
        return None
    d = [float(y) - float(x) for x, y in zip(ca, cb, strict=True)]
    if not all(math.isfinite(v) for v in d):
        return None
    mean = sum(d) / len(d)
    return math.sqrt(sum((v - mean) ** 2 for v in d) / (len(d) - 1) / len(d))


def _loss(a: Mapping[str, Any], b: Mapping[str, Any], axis: str) -> tuple[bool, str]:
    """Whether b's error is above a's beyond ``SIGNIFICANT`` standard errors (any rise
    without them), and the rise with its standard error in words."""
    rise = _err(b, axis) - _err(a, axis)
    se = paired_se(a, b, axis)
    if se is None:
        return rise > 0, ""
    return rise > SIGNIFICANT * se, f", +{rise:.2g} ± {se:.2g} rad/s"


def _crossings(
    rows: tuple[list[Any], list[Any]], code: str, what: str, tree: Mapping[str, Any]
) -> list[dict[str, Any]]:
    """Axes where the second of ``rows`` (table rows per horizon) beats the first at the
    first horizon and loses at the last, beyond its standard error."""
    out = []
    first, last = tree["seconds"][0], tree["seconds"][-1]
    a_rows, b_rows = rows
    for axis in AXES:
        a0, b0, a1, b1 = (
            _err(a_rows[0], axis),
            _err(b_rows[0], axis),
            _err(a_rows[-1], axis),
            _err(b_rows[-1], axis),
        )
        lost, se_text = _loss(a_rows[-1], b_rows[-1], axis)
        # a change that rounds to nothing at the printed digits is not a change
        same = f"{a0:.3g}" == f"{b0:.3g}" or f"{a1:.3g}" == f"{b1:.3g}"
        if b0 < a0 and lost and not same:
            out.append(
                {
                    "code": code,
                    "axis": axis,
                    "value": b1 / a1 if a1 > 0 else None,
                    "message": f"{axis}: {what} lowers the {first:g} s body-rate error "
                    f"({a0:.3g} -> {b0:.3g} rad/s) but raises it at {last:g} s "
                    f"({a1:.3g} -> {b1:.3g} rad/s{se_text})",
                }
            )
    return out


def _added(tree: Mapping[str, Any], j: int) -> list[dict[str, Any]]:
    """``effect_added_hurts_long`` of model j against model 0 (physics + effects and the
    full model): the effects model j adds win at one step and lose later."""
    table = tree["table"]
    out = []
    for kind, what in (("effects", "nominal + effects"), ("model", "the full model")):
        if kind not in table or f"{kind}_{j}" not in table:
            continue
        rows = (table[kind], table[f"{kind}_{j}"])
        text = f"{what} of model {j} against model 0"
        out += _crossings(rows, "effect_added_hurts_long", text, tree)
    return out


def _left_out(tree: Mapping[str, Any], key: str) -> list[dict[str, Any]]:
    """A ``gp_left_out`` finding per axis whose GP mean the rollouts of ``key`` leave out."""
    pred: Mapping[str, Any] = next((p for p in tree["predictors"] if p["key"] == key), {})
    weights = pred.get("rollout_gp") or {}
    return [
        {
            "code": "gp_left_out",
            "axis": axis,
            "value": float(weights[axis]),
            "message": f"{axis}: the rollouts leave the GP mean out (on held-out rollouts of "
            "the fit flight it did not lower the 0.5 s error significantly); one-step "
            "predictions keep it",
        }
        for axis in AXES
        if axis in weights and float(weights[axis]) == 0.0
    ]


def _model_findings(tree: Mapping[str, Any], j: int | None) -> list[dict[str, Any]]:
    """Findings of one model (its effects and full-model rows)."""
    sfx = "" if not j else f"_{j}"
    table = tree["table"]
    eff, full = f"effects{sfx}", f"model{sfx}"
    if eff not in table or full not in table:
        return []
    left_out = _left_out(tree, full)
    # an axis whose GP mean the rollouts leave out: the GP there cannot raise its error
    gone = {f["axis"] for f in left_out}
    out = [
        f
        for f in _crossings((table[eff], table[full]), "gp_hurts_long", "the GP", tree)
        if f["axis"] not in gone
    ]
    if j is None or j == 0:
        rows = (table["nominal"], table[eff])
        out += _crossings(rows, "effects_hurt_long", "adding the effects", tree)
    else:
        out += _added(tree, j)
    last = tree["seconds"][-1]
    for axis in AXES:
        a, b = _err(table[eff][-1], axis), _err(table[full][-1], axis)
        if b > TOLERANCE * a:
            out.append(
                {
                    "code": "gp_worse_long",
                    "axis": axis,
                    "value": b / a if a > 0 else None,
                    "message": f"{axis}: at {last:g} s the full model's body-rate error "
                    f"({b:.3g} rad/s) is above {TOLERANCE:g}x nominal + effects' ({a:.3g})",
                }
            )
    out += left_out
    out += band_findings(table[full], tree.get("band_sigma", 2.0))
    for f in out:
        f["model"] = 0 if j is None else j
    return out


def _ranking(tree: Mapping[str, Any]) -> list[dict[str, Any]]:
    """A ``ranking_changes`` finding when the order by error norm changes."""
    table, preds = tree["table"], tree["predictors"]
    n_models = 1 + max((p["model"] or 0) for p in preds)

    def shown(p: Mapping[str, Any], i: int) -> float:
        """The error norm as the table prints it (three digits)."""
        return float(f"{float(table[p['key']][i]['rate_error']['norm']):.3g}")

    def order(i: int) -> list[str]:
        """Labels best first; predictors whose printed errors are equal (physics only
        and physics + effects of a model without effects; 0.0334 and 0.0334) are one
        place, joined by ' = '."""
        places: list[tuple[float, list[str]]] = []
        for p in sorted(preds, key=lambda p: shown(p, i)):
            if places and shown(p, i) == places[-1][0]:
                places[-1][1].append(label(p, n_models))
            else:
                places.append((shown(p, i), [label(p, n_models)]))
        return [" = ".join(names) for _, names in places]

    # a change is a pair whose printed order reverses; a printed tie at either end is
    # none (a new user read 'physics only, hold the state' -> 'hold the state, physics
    # only' of two predictors both printed 0.0334 at the first horizon)
    flips = any(
        (shown(a, 0) - shown(b, 0)) * (shown(a, -1) - shown(b, -1)) < 0
        for k, a in enumerate(preds)
        for b in preds[k + 1 :]
    )
    first, last = order(0), order(-1)
    if not flips:
        return []
    s0, s1 = tree["seconds"][0], tree["seconds"][-1]
    return [
        {
            "code": "ranking_changes",
            "model": None,
            "axis": None,
            "value": None,
            "message": f"best to worst at {s0:g} s: {', '.join(first)}; "
            f"at {s1:g} s: {', '.join(last)}",
        }
    ]


def findings(tree: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Every finding of a ``horizons`` section (module docstring), models in order."""
    models = sorted({p["model"] for p in tree["predictors"] if p["model"] is not None})
    out: list[dict[str, Any]] = []
    for j in models:
        found = _model_findings(tree, j)
        if len(models) > 1:  # say whose finding it is (the --model order, from 0)
            for f in found:
                f["message"] = f"model {j}: {f['message']}"
        out += found
    return out + _ranking(tree) + _hold_beats(tree)


def _hold_beats(tree: Mapping[str, Any]) -> list[dict[str, Any]]:
    """``hold_beats_models``: the horizons at which the hold-the-state predictor's
    error norm is below every model's, as printed (a new user's Betaflight and
    Crazyflie windows: 1.45 against 6.76 rad/s at 0.5 s, and no word but a ranking)."""
    table, preds = tree["table"], tree["predictors"]
    if "naive" not in table:
        return []
    others = [p for p in preds if p["key"] != "naive"]
    if not others:
        return []
    n_models = 1 + max((p["model"] or 0) for p in preds)

    def shown(key: str, i: int) -> float:
        return float(f"{float(table[key][i]['rate_error']['norm']):.3g}")

    at = [
        i
        for i in range(len(tree["seconds"]))
        if all(shown("naive", i) < shown(p["key"], i) for p in others)
    ]
    if not at:
        return []
    k = at[-1]
    best = min(others, key=lambda p: shown(p["key"], k))
    when = ", ".join(f"{tree['seconds'][i]:g}" for i in at)
    return [
        {
            "code": "hold_beats_models",
            "model": None,
            "axis": None,
            "value": float(tree["seconds"][k]),
            "message": f"holding the state predicts the body rates better than every model "
            f"at {when} s (at {tree['seconds'][k]:g} s {shown('naive', k):.3g} rad/s against "
            f"{shown(best['key'], k):.3g} for the best, {label(best, n_models)}): rolled out "
            "open loop that far, no model here is worth its prediction on this flight",
        }
    ]


def added_rollout_sentence(horizons: Any, labels: tuple[str, str], j: int) -> str | None:
    """The verdict's word on ``effect_added_hurts_long`` of the full model ``j`` against
    model 0 (``labels``: theirs), or None without one: the one-step change the verdict
    quotes does not hold rolled out. On the Crazyflie halves (``--model base.npz
    --model base+motor_lag.npz``) the verdict said the model error falls 44.8 % while
    the horizons below it said the lag model's 0.5 s body-rate error was 2.6-3x the
    base model's, a line a reader of the verdict alone never saw."""
    if not isinstance(horizons, Mapping):
        return None
    found = [
        f.get("axis")
        for f in horizons.get("findings") or []
        if isinstance(f, Mapping)
        and f.get("code") == "effect_added_hurts_long"
        and f.get("model") == j
        and "the full model" in str(f.get("message", ""))
    ]
    table, secs = horizons.get("table") or {}, horizons.get("seconds") or []
    a_rows, b_rows = table.get("model"), table.get(f"model_{j}")
    axes = [a for a in AXES if a in found]
    if not axes or not a_rows or not b_rows or len(secs) < 2:
        return None
    return _rolled_text(labels, axes, (a_rows, b_rows), secs, table.get("naive"))


def files_rollout_sentence(
    before: Mapping[str, Any], after: Mapping[str, Any], labels: tuple[str, str]
) -> str | None:
    """:func:`added_rollout_sentence` for two evaluation files of the same samples
    (``report before.json after.json``; the caller checks the samples): the full model
    of ``after`` beats ``before``'s at the first horizon and loses at the last beyond
    2 paired standard errors on an axis (their chunk means, so only where both files
    hold them for the same windows). The two-file report said "With motor_lag added:
    the model error falls by 44.8 %" on the Crazyflie halves without it, where the
    one-file report of the same two models said it (eyes6)."""
    hb, ha = before.get("horizons"), after.get("horizons")
    if not isinstance(hb, Mapping) or not isinstance(ha, Mapping):
        return None
    secs = [float(s) for s in hb.get("seconds") or []]
    if len(secs) < 2 or [float(s) for s in ha.get("seconds") or []] != secs:
        return None
    a_rows = (hb.get("table") or {}).get("model")
    b_rows = (ha.get("table") or {}).get("model")
    if not a_rows or not b_rows or len(a_rows) != len(secs) or len(b_rows) != len(secs):
        return None
    try:
        found = _crossings((a_rows, b_rows), "effect_added_hurts_long", "", {"seconds": secs})
        paired = {a for a in AXES if paired_se(a_rows[-1], b_rows[-1], a) is not None}
    except (KeyError, TypeError, ValueError):  # a file this version does not read
        return None
    axes = [f["axis"] for f in found if f["axis"] in paired]
    naive = (ha.get("table") or {}).get("naive")
    return _rolled_text(labels, axes, (a_rows, b_rows), secs, naive) if axes else None


def _rolled_text(
    labels: tuple[str, str], axes: list[str], rows: tuple[Any, Any], secs: Any, naive: Any = None
) -> str:
    """The sentence of :func:`added_rollout_sentence`: ``rows`` the table rows per
    horizon of the model before (``labels[0]``) and after (``labels[1]``); ``naive`` the
    hold-the-state predictor's rows, said when the model after does worse than it at the
    last horizon (a new user read "x 1.97 -> 5.16" without learning that holding the
    state errs 3.68 there)."""
    a_rows, b_rows = rows

    def pair(k: int, axis: str) -> str:
        return f"{axis} {_err(a_rows[k], axis):.3g} → {_err(b_rows[k], axis):.3g}"

    text = (
        f"Rolled out open loop, {labels[1]} does worse than {labels[0]} on "
        f"{', '.join(axes)}, although better one step ahead: the body-rate error at "
        f"{secs[-1]:g} s goes {', '.join(pair(-1, a) for a in axes)} rad/s (at {secs[0]:g} "
        f"s {', '.join(pair(0, a) for a in axes)}; beyond 2 standard errors): the change "
        "above is the one-step angular acceleration's and does not hold that far ahead "
        "(the horizons table; docs/horizons.md)."
    )
    worse = [] if not naive or len(naive) != len(secs) else _worse_than_naive(b_rows, naive, axes)
    if worse:
        # per axis, as the table's per-axis column: its ranking, by the norm over the
        # axes, put holding the state behind the models (a new user read the two as
        # disagreeing)
        text = text[:-1] + (
            f"; there, on those axes, it does worse than holding the state "
            f"({', '.join(worse)} rad/s; the table's ranking is by the norm over the axes)."
        )
    return text


def _worse_than_naive(rows: Any, naive: Any, axes: list[str]) -> list[str]:
    """'x 3.68' per axis of ``axes`` where the last horizon's error of ``rows`` exceeds
    the hold-the-state predictor's (``naive``); [] where a number is missing."""
    out = []
    for a in axes:
        try:
            mine, hold = _err(rows[-1], a), _err(naive[-1], a)
        except (KeyError, TypeError, ValueError, IndexError):
            continue
        if mine is not None and hold is not None and mine > hold:
            out.append(f"{a} {hold:.3g}")
    return out
