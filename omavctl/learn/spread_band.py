"""The band's share of the rotors' thrust spread on a flight the model was not fitted on.

No two rotors push alike (the vehicle's ``rotor.thrust_tolerance``, ``s``, one standard
deviation per rotor): the fit flight's residual holds the spread's torque ``M delta``
(``M`` (n, 3, R) each rotor's residual per unit fractional thrust error,
:func:`omavctl.learn.spread.rotor_sensitivity`; ``delta`` ~ N(0, s^2 I) the vehicle's
unknown spread). The model takes it in two places: its linear effects' least-squares
estimates carry ``G delta`` (``G = A^+ M`` (P, R), ``A`` their stacked regressors over the
fit flight: a ``com_offset`` takes the spread's roll and pitch torque at hover), and its
GP mean carries what is left at the training points. On another flight the spread's
torque is ``M* delta``, while the model predicts ``H* G delta`` through the effects and
``k* K^-1 (M - H G) delta`` through the GP (``smooth``): the error left is ``Q delta`` with

    ``Q = (M* - smooth(M)) - (H* - smooth(H)) G``      (n, 3, R),

whose variance ``s^2 sum_r Q[:, :, r]^2`` this module adds to the band, weighted by the
GP's distance from its training points (:func:`gp_distance`: near them the band,
calibrated on the fit flight's held-out blocks, already holds the GP's error on targets
that held the spread's torque; counted there too, it made a well-specified model's band
cover 0.996 of a flight inside its fit flight's inputs, tests/test_band_inside.py). On
the fit flight's own inputs both brackets are near zero; where the new flight tilts the
arms to push sideways, a ``com_offset`` fitted on the spread's hover torque predicts a
yaw torque ``r x f`` the spread does not make, and this term says how far off that can
be (measured on the tune splits: docs/scorecard.md, session 28). It is the prior's
spread, not a posterior: the fit flight's residual does hold information on ``delta``,
but the GP takes it first (an explicit basis for ``delta`` in the GP with the fitted
hyperparameters moved one draw's yaw error half-way and another's not at all;
docs/intervals.md).

Computed in ``fit`` (:func:`spread_basis`: ``M`` at the training points and ``G``) and
stored in the model file (``spread_train`` (n, 3, R), ``spread_gain`` (P, R), P the
sizes of the model's linear effects, sorted by name); a file without them, a
vehicle without a tolerance, or a log whose rotor thrusts cannot be computed gets
no term. None of it moves the mean.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import ModelError
from omavctl.learn.signal import ResidualSamples
from omavctl.learn.spread import rotor_sensitivity
from omavctl.physics.effects import get_effect

__all__ = [
    "SpreadBasis",
    "gp_distance",
    "linear_names",
    "read_spread",
    "spread_basis",
    "spread_variance",
]


@dataclass
class SpreadBasis:
    """``M`` at the training points, ``train`` (n, 3, R), and the linear effects' share
    of the spread, ``gain`` (P, R) (P = 0: no linear effect)."""

    train: np.ndarray
    gain: np.ndarray

    def arrays(self) -> dict[str, np.ndarray]:
        """The model file's keys."""
        return {"spread_train": self.train, "spread_gain": self.gain}


def linear_names(effects: Sequence[str]) -> list[str]:
    """The effects estimated by least squares (not a 1-D search), sorted by name (the
    order of ``spread_gain``'s rows: a model file holds its effects sorted)."""
    return sorted(n for n in effects if get_effect(n).search is None)


def _sensitivity(samples: Sequence[ResidualSamples]) -> np.ndarray | None:
    parts = [s.held_of(rotor_sensitivity) for s in samples]
    if not parts or any(m is None for m in parts):
        return None
    return np.concatenate([p for p in parts if p is not None])


