"""What the rotors' thrust spread can make an effect's estimate look like.

No two rotors of a batch push alike: each rotor's thrust coefficient is off by a few
per cent (the vehicle's ``rotor.thrust_tolerance``, one standard deviation, ``s``).
The torque of such a spread follows the flight's thrusts, and its shape is close to
that of several effects: near hover a weak rotor is a constant roll/pitch torque,
which a centre-of-mass offset also makes; across attitudes it moves with the
force as ``r x f`` does. A least-squares estimate ``theta = A^+ y`` (``A`` (3n, p) the
stacked effect regressors) then carries ``A^+ M delta``: ``M`` (3n, R) the residual
of each rotor's thrust error (rad/s^2 per unit fraction, :func:`rotor_sensitivity`),
``delta`` ~ N(0, s^2 I) the vehicle's unknown spread. Flying longer does not average
it away (the same rotors fly every flight), so it is no part of the standard error:
it is the estimate's *systematic* part, ``s^2 (A^+ M)(A^+ M)^T``
(:func:`spread_covariance`), reported beside the standard error and added to the 95 %
interval of the parameter's physical value (:class:`omavctl.learn.estimate.EffectEstimate`).

Measured on the project's simulator (docs/intervals.md, "The rotors' thrust spread"):
six vehicles whose spread is drawn at 3 %, no centre-of-mass offset, steps and wobble
flights: ``com_offset`` fitted at -0.92 ... 3.8 mm on r_x, r_y with standard errors of
0.3-1.0 mm (up to 6 standard errors from the truth, 0), against a systematic part of
1.85 mm from this module.

Effects whose parameters *are* the spread (``motor_loss``, ``arm_thrust``) get no
systematic part.
A log without per-motor outputs gets none when the rotors' thrusts cannot be
computed from its commands (a fixed-rotor vehicle, a normalised command); with them
it gets one whatever the command's units (the wrench was mixed from those outputs).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effect_base import EffectContext
from omavctl.physics.effects import get_effect
from omavctl.physics.motor_effects import rotor_residuals

__all__ = ["SPREAD_ESTIMANDS", "rotor_sensitivity", "spread_covariance"]

#: Effects whose parameters estimate the spread itself: no systematic part.
SPREAD_ESTIMANDS = frozenset({"motor_loss", "arm_thrust"})


def rotor_sensitivity(ctx: EffectContext) -> np.ndarray | None:
    """Residual (N, 3, R) rad/s^2 of each rotor's thrust raised by its own thrust (a
    unit fractional error of rotor i alone): from the per-motor thrusts where the log
    has them, else from the omav's allocation of the commanded wrench (coaxial pairs
    split equally); None for a fixed-rotor vehicle without per-motor outputs or a
    normalised command (its wrench is in unknown units)."""
    if ctx.motor is not None:
        return rotor_residuals(ctx.motor.thrust, ctx.motor.torque, ctx.inertia_inv)
    vehicle = ctx.allocation.vehicle
    if ctx.fixed_rotors or ctx.torque_normalised or vehicle.force_normalised:
        return None  # no thrusts, or commands in unknown units: no thrusts to spread
    tilt, arm = ctx.arm_tilt, ctx.allocated[1]
    rotor = np.repeat(arm / 2.0, 2, axis=-1)
    return rotor_residuals(rotor, lambda t: ctx.allocation.forward(tilt, t)[:, 3:], ctx.inertia_inv)


def _tolerance(samples: Sequence[ResidualSamples]) -> float:
    """The vehicle's thrust tolerance (0 without effect contexts)."""
    for s in samples:
        for ctx, _ in s.contexts[:1]:
            return ctx.allocation.vehicle.thrust_tolerance
    return 0.0


def spread_covariance(
    samples: Sequence[ResidualSamples], x: np.ndarray, names: Sequence[str]
) -> np.ndarray | None:
    """Systematic covariance (p, p) that the vehicle's thrust spread gives the least-
    squares estimate of the stacked effect parameters with regressors x (n, 3, p) on
    ``samples`` (the same n samples): ``s^2 B B^T``, ``B = A^+ M``; the rows and columns
    of :data:`SPREAD_ESTIMANDS` zero. None when the tolerance is 0 or a log has no
    rotor thrusts to compute ``M`` from."""
    tol = _tolerance(samples)
    if tol <= 0.0 or x.size == 0:
        return None
    parts = [s.held_of(rotor_sensitivity) for s in samples]
    if any(m is None for m in parts):
        return None
    m = np.concatenate([p for p in parts if p is not None])
    n, _, p = x.shape
    if m.shape[0] != n:
        return None
    b = np.linalg.pinv(x.reshape(3 * n, p)) @ m.reshape(3 * n, m.shape[2])
    cov = tol**2 * (b @ b.T)
    k = 0
    for name in names:
        size = get_effect(name).n_theta
        if name in SPREAD_ESTIMANDS:
            cov[k : k + size, :] = 0.0
            cov[:, k : k + size] = 0.0
        k += size
    return np.asarray(cov)
