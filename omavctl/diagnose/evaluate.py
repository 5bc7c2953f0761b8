"""Compare models with measurements, find where they fail, name what is missing.

For every log (aligned on the model's grid, Savitzky-Golay settings of the
model, commands held like the derivative: :mod:`omavctl.learn.signal`), the measured
angular acceleration is compared with three predictions:

- ``nominal``: rigid body only (residual 0);
- ``effects``: nominal + the model's fitted physical effects;
- ``model``: nominal + effects + GP mean, with the GP's predictive std.

Metrics per axis (rad/s^2): RMSE, MAE, R^2 of the residual (1 - SSE / SS of
the nominal residual about its mean: the fraction of the nominal model's
error the prediction explains), mean predicted std, fraction of samples
within 2 sigma, and negative log predictive density. The nominal and effects
predictions carry the GP *prior* predictive std ``sqrt(s^2 + sigma^2)`` (what
is known without data), the model its posterior predictive std.

Diagnosis: every registered effect not in the model is fitted by weighted
least squares to the model's remaining error on alternate time blocks and
scored on the other blocks (held-out explained variance); standard errors by
a delete-one-block jackknife (robust to the correlation the derivative filter
puts between neighbouring samples). An effect is reported *missing* when its
held-out explained variance exceeds :data:`MIN_EXPLAINED`, its estimate is
significant (|value| > :data:`MIN_T` standard errors) and physically
plausible, its contribution is material (RMS above :data:`MIN_NOISE_RATIO`
times the measurement noise) and, estimated from the model's own training
points as ``fit --effects`` would, it lowers the held-out error. Candidates
whose fitted contributions correlate strongly are flagged ambiguous.
Structure left after the best effect (correlation with an input or state
feature, a spectral peak) is reported as unexplained. The same
ranking on the nominal residual says what the GP (with the effects) has
learned, in physical terms.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl import __version__
from omavctl.base.errors import LogError, ModelError, OmavctlError
from omavctl.learn.control_loss import out_of_control
from omavctl.learn.flights import body_rate_rate, sha256_of
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay, feature_names, residual_samples
from omavctl.logs.types import FlightLog
from omavctl.physics.effects import EFFECTS, get_effect
from omavctl.vehicle import Vehicle

__all__ = [
    "MIN_EXPLAINED",
    "MIN_T",
    "SCHEMA",
    "EvalResult",
    "diagnose",
    "evaluate",
]

SCHEMA = "omavctl.eval/1"
AXES = ("x", "y", "z")
#: Held-out explained variance above which a candidate effect counts as missing.
MIN_EXPLAINED = 0.15
#: Estimate / standard error above which a candidate effect counts as significant.
MIN_T = 4.0
#: A missing effect's contribution (RMS) must exceed this multiple of the noise
#: of the measured angular acceleration (:func:`measurement_noise`): below it
#: the "effect" is small physics or filter error the model may well leave out,
#: whatever fraction of its remaining error it explains (the simulator's default
#: 3 % thrust spread and 5 ms lags reach 1-2x; hidden effects 5x and more).
MIN_NOISE_RATIO = 3.0
#: Alternating train/test blocks of the diagnosis, s.
BLOCK_SECONDS = 2.0
#: Candidates whose fitted contributions correlate above this are ambiguous.
AMBIGUOUS_CORRELATION = 0.8
#: Sliding window of the worst-segment search, s; segments reported.
WORST_WINDOW_SECONDS = 1.0
WORST_COUNT = 5
#: Quantile bins of the residual-vs-feature tables.
BINS = 10

Progress = Callable[[str, float], None]


# ------------------------------------------------------------------ metrics
def axis_metrics(
    measured: np.ndarray, predicted: np.ndarray, std: np.ndarray, reference: np.ndarray
) -> dict[str, dict[str, float]]:
    """Per-axis metrics of a prediction.

    measured, predicted (n, 3) angular accelerations; std (n, 3) predictive std;
    reference (n, 3) the nominal residual (for R^2). Returns
    ``{metric: {"x": .., "y": .., "z": ..}}``.
    """
    err = measured - predicted
    sse = (err**2).sum(axis=0)
    sst = ((reference - reference.mean(axis=0)) ** 2).sum(axis=0)
    var = np.maximum(std, 1e-12) ** 2
    nlpd = 0.5 * np.log(2 * np.pi * var) + err**2 / (2 * var)
    out = {
        "rmse": np.sqrt((err**2).mean(axis=0)),
        "mae": np.abs(err).mean(axis=0),
        "r2": 1.0 - sse / np.maximum(sst, 1e-300),
        "mean_std": std.mean(axis=0),
        "coverage_2sigma": (np.abs(err) <= 2 * std).mean(axis=0),
        "nlpd": nlpd.mean(axis=0),
    }
    return {k: {a: float(v[i]) for i, a in enumerate(AXES)} for k, v in out.items()}


# ---------------------------------------------------------------- diagnosis
def _blocks(t: np.ndarray, log_id: np.ndarray, seconds: float) -> np.ndarray:
    """Block number (n,) of each sample: consecutive ``seconds`` windows per log."""
    out = np.empty(t.size, dtype=np.int64)
    offset = 0
    for lid in np.unique(log_id):
        sel = log_id == lid
        b = np.floor((t[sel] - t[sel].min()) / seconds).astype(np.int64)
        out[sel] = b + offset
        offset = int(out[sel].max()) + 1
    return out


@dataclass
class EffectScore:
    """One candidate effect fitted to a residual (see module docstring)."""

    name: str
    explained_variance: float
    explained_per_axis: dict[str, float]
    parameters: dict[str, list[float]]
    units: dict[str, str]
    t_value: float
    significant: bool
    plausible: bool
    contribution: np.ndarray = field(repr=False)
    #: RMS (rad/s^2) of the contribution, unweighted over all samples and axes
    contribution_rms: float = 0.0
    above_noise: bool = True
    #: explained variance with theta estimated from the model's training points
    #: (what ``fit --effects`` would estimate), None when not known
    refit_explained_variance: float | None = None
    ambiguous_with: list[str] = field(default_factory=list)

    @property
    def missing(self) -> bool:
        return (
            self.significant
            and self.plausible
            and self.above_noise
            and self.explained_variance >= MIN_EXPLAINED
            and (self.refit_explained_variance is None or self.refit_explained_variance > 0)
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "explained_variance": self.explained_variance,
            "explained_variance_per_axis": self.explained_per_axis,
            "parameters": self.parameters,
            "units": self.units,
            "t_value": self.t_value,
            "contribution_rms": self.contribution_rms,
            "above_noise": self.above_noise,
            "refit_explained_variance": self.refit_explained_variance,
            "significant": self.significant,
            "plausible": self.plausible,
            "missing": self.missing,
            "ambiguous_with": self.ambiguous_with,
            "identifiable": get_effect(self.name).identifiable,
        }


#: Physically plausible range of each effect's estimation parameters theta (each
#: effect's ``theta_range``): drag and lags are not negative, a centre of
#: mass lies within 0.2 m, the true inertia within half and twice the nominal
#: (theta = 1/scale - 1), a gyro bias below 0.2 rad/s. The diagnosis fits
#: within these bounds (bounded least squares): a missing effect must explain
#: the error with physically possible values.
THETA_RANGE: dict[str, tuple[float, float]] = {
    name: effect.theta_range for name, effect in EFFECTS.items()
}


def _bounded_lstsq(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """argmin |a x - b| subject to lo <= x <= hi (scipy's bounded least squares)."""
    from scipy.optimize import lsq_linear

    if a.shape[0] == 0:
        return np.zeros(a.shape[1])
    return np.asarray(lsq_linear(a, b, bounds=(lo, hi), method="bvls").x)


def score_effects(
    residual: np.ndarray,
    regressors: dict[str, np.ndarray],
    blocks: np.ndarray,
    std: np.ndarray | None = None,
    noise_floor: float = 0.0,
    refit: dict[str, np.ndarray] | None = None,
) -> list[EffectScore]:
    """Fit each candidate to ``residual`` (n, 3) on even blocks, score on odd ones.

    regressors: name -> (n, 3, p). Samples are weighted by ``1 / std^2`` (n, 3),
    the predictive variance of the model whose error ``residual`` is, so that
    where the model knows it is extrapolating its error counts less; then each
    axis is scaled so that it counts alike. Parameters are bounded to their
    plausible ranges (:data:`THETA_RANGE`); a parameter whose regressor could
    not explain 0.1 % of the residual even at the edge of its range is not
    excited by the data and stays 0. Ranked best first.
    """
    if std is None:
        std = np.ones_like(residual)
    w = 1.0 / np.maximum(std, 1e-9) ** 2  # (n, 3)
    w = w / np.maximum((w * residual**2).mean(axis=0), 1e-300)
    train = blocks % 2 == 0
    test = ~train
    if not train.any() or not test.any():  # too short for two blocks: halves
        half = residual.shape[0] // 2
        train = np.arange(residual.shape[0]) < half
        test = ~train
    ublocks = np.unique(blocks)
    rw = residual * np.sqrt(w)
    total = float((rw**2).sum())
    scores = []
    for name, x in regressors.items():
        effect = get_effect(name)
        p = x.shape[2]
        lo_b, hi_b = effect.theta_range
        xw = x * np.sqrt(w)[:, :, None]
        energy = np.einsum("nap,nap->p", xw, xw)
        reach = max(abs(lo_b), abs(hi_b))
        excited = energy * reach**2 >= 1e-3 * total
        if not excited.any():
            continue
        cols = np.flatnonzero(excited)
        lo = np.full(cols.size, lo_b)
        hi = np.full(cols.size, hi_b)

        def solve(rows: np.ndarray, xw=xw, cols=cols, p=p, lo=lo, hi=hi) -> np.ndarray:
            a = xw[rows][:, :, cols].reshape(-1, cols.size)
            out = np.zeros(p)
            out[cols] = _bounded_lstsq(a, rw[rows].reshape(-1), lo, hi)
            return out

        theta = solve(train)
        theta_all = solve(np.ones(residual.shape[0], dtype=bool))
        if len(ublocks) >= 3:
            jk = np.stack([solve(blocks != b) for b in ublocks])
            k = len(ublocks)
            cov = (k - 1) / k * (jk - jk.mean(0)).T @ (jk - jk.mean(0))
        else:
            cov = np.full((p, p), np.inf)
        pred = x @ theta  # (n, 3)
        sse0 = (w[test] * residual[test] ** 2).sum(axis=0)
        sse1 = (w[test] * (residual[test] - pred[test]) ** 2).sum(axis=0)
        ev = 1.0 - float(sse1.sum() / max(sse0.sum(), 1e-300))
        ev_axis = {a: float(1.0 - sse1[i] / max(sse0[i], 1e-300)) for i, a in enumerate(AXES)}
        refit_ev: float | None = None
        if refit is not None and name in refit:
            sse_refit = float((w * (residual - x @ refit[name]) ** 2).sum())
            refit_ev = 1.0 - sse_refit / max(total, 1e-300)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        # t values of components strictly inside their range (at a bound the
        # jackknife spread collapses and says nothing), capped for the JSON
        inside = excited & (theta_all > lo_b + 1e-12) & (theta_all < hi_b - 1e-12)
        tv = np.abs(theta_all) / np.maximum(se, 1e-12 * np.maximum(np.abs(theta_all), 1e-300))
        tval = float(min(np.max(np.where(inside, tv, 0.0), initial=0.0), 1e6))
        at_outer = excited & (
            (np.isclose(theta_all, hi_b) & (hi_b != 0))
            | (np.isclose(theta_all, lo_b) & (lo_b != 0))
        )
        cov[~excited, :] = 0.0
        cov[:, ~excited] = 0.0
        phys = effect.to_parameters(theta_all, cov)
        contribution = x @ theta_all  # (n, 3)
        contribution_rms = float(np.sqrt((contribution**2).mean()))
        params: dict[str, Any] = {k: v.tolist() for k, (v, _) in phys.items()}
        params.update({f"{k}_stderr": s.tolist() for k, (_, s) in phys.items()})
        params["excited"] = excited.tolist()
        scores.append(
            EffectScore(
                name=name,
                explained_variance=ev,
                explained_per_axis=ev_axis,
                parameters=params,
                units={prm.name: prm.unit for prm in effect.parameters},
                t_value=tval,
                significant=bool(tval >= MIN_T),
                plausible=not bool(at_outer.any()),
                contribution=contribution,
                contribution_rms=contribution_rms,
                above_noise=contribution_rms >= noise_floor,
                refit_explained_variance=refit_ev,
            )
        )
    scores.sort(key=lambda s: (not s.missing, -s.explained_variance))
    for i, s in enumerate(scores):
        for other in scores[i + 1 :]:
            c = _corr(s.contribution, other.contribution)
            if abs(c) >= AMBIGUOUS_CORRELATION and (s.missing or other.missing):
                s.ambiguous_with.append(other.name)
                other.ambiguous_with.append(s.name)
    return scores


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.reshape(-1) - a.mean(), b.reshape(-1) - b.mean()
    den = math.sqrt(float((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else 0.0


def unexplained_structure(
    residual: np.ndarray, features: dict[str, np.ndarray], dt: float, min_corr: float = 0.3
) -> list[dict[str, Any]]:
    """Structure in a residual (n, 3) that remains: feature correlations and spectral peaks.

    features: name -> (n,) values. A correlation counts when |r| >= min_corr;
    a spectral peak when a Welch periodogram bin above 0.2 Hz holds more than
    10x the median power and more than 10% of the total.
    """
    from scipy.signal import welch

    out: list[dict[str, Any]] = []
    for i, axis in enumerate(AXES):
        r = residual[:, i]
        if r.std() == 0:
            continue
        for name, f in features.items():
            if f.std() == 0:
                continue
            c = float(np.corrcoef(r, f)[0, 1])
            if abs(c) >= min_corr:
                out.append(
                    {"kind": "feature correlation", "axis": axis, "feature": name, "correlation": c}
                )
        nper = min(r.size, 512)
        if nper >= 64:
            freq, power = welch(r - r.mean(), fs=1.0 / dt, nperseg=nper)
            keep = freq > 0.2
            if keep.any():
                j = int(np.argmax(np.where(keep, power, -np.inf)))
                ratio = float(power[j] / max(np.median(power[keep]), 1e-300))
                share = float(power[j] / max(power.sum(), 1e-300))
                if ratio > 10 and share > 0.1:
                    out.append(
                        {
                            "kind": "spectral peak",
                            "axis": axis,
                            "frequency_hz": float(freq[j]),
                            "power_ratio": ratio,
                            "power_share": share,
                        }
                    )
    out.sort(key=lambda d: -abs(d.get("correlation", 0.0)))
    return out


# ------------------------------------------------------------------ result
@dataclass
class EvalResult:
    """Everything ``evaluate`` found: the JSON tree and the time series."""

    tree: dict[str, Any]
    series: dict[str, np.ndarray]


def _check_models(models: Sequence[ResidualGP], paths: Sequence[str]) -> None:
    ref = models[0].vehicle
    for m, p in zip(models[1:], paths[1:], strict=True):
        v = m.vehicle
        same = (
            np.isclose(v.mass, ref.mass)
            and np.allclose(v.inertia, ref.inertia)
            and v.topics == ref.topics
            and v.columns == ref.columns
            and v.frame == ref.frame
            and v.command_units == ref.command_units
        )
        if not same:
            raise ModelError(
                f"fit for another vehicle than {paths[0]} (mass, inertia, topics, columns or "
                "command units differ): evaluate them separately",
                p,
            )


def _grid(model: ResidualGP) -> tuple[float, SavitzkyGolay]:
    prov = model.provenance
    rate = float(prov.get("grid_rate_hz", model.vehicle.gains.rate_hz))
    sg_cfg = prov.get("savitzky_golay", {})
    from omavctl.learn.signal import DEFAULT_SG_ORDER, DEFAULT_SG_WINDOW

    sg = SavitzkyGolay(
        int(sg_cfg.get("window", DEFAULT_SG_WINDOW)),
        int(sg_cfg.get("order", DEFAULT_SG_ORDER)),
        1.0 / rate,
    )
    return rate, sg


def _check_rate(flight: FlightLog, vehicle: Vehicle, rate: float) -> None:
    """Refuse a log whose body rate was recorded at less than half the grid rate."""
    logged = body_rate_rate(flight, vehicle)
    if logged is not None and logged < 0.5 * rate:
        raise LogError(
            f"body rate logged at {logged:.1f} Hz, below half the model's grid rate "
            f"({rate:g} Hz): its Savitzky-Golay settings do not apply",
            flight.path,
        )


def _worst_segments(
    t: np.ndarray,
    log_id: np.ndarray,
    err: np.ndarray,
    context: dict[str, np.ndarray],
    log_names: Sequence[str],
    dt: float,
) -> list[dict[str, Any]]:
    """Top non-overlapping sliding windows by RMSE of err (n, 3)."""
    width = max(round(WORST_WINDOW_SECONDS / dt), 3)
    cands: list[tuple[float, int, int]] = []
    sq = (err**2).mean(axis=1)
    for lid in np.unique(log_id):
        idx = np.flatnonzero(log_id == lid)
        # contiguous runs (kept samples are consecutive grid indices within segments)
        breaks = np.flatnonzero(np.diff(t[idx]) > 1.5 * dt) + 1
        for run in np.split(idx, breaks):
            if run.size < width:
                continue
            c = np.concatenate([[0.0], np.cumsum(sq[run])])
            mse = (c[width:] - c[:-width]) / width
            for s in np.argsort(-mse)[: 20 * WORST_COUNT]:
                cands.append((float(mse[s]), int(run[s]), int(run[s + width - 1])))
    cands.sort(reverse=True)
    chosen: list[tuple[float, int, int]] = []
    for mse, a, b in cands:
        if all(b < ca or a > cb for _, ca, cb in chosen):
            chosen.append((mse, a, b))
        if len(chosen) == WORST_COUNT:
            break
    out = []
    for _, a, b in chosen:
        sel = slice(a, b + 1)
        seg: dict[str, Any] = {
            "log": log_names[int(log_id[a])],
            "start": float(t[a]),
            "end": float(t[b]),
            "rmse": {ax: float(np.sqrt((err[sel, i] ** 2).mean())) for i, ax in enumerate(AXES)},
        }
        for name, values in context.items():
            seg[name] = [float(v) for v in np.abs(values[sel]).mean(axis=0)]
        out.append(seg)
    return out


def _binned(
    err: np.ndarray, nominal_err: np.ndarray, features: dict[str, np.ndarray]
) -> dict[str, Any]:
    """Error of the model and of the nominal model in quantile bins of each feature."""
    out: dict[str, Any] = {}
    for name, f in features.items():
        edges = np.unique(np.quantile(f, np.linspace(0, 1, BINS + 1)))
        if edges.size < 3:
            continue
        which = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, edges.size - 2)
        nb = edges.size - 1
        count = np.bincount(which, minlength=nb)
        entry: dict[str, Any] = {
            "edges": edges.tolist(),
            "centers": ((edges[:-1] + edges[1:]) / 2).tolist(),
            "count": count.tolist(),
        }
        for label, e in (("model", err), ("nominal", nominal_err)):
            mean = np.stack([np.bincount(which, e[:, i], nb) for i in range(3)]) / np.maximum(
                count, 1
            )
            ms = np.stack([np.bincount(which, e[:, i] ** 2, nb) for i in range(3)]) / np.maximum(
                count, 1
            )
            entry[f"{label}_mean"] = {a: mean[i].tolist() for i, a in enumerate(AXES)}
            entry[f"{label}_rms"] = {a: np.sqrt(ms[i]).tolist() for i, a in enumerate(AXES)}
        out[name] = entry
    return out


def measurement_noise(
    samples: Sequence[ResidualSamples], sg: SavitzkyGolay, model: ResidualGP
) -> float:
    """Noise std (rad/s^2) of the measured angular acceleration.

    The body-rate noise of the logs (:attr:`ResidualSamples.rate_noise`, from
    second differences, median over logs and axes) through the derivative
    filter's noise gain ``||h||``; the model's noise std (median over axes of
    the GP's) when the logs do not tell. The GP's noise also holds whatever
    fast structure it could not fit, and it can be near 0 when its training
    flight was smooth enough for it to interpolate: the log's is the
    measurement's own.
    """
    rates = np.array([s.rate_noise for s in samples], dtype=float)
    if np.isfinite(rates).any():
        return float(np.nanmedian(rates)) * sg.noise_gain
    return float(np.median(np.sqrt(model.noise_variance)))


def diagnose(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    model_mean: np.ndarray,
    model_std: np.ndarray,
    features: dict[str, np.ndarray],
    sg: SavitzkyGolay,
) -> dict[str, Any]:
    """The ``diagnosis`` section (see module docstring).

    samples: the residual samples of every log built with every registry
    effect's regressor; model_mean (n, 3) the model's residual prediction on
    the concatenated samples and model_std (n, 3) its predictive std.
    """
    residual = np.concatenate([s.residual for s in samples])
    t = np.concatenate([s.t for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    blocks = _blocks(t, log_id, BLOCK_SECONDS)
    regs = {n: np.concatenate([s.regressors[n] for s in samples]) for n in EFFECTS}
    # The GP was trained on data that contained any missing effect: on this data
    # it predicts k(z, Z) (K + s^2 I)^-1 X_train theta of it. The model's error is
    # therefore linear in theta through X - smooth(X_train) (exact for the GP
    # mean with fixed hyperparameters).
    z = np.concatenate([s.inputs(model.features) for s in samples])
    candidates = {}
    refit = {}
    for n, r in regs.items():
        if n in model.effects:
            continue
        if n in model.train_regressors:
            r = r - model.smooth(z, model.train_regressors[n])
            refit[n] = model.basis_estimate(
                model.train_regressors[n], np.full(r.shape[2], get_effect(n).prior_std)
            )[0]
        candidates[n] = r
    remaining = residual - model_mean
    noise = measurement_noise(samples, sg, model)
    floor = MIN_NOISE_RATIO * noise
    missing = score_effects(remaining, candidates, blocks, model_std, floor, refit)
    # forward selection: accept the best missing effect, remove what it explains,
    # rescore the others on what is left (so one cause is not reported thrice)
    accepted: list[dict[str, Any]] = []
    after = remaining
    pool = dict(candidates)
    ranking = missing
    while ranking and ranking[0].missing and len(accepted) < 3:
        best = ranking[0]
        accepted.append({"name": best.name, "explained_variance": best.explained_variance})
        after = after - best.contribution
        pool.pop(best.name)
        ranking = score_effects(after, pool, blocks, model_std, floor, refit)
    # what the physics-free residual behaves like, with the same materiality: an
    # "effect" below the measurement's own noise is not claimed as learned
    learned = score_effects(residual, regs, blocks, noise_floor=floor)
    unexplained = unexplained_structure(after, features, sg.dt)
    return {
        "method": {
            "split": f"alternate {BLOCK_SECONDS:g} s blocks: fit on even, score on odd",
            "standard_errors": "delete-one-block jackknife",
            "min_explained_variance": MIN_EXPLAINED,
            "min_t_value": MIN_T,
            "min_contribution_rms": floor,
            "measurement_noise_std": noise,
            "refit": "parameters fitted to the model's own training points as fit --effects "
            "would (GP hyperparameters kept); a missing effect must lower the error with them",
            "parameter_bounds": "bounded least squares within THETA_RANGE (plausible values)",
            "selection": "forward: best missing effect removed, others rescored, up to 3",
        },
        "missing_effects": [s.to_json() for s in missing],
        "missing": [a["name"] for a in accepted],
        "missing_steps": accepted,
        "unexplained": unexplained,
        "learned": [s.to_json() for s in learned],
    }


def _where(given: str, absolute: str | None) -> str:
    """A file recorded by fit (as given there, and absolute) as typed from here:
    the absolute record when it exists (fit may have run elsewhere), else as given."""
    from omavctl.base.shell import display_path

    if absolute and Path(absolute).exists():
        return display_path(absolute)
    return display_path(given) if Path(given).exists() else given


def fit_command(model_path: str, model: ResidualGP, effect: str) -> str:
    """The ``omavctl fit`` command that refits ``model`` with ``effect`` added.

    Paths are valid from the current directory (the logs and vehicle file that fit
    read, the new model beside ``model_path``) and every word is shell-quoted.
    """
    from omavctl.base.shell import display_path, shell_join

    prov = model.provenance
    sources = [
        _where(str(s.get("path") or s.get("name")), s.get("abspath"))
        for s in prov.get("sources", [])
        if s.get("path") or s.get("name")
    ]
    effects = [*model.effects, effect]
    stem = Path(display_path(model_path)).with_suffix("")
    parts = ["omavctl", "fit", *sources]
    parts += ["--effects", ",".join(effects), "--out", f"{stem}+{effect}.npz"]
    kmed = prov.get("kmedoids", {})
    if "points" in kmed:
        parts += ["--points", str(kmed["points"])]
    sg = prov.get("savitzky_golay", {})
    if sg:
        parts += ["--sg-window", str(sg.get("window")), "--sg-order", str(sg.get("order"))]
    if model.features != "wrench":
        parts += ["--features", model.features]
    if "seed" in prov:
        parts += ["--seed", str(prov["seed"])]
    window = prov.get("time_window")
    if window and any(w is not None for w in window):
        lo, hi = window
        parts += [
            "--time-window",
            f"{'' if lo is None else f'{lo:g}'}:{'' if hi is None else f'{hi:g}'}",
        ]
    if prov.get("vehicle_path"):
        parts += ["--vehicle", _where(str(prov["vehicle_path"]), prov.get("vehicle_abspath"))]
    return shell_join(parts)


# ----------------------------------------------------------------- evaluate
def _read_log(
    path: str | Path,
    vehicle: Vehicle,
    rate: float,
    sg: SavitzkyGolay,
    time_window: tuple[float | None, float | None] | None,
) -> tuple[ResidualSamples, np.ndarray, dict[str, Any], list[dict[str, Any]]]:
    """One log's residual samples (every registry regressor, out-of-control samples
    removed), its attitude (n, 3) at them, its ``logs`` entry and its excluded spans."""
    from omavctl.logs import read_vehicle_log

    flight = read_vehicle_log(path, vehicle, rate=rate, time_window=time_window)
    _check_rate(flight, vehicle, rate)
    extra = {"desired": "desired_acceleration"} if flight.has("desired_acceleration") else {}
    s = residual_samples(flight, vehicle, sg, effects=tuple(EFFECTS), extra=extra)
    loss = out_of_control(s.t, s.omega, s.omega_dot, vehicle, s.residual)
    p = Path(path)
    spans = [{"log": p.name, "start": a, "end": b, "reason": why} for a, b, why in loss.spans]
    if loss.any:
        s = s.select(~loss.mask)
    if s.n < 10 * sg.window:
        raise LogError(
            f"only {s.n} usable samples after gaps, edges, ground time and loss of control "
            f"(need at least {10 * sg.window})",
            flight.path,
        )
    attitude = flight.signals["attitude"][s.index] if flight.has("attitude") else np.zeros((s.n, 3))
    log_json = {
        "path": str(p),
        "name": p.name,
        "sha256": sha256_of(p),
        "format": flight.format,
        # absolute time of the series' t = 0 on the log's own clock
        "t0": float(flight.t0),
        "duration": float(flight.t[-1] - flight.t[0]),
        "samples": s.n,
        "samples_total": s.total,
        "notes": list(flight.notes),
    }
    return s, attitude, log_json, spans


def _model_metrics(
    m: ResidualGP,
    path: str,
    samples: Sequence[ResidualSamples],
    measured: np.ndarray,
    nominal: np.ndarray,
    log_id: np.ndarray,
    log_names: Sequence[str],
) -> tuple[dict[str, Any], np.ndarray, np.ndarray, np.ndarray]:
    """One model's ``models`` entry with its metrics (overall and per log), and its
    effects prediction, residual mean and predictive std, each (n, 3)."""
    residual = measured - nominal
    eff_pred = np.concatenate([m.effects_samples(s) for s in samples])
    gp_mean, gp_var = m.gp_predict(
        np.concatenate([s.inputs(m.features) for s in samples]), noise=True
    )
    assert gp_var is not None
    mean = eff_pred + gp_mean
    std = np.sqrt(gp_var)
    prior_std = np.broadcast_to(np.sqrt(m.signal_variance + m.noise_variance), std.shape)
    metrics = {
        "nominal": axis_metrics(measured, nominal, prior_std, residual),
        "effects": axis_metrics(measured, nominal + eff_pred, prior_std, residual),
        "model": axis_metrics(measured, nominal + mean, std, residual),
    }
    by_log = []
    for i, name in enumerate(log_names):
        sel = log_id == i
        by_log.append(
            {
                "log": name,
                "nominal": axis_metrics(measured[sel], nominal[sel], prior_std[sel], residual[sel]),
                "model": axis_metrics(
                    measured[sel], nominal[sel] + mean[sel], std[sel], residual[sel]
                ),
            }
        )
    entry = {
        "path": path,
        "name": Path(path).name,
        "effects": {n: e.to_json() for n, e in m.effects.items()},
        "features": m.features,
        "n_train": m.n_train,
        "metrics": metrics,
        "metrics_by_log": by_log,
    }
    return entry, eff_pred, mean, std


def evaluate(
    model_paths: Sequence[str | Path],
    log_paths: Sequence[str | Path],
    time_window: tuple[float | None, float | None] | None = None,
    progress: Progress | None = None,
) -> EvalResult:
    """Evaluate one or more models on one or more logs (see module docstring)."""
    from omavctl.learn.model_file import load_model

    if not model_paths:
        raise OmavctlError("give at least one --model")
    if not log_paths:
        raise OmavctlError("give at least one log")
    mpaths = [str(p) for p in model_paths]
    models = [load_model(p) for p in mpaths]
    _check_models(models, mpaths)
    model = models[0]
    vehicle = model.vehicle
    rate, sg = _grid(model)
    samples: list[ResidualSamples] = []
    attitudes: list[np.ndarray] = []
    logs_json = []
    excluded: list[dict[str, Any]] = []
    for i, path in enumerate(log_paths):
        s, attitude_i, log_json, spans = _read_log(path, vehicle, rate, sg, time_window)
        samples.append(s)
        attitudes.append(attitude_i)
        logs_json.append(log_json)
        excluded += spans
        if progress is not None:
            progress("reading logs", (i + 1) / len(log_paths))
    measured = np.concatenate([s.omega_dot for s in samples])
    nominal = np.concatenate([s.nominal for s in samples])
    residual = measured - nominal
    t = np.concatenate([s.t for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    u = np.concatenate([s.u for s in samples])
    omega = np.concatenate([s.omega for s in samples])
    attitude = np.concatenate(attitudes)

    per_model = []
    series: dict[str, np.ndarray] = {
        "t": t,
        "log": log_id,
        "measured": measured,
        "nominal": nominal,
        "u": u,
        "omega": omega,
        "attitude": attitude,
    }
    for j, m in enumerate(models):
        entry, eff_pred, mean, std = _model_metrics(
            m, mpaths[j], samples, measured, nominal, log_id, [lj["name"] for lj in logs_json]
        )
        per_model.append(entry)
        series[f"effects_{j}"] = eff_pred
        series[f"mean_{j}"] = mean
        series[f"std_{j}"] = std
        if progress is not None:
            progress("predicting", (j + 1) / len(models))

    mean0 = series["mean_0"]
    metrics0: dict[str, Any] = per_model[0]["metrics"]
    err = residual - mean0
    names = feature_names("wrench")
    features = {names[k]: u[:, k] for k in range(6)}
    features.update({f"w{a}": omega[:, i] for i, a in enumerate(AXES)})
    features.update({"roll": attitude[:, 0], "pitch": attitude[:, 1]})
    tracking = None
    if all("desired" in s.held for s in samples):
        desired = np.concatenate([s.held["desired"] for s in samples])
        series["desired"] = desired
        terr = np.abs(desired - measured).mean(axis=0)
        tracking = {a: float(terr[i]) for i, a in enumerate(AXES)}
        tracking["mean"] = float(terr.mean())
    diagnosis = diagnose(samples, model, mean0, series["std_0"], features, sg)
    # regressors of the named effects (or the top candidate) for the report's
    # effect-signature figures
    shown = list(diagnosis["missing"]) or [e["name"] for e in diagnosis["missing_effects"][:1]]
    for name in shown:
        series[f"regressor_{name}"] = np.concatenate([s.regressors[name] for s in samples])
    if diagnosis["missing"]:
        top = diagnosis["missing"][0]
        diagnosis["fit_command"] = fit_command(mpaths[0], model, top)
    else:
        diagnosis["fit_command"] = None
    torque_units_known = not vehicle.torque_normalised  # command_units.torque of the vehicle
    tree = {
        "schema": SCHEMA,
        "omavctl_version": __version__,
        "models": [
            {k: v for k, v in pm.items() if k not in ("metrics", "metrics_by_log")}
            for pm in per_model
        ],
        "logs": logs_json,
        "grid_rate_hz": rate,
        "savitzky_golay": {"window": sg.window, "order": sg.order},
        "units": {"acceleration": "rad/s^2", "torque": "N m" if torque_units_known else "unknown"},
        "metrics": per_model[0]["metrics"],
        "metrics_by_log": per_model[0]["metrics_by_log"],
        "metrics_by_model": [pm["metrics"] for pm in per_model],
        "tracking": tracking,
        "worst_segments": _worst_segments(
            t,
            log_id,
            err,
            {"attitude_deg": np.rad2deg(attitude), "rate": omega, "u": u},
            [str(lj["name"]) for lj in logs_json],
            sg.dt,
        ),
        "binned": _binned(err, residual, features),
        "diagnosis": diagnosis,
        "excluded_spans": excluded,
        "flags": quality_flags(metrics0, excluded),
    }
    return EvalResult(tree=tree, series=series)


#: Held-out 2-sigma coverage below which the model's uncertainty is overconfident.
MIN_COVERAGE = 0.8
#: Model RMSE above this multiple of physics-only (nominal + effects) is flagged.
MAX_RATIO = 1.05


def quality_flags(
    metrics: dict[str, Any], excluded: Sequence[dict[str, Any]]
) -> list[dict[str, Any]]:
    """What a reader must know before trusting the model on these logs.

    ``overconfident``: 2-sigma coverage below :data:`MIN_COVERAGE` on an axis;
    ``worse_than_physics``: the model's RMSE above :data:`MAX_RATIO` x that of
    nominal + effects (the GP hurts); ``out_of_control``: samples excluded.
    """
    flags: list[dict[str, Any]] = []
    for a in AXES:
        cov = metrics["model"]["coverage_2sigma"][a]
        if cov < MIN_COVERAGE:
            flags.append(
                {
                    "code": "overconfident",
                    "axis": a,
                    "value": cov,
                    "message": f"axis {a}: the 2-sigma band covers {cov:.0%} of the "
                    "measurements (should be about 95 %): the model's uncertainty is "
                    "overconfident here",
                }
            )
        phys = metrics["effects"]["rmse"][a]
        mod = metrics["model"]["rmse"][a]
        if phys > 0 and mod > MAX_RATIO * phys:
            flags.append(
                {
                    "code": "worse_than_physics",
                    "axis": a,
                    "value": mod / phys,
                    "message": f"axis {a}: the model's error is {mod / phys:.2f}x that of "
                    "its physics alone: the GP does not transfer to these logs",
                }
            )
    for span in excluded:
        flags.append(
            {
                "code": "out_of_control",
                "axis": None,
                "value": span["end"] - span["start"],
                "message": f"{span['log']}: {span['start']:.2f}-{span['end']:.2f} s out of "
                f"control ({span['reason']}): kept out of the metrics and the diagnosis",
            }
        )
    return flags


def finite_json(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None (JSON has no NaN/Infinity)."""
    if isinstance(obj, dict):
        return {k: finite_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_json(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.ndarray):
        return finite_json(obj.tolist())
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
