"""Does the GP mean help open-loop rollouts? ``fit``'s check on held-out time blocks.

``fit``'s blocked cross-validation (:mod:`omavctl.learn.validation`) judges the
GP one sample at a time, where its error is dominated by the white part of the
residual. Rolled out over 0.5 s, what counts is the part of the GP mean that
persists along a window: a mean that is one latent std off in the same
direction for half a second barely moves the one-step error and adds
``0.5 s x`` that offset to the body rate. On the px4tools octocopter the yaw
GP lowered the one-step error of the flight after the fit span by 3 % and
raised its 0.5 s error by 54 % (docs/horizons.md).

So ``fit`` rolls the model out on the fit flight's own held-out time blocks:
per fold of the blocked cross-validation, a GP conditioned on the training
points of the other folds (same hyperparameters, same effects), from every
``STRIDE``-th start whose next 0.5 s lie in the held-out fold, with the GP mean
and without it. Per axis the paired difference of the 0.5 s body-rate errors
``|e_GP| - |e_effects|`` is averaged per 0.5 s chunk of start times (windows
that overlap are not independent); the GP mean stays in rollouts
(``rollout_gp`` = 1) only if it lowers that error by more than
``SIGNIFICANCE`` standard errors of the chunk means. Otherwise rollouts leave
it out (0): the one-step predictions keep it, and the rollout band adds the
squared mean it leaves out (:func:`omavctl.learn.rollout_residual.function_std`).
A flight too short for ``MIN_CHUNKS`` chunks keeps the GP mean (nothing to
judge on), as does an axis whose GP is off.

The rollouts run on the fit's held signals (body rate and command through the
Savitzky-Golay hold), not the raw grid signals ``evaluate`` uses: the check
compares two predictors on the same data, and the hold is what fit has.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from omavctl.learn.model import ResidualGP
from omavctl.learn.rollout_residual import GridSignals, gather, residual_function
from omavctl.learn.signal import ResidualSamples
from omavctl.learn.validation import fold_of
from omavctl.physics.open_loop import rollout

__all__ = ["HORIZON_SECONDS", "RolloutVerdict", "rollout_verdict"]

#: the rollout horizon judged (s): the longest of evaluate's default horizons
HORIZON_SECONDS = 0.5
#: samples between the starts of the held-out windows
STRIDE = 10
#: start times are averaged per chunk of this length (s) before the standard error
CHUNK_SECONDS = 0.5
#: fewest chunks for a verdict (fewer: the GP mean is kept)
MIN_CHUNKS = 4
#: the GP mean must lower the held-out 0.5 s error by this many standard errors
SIGNIFICANCE = 2.0
AXES = ("x", "y", "z")


@dataclass
class RolloutVerdict:
    """Per axis: ``weights`` (3,) the GP mean's weight in rollouts (0 or 1); the held-out
    0.5 s mean |error| with (``error_gp``) and without (``error_effects``) the GP mean,
    rad/s; ``change`` the mean paired difference and ``stderr`` its standard error
    (rad/s); ``chunks`` the number of 0.5 s chunks; ``notes`` for the summary."""

    weights: np.ndarray
    error_gp: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    error_effects: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    change: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    stderr: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    chunks: int = 0
    notes: list[str] = field(default_factory=list)


def held_out_model(m: ResidualGP, keep: np.ndarray) -> ResidualGP:
    """The model conditioned on the training points where ``keep`` (n,) (same
    hyperparameters, effects and calibration; rollout weight 1)."""
    return ResidualGP(
        vehicle=m.vehicle,
        features=m.features,
        input_names=m.input_names,
        inputs=m.inputs[keep],
        targets=m.targets[keep],
        input_mean=m.input_mean,
        input_scale=m.input_scale,
        target_mean=m.target_mean,
        signal_variance=m.signal_variance,
        length_scales=m.length_scales,
        noise_variance=m.noise_variance,
        latent_scale=m.latent_scale,
        beyond_scale=m.beyond_scale,
        mean_shrink=m.mean_shrink,
        effects=m.effects,
    )


def _held_out_errors(
    m: ResidualGP, samples: Sequence[ResidualSamples], train_idx: np.ndarray, n_prior: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Errors (W, 3) at 0.5 s of held-out rollouts without and with the GP mean, and the
    chunk (W,) of each window's start."""
    sg = samples[0].sg
    dt = sg.dt if sg is not None else 1.0 / m.vehicle.gains.rate_hz
    k = max(1, round(HORIZON_SECONDS / dt))
    inertia, inertia_inv = m.vehicle.inertia, m.vehicle.inertia_inv
    signals = [GridSignals(s.omega, s.u[:, 3:] @ inertia.T, None) for s in samples]
    win = gather(samples, signals, k, STRIDE)
    t = np.concatenate([s.t for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    fold = fold_of(t, log_id)
    offsets = np.cumsum([0] + [s.n for s in samples])[:-1]
    flat = offsets[win.log][:, None] + win.pos  # (W, K + 1) positions in the concatenation
    win_fold = np.where(np.all(fold[flat] == fold[flat[:, :1]], axis=1), fold[flat[:, 0]], -1)
    point_fold = np.concatenate([np.full(n_prior, -1), fold[train_idx]])
    errors = np.full((2, win.count, 3), np.nan)
    for f in np.unique(win_fold[win_fold >= 0]):
        sel = win_fold == f
        if not np.any(point_fold != f):  # every training point in this fold: none held out
            win_fold[sel] = -1
            continue
        sub, part = held_out_model(m, point_fold != f), win.subset(sel)
        eta0 = np.zeros((part.count, 3))
        for j, with_gp in enumerate((False, True)):
            fn = residual_function(sub, part, samples, with_gp)
            omega, _ = rollout(
                part.omega[:, 0], eta0, part.torque[:, :k], inertia, inertia_inv, dt, fn
            )
            errors[j, sel] = omega[:, k] - part.omega[:, k]
    chunk = np.floor(t[flat[:, 0]] / CHUNK_SECONDS).astype(np.int64) + 10**6 * win.log
    ok = win_fold >= 0
    return errors[0, ok], errors[1, ok], chunk[ok]


def rollout_verdict(
    m: ResidualGP, samples: Sequence[ResidualSamples], train_idx: np.ndarray, n_prior: int = 0
) -> RolloutVerdict:
    """Whether each axis' GP mean lowers the 0.5 s error of held-out rollouts (module
    docstring). samples: the fit's residual samples (with their effect contexts);
    train_idx (n - n_prior,): the training points' positions in the concatenated
    samples; the first ``n_prior`` training points (a prior model's) are in no fold."""
    verdict = RolloutVerdict(weights=np.ones(3))
    if not np.any(m.gp_enabled) or not samples:
        return verdict
    from threadpoolctl import threadpool_limits

    # small products per step: threaded BLAS spends more than it saves (as in evaluate)
    with threadpool_limits(limits=1, user_api="blas"):
        e_eff, e_gp, chunk = _held_out_errors(m, samples, np.asarray(train_idx, int), n_prior)
    ids, inverse = np.unique(chunk, return_inverse=True)
    verdict.chunks = int(ids.size)
    if ids.size < MIN_CHUNKS:
        verdict.notes.append(
            f"too short to judge the GP mean on held-out rollouts ({ids.size} chunks of "
            f"{CHUNK_SECONDS:g} s, {MIN_CHUNKS} needed): rollouts keep it"
        )
        return verdict
    diff = np.abs(e_gp) - np.abs(e_eff)  # (W, 3)
    counts = np.bincount(inverse)
    means = np.stack([np.bincount(inverse, diff[:, a]) / counts for a in range(3)], axis=1)
    verdict.error_gp, verdict.error_effects = np.abs(e_gp).mean(0), np.abs(e_eff).mean(0)
    verdict.change = means.mean(axis=0)
    verdict.stderr = means.std(axis=0, ddof=1) / np.sqrt(ids.size)
    for a, name in enumerate(AXES):
        if not m.gp_enabled[a]:
            continue
        if verdict.change[a] < -SIGNIFICANCE * verdict.stderr[a]:
            continue
        verdict.weights[a] = 0.0
        verdict.notes.append(
            f"axis {name}: the GP mean is left out of open-loop rollouts: on held-out time "
            f"blocks it changes the {HORIZON_SECONDS:g} s body-rate error by "
            f"{verdict.change[a]:+.3g} ± {verdict.stderr[a]:.2g} rad/s "
            f"({verdict.error_effects[a]:.3g} -> {verdict.error_gp[a]:.3g}), not "
            f"{SIGNIFICANCE:g} standard errors below 0"
        )
    return verdict
