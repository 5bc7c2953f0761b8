"""Why an axis got worse from one model to the next, from what the evaluation files hold.

:func:`worse_reason` is the clause after "Axis z got worse (+42.1 %): " in the change
lines (:func:`omavctl.diagnose.change.change_lines`): what the added effect explained
of that axis, its parameters indistinguishable from 0 or disagreeing with the evaluated
log, a kept effect's parameter the refit moved, and which part of the model (the
refitted effects or the GP) the physics-only error on the same flight says rose.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from omavctl.diagnose.activity import finite as _num
from omavctl.diagnose.estimate_text import null_component
from omavctl.diagnose.verdict_lines import AXES, ModelScore, _pct, _signed, get_path

__all__ = ["DERIVED", "MOVED", "worse_reason"]


def _disagreement(
    key: str,
    axis: str,
    v: float | None,
    se: float | None,
    held: Mapping[str, Any],
    i: int,
    below: str | None = None,
) -> list[str]:
    """A reason when a fitted parameter is more than 2 standard errors (combined) from
    the estimate the evaluated log gave (the diagnosis' ``parameters``); ``below``: the
    effect's name when the verdict's disagree line printed with this one says the same
    parameter on the same flights (``omavctl.diagnose.change._said_below``): the reason
    then points to it instead of saying it a second time with other numbers."""
    d, dse = _num(get_path(held, key, i)), _num(get_path(held, f"{key}_stderr", i))
    if v is None or se is None or d is None or dse is None:
        return []
    z = abs(v - d) / max(math.hypot(se, dse), 1e-300)
    if z <= 2.0:
        return []
    if below is not None:
        return [
            f"{below}'s {key}_{axis} as fitted on the fit flight disagrees with its estimate "
            "on the evaluated log (both, with their standard errors, in the line below that "
            "says the fit flight and this one disagree)"
        ]
    return [
        f"{key}_{axis} is {v:.3g} ± {se:.2g} as fitted on the fit flight but {d:.3g} ± "
        f"{dse:.2g} from the evaluated log, {z:.1f} standard errors apart: the fit flight "
        "did not pin it down (fit on both logs, or plan a flight with plan --objective effects)"
    ]


def worse_reason(
    before: ModelScore,
    after: ModelScore,
    added: Sequence[str],
    axis: str,
    removed: bool = False,
    said: frozenset[tuple[str, str]] = frozenset(),
) -> str:
    """Why ``axis`` got worse from ``before`` to ``after``, from what the files hold;
    ``removed``: ``after`` also lacks effects ``before`` has; ``said``: the (effect,
    parameter) disagreements a line printed with this one gives
    (``omavctl.diagnose.change._said_below``)."""
    i = AXES.index(axis)
    reasons: list[str] = []
    misfit: list[str] = []
    diag = get_path(before.tree, "diagnosis", "missing_effects", default=[]) or []
    learned = get_path(before.tree, "diagnosis", "learned_claims", default=[]) or []
    for name in added:
        entry = next((e for e in diag if isinstance(e, Mapping) and e.get("name") == name), None)
        ev = _num(get_path(entry, "explained_variance_per_axis", axis))
        if ev is not None and ev < 0.05:
            # of the earlier model's remaining error: a GP that had learned the effect
            # leaves it none, though it removes much of the physics-only error
            gp = " (its GP had learned it)" if name in learned else ""
            reasons.append(
                f"{name} explained {_pct(max(ev, 0.0))} of the {axis} error the earlier "
                f"model left{gp}"
            )
        params = after.effect_params.get(name) or {}
        held = get_path(entry, "parameters", default={}) or {}
        for key, vals in params.items():
            if str(key).endswith(DERIVED) or not isinstance(vals, list) or len(vals) != 3:
                continue
            v, se = _num(vals[i]), _num(get_path(params, f"{key}_stderr", i))
            # from absent: 0 for most, 1 for a scale (a new user read "scale_z = 2.45 ±
            # 2.9 is indistinguishable from 0" beside fit's interval [0.716, ∞))
            null = null_component(name, str(key), i)
            null = 0.0 if null is None or not math.isfinite(null) else null
            if v is not None and se is not None and abs(v - null) < 2 * se:
                reasons.append(
                    f"its fitted {key}_{axis} = {v:.3g} ± {se:.2g} is indistinguishable "
                    f"from {null:g}" + (" (absent)" if null != 0.0 else "")
                )
            below = name if (name, f"{key}_{axis}") in said else None
            misfit += _disagreement(key, axis, v, se, held, i, below)
    reasons += _moved(before, after, i)
    part = _which_part(before, after, axis)
    if misfit:  # the effect's own estimate is off: one sentence with the parts' numbers
        return _misfit_reason(misfit, part, axis)
    noise = _num(get_path(before.tree, "diagnosis", "method", "measurement_noise_std"))
    r0, r1 = _num(before.rmse.get(axis)), _num(after.rmse.get(axis))
    if noise and r0 is not None and r1 is not None and max(r0, r1) < 3 * noise:
        reasons.append(
            f"both errors are within {max(r0, r1) / noise:.1f}× the measurement noise "
            f"({noise:.2g} rad/s²)"
        )
    if part is not None:  # the physics-only error says which part rose
        return "; ".join([*reasons, part[1]])
    if not reasons:  # nothing in the files singles out the effect or the GP
        what = "the changed effects" if removed or not added else "the added effect"
        what += "s" if len(added) > 1 and not removed else ""
        return f"the files do not say why: {what} and the refitted GP changed together"
    return f"{'; '.join(reasons)}: the change comes from the refitted GP, not from the effect"


#: The keys of an estimate's JSON that are not parameters.
DERIVED = ("_stderr", "_systematic", "_ci95", "_ci95_statistical", "_pinned")
#: A kept effect's per-axis parameter that the refit moved by more than this fraction
#: of its larger magnitude is named among the reasons an axis got worse.
MOVED = 0.2


def _moved(before: ModelScore, after: ModelScore, i: int) -> list[str]:
    """'the refit moved inertia_error's scale_x -7.91 → -4.39' for each per-axis
    parameter component ``i`` of an effect both models hold that the refit moved by
    more than :data:`MOVED` (a Betaflight fit with com_offset added made x 97 % worse
    and was said to be com_offset's r_x, indistinguishable from 0, while the refit had
    moved the command's gain on x from -0.126 to -0.228)."""
    out = []
    for name in (n for n in after.effects if n in before.effects):
        p0, p1 = before.effect_params.get(name) or {}, after.effect_params.get(name) or {}
        for key, vals in p1.items():
            old = p0.get(key)
            if str(key).endswith(DERIVED) or not isinstance(old, list):
                continue
            if not (isinstance(vals, list) and len(vals) == len(old) == 3):
                continue
            v0, v1 = _num(old[i]), _num(vals[i])
            if v0 is None or v1 is None or abs(v1 - v0) <= MOVED * max(abs(v0), abs(v1)):
                continue
            out.append(f"the refit moved {name}'s {key}_{AXES[i]} {v0:.3g} → {v1:.3g}")
    return out


def _misfit_reason(misfit: Sequence[str], part: tuple[str, str, str] | None, axis: str) -> str:
    """Why ``axis`` got worse when an added effect's fitted parameter disagrees with the
    evaluated log (``misfit``), with which part rose (:func:`_which_part`) in the same
    sentence: the parameter is the cause when the physics-only error rose, a
    by-the-way when the refitted GP made the axis worse (it was said twice before, the
    second time as if it were another finding)."""
    said = "; ".join(misfit)
    if part is None:
        return said
    kind, _, numbers = part
    if kind == "physics":
        return f"the refitted effects made {axis} worse, not the GP ({numbers}), since {said}"
    if kind == "gp":
        return f"the refitted GP made {axis} worse, not the effects ({numbers}), though {said}"
    return f"both the refitted effects and the GP made {axis} worse ({numbers}); {said}"


def _which_part(before: ModelScore, after: ModelScore, axis: str) -> tuple[str, str, str] | None:
    """Which part of the model made ``axis`` worse, from the physics-only error on the
    same flight: the model's error is the physics-only error times the model's error
    relative to it (the GP's part), so the rise splits into the two factors' rises (on
    a log scale). ("physics" | "gp" | "both", the sentence, its numbers alone), None
    when a file lacks the physics-only error."""
    p0, p1 = _num(before.physics.get(axis)), _num(after.physics.get(axis))
    m0, m1 = _num(before.rmse.get(axis)), _num(after.rmse.get(axis))
    if not (p0 and p1 and m0 and m1) or min(p0, p1, m0, m1) <= 0 or m1 <= m0:
        return None
    g0, g1 = m0 / p0, m1 / p1
    share = math.log(p1 / p0) / math.log(m1 / m0)  # of the model error's rise
    verb = "rose" if p1 > p0 else "fell"
    phys = f"the physics-only error on {axis} {verb} {p0:.3g} → {p1:.3g} rad/s²"
    phys += f" ({_signed(p1 / p0 - 1)})"
    gp = f"the model's error relative to it went {g0:.2f}× → {g1:.2f}×"
    numbers = f"{phys} and {gp}"
    if share >= 2 / 3:
        return "physics", f"{numbers}: the refitted effects made {axis} worse, not the GP", numbers
    if share <= 1 / 3:
        return "gp", f"{numbers}: the refitted GP made {axis} worse, not the effects", numbers
    return "both", f"{numbers}: both the refitted effects and the GP made {axis} worse", numbers
