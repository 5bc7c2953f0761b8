"""Windows of logs and the residual a model adds when it is rolled out open loop.

Shared by ``evaluate``'s horizon table (:mod:`omavctl.diagnose.horizons`) and
``fit``'s check of the GP mean on held-out rollouts
(:mod:`omavctl.learn.rollout_check`). A window is K + 1 consecutive kept grid
samples of one log; all windows of all logs are rows of the same arrays, and
:func:`residual_function` gives the model's residual angular acceleration at
step k from the rolled-out body rate, for
:func:`omavctl.physics.open_loop.rollout`.

The effects are evaluated per grid period as the rigid body's torque is: at
the rolled-out body rate and each period's logged command (not the
Savitzky-Golay hold of the one-step residual, which averages ten periods);
effects that act through the command history only (lags, delay: a 1-D
search) through their exact form on the log, each period's own mean (the
lag's state from the logged command history), and effects that do not move
with the body rate on their full log context (per-rotor commands, battery
voltage), once per sample. The GP, fitted on held inputs, is evaluated at the
held commands and the rolled-out body rate. The GP mean enters with the
model's per-axis ``rollout_gp`` weight (``fit``'s verdict on held-out
rollouts; 1 for older files).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from omavctl.learn.band import growth_variance
from omavctl.learn.gp_mean import FusedMean
from omavctl.learn.model import ResidualGP
from omavctl.learn.recorded_noise import RecordedNoise, independent_noise
from omavctl.learn.rollout_force import (
    ForceRollout,
    force_residual,
    gravity_offset,
    lateral_drag,
    roll_force,
    trailing_mean,
)
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.open_loop import AttitudeResidual

__all__ = [
    "GridSignals",
    "Windows",
    "function_std",
    "gather",
    "held_spread",
    "per_sample",
    "residual_function",
    "window_starts",
]


@dataclass(frozen=True)
class GridSignals:
    """Unfiltered grid signals of one log at its kept samples (n of them): body rate
    (n, 3) rad/s, torque command (n, 3), attitude (n, 3) ZYX Euler rad or None; the
    body rate's noise at them (None: the samples' ``rate_noise``, independent per
    sample)."""

    body_rate: np.ndarray
    torque: np.ndarray
    attitude: np.ndarray | None
    noise: RecordedNoise | None = None


@dataclass
class Windows:
    """The windows of all logs, concatenated (W of them, K + 1 samples each).

    log (W,) index of the log; pos (W, K + 1) sample positions in their log;
    omega, torque, u, du, attitude gathered at them ((W, K + 1, c)); noise (W, 3)
    the body-rate noise std of their log (rad/s); noise_factor (W, K + 1) the
    variance of the noise of sample k less the start's, in units of ``noise**2``
    (2 for independent noise, less for a log interpolated from a slower
    recording); derivative_noise (W, 3) the variance (rad/s^2)^2 that noise puts
    into the Savitzky-Golay derivative.
    """

    log: np.ndarray
    pos: np.ndarray
    omega: np.ndarray
    torque: np.ndarray
    u: np.ndarray
    du: np.ndarray
    attitude: np.ndarray | None
    noise: np.ndarray
    noise_factor: np.ndarray
    derivative_noise: np.ndarray

    @property
    def count(self) -> int:
        return int(self.log.size)

    def subset(self, keep: np.ndarray) -> Windows:
        """The windows where ``keep`` (W,) bool is True."""
        att = None if self.attitude is None else self.attitude[keep]
        return Windows(
            self.log[keep],
            self.pos[keep],
            self.omega[keep],
            self.torque[keep],
            self.u[keep],
            self.du[keep],
            att,
            self.noise[keep],
            self.noise_factor[keep],
            self.derivative_noise[keep],
        )


def window_starts(index: np.ndarray, k: int, stride: int) -> np.ndarray:
    """Positions p (every ``stride``-th) whose samples p .. p + k are consecutive grid
    indices: index (n,) the kept grid indices of a log, increasing."""
    n = index.size
    if n <= k:
        return np.empty(0, dtype=int)
    p = np.arange(0, n - k, stride)
    return p[index[p + k] - index[p] == k]


def gather(
    samples: Sequence[ResidualSamples], signals: Sequence[GridSignals], k: int, stride: int
) -> Windows:
    """Every log's windows of k steps (:func:`window_starts`), gathered."""
    keys = ("log", "pos", "omega", "torque", "u", "du", "attitude", "noise", "factor", "deriv")
    parts: dict[str, list[np.ndarray]] = {key: [] for key in keys}
    has_attitude = all(g.attitude is not None for g in signals)
    for i, (s, g) in enumerate(zip(samples, signals, strict=True)):
        pos = window_starts(s.index, k, stride)[:, None] + np.arange(k + 1)
        parts["log"].append(np.full(pos.shape[0], i))
        parts["pos"].append(pos)
        parts["omega"].append(g.body_rate[pos])
        parts["torque"].append(g.torque[pos])
        parts["u"].append(s.u[pos])
        parts["du"].append(s.du[pos] if s.du.shape[0] == s.n else np.zeros((*pos.shape, 6)))
        if has_attitude:
            assert g.attitude is not None
            parts["attitude"].append(g.attitude[pos])
        rn = g.noise if g.noise is not None else independent_noise(s.rate_noise, s.index)
        parts["noise"].append(np.broadcast_to(rn.std, (pos.shape[0], 3)))
        parts["factor"].append(rn.difference_factor(pos[:, :1], pos))
        gain = 0.0 if s.sg is None else rn.derivative_factor(s.sg.derivative_coefficients, s.index)
        parts["deriv"].append(np.broadcast_to(gain * rn.std**2, (pos.shape[0], 3)))
    cat = {key: np.concatenate(v) if v else np.empty(0) for key, v in parts.items()}
    return Windows(
        log=cat["log"].astype(int),
        pos=cat["pos"].reshape(-1, k + 1).astype(int),
        omega=cat["omega"].reshape(-1, k + 1, 3),
        torque=cat["torque"].reshape(-1, k + 1, 3),
        u=cat["u"].reshape(-1, k + 1, 6),
        du=cat["du"].reshape(-1, k + 1, 6),
        attitude=cat["attitude"].reshape(-1, k + 1, 3) if has_attitude else None,
        noise=cat["noise"].reshape(-1, 3),
        noise_factor=cat["factor"].reshape(-1, k + 1),
        derivative_noise=cat["deriv"].reshape(-1, 3),
    )


