"""The verdict's sentence (:class:`Line`) and the lines that say how far a model can be
trusted on one flight: where it fails and what the vehicle was doing, whether its 2σ
band holds the errors, how much of the flight left the inputs it was trained on, the
spans kept out of the metrics and the evaluation's flags.

Split from :mod:`omavctl.diagnose.verdict`, which says what is missing (or learned)
and puts the lines in order; works on the evaluation JSON tree (schema
``omavctl.eval/1``) only, treating missing keys as empty.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from omavctl.diagnose.activity import activity, fails_text
from omavctl.diagnose.activity import finite as _num
from omavctl.diagnose.horizon_findings import open_loop_narrow

__all__ = [
    "AXES",
    "COVERAGE_GOOD",
    "COVERAGE_MIN",
    "COVERAGE_UNDER",
    "ENVELOPE_SHARE",
    "FIRST_FLAGS",
    "STANDS_OUT",
    "Line",
    "ModelScore",
    "coverage_of",
    "envelope_line",
    "excluded_line",
    "fails_line",
    "flag_lines",
    "get_path",
    "hold_line",
    "uncertainty_line",
]

AXES = ("x", "y", "z")
#: Below this fraction of samples within 2 sigma the uncertainty is overconfident.
COVERAGE_MIN = 0.8
#: Above this fraction, with a predicted std far above the error, cautious (underconfident).
COVERAGE_UNDER = 0.995
#: From this fraction up the uncertainty "can be trusted"; between COVERAGE_MIN and
#: it, it is called a little narrow.
COVERAGE_GOOD = 0.9
#: A predicted σ this many times the error is too wide to use (said with the factors).
USELESS_FACTOR = 10.0


@dataclass(frozen=True)
class Line:
    """One sentence of the verdict: ``key`` (missing, learned, change, fails, uncertainty,
    envelope, excluded, flag), its text, which file it is about (``who``, '' for the only one)
    and a command to run (the fit command that adds the missing effect)."""

    key: str
    text: str
    who: str = ""
    command: str | None = None
    #: the effect the sentence is about, when it is about one ('' otherwise)
    subject: str = ""
    test: bool = False  # the command tests a suggestion the flight did not confirm

    def plain(self) -> str:
        """The sentence with its file and command, as one line of text."""
        text = f"{self.who}: {self.text}" if self.who else self.text
        stop = "" if text.endswith((".", ":", "?", "!")) else "."  # after a plan command
        return f"{text}{stop} {self.add_words}: {self.command}" if self.command else text

    @property
    def add_words(self) -> str:
        """'Add it with' ('Add them with': several effects; 'Test it with': unconfirmed;
        'Without it': a model effect neither flight confirms)."""
        return (
            "Without it"
            if self.key == "unconfirmed"
            else "Test it with"
            if self.test
            else "Add them with"
            if " Also: " in self.text
            else "Add it with"
        )


@dataclass(frozen=True)
class ModelScore:
    """A model as the before/after comparison needs it."""

    label: str
    effects: tuple[str, ...]
    effect_params: Mapping[str, Any]
    rmse: Mapping[str, float]
    tree: Mapping[str, Any]
    #: the physics-only (nominal + effects) RMSE per axis on the same flight, when known
    physics: Mapping[str, float] = field(default_factory=dict)


#: A rise of the nominal + effects error on an axis from which a falling model error
#: says it (the GP carries the fall; the refitted effects alone predict worse).
PHYSICS_ROSE = 0.2
#: A model error that rises by more than this on an axis gets its own "Axis z got
#: worse" line (:func:`omavctl.diagnose.change.change_lines`).
WORSE_AXIS = 0.02


def physics_rose_clause(before: ModelScore, after: ModelScore) -> str:
    """'; its nominal + effects error rose on x (+64 %), y (+37 %): the refitted effects
    alone predict worse, the GP carries the fall' when ``after``'s physics-only error is
    at least :data:`PHYSICS_ROSE` above ``before``'s on an axis whose model error did not
    rise by more than :data:`WORSE_AXIS` (a
    new user saw only "the model error falls by 13.5 %" after refitting on a planned
    flight); '' otherwise. An axis whose model error rose too is not the GP's doing
    (a Crazyflie's motor lag: physics x, y -56 %, z +48 %, model z +42 %, was said
    "the GP carries the fall"): its own "Axis z got worse" line says why."""
    rose = {
        a: p1 / p0 - 1.0
        for a in AXES
        if (p0 := before.physics.get(a)) and (p1 := after.physics.get(a)) is not None
        and p1 / p0 - 1.0 >= PHYSICS_ROSE
        and (m0 := _num(before.rmse.get(a))) and (m1 := _num(after.rmse.get(a))) is not None
        and m1 / m0 - 1.0 <= WORSE_AXIS
    }  # fmt: skip
    if not rose:
        return ""
    axes = ", ".join(f"{a} ({_signed(c)})" for a, c in rose.items())
    return (
        f"; its nominal + effects error rose on {axes}: there the refitted effects alone "
        "predict worse, the GP carries the fall"
    )


def get_path(tree: Any, *keys: Any, default: Any = None) -> Any:
    """``tree[k0][k1]...`` or ``default`` when any level is missing."""
    for k in keys:
        if isinstance(tree, Mapping) and k in tree:
            tree = tree[k]
        elif isinstance(tree, list) and isinstance(k, int) and -len(tree) <= k < len(tree):
            tree = tree[k]
        else:
            return default
    return tree


def _pct(v: float) -> str:
    return f"{100 * v:.0f} %"


def _signed(v: float) -> str:
    return f"{100 * v:+.1f} %".replace("-", "−")


# --------------------------------------------------------------- where/why
#: Below this ratio of the worst segment's error to the flight's (its worst axis), no
#: part of the flight stands out: the verdict does not say "Fails most at".
STANDS_OUT = 1.5


def fails_line(tree: Mapping[str, Any]) -> Line | None:
    """Where the model fails most and what the vehicle was doing there; when the worst
    segment's error is under :data:`STANDS_OUT` times the flight's, that nothing stands
    out (a new user read "Fails most at 1.8–2.8 s ..., 1.1× its overall" as a place to
    look at)."""
    text = fails_text(tree)
    if not text:
        return None
    seg = (tree.get("worst_segments") or [{}])[0]
    rmse = seg.get("rmse") or {}
    vals = {a: v for a in AXES if (v := _num(rmse.get(a))) is not None}
    overall = get_path(tree, "metrics", "model", "rmse", default={}) or {}
    axis = max(vals, key=lambda a: vals[a])
    whole = _num(overall.get(axis)) if isinstance(overall, Mapping) else None
    start, end = _num(seg.get("start")), _num(seg.get("end"))
    if not whole or start is None or end is None or vals[axis] >= STANDS_OUT * whole:
        return Line("fails", text)
    return Line(
        "fails",
        f"No part of the flight stands out: the worst segment, {start:.1f}–{end:.1f} s of "
        f"{seg.get('log', '?')} ({activity(seg)}), has {'an' if axis == 'x' else 'a'} {axis} "
        f"error of {vals[axis]:.3g} "
        f"rad/s² RMS, only {vals[axis] / whole:.1f}× its overall.",
    )


def coverage_of(metrics: Mapping[str, Any]) -> dict[str, float]:
    """Per-axis fraction within 2 sigma (key ``coverage`` or ``coverage_2sigma``)."""
    cov = metrics.get("coverage") or metrics.get("coverage_2sigma") or {}
    return {a: v for a in AXES if (v := _num(get_path(cov, a))) is not None}


def _shares(cov: Mapping[str, float], axes: Sequence[str]) -> str:
    """'x 41 %, y 90 %' of the given axes."""
    return ", ".join(f"{a} {_pct(cov[a])}" for a in axes)


def uncertainty_line(tree: Mapping[str, Any]) -> Line | None:
    model = get_path(tree, "metrics", "model", default={}) or {}
    cov = coverage_of(model)
    if not cov:
        return None
    over = [a for a in AXES if a in cov and cov[a] < COVERAGE_MIN]
    std, rmse = model.get("mean_std") or {}, model.get("rmse") or {}
    under = [
        a
        for a in AXES
        if a in cov
        and cov[a] > COVERAGE_UNDER
        and (s := _num(std.get(a))) is not None
        and (r := _num(rmse.get(a))) is not None
        and s > 2 * r
    ]
    shown = _shares(cov, [a for a in AXES if a in cov])
    narrow = [a for a in AXES if a in cov and round(100 * cov[a]) < 100 * COVERAGE_GOOD]
    if over:
        text = (
            f"Uncertainty overconfident on {', '.join(over)}: only "
            f"{_shares(cov, over)} of the samples lie within "
            "the predicted 2σ (95 % expected); do not trust its error bars there"
            + (f" (within 2σ: {shown})." if len(over) < len(cov) else ".")
        )
    elif under:
        text = _cautious_text(under, std, rmse, shown) + (
            f"; a little narrow on {', '.join(narrow)}." if narrow else "."
        )
    elif narrow:
        text = (
            f"Uncertainty a little narrow on {', '.join(narrow)}: "
            f"{_shares(cov, narrow)} of the samples lie within "
            f"the predicted 2σ (95 % expected); use its error bars with care there "
            f"(within 2σ: {shown})."
        )
    hor = open_loop_narrow(tree.get("horizons"))  # the horizon table's band, if narrow
    if not (over or under or narrow):
        ahead = " one step ahead" if hor else ""
        text = f"Uncertainty can be trusted{ahead}: within 2σ {shown} (95 % expected)."
    # a band that holds every sample is wider than needed: allowed (issue 26 accepts a
    # wider band outside the fit inputs), but the user should know
    cautious = [a for a in AXES if a in cov and round(100 * cov[a]) >= 100 and a not in under]
    if cautious:
        text = (  # the shares are in the text already ('x 100 %, y 100 %' said twice)
            f"{text[:-1]}; the band is cautious on {', '.join(cautious)} (100 % inside): "
            "wider than needed."
        )
    return Line("uncertainty", f"{text[:-1]}; {hor}." if hor else text)


def _cautious_text(
    under: Sequence[str], std: Mapping[str, Any], rmse: Mapping[str, Any], shown: str
) -> str:
    """'Uncertainty cautious on x: ...' without its full stop; a band whose predicted σ
    is :data:`USELESS_FACTOR` times the error or more is called too wide to use, with the
    factors (a new user read "cautious ... more than twice the actual error" of a
    Crazyflie band 115x the error)."""
    factors = {a: float(std[a]) / float(rmse[a]) for a in under if float(rmse[a]) > 0}
    if factors and max(factors.values()) >= USELESS_FACTOR:
        each = ", ".join(f"{a} {f:.0f}x" for a, f in factors.items())
        return (
            f"Uncertainty too wide to use on {', '.join(under)}: the predicted σ is {each} "
            f"the actual error (within 2σ: {shown}); its error bars say little here"
        )
    return (
        f"Uncertainty cautious on {', '.join(under)}: the band is wider than needed, "
        f"the predicted σ more than twice the actual error (within 2σ: {shown})"
    )


def hold_line(tree: Mapping[str, Any]) -> Line | None:
    """The horizon table's ``hold_beats_models`` in the verdict: a new user's Betaflight
    report said, under its horizon figure only, that holding the state beat every model
    at every horizon, while its verdict spoke of one-step errors alone."""
    found = (tree.get("horizons") or {}).get("findings") or []
    said = [f for f in found if isinstance(f, Mapping) and f.get("code") == "hold_beats_models"]
    if not said:
        return None
    message = str(said[0].get("message"))
    return Line("horizons", f"Open loop: {message} (the horizon table).")


#: Share of a flight outside the model's training inputs from which the verdict says so.
ENVELOPE_SHARE = 0.25


def envelope_line(tree: Mapping[str, Any]) -> Line | None:
    """How much of the flight left the inputs the model was trained on, and whether
    its band still covers the errors there (``envelope`` of the evaluation)."""
    env = tree.get("envelope")
    if not isinstance(env, Mapping):
        return None
    share = _num(env.get("outside_fraction"))
    if share is None or share < ENVELOPE_SHARE:
        return None
    beyond = env.get("beyond") or {}
    most = ", ".join(
        f"{name} {v:.1f}×" for name, v in list(beyond.items())[:2] if _num(v) is not None
    )
    out, inside = env.get("coverage_outside") or {}, env.get("coverage_inside") or {}
    low = [a for a in AXES if (v := _num(out.get(a))) is not None and v < COVERAGE_MIN]
    where = [f"furthest, in training ranges beyond them: {most}"] if most else []
    unvaried = ", ".join(str(name) for name in env.get("unvaried") or {})
    if unvaried:  # constant in training: no range to measure the distance in
        where.append(f"not varied in training, varied here: {unvaried}")
    text = (
        f"{_pct(share)} of the samples lie outside the inputs the model was trained on "
        f"({'; '.join(where)})"
    )
    flags = tree.get("flags") or []
    far = ("far_outside_training", "underexcited")
    if any(isinstance(f, Mapping) and f.get("code") in far for f in flags):
        return Line("envelope", text + ".")  # no word on a band that far out: the flag's
    if low:
        there = ", ".join(f"{a} {_pct(out[a])}" for a in low)
        here = ", ".join(f"{a} {_pct(v)}" for a in low if (v := _num(inside.get(a))) is not None)
        text += (
            f"; there the 2σ band covers only {there} (inside: {here or 'no samples'}): "
            "the model extrapolates; fly a flight that covers these inputs and fit on both."
        )
    else:
        text += "; its band still covers the errors there."
    return Line("envelope", text)


def excluded_line(tree: Mapping[str, Any]) -> Line | None:
    spans = [s for s in tree.get("excluded_spans") or [] if isinstance(s, Mapping)]
    if not spans:
        return None
    total = sum(
        max((_num(s.get("end")) or 0.0) - (_num(s.get("start")) or 0.0), 0.0) for s in spans
    )
    reasons = sorted({str(s.get("reason", "")) for s in spans if s.get("reason")})
    text = f"Kept out of the metrics: {len(spans)} span(s), {total:.1f} s"
    text += f" ({'; '.join(reasons)})." if reasons else "."
    return Line("excluded", text)


def flag_lines(tree: Mapping[str, Any]) -> list[Line]:
    out = []
    zero = _zero_line(tree.get("flags") or [])
    for flag in tree.get("flags") or []:
        if not isinstance(flag, Mapping) or flag.get("code") in ("overconfident", "out_of_control"):
            continue  # the uncertainty and kept-out sentences say these
        if zero is not None and flag.get("code") == "no_better_than_zero":
            out += [zero] if zero not in out else []
            continue
        message = str(flag.get("message", flag.get("code", "")))
        axis = (
            f"axis {flag['axis']}: " if flag.get("axis") and not message.startswith("axis") else ""
        )
        key = FIRST_FLAGS.get(str(flag.get("code")), "flag")
        out.append(Line(key, f"{axis}{message}"))
    return out


_ZERO = re.compile(
    r"axis (?P<a>[xyz]): the model's error \((?P<m>\S+) rad/s² RMS\) is not below the "
    r"angular acceleration itself \((?P<z>[^)]+)\): (?P<rest>predicting none would do as well.*)",
    re.S,
)


def _zero_line(flags: Sequence[Any]) -> Line | None:
    """The ``no_better_than_zero`` flags of several axes as one line (each axis's
    numbers, the advice once), None for one axis or messages of another form: the same
    long sentence three times over led a Crazyflie verdict."""
    found = [
        _ZERO.fullmatch(str(f.get("message", "")))
        for f in flags
        if isinstance(f, Mapping) and f.get("code") == "no_better_than_zero"
    ]
    parts = [m for m in found if m is not None]
    if len(parts) < 2 or len(parts) < len(found) or len({m["rest"] for m in parts}) > 1:
        return None
    axes = ", ".join(m["a"] for m in parts)
    model = ", ".join(f"{m['a']} {m['m']}" for m in parts)
    itself = ", ".join(f"{m['a']} {m['z']}" for m in parts)
    return Line(
        FIRST_FLAGS["no_better_than_zero"],
        f"axes {axes}: the model's error ({model} rad/s² RMS) is not below the angular "
        f"acceleration itself ({itself}): {parts[0]['rest']}",
    )


#: Flags said before everything else (their line keys): what follows them is not a
#: held-out judgement, or not of a model that belongs to the log.
FIRST_FLAGS = {
    "training_data": "training",
    "underexcited": "underexcited",
    "far_outside_training": "mismatch",
    # a model that does not help on some axis: said before "nothing missing"
    "worse_than_physics": "worse",
    "no_better_than_zero": "worse",
}
