"""The verdict of one evaluation, in a few sentences, first.

What is missing (or that nothing is), where the model fails and what the
vehicle was doing there, and whether its uncertainty can be trusted. Used by
``evaluate``'s terminal summary and at the top of the report; works on the
evaluation JSON tree (schema ``omavctl.eval/1``) only, treating missing keys as
empty. This module says what is missing or learned and orders the lines; the
sentence type and the lines on where the model fails, its band, the inputs it
left and the flags are :mod:`omavctl.diagnose.verdict_lines`. The before/after
change of two models or files, and the verdict of a report of several, are
:mod:`omavctl.diagnose.change`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from omavctl.diagnose import claim_text as ct
from omavctl.diagnose.activity import activity
from omavctl.diagnose.activity import finite as _num
from omavctl.diagnose.actuators import actuator_sentence
from omavctl.diagnose.axis_share import axis_held, axis_held_line
from omavctl.diagnose.estimate_text import AXIS_CLAIM, estimate_sentence
from omavctl.diagnose.fit_vs_flight import disagree_line, elsewhere_clause, pinned_here_line
from omavctl.diagnose.given import given_sentence
from omavctl.diagnose.heldout import on_what
from omavctl.diagnose.joint_text import (
    joint_left_words,
    joint_share,
    joint_text,
    linear_words,
    min_explained,
    named_later,
    replaced_text,
    together_words,
)
from omavctl.diagnose.unconfirmed import unconfirmed_line
from omavctl.diagnose.verdict_lines import (
    AXES,
    COVERAGE_MIN,
    FIRST_FLAGS,
    Line,
    ModelScore,
    _pct,
    coverage_of,
    envelope_line,
    excluded_line,
    fails_line,
    flag_lines,
    get_path,
    hold_line,
    uncertainty_line,
)

__all__ = [
    "AXES",
    "COVERAGE_MIN",
    "Line",
    "ModelScore",
    "activity",
    "coverage_of",
    "get_path",
    "learned_not_modelled",
    "verdict",
]


# ------------------------------------------------------------------ missing
def _missing_line(tree: Mapping[str, Any]) -> Line:
    diag = get_path(tree, "diagnosis", default={}) or {}
    missing = [str(m) for m in get_path(diag, "missing", default=[]) or []]
    entries = {str(e.get("name")): e for e in diag.get("missing_effects", []) or []}
    if not missing and (learned := ct.learned_claim_text(diag, on_what(tree))):
        cmd = diag.get("fit_command")
        return Line("missing", learned, command=cmd if isinstance(cmd, str) and cmd else None)
    if not missing:
        threshold = _num(get_path(diag, "method", "min_explained_variance"))
        text = "Nothing missing: no registered effect explains"
        text += f" {_pct(threshold)} or more" if threshold is not None else " a material share"
        text += f" of the model's remaining error {on_what(tree)}."
        quiet, quiet_name = _within_noise(diag, threshold, on_what(tree))
        if quiet:
            text = f"Nothing claimed as missing: {quiet}"
        near = _below_noise(diag)
        test = diag.get("test_command") if near else _quiet_test(tree, quiet_name)
        if near:
            text = f"Nothing claimed as missing: {near}"
            text += given_sentence(diag, str(diag.get("below_noise")))
        elif held := _refit_rejected(diag):
            text, test = f"Nothing claimed as missing: {held[0]}", held[1]
        elif unpinned := ct.not_pinned_names(diag):
            text = f"Nothing claimed as missing.{ct.not_pinned_text(diag)}"
            test = (diag.get("effect_commands") or {}).get(unpinned[0])
        text += actuator_sentence(diag)
        structure = _structure(diag.get("unexplained"))
        if structure:
            text += f" Some structure remains that no registered effect explains: {structure}."
        # nothing is claimed: the command only tests the effect ("Test it with", and
        # ``test`` in the JSON), it does not add a missing one
        cmd = test if isinstance(test, str) and test else None
        return Line("missing", text, command=cmd, test=cmd is not None)
    top = entries.get(missing[0], {})
    ev = _num(top.get("explained_variance"))
    per_axis = top.get("explained_variance_per_axis") or {}
    axes = ", ".join(
        f"{a} {_pct(v)}" for a in AXES if (v := _num(per_axis.get(a))) is not None and v > 0.005
    )
    text = f"Missing: {missing[0]}"
    # an axis whose share is a few per cent is not claimed: its component of the
    # estimate is whatever else that axis's residual holds (the demo's drag: z 2 %,
    # D_z 0.225 with an interval six standard errors from the truth)
    claimed: set[str] | None = {
        a for a in AXES if (v := _num(per_axis.get(a))) is not None and v >= AXIS_CLAIM
    }
    how, every_axis = _how_missing(tree, missing[0], ev, axes)
    text += how
    claimed = None if every_axis else claimed
    text += "."
    said = estimate_sentence(ct.claim_estimate(diag, missing[0]), claimed)
    text += said + (elsewhere_clause(tree) if said else "")
    text += _also_text(diag, missing)
    amb = top.get("ambiguous_with") or []
    if amb:
        text += f" Ambiguous with {', '.join(map(str, amb))} (their signatures look alike)."
    alike = _look_alikes(missing[0])
    if alike:
        text += f" A residual of {missing[0]}'s shape is also left by {alike}."
    text += ct.not_pinned_text(diag)
    text += actuator_sentence(diag)
    cmd = diag.get("fit_command")
    text += given_sentence(diag, missing[0])
    if amb and isinstance(sep := diag.get("separate_command"), str) and sep:
        text += f" To plan a flight that tells them apart: {sep}"
    elif amb and isinstance(sep := diag.get("separate_flight"), str) and sep:
        text += f" {sep[0].upper()}{sep[1:]}"
    return Line("missing", text, command=cmd if isinstance(cmd, str) and cmd else None)


def _how_missing(
    tree: Mapping[str, Any], name: str, ev: float | None, axes: str
) -> tuple[str, bool]:
    """The clause after "Missing: name" and whether it is claimed on every axis: found on
    the held-out flight itself (a linear profile), by the joint selection on the
    physics-only error (the model's own share can be negative where its GP absorbed the
    effect: it is not the claim), or by its share of the model's remaining error."""
    diag = get_path(tree, "diagnosis", default={}) or {}
    weak = ev is None or ev < min_explained(diag)
    linear, joint = linear_words(diag, name), joint_share(diag, name)
    if linear is not None and weak:
        return f" — {linear}", True
    if joint is not None and weak:
        text = (
            f" — estimated from the fit flight as fit --effects would, it removes "
            f"{_pct(joint)} of the squared physics-only error {on_what(tree)}"
            f"{joint_left_words(diag, name, _model_effects(tree))}"
        )
        if ev is not None:
            share = f"{_pct(ev)} of" if ev > 0.005 else "none of"  # -2 % reads as a typo
            text += (
                f" (the model's GP has absorbed it: it explains {share} the model's "
                "remaining error)"
            )
        if clause := replaced_text(diag, name):
            text += f"; {clause}"
        return text, True
    if ev is not None:
        text = f" — it explains {_pct(ev)} of the model's remaining error {on_what(tree)}"
        # the total weighs the three axes alike (each in units of its own error): a new
        # user read "22 % (x 2 %, y 72 %, z 2 %)" as a share of the squared error, which
        # the y axis held 94 % of
        return text + (f" (the axes weighted alike: {axes})" if axes else ""), False
    return "", False


