"""A lag or delay claimed on its fit-flight estimate, checked as ``fit`` makes it.

:mod:`omavctl.diagnose.held_beside` claims a lag or delay the held-out flight cannot pin
down when its estimate from the fit flight's training points (generalised least
squares with the model's kernel, beside the look-alikes) excludes 0. That estimate
treats the training points as independent, and it leaves out what ``fit --effects``
adds to a timing's standard error: the autocorrelated residual of the whole flight
(a Newey-West sandwich) and the allowances for another timing form or the torque gain's
(:mod:`omavctl.learn.effect_search`). A new user's Crazyflie window (session 34,
log15 at 15.8-50.8 s judged on log16): the verdict said "the fit flight shows it (8
ms, its 95 % interval excluding 0)" and printed the fit that adds command_delay; that
fit said "tau_d = 7.48 ± 21 ms [below 48.6 ms]: cannot be pinned down from this flight"
(its residual's variance factor 33, the gain's form 21 ms).

So where the model's fit logs can still be read (:func:`omavctl.diagnose.logread.
fit_flight_reader`: the files the model names, unchanged), the claim is checked with
the estimate the printed command would make on them (:func:`omavctl.diagnose.
estimates.fit_estimate`, its two stages): the claim stands only where that interval
excludes 0 too, and the sentence quotes it. Where the logs cannot be read, the
training points' estimate stands, and the sentence says that it was not checked.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from omavctl.diagnose.claims import excludes_null
from omavctl.diagnose.estimates import SecondStage, fit_estimate
from omavctl.diagnose.logread import FitFlight
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import SavitzkyGolay

__all__ = ["checked_on_fit_flight", "fit_flight_estimate_json"]


def fit_flight_estimate_json(
    read: FitFlight | None, model: ResidualGP, name: str, sg: SavitzkyGolay
) -> dict[str, Any] | None:
    """``name``'s estimate (an estimate's JSON) as ``fit --effects <the model's>,<name>``
    makes it on the model's fit logs; None when they cannot be read."""
    samples = read() if read is not None else None
    if not samples:
        return None
    stage = SecondStage(samples, model, sg)
    return fit_estimate(samples, list(model.effects), name, stage).to_json()


def checked_on_fit_flight(
    entry: Mapping[str, Any], read: FitFlight | None, model: ResidualGP, sg: SavitzkyGolay
) -> tuple[dict[str, Any], bool]:
    """The held-back timing claim's ``entry`` with what the check found, and whether the
    claim stands: ``fit_flight_fit`` the estimate as fit makes it (absent when the logs
    cannot be read: the claim stands on the training points' estimate, with
    ``fit_flight_checked`` False)."""
    name = str(entry.get("name"))
    fit = fit_flight_estimate_json(read, model, name, sg)
    if fit is None:
        return {**entry, "fit_flight_checked": False}, True
    return {**entry, "fit_flight_checked": True, "fit_flight_fit": fit}, excludes_null(
        name, fit, None
    )
