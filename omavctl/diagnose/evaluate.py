"""Compare models with measurements, find where they fail, name what is missing.

For every log (aligned on the model's grid, Savitzky-Golay settings of the
model, commands held like the derivative: :mod:`omavctl.learn.signal`), the measured
angular acceleration is compared with three predictions:

- ``nominal``: rigid body only (residual 0);
- ``effects``: nominal + the model's fitted physical effects;
- ``model``: nominal + effects + GP mean, with the GP's predictive std.

The nominal and effects predictions carry the GP *prior* predictive std
``sqrt(s^2 + sigma^2)`` (what is known without data), the model its
posterior predictive std. The steps of :func:`evaluate`, each in its module:

- metrics per axis, worst segments, binned errors and quality flags:
  :mod:`omavctl.diagnose.metrics`;
- scoring candidate physical effects against the model's remaining error:
  :mod:`omavctl.diagnose.scoring`;
- the ``diagnosis`` (missing effects by forward selection, unexplained
  structure, what the GP has learned, the ``fit`` command that adds the top
  missing effect): :mod:`omavctl.diagnose.diagnosis`.

Writing and reading the result: :mod:`omavctl.diagnose.evalio`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omavctl import __version__
from omavctl.base.errors import ModelError, OmavctlError
from omavctl.diagnose.diagnosis_commands import claim_advice, diagnosis_with_commands
from omavctl.diagnose.heldout import training_data_flags
from omavctl.diagnose.horizons import DEFAULT_HORIZONS, GridSignals, horizon_table
from omavctl.diagnose.logread import _grid, _read_log
from omavctl.diagnose.metrics import (
    AXES,
    axis_metrics,
    binned_errors,
    envelope_flags,
    quality_flags,
    training_envelope,
    worst_segments,
)
from omavctl.diagnose.model_flags import file_flags
from omavctl.learn.effect_fit import check_available
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay, feature_names
from omavctl.physics.effects import EFFECTS
from omavctl.vehicle import Vehicle

__all__ = ["SCHEMA", "EvalResult", "evaluate"]

SCHEMA = "omavctl.eval/1"

Progress = Callable[[str, float], None]


@dataclass
class EvalResult:
    """Everything ``evaluate`` found: the JSON tree and the time series."""

    tree: dict[str, Any]
    series: dict[str, np.ndarray]


def _check_models(models: Sequence[ResidualGP], paths: Sequence[str]) -> None:
    """Refuse models fitted for different vehicles than the first."""
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
    # the effects' parameter uncertainty and the rotors' spread are part of the prediction's
    gp_var = gp_var + np.concatenate([m.effects_variance(s) for s in samples])
    mean = eff_pred + gp_mean
    std = np.sqrt(gp_var)
    prior_std = np.broadcast_to(np.sqrt(m.signal_variance + m.noise_variance), std.shape)
    rms = np.sqrt((measured**2).mean(axis=0))
    metrics = {
        # predicting no angular acceleration at all: what any model must beat
        "zero": {"rmse": {a: float(rms[i]) for i, a in enumerate("xyz")}},
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
        "fit_flight": _fit_flight(m),
        "metrics": metrics,
        "metrics_by_log": by_log,
    }
    return entry, eff_pred, mean, std


def _fit_flight(m: ResidualGP) -> dict[str, Any]:
    """The logs (names) and time window a model was fitted on, from its provenance."""
    sources = m.provenance.get("sources") or []
    window = m.provenance.get("time_window")
    return {
        "logs": [str(s.get("name")) for s in sources if isinstance(s, dict)],
        "time_window": list(window) if isinstance(window, (list, tuple)) else None,
    }


def _considered(models: Sequence[ResidualGP]) -> list[str]:
    """The effects whose regressors the logs' samples need: what the diagnosis considers
    (``Effect.diagnosed``) and every model's own."""
    return [n for n, e in EFFECTS.items() if e.diagnosed or any(n in m.effects for m in models)]


def _read_logs(
    log_paths: Sequence[str | Path],
    vehicle: Vehicle,
    rate: float,
    sg: SavitzkyGolay,
    time_window: tuple[float | None, float | None] | None,
    progress: Progress | None,
    effects: Sequence[str] = tuple(EFFECTS),
) -> tuple[list[ResidualSamples], list[GridSignals], list[dict[str, Any]], list[dict[str, Any]]]:
    """Every log's residual samples and unfiltered signals (:func:`_read_log`), the
    ``logs`` entries and the excluded (out-of-control) spans of all of them."""
    samples: list[ResidualSamples] = []
    grids: list[GridSignals] = []
    logs_json = []
    excluded: list[dict[str, Any]] = []
    for i, path in enumerate(log_paths):
        s, grid, log_json, spans = _read_log(path, vehicle, rate, sg, time_window, effects)
        samples.append(s)
        grids.append(grid)
        logs_json.append(log_json)
        excluded += spans
        if progress is not None:
            progress("reading logs", (i + 1) / len(log_paths))
    return samples, grids, logs_json, excluded


