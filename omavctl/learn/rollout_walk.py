"""How the residual a model leaves adds up over a rollout, measured on the fit flight.

The horizon band (:mod:`omavctl.diagnose.horizons`) integrates the GP's noise
variance ``s_p^2`` (what the model calls unpredictable) into the body rate. As
white noise at the grid rate it adds ``k dt^2 s_p^2`` after k steps (a random
walk). On a flight whose unexplained acceleration persists over many grid
samples (a torque the model lacks, a trim offset, an axis whose GP is off so
that all of its residual is "noise"; the Savitzky-Golay derivative itself
correlates neighbouring samples) the integral grows faster: on the Betaflight
smooth tune at 500 Hz the roll/pitch/yaw residual integrates over 0.5 s to
45/54/43 times the random walk's variance (docs/horizons.md).

So ``fit`` measures it, per axis, on its own flight's held-out time blocks:
the residual after the effects and the GP mean, the GP conditioned on the
training points outside the block (:func:`held_out_model`, the blocked
cross-validation's folds), and for window lengths k the gain

    g_k = mean over windows inside a block of (dt sum_{j<k} r_j)^2 / (k dt^2 mean(r^2))

(uncentred: a mean the model leaves integrates as it would in a rollout).
``g_1 = 1``; a white residual keeps ``g_k`` near 1, a persistent one grows it
towards k. The band multiplies the random walk by ``g_k`` (never by less than
1: a residual that integrates to less than a random walk, an oscillation, keeps
the random walk). Stored at :data:`GAIN_SECONDS` log-spaced window lengths in the
model's provenance (``rollout_walk``); between them interpolated in log k,
beyond the longest continued as fully persistent (``g_k`` proportional to k).
A file without it gets 1 (the random walk).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from omavctl.learn.model import ResidualGP
from omavctl.learn.rollout_check import held_out_model
from omavctl.learn.rollout_residual import window_starts
from omavctl.learn.signal import ResidualSamples
from omavctl.learn.validation import fold_of

__all__ = ["GAIN_SECONDS", "walk_gain", "walk_gain_at"]

#: the longest window (s) the gain is measured over
GAIN_SECONDS = 1.0
#: log-spaced window lengths stored
GAIN_POINTS = 16
AXES = ("x", "y", "z")


def _held_out_residual(
    m: ResidualGP, samples: Sequence[ResidualSamples], train_idx: np.ndarray, n_prior: int
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per log the residual (n, 3) after the effects and the held-out GP mean, and the
    fold (n,) of each sample."""
    t = np.concatenate([s.t for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    fold = fold_of(t, log_id)
    point_fold = np.concatenate([np.full(n_prior, -1), fold[train_idx]])
    offsets = np.cumsum([0] + [s.n for s in samples])
    resid = [s.residual - m.effects_samples(s) for s in samples]
    if m.n_train > 0 and np.any(m.gp_enabled):
        for f in np.unique(fold):
            if not np.any(point_fold != f):  # a flight of one block (a crash): none held out
                continue
            sub = held_out_model(m, point_fold != f)
            for i, s in enumerate(samples):
                sel = fold[offsets[i] : offsets[i + 1]] == f
                if sel.any():
                    resid[i][sel] -= sub.gp_predict(s.inputs(m.features)[sel], variance=False)[0]
    return resid, [fold[offsets[i] : offsets[i + 1]] for i in range(len(samples))]


def walk_gain(
    m: ResidualGP, samples: Sequence[ResidualSamples], train_idx: np.ndarray, n_prior: int = 0
) -> dict[str, Any]:
    """The ``rollout_walk`` provenance entry: window lengths ``steps`` (grid steps),
    ``dt`` (s) and per axis the gain ``g_k`` (>= 1) at them (module docstring);
    empty without samples."""
    if not samples:
        return {}
    dt = float(np.median(np.diff(samples[0].t))) if samples[0].n > 1 else 0.0
    if not dt > 0:
        return {}
    k_max = max(1, round(GAIN_SECONDS / dt))
    steps = np.unique(np.round(np.geomspace(1, k_max, GAIN_POINTS)).astype(int))
    resid, folds = _held_out_residual(m, samples, np.asarray(train_idx, int), n_prior)
    power = np.mean(np.concatenate(resid) ** 2, axis=0)  # (3,)
    gains = np.ones((steps.size, 3))
    for j, k in enumerate(steps):
        total, count = np.zeros(3), 0
        for s, r, f in zip(samples, resid, folds, strict=True):
            p = window_starts(s.index, int(k), 1)
            p = p[f[p] == f[p + k]]  # inside one held-out block
            if p.size == 0:
                continue
            c = np.concatenate([np.zeros((1, 3)), np.cumsum(r, axis=0)])
            total += np.sum((c[p + k] - c[p]) ** 2, axis=0)
            count += p.size
        if count and np.all(power > 0):
            gains[j] = np.maximum(total / count / (k * power), 1.0)
        elif j > 0:  # no window this long: fully persistent from the last measured
            gains[j] = gains[j - 1] * k / steps[j - 1]
    return {
        "dt": dt,
        "steps": steps.tolist(),
        "gain": {a: gains[:, i].tolist() for i, a in enumerate(AXES)},
    }


def walk_gain_at(entry: dict[str, Any] | None, steps: np.ndarray) -> np.ndarray:
    """The gain (len(steps), 3) at window lengths ``steps`` (grid steps) from a
    ``rollout_walk`` entry: interpolated in log k, beyond the longest stored length
    proportional to k; 1 without an entry (the random walk)."""
    k = np.maximum(np.asarray(steps, dtype=float), 1.0)
    if not entry or not entry.get("steps"):
        return np.ones((k.size, 3))
    at = np.asarray(entry["steps"], dtype=float)
    out = np.empty((k.size, 3))
    for i, a in enumerate(AXES):
        g = np.asarray(entry["gain"][a], dtype=float)
        out[:, i] = np.interp(np.log(k), np.log(at), g)
        out[:, i] = np.where(k > at[-1], g[-1] * k / at[-1], out[:, i])
    return np.maximum(out, 1.0)