def _model_effects(tree: Mapping[str, Any]) -> list[str]:
    """The effects of the evaluation's model (none when it holds several models)."""
    models = tree.get("models")
    if not isinstance(models, list) or len(models) != 1 or not isinstance(models[0], Mapping):
        return []
    effects = models[0].get("effects")
    return [str(n) for n in effects] if isinstance(effects, Mapping | list) else []


def _also_text(diag: Mapping[str, Any], missing: Sequence[str]) -> str:
    """' Also: B, C (...).' for the missing effects after the first, with the joint
    selection's shares, or else how a later step named each (:func:`named_later`: the
    report's ranking scores each effect alone); '' for one missing effect."""
    if len(missing) < 2:
        return ""
    together = joint_text(diag, missing)
    later = [why for name, (_, why) in named_later(diag).items() if name in missing[1:]]
    if later and together == f" ({together_words(diag)})":
        together = f" ({together_words(diag)}; {'; '.join(later)})"
    return f" Also: {', '.join(missing[1:])}{together}."


def _structure(items: Any, most: int = 2) -> str:
    """The first ``most`` items of the diagnosis' ``unexplained`` (strongest first) in
    words, '' when there are none: the verdict says what it refers to, in the terminal
    (which has no Diagnosis section) as in the report."""
    said: list[str] = []
    for it in [i for i in items or [] if isinstance(i, Mapping)][:most]:
        axis = it.get("axis", "?")
        if it.get("kind") == "feature correlation" and (r := _num(it.get("correlation"))):
            said.append(f"the {axis} error correlates with {it.get('feature', '?')} (r = {r:.2f})")
        elif it.get("kind") == "spectral peak" and (f := _num(it.get("frequency_hz"))):
            share = _num(it.get("power_share"))
            part = f", {_pct(share)} of its power" if share is not None else ""
            said.append(f"the {axis} error has a spectral peak at {f:.2g} Hz{part}")
    more = len([i for i in items or [] if isinstance(i, Mapping)]) - len(said)
    if said and more > 0:
        said.append(f"{more} more in the evaluation JSON (diagnosis.unexplained)")
    return "; ".join(said)


