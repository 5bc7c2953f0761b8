"""Honest standard errors and 95 % intervals of effect parameters.

The residual samples of a flight are not independent: the Savitzky-Golay
derivative smooths over a window, the controller couples neighbouring
samples, and whatever the effects and the GP do not explain (a misspecified
form, a lag fitted as a delay) stays in the residual as slow structure. The
ordinary least-squares covariance ``s^2 (A^T A)^-1`` assumes white residuals
and is then several times too narrow.

:func:`hac_covariance` is the Newey-West sandwich of a least-squares fit:
``(A^T A)^-1 S (A^T A)^-1`` with ``S`` the Bartlett-weighted sum of the
autocovariances of the per-sample scores ``g_t = sum_a x_ta e_ta`` up to a
bandwidth chosen from the scores' own lag-1 autocorrelation (Andrews' AR(1)
plug-in rule, 1991), summed only within contiguous segments of one log. A
misspecified form leaves correlated residual structure in the scores, so its
interval widens with it.

:func:`interval95` turns a value and its standard error into a 95 % interval,
and :func:`pinned_down` says whether the interval determines the parameter:
not when it is wider than the parameter's plausible range, includes the
value at which the effect is absent, or lies wholly beyond the parameter's
physical bound (:data:`PHYSICAL_BOUNDS`: a time constant, a delay, a drag, a
thrust loss, an inertia scale are not negative). An interval that reaches past
the bound is cut there, whichever side the estimate is on (``T_m`` 9.5 ms
-/+ 36 ms is 0 to 45.5 ms, "≥ 0"); one wholly beyond it is left whole (not
physical); the standard error is not changed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = [
    "PHYSICAL_BOUNDS",
    "SPREAD_MEANING",
    "SPREAD_WORDS",
    "Z95",
    "bandwidth",
    "bound_note",
    "cut_at_bound",
    "hac_covariance",
    "hac_meat",
    "interval95",
    "interval_ends",
    "interval_span",
    "null_values",
    "parameter_interval95",
    "physical_bound",
    "physical_side",
    "pinned_down",
    "plausible_range",
    "segment_ids",
    "unpinned_words",
]

#: Why an interval that the flight alone would pin down does not: the rotors' spread.
SPREAD_WORDS = "a thrust spread within the rotors' tolerance makes this torque too"
#: What "± 0.0019 spread" beside a standard error is, wherever it is printed.
SPREAD_MEANING = (
    "± spread: one standard deviation that the rotors' thrust tolerance (vehicle "
    "rotor.thrust_tolerance) adds: the same rotors fly every flight, so more of the same "
    "flight does not average it away, though a flight that excites the effect more passes "
    "less of it on; the 95 % interval holds it and the standard error together"
)

#: Two-sided 95 % normal quantile.
Z95 = 1.959963984540054
#: The largest bandwidth, as a fraction of the samples of the longest segment.
_MAX_BANDWIDTH_FRACTION = 0.25
#: The physical lower bound of each bounded parameter, (effect, parameter) -> bound:
#: a time constant, a delay, a drag coefficient, a thrust loss in a wake cannot be
#: negative, nor can an inertia scale (true / nominal; nor the torque gain 1 / scale
#: of a normalised command). The plausible ranges (``theta_range``) are narrower and
#: say what is usual; these say what is possible. The other parameters (CoM offset,
#: gyro bias, thrust curvature, motor-loss contrasts, battery sag) take either sign.
PHYSICAL_BOUNDS: dict[tuple[str, str], float] = {
    ("rotational_drag", "D"): 0.0,
    ("inertia_error", "scale"): 0.0,
    ("servo_lag", "T_s"): 0.0,
    ("motor_lag", "T_m"): 0.0,
    ("command_delay", "tau_d"): 0.0,
    ("rotor_interference", "rotor_rotor"): 0.0,
    ("rotor_interference", "rotor_arm"): 0.0,
}


def segment_ids(samples: Sequence[ResidualSamples]) -> np.ndarray:
    """Contiguous-segment number (N,) of every stacked sample: a new segment at each
    log and wherever the time step exceeds 1.5x the log's median step."""
    out = []
    offset = 0
    for s in samples:
        if s.n == 0:
            continue
        t = np.asarray(s.t, float)
        dt = np.diff(t)
        step = float(np.median(dt)) if dt.size else 1.0
        seg = np.concatenate([[0], np.cumsum(dt > 1.5 * step)])
        out.append(seg + offset)
        offset = int(seg.max()) + offset + 1
    return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