def _measured_series(
    samples: Sequence[ResidualSamples], grids: Sequence[GridSignals]
) -> dict[str, np.ndarray]:
    """The series every evaluation holds, concatenated over the logs: ``t`` (n,),
    ``log`` (n,) index of the log, ``measured`` and ``nominal`` angular
    acceleration (n, 3), commands ``u`` (n, 6), body rate ``omega`` (n, 3) and
    ``attitude`` (n, 3)."""
    return {
        "t": np.concatenate([s.t for s in samples]),
        "log": np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)]),
        "measured": np.concatenate([s.omega_dot for s in samples]),
        "nominal": np.concatenate([s.nominal for s in samples]),
        "u": np.concatenate([s.u for s in samples]),
        "omega": np.concatenate([s.omega for s in samples]),
        "attitude": np.concatenate(
            [
                g.attitude if g.attitude is not None else np.zeros((s.n, 3))
                for s, g in zip(samples, grids, strict=True)
            ]
        ),
    }


def _predict_models(
    models: Sequence[ResidualGP],
    mpaths: Sequence[str],
    samples: Sequence[ResidualSamples],
    series: dict[str, np.ndarray],
    log_names: Sequence[str],
    progress: Progress | None,
) -> list[dict[str, Any]]:
    """Every model's ``models`` entry with its metrics (:func:`_model_metrics`);
    adds its predictions to ``series`` as ``effects_<j>``, ``mean_<j>`` and
    ``std_<j>`` (n, 3)."""
    per_model = []
    for j, m in enumerate(models):
        entry, eff_pred, mean, std = _model_metrics(
            m, mpaths[j], samples, series["measured"], series["nominal"], series["log"], log_names
        )
        per_model.append(entry)
        series[f"effects_{j}"] = eff_pred
        series[f"mean_{j}"] = mean
        series[f"std_{j}"] = std
        if progress is not None:
            progress("predicting", (j + 1) / len(models))
    return per_model


