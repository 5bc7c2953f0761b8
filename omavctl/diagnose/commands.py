"""The commands a diagnosis prints: the ``fit`` command that adds a named effect, and
what separates two look-alikes (a ``plan --objective effects`` command for the omav,
words for a vehicle ``plan`` cannot fly). Split from :mod:`omavctl.diagnose.diagnosis`,
which decides what is named; these only say how to act on it.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omavctl.diagnose.verdict import learned_not_modelled
from omavctl.learn.model import ResidualGP

__all__ = [
    "SHOWN_BY",
    "effect_commands",
    "fit_command",
    "separate_command",
    "separate_flight",
    "separation",
]


def effect_commands(
    diagnosis: dict[str, Any], model_path: str, model: ResidualGP
) -> dict[str, str]:
    """The ``fit`` command that adds each effect the diagnosis names (missing, learned
    and claimed, those the top one is ambiguous with, held back because their interval
    holds their null, by the noise floor or by the refit test, learned but not
    modelled), by effect name, in that order."""
    top = (diagnosis.get("missing") or [None])[0]
    entry: dict[str, Any] = next(
        (e for e in diagnosis.get("missing_effects") or [] if e["name"] == top), {}
    )
    names = [
        *(diagnosis.get("missing") or []),
        *(diagnosis.get("learned_claims") or []),
        *(entry.get("ambiguous_with") or []),
        *(str(e.get("name")) for e in diagnosis.get("not_pinned") or []),
        diagnosis.get("below_noise"),
        diagnosis.get("refit_rejected"),
        *learned_not_modelled(diagnosis, list(model.effects)),
    ]
    out: dict[str, str] = {}
    for name in names:
        if name and name not in out and name not in model.effects:
            out[str(name)] = fit_command(model_path, model, str(name))
    return out


def separate_command(diagnosis: dict[str, Any], model_path: str) -> str | None:
    """The commands that plan a flight telling the top missing effect from the
    look-alikes it is ambiguous with (``plan --objective effects`` on a figure-8
    task), None when it has none.

    Both files go beside the model, named after it (``M.fig8.csv``, the task, and
    ``M.separate.csv``, the planned flight), never into the directory the user runs
    the command from, where ``fig8.csv`` or ``next.csv`` may be the user's own files
    (``task`` and ``plan`` replace an existing ``--out``).
    """
    from omavctl.base.shell import display_path, shell_join

    top = (diagnosis.get("missing") or [None])[0]
    entry: dict[str, Any] = next(
        (e for e in diagnosis.get("missing_effects") or [] if e["name"] == top), {}
    )
    alike = [str(n) for n in entry.get("ambiguous_with") or []]
    if not top or not alike:
        return None
    names = ",".join([str(top), *alike])
    model = display_path(model_path)
    stem = str(Path(model).with_suffix(""))
    fig8, out = f"{stem}.fig8.csv", f"{stem}.separate.csv"
    task = shell_join(["omavctl", "task", "fig8", "--out", fig8])
    words = ["plan", "--task", fig8, "--model", model, "--objective", "effects"]
    plan = shell_join(["omavctl", *words, "--effects", names, "--out", out])
    return f"{task} && {plan}"


#: Where an effect shows (what a flight must vary), in words: the flight that tells
#: look-alikes apart varies what one responds to and the other does not.
SHOWN_BY = {
    "rotational_drag": "fast sustained body rates (its torque grows with the rate squared)",
    "com_offset": "throttle changes, in roll and pitch only (its torque is r × thrust)",
    "inertia_error": "large angular accelerations",
    "gyro_bias": "level hover and slow turns (a constant rate offset)",
    "servo_lag": "fast tilt-servo moves",
    "motor_lag": "fast command steps or a sweep to high frequency (a lag's phase levels off)",
    "command_delay": "a sweep over several frequencies (a delay's phase grows with frequency)",
    "rotor_interference": "a wide range of arm tilts",
    "thrust_curve": "a wide range of throttle",
    "motor_loss": "throttle changes, in yaw too (a weak motor also unbalances the yaw moment)",
    "battery_sag": "varied throttle over a long stretch of the battery",
    "drag_moment": "changes of horizontal speed (the rotors' drag follows the velocity)",
    "arm_thrust": "sideways pushes that tilt the arms, in yaw too (an arm's extra thrust "
    "then turns the vehicle)",
}


def separate_flight(diagnosis: dict[str, Any], why_not: str) -> str | None:
    """In words, the flight that would tell the top missing effect from its look-alikes
    where ``plan`` cannot fly the vehicle (``why_not``, e.g. "plan flies only the
    omav"); None when it has none."""
    top = (diagnosis.get("missing") or [None])[0]
    entry: dict[str, Any] = next(
        (e for e in diagnosis.get("missing_effects") or [] if e["name"] == top), {}
    )
    names = [str(n) for n in [top, *(entry.get("ambiguous_with") or [])] if n]
    if len(names) < 2:
        return None
    parts = [f"{n} shows in {SHOWN_BY[n]}" for n in names if n in SHOWN_BY]
    text = f"plan cannot design the flight that tells them apart ({why_not})"
    return f"{text}; fly one where they differ: {'; '.join(parts)}." if parts else f"{text}."


def separation(diagnosis: dict[str, Any], model_path: str, fixed_rotors: bool) -> dict[str, Any]:
    """The diagnosis' ``separate_command`` (plan flies the omav) or, for a vehicle of
    fixed rotors that plan cannot fly, ``separate_flight``: that flight in words."""
    if fixed_rotors:
        why = "plan flies only the omav, not fixed rotors"
        return {"separate_command": None, "separate_flight": separate_flight(diagnosis, why)}
    return {"separate_command": separate_command(diagnosis, model_path)}


def _where(given: str, absolute: str | None) -> str:
    """A file recorded by fit (as given there, and absolute) as typed from here:
    the absolute record when it exists (fit may have run elsewhere), else as given."""
    from omavctl.base.shell import display_path

    if absolute and Path(absolute).exists():
        return display_path(absolute)
    return display_path(given) if Path(given).exists() else given


def _renamed(stem: Path, added: Sequence[str], drop: Sequence[str]) -> Path:
    """The new model's name: ``stem`` with ``+NAME`` for each of ``added`` and ``-NAME``
    for each of ``drop``, where one undoes the other in the name (``m0-rotor_interference``
    with it added back is ``m0``, not ``m0-rotor_interference+rotor_interference``); never
    the model's own name nor an existing file's (``+refit`` then: a model the loop made
    earlier is not overwritten)."""
    base, *ops = re.split(r"(?=[+-][A-Za-z])", stem.name)
    marks = [(op[0], op[1:]) for op in ops]
    for sign, names in (("+", added), ("-", drop)):
        other = "-" if sign == "+" else "+"
        for name in names:
            if (other, name) in marks:
                marks.remove((other, name))
            else:
                marks.append((sign, name))
    name = base + "".join(sign + n for sign, n in marks)
    taken = name == stem.name or stem.with_name(name + ".npz").exists()
    return stem.with_name(name + "+refit" if taken else name)


def fit_command(
    model_path: str, model: ResidualGP, effect: str | Sequence[str], drop: Sequence[str] = ()
) -> str:
    """The ``omavctl fit`` command that refits ``model`` with ``effect`` added (one
    name, or several estimated jointly in one fit) and the effects ``drop`` left out
    (the model's name with ``-NAME`` for each, e.g. ``m0+rotational_drag-inertia_error``).

    Paths are valid from the current directory (the logs and vehicle file that fit
    read, the new model beside ``model_path``) and every word is shell-quoted.
    """
    from omavctl.base.shell import display_path, shell_join

    prov = model.provenance
    sources = [
        _where(str(s.get("path") or s.get("name")), s.get("abspath"))
        for s in prov.get("sources", [])
        if s.get("path") or s.get("name")
    ]
    added = [effect] if isinstance(effect, str) else [e for e in effect if e not in model.effects]
    stem = Path(display_path(model_path)).with_suffix("")
    # the model's effects in the order its name gives them (m0+rotational_drag+inertia_error
    # holds them in the registry's order), then the rest, then the new ones
    named = [e for e in stem.name.split("+")[1:] if e in model.effects]
    effects = [*named, *(e for e in model.effects if e not in named), *added]
    effects = [e for e in effects if e not in drop]
    out = f"{_renamed(stem, added, drop)}.npz"
    parts = ["omavctl", "fit", *sources]
    parts += ["--effects", ",".join(effects)] if effects else []
    parts += ["--out", out]
    kmed = prov.get("kmedoids", {})
    if "points" in kmed:
        parts += ["--points", str(kmed["points"])]
    sg = prov.get("savitzky_golay", {})
    if sg:
        parts += ["--sg-window", str(sg.get("window")), "--sg-order", str(sg.get("order"))]
    if model.features != "wrench":
        parts += ["--features", model.features]
    if "seed" in prov:
        parts += ["--seed", str(prov["seed"])]
    window = prov.get("time_window")
    if window and any(w is not None for w in window):
        lo, hi = window
        parts += [
            "--time-window",
            f"{'' if lo is None else f'{lo:g}'}:{'' if hi is None else f'{hi:g}'}",
        ]
    if prov.get("vehicle_path"):
        parts += ["--vehicle", _where(str(prov["vehicle_path"]), prov.get("vehicle_abspath"))]
    return shell_join(parts)