def per_sample(
    win: Windows, samples: Sequence[ResidualSamples], values: Sequence[np.ndarray]
) -> np.ndarray:
    """Per-log sample series ``values[i]`` (n_i, c) gathered at the windows (W, K + 1, c)."""
    if win.count == 0:
        return np.empty((0, win.pos.shape[1], values[0].shape[1] if values else 0))
    out = np.empty((win.count, win.pos.shape[1], values[0].shape[1]))
    for i in range(len(samples)):
        sel = win.log == i
        out[sel] = values[i][win.pos[sel]]
    return out


#: the effects a rollout adds per grid period as the physics acts over it (unheld); False:
#: held like the one-step residual (the Savitzky-Golay kernel's weighted mean over
#: neighbouring periods), as before 2026-11-26 (kept for benchmarks/horizons_lag.py)
PER_PERIOD = True


def _on_log(s: ResidualSamples, values: Any) -> np.ndarray:
    """``values(ctx)`` (N, c) per grid period of each kept segment, at the samples (n, c):
    not held (a rollout step integrates one period, not the derivative's window)."""
    parts = [np.asarray(values(ctx))[keep] for ctx, keep in s.contexts]
    out = np.concatenate(parts) if parts else np.empty((0, 3))
    return out if s.mask is None else out[s.mask]


def _history_effects(m: ResidualGP, s: ResidualSamples) -> np.ndarray:
    """Residual (n, 3) of the model's effects that act through the command history
    (lags, delay: estimated by a 1-D search) in their exact form on the log, each
    period's own mean (the lag's state from the logged command history), beside the
    rigid body's logged command of that period: together the lagged command."""
    out = np.zeros((s.n, 3))
    for est in m.effects.values():
        effect = est.effect
        if effect.search is None:
            continue
        value = float(est.values[effect.parameters[0].name][0])
        if PER_PERIOD:
            out += _on_log(s, lambda ctx, e=effect, v=value: e.exact(ctx, v))
        else:
            out += s.exact(est.name, value)
    return out