def _below_noise(diag: Mapping[str, Any]) -> str:
    """The sentence for the effect the diagnosis holds back only by its noise floor
    (``below_noise``: its part of the error is above the log's noise, but below the
    three times it a claim needs), else ''."""
    name = diag.get("below_noise")
    entries = diag.get("missing_effects", []) or []
    entry: Mapping[str, Any] = next((e for e in entries if e.get("name") == name), {})
    floor = _num(get_path(diag, "method", "min_contribution_rms"))
    noise = _num(get_path(diag, "method", "measurement_noise_std"))
    ev, rms = _num(entry.get("explained_variance")), _num(entry.get("contribution_rms"))
    if not name or floor is None or noise is None or ev is None or rms is None:
        return ""
    return (
        f"{name} would explain {_pct(ev)} of the model's remaining error on held-out "
        f"data, but its part, {rms:.2g} rad/s² RMS, is above the log's noise ({noise:.2g}) "
        f"and below the {floor:.2g} a claim needs (three times it). To test it, fit with it "
        "and compare both models on a flight neither saw."
    )


def _quiet_test(tree: Mapping[str, Any], name: str | None) -> str | None:
    """The command that tests the effect :func:`_within_noise` named, unless the line of
    an effect held back on an axis (:func:`axis_held_line`) prints it."""
    if name is None:
        return None
    diag = get_path(tree, "diagnosis", default={}) or {}
    effects = [str(e) for e in get_path(tree, "models", 0, "effects", default={}) or {}]
    held = axis_held(diag, effects)
    if held and held[0]["name"] == name:
        return None
    command = (diag.get("effect_commands") or {}).get(name)
    return command if isinstance(command, str) and command else None


def _within_noise(
    diag: Mapping[str, Any], threshold: float | None, where: str
) -> tuple[str, str | None]:
    """The sentence for a significant effect that explains a claim's share of the model's
    remaining error but whose part is within the log's own measurement noise ('' for
    none). A new user's figure-8 with a drag the model lacked read "Nothing missing: no
    registered effect explains 15 % or more" while rotational_drag explained 24 % (t
    8.2), its part 0.023 rad/s² RMS beside a noise of 0.029. Returns the sentence and
    the effect's name (('', None) for none)."""
    noise = _num(get_path(diag, "method", "measurement_noise_std"))
    floor = _num(get_path(diag, "method", "min_contribution_rms"))
    if noise is None or floor is None or threshold is None:
        return "", None
    for e in diag.get("missing_effects") or []:
        ev, rms = _num(e.get("explained_variance")), _num(e.get("contribution_rms"))
        if ev is None or rms is None or e.get("missing") is True:
            continue
        if e.get("significant") and e.get("plausible") and ev >= threshold and rms < noise:
            return (
                f"{e.get('name')} explains {_pct(ev)} of the model's remaining error {where}, "
                f"but its part, {rms:.2g} rad/s² RMS, is within the log's own measurement "
                f"noise ({noise:.2g}; a claim needs {floor:.2g}, three times it): too small to "
                "claim from this flight, not shown absent. Fitted with it, a model can still "
                "lower the error: compare both on a flight neither saw."
            ), str(e.get("name"))
    return "", None