def _lagged(g: np.ndarray, seg: np.ndarray, lag: int) -> np.ndarray:
    """sum_t g_t g_{t-lag}^T (p, p) over pairs in the same segment; g (n, p)."""
    same = seg[lag:] == seg[:-lag]
    return np.asarray(g[lag:][same].T @ g[:-lag][same])


def bandwidth(g: np.ndarray, seg: np.ndarray) -> int:
    """Bartlett bandwidth (samples) from the lag-1 autocorrelation of each score
    column of g (n, p): Andrews' AR(1) plug-in ``1.1447 (alpha n)^(1/3)``."""
    n = g.shape[0]
    if n < 4:
        return 0
    same = seg[1:] == seg[:-1]
    num = den = 0.0
    for j in range(g.shape[1]):
        x, y = g[1:, j][same], g[:-1, j][same]
        var = float(np.dot(y, y))
        if var <= 0:
            continue
        rho = min(max(float(np.dot(x, y)) / var, -0.97), 0.97)
        s4 = (var / max(y.size, 1)) ** 2
        num += 4 * rho**2 * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += s4 / (1 - rho) ** 4
    if den <= 0:
        return 0
    longest = int(np.max(np.bincount(seg - seg.min()))) if seg.size else n
    cap = max(int(_MAX_BANDWIDTH_FRACTION * longest), 1)
    return int(min(math.ceil(1.1447 * (num / den * n) ** (1 / 3)), cap))


def hac_meat(g: np.ndarray, seg: np.ndarray, lags: int | None = None) -> np.ndarray:
    """Newey-West long-run covariance (p, p) of the scores g (n, p), Bartlett weights
    up to ``lags`` (default :func:`bandwidth`), only within segments seg (n,)."""
    lags = bandwidth(g, seg) if lags is None else lags
    meat = g.T @ g
    for lag in range(1, min(lags, g.shape[0] - 1) + 1):
        gam = _lagged(g, seg, lag)
        meat += (1.0 - lag / (lags + 1.0)) * (gam + gam.T)
    return np.asarray(meat)


