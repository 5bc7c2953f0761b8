"""Pathwise posterior samples as one fused float32 matrix product (the fast rollouts).

:class:`~omavctl.planning.gp.PathwiseSamples` evaluates, per axis ``a`` and
sample ``m``, ``f_m(z) = c_a + phi_a(z) w_am + k_a(z, Z) v_am`` and the
posterior mean ``c_a + k_a(z, Z) alpha_a``. Both are linear in two
elementwise maps of one affine function of ``x(z) = [z, q_x, q_y, q_z, 1]``
with ``q_a = |z / l_a|^2``:

* random features: ``cos(z Omega_a + b_a)`` (3 D columns),
* kernel rows: ``exp(z . Z_a / l_a^2 - q_a / 2 - |Z_a / l_a|^2 / 2)`` (3 n columns;
  the squared distance by matrix products, never broadcast differences).

So one step is ``P = W^T x`` ((3D + 3n, R) for R queries, one GEMM), ``cos`` and
``exp`` in place on its two row blocks, and ``out = V_m^T P`` ((6, R), one GEMM)
with ``V_m`` holding ``s_a sqrt(2/D) w_am``, ``s_a^2 v_am`` (rows 0-2: the
sample) and ``s_a^2 alpha_a`` (rows 3-5: the mean). The signal variance lives
in ``V`` only, so an axis with ``s_a^2 = 0`` (GP switched off) contributes
exactly ``c_a``.

Everything inside is float32: the step costs a fraction of float64 (cosine and
exponential dominate). The weights ``alpha`` and ``v`` of a model with little
noise are large with alternating signs, so the float32 answer carries an
absolute error of about ``1e-7 sum_j |k_j| |alpha_j|`` (about 1e-3 rad/s^2 on a
200-point model: far below the noise std); ``tests/test_planning_numerics.py``
bounds it against the float64 evaluation.
"""

from __future__ import annotations

import numpy as np

from omavctl.planning.gp import PathwiseSamples

__all__ = ["FusedSamples"]


class FusedSamples:
    """The M pathwise samples and the posterior mean of ``samples``, fused, float32.

    ``evaluate(z, m)`` takes normalised inputs z (d, R) (column-major batch, any
    float dtype) of one sample index m and returns (6, R) float64: rows 0-2 the
    sample, rows 3-5 the posterior mean. ``chunk`` bounds the work buffer to
    (3D + 3n, chunk) float32 so that it stays in cache.
    """

    def __init__(self, samples: PathwiseSamples, chunk: int = 256) -> None:
        gp = samples.gp
        d, n = gp.d, gp.n
        n_samples, n_feat = samples.w.shape[1], samples.w.shape[2]
        self.d, self.n, self.features, self.chunk = d, n, n_feat, chunk
        self.mean_offset = np.asarray(gp.mean, float)
        rows = 3 * n_feat + 3 * n
        w_t = np.zeros((rows, d + 4))
        v_t = np.zeros((n_samples, 6, rows))
        for a in range(3):
            f = slice(a * n_feat, (a + 1) * n_feat)
            k = slice(3 * n_feat + a * n, 3 * n_feat + (a + 1) * n)
            zl = gp.inputs / gp.length_scales[a]
            w_t[f, :d] = samples.omega[a].T
            w_t[f, d + 3] = samples.phase[a]
            w_t[k, :d] = zl / gp.length_scales[a]
            w_t[k, d + a] = -0.5
            w_t[k, d + 3] = -0.5 * np.einsum("nd,nd->n", zl, zl)
            s2 = float(gp.signal_variance[a])
            v_t[:, a, f] = samples.scale[a] * samples.w[a]
            v_t[:, a, k] = s2 * samples.v[a]
            v_t[:, 3 + a, k] = s2 * gp.alpha[a]
        self.inv_l2 = (1.0 / gp.length_scales**2).astype(np.float32)  # (3, d)
        self.w_t = np.ascontiguousarray(w_t, dtype=np.float32)  # (rows, d + 4)
        self.v_t = np.ascontiguousarray(v_t, dtype=np.float32)  # (M, 6, rows)
        self._cos = slice(0, 3 * n_feat)
        self._exp = slice(3 * n_feat, rows)
        self._x = np.empty((d + 4, chunk), np.float32)
        self._p = np.empty((rows, chunk), np.float32)
        self._o = np.empty((6, chunk), np.float32)

    def evaluate(self, z: np.ndarray, m: int, out: np.ndarray | None = None) -> np.ndarray:
        """Sample m and posterior mean (6, R) float64 at normalised inputs z (d, R)."""
        d, r_count = self.d, z.shape[1]
        if out is None:
            out = np.empty((6, r_count))
        for lo in range(0, r_count, self.chunk):
            hi = min(lo + self.chunk, r_count)
            w = hi - lo
            x, p, o = self._x[:, :w], self._p[:, :w], self._o[:, :w]
            x[:d] = z[:, lo:hi]
            np.matmul(self.inv_l2, x[:d] * x[:d], out=x[d : d + 3])
            x[d + 3] = 1.0
            np.matmul(self.w_t, x, out=p)
            np.cos(p[self._cos], out=p[self._cos])
            np.exp(p[self._exp], out=p[self._exp])
            np.matmul(self.v_t[m], p, out=o)
            out[:, lo:hi] = o
        out[:3] += self.mean_offset[:, None]
        out[3:] += self.mean_offset[:, None]
        return out
