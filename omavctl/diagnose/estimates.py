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
evaluated model's features at hand, ``fit``'s second stage follows as well: GP
hyperparameters fitted to the first pass's residual at k-medoids points of these
samples, the lags and delays searched again jointly with that GP, the other effects
by generalised least squares there, the covariance made honest as fit makes it.
(The model's own hyperparameters will not do: its GP learned the missing effect on
its fit flight and absorbs it all.) Without that stage the intervals ignored what
the GP can absorb: on a simulated CoM offset the first pass alone said r_y =
-0.01348 m (95 %: -0.0135 to -0.01346) where ``fit`` on the same log says -0.01347
+- 0.00038 m, twenty times wider; on the Crazyflie's log15 (33.3-50.8 s) it said
T_m = 86.5 ms (83.5 to 89.5) where ``fit`` says 77.8 +- 10.2 ms.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import cached_property
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
from omavctl.learn.effect_search import SearchResult, gls_search
from omavctl.learn.fit_steps import Residuals, first_pass
from omavctl.learn.hyperparameters import fit_hyperparameters, measurement_noise_std
from omavctl.learn.model import EffectEstimate, ResidualGP
from omavctl.learn.points import normalisation, select_points
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay, feature_names

__all__ = [
    "ESTIMATE_METHOD",
    "SecondStage",
    "estimate_together",
    "fit_estimate",
    "fit_estimates",
]

#: How the diagnosis estimates an effect's parameters (in the evaluation JSON).
ESTIMATE_METHOD = (
    "as fit --effects estimates it (its first pass, on these samples, with the model's "
    "effects): exact 1-D search for lags and delays, least squares for the others, "
    "then the latter jointly with a GP fitted to these samples (generalised least "
    "squares at k-medoids points, as fit's joint step); standard errors by a Newey-West "
    "sandwich over contiguous samples, at least the joint step's, 95 % interval "
    "= value -/+ 1.96 standard errors"
)
#: Points of the held-out samples the second stage uses (fit uses 200; 100 keeps evaluate
#: within the test budget, and the agreement tests of tests/test_intervals.py still hold).
JOINT_POINTS = 100


def _points(samples: Sequence[ResidualSamples], model: ResidualGP) -> tuple[np.ndarray, np.ndarray]:
    """Normalised GP inputs (N, d) of the stacked samples and the indices (k,) of their
    k-medoids points, as ``fit`` picks its training points."""
    inputs = np.concatenate([s.inputs(model.features) for s in samples])
    mean, scale = normalisation(inputs)
    zn = (inputs - mean) / scale
    idx, _ = select_points(zn, min(JOINT_POINTS, zn.shape[0]), 0)
    return zn, idx


class SecondStage:
    """What ``fit``'s second stage needs on one evaluation's samples: the evaluated
    model (its GP features, its vehicle), the derivative filter ``sg`` and, picked
    once on first use for all the effects estimated, the k-medoids points."""

    def __init__(
        self, samples: Sequence[ResidualSamples], model: ResidualGP, sg: SavitzkyGolay
    ) -> None:
        self.samples, self.model, self.sg = list(samples), model, sg

    @cached_property
    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Normalised inputs (N, d) and k-medoids indices (k,) (:func:`_points`)."""
        return _points(self.samples, self.model)


def _with_gp(
    original: list[ResidualSamples], res: Residuals, stage: SecondStage
) -> tuple[dict[str, EffectEstimate], dict[str, SearchResult]]:
    """The effects of ``res`` estimated jointly with a GP as ``fit`` estimates them on
    these samples: GP hyperparameters fitted to the first pass's residual at k-medoids
    points of the model's inputs (one optimiser start); the searched effects again by
    the 1-D search jointly with that GP (:func:`omavctl.learn.effect_search.gls_search`,
    as fit's ``_refine_searched``), the linear ones by generalised least squares there
    (:func:`omavctl.learn.fit_steps.joint_step`), their covariance made honest about
    autocorrelation. Returns the linear estimates and the searched results."""
    model, sg = stage.model, stage.sg
    zn, idx = stage.points
    with threadpool_limits(1):
        axes, t_mean, sv, ls, _ = fit_hyperparameters(
            zn[idx],
            res.targets[idx],
            restarts=0,
            input_names=feature_names(model.features),
            noise_floor=measurement_noise_std(res.samples, sg),
        )
    nv = np.array([a.noise_std**2 for a in axes])
    names = res.linear
    p_mean, p_std = effect_prior(names, res.first_pass, model.vehicle)
    x_tr = res.x_eff[idx] if res.x_eff is not None else np.zeros((len(idx), 3, 0))
    found = res.found
    if found:
        hyper = (t_mean, sv, ls, nv)
        found = gls_search(original, idx, found, x_tr, (p_mean, p_std), zn[idx], hyper)
    if not names:
        return dict(res.first_pass.estimates), found
    y_raw = res.targets[idx] + x_tr @ res.first_pass.theta
    theta, cov = joint_effects(zn[idx], y_raw, x_tr, t_mean, sv, ls, nv, p_std, p_mean)
    eff = refit_estimates(names, theta, honest_covariance(cov, res.first_pass), res.first_pass)
    return dict(eff.estimates), found


def estimate_together(
    samples: Sequence[ResidualSamples],
    model_effects: Sequence[str],
    names: Sequence[str],
    stage: SecondStage | None = None,
) -> dict[str, EffectEstimate]:
    """Every one of ``names`` estimated as ``fit --effects <model_effects>,<names>``
    estimates them, all together: its first pass and, given the ``stage``, its second
    (jointly with a GP fitted to these samples).

    ``samples`` must carry every named effect's regressor and context.
    """
    every = [*model_effects, *(n for n in names if n not in model_effects)]
    res = first_pass(list(samples), every)
    linear, found = res.first_pass.estimates, res.found
    if stage is not None:
        linear, found = _with_gp(list(samples), res, stage)
    merged = merged_estimates(list(names), linear, found)
    return {n: merged[n] for n in names}


def fit_estimate(
    samples: Sequence[ResidualSamples],
    model_effects: Sequence[str],
    name: str,
    stage: SecondStage | None = None,
) -> EffectEstimate:
    """``name``'s estimate as ``fit --effects <model_effects>,<name>`` makes it
    (:func:`estimate_together` of one effect)."""
    return estimate_together(samples, model_effects, [name], stage)[name]


def fit_estimates(
    samples: Sequence[ResidualSamples],
    model_effects: Sequence[str],
    names: Iterable[str],
    stage: SecondStage | None = None,
) -> dict[str, dict[str, Any]]:
    """The JSON of :func:`fit_estimate` (values, standard errors, 95 % intervals,
    whether each is pinned down) for every effect of ``names``, each estimated with
    the model's effects alone."""
    return {n: fit_estimate(samples, model_effects, n, stage).to_json() for n in names}
