"""Fit commands the diagnosis must not suggest because of the other models given.

``evaluate`` diagnoses its first model. When further models were given on the
command line, a suggested ``omavctl fit ... --effects ...,NAME --out M+NAME.npz``
can be pointless (a later model already has ``NAME``) or harmful (its ``--out``
is one of the given model files, which running it would overwrite).
:func:`withhold_given` drops such commands and records, per effect, the given
model that already has it or would be overwritten (``diagnosis["given"]``), which
the verdict names instead of a command.
"""

from __future__ import annotations

import os
import shlex
from collections.abc import Mapping, Sequence
from typing import Any

from omavctl.diagnose.claim_text import effect_to_test
from omavctl.learn.model import ResidualGP

__all__ = ["given_sentence", "withhold_given"]


def _out_of(command: str) -> str | None:
    """The ``--out`` file of a shell-quoted ``omavctl fit`` command, or None."""
    words = shlex.split(command)
    for i, word in enumerate(words[:-1]):
        if word == "--out":
            return words[i + 1]
    return None


def _same_file(a: str, b: str) -> bool:
    """Whether paths ``a`` and ``b`` name the same file (existing or not)."""
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.abspath(a) == os.path.abspath(b)


def _holder(
    effect: str, command: str, models: Sequence[ResidualGP], paths: Sequence[str]
) -> dict[str, Any] | None:
    """The given model that makes ``command`` (which adds ``effect`` to the first
    model) pointless or harmful, as ``{"model": path, "has_it": bool}``: a later
    model that has ``effect`` (``has_it``), or the model its ``--out`` would
    overwrite; None when there is none."""
    for model, path in zip(models[1:], paths[1:], strict=True):
        if effect in model.effects:
            return {"model": path, "has_it": True}
    out = _out_of(command)
    for path in paths if out is not None else []:
        if _same_file(str(out), path):
            return {"model": path, "has_it": False}
    return None


def withhold_given(
    diagnosis: dict[str, Any], models: Sequence[ResidualGP], paths: Sequence[str]
) -> None:
    """Drop from ``diagnosis`` (in place) every fit command a given model makes
    pointless or would be overwritten by: ``fit_command`` (of the top missing
    effect), ``test_command`` (of :func:`~omavctl.diagnose.claim_text.effect_to_test`)
    and the entries of ``effect_commands``; ``diagnosis["given"]`` maps each such effect to that
    model (``{"model": path as given, "has_it": bool}``, False: the command would
    overwrite it). ``models`` and ``paths``: every model of the
    evaluation, the diagnosed one first."""
    given: dict[str, dict[str, Any]] = {}
    keyed = {"fit_command": (diagnosis.get("missing") or [None])[0]}
    keyed["test_command"] = effect_to_test(diagnosis)
    for key, effect in keyed.items():
        command = diagnosis.get(key)
        if effect and isinstance(command, str):
            holder = _holder(str(effect), command, models, paths)
            if holder is not None:
                given[str(effect)] = holder
                diagnosis[key] = None
    commands = diagnosis.get("effect_commands") or {}
    for effect, command in list(commands.items()):
        holder = _holder(effect, command, models, paths)
        if holder is not None:
            given[effect] = holder
            del commands[effect]
    diagnosis["given"] = given


def given_sentence(diag: Mapping[str, Any], name: str) -> str:
    """Said instead of a fit command when another model given to evaluate already
    has effect ``name``, or when the command would overwrite a given model."""
    held = (diag.get("given") or {}).get(name)
    if not isinstance(held, Mapping):
        return ""
    if held.get("has_it"):
        return f" {held.get('model')}, also given with --model, already has it."
    return (
        f" Its fit command is not shown: its --out would overwrite {held.get('model')}, "
        "given with --model."
    )