def _static_effects(m: ResidualGP, s: ResidualSamples) -> np.ndarray:
    """Residual (n, 3) of effects that do not move with the body rate, per period on the
    log (their full context: per-rotor commands, battery voltage)."""
    if PER_PERIOD and s.contexts:
        return _on_log(s, m.effects_residual)
    return m.effects_mean(s.u, s.omega)


def _commands(m: ResidualGP, s: ResidualSamples) -> np.ndarray:
    """Scaled wrench u (n, 6) per period as logged (what the rigid body integrates), for
    effects that move with the body rate; the held u without effect contexts."""
    if not (PER_PERIOD and s.contexts):
        return s.u
    v = m.vehicle
    return _on_log(s, lambda c: np.hstack([c.force / v.mass, c.torque @ v.inertia_inv.T]))


def function_std(m: ResidualGP, s: ResidualSamples) -> np.ndarray:
    """Std (n, 3) of the residual function a rollout uses at the log's inputs: the GP's
    latent variance plus the effects' parameter variance and the rotors' spread (no
    measurement noise), plus ``((1 - w) m)^2`` for the part ``1 - w`` of the GP mean m
    a rollout leaves out (``rollout_gp`` weight w: predicting 0 where the GP says m
    costs m^2), plus the one-step band's growth beyond the fit flight's inputs
    (:func:`omavctl.learn.band.growth_variance`: how far the model's error may grow
    where the fit flight never went, an error of the function, which a rollout
    integrates; zero inside the inputs)."""
    z = s.inputs(m.features)
    mean, var = m.gp_predict(z, noise=False)
    assert var is not None
    var = var + ((1.0 - m.rollout_gp) * mean) ** 2 + m.effects_variance(s)
    var = var + growth_variance(m, z)
    return np.sqrt(np.maximum(var, 0.0))


def _with_effects(m: ResidualGP, names: Sequence[str]) -> ResidualGP | None:
    """The model with only the named effects (a shallow copy; None for none)."""
    if not names:
        return None
    sub = copy.copy(m)
    sub.effects = {n: m.effects[n] for n in names}
    return sub


def _split_effects(m: ResidualGP, win: Windows) -> tuple[ResidualGP | None, ResidualGP | None]:
    """The model's effects that do not depend on the body rate (evaluated once per
    sample: the rotor interference's allocation is costly) and those that do (per
    step), found by moving the body rate of a few windows' starts; those of a measured
    state (:func:`_held`) are in neither."""
    u, omega = win.u[:8, 0], win.omega[:8, 0]
    static: list[str] = []
    moving: list[str] = []
    linear = (n for n, e in m.effects.items() if e.effect.search is None)
    for name in (n for n in linear if not m.effects[n].effect.measured_state):
        sub = _with_effects(m, [name])
        assert sub is not None
        same = np.array_equal(sub.effects_mean(u, omega), sub.effects_mean(u, omega + 0.37))
        (static if same else moving).append(name)
    return _with_effects(m, static), _with_effects(m, moving)


#: effects of a measured state (``Effect.measured_state``: the accelerometer's force): on a
#: log with an attitude the lateral force is rolled forward from the window's start by the
#: rolled-out attitude (:mod:`omavctl.learn.rollout_force`), else held at the start, what
#: an open-loop prediction may know; False: read from the log along the window (an
#: oracle, for benchmarks)
HOLD_MEASURED = True
#: roll the measured force forward where the log has an attitude (False: hold it there
#: too, as before session 15; kept for benchmarks/horizons_force.py)
PREDICT_FORCE = True


#: on a log with an attitude, the force a rollout starts from: the mean of the window's
#: first sample and those of the Savitzky-Golay window before it (the past only: the
#: accelerometer's vibration does not persist over a window); False: the start's sample
START_MEAN = True


@dataclass
class _Measured:
    """The measured-state effects (a sub-model), their residual (W, K + 1, 3) along the
    windows as the log has it, the median-free force (W, K + 1, 3) N; when the force is
    rolled forward (else None): the force a rollout starts from (W, 3) N, its residual
    (W, 3), the gravity offset (W, 2) and the lateral drag d (1/s)."""

    sub: ResidualGP
    series: np.ndarray
    force: np.ndarray
    start: np.ndarray | None = None
    start_value: np.ndarray | None = None
    offset: np.ndarray | None = None
    drag: float | None = None