def _features(series: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Named (n,) features the error is related to: the six wrench commands, the
    body rates ``wx, wy, wz``, roll and pitch."""
    u, omega, attitude = series["u"], series["omega"], series["attitude"]
    names = feature_names("wrench")
    features = {names[k]: u[:, k] for k in range(6)}
    features.update({f"w{a}": omega[:, i] for i, a in enumerate(AXES)})
    features.update({"roll": attitude[:, 0], "pitch": attitude[:, 1]})
    return features


def _tracking(
    samples: Sequence[ResidualSamples], series: dict[str, np.ndarray]
) -> dict[str, float] | None:
    """Mean |desired - measured| angular acceleration per axis and overall, when
    every log holds the controller's desired acceleration (then added to
    ``series`` as ``desired`` (n, 3)); else None."""
    if not all("desired" in s.held for s in samples):
        return None
    desired = np.concatenate([s.held["desired"] for s in samples])
    series["desired"] = desired
    terr = np.abs(desired - series["measured"]).mean(axis=0)
    tracking = {a: float(terr[i]) for i, a in enumerate(AXES)}
    tracking["mean"] = float(terr.mean())
    return tracking


def _failures(
    series: dict[str, np.ndarray],
    features: dict[str, np.ndarray],
    log_names: Sequence[str],
    dt: float,
    thrust_known: bool = True,
    attitude_logged: Sequence[bool] = (),
) -> dict[str, Any]:
    """``worst_segments`` and ``binned``: where the first model's error is largest.

    ``thrust_known``: False when the force command is normalised (its ``u`` is not
    an acceleration, so no segment may speak of thrust in g). ``attitude_logged``:
    per log, whether it holds the attitude (a segment of one that does not has no
    ``attitude_deg``, so that no one reads its zeros as "level").
    """
    residual = series["measured"] - series["nominal"]
    err = residual - series["mean_0"]
    context = {
        "attitude_deg": np.rad2deg(series["attitude"]),
        "rate": series["omega"],
        "u": series["u"],
    }
    segments = worst_segments(series["t"], series["log"], err, context, log_names, dt)
    for seg in segments:
        seg["thrust_known"] = thrust_known
        i = log_names.index(seg["log"])
        if i < len(attitude_logged) and not attitude_logged[i]:
            seg["attitude_deg"] = None
    return {"worst_segments": segments, "binned": binned_errors(err, residual, features)}


def _load_models(
    model_paths: Sequence[str | Path], log_paths: Sequence[str | Path]
) -> tuple[list[str], list[ResidualGP]]:
    """The model files read and checked against each other, with their paths."""
    from omavctl.learn.model_file import load_model

    if not model_paths:
        raise OmavctlError("give at least one --model")
    if not log_paths:
        raise OmavctlError("give at least one log")
    mpaths = [str(p) for p in model_paths]
    models = [load_model(p) for p in mpaths]
    _check_models(models, mpaths)
    return mpaths, models


def evaluate(
    model_paths: Sequence[str | Path],
    log_paths: Sequence[str | Path],
    time_window: tuple[float | None, float | None] | None = None,
    progress: Progress | None = None,
    horizons: Sequence[float] = DEFAULT_HORIZONS,
    horizon_stride: int = 1,
    with_diagnosis: bool = True,
) -> EvalResult:
    """Evaluate one or more models on one or more logs (see module docstring).

    ``horizons`` (s) and ``horizon_stride`` (samples between starts): the open-loop
    prediction table (:func:`omavctl.diagnose.horizons.horizon_table`); no
    horizons: none. ``with_diagnosis`` False: ``diagnosis`` None, for callers that read
    only the metrics and tracking, which it does not change (benchmarks/informative.py).

    The diagnosis, worst segments and binned errors are of the first model;
    the series (n samples over all logs) are those of :func:`_measured_series`,
    then per model j ``effects_<j>``, ``mean_<j>``, ``std_<j>`` (n, 3), then
    ``desired`` and ``contribution_<name>`` when known.
    """
    mpaths, models = _load_models(model_paths, log_paths)
    model = models[0]
    rate, sg = _grid(model)
    samples, grids, logs_json, excluded = _read_logs(
        log_paths, model.vehicle, rate, sg, time_window, progress, _considered(models)
    )
    check_available(samples, sorted({name for m in models for name in m.effects}))
    log_names = [str(lj["name"]) for lj in logs_json]
    series = _measured_series(samples, grids)
    per_model = _predict_models(models, mpaths, samples, series, log_names, progress)
    features = _features(series)
    tracking = _tracking(samples, series)
    diagnosis = (
        diagnosis_with_commands(samples, models, mpaths, series, features, sg)
        if with_diagnosis
        else None
    )
    torque_units_known = not model.vehicle.torque_normalised  # command_units.torque
    envelope = _envelope(model, samples, series)
    tree = {
        "schema": SCHEMA,
        "omavctl_version": __version__,
        "models": [
            {k: v for k, v in pm.items() if k not in ("metrics", "metrics_by_log")}
            for pm in per_model
        ],
        "logs": logs_json,
        "time_window": None if time_window is None else list(time_window),
        "grid_rate_hz": rate,
        "savitzky_golay": {"window": sg.window, "order": sg.order},
        "units": {
            "acceleration": "rad/s^2",
            "torque": "N m" if torque_units_known else "unknown",
            "force": "unknown" if model.vehicle.force_normalised else "N",
        },
        "metrics": per_model[0]["metrics"],
        "metrics_by_log": per_model[0]["metrics_by_log"],
        "metrics_by_model": [pm["metrics"] for pm in per_model],
        "tracking": tracking,
        **_failures(
            series,
            features,
            log_names,
            sg.dt,
            not model.vehicle.force_normalised,
            [g.attitude is not None for g in grids],
        ),
        "diagnosis": diagnosis,
        "excluded_spans": excluded,
        "flags": file_flags(models, mpaths)
        + training_data_flags(model, logs_json, time_window)
        + quality_flags(per_model[0]["metrics"], excluded, *claim_advice(diagnosis))
        + envelope_flags(envelope),
        "envelope": envelope,
        "horizons": horizon_table(models, samples, grids, rate, horizons, horizon_stride)
        if horizons
        else None,
    }
    return EvalResult(tree=tree, series=series)


def _envelope(
    model: ResidualGP, samples: Sequence[ResidualSamples], series: dict[str, np.ndarray]
) -> dict[str, Any] | None:
    """The first model's training envelope against the logs (:func:`training_envelope`);
    None for a model without training points."""
    if model.n_train == 0:
        return None
    inputs = np.concatenate([s.inputs(model.features) for s in samples])
    error = series["measured"] - series["nominal"] - series["mean_0"]
    return training_envelope(model.inputs, inputs, list(model.input_names), error, series["std_0"])
