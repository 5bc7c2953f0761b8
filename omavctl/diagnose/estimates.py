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
autocorrelation-robust standard errors and their 95 % intervals. With the
evaluated model's features at hand, the effects that ``fit`` then estimates jointly
with its GP (:func:`omavctl.learn.fit_steps.joint_step`) are estimated so here too:
GP hyperparameters fitted to the first pass's residual at k-medoids points of these
samples, generalised least squares there, the covariance made honest as fit makes
it. (The model's own hyperparameters will not do: its GP learned the missing effect
on its fit flight and absorbs it all.) Without that
step the interval ignored what the GP can absorb: on a simulated CoM offset the
first pass alone said r_y = -0.01348 m (95 %: -0.0135 to -0.01346) where ``fit``
on the same log says -0.01347 +- 0.00038 m, twenty times wider.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from omavctl.learn.effect_fit import (
    effect_prior,
    honest_covariance,
    joint_effects,
    merged_estimates,
    refit_estimates,
)
from omavctl.learn.fit_steps import Residuals, first_pass
from omavctl.learn.hyperparameters import fit_hyperparameters, measurement_noise_std
from omavctl.learn.model import EffectEstimate, ResidualGP
from omavctl.learn.points import normalisation, select_points
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay, feature_names

__all__ = ["ESTIMATE_METHOD", "fit_estimate", "fit_estimates"]

#: How the diagnosis estimates an effect's parameters (in the evaluation JSON).
ESTIMATE_METHOD = (
    "as fit --effects estimates it (its first pass, on these samples, with the model's "
    "effects): exact 1-D search for lags and delays, least squares for the others, "
    "then the latter jointly with a GP fitted to these samples (generalised least "
    "squares at k-medoids points, as fit's joint step); standard errors by a Newey-West "
    "sandwich over contiguous samples, at least the joint step's, 95 % interval "
    "= value -/+ 1.96 standard errors"
)
#: Points of the held-out samples the joint step uses (fit's default).
JOINT_POINTS = 200


def _joint_with_gp(
    res: Residuals, model: ResidualGP, sg: SavitzkyGolay
) -> dict[str, EffectEstimate]:
    """The linear effects of ``res`` estimated jointly with a GP as ``fit``'s joint step
    (:func:`omavctl.learn.fit_steps.joint_step`) estimates them on these samples: GP
    hyperparameters fitted to the first pass's residual at k-medoids points of the
    model's inputs (one optimiser start), then generalised least squares there and
    the covariance made honest about autocorrelation."""
    names = res.linear
    if not names or res.x_eff is None:
        return dict(res.first_pass.estimates)
    inputs = np.concatenate([s.inputs(model.features) for s in res.samples])
    mean, scale = normalisation(inputs)
    zn = (inputs - mean) / scale
    idx, _ = select_points(zn, min(JOINT_POINTS, zn.shape[0]), 0)
    x_tr = res.x_eff[idx]
    floor = measurement_noise_std(res.samples, sg)
    with threadpool_limits(1):
        axes, t_mean, sv, ls, _ = fit_hyperparameters(
            zn[idx],
            res.targets[idx],
            restarts=0,
            input_names=feature_names(model.features),
            noise_floor=floor,
        )
    y_raw = res.targets[idx] + x_tr @ res.first_pass.theta
    p_mean, p_std = effect_prior(names, res.first_pass, model.vehicle)
    nv = np.array([a.noise_std**2 for a in axes])
    theta, cov = joint_effects(zn[idx], y_raw, x_tr, t_mean, sv, ls, nv, p_std, p_mean)
    eff = refit_estimates(names, theta, honest_covariance(cov, res.first_pass), res.first_pass)
    return dict(eff.estimates)


def fit_estimate(
    samples: Sequence[ResidualSamples],
    model_effects: Sequence[str],
    name: str,
    model: ResidualGP | None = None,
    sg: SavitzkyGolay | None = None,
) -> EffectEstimate:
    """``name``'s estimate as ``fit --effects <model_effects>,<name>`` makes it: its
    first pass, then (given the evaluated ``model``'s features and the derivative
    filter ``sg``) the linear effects jointly with a GP fitted to these samples.

    ``samples`` must carry every named effect's regressor and context.
    """
    names = list(model_effects) if name in model_effects else [*model_effects, name]
    res = first_pass(list(samples), names)
    linear = res.first_pass.estimates
    if model is not None and sg is not None and name in res.linear:
        linear = _joint_with_gp(res, model, sg)
    return merged_estimates([name], linear, res.found)[name]


def fit_estimates(
    samples: Sequence[ResidualSamples],
    model_effects: Sequence[str],
    names: Iterable[str],
    model: ResidualGP | None = None,
    sg: SavitzkyGolay | None = None,
) -> dict[str, dict[str, Any]]:
    """The JSON of :func:`fit_estimate` (values, standard errors, 95 % intervals,
    whether each is pinned down) for every effect of ``names``."""
    return {n: fit_estimate(samples, model_effects, n, model, sg).to_json() for n in names}
