"""The effects objective: flights that pin down and tell apart named physical effects.

``plan --objective effects`` scores a candidate by what its flight would teach
``fit`` about the parameters ``theta`` of the named effects
(:mod:`omavctl.physics.effects`), D-optimally: the cost of a simulation is

    -log det( S (F_model + F_flight) S )

with ``S = diag(scale)`` (parameters relative to their size, so the number is
unit-free; the scaling shifts every cost by the same constant and never changes
the ranking). ``F`` is the information ``fit`` has about ``theta`` in its joint
estimate of effects and GP (generalised least squares, :func:`omavctl.learn.fit.joint_effects`):
per axis ``a`` the regressors ``X_a`` at the training points, weighted by the
inverse GP covariance ``K_a = s_a^2 k(Z, Z) + sigma_a^2 I``, so a regressor the
GP would explain as well (a smooth function of its inputs near its data) counts
for little, and the GP's noise variance is the noise:

* ``F_model = sum_a X_a^T K_a^-1 X_a + B^-1``: the model's training points
  (their regressors are stored in the model, ``regressor_<name>``) and fit's
  prior ``B`` (each effect's ``prior_std``); its inverse gives the standard
  errors ``fit`` wrote for the linear effects (to within the change of the GP's
  variances by fit's cross-validation, which comes after the joint estimate).
* ``F_flight``: the information the flight's points add (the points ``fit``
  would pick, :func:`~omavctl.planning.scoring.batched_pick_indices`), by a
  rank-m update of the same GLS: with ``B_a = L_a^-1 K_ZX``, the residual
  regressor ``R_a = X_X - B_a^T L_a^-1 X_Z`` (what the old points' regressors do
  not already predict) and ``Q_a = K_XX + sigma_a^2 I - B_a^T B_a``,
  ``F_flight = sum_a R_a^T Q_a^-1 R_a``.

The regressors along a simulated flight come from the GP inputs the planner
records at every ``stride``-th step (scaled commanded wrench, body rates),
through the registry's own regressor code; time derivatives (command delay,
lags) by central differences on that grid. Effects estimated by a 1-D search
(delay, lags) enter through their first-order form ``-T d/dt``: its column is
the Jacobian of the exact form with respect to the parameter (up to the shift
by the parameter itself, which changes a flight's sums of squares very little).

Besides the cost, every simulation reports the expected relative standard
errors (geometric mean over the parameters) and the largest correlation
between parameters of *different* effects in ``(F_model + F_flight)^-1`` (how
far the flight tells the effects apart).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.linalg import solve_triangular

from omavctl.base.errors import OmavctlError
from omavctl.physics.effects import EFFECTS, EffectContext, get_effect
from omavctl.physics.rigid_body import cross
from omavctl.planning.gp import GPAxes
from omavctl.planning.scoring import Flights, batched_pick_indices

__all__ = [
    "EffectsObjective",
    "EffectsPrior",
    "effects_from_evaluation",
    "parameter_labels",
    "resolve_effects",
]

#: Effects whose regressor needs the body rate (the model's GP inputs must hold it).
_NEEDS_RATE = ("rotational_drag", "inertia_error", "gyro_bias")


def effects_from_evaluation(path: str | Path) -> tuple[str, ...]:
    """Effects an evaluation JSON names as missing, then those ambiguous with them.

    ``diagnosis.missing`` best first, then every ``ambiguous_with`` entry of a
    ``missing_effects`` candidate that is missing (each name once).
    """
    p = Path(path)
    try:
        tree = json.loads(p.read_text())
        diagnosis = tree["diagnosis"]
        names = [str(n) for n in diagnosis["missing"]]
        for cand in diagnosis.get("missing_effects", []):
            if cand.get("name") in names:
                names += [str(n) for n in cand.get("ambiguous_with", [])]
    except OSError as exc:
        raise OmavctlError(f"cannot read the evaluation: {exc.strerror}", p) from None
    except (ValueError, KeyError, TypeError, AttributeError):
        raise OmavctlError(
            "not an evaluation JSON of omavctl evaluate (no diagnosis.missing)", p
        ) from None
    return tuple(dict.fromkeys(n for n in names if n in EFFECTS))


def resolve_effects(model, named: Sequence[str]) -> tuple[str, ...]:
    """The effects to plan for: ``named``, else the model's fitted effects.

    Raises OmavctlError for unknown or unidentifiable effects, effects that need
    body rates the model's GP inputs lack, and when nothing is named or fitted.
    """
    names = tuple(dict.fromkeys(named)) or tuple(sorted(model.effects))
    names = tuple(n for n in names if named or get_effect(n).identifiable)
    if not names:
        raise OmavctlError(
            "--objective effects needs effects: name them with --effects, or pass an "
            "--evaluation that names missing effects, or a model fitted with --effects"
        )
    for name in names:
        if name not in EFFECTS:
            known = ", ".join(sorted(EFFECTS))
            raise OmavctlError(f"--effects: unknown effect '{name}' (known: {known})")
        if not get_effect(name).identifiable:
            raise OmavctlError(f"--effects: {name} cannot be identified from angular accelerations")
        if name in _NEEDS_RATE and "rate" not in model.features.split("+"):
            raise OmavctlError(
                f"--effects {name} needs body rates among the model's GP inputs "
                f"(the model was fitted with --features {model.features}; refit with +rate)"
            )
        if name not in model.train_regressors:
            raise OmavctlError(
                f"the model stores no regressor of {name} at its training points "
                "(fitted by an older omavctl): refit it to plan for effects"
            )
    return names


def parameter_labels(names: Sequence[str]) -> list[str]:
    """A label per estimation parameter theta of ``names``: ``effect.parameter`` with
    ``_x``/``_y``/``_z`` for a body-axis triple (as the reports write them) or ``[i]``.

    An effect whose theta is not its physical parameter (``inertia_error``: theta =
    1/scale - 1) is labelled ``theta`` so that no value is read in the wrong unit.
    """
    from omavctl.physics.effect_base import Effect

    out = []
    for name in names:
        eff = get_effect(name)
        physical = type(eff).to_theta is Effect.to_theta
        for p in eff.parameters:
            base = f"{name}.{p.name if physical else 'theta'}"
            if p.size == 3:
                out += [f"{base}_{a}" for a in "xyz"]
            else:
                out += [base + (f"[{i}]" if p.size > 1 else "") for i in range(p.size)]
    return out


@dataclass(frozen=True)
class EffectsPrior:
    """What the model already knows about theta of ``names``: values (p,), the scale
    (p,) parameters are measured in, and the information ``F_model`` (p, p) in scaled
    units."""

    names: tuple[str, ...]
    values: np.ndarray
    scale: np.ndarray
    information: np.ndarray
    #: names of the effects the model has fitted (the others start at fit's prior, 0)
    fitted: tuple[str, ...] = ()
    #: standard errors (p,) of theta that ``fit`` stored (a lag's or delay's from its
    #: 1-D search over every sample); NaN where not fitted or not determined
    fit_stderr: np.ndarray | None = None
    #: the part (p,) of theta's uncertainty that the rotors' thrust spread gives it (0
    #: where none): the same for every flight of the vehicle, no plan lowers it
    fit_systematic: np.ndarray | None = None

    @classmethod
    def from_model(cls, model, gp: GPAxes, names: Sequence[str]) -> EffectsPrior:
        """GLS information of the model's training points plus fit's prior (module doc).

        Scale: ``|theta|`` of a fitted effect, at least a tenth of its ``prior_std``;
        ``prior_std`` for an effect the model has not fitted.
        """
        values, scale, prior = [], [], []
        for name in names:
            eff = get_effect(name)
            std = np.full(eff.n_theta, eff.prior_std)
            theta = model.effects[name].theta if name in model.effects else np.zeros(eff.n_theta)
            theta = np.where(np.isfinite(theta), theta, 0.0)
            values.append(theta)
            scale.append(np.maximum(np.abs(theta), 0.1 * std) if name in model.effects else std)
            prior.append(std)
        s = np.concatenate(scale)
        x = np.concatenate([model.train_regressors[n] for n in names], axis=-1)
        info = np.diag(1.0 / np.concatenate(prior) ** 2)
        for a in range(3):
            w = solve_triangular(gp.chol[a], x[:, a, :], lower=True)
            info += w.T @ w
        fitted = tuple(n for n in names if n in model.effects)
        fit_se = np.concatenate(
            [
                model.effects[n].theta_stderr
                if n in model.effects
                else np.full(get_effect(n).n_theta, np.nan)
                for n in names
            ]
        )
        spread = np.concatenate(
            [
                model.effects[n].theta_systematic if n in model.effects else np.zeros(len(t))
                for n, t in zip(names, values, strict=True)
            ]
        )
        theta = np.concatenate(values)
        return cls(tuple(names), theta, s, info * np.outer(s, s), fitted, fit_se, spread)

    def standard_errors(self, information: np.ndarray) -> np.ndarray:
        """Standard errors (..., p) of theta in its units from scaled information (..., p, p)."""
        return _relative_se(information) * self.scale


def _relative_se(information: np.ndarray) -> np.ndarray:
    cov = np.linalg.inv(information)
    return np.sqrt(np.clip(np.einsum("...ii->...i", cov), 0.0, None))


def flight_regressors(model, inputs: np.ndarray, names: Sequence[str], dt: float) -> np.ndarray:
    """Regressors (B, Ts, 3, p) of ``names`` along flights of normalised GP inputs
    (B, Ts, d) on a grid of ``dt`` s (the registry's code; derivatives by central
    differences)."""
    v = model.vehicle
    n_sets, steps, _ = inputs.shape
    z = np.asarray(inputs, float) * model.input_scale + model.input_mean
    u = z[..., :6]
    omega = z[..., 6:9] if "rate" in model.features.split("+") else np.zeros((*u.shape[:2], 3))
    p = sum(get_effect(n).n_theta for n in names)
    out = np.empty((n_sets, steps, 3, p))

    def derivative(a: np.ndarray) -> np.ndarray:
        return np.gradient(a, dt, axis=0) if a.shape[0] > 1 else np.zeros_like(a)

    for b in range(n_sets):
        w = omega[b]
        ctx = EffectContext(
            omega=w,
            force=u[b, :, :3] * v.mass,
            torque=u[b, :, 3:] @ v.inertia.T,
            omega_dot_nominal=u[b, :, 3:] - cross(w, w @ v.inertia.T) @ v.inertia_inv.T,
            inertia=v.inertia,
            dt=dt,
            allocation=model.allocation,
            derivative=derivative,
            torque_normalised=v.torque_normalised,
        )
        out[b] = np.concatenate([get_effect(n).regressor(ctx) for n in names], axis=-1)
    return out


def information_gain(
    gp: GPAxes, x_train: np.ndarray, picks: np.ndarray, x_picks: np.ndarray, chunk: int = 128
) -> np.ndarray:
    """Information (B, p, p) that points picks (B, m, d) with regressors x_picks
    (B, m, 3, p) add to the GLS of the training points (regressors x_train (n, 3, p))."""
    n_sets, m, d = picks.shape
    p = x_train.shape[2]
    out = np.zeros((n_sets, p, p))
    eye = np.eye(m)
    for a in range(3):
        l_inv = solve_triangular(gp.chol[a], np.eye(gp.n), lower=True)
        w = l_inv @ x_train[:, a, :]  # (n, p)
        for lo in range(0, n_sets, chunk):
            zx = picks[lo : lo + chunk]
            b = zx.shape[0]
            b1 = (l_inv @ gp.kernel(a, gp.inputs, zx.reshape(-1, d))).T.reshape(b, m, -1)
            q = gp.kernel(a, zx, zx) + gp.noise_variance[a] * eye - b1 @ b1.swapaxes(1, 2)
            r = x_picks[lo : lo + b, :, a, :] - b1 @ w  # (b, m, p)
            out[lo : lo + b] += r.swapaxes(1, 2) @ np.linalg.solve(q, r)
    return out


def max_cross_correlation(information: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Largest |correlation| (...,) between parameters of different groups (p,) in the
    covariance ``information^-1`` (0 with a single group)."""
    cov = np.linalg.inv(information)
    sd = np.sqrt(np.clip(np.einsum("...ii->...i", cov), 1e-300, None))
    corr = np.abs(cov / (sd[..., :, None] * sd[..., None, :]))
    different = groups[:, None] != groups[None, :]
    if not different.any():
        return np.zeros(information.shape[:-2])
    return np.where(different, corr, 0.0).max(axis=(-2, -1))


