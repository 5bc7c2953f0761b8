"""Section 5 of the report: the diagnosis.

How candidate effects are scored, the effects named missing, the ranking of
every candidate (explained variance, parameters with standard errors, t value,
plausibility, ambiguity), the ``omavctl fit`` command that adds the top one,
the structure no registered effect explains, and what the nominal model's
residual resembles (what the GP has learned, in physical terms).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from omavctl.diagnose.joint_text import named_later
from omavctl.report.document import (
    Block,
    Bullets,
    Cell,
    Code,
    Content,
    Heading,
    Inline,
    Lines,
    Para,
    Span,
    Table,
)
from omavctl.report.numfmt import AXES, axes_of, num, pct, torque_unit_unknown
from omavctl.report.params import (
    _estimates,
    _param_lines,
    entry_parameters,
    fitted_effect_items,
    spread_legend,
)

__all__ = ["diagnosis_section", "fitted_effect_items", "spread_legend"]


def _flag(v: Any) -> str:
    return "yes" if v is True else "no" if v is False else "n/a"


def _part(e: Mapping[str, Any], joint: float | None = None) -> str:
    """The effect's part of the error (RMS) and whether it clears the noise floor; with
    ``joint``, its part of the physics-only error where the joint selection claimed it
    (the floor it cleared: "0.016 (below 3× noise)" alone read as a claim under the
    floor, a new user's demo report)."""
    rms = e.get("contribution_rms")
    if not isinstance(rms, int | float):
        return "n/a"
    text = f"{num(rms, 2)}" + ("" if e.get("above_noise", True) else " (below 3× noise)")
    return text + (f"; {num(joint, 2)} of the physics-only error" if joint is not None else "")


def _candidates_blocks(
    diag: Mapping[str, Any], torque_unknown: bool, later: Mapping[str, tuple[str, str]]
) -> list[Block]:
    """The ranking of the candidate missing effects with its legend ([] without one); of
    the effects the joint selection claimed, their part of the held-out physics-only
    error (rad/s² RMS) beside their part of the model's."""
    entries = diag.get("missing_effects") or []
    if not entries:
        return []
    joint = {
        str(j.get("name")): float(j["contribution_rms"])
        for j in diag.get("joint_steps") or []
        if isinstance(j, Mapping) and str(j.get("name")) in later
        and isinstance(j.get("contribution_rms"), int | float)
    }  # fmt: skip
    return [
        Heading(4, "Candidate missing effects, best first"),
        _ranking_table(entries, torque_unknown, "missing", later=later, joint=joint),
        *(Para(x, note=True) for x in spread_legend(_estimates(entries))),
    ]


def _ranking_table(
    entries: Sequence[Any],
    torque_unknown: bool,
    what: str,
    held: Sequence[str] = (),
    later: Mapping[str, tuple[str, str]] | None = None,
    joint: Mapping[str, float] | None = None,
) -> Table:
    """The ranking of ``entries``, one effect at a time; ``later``: effects a later
    selection step named (:func:`omavctl.diagnose.joint_text.named_later`), marked
    claimed with that step instead of "no"; ``joint``: of those the joint selection
    claimed, their part of the held-out physics-only error (rad/s² RMS)."""
    rows: list[list[Cell]] = []
    for i, e in enumerate(entries):
        if not isinstance(e, Mapping):
            continue
        ev_axis = e.get("explained_variance_per_axis")
        per_axis = (
            Lines(tuple(f"{a} {pct(v)}" for a, v in zip(AXES, axes_of(ev_axis), strict=True)))
            if isinstance(ev_axis, Mapping)
            else "n/a"
        )
        name: tuple[Inline, ...] = (Span(str(e.get("name", "?")), "code"),)
        if e.get("identifiable") is False:
            name = (*name, Span(" (not identifiable)", "em"))
        if str(e.get("name")) in held:
            name = (*name, Span(" (in the model)", "em"))
        missing = e.get("missing")
        rows.append(
            [
                str(i + 1),
                name,
                pct(e.get("explained_variance")),
                per_axis,
                Lines(
                    _param_lines(
                        _shown_parameters(e),
                        e.get("units") or {},
                        torque_unknown,
                        str(e.get("name", "?")),  # the effect, not its cell
                    )
                ),
                num(e.get("t_value"), 3),
                _flag(e.get("significant")),
                _flag(e.get("plausible")),
                _part(e, (joint or {}).get(str(e.get("name")))),
                _claimed_cell(what, missing, (later or {}).get(str(e.get("name")))),
                ", ".join(str(x) for x in e.get("ambiguous_with", []) or []) or "–",
            ]
        )
        if what == "missing":  # the refit test's number decides too: shown where it does
            rows[-1].insert(-2, pct(e.get("refit_explained_variance")))
    columns = [
        "#",
        "effect",
        "explained variance",
        "per axis",
        _parameters_header(entries, what),
        "t value",
        "significant",
        "plausible",
        "its part, rad/s² RMS",
        what,
        "ambiguous with",
    ]
    if what == "missing":
        columns.insert(-2, "explained as fit --effects would fit it")
    return Table(columns=columns, rows=rows, align="rlrrwrlll" + "r" * (what == "missing") + "ll")


#: What a ranking's own fit is, said where its point is shown without an interval.
ALONE_WORDS = "each effect alone: a size of what the GP left, not the vehicle's value"


def _shown_parameters(e: Mapping[str, Any]) -> Mapping[str, Any]:
    """A ranking row's parameters: fit's ``estimate`` with its errors and interval, or,
    without one, the ranking's own fit to the residual (each effect alone) as points
    only. That fit's standard error is of what the GP left, not of the vehicle's value:
    on the Crazyflie it put a motor lag at 21 ± 1.7 ms [17.7, 24.4] beside the verdict's
    66 ms [19, 114] and fit's 63.8 ± 9.7 ms, 25 of its standard errors away (eyes5,
    session 20)."""
    params = entry_parameters(e)
    if e.get("estimate"):
        return params
    derived = ("_stderr", "_ci95", "_pinned", "_systematic", "_ci95_statistical")
    return {k: v for k, v in params.items() if not str(k).endswith(derived)}


def _parameters_header(entries: Sequence[Any], what: str) -> str:
    """The parameters column's header, saying which residual they were fitted to: the
    same effect is quoted from several (the verdict's estimate, the fitted model, this
    ranking) and the numbers differ."""
    rows = [e for e in entries if isinstance(e, Mapping)]
    fit_like = sum(bool(e.get("estimate")) for e in rows)
    on = "the nominal residual" if what == "learned" else "the model's remaining error"
    if not fit_like:
        return f"parameters on {on}, {ALONE_WORDS} (no interval)"
    head = f"parameters on {on}, as fit --effects estimates them: ± std. error [95 % interval]"
    return head if fit_like == len(rows) else f"{head}; the others {ALONE_WORDS}"


def _claimed_cell(what: str, claimed: Any, later: tuple[str, str] | None) -> Cell:
    """MISSING (or LEARNED) where the ranking claims the effect, with the later step's
    words where a later selection step did, else yes/no."""
    if claimed is True:
        return (Span(what.upper(), "strong"),)
    if later is not None:
        return (Span(what.upper(), "strong"), f" ({later[0]})")
    return _flag(claimed)


def _unexplained_items(items: Sequence[Any]) -> list[Content]:
    out: list[Content] = []
    for it in items:
        if not isinstance(it, Mapping):
            continue
        kind = str(it.get("kind", "structure"))
        axis = it.get("axis", "?")
        if kind == "feature correlation":
            out.append(
                f"axis {axis}: correlation {num(it.get('correlation'), 3)} with feature "
                f"{it.get('feature', '?')}"
            )
        elif kind == "spectral peak":
            out.append(
                f"axis {axis}: spectral peak at {num(it.get('frequency_hz'), 3)} Hz "
                f"({pct(it.get('power_share'))} of the power, "
                f"{num(it.get('power_ratio'), 3)}× the median)"
            )
        else:
            rest = ", ".join(f"{k} {_fmt_any(v)}" for k, v in it.items() if k != "kind")
            out.append(f"{kind}: {rest}")
    return out


def _fmt_any(v: Any) -> str:
    return num(v) if isinstance(v, int | float) and not isinstance(v, bool) else str(v)


def diagnosis_section(
    tree: Mapping[str, Any], k: int, label: str, learned_as: str | None = None
) -> list[Block]:
    """The diagnosis of evaluation ``k``: method, missing effects, their ranking, the fit
    command, unexplained structure and what the nominal residual resembles. With
    ``learned_as`` (the label of an earlier file with the same ranking) that last ranking
    is not repeated."""
    blocks: list[Block] = [Heading(3, label, f"diagnosis-{k}")]
    diag = tree.get("diagnosis")
    if not isinstance(diag, Mapping):
        return [*blocks, Para("No diagnosis in this evaluation.", note=True)]
    torque_unknown = torque_unit_unknown(tree)
    method = diag.get("method") or {}
    if method:
        blocks.append(
            Para(
                "Every registered effect not in the model is fitted to the model's remaining "
                f"error and scored on held-out data ({method.get('split', 'held-out blocks')}; "
                f"standard errors: {method.get('standard_errors', 'n/a')}). An effect is "
                "missing when it explains at least "
                f"{pct(method.get('min_explained_variance'))} of the held-out error, its "
                f"estimate is significant (t ≥ {num(method.get('min_t_value'), 3)}) and "
                "physically plausible, its part of the error is at least "
                f"{num(method.get('min_contribution_rms'), 2)} rad/s² RMS (three times the "
                "log's measurement noise: less is not claimed), and fitted as fit --effects "
                "would fit it, it still lowers the error. An effect the GP has absorbed "
                "(so that it explains little of the model's remaining error) is also missing "
                "when, estimated from the fit flight as fit --effects would, it removes at "
                "least 15 % of the physics-only error on the held-out flight, consistently "
                "over its 2 s blocks, the upper end of its part of that error's 95 % "
                "interval at least the same floor (the table's 'joint selection'). Either way "
                "a claim stands only where the 95 % interval of its estimate as the printed "
                "fit command makes it, on the fit flight, excludes the value at which it is "
                "absent: the flight's statistical interval (the rotors' thrust spread, which "
                "fit's interval adds, says what the torque is, not whether it is there)."
            )
        )
    missing = [str(x) for x in diag.get("missing", []) or []]
    later = named_later(diag)
    blocks += _missing_paras(missing, later)
    learned = [str(x) for x in diag.get("learned_claims") or []]
    if learned:  # what the GP learned, confirmed on the held-out flight: claimed
        names = (s for name in learned for s in (Span(name, "strong"), ", "))
        blocks.append(Para(("Learned by the GP, not yet in the physics: ", *names)[:-1]))
    held_back = [e for e in diag.get("not_pinned") or [] if isinstance(e, Mapping)]
    ranked = [*(diag.get("missing_effects") or []), *(diag.get("learned") or [])]
    blocks += _held_paras(
        [e for e in held_back if not e.get("not_physical")], ranked, torque_unknown
    )
    unphysical = [str(e.get("name")) for e in held_back if e.get("not_physical")]
    if unphysical:
        blocks.append(
            Para(
                "Not claimed, not physical (the 95 % interval excludes the value of no effect "
                f"only below the parameter's physical bound): {', '.join(unphysical)}."
            )
        )
    blocks += _candidates_blocks(diag, torque_unknown, later)
    command = diag.get("fit_command")
    if isinstance(command, str) and command:
        top = ", ".join(missing) if missing else (learned or ["the top effect"])[0]
        blocks.append(Heading(4, f"Command that adds {top}"))
        blocks.append(Code(command))
    unexplained = _unexplained_items(diag.get("unexplained") or [])
    blocks.append(Heading(4, "Unexplained structure"))
    if unexplained:
        steps = [
            str(m.get("name")) for m in diag.get("missing_steps") or [] if isinstance(m, Mapping)
        ]
        after = f" with {', '.join(steps)} added" if steps else ""  # the selection's, if any
        blocks.append(
            Para(f"Structure the model's error keeps{after}, which no registered effect explains:")
        )
        blocks.append(Bullets(unexplained))
    else:
        blocks.append(Para("None found (no feature correlation, no spectral peak)."))
    blocks += _learned_blocks(tree, diag, learned_as, torque_unknown)
    blocks += _learned_commands(tree, diag)
    return blocks


def _held_paras(
    held: Sequence[Mapping[str, Any]], ranked: Sequence[Any], torque_unknown: bool
) -> list[Block]:
    """The effects held back as not pinned down, each with the estimate that decided it
    (fit's, as the verdict quotes it): the ranking's intervals fit each effect alone
    to the model's remaining error and may exclude the no-effect value where this
    one does not (inertia_error, scale_y [1.02, 1.04] in the table beside 0.84..1.14)."""
    if not held:
        return []
    parts = []
    for e in held:
        name, est = str(e.get("name")), entry_parameters(e, *ranked)  # flags: ``ranked``'s
        lines = _param_lines(est, e.get("units") or {}, torque_unknown, name) if est else ()
        said = ": cannot be pinned down from this flight"  # the sentence says it once
        words = [x if isinstance(x, str) else x.text for x in lines if isinstance(x, str | Span)]
        text = "; ".join(x.removesuffix(said) for x in words)
        parts.append(f"{name} ({text})" if text else name)
    return [
        Para(
            "Not claimed, cannot be pinned down from this flight: "
            + ", ".join(parts)
            + ". Estimated as fit --effects would, as the verdict quotes it; the table "
            "below fits each effect alone to the model's remaining error, and its "
            "intervals can differ."
        )
    ]


def _missing_paras(missing: Sequence[str], later: Mapping[str, tuple[str, str]]) -> list[Block]:
    """'Missing: A, B, C', and how a later step named those the ranking below, which
    scores each effect alone, does not (:func:`~omavctl.diagnose.joint_text.named_later`)."""
    if not missing:
        return [Para("No registered effect is missing from this model.")]
    out: list[Block] = [
        Para(("Missing: ", *(s for name in missing for s in (Span(name, "strong"), ", ")))[:-1])
    ]
    if later:
        out.append(
            Para(
                "The ranking below scores each effect alone on the model's remaining error; "
                f"named by a later step: {'; '.join(why for _, why in later.values())}."
            )
        )
    return out


def _learned_commands(tree: Mapping[str, Any], diag: Mapping[str, Any]) -> list[Block]:
    """The ``fit`` command of each effect the nominal residual shows that the model does
    not hold as physics: what makes it physical and testable."""
    from omavctl.diagnose.verdict import learned_not_modelled

    effects = [str(e) for e in ((tree.get("models") or [{}])[0].get("effects") or {})]
    commands = diag.get("effect_commands") or {}
    blocks: list[Block] = []
    for name in learned_not_modelled(diag, effects):
        command = commands.get(name) if isinstance(commands, Mapping) else None
        if not isinstance(command, str):
            continue
        if not blocks:
            blocks.append(Heading(4, "Commands that make a learned effect physical"))
            blocks.append(
                Para(
                    "Each learned effect the model does not hold as physics, fitted as one: "
                    "compare both models on a flight neither saw (an effect that only looks "
                    "like the residual, e.g. a look-alike of an effect the model has, will "
                    "not lower the error there)."
                )
            )
        blocks.append(Para((Span(name, "code"), ":")))
        blocks.append(Code(command))
    return blocks


def _order_note(
    learned: Sequence[Any], held: Sequence[str], diag: Mapping[str, Any]
) -> list[Block]:
    """Why an effect the model holds stands below one it does not in the ranking on the
    nominal residual (claimed ones first, then by share): the test it fails (the
    px4tools report listed com_offset, 26 %, above the model's own inertia_error, 42 %,
    with nothing saying why: docs/real-data-check.md item 9); [] when none does."""
    from omavctl.diagnose.axis_share import failed_test

    floor = (diag.get("method") or {}).get("min_explained_variance")
    if not isinstance(floor, int | float):
        return []
    entries = [e for e in learned if isinstance(e, Mapping)]
    said = []
    for i, e in enumerate(entries):
        above = [str(a.get("name")) for a in entries[:i] if str(a.get("name")) not in held]
        if str(e.get("name")) in held and e.get("missing") is not True and above:
            said.append(
                f"{e.get('name')} (in the model) stands below {', '.join(above)}: the order "
                "is the effects that pass every test first, then by share, and "
                f"{e.get('name')} does not pass them here: {failed_test(e, float(floor))}"
            )
    return [Para("; ".join(said) + ".", note=True)] if said else []


def _learned_blocks(
    tree: Mapping[str, Any], diag: Mapping[str, Any], learned_as: str | None, torque_unknown: bool
) -> list[Block]:
    """'What the nominal model's residual resembles': the ranking fitted to the nominal
    residual (``diag["learned"]``, the first model's effects marked, and why one stands
    below an effect the model lacks), or with ``learned_as`` a note that it is the same
    as for that file."""
    learned = diag.get("learned") or []
    held = [str(e) for e in ((tree.get("models") or [{}])[0].get("effects") or {})]
    blocks: list[Block] = []
    if learned and learned_as is not None:
        blocks.append(Heading(4, "What the nominal model's residual resembles"))
        blocks.append(
            Para(
                f"Same as for {learned_as}: this ranking is fitted to the nominal model's "
                "residual on the same logs, so it does not depend on the model.",
                note=True,
            )
        )
    elif learned:
        blocks.append(Heading(4, "What the nominal model's residual resembles"))
        found = [
            str(e.get("name"))
            for e in learned
            if isinstance(e, Mapping) and e.get("missing") is True
        ]
        text = (
            "The same ranking on the nominal model's residual (measured − rigid body): which "
            "physical effects the data shows beyond the nominal model, whatever the model "
            "learned. A high rank is not proof that the effect is present: effects whose "
            "signatures look alike stand in for one another."
        )
        if found:
            text += " Resembles most: " + ", ".join(found) + "."
        blocks.append(Para(text))
        blocks.append(_ranking_table(learned, torque_unknown, "learned", held))
        blocks += [Para(x, note=True) for x in spread_legend(_estimates(learned))]
        blocks += _order_note(learned, held, diag)
    return blocks