def spread_basis(
    samples: Sequence[ResidualSamples],
    idx: np.ndarray,
    effects: Sequence[str],
    tolerance: float,
    prior: SpreadBasis | None = None,
    n_prior: int = 0,
) -> SpreadBasis | None:
    """The spread's basis of a model fitted on ``samples`` with training points ``idx``
    (into the samples' concatenation) after ``n_prior`` points of a prior model (whose
    basis ``prior`` goes first; None without one) and the named ``effects``; None when
    the tolerance is 0 or the rotors' thrusts cannot be computed."""
    m = _sensitivity(samples)
    if tolerance <= 0.0 or m is None or (n_prior and prior is None):
        return None
    train = m[idx]
    if prior is not None:
        if prior.train.shape[2] != train.shape[2]:
            return None
        train = np.concatenate([prior.train, train])
    names = linear_names(effects)
    if not names:
        return SpreadBasis(train, np.zeros((0, m.shape[2])))
    x = np.concatenate([np.concatenate([s.regressors[n] for s in samples]) for n in names], -1)
    n, _, p = x.shape
    gain = np.linalg.pinv(x.reshape(3 * n, p)) @ m.reshape(3 * n, m.shape[2])
    return SpreadBasis(train, np.asarray(gain))


def spread_variance(model: Any, samples: ResidualSamples) -> np.ndarray:
    """Variance (n, 3) the rotors' thrust spread adds to ``model``'s prediction on a
    log's samples: ``s^2 sum_r Q_r^2`` times the GP's distance from its training points
    (module docstring); zeros without a basis, a tolerance or the rotors' thrusts."""
    out = np.zeros((samples.n, 3))
    basis: SpreadBasis | None = model.spread
    tol = model.vehicle.thrust_tolerance
    if basis is None or tol <= 0.0 or samples.n == 0:
        return out
    m = samples.held_of(rotor_sensitivity)
    if m is None or m.shape[2] != basis.train.shape[2]:
        return out
    z = samples.inputs(model.features)
    q = m - model.smooth(z, basis.train)
    names = linear_names(list(model.effects))
    if names and basis.gain.shape[0]:
        h = np.concatenate([samples.regressors[n] for n in names], -1)
        ht = np.concatenate([model.train_regressors[n] for n in names], -1)
        q -= np.einsum("nap,pr->nar", h - model.smooth(z, ht), basis.gain)
    return np.asarray(tol**2 * np.einsum("nar,nar->na", q, q) * gp_distance(model, z))


def gp_distance(model: Any, z: np.ndarray) -> np.ndarray:
    """The GP's distance (B, 3) from its training points at inputs z (B, d): its latent
    variance over its prior, at most 1 (0 at the training points; 1 on an axis whose GP
    is off, which carries nothing back). Near the training points the band, calibrated
    on the fit flight's held-out blocks, already holds the GP's error on targets that
    held the spread's torque."""
    _, latent = model.latent(z)
    prior = np.asarray(model.latent_scale * model.signal_variance, dtype=float)
    on = prior > 0
    return np.where(on, np.minimum(latent / np.where(on, prior, 1.0), 1.0), 1.0)


def read_spread(
    arrays: Any,
    n: int,
    effects: Sequence[str],
    floats: Callable[[Any, str, tuple[int, ...], Path], np.ndarray],
    path: Path,
) -> SpreadBasis | None:
    """The optional ``spread_train`` (n, 3, R) and ``spread_gain`` (P, R) of a model file
    with n training points and ``effects`` (P their linear effects' sizes), checked by
    ``floats`` (the file's number reader); None when absent."""
    if "spread_train" not in arrays:
        return None
    if "spread_gain" not in arrays or arrays["spread_train"].ndim != 3:
        raise ModelError("key 'spread_train' needs 'spread_gain' and must be (n, 3, R)", path)
    rotors = arrays["spread_train"].shape[2]
    size = sum(get_effect(e).n_theta for e in linear_names(effects))
    train = floats(arrays, "spread_train", (n, 3, rotors), path)
    return SpreadBasis(train, floats(arrays, "spread_gain", (size, rotors), path))