def _alternative_lines(tree: Mapping[str, Any]) -> list[Line]:
    """For each effect the top missing one is ambiguous with: the command that fits it
    instead, to compare both on a flight neither saw."""
    diag = get_path(tree, "diagnosis", default={}) or {}
    missing = [str(m) for m in diag.get("missing") or []]
    if not missing:
        return []
    entry: Mapping[str, Any] = next(
        (e for e in _entries(diag, "missing_effects") if e.get("name") == missing[0]), {}
    )
    commands = diag.get("effect_commands") or {}
    out = []
    for alt in map(str, entry.get("ambiguous_with") or []):
        command = commands.get(alt) if isinstance(commands, Mapping) else None
        if isinstance(command, str) and command:
            text = (
                f"To test {alt} instead (its signature looks like {missing[0]}'s), fit with "
                "it and compare both models on a flight neither saw."
            )
            out.append(Line("missing", text, command=command, subject=alt, test=True))
    return out


def _entries(diag: Mapping[str, Any], key: str) -> list[Mapping[str, Any]]:
    """The mappings in the list ``diag[key]`` (an evaluation file may hold anything)."""
    items = diag.get(key)
    return [e for e in items if isinstance(e, Mapping)] if isinstance(items, list) else []


def _refit_rejected(diag: Mapping[str, Any]) -> tuple[str, str | None] | None:
    """The sentence for the effect held back only by the refit test, with the number
    that decided it, and the command that tests it; None when there is none."""
    name = diag.get("refit_rejected")
    entries = _entries(diag, "missing_effects")
    entry: Mapping[str, Any] = next((e for e in entries if e.get("name") == name), {})
    ev, refit = _num(entry.get("explained_variance")), _num(entry.get("refit_explained_variance"))
    if not name or ev is None or refit is None:
        return None
    commands = diag.get("effect_commands") or {}
    text = (
        f"{name} would explain {_pct(ev)} of the model's remaining error on held-out data "
        f"with parameters fitted to that error, but with the parameters fit --effects would "
        f"estimate from the model's training points it explains {100 * refit:.0f} % (the "
        "error would grow): not claimed. To test it, fit with it and compare both models on "
        "a flight neither saw."
    )
    command = commands.get(name) if isinstance(commands, Mapping) else None
    return text, command if isinstance(command, str) and command else None


def learned_not_modelled(diag: Mapping[str, Any], effects: Sequence[str]) -> list[str]:
    """Effects the nominal residual shows (``learned``, claimed there) that the model
    does not hold as physics (not in ``effects``) and that are not named missing: what
    the GP has absorbed, which ``fit --effects`` would make physical and testable."""
    said = [*(diag.get("missing") or []), *(diag.get("learned_claims") or [])]
    named = set(effects) | set(map(str, said)) | set(ct.not_pinned_names(diag))
    return [
        str(e.get("name"))
        for e in diag.get("learned") or []
        if isinstance(e, Mapping) and e.get("missing") is True and e.get("name") not in named
    ]


#: Why a learned effect was not claimed (``diagnosis.learned_held``), in words.
_HELD_WHY = {
    "not_pinned": (
        ": its 95 % interval on this flight holds the value at which it is absent (not "
        "pinned down away from its null)."
    ),
    "no_fall": (
        ": it is pinned down away from its null, but estimated from the fit flight as "
        "fit --effects would, adding it does not lower the held-out physics-only error "
        "enough (the joint selection's test)."
    ),
    "not_shown": (
        ": with the model's effects subtracted (the physics-only error) it no longer "
        "explains a material share of what is left."
    ),
    "look_alike": ": an effect the model holds leaves a residual of the same shape.",
    "fit_flight_not_pinned": (
        ": this flight does not pin it down, and the fit flight, estimated as fit "
        "--effects would, does not either (its 95 % interval holds the value at which it "
        "is absent; the model's training points alone had excluded it):"
    ),
}


