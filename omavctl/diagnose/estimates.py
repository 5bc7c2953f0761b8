"""The diagnosis's estimate of each effect, made as ``fit --effects`` makes it.

The ranking of :mod:`omavctl.diagnose.scoring` fits each candidate alone, by
bounded least squares on its linearised regressor, to a residual whose
per-axis weights make the axes count alike: good for ranking, but on a log
with a normalised torque command (the gain unknown) or a lag it estimated
something other than what ``fit --effects`` then reports (on the px4tools
octocopter, a motor lag of 0.086 s against fit's 0.012 s: six combined
standard errors apart). The estimate reported beside each effect is instead
the first pass of ``fit`` (:func:`omavctl.learn.fit_steps.first_pass`) on
the same samples, with the effects ``fit`` would estimate together (the
model's, plus this one, as the suggested ``fit`` command names them): the
exact 1-D search for lags and delays, least squares for the others, the
autocorrelation-robust standard errors and their 95 % intervals.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from omavctl.learn.effect_fit import merged_estimates
from omavctl.learn.fit_steps import first_pass
from omavctl.learn.model import EffectEstimate
from omavctl.learn.signal import ResidualSamples

__all__ = ["ESTIMATE_METHOD", "fit_estimate", "fit_estimates"]

#: How the diagnosis estimates an effect's parameters (in the evaluation JSON).
ESTIMATE_METHOD = (
    "as fit --effects estimates it (its first pass, on these samples, with the model's "
    "effects): exact 1-D search for lags and delays, least squares for the others; "
    "standard errors by a Newey-West sandwich over contiguous samples, 95 % interval "
    "= value -/+ 1.96 standard errors"
)


def fit_estimate(
    samples: Sequence[ResidualSamples], model_effects: Sequence[str], name: str
) -> EffectEstimate:
    """``name``'s estimate as ``fit --effects <model_effects>,<name>`` makes it first.

    ``samples`` must carry every named effect's regressor and context.
    """
    names = list(model_effects) if name in model_effects else [*model_effects, name]
    res = first_pass(list(samples), names)
    return merged_estimates([name], res.first_pass.estimates, res.found)[name]


def fit_estimates(
    samples: Sequence[ResidualSamples], model_effects: Sequence[str], names: Iterable[str]
) -> dict[str, dict[str, Any]]:
    """The JSON of :func:`fit_estimate` (values, standard errors, 95 % intervals,
    whether each is pinned down) for every effect of ``names``."""
    return {n: fit_estimate(samples, model_effects, n).to_json() for n in names}
