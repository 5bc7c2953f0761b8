"""Open-loop prediction over horizons: how far ahead each model sees.

From every start sample (every ``stride``-th) of a log, the angular dynamics
are rolled forward open loop over the logged torque commands for the longest
horizon (:func:`omavctl.physics.open_loop.rollout`, all windows at once) and
compared with the logged body rate and attitude at each horizon. Four
predictors:

- ``naive``: hold the state (body rate and attitude stay as at the start);
- ``nominal``: the rigid body alone (physics only);
- ``effects``: rigid body + the model's fitted physical effects;
- ``model``: + the GP mean (the full model).

The residual of ``effects`` and ``model`` is evaluated at the rolled-out body
rate: the effects at each period's logged command (as the rigid body's
torque), those that act through the command history only (lags, delay)
through their exact per-period form on the log, the GP at the commands held
like the fit's inputs (:mod:`omavctl.learn.rollout_residual`). Windows are
starts whose next K samples are consecutive grid samples kept by
``evaluate``: no window crosses a gap, a segment edge or an out-of-control
span. Every horizon uses the same starts (those valid for the longest), so
the rows of the table are comparable.

The full model's band: the body-rate error at step k has the std
``sqrt(f_k s_r^2 + (dt sum_{j<k} s_j)^2 + g_k k dt^2 s_p^2)`` per axis, with ``s_r``
the log's body-rate noise and ``f_k s_r^2`` the variance of the noise of sample
k less the start's (2 for independent samples; exact through the interpolation
weights for a gyro recorded more slowly than the grid,
:mod:`omavctl.learn.recorded_noise`), ``s_j`` the std of the
model's residual function at step j (GP latent variance + the effects'
parameter variance + the one-step band's growth beyond the fit flight's inputs,
:func:`omavctl.learn.band.growth_variance`, at the logged inputs, plus, for an
effect of a measured force,
what its rollout's prediction errs after j steps on the log: the force held at the
window's start, or rolled forward by the logged attitude where the log has one,
:func:`~omavctl.learn.rollout_residual.held_spread`) and ``s_p^2`` the GP's noise
variance less what the rate noise puts into the Savitzky-Golay derivative
(motion the model cannot predict, integrated as a random walk times ``g_k``: how
much faster the residual the model leaves added up over k steps on the fit
flight's held-out blocks, :mod:`omavctl.learn.rollout_walk`; 1 for white noise).
Summing the std along the window treats the function's error as fully
correlated over the window: exact for an error in a constant parameter, an
upper bound for a GP whose inputs move less than its length scales. Coverage
is the fraction of windows whose error is within 2 std.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError, OmavctlError
from omavctl.diagnose.horizon_findings import findings
from omavctl.learn.model import ResidualGP
from omavctl.learn.recorded_noise import independent_noise
from omavctl.learn.rollout_residual import (
    GridSignals,
    Windows,
    function_std,
    gather,
    held_spread,
    per_sample,
    residual_function,
    window_starts,
)
from omavctl.learn.rollout_walk import walk_gain_at
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.open_loop import rollout
from omavctl.physics.rigid_body import rotation_matrix

__all__ = [
    "DEFAULT_HORIZONS",
    "GridSignals",
    "Windows",
    "horizon_steps",
    "horizon_table",
    "parse_horizons",
    "window_starts",
]

#: horizons (s) of the system-identification benchmarks: 1, 10 and 50 steps at 100 Hz
DEFAULT_HORIZONS = (0.01, 0.1, 0.5)
#: the predictive band's half-width in std
BAND_SIGMA = 2.0
#: most window samples (windows x (K + 1)) held at once: a stride 1 on a 4 min log
#: at 100 Hz with 0.5 s windows (about 400 MB); longer logs get a larger stride
MAX_WINDOW_SAMPLES = 1_200_000
AXES = ("x", "y", "z")
#: windows are grouped by start time into chunks of this many longest horizons for the
#: standard errors (errors of overlapping windows are not independent)
CHUNK_HORIZONS = 2


def parse_horizons(text: str) -> tuple[float, ...]:
    """``--horizons`` text: comma-separated seconds (``"0.01,0.1,0.5"``) or ``none``."""
    if text.strip().lower() == "none":
        return ()
    out = []
    for part in text.split(","):
        try:
            h = float(part)
        except ValueError:
            raise ConfigError(
                f"--horizons must be seconds separated by commas (e.g. 0.01,0.1,0.5) or "
                f"none, got '{text[:60]}'"
            ) from None
        if not (np.isfinite(h) and h > 0):
            raise ConfigError(f"--horizons: {part.strip()} is not a positive number of seconds")
        out.append(h)
    return tuple(out)


def horizon_steps(horizons: Sequence[float], rate: float) -> list[int]:
    """Grid steps (rounded) of horizons (s) at ``rate`` Hz; refuses a horizon shorter
    than one step, not finite, or repeated."""
    steps = []
    for h in horizons:
        if not np.isfinite(h) or h <= 0:
            raise OmavctlError(f"--horizons: {h:g} is not a positive number of seconds")
        k = round(float(h) * rate)
        if k < 1:
            raise OmavctlError(
                f"--horizons: {h:g} s is shorter than one step of the {rate:g} Hz grid"
            )
        if k in steps:
            raise OmavctlError(f"--horizons: {h:g} s is the same number of grid steps ({k}) twice")
        steps.append(k)
    return sorted(steps)


def _geodesic(eta_a: np.ndarray, rot_b: np.ndarray) -> np.ndarray:
    """Rotation angle (...) rad between ZYX Euler attitudes eta_a (..., 3) and the
    rotation matrices rot_b (..., 3, 3) (the logged attitude's, computed once per
    table): ``2 arcsin(|R_a - R_b|_F / (2 sqrt 2))``, accurate for small angles."""
    diff = rotation_matrix(eta_a) - rot_b
    norm = np.sqrt(np.einsum("...ij,...ij->...", diff, diff))
    return 2.0 * np.arcsin(np.clip(norm / (2.0 * np.sqrt(2.0)), 0.0, 1.0))


@dataclass
class _Run:
    """One predictor's errors: rate (W, K + 1, 3) rad/s, attitude (W, K + 1) rad or
    None, band std (W, K + 1, 3) or None."""

    rate: np.ndarray
    attitude: np.ndarray | None
    std: np.ndarray | None = None


def _rolled(
    win: Windows,
    inertia: np.ndarray,
    inertia_inv: np.ndarray,
    dt: float,
    residual: Any,
    rot: np.ndarray | None = None,
) -> _Run:
    """Errors of a rollout from every window's measured start (residual None: physics
    only); rot (W, K + 1, 3, 3) the logged attitude's rotation matrices (None: computed
    here)."""
    k = win.pos.shape[1] - 1
    eta0 = win.attitude[:, 0] if win.attitude is not None else np.zeros((win.count, 3))
    omega, eta = rollout(
        win.omega[:, 0], eta0, win.torque[:, :k], inertia, inertia_inv, dt, residual
    )
    attitude = None
    if win.attitude is not None:
        attitude = _geodesic(eta, rotation_matrix(win.attitude) if rot is None else rot)
    return _Run(rate=omega - win.omega, attitude=attitude)


def _naive(win: Windows, rot: np.ndarray | None) -> _Run:
    """Errors of holding the start state over the window (rot as in :func:`_rolled`,
    not None where the windows have an attitude)."""
    attitude = None
    if win.attitude is not None:
        assert rot is not None
        attitude = _geodesic(np.broadcast_to(win.attitude[:, :1], win.attitude.shape), rot)
    return _Run(rate=win.omega[:, :1] - win.omega, attitude=attitude)


def _band(m: ResidualGP, win: Windows, samples: Sequence[ResidualSamples], dt: float) -> np.ndarray:
    """Std (W, K + 1, 3) of the full model's body-rate error (module docstring)."""
    s_fun = per_sample(win, samples, [function_std(m, s) for s in samples])
    held = held_spread(m, win, samples)  # what the measured force's prediction errs
    if held is not None:
        s_fun = s_fun + held
    drift = np.zeros_like(s_fun)
    drift[:, 1:] = dt * np.cumsum(s_fun[:, :-1], axis=1)
    # the white residual the body rate integrates: the GP's noise variance less what the
    # log's rate noise puts into the Savitzky-Golay derivative (measurement, not motion)
    process = np.maximum(m.noise_variance[None, :] - win.derivative_noise, 0.0)  # (W, 3)
    # a random walk, times how much faster the fit flight's held-out residual adds up
    steps = np.arange(s_fun.shape[1])
    gain = walk_gain_at(m.provenance.get("rollout_walk"), steps)  # (K + 1, 3)
    walk = (steps[:, None] * gain)[None] * dt**2 * process[:, None, :]
    measured = win.noise_factor[:, :, None] * win.noise[:, None, :] ** 2
    return np.sqrt(measured + drift**2 + walk)


