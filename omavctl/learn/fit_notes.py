"""What ``fit``'s summary says about its effects and command units, in words.

:func:`effect_unit` is also how the CLI shows a parameter's unit when the
commands are normalised.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.learn.effect_fit import GAIN_EFFECT, EffectFit, torque_gain
from omavctl.learn.effect_search import SearchResult
from omavctl.learn.intervals import Z95
from omavctl.physics.effects import get_effect
from omavctl.vehicle import NORMALISED, Vehicle

__all__ = ["actuator_notes", "effect_notes", "effect_unit", "search_notes", "unit_notes"]


def effect_unit(name: str, unit: str, command_units: Mapping[str, str]) -> str:
    """The unit of a parameter of effect ``name`` for display, given the command units.

    With a normalised torque command, ``N m`` becomes ``[torque unit]`` (as in
    the report); ``com_offset``'s ``r`` (a torque per force) becomes
    ``[torque unit]/N``, ``N m/[force unit]`` or ``[torque unit]/[force unit]``;
    ``drag_moment``'s ``h`` (a torque per *measured* force, N) ``[torque unit]/N``.
    A time constant or a delay stays in s: the rotors lag in time whatever unit their
    command is logged in. (It was shown "s (x torque gain)": the form the model
    predicts with, ``lag(tau, T) + theta tau``, gives a value that scales with the
    command's unit to first order, T x gain: 9.6 ms at gain 0.2 and 213 ms at gain 5
    for a simulated 50 ms motor lag, where the gain on the timed torque, ``g lag(tau,
    T)``, finds 50.4 and 49.6 ms; :func:`search_notes` gives that value.)
    """
    torque = command_units.get("torque") == NORMALISED
    force = command_units.get("force") == NORMALISED
    if name == "drag_moment" and unit == "m" and torque:
        # a torque per measured force: the accelerometer's, in N whatever the commands' units
        return "[torque unit]/N"
    if name == "com_offset" and unit == "m" and (torque or force):
        num = "[torque unit]" if torque else "N m"
        return f"{num}/{'[force unit]' if force else 'N'}"
    if torque:
        return unit.replace("N m", "[torque unit]")
    return unit


def unit_notes(
    vehicle: Vehicle,
    added: Sequence[str],
    gain: np.ndarray | None,
    gain_se: np.ndarray | None,
    names: Sequence[str] = (),
) -> list[str]:
    """What the summary says about normalised commands and the fitted gain (``names``:
    the effects the fit estimates)."""
    notes = []
    if added:
        notes.append(
            f"torque command is normalised (command_units.torque): {', '.join(added)} added "
            "to estimate its per-axis gain (torque = gain x command)"
        )
    if gain is not None and gain_se is not None:
        diag = np.diag(vehicle.inertia)
        shown = ", ".join(
            f"{a} {g:.4g} ± {e:.2g} ({g / i:.4g} rad/s^2 per unit)"
            for a, g, e, i in zip("xyz", gain, gain_se, diag, strict=True)
        )
        notes.append(
            f"torque command gain (N m per command unit with the assumed inertia; the log "
            f"determines only gain / inertia): {shown}"
        )
        bad = [a for a, g in zip("xyz", gain, strict=True) if not (np.isfinite(g) and g > 0)]
        if bad:
            notes.append(
                f"torque command gain not positive on axis {', '.join(bad)}: check the sign "
                "of the torque columns and the frame (FLU/FRD) in the vehicle YAML"
                + (
                    "; with motor outputs also a motor lag the fit does not model "
                    "(--effects motor_lag): a torque that lags its command by more than "
                    "a quarter of the motion's period correlates negatively with it"
                    if vehicle.motors is not None and "motor_lag" not in names
                    else ""
                )
            )
        notes.append(
            "torque units are unknown: parameters in N m are shown in [torque unit] "
            "(relative to the assumed inertia)"
        )
    if vehicle.force_normalised:
        notes.append(
            "force command is normalised (command_units.force): the GP inputs f/m are a "
            "scaled thrust feature, not an acceleration in m/s^2"
        )
    return notes


def effect_notes(eff: EffectFit, torque_normalised: bool = False) -> list[str]:
    """Warnings about effect parameters the logs do not determine.

    With ``torque_normalised`` ``inertia_error`` is the command gain: the
    warning is about a gain within two standard errors of zero.
    """
    notes = []
    for name, est in eff.estimates.items():
        effect = get_effect(name)
        if name == GAIN_EFFECT and torque_normalised:
            gain, se = torque_gain(est)
            axes = [a for a, g, e in zip("xyz", gain, se, strict=True) if not abs(g) >= 2 * e]
            if axes:
                notes.append(
                    f"torque command gain on axis {', '.join(axes)} within 2 standard errors "
                    "of zero: the logs barely excite it (or the GP explains the same trend)"
                )
            continue
        if name == GAIN_EFFECT:
            notes += _no_torque_notes(est)
        if not effect.identifiable:
            notes.append(
                f"{name} is not identifiable from angular accelerations (see its docs): "
                "its estimate is unreliable"
            )
            continue
        nulls = effect.null_parameters()  # where the effect is absent: scale 1, D 0
        for p in effect.parameters:
            value = np.asarray(est.values[p.name])
            null = np.broadcast_to(np.asarray(nulls[p.name], float).reshape(-1), value.shape)
            # a component exactly 0 was never excited (motor_loss beyond the rotors)
            near = np.abs(value - null) < 2.0 * est.stderr[p.name]
            if name == GAIN_EFFECT and p.name == "scale":
                # as its interval, on the torque's gain 1/scale: a Crazyflie's scale_x
                # 8.56 +- 8.6 was "within 2 standard errors of 1" beside the interval
                # [2.88, inf) its gain 0.12 +- 0.12 gives, which excludes 1
                gain, gain_se = torque_gain(est)
                near = np.abs(np.asarray(gain) - 1.0) < 2.0 * np.asarray(gain_se)
            weak = np.flatnonzero(near & (value != 0.0))
            if weak.size:
                # a scalar parameter by its name; a vector's components as the reports
                # write them (D_x)
                which = ", ".join(
                    p.name if p.size == 1 else f"{p.name}_{'xyz'[i] if p.size == 3 else i}"
                    for i in weak
                )
                at = "zero" if not null[weak].any() else f"{float(null[weak][0]):g}"
                notes.append(
                    f"{name}: {which} within 2 standard errors of {at}: these logs do not "
                    "tell it from the effect's absence (small, absent, or barely excited)"
                )
    return notes


#: An inverse inertia scale (the torque's gain on the acceleration) below which the
#: model predicts little of an axis's acceleration from its torque (scale above 2).
MAX_SMALL_GAIN = 0.5


def _no_torque_notes(est: Any) -> list[str]:
    """'inertia_error: on x the measured angular acceleration does not show the torque
    (1/scale_x = 0.012 ± 0.2, within 2 standard errors of 0): scale_x 82 is no estimate'
    for the axes whose inverse scale (the regression's coefficient, the torque's gain
    on the acceleration) the logs cannot tell from 0: a Crazyflie's hover logs gave
    scale_x 82 ± 1400, with only 'within 2 standard errors of 1' said, and a model that
    predicts almost no roll."""
    scale = np.asarray(est.values["scale"], float)
    gain, gain_se = torque_gain(est)
    # the gain not told from 0 and small: the model predicts little from the torque (a
    # scale of 0.4, gain 2.5 +- 1.6, predicts more than nominal: not this note's case)
    axes = [
        i
        for i in range(scale.size)
        if np.isfinite(gain_se[i]) and abs(gain[i]) < min(2 * gain_se[i], MAX_SMALL_GAIN)
    ]
    return [
        f"inertia_error: on {'xyz'[i]} the measured angular acceleration does not show the "
        f"torque (1/scale_{'xyz'[i]} = {gain[i]:.2g} ± {gain_se[i]:.2g}, within 2 standard errors "
        f"of 0): scale_{'xyz'[i]} {scale[i]:.3g} is no estimate, and the model predicts little "
        f"of the {'xyz'[i]} acceleration from the commanded torque; these logs do not show "
        "what the torque on that axis does (hover alone, or a command in other units)"
        for i in axes
    ]


def search_notes(
    found: Mapping[str, SearchResult],
    normalised: bool = False,
    confirmed: Collection[str] = (),
) -> list[str]:
    """What the summary says about effects estimated by a 1-D search; ``normalised``:
    the torque command is, and the value with the gain on the timed torque is then
    always given, as the time in s that does not depend on the command's unit;
    ``confirmed``: the effects the actuators' feedback shows at the fitted value
    (:func:`actuator_notes`), whose better-fitting form is not suggested instead."""
    notes = []
    for r in found.values():
        p = get_effect(r.name).parameters[0]
        notes.append(
            f"{r.name}: {p.name} = {r.value * 1e3:.1f} ± {r.stderr * 1e3:.1f} ms "
            "(exact form, 1-D search jointly with the GP and the linear effects)"
        )
        if r.better_form is not None and r.form_significant and r.name in confirmed:
            notes.append(
                f"{r.name}: the form of {r.better_form} fits these samples better, but the "
                f"actuators' feedback shows {r.name} (below); its standard error allows "
                f"{r.form_allowance * 1e3:.1f} ms for the difference"
            )
        elif r.better_form is not None and r.form_significant:
            notes.append(
                f"{r.name}: the form of {r.better_form} fits these samples better: "
                f"{r.name}'s form may be wrong, and its standard error allows "
                f"{r.form_allowance * 1e3:.1f} ms for it (try --effects with "
                f"{r.better_form} instead)"
            )
        elif r.better_form is not None:
            notes.append(
                f"{r.name}: the form of {r.better_form} fits these samples about as well "
                "(not significantly better: these samples do not tell the two forms "
                f"apart); its standard error allows {r.form_allowance * 1e3:.1f} ms for "
                "either form"
            )
        if r.coupled is not None and normalised:
            notes.append(
                f"{r.name}: {p.name} = {r.coupled * 1e3:.1f} ms with the torque gain on the "
                "timed torque (g x lag): the time in s whatever the command's unit, the one "
                "to quote as the vehicle's; the "
                f"{r.value * 1e3:.1f} ms above is of the form the model predicts with (lag + "
                "(g - 1) x command), which on normalised commands scales with their unit "
                f"(about {p.name} x gain), and its standard error allows "
                f"{r.gain_allowance * 1e3:.1f} ms for the difference"
            )
        elif r.coupled is not None and r.gain_allowance >= 0.5 * r.stderr:
            notes.append(
                f"{r.name}: with the torque gain on the timed torque (g x lag, not lag + "
                f"(g - 1) x command) the search finds {p.name} = {r.coupled * 1e3:.1f} ms: "
                "the lag and the gain trade on these samples, and its standard error "
                f"allows {r.gain_allowance * 1e3:.1f} ms for it: quote {p.name} by its "
                "interval, which allows both, not by either value alone"
            )
        if r.traded is not None:
            notes.append(
                f"{r.name}: traded with {r.traded} on these samples (searched again at "
                f"each {p.name}, the fit changes little): its standard error is its profile "
                "interval's, and the two cannot be pinned down separately from this flight"
            )
        if r.at_bound:
            lo, hi = get_effect(r.name).search  # type: ignore[misc]
            notes.append(
                f"{r.name}: {p.name} at the edge of its search interval "
                f"({lo * 1e3:g} to {hi * 1e3:g} ms): the logs do not determine it, or "
                "the effect is absent"
            )
    return notes


def actuator_notes(
    found: Mapping[str, SearchResult],
    samples: Sequence[Any],
    vehicle: Vehicle,
    confirmed: set[str] | None = None,
) -> list[str]:
    """Beside each fitted lag or delay, what the actuators' own feedback of each log
    shows for it (:mod:`omavctl.learn.actuator_timing`): the logged tilts' lag for
    ``servo_lag``, the rotors' for ``motor_lag``, their common delay for
    ``command_delay``; none for a log that does not record them. The names whose
    feedback shows them at the fitted value where the torque's search preferred another
    form (:func:`_form_shown`) are added to ``confirmed``: :func:`search_notes` then
    does not tell the user to try that form instead."""
    from omavctl.learn.actuator_timing import SHOWN_BY, actuator_timing

    names = [n for n in found if n in SHOWN_BY]
    if not names:
        return []
    notes = []
    for s in samples:
        flight = getattr(s, "flight", None)
        fits = actuator_timing(flight, vehicle) if flight is not None else {}
        for name in names:
            kinds, what = SHOWN_BY[name]
            got = [fits[k] for k in kinds if k in fits]
            if not got:
                continue
            shown = [f.timing(what) for f in got]
            value = float(np.mean([v for v, _ in shown]))
            lo, hi = max(ci[0] for _, ci in shown), min(ci[1] for _, ci in shown)
            p = get_effect(name).parameters[0].name
            span = f"95 %: {lo * 1e3:.1f} to {hi * 1e3:.1f} ms" if lo <= hi else "they disagree"
            which = " and ".join("tilts" if k == "tilt" else "rotors" for k in kinds)
            how = f"{p} = {value * 1e3:.1f} ms ({span})"
            if any(f.undersampled for f in got):
                how = (
                    f"{value * 1e3:.1f} ms late in all ({span}; the log's commands are samples "
                    "of a faster controller, so a delay and a lag are not told apart from them, "
                    "nor by the torque's forms, which rest on the same commands)"
                )
            shown_form = _form_shown(found[name], lo, hi)
            if shown_form and confirmed is not None:
                confirmed.add(name)
            notes.append(
                f"{name}: the actuators' own feedback of {s.path.name} (the logged {which} "
                f"against their commands) gives {how}{shown_form}"
            )
    return notes


def _form_shown(r: SearchResult | None, lo: float, hi: float) -> str:
    """Where the torque's search said another timing form fits better (significantly)
    but the actuators' feedback shows this effect at a value inside the fit's 95 %
    interval: '; that is motor_lag at the fitted value: ...'; '' otherwise. A new user's
    figure-8 with a hidden 40 ms motor lag and a drag the model lacked read "the form of
    command_delay fits these samples better ... try command_delay instead" beside the
    rotors' feedback "T_m = 40.0 ms (37.5 to 42.5 ms)"."""
    if r is None or r.better_form is None or not r.form_significant or lo > hi:
        return ""
    if not (lo <= r.value + Z95 * r.stderr and r.value - Z95 * r.stderr <= hi):
        return ""
    return (
        f"; that is {r.name} at the fitted value: the torque's better fit with "
        f"{r.better_form}'s form comes from elsewhere in these samples (an effect the model "
        "lacks can bend one timing form toward another), not from a wrong form"
    )
