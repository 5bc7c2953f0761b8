"""Torque effects fitted beside an inertia scale, reported in physical units.

The registry's regressors turn an effect's torque into an angular acceleration
with the *nominal* inertia (``I^-1 tau_e``). Beside ``inertia_error`` the true
inertia is ``diag(scale) I``, so the vehicle feels ``diag(g) I^-1 tau_e`` with
``g = 1 / scale = 1 + theta_I`` per axis (a diagonal inertia), while the additive
linear model fits ``I^-1 tau_e'``: a torque effect beside the scale comes out as
seen through the nominal inertia (a drag ``D`` as ``D / scale``, a CoM offset's
``r_y`` as ``r_y / scale_x``). With scales 0.7-1.4 that is a 30 % bias, far
outside intervals of a few per cent (the scorecard's report5 misses of drag and
CoM offset beside an inertia scale, docs/intervals.md).

The model keeps predicting with the additive coefficients ``theta'`` (what it
was fitted with); the reported parameters are the physical ones: over the fit's
samples the additive model ``X_T theta'_T`` is the least-squares projection of
``diag(g) X_T theta_T`` (``X_T`` the torque effects' regressors), so
``theta'_T = M(g) theta_T`` with ``M(g) = (X_T^T X_T)^-1 sum_k g_k X_Tk^T X_Tk``
(``X_Tk`` the axis-k rows; for a drag ``M = diag(g)`` exactly), and
``theta_T = M(g)^-1 theta'_T``. Its covariance is the delta method through the
joint covariance of ``theta'`` and ``theta_I``: the scale's uncertainty and its
correlation with the torque effect enter each member's interval.

Only for a torque command in N m (``torque_normalised`` false): a normalised
command's gain already holds the inertia, and the physical split is not seen.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from omavctl.physics.effects import get_effect

__all__ = ["GAIN", "TORQUE_EFFECTS", "PhysicalMap", "physical_map", "to_physical"]

#: The effect whose scale divides every torque the vehicle feels.
GAIN = "inertia_error"
#: Linear effects that add a body torque (or change the rotors' thrust, and so the
#: torque): the true inertia divides them. Not ``gyro_bias`` (a sensor error), and not
#: the motor-level effects (``motor_loss``, ``thrust_curve``, ``battery_sag``): beside
#: them ``inertia_error`` is the rotors' common torque gain, which no log tells from an
#: inertia (a loss shared by every rotor is that gain, omavctl.physics.motor_effects),
#: and their parameters are defined relative to it, i.e. the additive ones. A quad with
#: one motor 15 % weak (mean loss 3.75 %) fits a scale of 1.039; dividing by it put the
#: loss 12 standard errors off (tests/test_motor_effects.py).
TORQUE_EFFECTS = frozenset({"rotational_drag", "com_offset", "rotor_interference"})


@dataclass(frozen=True)
class PhysicalMap:
    """What :func:`to_physical` needs of a fit's samples: the stacked-theta columns of
    the inertia scale (3,) and of the torque effects (q,), ``(X_T^T X_T)^+`` (q, q)
    and the per-axis ``X_Tk^T X_Tk`` (3, q, q)."""

    gain: np.ndarray
    torque: np.ndarray
    a_inv: np.ndarray
    b: np.ndarray


def physical_map(x: np.ndarray, names: Sequence[str], normalised: bool) -> PhysicalMap | None:
    """The map of the stacked regressors x (n, 3, p) of the linear effects ``names``
    (in order); None unless ``inertia_error`` is fitted beside a torque effect on a
    torque command in N m (``normalised`` false)."""
    if normalised or GAIN not in names:
        return None
    cols: dict[str, np.ndarray] = {}
    start = 0
    for name in names:
        size = get_effect(name).n_theta
        cols[name] = np.arange(start, start + size)
        start += size
    torque = [cols[n] for n in names if n in TORQUE_EFFECTS]
    if not torque:
        return None
    idx = np.concatenate(torque)
    xt = x[:, :, idx]
    b = np.einsum("nkp,nkq->kpq", xt, xt)
    return PhysicalMap(cols[GAIN], idx, np.linalg.pinv(b.sum(axis=0)), b)


def to_physical(
    theta: np.ndarray, cov: np.ndarray, pm: PhysicalMap | None
) -> tuple[np.ndarray, np.ndarray]:
    """The stacked theta (p,) and its covariance (p, p) with the torque effects'
    entries in physical units (module docstring); unchanged without a map or where
    the inertia scale is not a positive finite number."""
    if pm is None:
        return theta, cov
    g = 1.0 + theta[pm.gain]
    if not (np.all(np.isfinite(g)) and np.all(g > 0) and np.all(np.isfinite(cov))):
        return theta, cov
    m_inv = np.linalg.pinv(pm.a_inv @ np.einsum("k,kpq->pq", g, pm.b))
    phys = m_inv @ theta[pm.torque]
    out = np.array(theta, dtype=float, copy=True)
    out[pm.torque] = phys
    jac = np.eye(theta.size)
    jac[np.ix_(pm.torque, pm.torque)] = m_inv
    for k, col in enumerate(pm.gain):
        jac[pm.torque, col] = -m_inv @ pm.a_inv @ pm.b[k] @ phys
    return out, jac @ cov @ jac.T
