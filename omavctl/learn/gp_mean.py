"""The GP posterior mean of a model as one fused float32 matrix product.

:meth:`omavctl.learn.model.ResidualGP.gp_predict` evaluates the mean per axis
in float64; an open-loop rollout of thousands of windows calls it at every
step. Per axis ``a`` the kernel row is ``s_a^2 exp(-|z/l_a - Z_a|^2 / 2)``, whose
exponent is affine in ``x(z) = [z, q_0, q_1, q_2, 1]`` with
``q_a = |z / l_a|^2``:

    -|z/l_a - Z_aj|^2 / 2 = z . (Z_aj / l_a) - q_a / 2 - |Z_aj|^2 / 2

so all three axes' kernel rows are one GEMM ``x W`` ((B, d + 4) by
(d + 4, 3n)), an ``exp`` in place, and one GEMM with the block-diagonal
weights ``s_a^2 alpha_a`` ((3n, 3)). The same arrangement as the planner's
:class:`omavctl.planning.fused.FusedSamples`, for the mean alone, in the learn
layer so that ``evaluate`` can use it.

float32 inside: the weights of a model with little noise are large with
alternating signs, so the answer carries an absolute error of about
``1e-7 sum_j |k_j| |alpha_j|`` (``tests/test_horizons.py`` bounds it against
the float64 evaluation).
"""

from __future__ import annotations

import numpy as np

__all__ = ["FusedMean"]


class FusedMean:
    """The posterior mean (B, 3) of a :class:`~omavctl.learn.model.ResidualGP` at
    physical GP inputs (B, d), float32 inside (module docstring)."""

    def __init__(self, model) -> None:
        z_scaled, alpha = model.mean_weights  # (3, n, d), (3, n)
        n_axes, n, d = z_scaled.shape
        lengths = np.asarray(model.length_scales, dtype=float)  # (3, d)
        w = np.zeros((d + 4, n_axes * n))
        v = np.zeros((n_axes * n, n_axes))
        for a in range(n_axes):
            cols = slice(a * n, (a + 1) * n)
            w[:d, cols] = (z_scaled[a] / lengths[a]).T
            w[d + a, cols] = -0.5
            w[d + 3, cols] = -0.5 * np.einsum("nd,nd->n", z_scaled[a], z_scaled[a])
            v[cols, a] = model.signal_variance[a] * alpha[a]
        self._w = w.astype(np.float32)
        self._v = v.astype(np.float32)
        self._inv_sq = (1.0 / lengths**2).T  # (d, 3)
        self._mean = np.asarray(model.input_mean, dtype=float)
        self._scale = np.asarray(model.input_scale, dtype=float)
        self._c = np.asarray(model.target_mean, dtype=float)

    def __call__(self, z: np.ndarray) -> np.ndarray:
        """Mean (B, 3) rad/s^2 at physical GP inputs z (B, d)."""
        zn = (np.atleast_2d(np.asarray(z, dtype=float)) - self._mean) / self._scale
        x = np.empty((zn.shape[0], zn.shape[1] + 4), dtype=np.float32)
        x[:, : zn.shape[1]] = zn
        x[:, zn.shape[1] : zn.shape[1] + 3] = (zn**2) @ self._inv_sq
        x[:, -1] = 1.0
        p = x @ self._w
        np.minimum(p, 0.0, out=p)  # the exponent is -|.|^2 / 2: rounding only above 0
        np.exp(p, out=p)
        return self._c + (p @ self._v).astype(float)