def _noise(samples: Sequence[ResidualSamples], signals: Sequence[GridSignals]) -> list[Any]:
    """Per log: the body-rate noise (rad/s per axis) the band uses, whether it was
    estimated on the recorded samples of a slower recording, and the grid's estimate."""
    out = []
    for s, g in zip(samples, signals, strict=True):
        grid = np.nan_to_num(np.asarray(s.rate_noise, dtype=float), nan=0.0)
        rn = g.noise if g.noise is not None else independent_noise(grid, s.index)
        out.append({**_axes(rn.std), "recorded": rn.upsampled, "grid": _axes(grid)})
    return out


def _axes(v: np.ndarray) -> dict[str, float]:
    return {a: float(v[i]) for i, a in enumerate(AXES)}


def _chunk_ids(win: Windows, k: int) -> np.ndarray:
    """Chunk (W,) of each window: its log and its start's block of ``CHUNK_HORIZONS`` x
    k samples (windows of neighbouring starts overlap: their errors are not
    independent, the chunks' means nearly are)."""
    key = win.log.astype(np.int64) * (1 << 40) + win.pos[:, 0] // max(CHUNK_HORIZONS * k, 1)
    return np.unique(key, return_inverse=True)[1].reshape(-1)


def _chunked(err: np.ndarray, ids: np.ndarray) -> tuple[dict[str, list[float]], dict[str, float]]:
    """Per chunk the mean of err (W, 4: x, y, z, norm), and the standard error of the
    mean over windows from the chunks' spread (0 with fewer than 2 chunks)."""
    n = int(ids.max()) + 1 if ids.size else 0
    counts = np.bincount(ids, minlength=n).astype(float)
    means = np.stack([np.bincount(ids, err[:, c], minlength=n) / counts for c in range(4)], 1)
    se = means.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(4)
    names = (*AXES, "norm")
    return (
        {a: means[:, c].tolist() for c, a in enumerate(names)},
        {a: float(se[c]) for c, a in enumerate(names)},
    )


