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

#: columns per padded block: a multiple of every BLAS kernel's tile width
_LANES = 64


class FusedSamples:
    """The M pathwise samples and the posterior mean of ``samples``, fused, float32.

    ``evaluate(z, m)`` takes normalised inputs z (d, R) (column-major batch, any
    float dtype) of one sample index m and returns (6, R) float64: rows 0-2 the
    sample, rows 3-5 the posterior mean. ``chunk`` (a multiple of 64) bounds the
    work buffer to (3D + 3n, chunk) float32 so that it stays in cache.

    A column's answer depends only on its place in the whole batch, to the bit,
    not on how the batch is split: every block is padded with zero columns to the
    same width (:meth:`set_batch`), so that every GEMM has one shape and BLAS one
    kernel (its kernels for other shapes and for ragged edges round differently),
    and a piece of the batch that starts at column ``offset`` of the whole puts each
    column where the whole would (column j at place (offset + j) mod width of its
    block): some BLAS kernels (OpenBLAS's Haswell SGEMM, for one) round a block's
    first and last columns differently from the others. ``plan`` relies on it: its
    results do not depend on how the candidates are split over ``--jobs``.
    """

    def __init__(self, samples: PathwiseSamples, chunk: int = 256) -> None:
        gp = samples.gp
        d, n = gp.d, gp.n
        n_samples, n_feat = samples.w.shape[1], samples.w.shape[2]
        if chunk % _LANES:
            raise ValueError(f"chunk must be a multiple of {_LANES}, got {chunk}")
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
        self.width = chunk

    def set_batch(self, columns: int) -> None:
        """Fix the block width for batches of up to ``columns`` columns: the smallest
        multiple of 64 that holds them, at most ``chunk``. Every GEMM of
        :meth:`evaluate` then has the same shape until the next call, so that a column's
        answer does not depend on how the batch was split (BLAS picks its kernels by
        shape, and they round differently)."""
        self.width = min(self.chunk, -(-max(columns, 1) // _LANES) * _LANES)

    def evaluate(
        self, z: np.ndarray, m: int, out: np.ndarray | None = None, offset: int = 0
    ) -> np.ndarray:
        """Sample m and posterior mean (6, R) float64 at normalised inputs z (d, R),
        columns ``offset`` to ``offset + R`` of the whole batch (see the class)."""
        d, r_count, wp = self.d, z.shape[1], self.width
        if out is None:
            out = np.empty((6, r_count))
        x, p, o = self._x[:, :wp], self._p[:, :wp], self._o[:, :wp]
        for start in range(-(offset % wp), r_count, wp):
            lo, hi = max(start, 0), min(start + wp, r_count)
            a, b = lo - start, hi - start  # the columns' places in the block
            x[:d, :a] = 0.0
            x[:d, a:b] = z[:, lo:hi]
            x[:d, b:] = 0.0
            np.matmul(self.inv_l2, x[:d] * x[:d], out=x[d : d + 3])
            x[d + 3] = 1.0
            np.matmul(self.w_t, x, out=p)
            np.cos(p[self._cos], out=p[self._cos])
            np.exp(p[self._exp], out=p[self._exp])
            np.matmul(self.v_t[m], p, out=o)
            out[:, lo:hi] = o[:, a:b]
        out[:3] += self.mean_offset[:, None]
        out[3:] += self.mean_offset[:, None]
        return out
