"""How well a prediction matches the measurements, and where it fails.

Metrics per axis (rad/s^2): RMSE, MAE, R^2 of the residual (1 - SSE / SS of
the nominal residual about its mean: the fraction of the nominal model's
error the prediction explains), mean predicted std, fraction of samples
within 2 sigma, and negative log predictive density. Where the model fails:
the worst time windows (:func:`worst_segments`) and its error in quantile
bins of each feature (:func:`binned_errors`). What a reader must know before
trusting a model on the logs: :func:`quality_flags`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = [
    "AXES",
    "MAX_RATIO",
    "MIN_COVERAGE",
    "axis_metrics",
    "binned_errors",
    "quality_flags",
    "worst_segments",
]

AXES = ("x", "y", "z")
#: Sliding window of the worst-segment search, s; segments reported.
WORST_WINDOW_SECONDS = 1.0
WORST_COUNT = 5
#: Quantile bins of the residual-vs-feature tables.
BINS = 10

#: Held-out 2-sigma coverage below which the model's uncertainty is overconfident.
MIN_COVERAGE = 0.8
#: Model RMSE above this multiple of physics-only (nominal + effects) is flagged.
MAX_RATIO = 1.05


def axis_metrics(
    measured: np.ndarray, predicted: np.ndarray, std: np.ndarray, reference: np.ndarray
) -> dict[str, dict[str, float]]:
    """Per-axis metrics of a prediction.

    measured, predicted (n, 3) angular accelerations; std (n, 3) predictive std;
    reference (n, 3) the nominal residual. ``r2`` is the fraction of the nominal
    model's squared error the prediction removes, ``1 - SSE / sum(reference^2)``: 0 for
    the nominal model itself, 1 for a perfect prediction, negative when it is worse
    than the nominal. Returns ``{metric: {"x": .., "y": .., "z": ..}}``.
    """
    err = measured - predicted
    sse = (err**2).sum(axis=0)
    sst = (reference**2).sum(axis=0)
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


def worst_segments(
    t: np.ndarray,
    log_id: np.ndarray,
    err: np.ndarray,
    context: dict[str, np.ndarray],
    log_names: Sequence[str],
    dt: float,
) -> list[dict[str, Any]]:
    """Top non-overlapping sliding windows by RMSE of err (n, 3).

    t (n,) times, log_id (n,) index into ``log_names``; context: name -> (n, k)
    values whose mean |value| over each window is reported with it; dt the
    grid step. At most :data:`WORST_COUNT` windows of :data:`WORST_WINDOW_SECONDS`.
    """
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


def binned_errors(
    err: np.ndarray, nominal_err: np.ndarray, features: dict[str, np.ndarray]
) -> dict[str, Any]:
    """Error of the model and of the nominal model in quantile bins of each feature.

    err, nominal_err (n, 3); features: name -> (n,) values, binned at
    :data:`BINS` quantiles (features with fewer than 2 distinct bins left out).
    """
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


def quality_flags(
    metrics: dict[str, Any],
    excluded: Sequence[dict[str, Any]],
    claims: Sequence[str] = (),
    shares: Mapping[str, Mapping[str, float]] | None = None,
) -> list[dict[str, Any]]:
    """What a reader must know before trusting the model on these logs.

    ``overconfident``: 2-sigma coverage below :data:`MIN_COVERAGE` on an axis;
    ``worse_than_physics``: the model's RMSE above :data:`MAX_RATIO` x that of
    nominal + effects (the GP hurts); ``no_better_than_zero``: the model's RMSE not
    below the RMS of the measured angular acceleration (``metrics.zero``; its advice
    names the diagnosis's ``claims`` that act on the axis first, :func:`_zero_advice`:
    ``shares`` per claim and axis the share of the error it explains, an axis under
    :data:`ZERO_ADVICE_SHARE` not its; a Crazyflie's z, 0 % of it motor_lag's, was told
    to add motor_lag first);
    ``out_of_control``: samples excluded.
    """
    flags: list[dict[str, Any]] = []
    for a in AXES:
        zero = (metrics.get("zero") or {}).get("rmse", {}).get(a)
        if zero is not None and metrics["model"]["rmse"][a] >= zero:
            flags.append(
                {
                    "code": "no_better_than_zero",
                    "axis": a,
                    "value": metrics["model"]["rmse"][a] / zero if zero > 0 else None,
                    "message": f"axis {a}: the model's error "
                    f"({metrics['model']['rmse'][a]:.3g} rad/s² RMS) is not below the "
                    f"angular acceleration itself ({zero:.3g}): predicting none would do "
                    f"as well; {_zero_advice(_acting(claims, shares, a))}",
                }
            )
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


#: A claim that explains under this share of an axis's error is not advised on that
#: axis (as the verdict names the axes of a claim, AXIS_CLAIM).
ZERO_ADVICE_SHARE = 0.05


def _acting(
    claims: Sequence[str], shares: Mapping[str, Mapping[str, float]] | None, axis: str
) -> list[str]:
    """The ``claims`` that explain at least :data:`ZERO_ADVICE_SHARE` of ``axis``'s
    error (all of those without shares)."""
    return [
        c
        for c in claims
        if shares is None or c not in shares or shares[c].get(axis, 1.0) >= ZERO_ADVICE_SHARE
    ]


def _zero_advice(claims: Sequence[str]) -> str:
    """What to do about a model no better than predicting no acceleration. With effects
    the diagnosis claims, adding them comes first: on a flight whose angular
    acceleration is small on an axis (a figure-8's roll), a missing effect alone can
    exceed it (report6 draw 28: a default thrust spread's CoM offset and a hidden 50 ms
    delay left x at 1.15 rad/s² RMS against a 0.40 signal), while a wrong gain, sign or
    frame of the command is what is left when nothing explains the error."""
    frame = (
        "check the command's gain, sign and frame, and whether the flight moves the "
        "vehicle enough for its commands to show"
    )
    if not claims:
        return frame
    return (
        f"the diagnosis names what the physics lacks ({', '.join(claims)}): add "
        f"{'them' if len(claims) > 1 else 'it'} first; if the error stays, {frame}"
    )


#: Training ranges beyond which (or an input constant in training that varies) model
#: and log may not belong together (``far_outside_training`` flag).
FAR_RANGES = 10.0


def envelope_flags(env: Mapping[str, Any] | None) -> list[dict[str, Any]]:
    """A ``far_outside_training`` flag when the log goes more than :data:`FAR_RANGES`
    training ranges beyond the model's inputs, or varies an input that was constant in
    training (``env``: :func:`training_envelope`'s result)."""
    if not env:
        return []
    beyond = dict(env.get("beyond") or {})
    unvaried = list(env.get("unvaried") or {})
    flags = []
    # an input the fit flight barely moved is far in its own tiny range: say that first
    weak = {
        k: v for k, v in (env.get("underexcited") or {}).items() if beyond.get(k, 0) > FAR_RANGES
    }
    if weak:
        flags.append(_underexcited_flag(weak, beyond))
        beyond = {k: v for k, v in beyond.items() if k not in weak}
    name, far = max(beyond.items(), key=lambda kv: kv[1], default=("", 0.0))
    if far <= FAR_RANGES and not unvaried:
        return flags
    what = (
        [f"goes {far:.0f} training ranges beyond the model's inputs ({name})"]
        if far > FAR_RANGES
        else []
    )
    if unvaried:
        what.append(f"varies {', '.join(unvaried)}, constant in training")
    return [
        *flags,
        {
            "code": "far_outside_training",
            "axis": None,
            "value": far if far > FAR_RANGES else None,
            "message": f"The log {' and '.join(what)}: is the model this vehicle's, and "
            "are the log's units and frame the model's?",
        },
    ]


def input_unit(name: str) -> str:
    """The unit of a GP input by its name (:func:`omavctl.learn.signal.feature_names`)."""
    if name.startswith("d/dt"):
        return "rad/s³"
    if name.startswith("(I^-1 tau)"):
        return "rad/s²"
    if name.startswith("f"):
        return "m/s²"
    return "rad/s" if name.startswith("w") else ""


def _underexcited_flag(
    weak: Mapping[str, Mapping[str, float]], beyond: Mapping[str, float]
) -> dict[str, Any]:
    """The ``underexcited`` flag: inputs the fit flight barely moved, which this log
    moves :data:`UNDEREXCITED_RATIO` times more (so it lies many of their training
    ranges beyond the model's inputs without any mismatch of model and log)."""
    parts = []
    for name, span in weak.items():
        s, f, unit = span["training_span"], span["flight_span"], input_unit(name)
        parts.append(f"{name} (over {s:.2g} {unit} there, {f:.2g} {unit} here)".replace("  ", " "))
    far = max(beyond[k] for k in weak)
    names = ", ".join(weak)
    return {
        "code": "underexcited",
        "axis": None,
        "value": far,
        "message": f"The fit flight barely excited {'; '.join(parts)}: this log goes "
        f"{far:.0f} of those training ranges beyond the model's inputs because the fit "
        f"flight did not move {'it' if len(weak) == 1 else 'them'}, not (as far as this "
        f"shows) because model and log differ. Fit on a flight that moves {names} (or on "
        "both logs) before trusting the model here.",
    }


#: An input varied in training counts as barely excited by the fit flight when the
#: evaluated flight moves it over this many times its training range.
UNDEREXCITED_RATIO = 10.0

#: A held-out sample is outside the training envelope when one of its GP inputs
#: lies beyond the training points' [min, max] by more than this fraction of it.
ENVELOPE_MARGIN = 0.25


def _excursions(
    train_inputs: np.ndarray, inputs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per input (d,): varied in training, its training span (1 where unvaried); per
    sample and input (n, d): the gap beyond the training [min, max], that gap in
    training spans (0 for unvaried inputs), and whether an unvaried input moved."""
    lo, hi = train_inputs.min(axis=0), train_inputs.max(axis=0)
    scale = np.maximum(np.maximum(np.abs(lo), np.abs(hi)), 1.0)
    varied = hi - lo > 1e-9 * scale
    span = np.where(varied, hi - lo, 1.0)
    gap = np.maximum(lo - inputs, inputs - hi).clip(min=0.0)
    beyond = np.where(varied, gap / span, 0.0)
    moved = ~varied & (gap > 1e-9 * scale)
    return varied, span, gap, beyond, moved


def outside_envelope(train_inputs: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """Whether each sample (n,) of inputs (n, d) lies outside the envelope of the
    training inputs (m, d), as :func:`training_envelope` counts it: beyond an input's
    training [min, max] by more than :data:`ENVELOPE_MARGIN` of its range, or an input
    that did not vary in training has moved."""
    _, _, _, beyond, moved = _excursions(train_inputs, inputs)
    return np.asarray((beyond > ENVELOPE_MARGIN).any(axis=1) | moved.any(axis=1))


def training_envelope(
    train_inputs: np.ndarray,
    inputs: np.ndarray,
    names: Sequence[str],
    error: np.ndarray,
    std: np.ndarray,
) -> dict[str, Any]:
    """How much of a flight lies beyond the inputs a model was trained on, and the
    model's 2-sigma coverage inside and outside that envelope.

    train_inputs (m, d) the model's training inputs and inputs (n, d) the flight's,
    in the same (unnormalised) units; error (n, 3) measured minus predicted residual,
    std (n, 3) the predictive std. ``beyond`` gives, per input that leaves the
    envelope, the largest excursion in units of its training range; ``unvaried``,
    per input that did not vary in training (a normalised thrust's x and y, say)
    but does here, the largest distance from its training value (its units): no
    range to measure it in, and every such sample is outside.
    """
    varied, span, gap, beyond, moved = _excursions(train_inputs, inputs)
    outside = np.asarray((beyond > ENVELOPE_MARGIN).any(axis=1) | moved.any(axis=1))
    within = np.abs(error) <= 2.0 * std

    def coverage(sel: np.ndarray) -> dict[str, float | None]:
        n = int(sel.sum())
        return {a: float(within[sel, i].mean()) if n else None for i, a in enumerate(AXES)}

    flight_span = np.ptp(inputs, axis=0) if inputs.size else np.zeros(len(names))
    # barely excited: this flight moves the input far more, around the level the fit
    # flight held it at (a level outside this flight's range is a mismatch of model and
    # log: a normalised thrust's fz/m of 0.2 against 9.8 m/s^2 here)
    mid = 0.5 * (train_inputs.min(axis=0) + train_inputs.max(axis=0)) if inputs.size else 0.0
    held = (inputs.min(axis=0) <= mid) & (mid <= inputs.max(axis=0)) if inputs.size else False
    weak = varied & held & (flight_span >= UNDEREXCITED_RATIO * span)
    worst = beyond.max(axis=0) if inputs.size else np.zeros(len(names))
    far = gap.max(axis=0) if inputs.size else np.zeros(len(names))
    order = np.argsort(-worst)
    return {
        "margin": ENVELOPE_MARGIN,
        "outside_fraction": float(outside.mean()) if outside.size else 0.0,
        "beyond": {names[j]: float(worst[j]) for j in order if worst[j] > ENVELOPE_MARGIN},
        "unvaried": {names[j]: float(far[j]) for j in range(len(names)) if moved[:, j].any()},
        "underexcited": {
            names[j]: {"training_span": float(span[j]), "flight_span": float(flight_span[j])}
            for j in map(int, np.flatnonzero(weak))
        },
        "coverage_inside": coverage(~outside),
        "coverage_outside": coverage(outside),
    }
