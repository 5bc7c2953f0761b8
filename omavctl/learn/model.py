"""The residual model artifact: physical effects plus one GP per body axis.

The model predicts the angular-acceleration residual ``omega_dot_measured -
I^-1 (tau_cmd - omega x I omega)`` (rad/s^2, body frame) as

    residual(u, omega) = sum_e X_e(u, omega) theta_e  +  GP(z)

with ``u = [f/m, I^-1 tau]`` (B, 6) the scaled commanded wrench, ``X_e`` the
registry regressor of each fitted effect (:mod:`omavctl.physics.effects`) and
``z`` the GP input: ``u`` (6-D, features "wrench") or ``[u, omega]`` (9-D,
"wrench+rate"). Each axis has an independent GP with a squared-exponential ARD
kernel on normalised inputs ``zn = (z - input_mean) / input_scale``::

    k(a, b) = s^2 exp(-1/2 sum_j ((a_j - b_j) / l_j)^2),   y ~ GP(c, k) + N(0, sigma^2)

Predictions are computed here in numpy (Cholesky of ``K + sigma^2 I``), so
loading and using a model never needs scikit-learn.

The file that holds it (schema ``omavctl.model/2``): :mod:`omavctl.learn.model_file`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.linalg import cho_solve, cholesky, solve_triangular

from omavctl.learn.band import band_variance
from omavctl.learn.effects_band import effect_residual, parameter_variance
from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.mean_shrink import shrink_mean
from omavctl.learn.spread_band import SpreadBasis, spread_variance
from omavctl.learn.validation import beyond_envelope_variance
from omavctl.physics.effects import EffectContext
from omavctl.physics.rigid_body import cross
from omavctl.vehicle import Vehicle

__all__ = ["SCHEMA", "EffectEstimate", "ResidualGP"]

SCHEMA_NAME = "omavctl.model"
SCHEMA_VERSION = 2
SCHEMA = f"{SCHEMA_NAME}/{SCHEMA_VERSION}"
#: Written instead when an effect predicts with coefficients other than its parameters'
#: (``EffectEstimate.fitted``): a reader of version 2 would predict with the parameters.
SCHEMA_FITTED = f"{SCHEMA_NAME}/3"

#: Query rows per block in predictions (bounds the (B, n) kernel matrix).
_CHUNK = 4096


class ResidualGP:
    """Effects plus an independent GP per body axis (see module docstring).

    Built by :func:`omavctl.learn.fit.fit_model` or :func:`~.model_file.load_model`; the
    Cholesky factors and weights are computed once, at construction. Attributes
    (read-only by convention): ``vehicle``, ``features``, ``input_names`` (d,), ``inputs``
    (n, d), ``targets`` (n, 3), ``input_mean``/``input_scale`` (d,), ``target_mean``,
    ``signal_variance``, ``noise_variance`` (3,) (the GP's; the band's:
    ``band_noise``, ``band_scale``, ``band_slope``, ``*_growth`` (3,), :mod:`.band`),
    ``length_scales`` (3, d), ``effects``
    (name -> :class:`EffectEstimate`), ``provenance`` (dict).
    """

    def __init__(
        self,
        *,
        vehicle: Vehicle,
        features: str,
        input_names: tuple[str, ...],
        inputs: np.ndarray,
        targets: np.ndarray,
        input_mean: np.ndarray,
        input_scale: np.ndarray,
        target_mean: np.ndarray,
        signal_variance: np.ndarray,
        length_scales: np.ndarray,
        noise_variance: np.ndarray,
        band_noise: np.ndarray | None = None,
        band_scale: np.ndarray | None = None,
        band_slope: np.ndarray | None = None,
        torque_growth: np.ndarray | None = None,
        range_growth: np.ndarray | None = None,
        latent_scale: np.ndarray | None = None,
        beyond_scale: np.ndarray | None = None,
        mean_shrink: np.ndarray | None = None,
        rollout_gp: np.ndarray | None = None,
        effects: Mapping[str, EffectEstimate] | None = None,
        provenance: Mapping[str, Any] | None = None,
        train_regressors: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.features = features
        self.input_names = tuple(input_names)
        self.inputs = np.asarray(inputs, dtype=float)
        self.targets = np.asarray(targets, dtype=float)
        self.input_mean = np.asarray(input_mean, dtype=float)
        self.input_scale = np.asarray(input_scale, dtype=float)
        self.target_mean = np.asarray(target_mean, dtype=float)
        self.signal_variance = np.asarray(signal_variance, dtype=float)
        self.length_scales = np.asarray(length_scales, dtype=float)
        self.noise_variance = np.asarray(noise_variance, dtype=float)
        #: (3,) the band's noise variance inside the fit inputs (:mod:`omavctl.learn.band`)
        band = self.noise_variance if band_noise is None else np.asarray(band_noise, float)
        self.band_noise = np.minimum(band, self.noise_variance)
        #: (3,) the band inside the fit inputs (:mod:`omavctl.learn.band`; 1 and 0: as is)
        self.band_scale = np.ones(3) if band_scale is None else np.asarray(band_scale, float)
        self.band_slope = np.zeros(3) if band_slope is None else np.asarray(band_slope, float)
        #: (3,) the band's growth per rad/s^2 of commanded angular acceleration beyond the fit's
        self.torque_growth = (
            np.zeros(3) if torque_growth is None else np.asarray(torque_growth, float)
        )
        #: (3,) the band's growth (rad/s^2) per training range beyond the training box
        self.range_growth = np.zeros(3) if range_growth is None else np.asarray(range_growth, float)
        #: (3,) factor on the latent variance, fit's calibration (1: as the kernel says)
        self.latent_scale = np.ones(3) if latent_scale is None else np.asarray(latent_scale, float)
        #: (3,) weight on the variance gained beyond the training box (0: older files;
        #: :func:`~omavctl.learn.validation.beyond_envelope_variance`)
        self.beyond_scale = np.zeros(3) if beyond_scale is None else np.asarray(beyond_scale, float)
        #: (3,) weight of the latent variance against the squared GP mean (mean_shrink; 0: none)
        self.mean_shrink = np.zeros(3) if mean_shrink is None else np.asarray(mean_shrink, float)
        #: (3,) weight of the GP mean in open-loop rollouts (learn.rollout_check; 1: all)
        self.rollout_gp = np.ones(3) if rollout_gp is None else np.asarray(rollout_gp, float)
        self.effects: dict[str, EffectEstimate] = dict(effects or {})
        self.provenance: dict[str, Any] = dict(provenance or {})
        #: effect name -> regressor (n, 3, p) at the training points (may be empty)
        self.train_regressors: dict[str, np.ndarray] = {
            k: np.asarray(v, dtype=float) for k, v in (train_regressors or {}).items()
        }
        n, d = self.inputs.shape
        for name, reg in self.train_regressors.items():
            if reg.ndim != 3 or reg.shape[:2] != (n, 3):
                raise ValueError(f"regressor of '{name}' must be (n, 3, p), got {reg.shape}")
        if d != len(self.input_names):
            raise ValueError(f"inputs have {d} columns, input_names {len(self.input_names)}")
        if self.targets.shape != (n, 3) or self.length_scales.shape != (3, d):
            raise ValueError("targets must be (n, 3) and length_scales (3, d)")
        self._allocation: Any = None
        #: the rotors' thrust spread at the training points (:mod:`omavctl.learn.spread_band`)
        self.spread: SpreadBasis | None = None
        self._factorise(n)

    def _factorise(self, n: int) -> None:
        """Per axis: the inputs scaled by the length scales, the Cholesky factor of
        ``K + sigma^2 I`` (n training points) and the GP mean's weights."""
        zn = self.normalise(self.inputs)
        #: the training inputs' box (normalised), beyond which the band grows
        self._box = (zn.min(axis=0), zn.max(axis=0))
        self._z = zn[None, :, :] / self.length_scales[:, None, :]  # (3, n, d)
        self._z_sq = np.einsum("and,and->an", self._z, self._z)  # (3, n)
        self._chol = np.empty((3, n, n))
        self._alpha = np.empty((3, n))
        for a in range(3):
            k = self._kernel(a, self._z[a], self._z_sq[a])
            k[np.diag_indices(n)] += self.noise_variance[a]
            self._chol[a] = cholesky(k, lower=True)
            self._alpha[a] = cho_solve(
                (self._chol[a], True), self.targets[:, a] - self.target_mean[a]
            )

    # --------------------------------------------------------------- basics
    @property
    def n_train(self) -> int:
        """Number of training points."""
        return int(self.inputs.shape[0])

    @property
    def mean_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """Length-scaled training inputs (3, n, d) and weights (3, n) of the GP mean."""
        return self._z, self._alpha

    @property
    def gp_enabled(self) -> np.ndarray:
        """Per axis (3,) whether the GP is on; off (signal variance 0, ``fit``'s blocked
        cross-validation found it did not help): mean 0, constant variance."""
        return np.asarray(self.signal_variance > 0)

    @property
    def n_inputs(self) -> int:
        """GP input dimension d (6 or 9)."""
        return int(self.inputs.shape[1])

    @property
    def uses_rate(self) -> bool:
        """Whether predictions need body rates (rate features or any effect)."""
        return "rate" in self.features.split("+") or bool(self.effects)

    def normalise(self, z: np.ndarray) -> np.ndarray:
        """Normalised GP inputs (..., d) from physical inputs (..., d)."""
        return (z - self.input_mean) / self.input_scale

    @property
    def uses_command_rate(self) -> bool:
        """Whether the GP inputs include the command's rate of change (``dtorque``)."""
        return "dtorque" in self.features.split("+")

    def gp_inputs(
        self, u: np.ndarray, omega: np.ndarray | None = None, du: np.ndarray | None = None
    ) -> np.ndarray:
        """GP inputs z (B, d) from u (B, 6), omega (B, 3) for the "rate" features and du
        (B, 6) (rate of change of u, 1/s) for the "dtorque" features."""
        u = np.asarray(u, dtype=float)
        if u.shape[-1] != 6:
            raise ValueError(f"u must have 6 columns [f/m, I^-1 tau], got shape {u.shape}")
        parts = [u]
        names = self.features.split("+")
        if "rate" in names:
            if omega is None:
                raise ValueError("this model uses body rates: pass omega (B, 3)")
            parts.append(np.broadcast_to(omega, (*u.shape[:-1], 3)))
        if "dtorque" in names:
            if du is None:
                raise ValueError("this model uses the command's rate of change: pass du (B, 6)")
            parts.append(np.broadcast_to(np.asarray(du, dtype=float), u.shape)[..., 3:])
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=-1)

    def _kernel(self, axis: int, zq: np.ndarray, zq_sq: np.ndarray) -> np.ndarray:
        """k(zq, Z) (B, n) for length-scaled queries zq (B, d) with squared norms (B,).

        ``s^2 exp(zq . Z_j - |zq|^2 / 2 - |Z_j|^2 / 2)``, the exponent clamped at 0
        (rounding), built in place in one (B, n) array: a rollout calls it at every
        step, and the temporaries of the plain formula cost as much as its ``exp``.
        """
        k = zq @ self._z[axis].T
        k -= 0.5 * zq_sq[:, None]
        k -= 0.5 * self._z_sq[axis]
        np.minimum(k, 0.0, out=k)
        np.exp(k, out=k)
        k *= self.signal_variance[axis]
        return k

    # ----------------------------------------------------------- prediction
    def gp_predict(
        self, z: np.ndarray, noise: bool = False, variance: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """GP mean (B, 3) and variance (B, 3) (rad/s^2, (rad/s^2)^2) at inputs z (B, d).

        ``noise`` adds the band's noise (a new measurement, not the latent function:
        :func:`omavctl.learn.band.band_variance`);
        ``variance=False`` skips it (None). The mean is weighed by its band
        (``mean_shrink``, :mod:`omavctl.learn.mean_shrink`).
        """
        shrink = bool(np.any(self.mean_shrink > 0))
        mean, latent = self.latent(z, variance or shrink)
        var = latent
        if shrink:
            mean, added = shrink_mean(mean, latent, self.mean_shrink)
            var = latent + added
        if variance and noise:
            var = band_variance(self, z, var, latent)
        return mean, var if variance else None

    def latent(self, z: np.ndarray, variance: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The GP mean before ``mean_shrink`` (B, 3) and its calibrated latent variance
        (B, 3) (zero unless ``variance``): the posterior variance times ``latent_scale``
        plus the growth beyond the training box, at inputs z (B, d)."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        zn = self.normalise(z)
        mean, var = np.empty((z.shape[0], 3)), np.zeros((z.shape[0], 3))
        lo, hi = self._box
        # rows in chunks: the (B, n) kernel matrix of a long log would not fit otherwise
        for start in range(0, max(z.shape[0], 1), _CHUNK):
            rows = slice(start, start + _CHUNK)
            for a in range(3):
                zq = zn[rows] / self.length_scales[a]
                k = self._kernel(a, zq, np.einsum("bd,bd->b", zq, zq))
                mean[rows, a] = self.target_mean[a] + k @ self._alpha[a]
                if variance:  # k is not needed after: solve in place (a copy cost a third)
                    v = solve_triangular(
                        self._chol[a], k.T, lower=True, check_finite=False, overwrite_b=True
                    )
                    var[rows, a] = self.latent_scale[a] * np.maximum(
                        self.signal_variance[a] - np.einsum("nb,nb->b", v, v), 0.0
                    ) + self.beyond_scale[a] * beyond_envelope_variance(
                        zn[rows], lo, hi, self.signal_variance[a], self.length_scales[a]
                    )
        return mean, var

    def smooth(self, z: np.ndarray, values: np.ndarray) -> np.ndarray:
        """What the GP mean would predict at z (B, d) from training targets ``values``.

        values (n, 3, p): p alternative target columns per axis at the training
        points; returns (B, 3, p) = ``c + k(z, Z) (K + sigma^2 I)^-1 (values - c)``
        per axis with ``c`` the mean of ``values`` over the training points: the
        GP posterior mean is linear in its targets, including the target mean
        ``fit`` subtracts (a constant the GP carries everywhere, also where it
        extrapolates). ``evaluate`` uses it to know how much of an effect the
        GP has absorbed from its training data.
        """
        z = np.atleast_2d(np.asarray(z, dtype=float))
        zn = self.normalise(z)
        out = np.empty((z.shape[0], 3, values.shape[2]))
        for a in range(3):
            if not self.signal_variance[a] > 0:  # GP off: it absorbed nothing
                out[:, a, :] = 0.0
                continue
            zq = zn / self.length_scales[a]
            k = self._kernel(a, zq, np.einsum("bd,bd->b", zq, zq))
            c = values[:, a, :].mean(axis=0)
            out[:, a, :] = c + k @ cho_solve((self._chol[a], True), values[:, a, :] - c)
        return out

    def basis_estimate(
        self, values: np.ndarray, prior_std: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Parameters of an effect this model lacks, estimated as ``fit --effects`` would.

        values (n, 3, p): the effect's regressor at the training points, whose
        targets still contain the effect (the model was fitted without it).
        Mirrors ``fit``: ordinary least squares first, the GP's target mean
        taken after removing it, then the generalised least squares of the
        joint step (:func:`omavctl.learn.effect_fit.joint_effects`) with this model's
        hyperparameters and prior N(0, diag prior_std^2). Returns theta (p,)
        and its covariance (p, p). ``fit`` also re-optimises the
        hyperparameters and reselects its points from every sample: this is
        the estimate from the same training points and kernel.
        """
        n, _, p = values.shape
        ols, *_ = np.linalg.lstsq(values.reshape(3 * n, p), self.targets.reshape(3 * n), rcond=None)
        centre = (self.targets - values @ ols).mean(axis=0)
        a_mat = np.diag(1.0 / np.asarray(prior_std, dtype=float) ** 2)
        b_vec = np.zeros(p)
        for a in range(3):
            c = (self._chol[a], True)
            a_mat += values[:, a, :].T @ cho_solve(c, values[:, a, :])
            b_vec += values[:, a, :].T @ cho_solve(c, self.targets[:, a] - centre[a])
        cov = np.linalg.inv(a_mat)
        return cov @ b_vec, cov

    def predict(
        self,
        u: np.ndarray,
        omega: np.ndarray | None = None,
        noise: bool = False,
        du: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Residual mean (B, 3) rad/s^2 and variance (B, 3) at scaled wrenches u (B, 6).

        omega (B, 3) body rates in rad/s, needed when :attr:`uses_rate`. The mean
        includes the static effects (:meth:`effects_mean`); the variance is the
        GP's (latent function, plus sigma^2 with ``noise``).
        """
        u = np.atleast_2d(np.asarray(u, dtype=float))
        mean, var = self.gp_predict(self.gp_inputs(u, omega, du), noise=noise)
        assert var is not None
        if self.effects:
            mean = mean + self.effects_mean(u, omega)
        return mean, var

    def mean(
        self, u: np.ndarray, omega: np.ndarray | None = None, du: np.ndarray | None = None
    ) -> np.ndarray:
        """Residual mean (B, 3) rad/s^2 at u (B, 6), omega (B, 3): the controller's ``mu``."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        mean, _ = self.gp_predict(self.gp_inputs(u, omega, du), variance=False)
        if self.effects:
            mean = mean + self.effects_mean(u, omega)
        return mean

    # --------------------------------------------------------------- effects
    @property
    def allocation(self) -> Any:
        """The vehicle's :class:`~omavctl.physics.allocation.Allocation` (built on demand)."""
        if self._allocation is None:
            from omavctl.physics.allocation import Allocation

            self._allocation = Allocation(self.vehicle)
        return self._allocation

    def effects_residual(self, ctx: EffectContext) -> np.ndarray:
        """Residual (N, 3) rad/s^2 the fitted effects cause on a time series ``ctx``.

        Per sample, not filtered: for a log use
        :func:`omavctl.learn.signal.residual_samples` (its held regressors) and
        :meth:`predict_samples`.
        """
        out = np.zeros((ctx.omega.shape[0], 3))
        for est in self.effects.values():
            out += est.effect.regressor(ctx) @ est.theta
        return out

    def effects_mean(self, u: np.ndarray, omega: np.ndarray | None = None) -> np.ndarray:
        """Static part of the effects (B, 3) at single instants u (B, 6), omega (B, 3).

        Effects that act through the command history (servo and motor lag,
        command delay: those estimated by a 1-D search) contribute nothing here:
        an instant has no history (the rows of u are not a time series; a rotor
        list's motor-lag regressor would lag one row behind the other).
        """
        u = np.atleast_2d(np.asarray(u, dtype=float))
        static = [est for est in self.effects.values() if est.effect.search is None]
        if not static:
            return np.zeros((u.shape[0], 3))
        if omega is None:
            raise ValueError("this model has physical effects: pass omega (B, 3)")
        v = self.vehicle
        omega = np.broadcast_to(np.asarray(omega, dtype=float), (u.shape[0], 3))
        torque = u[:, 3:] @ v.inertia.T
        nominal = u[:, 3:] - cross(omega, omega @ v.inertia.T) @ v.inertia_inv.T
        ctx = EffectContext(
            omega=omega,
            force=u[:, :3] * v.mass,
            torque=torque,
            omega_dot_nominal=nominal,
            inertia=v.inertia,
            dt=1.0 / v.gains.rate_hz,
            allocation=self.allocation,
            derivative=np.zeros_like,
            torque_normalised=v.torque_normalised,
            fixed_rotors=v.motors is not None and not v.motors.tilting,
        )
        out = np.zeros((u.shape[0], 3))
        for est in static:
            out += est.effect.regressor(ctx) @ est.theta
        return out

    def predict_samples(
        self, samples: Any, noise: bool = False, variance: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Prediction (mean (n, 3), variance (n, 3)) for the residual of a log.

        ``samples``: :class:`omavctl.learn.signal.ResidualSamples` built with
        ``effects=`` this model's effect names (held regressors, held inputs),
        so that the prediction is filtered like the measured residual.
        ``variance=False`` skips the variance (None).
        """
        mean, var = self.gp_predict(samples.inputs(self.features), noise=noise, variance=variance)
        if var is not None:
            var = var + self.effects_variance(samples)
        return mean + self.effects_samples(samples), var

    def effects_variance(self, samples: Any) -> np.ndarray:
        """Variance (n, 3) the effects' parameter uncertainty (``diag(R Sigma R^T)``, the
        term of a GP with explicit basis functions, Rasmussen & Williams §2.7, eq. 2.42:
        :func:`omavctl.learn.effects_band.parameter_variance`) and the rotors' thrust
        spread (:func:`omavctl.learn.spread_band.spread_variance`) add to the prediction
        on a log's samples (zeros when the model has neither)."""
        return parameter_variance(self, samples) + spread_variance(self, samples)

    def basis_covariance(self, at_train: np.ndarray, prior_std: np.ndarray) -> np.ndarray:
        """Posterior covariance (P, P) of effect parameters with sensitivities at_train
        (m, 3, P) at the training points and prior stds (P,), this model's GP the model
        of what they leave: ``(B^-1 + sum_a H_a^T K_a^-1 H_a)^-1``, ``H_a`` centred on an
        axis whose GP is on (its target mean carries a constant)."""
        a_mat = np.diag(1.0 / np.asarray(prior_std, dtype=float) ** 2)
        for a in range(3):
            h = at_train[:, a, :]
            if self.gp_enabled[a]:
                h = h - h.mean(axis=0)
            a_mat += h.T @ cho_solve((self._chol[a], True), h)
        return np.asarray(np.linalg.inv(a_mat))

    @property
    def _fitted(self) -> bool:
        return any(est.fitted is not None for est in self.effects.values())

    def effects_samples(self, samples: Any) -> np.ndarray:
        """Residual (n, 3) the fitted effects cause on a log's samples (held).

        Linear effects through their held regressors; effects estimated by a
        1-D search (lags, delay: :attr:`Effect.search`) through their exact form.
        """
        out = np.zeros((samples.n, 3))
        for est in self.effects.values():
            out += effect_residual(samples, est, est.values)
        return out

    # ----------------------------------------------------------- persistence
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The file's arrays by key (:mod:`omavctl.learn.model_file` lists them)."""
        effects = {name: est.to_json() for name, est in sorted(self.effects.items())}
        return {
            "schema": np.array(SCHEMA_FITTED if self._fitted else SCHEMA),
            "features": np.array(self.features),
            "input_names": np.array(self.input_names),
            "train_inputs": self.inputs,
            "train_targets": self.targets,
            "input_mean": self.input_mean,
            "input_scale": self.input_scale,
            "target_mean": self.target_mean,
            "signal_variance": self.signal_variance,
            "length_scales": self.length_scales,
            "noise_variance": self.noise_variance,
            "band_noise": self.band_noise,
            "band_scale": self.band_scale,
            "band_slope": self.band_slope,
            "torque_growth": self.torque_growth,
            "range_growth": self.range_growth,
            "latent_scale": self.latent_scale,
            "beyond_scale": self.beyond_scale,
            "mean_shrink": self.mean_shrink,
            "rollout_gp": self.rollout_gp,
            "effects": np.array(json.dumps(effects, sort_keys=True)),
            "vehicle": np.array(self.vehicle.to_json()),
            "provenance": np.array(json.dumps(self.provenance, sort_keys=True)),
            **{f"regressor_{k}": v for k, v in sorted(self.train_regressors.items())},
            **(self.spread.arrays() if self.spread is not None else {}),
        }