def _force_on_log(s: ResidualSamples) -> np.ndarray:
    """The median-free measured force (n, 3) N at the samples (zeros without one)."""
    if not s.contexts:
        return np.zeros((s.n, 3))
    return _on_log(
        s, lambda c: np.zeros((c.omega.shape[0], 3)) if c.measured_force is None
        else c.measured_force
    )  # fmt: skip


def _start_mean(force: np.ndarray, s: ResidualSamples) -> np.ndarray:
    """:func:`trailing_mean` (n, 3) of the force over the Savitzky-Golay window, within
    each run of consecutive grid samples (not across a gap or a segment edge)."""
    n = s.sg.window if s.sg else 1
    cuts = np.flatnonzero(np.diff(s.index) != 1) + 1
    parts = [trailing_mean(f, n) for f in np.split(force, cuts)]
    return np.concatenate(parts) if parts else force


def _measured(m: ResidualGP, win: Windows, samples: Sequence[ResidualSamples]) -> _Measured | None:
    """The model's measured-state effects along the windows; None for none."""
    sub = _with_effects(m, [n for n, e in m.effects.items() if e.effect.measured_state])
    if sub is None:
        return None
    series = per_sample(win, samples, [_static_effects(sub, s) for s in samples])
    on_log = [_force_on_log(s) for s in samples]
    got = _Measured(sub, series, per_sample(win, samples, on_log))
    if not (PREDICT_FORCE and HOLD_MEASURED and win.attitude is not None):
        return got
    v = m.vehicle
    if START_MEAN:
        means = [_start_mean(f, s) for f, s in zip(on_log, samples, strict=True)]
        got.start = per_sample(win, samples, means)[:, 0]
    else:
        got.start = got.force[:, 0]
    got.start_value = series[:, 0] + force_residual(sub.effects, got.start - got.force[:, 0],
                                                    v.inertia_inv)  # fmt: skip
    got.offset = gravity_offset(win.attitude, win.log)
    got.drag = lateral_drag(got.force, win.attitude, got.offset, v.mass, 1.0 / v.gains.rate_hz)
    return got


def _held(m: ResidualGP, win: Windows, samples: Sequence[ResidualSamples]) -> np.ndarray | None:
    """Residual (W, 1, 3) of the model's measured-state effects at each window's start
    (W, K + 1, 3 along the window when :data:`HOLD_MEASURED` is False); None for none."""
    got = _measured(m, win, samples)
    if got is None:
        return None
    return got.series[:, :1] if HOLD_MEASURED else got.series


class _PredictedForce:
    """The measured-state effects' residual (W, 3) as a rollout predicts it: called as
    ``f(k, eta)`` with the rolled-out attitude eta (W, 3) at step k's midpoint; the
    first call of a rollout (step 0, before the steps) gives the start's value."""

    def __init__(self, m: ResidualGP, got: _Measured) -> None:
        assert got.start is not None and got.start_value is not None and got.offset is not None
        self.m, self.got = m, got
        self.start, self.value, self.offset = got.start, got.start_value, got.offset
        self.roll: ForceRollout | None = None

    def __call__(self, k: int, eta: np.ndarray) -> np.ndarray:
        v = self.m.vehicle
        if k == 0 and self.roll is None:
            drag = self.got.drag or 0.0
            self.roll = ForceRollout(self.start, self.offset, drag, v.mass, 1.0 / v.gains.rate_hz)
            return self.value
        assert self.roll is not None
        df = self.roll.step(eta) - self.start
        if k == self.got.series.shape[1] - 2:  # the last step: the next rollout starts anew
            self.roll = None
        return self.value + force_residual(self.got.sub.effects, df, v.inertia_inv)


def predicted_force(m: ResidualGP, win: Windows, samples: Sequence[ResidualSamples]) -> Any:
    """The measured-state effects' residual along the windows as a rollout predicts it
    from the rolled-out attitude (:class:`_PredictedForce`); None when the model has none
    or the force is held (no attitude, :data:`PREDICT_FORCE`)."""
    got = _measured(m, win, samples)
    if got is None or got.drag is None:
        return None
    return _PredictedForce(m, got)