def _row(run: _Run, k: int, dt: float, ids: np.ndarray) -> dict[str, Any]:
    """One predictor's table entry at k steps: mean |error| per axis and of the norm,
    their chunk means and standard errors, their sums over steps 1..k, and the
    band's coverage when it has one."""
    rate = run.rate[:, 1 : k + 1]
    norm = np.linalg.norm(rate, axis=-1)  # (W, k)
    last = np.column_stack([np.abs(rate[:, -1]), norm[:, -1]])
    chunks, se = _chunked(last, ids)
    row: dict[str, Any] = {
        "seconds": k * dt,
        "steps": k,
        "rate_error": {
            **_axes(np.abs(rate[:, -1]).mean(axis=0)),
            "norm": float(norm[:, -1].mean()),
        },
        "rate_error_se": se,
        "rate_error_chunks": chunks,
        "rate_error_sum": float(norm.sum(axis=1).mean()),
        "attitude_error": None,
        "attitude_error_sum": None,
        "coverage": None,
        "band_halfwidth": None,
    }
    if run.attitude is not None:
        row["attitude_error"] = float(run.attitude[:, k].mean())
        row["attitude_error_sum"] = float(run.attitude[:, 1 : k + 1].sum(axis=1).mean())
    if run.std is not None:
        inside = np.abs(run.rate[:, k]) <= BAND_SIGMA * run.std[:, k]
        row["coverage"] = {**_axes(inside.mean(axis=0)), "all": float(inside.mean())}
        row["band_halfwidth"] = _axes(BAND_SIGMA * run.std[:, k].mean(axis=0))
    return row


def _curve(run: _Run) -> dict[str, Any]:
    """Mean |error| per step 0..K: per axis, the norm, the attitude and the band."""
    out: dict[str, Any] = {
        a: np.abs(run.rate[:, :, i]).mean(axis=0).tolist() for i, a in enumerate(AXES)
    }
    out["norm"] = np.linalg.norm(run.rate, axis=-1).mean(axis=0).tolist()
    out["attitude"] = None if run.attitude is None else run.attitude.mean(axis=0).tolist()
    if run.std is not None:
        half = BAND_SIGMA * run.std.mean(axis=0)
        out["band"] = {a: half[:, i].tolist() for i, a in enumerate(AXES)}
    return out


