"""GP numerics for planning: shared kernels, pathwise posterior samples, rank updates.

The planner needs, for thousands of simulated states at once, (a) the model's
posterior mean (the controller inverts it), (b) a *consistent function
sample* from the GP posterior per simulation (the simulated "truth"), and
(c) the posterior variance at test points after adding hypothetical data,
without refitting. None of these is offered by a library for batched use, so
they are written here on top of the hyperparameters of a fitted
:class:`omavctl.learn.model.ResidualGP`.

Kernel (per axis a, normalised inputs z):
``k(z, z') = s_a^2 exp(-|(z - z') / l_a|^2 / 2)``, noise ``sigma_a^2``.

Pathwise conditioning (Wilson et al., 2020) with random Fourier features:
``f_m(z) = c_a + phi(z) w_m + k(z, Z) v_m`` with ``w_m ~ N(0, I)``,
``v_m = (K + sigma^2 I)^-1 (y - c_a - Phi(Z) w_m - eps_m)``,
``eps_m ~ N(0, sigma^2 I)``; ``phi(z) = s_a sqrt(2/D) cos(z Omega_a / l_a + b)``,
``Omega ~ N(0, I)``, ``b ~ U(0, 2 pi)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_solve, cholesky, solve_triangular

from omavctl.learn.validation import beyond_reach

__all__ = ["GPAxes", "PathwiseSamples", "posterior_variance_with_data", "se_kernel"]


def se_kernel(a: np.ndarray, b: np.ndarray, length: np.ndarray, variance: float) -> np.ndarray:
    """Squared-exponential kernel matrix (..., na, nb) of a (..., na, d) and b (..., nb, d).

    Squared distances by matrix products (|a|^2 + |b|^2 - 2 a.b), which is
    much faster than broadcast differences for large batches.
    """
    a = a / length
    b = b / length
    a2 = np.einsum("...id,...id->...i", a, a)
    b2 = np.einsum("...jd,...jd->...j", b, b)
    d2 = a2[..., :, None] + b2[..., None, :] - 2.0 * a @ np.swapaxes(b, -1, -2)
    return variance * np.exp(-0.5 * np.maximum(d2, 0.0))


@dataclass
class GPAxes:
    """Hyperparameters and training data of the three per-axis GPs.

    inputs (n, d) normalised; targets (n, 3); mean (3,); signal_variance (3,);
    length_scales (3, d); noise_variance (3,); latent_scale (3,) and beyond_scale
    (3,): fit's calibration of the band (:meth:`band_variance`; default 1 and 0,
    the kernel's own variance). Factorisations are built lazily.
    """

    inputs: np.ndarray
    targets: np.ndarray
    mean: np.ndarray
    signal_variance: np.ndarray
    length_scales: np.ndarray
    noise_variance: np.ndarray
    latent_scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    beyond_scale: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_model(cls, model) -> GPAxes:
        """From a :class:`omavctl.learn.model.ResidualGP` (inputs normalised here)."""
        return cls(
            inputs=model.normalise(model.inputs),
            targets=np.asarray(model.targets, float),
            mean=np.asarray(model.target_mean, float),
            signal_variance=np.asarray(model.signal_variance, float),
            length_scales=np.asarray(model.length_scales, float),
            noise_variance=np.asarray(model.noise_variance, float),
            latent_scale=np.asarray(model.latent_scale, float),
            beyond_scale=np.asarray(model.beyond_scale, float),
        )

    def __post_init__(self) -> None:
        n = self.inputs.shape[0]
        #: the training inputs' box, beyond which the band grows (:meth:`band_variance`)
        self.box = (self.inputs.min(axis=0), self.inputs.max(axis=0))
        self.chol = np.empty((3, n, n))
        self.alpha = np.empty((3, n))
        for a in range(3):
            k = self.kernel(a, self.inputs, self.inputs)
            k[np.diag_indices(n)] += self.noise_variance[a]
            self.chol[a] = cholesky(k, lower=True)
            self.alpha[a] = cho_solve((self.chol[a], True), self.targets[:, a] - self.mean[a])

    @property
    def n(self) -> int:
        return int(self.inputs.shape[0])

    @property
    def d(self) -> int:
        return int(self.inputs.shape[1])

    def kernel(self, axis: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """k_axis(a, b): (..., na, nb)."""
        return se_kernel(a, b, self.length_scales[axis], float(self.signal_variance[axis]))

    def posterior_mean(self, z: np.ndarray) -> np.ndarray:
        """Posterior mean (B, 3) at normalised inputs z (B, d)."""
        out = np.empty((z.shape[0], 3))
        for a in range(3):
            out[:, a] = self.mean[a] + self.kernel(a, z, self.inputs) @ self.alpha[a]
        return out

    def posterior_variance(self, z: np.ndarray) -> np.ndarray:
        """Latent posterior variance (B, 3) at normalised inputs z (B, d)."""
        out = np.empty((z.shape[0], 3))
        for a in range(3):
            v = solve_triangular(self.chol[a], self.kernel(a, self.inputs, z), lower=True)
            out[:, a] = self.signal_variance[a] - np.einsum("nb,nb->b", v, v)
        return np.maximum(out, 0.0)

    def band_variance(self, z: np.ndarray) -> np.ndarray:
        """Variance (B, 3) of the model's latent band at normalised inputs z (B, d).

        What :meth:`omavctl.learn.model.ResidualGP.latent` gives: the posterior
        variance times ``latent_scale``, plus ``beyond_scale s^2 sum_j (e_j / l_j)^2``
        beyond the training inputs' box
        (:func:`omavctl.learn.validation.beyond_envelope_variance`).

        Without the band's noise (``band_noise`` inside the fit flight's inputs, rising
        to ``noise_variance`` with growth terms beyond: :mod:`omavctl.learn.band`), on
        purpose: the planner's cost is what a flight's data can lower. Inside the
        inputs the noise is the same for every candidate and test point (no flight
        lowers the measurement noise), so adding it leaves the ranking as it is and
        only shrinks the stated fall: on the demo's plan 19 % against the task flown
        again would read 14 % (its mean ``band_noise`` 0.00097 beside costs of 0.0021
        and 0.0032 (rad/s^2)^2). The latent figure is the one measured right on
        average (expected +22.3 %, realised +21.1 % on the region's held-out flights,
        docs/informative.md). The noise's growth beyond the inputs would reward flights
        that reach far beyond the task, which refits measured to hurt (the tilt margin,
        docs/informative.md). Nor does it hold the variance ``mean_shrink`` adds
        (``gp_predict``'s latent variance is 7-29 % above this at the training inputs
        of the demo's and five scorecard models, ``benchmarks/planner_band.py``).
        """
        out = self.latent_scale * self.posterior_variance(z)
        for a in range(3):
            reach = beyond_reach(z, *self.box, self.length_scales[a])
            out[:, a] += self.beyond_scale[a] * self.signal_variance[a] * reach
        return out


class PathwiseSamples:
    """M consistent function samples of the posterior, evaluated in batches.

    ``evaluate(z, idx)`` gives sample ``idx[b]`` at ``z[b]`` together with the
    posterior mean at the same inputs (both (B, 3)), sharing the kernel rows.
    """

    def __init__(
        self, gp: GPAxes, n_samples: int, rng: np.random.Generator, n_features: int = 256
    ) -> None:
        self.gp = gp
        d, n = gp.d, gp.n
        self.omega = rng.standard_normal((3, d, n_features)) / gp.length_scales[:, :, None]
        self.phase = rng.uniform(0.0, 2.0 * np.pi, size=(3, n_features))
        self.scale = np.sqrt(2.0 * gp.signal_variance / n_features)  # (3,)
        self.w = rng.standard_normal((3, n_samples, n_features))
        eps = rng.standard_normal((3, n_samples, n)) * np.sqrt(gp.noise_variance)[:, None, None]
        self.v = np.empty((3, n_samples, n))
        for a in range(3):
            prior_at_data = self.features(a, gp.inputs) @ self.w[a].T  # (n, M)
            rhs = (gp.targets[:, a] - gp.mean[a])[:, None] - prior_at_data - eps[a].T
            self.v[a] = cho_solve((gp.chol[a], True), rhs).T

    def features(self, axis: int, z: np.ndarray) -> np.ndarray:
        """Random Fourier features (B, D) of axis ``axis`` at normalised z (B, d)."""
        return self.scale[axis] * np.cos(z @ self.omega[axis] + self.phase[axis])

    def mean(self, z: np.ndarray) -> np.ndarray:
        """Posterior mean (B, 3) at z (B, d) (no sample: skips the features)."""
        return self.gp.posterior_mean(z)

    def evaluate(self, z: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sample (B, 3), posterior mean (B, 3)) at z (B, d) for samples idx (B,)."""
        gp = self.gp
        sample = np.empty((z.shape[0], 3))
        mean = np.empty((z.shape[0], 3))
        for a in range(3):
            kz = gp.kernel(a, z, gp.inputs)  # (B, n)
            mean[:, a] = gp.mean[a] + kz @ gp.alpha[a]
            prior = np.einsum("bf,bf->b", self.features(a, z), self.w[a][idx])
            sample[:, a] = gp.mean[a] + prior + np.einsum("bn,bn->b", kz, self.v[a][idx])
        return sample, mean


def posterior_variance_with_data(
    gp: GPAxes, new_inputs: np.ndarray, test: np.ndarray, chunk: int = 256
) -> np.ndarray:
    """Posterior variance at ``test`` after adding ``new_inputs`` to the training set.

    new_inputs (B, m, d): B hypothetical data sets of m normalised inputs each;
    test (S, d). Returns (B, S, 3) latent variances. Targets are not needed.

    Rank-m update of the prior Cholesky factor L (K + sigma^2 I = L L^T), per
    data set: ``B1 = L^-1 K_ZX``, ``L22 = chol(K_XX + sigma^2 I - B1^T B1)``,
    ``var = var_prior - |L22^-1 (K_XS - B1^T L^-1 K_ZS)|^2``. Never refits.
    """
    n_sets, m, _ = new_inputs.shape
    out = np.empty((n_sets, test.shape[0], 3))
    for a in range(3):
        a_zs = solve_triangular(gp.chol[a], gp.kernel(a, gp.inputs, test), lower=True)  # (n, S)
        prior = gp.signal_variance[a] - np.einsum("ns,ns->s", a_zs, a_zs)
        noise = gp.noise_variance[a]
        for lo in range(0, n_sets, chunk):
            x = new_inputs[lo : lo + chunk]  # (b, m, d)
            b = x.shape[0]
            k_zx = gp.kernel(a, gp.inputs, x.reshape(-1, x.shape[-1]))  # (n, b*m)
            b1 = solve_triangular(gp.chol[a], k_zx, lower=True).reshape(-1, b, m)
            b1 = np.moveaxis(b1, 1, 0)  # (b, n, m)
            schur = gp.kernel(a, x, x) - np.swapaxes(b1, 1, 2) @ b1
            schur[:, np.arange(m), np.arange(m)] += noise
            l22 = np.linalg.cholesky(schur)  # (b, m, m)
            c = gp.kernel(a, x, test) - np.swapaxes(b1, 1, 2) @ a_zs  # (b, m, S)
            w = np.linalg.solve(l22, c)  # triangular, but batched solve is fine at m ~ 100
            out[lo : lo + b, :, a] = prior[None, :] - np.einsum("bms,bms->bs", w, w)
    return np.maximum(out, 0.0)
