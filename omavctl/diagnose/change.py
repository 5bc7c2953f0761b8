"""The before/after change of two or more models or evaluation files, per axis.

How much the error falls when an effect is added, with the reason for any axis
that got worse (a fitted parameter the evaluated log disagrees with), and the
verdict of a report of several evaluations: what the first lacked, every step's
change, the last file's own verdict (:func:`omavctl.diagnose.verdict.verdict`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from itertools import pairwise
from typing import Any

from omavctl.diagnose.activity import finite as _num
from omavctl.diagnose.axis_worse import worse_reason
from omavctl.diagnose.claim_text import not_pinned_names
from omavctl.diagnose.fit_vs_flight import disagreeing
from omavctl.diagnose.horizon_findings import added_rollout_sentence, files_rollout_sentence
from omavctl.diagnose.metrics import quality_flags
from omavctl.diagnose.verdict import verdict
from omavctl.diagnose.verdict_lines import (
    AXES,
    FIRST_FLAGS,
    WORSE_AXIS,
    Line,
    ModelScore,
    _pct,
    _signed,
    get_path,
    physics_rose_clause,
    uncertainty_line,
)

__all__ = [
    "MATERIAL_FALL",
    "change_lines",
    "ordered",
    "reconciled_head",
    "report_verdict",
    "scores_of_files",
    "scores_of_models",
    "verdict_of_models",
]

#: A fall of the model error (sum over axes, same flight) from this fraction up,
#: when effects were added, is measured evidence that they were missing: the first
#: model's "nothing missing" is then not said above it.
MATERIAL_FALL = 0.10


def scores_of_files(evals: Sequence[tuple[Mapping[str, Any], str]]) -> list[ModelScore]:
    """One :class:`ModelScore` per evaluation file: its first model, but the last
    file's last (``--model`` repeated: a new user's ``report base.json both.json``
    compared base.npz with itself, "the model error rises by 0.0 %"), labelled
    'file: model'."""
    out = []
    for i, (tree, label) in enumerate(evals):
        effects = get_path(tree, "models", 0, "effects", default={}) or {}
        rmse = get_path(tree, "metrics", "model", "rmse", default={}) or {}
        physics = get_path(tree, "metrics", "effects", "rmse", default={}) or {}
        models = scores_of_models(tree) if i == len(evals) - 1 and i > 0 else []
        if len(models) > 1:
            out.append(replace(models[-1], label=f"{label}: {models[-1].label}"))
            continue
        out.append(ModelScore(label, tuple(effects), effects, rmse, tree, physics))
    return out


def scores_of_models(tree: Mapping[str, Any]) -> list[ModelScore]:
    """One :class:`ModelScore` per model of one evaluation file (``--model`` repeated)."""
    models = tree.get("models") or []
    by_model = tree.get("metrics_by_model") or [tree.get("metrics") or {}]
    out = []
    for m, metrics in zip(models, by_model, strict=False):
        effects = m.get("effects") or {}
        rmse = get_path(metrics, "model", "rmse", default={}) or {}
        physics = get_path(metrics, "effects", "rmse", default={}) or {}
        name = str(m.get("name", "?"))
        out.append(ModelScore(name, tuple(effects), effects, rmse, tree, physics))
    return out


def ordered(first: ModelScore, last: ModelScore) -> tuple[ModelScore, ModelScore]:
    """(before, after) of two scores: when one's effects are a strict subset of the
    other's, the subset is "before" whatever the order they were given in (the change
    is then always effects *added*); otherwise the given order."""
    if set(last.effects) < set(first.effects):
        return last, first
    return first, last


def _said_below(
    shown: Mapping[str, Any] | None, before: ModelScore, after: ModelScore
) -> frozenset[tuple[str, str]]:
    """The (effect, parameter) pairs whose fitted value and this flight's estimate the
    verdict of ``shown`` (printed with the change lines) says disagree for ``after``'s
    model (:func:`omavctl.diagnose.fit_vs_flight.disagreeing`); empty unless ``after``
    is a model of ``shown`` and ``before`` was evaluated on the same samples (then both
    sentences are about the same parameter on the same pair of flights)."""
    if shown is None or after.tree is not shown or not _same_flight(before, after):
        return frozenset()
    models = shown.get("models") or []
    # the score holds its model's own effects mapping (scores_of_files, scores_of_models)
    at = [i for i, m in enumerate(models) if get_path(m, "effects") is after.effect_params]
    return frozenset(disagreeing(shown, at[0])) if at else frozenset()


def change_lines(
    scores: Sequence[ModelScore],
    name_after: bool = True,
    shown: Mapping[str, Any] | None = None,
) -> list[Line]:
    """Before/after: the first score against the last (ordered by :func:`ordered`),
    per axis, worse axes explained; ``name_after`` names both in the sentence (when
    the line does not say which files it compares); ``shown``: the evaluation whose
    verdict is printed with these lines (its disagree line is not repeated)."""
    if len(scores) < 2:
        return []
    before, after = ordered(scores[0], scores[-1])
    said = _said_below(shown, before, after)
    added = [e for e in after.effects if e not in before.effects]
    removed = [e for e in before.effects if e not in after.effects]
    changes: dict[str, float] = {}
    for a in AXES:
        r0, r1 = _num(before.rmse.get(a)), _num(after.rmse.get(a))
        if r0 and r1 is not None:
            changes[a] = r1 / r0 - 1.0
    if not changes:
        return []
    if added and not removed:
        what = "With " + ", ".join(added) + " added"
        if name_after:
            what += f" ({before.label} → {after.label})"
    else:  # neither holds the other's effects: the given order, said in words
        what = f"From {before.label} to {after.label}"
        what += "".join(
            f", {', '.join(e)} {w}" for e, w in ((added, "added"), (removed, "removed")) if e
        )
    b0 = [v for a in AXES if (v := _num(before.rmse.get(a))) is not None]
    b1 = [v for a in AXES if (v := _num(after.rmse.get(a))) is not None]
    mean = sum(b1) / sum(b0) - 1.0 if b0 and len(b0) == len(b1) and sum(b0) > 0 else None
    if mean is not None:
        verb = "falls" if mean < 0 else "rises"
        text = f"{what}: the model error {verb} by {abs(100 * mean):.1f} % (sum over axes)"
        if abs(mean) < 0.0005:  # a new user read "rises by 0.0 %" beside x +4.8 %, y -16.1 %
            text = f"{what}: the model error summed over the axes is unchanged (within 0.1 %)"
        worse = [a for a, c in changes.items() if c >= 0.0005]  # shown as +0.1 % or more
        if mean < 0.0005 and worse:  # a sum that hides an axis that rose
            text += f", but rises on {' and '.join(worse)}"
    else:
        text = f"{what}: model error"
    text += " — " + ", ".join(f"{a} {_signed(c)}" for a, c in changes.items())
    rose = physics_rose_clause(before, after) if mean is not None and mean < 0 else ""
    lines = [Line("change", text + _other_samples(before, after) + rose + ".")]
    for a, c in changes.items():
        if c > WORSE_AXIS:
            lines.append(
                Line(
                    "change",
                    f"Axis {a} got worse ({_signed(c)}): "
                    f"{worse_reason(before, after, added, a, bool(removed), said)}.",
                )
            )
    return lines


def _other_samples(before: ModelScore, after: ModelScore) -> str:
    """'' when both scores are of the same samples or a file lacks the nominal error;
    else the words that say the change mixes two flights with two models (a new user's
    report of an evaluation on one log and one on two said "the model error falls by
    53.4 %" as if the effect had done it)."""
    n0 = get_path(before.tree, "metrics", "nominal", "rmse", default={}) or {}
    n1 = get_path(after.tree, "metrics", "nominal", "rmse", default={}) or {}
    pairs = [(a, _num(n0.get(a)), _num(n1.get(a))) for a in AXES]
    if any(v0 is None or v1 is None for _, v0, v1 in pairs) or _same_flight(before, after):
        return ""
    nominal = ", ".join(f"{a} {v0:.3g} → {v1:.3g}" for a, v0, v1 in pairs)
    return (
        f"; but not on the same samples (the nominal model's error differs: {nominal} "
        "rad/s²), so this compares the flights as much as the models: evaluate both models "
        "on one flight (evaluate LOG --model A --model B) to compare them"
    )


def _same_flight(before: ModelScore, after: ModelScore) -> bool:
    """Both scores are of the same samples: the same nominal RMSE on every axis."""
    n0 = get_path(before.tree, "metrics", "nominal", "rmse", default={}) or {}
    n1 = get_path(after.tree, "metrics", "nominal", "rmse", default={}) or {}
    pairs = [(_num(n0.get(a)), _num(n1.get(a))) for a in AXES]
    return all(
        a is not None and b is not None and abs(a - b) <= 1e-9 * max(abs(a), 1e-300)
        for a, b in pairs
    )


def _why_missed(tree: Mapping[str, Any], name: str) -> str:
    """Which of the diagnosis' tests ``name`` failed on ``tree``, with their numbers."""
    diag = get_path(tree, "diagnosis", default={}) or {}
    entry = next(
        (
            e
            for e in diag.get("missing_effects") or []
            if isinstance(e, Mapping) and e.get("name") == name
        ),
        None,
    )
    if entry is None:
        return f"{name} was not among its candidates"
    method = diag.get("method") or {}
    ev, need = _num(entry.get("explained_variance")), _num(method.get("min_explained_variance"))
    t, need_t = _num(entry.get("t_value")), _num(method.get("min_t_value"))
    rms, floor = _num(entry.get("contribution_rms")), _num(method.get("min_contribution_rms"))
    refit = _num(entry.get("refit_explained_variance"))
    failed = []
    if ev is not None and need is not None and ev < need:
        failed.append(
            f"it explained {_pct(max(ev, 0.0))} of the held-out error ({_pct(need)} needed)"
        )
    if t is not None and need_t is not None and t < need_t:
        failed.append(f"t value {t:.2g} ({need_t:g} needed)")
    if rms is not None and floor is not None and rms < floor:
        failed.append(f"its part {rms:.2g} rad/s² RMS, below the claim floor {floor:.2g}")
    if entry.get("plausible") is False:
        failed.append("its estimate sat at a bound of its plausible range")
    if refit is not None and refit <= 0:
        failed.append(f"fitted as fit --effects would fit it, it explained {100 * refit:.0f} %")
    if name in not_pinned_names(diag):
        failed.append(
            "estimated on this flight as fit would, its 95 % interval did not exclude the "
            "value at which it is absent: not pinned down"
        )
    return "; ".join(failed) if failed else "it passed its tests but another was preferred"


def reconciled_head(head: Line, before: ModelScore, after: ModelScore) -> Line:
    """``head``, the first sentence of ``before``'s verdict, unless it says nothing is
    missing while ``after`` adds effects and the model error on the same flight falls
    by :data:`MATERIAL_FALL` or more: then one sentence that says what the
    measurement shows, and which of the diagnosis' tests missed the effect."""
    diag = get_path(before.tree, "diagnosis", default={}) or {}
    added = [e for e in after.effects if e not in before.effects]
    if head.key != "missing" or diag.get("missing") or not added:
        return head
    b0 = [_num(before.rmse.get(a)) for a in AXES]
    b1 = [_num(after.rmse.get(a)) for a in AXES]
    if None in b0 or None in b1 or not _same_flight(before, after):
        return head
    fall = 1.0 - sum(v for v in b1 if v is not None) / max(
        sum(v for v in b0 if v is not None), 1e-300
    )
    if fall < MATERIAL_FALL:
        return head
    why = "; ".join(f"{name}: {_why_missed(before.tree, name)}" for name in added)
    text = (
        f"Missing: {', '.join(added)}, measured — with {'it' if len(added) == 1 else 'them'} "
        f"added ({after.label}) the model error on the same flight falls by {100 * fall:.1f} % "
        f"(sum over axes), although this model's diagnosis claimed nothing missing ({why})."
    )
    return Line("missing", text, head.who, None)


def verdict_of_models(tree: Mapping[str, Any]) -> list[Line]:
    """One evaluation's verdict with the before/after change of its models (``--model``
    repeated) after the first sentence, reconciled with it (:func:`reconciled_head`);
    a learned effect a later model adds is not offered again."""
    own = verdict(tree)
    models = scores_of_models(tree)
    if len(models) < 2:
        return own
    before, after = ordered(models[0], models[-1])
    added = {e for e in after.effects if e not in before.effects}
    # the first "missing" sentence, wherever flags put it, is reconciled with the change
    at = next((i for i, ln in enumerate(own) if ln.key == "missing"), 0)
    head = own[at]
    if before is models[0]:  # the diagnosed model is the one the effects were added to
        own[at] = reconciled_head(own[at], before, after)
    # the first model's leading flags say which model they are about (one stood above
    # "The lines below are about ...": docs/real-data-check.md item 16), and so does its
    # own first sentence there ("Missing: com_offset ..." read as the better model's)
    firsts = set(FIRST_FLAGS.values())
    lead = next((i for i, ln in enumerate(own) if ln.key not in firsts), 0)
    lead += 1 if lead == at == 0 and own[0] is head else 0
    own[:lead] = [replace(ln, text=f"With {models[0].label}: {ln.text}") for ln in own[:lead]]
    rest = [ln for ln in own[1:] if not (ln.key in ("learned", "axis") and ln.subject in added)]
    which = Line(
        "change",
        f"The lines below are about {models[0].label} (the first --model), "
        f"{_effects_words(models[0])}.",
    )
    # with three or more models each step's change first (a step that made an axis
    # worse must not hide behind an overall gain, as in report_verdict), then first to last
    steps = pairwise(models) if len(models) > 2 else ()
    changes = [ln for a, b in steps for ln in change_lines([a, b], shown=tree)]
    changes += change_lines(models, shown=tree)
    labels = (models[0].label, models[-1].label)
    rolled = added_rollout_sentence(tree.get("horizons"), labels, len(models) - 1)
    changes += [Line("change", rolled)] if rolled else []
    return [own[0], *changes, *_later_flags(tree, models), which, *rest]


def _later_flags(tree: Mapping[str, Any], models: Sequence[ModelScore]) -> list[Line]:
    """The models after the first that are no better than predicting no acceleration,
    or worse than their own physics, on an axis, or whose band is not to be trusted
    as it is: 'with M: axis z: ...' (the flags of
    :func:`omavctl.diagnose.metrics.quality_flags` were the first model's only:
    docs/real-data-check.md item 13)."""
    by_model = tree.get("metrics_by_model") or []
    out = []
    for score, metrics in zip(models[1:], by_model[1:], strict=False):
        try:
            flags = quality_flags(metrics, [])
        except (KeyError, TypeError):  # an evaluation without the per-model metrics
            flags = []
        for flag in flags:
            if flag["code"] in ("no_better_than_zero", "worse_than_physics"):
                out.append(Line("worse", f"With {score.label}: {flag['message']}"))
        # its band too: "can be trusted" stood for the first model only (a new user's
        # Crazyflie halves: the recommended lag model covered x 82 %, y 85 %)
        band = uncertainty_line({"metrics": metrics}) if isinstance(metrics, Mapping) else None
        if band is not None and not band.text.startswith("Uncertainty can be trusted"):
            said = band.text.removeprefix("Uncertainty ")  # the report titles it so
            out.append(Line("uncertainty", f"With {score.label}, the uncertainty is {said}"))
    return out


def _effects_words(score: ModelScore) -> str:
    """ "with effects a, b" or "with no effects" for one model."""
    return f"with effects {', '.join(score.effects)}" if score.effects else "with no effects"


def report_verdict(evals: Sequence[tuple[Mapping[str, Any], str]]) -> list[Line]:
    """The verdict of a report: one file's own; with several, what each but the last
    lacked, the before/after change per axis (each step when there are three or more,
    then first to last) and the last file's verdict."""
    if not evals:
        return []
    if len(evals) == 1:
        tree = evals[0][0]
        return verdict_of_models(tree)
    last, label1 = evals[-1]
    scores = scores_of_files(evals)
    lines: list[Line] = []

    def step(i: int, j: int) -> list[Line]:
        if ordered(scores[i], scores[j])[0] is scores[j]:
            i, j = j, i
        return [
            Line(ln.key, ln.text, f"{evals[i][1]} → {evals[j][1]}")
            for ln in change_lines([scores[i], scores[j]], name_after=False, shown=last)
        ]

    # each file's first sentence (what it lacked: why the next one was fitted), and
    # with three or more each step's change: a step that made an axis worse must not
    # hide behind an overall gain; then first to last and the last file's verdict
    for i, (tree, label) in enumerate(evals[:-1]):
        own = verdict(tree)
        head = reconciled_head(own[0], scores[i], scores[i + 1])
        lines.append(replace(head, who=label))
        # a warning may lead the file's verdict; what it lacked must still be said;
        # replace() keeps whether a command adds an effect or only tests a look-alike
        lines += [replace(ln, who=label) for ln in own[1:] if ln.key == "missing"]
        # and an effect held back on one axis, with its test command, unless the next
        # file's model holds it (a new user's report dropped the terminal's "Not claimed
        # although it explains 28 % of the y error ...: rotational_drag", a real drag)
        held = set(get_path(evals[i + 1][0], "models", 0, "effects", default={}) or {})
        lines += [
            replace(ln, who=label) for ln in own[1:] if ln.key == "axis" and ln.subject not in held
        ]
        if len(evals) > 2:
            lines += step(i, i + 1)
    lines += step(0, len(evals) - 1)
    if len(scores_of_models(last)) < 2:  # else the last file's own lines roll its models
        lines += _files_rolled(scores[0], scores[-1])
    lines += [replace(ln, who=label1) for ln in verdict_of_models(last)]
    return lines


def _files_rolled(first: ModelScore, last: ModelScore) -> list[Line]:
    """The first-to-last change's rolled-out line of a report of several files on the
    same samples, as one file evaluated with both models gives it
    (:func:`omavctl.diagnose.horizon_findings.files_rollout_sentence`)."""
    before, after = ordered(first, last)
    if not _same_flight(before, after):
        return []
    rolled = files_rollout_sentence(before.tree, after.tree, (before.label, after.label))
    return [Line("change", rolled, f"{before.label} → {after.label}")] if rolled else []
