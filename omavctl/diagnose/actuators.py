"""The timing effects the actuators' own feedback shows, in the diagnosis's claims.

The angular acceleration of a smooth flight often cannot tell a servo lag, a motor lag
and a command delay apart (their torques look alike: "ambiguous"), and a lag whose
torque the model's other effects share may not be pinned down at all. Where the log
records the arms' tilts and the rotors' speeds, the actuators show their timing
directly (:mod:`omavctl.learn.actuator_timing`): the tilts lag for ``servo_lag``, the
rotors for ``motor_lag``, both are late by one time for ``command_delay``.

Used in the claims (:func:`with_actuators`), after the torque-based selection:

- a timing effect the actuators show (its lag or delay at least :data:`LAG_MIN` /
  :data:`DELAY_MIN`, the fit at least halving their mismatch) whose torque on this
  flight (its exact form at the actuators' value) is at least the claim floor is
  claimed, if the model lacks it;
- a timing effect claimed from the torque alone that the recorded actuators rule out
  (the whole 95 % interval of their lag or delay under the minimum) is held back, and
  left out of the other claims' ambiguous sets.

A lag or delay the actuators show under the claim floor is said, not claimed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.claims import Guarded
from omavctl.learn.actuator_timing import ActuatorFit, actuator_timing
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = [
    "DELAY_MIN",
    "LAG_MIN",
    "actuator_fits",
    "actuator_sentence",
    "shown_timing",
    "with_actuators",
]

#: Lag (s) of the tilts or rotors from which the actuators show a servo or motor lag
#: (the simulator's default actuators lag by 5 ms), and delay (s) from which both show a
#: command delay (a 1 kHz controller logged at 100 Hz reads as 4-8 ms).
LAG_MIN, DELAY_MIN = 0.015, 0.015
#: The fitted timing must leave at most this share of the actuators' RMS mismatch.
FIT_SHARE = 0.5

_PARAM = {"servo_lag": "T_s", "motor_lag": "T_m", "command_delay": "tau_d"}


def actuator_fits(samples: Sequence[ResidualSamples], model: ResidualGP) -> dict[str, ActuatorFit]:
    """The tilts' and rotors' timing of the first log that records them (evaluate keeps
    each log's flight on its samples); empty without one."""
    for s in samples:
        if s.flight is not None:
            fits = actuator_timing(s.flight, model.vehicle)
            if fits:
                return fits
    return {}


def _fits_well(fit: ActuatorFit) -> bool:
    return fit.rms_fit <= FIT_SHARE * fit.rms_none


def shown_timing(fits: Mapping[str, ActuatorFit]) -> dict[str, dict[str, Any]]:
    """Effect name -> {"value", "ci95", "kinds"} of the timing effects the actuators show.
    Where the commands are samples of a faster controller, tilts and rotors late by one
    time show the command late (``command_delay``), not two lags of that time."""
    out: dict[str, dict[str, Any]] = {}
    tilt, rotor = fits.get("tilt"), fits.get("rotor")
    late = [f for f in (tilt, rotor) if f is not None]
    delays = [f.timing("tau") for f in late]
    common = any(f.undersampled for f in late)
    if (
        late
        and (len(late) == 2 or not common)
        and all(d >= DELAY_MIN and _fits_well(f) for f, (d, _) in zip(late, delays, strict=True))
    ):
        lo, hi = max(ci[0] for _, ci in delays), min(ci[1] for _, ci in delays)
        if lo <= hi:  # one delay for both
            out["command_delay"] = {
                "value": float(np.mean([d for d, _ in delays])),
                "ci95": [lo, hi],
                "kinds": [f.kind for f in late],
            }
    for name, fit in (("servo_lag", tilt), ("motor_lag", rotor)):
        if fit is None or (fit.undersampled and "command_delay" in out):
            continue
        value, ci = fit.timing("T")
        if value >= LAG_MIN and _fits_well(fit):
            out[name] = {"value": value, "ci95": list(ci), "kinds": [fit.kind]}
    return out


def ruled_out(fits: Mapping[str, ActuatorFit]) -> set[str]:
    """The timing effects the recorded actuators rule out: every 95 % interval of the
    lag or delay that would show them under the minimum (a lag fitted to a faster
    controller's commands only errs long, a delay short: there the delay's is how late
    in all, and where both kinds are late by one time, neither lag is more than it)."""
    out = set()
    tilt, rotor = fits.get("tilt"), fits.get("rotor")
    if tilt is not None and tilt.T_ci95[1] < LAG_MIN:
        out.add("servo_lag")
    if rotor is not None and rotor.T_ci95[1] < LAG_MIN:
        out.add("motor_lag")
    late = [f for f in (tilt, rotor) if f is not None]
    if late and all(f.timing("tau")[1][1] < DELAY_MIN for f in late):
        out.add("command_delay")
    if tilt is not None and rotor is not None and "command_delay" in shown_timing(fits):
        if tilt.undersampled and tilt.late_than(rotor) < LAG_MIN:
            out.add("servo_lag")  # both late by one time: the command, not the servos
        if rotor.undersampled and rotor.late_than(tilt) < LAG_MIN:
            out.add("motor_lag")
    return out


def _part_over_floor(
    samples: Sequence[ResidualSamples], name: str, value: float, floor: float
) -> float:
    """RMS of the effect's exact form at ``value`` on these samples over the floor."""
    part = np.concatenate([s.exact(name, value) for s in samples])
    return float(np.sqrt((part**2).mean()) / floor) if floor > 0 else 0.0


def with_actuators(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    guarded: Guarded,
    fits: Mapping[str, ActuatorFit],
    floor: float,
) -> tuple[Guarded, dict[str, Any] | None]:
    """``guarded`` with the timing claims the actuators show added and those they rule
    out held back (module docstring), and the diagnosis's ``actuators`` JSON (None
    without recorded actuators)."""
    if not fits:
        return guarded, None
    shown = shown_timing(fits)
    out_ruled = ruled_out(fits)
    for name, entry in shown.items():
        entry["part_over_floor"] = _part_over_floor(samples, name, entry["value"], floor)
    added = [
        n for n, e in shown.items()
        if n not in guarded.kept and n not in model.effects and e["part_over_floor"] >= 1.0
    ]  # fmt: skip
    dropped = [n for n in guarded.kept if n in out_ruled]
    kept = [n for n in guarded.kept if n not in dropped] + added
    held = [h for h in guarded.held_back if h.get("name") not in added]
    for n in dropped:
        held.append(
            {
                "name": n,
                "units": {p.name: p.unit for p in get_effect(n).parameters},
                "estimate": guarded.estimates.get(n),
                "axes": None,
                "actuators": "ruled out",
            }
        )
    estimates = {n: e for n, e in guarded.estimates.items() if n in kept}
    new = Guarded(kept=kept, estimates=estimates, held_back=held, profiles=guarded.profiles)
    info = {
        "fits": {k: f.to_json() for k, f in fits.items()},
        "shown": {n: {**e, "parameter": _PARAM[n]} for n, e in shown.items()},
        "ruled_out": sorted(out_ruled),
        "claimed": added,
        "held_back": dropped,
        "min_lag": LAG_MIN,
        "min_delay": DELAY_MIN,
    }
    return new, info


def _ms(v: float) -> str:
    """Seconds as milliseconds: '92 ms', '4.3 ms'."""
    return f"{1000.0 * v:.0f} ms" if v >= 0.0095 else f"{1000.0 * v:.1f} ms"


def _kind_words(fit: Mapping[str, Any]) -> str:
    what = "tilts" if fit.get("kind") == "tilt" else "rotors' thrusts"
    if fit.get("undersampled"):
        late, (lo, hi) = float(fit["late"]), fit["late_ci95"]
        return f"the {what} are {_ms(late)} late in all (95 %: {_ms(lo)} to {_ms(hi)})"
    tau, lag = float(fit["tau"]), float(fit["T"])
    lo, hi = fit["T_ci95"] if lag >= tau else fit["tau_ci95"]
    if max(tau, lag) < LAG_MIN:
        return f"the {what} follow their commands within {_ms(max(tau, lag) + 1e-9)}"
    how = f"with a lag of {_ms(lag)}" if lag >= tau else f"{_ms(tau)} late"
    return f"the {what} follow their commands {how} (95 %: {_ms(lo)} to {_ms(hi)})"


def _timing_discussed(diag: Mapping[str, Any]) -> bool:
    """Whether the verdict names a lag or delay: claimed, held back, or ambiguous with
    the top claim."""
    named = {str(n) for n in diag.get("missing") or []}
    named |= {str(h.get("name")) for h in diag.get("not_pinned") or [] if isinstance(h, Mapping)}
    for e in (diag.get("missing_effects") or [])[:1]:
        named |= {str(a) for a in e.get("ambiguous_with") or []}
    return bool(named & set(_PARAM))


def actuator_sentence(diag: Mapping[str, Any]) -> str:
    """' The actuators' own feedback ...' for the verdict: how the logged tilts and rotors
    follow their commands, what that shows and what was claimed or held back from it;
    '' without recorded actuators, or when they show nothing and the verdict names no
    lag or delay (every omav verdict said its servos follow within 6 ms)."""
    info = diag.get("actuators")
    if not isinstance(info, Mapping) or not info.get("fits"):
        return ""
    if not (info.get("shown") or info.get("held_back") or _timing_discussed(diag)):
        return ""  # actuators that follow at once, and no lag or delay in question
    fits = info["fits"]
    text = " The actuators' own feedback (the logged tilts and rotor speeds): " + "; ".join(
        _kind_words(fits[k]) for k in ("tilt", "rotor") if k in fits
    )
    if any(f.get("undersampled") for f in fits.values()):
        text += (
            " (the log's commands are samples of a faster controller: between its rows"
            " they move in ways the actuators do not follow, so a delay and a lag are not"
            " told apart from them"
        )
        common = "command_delay" in (info.get("shown") or {})
        text += "; tilts and rotors late by one time are the command late)" if common else ")"
    shown = info.get("shown") or {}
    if shown:
        names = ", ".join(
            f"{n} ({e['parameter']} {_ms(float(e['value']))})" for n, e in shown.items()
        )
        text += f": they show {names}"
        claimed = [n for n in info.get("claimed") or [] if n in shown]
        below = [n for n, e in shown.items() if float(e.get("part_over_floor", 0.0)) < 1.0]
        if claimed:
            text += f"; claimed from them: {', '.join(claimed)}"
        if below:
            text += f"; under the claim floor in this flight's torque: {', '.join(below)}"
    held = info.get("held_back") or []
    if held:
        text += f"; they rule out {', '.join(held)}, claimed from the torque alone: held back"
    ruled = set(info.get("ruled_out") or [])
    others = sorted(
        str(h.get("name"))
        for h in diag.get("not_pinned") or []
        if isinstance(h, Mapping) and h.get("name") in ruled and h.get("name") not in held
    )
    if others:
        text += f"; they rule out {', '.join(others)}, which the torque could not pin down"
    return text + "."
