"""The band's share of the effects' parameter uncertainty.

A model's prediction is the effects ``sum_e X_e theta_e`` plus a GP trained on the
residual after them (:mod:`omavctl.learn.model`). Its predictive variance then holds
the term of a GP with explicit basis functions (Rasmussen & Williams §2.7, eq. 2.42):
``diag(R Sigma R^T)``, ``R = H* - k*(K + sigma^2 I)^-1 H`` with ``H*`` (n, 3, P) the
effects' sensitivities at the predicted samples and ``H`` (m, 3, P) at the training
points (the GP mean's weight, :mod:`omavctl.learn.mean_shrink`, is not applied here:
its cost is the band's own ``((1 - w) m)^2`` term) and ``Sigma``
the parameters' posterior covariance with the model's calibrated GP as the model of
what they leave (:meth:`omavctl.learn.model.ResidualGP.basis_covariance`).

Beyond the training inputs neither the GP nor that posterior vouches for the
parameters (an effect fitted on one flight may be off on another by more than the
GP-based posterior allows); there the term rises to at least the robust one, the
effects' HAC standard errors taken as independent, from :data:`BEYOND_MARGIN` of a
training range beyond the box, fully at twice that (issue 26: a band wider than
needed outside the fit flight's inputs is accepted, an overconfident one is not).

Arrays: n samples, m training points, P parameters.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from omavctl.learn.estimate import GAIN_EFFECT, GAIN_PRIOR_FACTOR, EffectEstimate

__all__ = ["BEYOND_MARGIN", "beyond_weight", "effect_residual", "parameter_variance"]

#: Beyond the training inputs' box by this fraction of a training range (the margin at
#: which ``evaluate`` counts a sample outside the fit flight's inputs), the parameter
#: term rises towards the robust one, fully at twice the margin: the effects'
#: autocorrelation-robust standard errors taken as independent, nothing absorbed by the
#: GP (:func:`parameter_variance`).
BEYOND_MARGIN = 0.25


def parameter_variance(model: Any, samples: Any) -> np.ndarray:
    """Variance (n, 3) the effects' parameter uncertainty adds to ``model``'s
    prediction on a log's samples: ``diag(R Sigma R^T)`` per axis, the term of a GP
    with explicit basis functions (Rasmussen & Williams §2.7, eq. 2.42).

    ``R = H* - k*(K + sigma^2 I)^-1 H``: a parameter error ``delta`` moves the
    effects' prediction by ``H* delta`` (``H*`` (n, 3, P) the sensitivities at the
    samples) and the GP's targets by ``H delta`` at the training points, of which its
    mean carries back the part it can represent (in full: the cost of weighing the
    mean, :mod:`omavctl.learn.mean_shrink`, is the band's own ``((1 - w) m)^2``).
    ``Sigma = (B^-1 + sum_a H_a^T K_a^-1 H_a)^-1`` is the parameters' posterior
    covariance with this model's calibrated GP as the model of what they
    leave (``B`` the effects' prior). The intervals ``fit`` reports are wider (robust
    to autocorrelation, :mod:`omavctl.learn.intervals`): the band's GP part already
    carries that autocorrelation, and counting it twice made the band over-wide
    inside the fit flight's inputs (docs/generalisation.md). Beyond the training
    inputs, where neither vouches for the parameters, the term rises to at least
    ``sum_j (se_j H*_j)^2`` with those robust errors (fully a quarter of a training
    range beyond the box: :func:`beyond_weight`). Linear
    effects enter by their regressors (exact); a searched effect (lag, delay) by
    its exact form's difference one standard error away, and at the training points
    by its linearised regressor scaled to that sensitivity. A file without training
    regressors gets ``sum_j (se_j H*_j)^2`` everywhere. (The model's
    :meth:`omavctl.learn.model.ResidualGP.effects_variance`.)
    """
    if not model.effects:
        return np.zeros((samples.n, 3))
    basis = _basis(model, samples)
    if basis is None:
        return _independent(model, samples)
    at_samples, at_train, prior_std = basis
    z = samples.inputs(model.features)
    sigma = model.basis_covariance(at_train, prior_std)
    # the GP mean carries back a parameter error in full (R&W eq. 2.42), also where
    # ``mean_shrink`` weighs the mean: that weighing's cost is its own term of the band,
    # ((1 - w) m)^2; weighing the carry-back too counted it again, and where the GP mean
    # is near 0 (w near 0) left H* Sigma H*^T, the parameters' confounded directions in
    # full (docs/intervals.md, "The effects' term inside the fit inputs")
    r = at_samples - model.smooth(z, at_train)
    inside = np.maximum(np.einsum("nap,pq,naq->na", r, sigma, r), 0.0)
    rho = beyond_weight(model.inputs, z)
    if not np.any(rho > 0):
        return np.asarray(inside)
    return np.asarray(np.maximum(inside, rho[:, None] * _independent(model, samples)))


def beyond_weight(train: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Weight (n,) in [0, 1] of the robust term at inputs z (n, d): 0 up to
    :data:`BEYOND_MARGIN` of a training range beyond the training inputs' box (m, d)
    ``train`` (inside the fit flight's inputs as ``evaluate`` counts them), rising to 1
    at twice that (an input constant in training that moves: 1)."""
    lo, hi = train.min(axis=0), train.max(axis=0)
    span = hi - lo
    gap = np.maximum(lo - z, z - hi).clip(min=0.0)
    varied = span > 1e-9 * np.maximum(np.maximum(np.abs(lo), np.abs(hi)), 1.0)
    excess = np.where(varied, gap / np.where(varied, span, 1.0), np.where(gap > 0, np.inf, 0.0))
    reach = excess.max(axis=1, initial=0.0)
    return np.asarray(np.clip((reach - BEYOND_MARGIN) / BEYOND_MARGIN, 0.0, 1.0))


def _basis(model: Any, samples: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The effects' sensitivities at the samples (n, 3, P) and at the training points
    (m, 3, P), and their prior stds (P,), for :func:`parameter_variance`; None when a
    fitted effect has no training regressor (older files)."""
    cols: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for est in model.effects.values():
        train = model.train_regressors.get(est.name)
        if train is None:
            return None
        effect = est.effect
        if effect.search is None:
            prior = np.full(effect.n_theta, effect.prior_std)
            if est.name == GAIN_EFFECT and model.vehicle.torque_normalised:
                prior = np.maximum(GAIN_PRIOR_FACTOR * np.abs(1.0 + est.theta), 1e-9)
            cols.append((samples.regressors[est.name], train, prior))
            continue
        pname = effect.parameters[0].name
        step = float(est.stderr[pname][0])
        if not (np.isfinite(step) and step > 0):
            step = 0.1 * effect.prior_std
        moved = {k: v.copy() for k, v in est.values.items()}
        moved[pname][0] += step
        sens = (
            effect_residual(samples, est, moved) - effect_residual(samples, est, est.values)
        ) / step
        lin = samples.regressors[est.name][..., 0]
        xx = float(np.sum(lin * lin))
        gain = float(np.sum(sens * lin)) / xx if xx > 0 else 0.0
        cols.append((sens[..., None], gain * train[..., :1], np.array([effect.prior_std])))
    return (
        np.concatenate([c[0] for c in cols], axis=-1),
        np.concatenate([c[1] for c in cols], axis=-1),
        np.concatenate([c[2] for c in cols]),
    )


def _independent(model: Any, samples: Any) -> np.ndarray:
    """``sum_j (d r / d theta_j)^2 se_j^2`` (n, 3): the effects' parameters taken as
    independent, from their standard errors, with nothing absorbed by the GP (files
    without training regressors)."""
    out = np.zeros((samples.n, 3))
    for est in model.effects.values():
        base = effect_residual(samples, est, est.values)
        for pname, se in est.stderr.items():
            for j in range(se.size):
                if not (np.isfinite(se[j]) and se[j] > 0):
                    continue
                moved = {k: v.copy() for k, v in est.values.items()}
                moved[pname][j] += se[j]
                out += (effect_residual(samples, est, moved) - base) ** 2
    return out


def effect_residual(samples: Any, est: EffectEstimate, values: dict[str, np.ndarray]) -> np.ndarray:
    """Residual (n, 3) of one fitted effect at parameter ``values`` on a log's samples.

    Linear effects through their held regressors (at ``values`` moved from the
    estimate's, the coefficients the model predicts with moved as much); effects
    estimated by a 1-D search (lags, delay: :attr:`Effect.search`) through their
    exact form.
    """
    effect = est.effect
    if effect.search is not None:
        return samples.exact(est.name, float(values[effect.parameters[0].name][0]))
    if est.name not in samples.regressors:
        raise ValueError(f"samples lack the regressor of effect '{est.name}'")
    theta = est.theta
    if values is not est.values:
        theta = theta + effect.to_theta(values) - effect.to_theta(est.values)
    return samples.regressors[est.name] @ theta