def _predictors(
    models: Sequence[ResidualGP],
    win: Windows,
    samples: Sequence[ResidualSamples],
    dt: float,
) -> list[tuple[dict[str, Any], _Run]]:
    """Every predictor's description and errors: naive, nominal, then per model
    effects and the full model (with its band)."""
    v = models[0].vehicle
    rot = None if win.attitude is None else rotation_matrix(win.attitude)
    nominal = _rolled(win, v.inertia, v.inertia_inv, dt, None, rot)
    out: list[tuple[dict[str, Any], _Run]] = [
        ({"key": "naive", "kind": "naive", "model": None}, _naive(win, rot)),
        ({"key": "nominal", "kind": "nominal", "model": None}, nominal),
    ]
    for j, m in enumerate(models):
        suffix = "" if j == 0 else f"_{j}"
        # no effects: their residual is zero at every step, the rollout physics only's
        eff = (
            _rolled(
                win, v.inertia, v.inertia_inv, dt, residual_function(m, win, samples, False), rot
            )
            if m.effects
            else _Run(rate=nominal.rate, attitude=nominal.attitude)
        )
        full = _rolled(
            win, v.inertia, v.inertia_inv, dt, residual_function(m, win, samples, True), rot
        )
        full.std = _band(m, win, samples, dt)
        out.append(({"key": f"effects{suffix}", "kind": "effects", "model": j}, eff))
        weights = {a: float(w) for a, w in zip(AXES, m.rollout_gp, strict=True)}
        out.append(
            ({"key": f"model{suffix}", "kind": "model", "model": j, "rollout_gp": weights}, full)
        )
    return out


def _no_windows(steps: Sequence[int], dt: float, stride: int, n_logs: int) -> dict[str, Any]:
    """The section of logs without a stretch as long as the longest horizon: no table,
    a finding that says why (the rest of the evaluation stands)."""
    message = (
        f"no stretch of {steps[-1] + 1} consecutive usable samples ({steps[-1] * dt:g} s) in "
        "the logs: no horizon table (shorten --horizons)"
    )
    return {
        "steps": list(steps),
        "seconds": [k * dt for k in steps],
        "stride": stride,
        "windows": 0,
        "windows_by_log": [0] * n_logs,
        "band_sigma": BAND_SIGMA,
        "attitude": False,
        "predictors": [],
        "table": {},
        "curves": {},
        "findings": [
            {"code": "no_windows", "model": None, "axis": None, "value": None, "message": message}
        ],
    }


def horizon_table(
    models: Sequence[ResidualGP],
    samples: Sequence[ResidualSamples],
    signals: Sequence[GridSignals],
    rate: float,
    horizons: Sequence[float] = DEFAULT_HORIZONS,
    stride: int = 1,
) -> dict[str, Any]:
    """The evaluation's ``horizons`` section (docs/schemas.md): per predictor and
    horizon the mean error of body rate and attitude, their sums over the horizon,
    the full model's band coverage, the curves per step and the findings."""
    if stride < 1:
        raise OmavctlError(f"--horizon-stride: {stride} is not a positive number of samples")
    steps = horizon_steps(horizons, rate)
    dt = 1.0 / rate
    requested = stride
    n_total = sum(s.n for s in samples)
    stride = max(stride, math.ceil(n_total * (steps[-1] + 1) / MAX_WINDOW_SAMPLES))
    win = gather(samples, signals, steps[-1], stride)
    if win.count == 0:
        return {
            **_no_windows(steps, dt, stride, len(samples)),
            "rate_noise": _noise(samples, signals),
        }
    from threadpoolctl import threadpool_limits

    # small GEMMs per step: threaded BLAS spends more than it saves (7x on 2 busy cores)
    # a rollout that diverges (a model far outside its inputs) gives inf, written as null
    with threadpool_limits(limits=1, user_api="blas"), np.errstate(over="ignore", invalid="ignore"):
        runs = _predictors(models, win, samples, dt)
        ids = _chunk_ids(win, steps[-1])
        table = {d["key"]: [_row(run, k, dt, ids) for k in steps] for d, run in runs}
        curves = {d["key"]: _curve(run) for d, run in runs}
    tree: dict[str, Any] = {
        "steps": steps,
        "seconds": [k * dt for k in steps],
        "stride": stride,
        "stride_requested": requested,
        "windows": win.count,
        "windows_by_log": np.bincount(win.log, minlength=len(samples)).tolist(),
        "band_sigma": BAND_SIGMA,
        "chunk_seconds": CHUNK_HORIZONS * steps[-1] * dt,
        "attitude": win.attitude is not None,
        "predictors": [d for d, _ in runs],
        "table": table,
        "curves": curves,
        "rate_noise": _noise(samples, signals),
    }
    tree["findings"] = findings(tree)
    return tree