def held_spread(
    m: ResidualGP, win: Windows, samples: Sequence[ResidualSamples]
) -> np.ndarray | None:
    """Std (W, K + 1, 3) of the measured-state effects' error in a rollout after k steps:
    ``sqrt(mean (p_k - g_k)^2)`` over the windows of the same log (a statistic of the
    log's measured force, as its rate noise is), with ``g_k`` the term on the log and
    ``p_k`` the rollout's: the start's value held (:data:`HOLD_MEASURED`), or, on a log
    with an attitude, the force rolled forward by the logged attitude (the error the
    prediction makes where the attitude is right); None when the log's force is read."""
    got = _measured(m, win, samples)
    if got is None or not HOLD_MEASURED or win.count == 0:
        return None
    err = (got.series - got.series[:, :1]) ** 2
    if got.drag is not None and win.attitude is not None:
        assert got.start is not None and got.start_value is not None and got.offset is not None
        v = m.vehicle
        mid = 0.5 * (win.attitude[:, 1:] + win.attitude[:, :-1])  # steps' midpoints
        f = roll_force(got.start, got.offset, mid, got.drag, v.mass, 1.0 / v.gains.rate_hz)
        moved = force_residual(got.sub.effects, f - got.start[:, None], v.inertia_inv)
        on_log = 0.5 * (got.series[:, 1:] + got.series[:, :-1])
        err[:, :-1] = (got.start_value[:, None] + moved - on_log) ** 2
        err[:, -1] = err[:, -2]
    out = np.empty_like(got.series)
    for i in np.unique(win.log):
        sel = win.log == i
        out[sel] = np.sqrt(err[sel].mean(axis=0))
    return out


def _rolled_mean(m: ResidualGP) -> Any:
    """The GP mean (B, 3) at GP inputs (B, d) as a rollout calls it: the fused float32
    product, or ``gp_predict`` when the model weighs its mean by its band
    (``mean_shrink``: the weight needs the latent variance, which the fused product
    does not compute; the rollout then predicts what ``evaluate``'s one-step
    metrics predict)."""
    if np.any(m.mean_shrink > 0):
        return lambda z: m.gp_predict(z, variance=False)[0]
    return FusedMean(m)


def residual_function(
    m: ResidualGP, win: Windows, samples: Sequence[ResidualSamples], with_gp: bool
) -> Any:
    """The residual ``f(k, omega)`` (W, 3) of the effects (and the GP mean, weighed by
    ``m.rollout_gp``) at step k, for :func:`omavctl.physics.open_loop.rollout`."""
    static, moving = _split_effects(m, win)
    fixed = [_history_effects(m, s) for s in samples]  # what the body rate does not change
    if static is not None:
        fixed = [f + _static_effects(static, s) for f, s in zip(fixed, samples, strict=True)]
    weight = np.asarray(m.rollout_gp, dtype=float)
    with_gp = with_gp and bool(np.any(weight > 0))
    uses_rate = "rate" in m.features.split("+")
    if with_gp and not uses_rate:  # the GP mean needs no rollout
        fixed = [
            f + weight * m.gp_predict(s.inputs(m.features), variance=False)[0]
            for f, s in zip(fixed, samples, strict=True)
        ]
    gp_rolled = _rolled_mean(m) if with_gp and uses_rate else None
    base = per_sample(win, samples, fixed)
    predicted = predicted_force(m, win, samples)
    held = None if predicted is not None else _held(m, win, samples)
    if held is not None:
        base = base + held
    u_now = None if moving is None else per_sample(win, samples, [_commands(m, s) for s in samples])

    def residual(k: int, omega: np.ndarray, eta: np.ndarray | None = None) -> np.ndarray:
        out = base[:, k]
        if predicted is not None:
            assert eta is not None
            out = out + predicted(k, eta)
        if moving is not None:
            assert u_now is not None
            out = out + moving.effects_mean(u_now[:, k], omega)
        if gp_rolled is not None:
            out = out + weight * gp_rolled(m.gp_inputs(win.u[:, k], omega, win.du[:, k]))
        return out

    if predicted is not None:
        return AttitudeResidual(residual)
    return residual
