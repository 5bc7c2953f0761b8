"""Effects a model holds that neither its fit flight nor the evaluated one confirms.

The loop adds what a verdict claims, and a later fit can show that an effect added on
one round's evidence is not there: on a tune draw (own-drag 7, a hidden 0.47-0.54
N m s^2 drag) the first verdict claimed ``inertia_error`` beside the drag, and after
the next round's fit the scale was 1.02, 1.05, 1.15 with every 95 % interval holding 1;
on this flight too. The claims guard would not claim it on either flight, yet the model
keeps it and every later fit command with it (docs/scorecard.md, session 20).

:func:`unconfirmed` names the first model's effects whose statistical 95 % interval
(the one the claims guard reads, :func:`omavctl.diagnose.claims.excludes_null`) holds
the effect's null on every component, both as fitted (the model file) and as estimated
on the evaluated flight (``diagnosis.learned``), into ``diagnosis.unconfirmed``;
:func:`unconfirmed_line` says so from the evaluation JSON with
the command that fits the model without them (``diagnosis.without_command``). The fit
that adds a claim (``diagnosis.fit_command``) left them out from session 21 to 29; since
session 30 it keeps them: their intervals were judged in a model that lacks the claims,
which may be what they stand beside (a new user's ``rotor_interference``, dropped by the
fit that added ``com_offset``, left the model's x error 44 % worse than before; kept, it
was pinned down at 0.26 beside the offset). The next evaluation judges them again, and
when it claims nothing its command is the fit without them.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

from omavctl.diagnose.claims import claimed_rows, excludes_null
from omavctl.diagnose.fit_vs_flight import flight_words
from omavctl.diagnose.verdict_lines import Line, get_path
from omavctl.learn.intervals import interval_span, null_values

__all__ = ["shown_by_actuators", "unconfirmed", "unconfirmed_line"]


def _holds_null(name: str, estimate: Any) -> bool:
    """Every component's interval of ``estimate`` (an estimate's JSON) holds the null;
    False when it has no finite interval."""
    if not isinstance(estimate, Mapping) or not claimed_rows(name, estimate, None):
        return False
    return not excludes_null(name, estimate, None)


def shown_by_actuators(diagnosis: Mapping[str, Any]) -> set[str]:
    """The effects the actuators' own feedback shows (``diagnosis.actuators.shown``): not
    unconfirmed whatever the torque's intervals say. report20 draw 49 (a 120 ms motor
    lag and a 29 ms delay): the torque's T_m intervals held 0 on both flights while the
    logged rotors followed their commands 120 ms late (117 to 122 ms); the verdict said
    fit without motor_lag, and the model that followed it had 3.7x the error."""
    shown = get_path(diagnosis, "actuators", "shown", default={}) or {}
    return {str(n) for n in shown} if isinstance(shown, Mapping) else set()


def unconfirmed(
    effects: Mapping[str, Any], learned: list[Any] | None, needed: Collection[str] = ()
) -> list[tuple[str, Any, Any]]:
    """(name, fitted estimate JSON, this flight's estimate JSON) of each of a model's
    ``effects`` (name -> estimate JSON) whose fitted and evaluated-flight intervals
    (``learned``: the diagnosis's entries) both hold its null on every component; not
    those ``needed`` (fit adds them whatever it is told: the gain of a normalised torque
    command's ``inertia_error``, whose null says nothing)."""
    here = {str(e.get("name")): e.get("estimate") for e in learned or [] if isinstance(e, Mapping)}
    return [
        (str(name), fitted, here[str(name)])
        for name, fitted in effects.items()
        if str(name) not in needed
        and _holds_null(str(name), fitted)
        and _holds_null(str(name), here.get(str(name)))
    ]


def _rows(name: str, estimate: Any) -> str:
    """'scale 0.838 to 1.21, 0.949 to 1.15, 0.587 to 1.72' (the statistical intervals)."""
    by: dict[str, list[str]] = {}
    for param, _, _, (lo, hi) in claimed_rows(name, estimate, None):
        by.setdefault(param, []).append(interval_span(name, param, lo, hi)[0])
    return "; ".join(f"{p} {', '.join(v)}" for p, v in by.items())


def unconfirmed_line(tree: Mapping[str, Any]) -> Line | None:
    """'Not confirmed by either flight: inertia_error — ...' for the first model's
    effects ``diagnosis.unconfirmed`` names (:func:`unconfirmed`, decided once when the
    evaluation was made), with ``diagnosis.without_command``; None when it names none
    (or the file predates it)."""
    names = get_path(tree, "diagnosis", "unconfirmed", default=[]) or []
    model = get_path(tree, "models", 0, default={})
    effects = model.get("effects") if isinstance(model, Mapping) else None
    if not names or not isinstance(effects, Mapping):
        return None
    learned = get_path(tree, "diagnosis", "learned", default=[]) or []
    estimated = {str(e.get("name")): e.get("estimate") for e in learned if isinstance(e, Mapping)}
    found = [(str(n), effects.get(n), estimated.get(n)) for n in names]
    found = [(n, f, h) for n, f, h in found if isinstance(f, Mapping) and isinstance(h, Mapping)]
    if not found:
        return None
    fit = model.get("fit_flight") if isinstance(model.get("fit_flight"), Mapping) else {}
    there = flight_words(fit.get("logs") or [], fit.get("time_window")) or "its fit flight"
    said = []
    for name, fitted, here in found:
        nulls = {f"{float(v.flat[0]):g}" for v in null_values(name).values()}
        said.append(
            f"{name}, whose 95 % intervals hold {' / '.join(sorted(nulls))} (its value without "
            f"the effect) on every component as fitted on {there} ({_rows(name, fitted)}) and on "
            f"this flight ({_rows(name, here)})"
        )
    it = "it" if len(found) == 1 else "them"
    text = (
        f"Not confirmed by either flight: {'; '.join(said)}. The claims guard would not "
        f"claim {it} on either; the model may hold an effect the vehicle lacks."
    )
    if get_path(tree, "diagnosis", "fit_command"):  # the fit that adds the claims keeps it
        text += (
            f" Judged in a model that lacks what is missing, which {it} may stand beside: the "
            f"fit command above keeps {it}, and its model's evaluation judges {it} again. To "
            f"compare now, fit without {it} and evaluate both models on a flight neither saw."
        )
    else:
        text += f" Fit without {it}, and evaluate both models on a flight neither saw."
    return Line("unconfirmed", text, command=get_path(tree, "diagnosis", "without_command"))