def hac_covariance(
    x: np.ndarray, resid: np.ndarray, seg: np.ndarray, lags: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """HAC (Newey-West) covariance (p, p) of the least-squares fit of a residual on
    x (n, 3, p) with remaining residual ``resid`` (n, 3), and the white-residual
    covariance ``s^2 (A^T A)^+`` (p, p) beside it (their diagonal ratio is the
    variance inflation the autocorrelation causes)."""
    n, _, p = x.shape
    a = x.reshape(3 * n, p)
    bread = np.linalg.pinv(a.T @ a)
    g = np.einsum("nap,na->np", x, resid)  # per-sample scores
    cov = bread @ hac_meat(g, seg, lags) @ bread
    s2 = float(np.sum(resid**2) / max(3 * n - p, 1))
    return 0.5 * (cov + cov.T), s2 * bread


def physical_bound(name: str, param: str) -> float | None:
    """The physical lower bound of effect ``name``'s parameter ``param``
    (:data:`PHYSICAL_BOUNDS`), None when it takes either sign."""
    return PHYSICAL_BOUNDS.get((name, param))


def interval95(value: np.ndarray, stderr: np.ndarray, bound: float | None = None) -> np.ndarray:
    """95 % intervals (size, 2) ``value -/+ 1.96 stderr``; NaN where the standard
    error is not finite. With a physical lower ``bound``, one rule for every
    component: an interval that reaches past the bound from the physical side is cut
    there (what lies below is impossible, not uncertain), whichever side of it the
    estimate lies on (a Betaflight fit's inertia scales, -7.9 +- 54 on x and 2.5 +- 3
    on z, were [-115, 98.8] and [0, 8.31]: now [0, 98.8] and [0, 8.31]); an interval
    wholly below the bound keeps its ends (it is not physical, and says so:
    :func:`physical_side`)."""
    v = np.asarray(value, float).reshape(-1)
    se = np.asarray(stderr, float).reshape(-1)
    half = np.where(np.isfinite(se), Z95 * se, np.nan)
    low, high = v - half, v + half
    if bound is not None:
        with np.errstate(invalid="ignore"):
            low = np.where((high >= bound) & (low < bound), bound, low)
    return np.stack([low, high], axis=-1)


#: Parameters estimated linearly in their reciprocal: ``inertia_error``'s theta is
#: ``1/scale - 1``, the gain of the torque command (its standard error is carried to
#: the scale by the delta method, ``se_scale = se_gain scale^2``). Their 95 % intervals
#: are made on the gain, where the estimate is linear, and mapped through ``1/x``: a
#: Betaflight gain of -0.126 +- 0.82 was a scale of -7.9 +- 54, [0, 98.8] once cut at 0,
#: which said the gain is above 0.0106 where the data cannot tell it from 0.
RECIPROCAL: frozenset[tuple[str, str]] = frozenset({("inertia_error", "scale")})


def parameter_interval95(name: str, param: str, value: Any, stderr: Any) -> np.ndarray:
    """95 % intervals (size, 2) of effect ``name``'s parameter ``param``: made where
    the parameter is estimated linearly (:data:`RECIPROCAL`: on its reciprocal, mapped
    back by :func:`reciprocal_interval95`), else :func:`interval95` cut at the
    parameter's physical bound."""
    if (name, param) in RECIPROCAL:
        return reciprocal_interval95(value, stderr)
    return interval95(value, stderr, physical_bound(name, param))


def reciprocal_interval95(value: Any, stderr: Any) -> np.ndarray:
    """95 % intervals (size, 2) of a positive parameter ``s`` estimated linearly in
    ``g = 1/s`` whose standard error came by the delta method (``se_g = se_s / s^2``):
    ``g -/+ 1.96 se_g`` mapped through ``1/g`` (monotone on each side of 0). An
    interval of ``g`` across 0 keeps its physical side, ``s`` from ``1/g_high`` to
    infinity (the gain cannot be told from 0, so no scale is too large); one wholly
    at ``g < 0`` maps to negative ``s`` (not physical, kept whole, as
    :func:`interval95` keeps one wholly beyond its bound). NaN where ``s`` or its
    standard error is not finite."""
    s = np.asarray(value, float).reshape(-1)
    se = np.asarray(stderr, float).reshape(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = 1.0 / s
        half = Z95 * se / s**2
        g_lo, g_hi = g - half, g + half
        low = 1.0 / g_hi
        high = np.where((g_lo > 0.0) | (g_hi < 0.0), 1.0 / g_lo, np.inf)
    bad = ~(np.isfinite(s) & np.isfinite(se) & (s != 0.0))
    out = np.stack([low, high], axis=-1)
    out[bad] = np.nan
    return out


def cut_at_bound(name: str, param: str, low: float) -> bool:
    """Whether an interval's ``low`` end is ``name``'s ``param``'s physical bound (the
    interval was cut there, :func:`interval95`: the text says "≥ 0")."""
    bound = physical_bound(name, param)
    return bound is not None and float(low) == bound


def bound_note(
    name: str, param: str, low: float, value: float | None = None, high: float | None = None
) -> str:
    """'cut at T_m ≥ 0' when an interval's ``low`` end is the parameter's physical bound
    (:func:`cut_at_bound`), else ''; '...; the estimate is below it' when the estimate
    ``value`` is (it then lies outside its interval: tau_d -0.617 ms, 95 % 0 to 0.637).
    Given the interval's ``high`` end, an estimate outside it on either side is said
    whether or not the interval was cut (Betaflight: scale_x -7.912 beside [0.663, ∞))."""
    cut = cut_at_bound(name, param, low)
    if not cut and high is None:
        return ""
    v = None if value is None else float(value)
    side = "below" if v is not None and v < low else ""
    side = "above" if v is not None and high is not None and v > high else side
    said = [f"the estimate is {side} it"] if side else []
    if not cut:
        return "; ".join(said)
    bound = physical_bound(name, param)
    # cut at the value where the effect is absent (a lag, a delay, a drag at 0): the
    # interval reaches absence, so its narrowness says nothing of a size (eyes6)
    null = np.asarray(null_values(name).get(param, np.array([np.nan])), float).reshape(-1)
    absent = bool(null.size) and bool(np.all(null == bound))
    cut_words = f"cut at {param} ≥ {bound:g}" + (", not told from absent" if absent else "")
    return "; ".join([cut_words, *said])


def physical_side(name: str, param: str, interval: np.ndarray) -> np.ndarray:
    """bool (size,): some of each 95 % interval (size, 2) lies at or above the
    parameter's physical bound (always, for a parameter without one); false for an
    interval wholly beyond it (a negative delay, tau_d -2.70 to -0.03 ms: not physical,
    whatever else it excludes)."""
    iv = np.asarray(interval, float).reshape(-1, 2)
    bound = physical_bound(name, param)
    if bound is None:
        return np.ones(iv.shape[0], dtype=bool)
    with np.errstate(invalid="ignore"):
        return np.asarray(~(iv[:, 1] < bound))


def null_values(name: str) -> dict[str, np.ndarray]:
    """Each parameter's value (size,) at which the effect ``name`` is absent
    (:meth:`Effect.null_parameters`)."""
    return get_effect(name).null_parameters()


def plausible_range(name: str) -> dict[str, tuple[float, float]]:
    """Each parameter's plausible (low, high), from the effect's ``theta_range``."""
    effect = get_effect(name)
    if effect.parameter_range is not None:
        return {p.name: effect.parameter_range for p in effect.parameters}
    lo, hi = effect.theta_range
    out = {}
    for theta in (lo, hi):
        if not math.isfinite(theta):
            return {p.name: (-math.inf, math.inf) for p in effect.parameters}
    zero = np.zeros((effect.n_theta, effect.n_theta))
    at_lo = effect.to_parameters(np.full(effect.n_theta, lo), zero)
    at_hi = effect.to_parameters(np.full(effect.n_theta, hi), zero)
    for p in effect.parameters:
        a = float(np.min(at_lo[p.name][0]))
        b = float(np.max(at_hi[p.name][0]))
        out[p.name] = (min(a, b), max(a, b))
    return out


def pinned_down(name: str, param: str, interval: np.ndarray) -> np.ndarray:
    """bool (size,): the 95 % interval (size, 2) of ``name``'s parameter ``param``
    determines it: finite, not holding the value at which the effect is absent, not
    wholly beyond the physical bound (:func:`physical_side`), and
    within and narrower than the plausible range (for ``inertia_error``'s scale
    outside it, the inverse gain of a normalised torque command: a half-width below
    the estimate's magnitude)."""
    lo, hi = plausible_range(name)[param]
    iv = np.asarray(interval, float).reshape(-1, 2)
    null = null_values(name)[param]
    null = null if null.size == iv.shape[0] else np.full(iv.shape[0], null.flat[0])
    width = iv[:, 1] - iv[:, 0]
    centre = 0.5 * (iv[:, 0] + iv[:, 1])
    finite = np.isfinite(iv).all(axis=1)
    with np.errstate(invalid="ignore"):
        inside = (centre >= lo) & (centre <= hi)
        # a normalised torque command's gain is estimated as inertia_error's scale
        # (1 / gain): any positive value is plausible, judged by its relative width
        gain = name == "inertia_error"
        outside = 0.5 * width < np.abs(centre) if gain else np.zeros_like(inside)
        narrow = np.where(inside, width < (hi - lo), outside)
        excludes_null = (iv[:, 0] > null) | (iv[:, 1] < null)
    return np.asarray(finite & narrow & excludes_null & physical_side(name, param, iv))


def unpinned_words(name: str, param: str, interval: Sequence[float], i: int = 0) -> str:
    """Why component ``i``'s 95 % interval (low, high) does not pin ``name``'s ``param``
    down (:func:`pinned_down` false), in words that follow the interval: one that
    excludes the effect's absence but lies outside its plausible range is pinned, as
    something this effect alone cannot be ("D_z = 1.08 (0.809 to 1.34)" is no drag)."""
    lo, hi = (float(v) for v in interval)
    plo, phi = plausible_range(name)[param]
    null = np.asarray(null_values(name)[param], float).reshape(-1)
    zero = float(null[i] if i < null.size else null[0])
    centre = 0.5 * (lo + hi)
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo <= zero <= hi:
        return "cannot be pinned down from this flight"
    bound = physical_bound(name, param)
    if bound is not None and hi < bound:
        return f"not physical: {param} cannot be below {bound:g}; something else on this axis"
    if name != "inertia_error" and not plo <= centre <= phi:
        return (
            f"outside the plausible {plo:.3g} to {phi:.3g}: not this effect alone, "
            "something else on this axis"
        )
    if name != "inertia_error" and hi - lo >= phi - plo:
        return f"wider than the plausible {plo:.3g} to {phi:.3g}: cannot be pinned down"
    return "cannot be pinned down from this flight"


def interval_span(
    name: str, param: str, lo: float, hi: float, null: float | None = None, joiner: str = " to "
) -> tuple[str, int]:
    """A 95 % interval as shown, 'low to high' (:func:`interval_ends`; ``joiner`` between
    the ends), or 'below high' where its low end is the physical bound it was cut at
    (:func:`cut_at_bound`): "0 to 5.99e-06" read as a value pinned near 0, when all the
    interval says is that the parameter, a delay that cannot be negative, is below its
    high end (eyes6); 'above low' where it has no high end (an inertia scale whose
    gain cannot be told from 0, :func:`reciprocal_interval95`). With the number of
    significant digits used."""
    if math.isfinite(lo) and hi == math.inf:
        return f"above {lo:.3g}", 3
    a, b, digits = interval_ends(lo, hi, null)
    if cut_at_bound(name, param, lo) and math.isfinite(hi):
        return f"below {b}", digits
    return f"{a}{joiner}{b}", digits


def interval_ends(lo: float, hi: float, null: float | None = None) -> tuple[str, str, int]:
    """Both ends of a 95 % interval with the fewest significant digits (3 to 6) that print
    them apart and print neither as the effect's ``null`` unless it is (a Crazyflie's
    inertia scale [1.00009, 1.21], pinned down, printed "[1, 1.21]"), and that number
    of digits (for the estimate beside them)."""
    for digits in range(3, 7):
        a, b = f"{lo:.{digits}g}", f"{hi:.{digits}g}"
        n = f"{null:.{digits}g}" if null is not None and math.isfinite(null) else None
        hides = n is not None and ((a == n and lo != null) or (b == n and hi != null))
        if a != b and not hides:
            return a, b, digits
    return f"{lo:.6g}", f"{hi:.6g}", 6