class EffectsObjective:
    """Cost (K, M): ``-log det`` of the scaled information after each flight (module doc).

    ``metrics`` gives the cost and, per simulation, the expected relative standard
    error (geometric mean) and the largest cross-effect correlation.
    """

    def __init__(self, model, gp: GPAxes, names: Sequence[str], points: int, stride: int) -> None:
        self.model, self.gp, self.points = model, gp, points
        self.dt = stride / model.vehicle.gains.rate_hz
        self.prior = EffectsPrior.from_model(model, gp, names)
        self.x_train = np.concatenate([model.train_regressors[n] for n in names], axis=-1)
        self.groups = np.concatenate(
            [np.full(get_effect(n).n_theta, i) for i, n in enumerate(names)]
        )

    @property
    def names(self) -> tuple[str, ...]:
        return self.prior.names

    def information(self, flights: Flights) -> np.ndarray:
        """Scaled information (K, M, p, p) after each simulated flight."""
        k_count, m_count, steps, d = flights.inputs.shape
        flat = flights.inputs.reshape(k_count * m_count, steps, d)
        idx = batched_pick_indices(flat, self.points)
        rows = np.arange(flat.shape[0])[:, None]
        x_all = flight_regressors(self.model, flat, self.names, self.dt)
        gain = information_gain(
            self.gp, self.x_train, np.asarray(flat[rows, idx], float), x_all[rows, idx]
        )
        s = self.prior.scale
        total = self.prior.information + gain * np.outer(s, s)
        return total.reshape(k_count, m_count, *total.shape[1:])

    def metrics(self, flights: Flights) -> dict[str, np.ndarray]:
        """``effects`` cost, ``effects_rel_se`` and ``effects_correlation``, each (K, M),
        and ``effects_se`` (K, M, p) the expected standard errors of theta."""
        info = self.information(flights)
        sign, logdet = np.linalg.slogdet(info)
        rel = _relative_se(info)
        return {
            "effects": np.where(sign > 0, -logdet, np.inf),
            "effects_rel_se": np.exp(np.log(np.maximum(rel, 1e-300)).mean(axis=-1)),
            "effects_correlation": max_cross_correlation(info, self.groups),
            "effects_se": rel * self.prior.scale,
        }

    def __call__(self, flights: Flights) -> np.ndarray:
        return self.metrics(flights)["effects"]