def _held_why(diag: Mapping[str, Any], name: str) -> str:
    """Which test held the learned effect ``name`` back (``learned_held``); both, as
    "or", for a file written before the diagnosis said which."""
    held = diag.get("learned_held")
    if not isinstance(held, Mapping):
        return (
            " (not pinned down away from its null, or adding it does not lower the held-out "
            "physics-only error)."
        )
    why = str(held.get(name, "not_shown"))
    if why == "fit_flight_not_pinned":
        est = (diag.get("fit_flight_unpinned") or {}).get(name)
        units = next(
            (e.get("units") for e in diag.get("learned") or [] if e.get("name") == name), None
        )
        there = estimate_sentence({"name": name, "estimate": est, "units": units})
        there = there.replace(" Estimated on this flight as fit would: ", " ", 1)
        return _HELD_WHY[why] + (there if there else " see the fit's own table.")
    return _HELD_WHY.get(why, ".")


def _learned_line(tree: Mapping[str, Any]) -> Line | None:
    """When nothing is missing: the effect the GP has absorbed instead of the physics
    (the nominal residual shows it, the model does not hold it and no effect it holds
    looks alike), with the command that makes it physical and testable."""
    diag = get_path(tree, "diagnosis", default={}) or {}
    if diag.get("missing"):
        return None  # the missing effect's command is the next step
    effects = [str(e) for e in get_path(tree, "models", 0, "effects", default={}) or {}]
    entries = {str(e.get("name")): e for e in diag.get("learned") or [] if isinstance(e, Mapping)}
    remaining = {str(e.get("name")): e for e in _entries(diag, "missing_effects")}
    commands = diag.get("effect_commands") or {}
    for name in learned_not_modelled(diag, effects):
        entry = entries[name]
        if set(map(str, entry.get("ambiguous_with") or [])) & set(effects):
            continue  # what the model's own effects already explain
        ev, rms = _num(entry.get("explained_variance")), _num(entry.get("contribution_rms"))
        if ev is None or rms is None:
            continue
        left = _num(remaining.get(name, {}).get("contribution_rms"))
        text = (
            f"Not modelled as physics: {name}, which the nominal model's residual looks like "
            f"(it explains {_pct(ev)} of it, {rms:.2g} rad/s² RMS"
            + (f"; the model leaves {left:.2g} rad/s² RMS of it" if left is not None else "")
            + "). What the GP learned of it holds only where the fit flight went; fitted as "
            "a physical effect it is tested on every flight."
        )
        command = commands.get(name) if isinstance(commands, Mapping) else None
        # the learned claim's test ran (nothing missing) and did not take it
        unconfirmed = "learned_claims" in diag
        if unconfirmed:
            text += " Not claimed: this flight does not confirm it" + _held_why(diag, name)
        if name in (diag.get("below_noise"), diag.get("refit_rejected")):
            return Line("learned", text + " Its fit command is the one above.", subject=name)
        cmd = command if isinstance(command, str) else None
        return Line("learned", text, command=cmd, subject=name, test=unconfirmed)
    return None


def _look_alikes(name: str) -> str:
    """What else leaves a residual like the registered effect ``name`` ('' if unknown)."""
    from omavctl.physics.effects import EFFECTS

    effect = EFFECTS.get(name)
    return effect.look_alikes if effect is not None else ""


def verdict(tree: Mapping[str, Any]) -> list[Line]:
    """The verdict of one evaluation: missing, where it fails, uncertainty, flags; a
    log the model was fitted on, one far beyond its inputs, or an axis the model does
    not help on is said first."""
    flags = flag_lines(tree)
    first = set(FIRST_FLAGS.values())
    rank = {key: i for i, key in enumerate(dict.fromkeys(FIRST_FLAGS.values()))}
    firsts = sorted((ln for ln in flags if ln.key in first), key=lambda ln: rank[ln.key])
    lines = [*firsts, _missing_line(tree), *_alternative_lines(tree)]
    learned = _learned_line(tree)
    for line in (
        learned,
        axis_held_line(tree, [learned.subject] if learned and learned.subject else []),
        disagree_line(tree),
        pinned_here_line(tree),
        unconfirmed_line(tree),
        fails_line(tree),
        uncertainty_line(tree),
        hold_line(tree),
        envelope_line(tree),
        excluded_line(tree),
    ):
        if line is not None:
            lines.append(line)
    return lines + [ln for ln in flags if ln.key not in first]
