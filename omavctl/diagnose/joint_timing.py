"""A lag or delay of the joint selection that the claims guard holds back, replaced by
the next lag or delay that passed the same joint step.

The joint selection (:mod:`omavctl.diagnose.joint`) tests each effect with its
linearised regressor, in which a motor lag, a servo lag and a command delay coincide to
first order: which of them it accepts is decided by a few per cent of gain. The claims
guard then estimates the accepted one with its exact form on the held-out flight
(:func:`omavctl.diagnose.claims.guard_claims`, the numbers of the printed fit command),
which does tell them apart. On two report5 draws (a hidden 50 ms command delay, figure-8
-> steps, 1 kHz) the joint step accepted ``motor_lag`` (35.6 % of what ``com_offset``
left, against the delay's 34.6 %); its exact estimate, 42 +- 33 ms, held its null and was
held back, and the delay, which the guard pins down at 49.5 +- 1.3 ms, was never guarded:
the verdict named only ``com_offset``. Here the next of the step's
:attr:`~omavctl.diagnose.joint.JointStep.timing_rivals` is guarded in its place, and
claimed when kept.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from omavctl.diagnose.claims import Guarded

__all__ = ["with_timing_rivals"]


def with_timing_rivals(
    guard: Callable[[list[str]], Guarded],
    names: list[str],
    rivals: Mapping[str, Sequence[str]],
) -> Guarded:
    """``guard(names)``; for each claim it holds back that has timing ``rivals`` (name ->
    the other lags and delays that passed its joint step, best first), the first rival
    not already claimed that ``guard`` keeps in its place, with the names it was guarded
    with; the held-back claim then leaves the result (its rival answered the step)."""
    out = guard(names)
    for held in [str(h["name"]) for h in out.held_back]:
        for rival in rivals.get(held, ()):
            if rival in names or held not in names:
                continue
            swapped = [rival if n == held else n for n in names]
            trial = guard(swapped)
            if rival in trial.kept:
                names, out = swapped, trial
                break
    return out
