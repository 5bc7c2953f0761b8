"""Exact estimation of effects that enter the residual nonlinearly (lags, delay).

A first-order lag ``T`` or a pure delay ``tau_d`` is not linear in its
parameter: linearised (``-T d/dt``) a 35 ms lag comes out near 30 ms and real
delays are biased. Each such effect (``Effect.search`` set) is estimated by a
1-D search over its exact form (:meth:`omavctl.physics.effects.Effect.exact`):
for a trial value the exact residual is subtracted and the *linear* effects
fitted with it are profiled out by ordinary least squares; the value with the
smallest remaining sum of squares wins (a grid of :data:`GRID` values over the
effect's search interval, then a bounded scalar refinement). Several searched
effects are found by coordinate descent. The standard error is the
Newey-West sandwich of the search linearised at its optimum (the exact form's
derivative, the linear effects profiled out of it and of the residual;
:func:`omavctl.learn.intervals.hac_covariance`): the samples are
autocorrelated, and a form that does not fit (a lag searched as a delay)
leaves correlated structure that widens it, where a curvature-based error
would be optimistic. A searched timing form is also checked against the other
timing forms (:data:`TIMING_FORMS`): when another fits the samples better, the
parameter's standard error grows by the shift that would cost as much as the
better form saves (a lag searched as a delay says so in its interval).

With an unknown torque gain (:data:`GAIN`, the ``scale`` of ``inertia_error``)
the linear regressor of the gain is the *commanded* torque, so the searched
form reads ``lag(tau, T) + theta tau``; physically the gain multiplies the
*timed* torque (``g lag(tau, T)``). Where the gain is near 1 the two agree;
where it is not (a hover flight, roll and pitch barely excited: gain ~0.2) the
first fits a short lag plus a high-pass of the command (plausibly the rate loop
answering gyro noise) and the two optima lie tens of ms apart: the lag and the gain trade
(measured on the Crazyflie hover logs, ``benchmarks/lag_profile.py``). The
search is therefore repeated with the gain's regressor on the timed torque
(:func:`_coupled_search`); the two forms are taken as equally plausible and
the spread of their optima is added to the standard error (``gain_allowance``,
:func:`_gain_share`), so that the interval holds both.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from omavctl.learn.intervals import Z95, hac_covariance, segment_ids
from omavctl.learn.signal import ResidualSamples
from omavctl.learn.validation import cholesky_of_k
from omavctl.physics.effects import EFFECTS, get_effect

__all__ = ["GRID", "SearchResult", "search_effects"]

#: Trial values on the search interval before refinement.
GRID = 31
#: The effects whose form is a timing of the wrench (a delay or a lag): each
#: searched one is checked against the others (:func:`_form_allowance`).
TIMING_FORMS = tuple(name for name, e in EFFECTS.items() if e.search is not None)
#: Values of a profile interval's grid (:func:`_profile_se`; half the search's: each
#: value searches the partner again, and the diagnosis runs it for every candidate).
PROFILE_GRID = 16
#: Coordinate-descent sweeps over several searched effects.
SWEEPS = 2
#: The linear effect whose regressor is the commanded torque times the unknown gain
#: (:func:`_coupled_search`).
GAIN = "inertia_error"


@dataclass(frozen=True)
class SearchResult:
    """Estimate of one searched effect: value and standard error in its unit;
    ``inflation`` the variance factor of autocorrelated residuals (HAC over white);
    ``better_form`` another timing form that fits the samples better (the form may be
    wrong), ``form_allowance`` the standard-error share it added and
    ``form_significant`` whether it fits significantly better (see
    :func:`_form_allowance`); ``coupled`` the value found with the torque gain on
    the timed torque (None without a gain) and ``gain_allowance`` the share its
    distance added (:func:`_coupled_search`); ``traded`` the other searched effects
    whose re-search at each grid value widened the standard error to its profile
    interval's (:func:`_profile_se`: the two trade on these samples), None when the
    profile did not widen it by half."""

    name: str
    value: float
    stderr: float
    at_bound: bool
    inflation: float = 1.0
    better_form: str | None = None
    form_allowance: float = 0.0
    coupled: float | None = None
    gain_allowance: float = 0.0
    traded: str | None = None
    #: whether ``better_form`` fits significantly better: its saving in the sum of
    #: squares beyond ``Z95^2`` times the residual variance (times ``inflation``), as
    #: the profile interval counts (:func:`_form_allowance`)
    form_significant: bool = False


class _Problem:
    """Residual, linear regressors and exact forms of the samples, stacked."""

    def __init__(self, samples: Sequence[ResidualSamples], linear: Sequence[str]) -> None:
        self.samples = list(samples)
        self.residual = np.concatenate([s.residual for s in samples])  # (n, 3)
        self.x = (
            np.concatenate(
                [np.concatenate([s.regressors[nm] for s in samples]) for nm in linear], axis=-1
            )
            if linear
            else np.zeros((self.residual.shape[0], 3, 0))
        )
        self.segment = segment_ids(samples)
        self.gain_cols: slice | None = None
        self.normalised = False
        self.inertia: np.ndarray | None = None
        if GAIN in linear:
            start = sum(get_effect(nm).n_theta for nm in linear[: list(linear).index(GAIN)])
            self.gain_cols = slice(start, start + 3)
            ctx = next((c for s in samples for c, _ in s.contexts), None)
            self.normalised = bool(ctx is not None and ctx.torque_normalised)
            self.inertia = None if ctx is None else np.asarray(ctx.inertia, float)

    def gain_shift(self, e: np.ndarray) -> np.ndarray:
        """The change (n, 3, 3) of the gain's regressor when the torque is timed so that
        the angular acceleration changes by e (n, 3): ``I^-1 e_k (I e)_k`` for a
        normalised command, ``e_k`` on axis k for the inertia scale."""
        if self.normalised and self.inertia is not None:
            inv = np.linalg.inv(self.inertia)
            return np.asarray(inv[None, :, :] * (e @ self.inertia.T)[:, None, :])
        return np.asarray(np.eye(3)[None, :, :] * e[:, None, :])

    def rss_coupled(self, y: np.ndarray, e: np.ndarray) -> float:
        """:meth:`rss` of y (n, 3) with the gain's regressor on the torque timed by e."""
        assert self.gain_cols is not None
        x = self.x.copy()
        x[:, :, self.gain_cols] += self.gain_shift(e)
        a, b = x.reshape(-1, x.shape[2]), y.reshape(-1)
        theta, *_ = np.linalg.lstsq(a, b, rcond=None)
        r = b - a @ theta
        return float(r @ r)

    def exact(self, name: str, value: float) -> np.ndarray:
        return np.concatenate([s.exact(name, value) for s in self.samples])

    def rss(self, y: np.ndarray, rows: np.ndarray | None = None) -> float:
        """Sum of squares of y (n, 3) after the linear effects, least squares on ``rows``."""
        if rows is not None:
            y, x = y[rows], self.x[rows]
        else:
            x = self.x
        b = y.reshape(-1)
        if x.shape[2]:
            a = x.reshape(-1, x.shape[2])
            theta, *_ = np.linalg.lstsq(a, b, rcond=None)
            b = b - a @ theta
        return float(b @ b)


def _refine(
    f: object, lo: float, hi: float, start: float, width: float, tol: float = 2e-5
) -> float:
    """Bounded scalar minimum of f near ``start`` (within ``width`` on each side)."""
    a, b = max(lo, start - width), min(hi, start + width)
    if b - a <= 0:
        return start
    res = minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": tol})
    return float(res.x)


def _search_one(
    prob: _Problem,
    name: str,
    base: np.ndarray,
    rows: np.ndarray | None = None,
    start: float | None = None,
) -> float:
    """Best value of ``name`` for the residual ``base`` (n, 3) minus its exact form."""
    lo, hi = get_effect(name).search  # type: ignore[misc]
    step = (hi - lo) / (GRID - 1)

    def cost(v: float) -> float:
        return prob.rss(base - prob.exact(name, v), rows)

    if start is None:
        grid = np.linspace(lo, hi, GRID)
        start = float(grid[int(np.argmin([cost(float(v)) for v in grid]))])
    return _refine(cost, lo, hi, start, 2 * step)


def _sandwich(prob: _Problem, name: str, base: np.ndarray, value: float) -> tuple[float, float]:
    """HAC standard error of ``value`` and its variance inflation over white residuals:
    the exact form linearised at ``value``, the linear effects profiled out of it and
    of the residual (the Gauss-Newton step of the search, a sandwich around it)."""
    lo, hi = get_effect(name).search  # type: ignore[misc]
    h = 1e-3 * (hi - lo)
    jac = (prob.exact(name, value + h) - prob.exact(name, value - h)) / (2 * h)  # (n, 3)
    rest = base - prob.exact(name, value)
    if prob.x.shape[2]:  # profile the linear effects out of both
        a = prob.x.reshape(-1, prob.x.shape[2])
        q, _ = np.linalg.qr(a)
        jac = (jac.reshape(-1) - q @ (q.T @ jac.reshape(-1))).reshape(jac.shape)
        rest = (rest.reshape(-1) - q @ (q.T @ rest.reshape(-1))).reshape(rest.shape)
    if not float(np.sum(jac**2)) > 0:
        return float("inf"), 1.0
    cov, white = hac_covariance(jac[:, :, None], rest, prob.segment)
    var, var_white = float(cov[0, 0]), float(white[0, 0])
    inflation = max(var / var_white, 1.0) if var_white > 0 else 1.0
    return math.sqrt(max(var, var_white)), inflation


def _form_allowance(
    prob: _Problem,
    name: str,
    base: np.ndarray,
    value: float,
    searched: Sequence[str],
    inflation: float = 1.0,
) -> tuple[str | None, float, bool]:
    """The timing form (another searched effect not estimated here) that fits ``base``
    better than ``name`` at ``value``, and the allowance for the wrong form: the shift
    ``delta = sqrt(dRSS / |J|^2)`` of ``name``'s parameter that would cost as much as
    the better form saves (J the exact form's derivative, linear effects profiled).
    A first-order lag searched as a delay fits worse than the lag itself: its
    parameter is then not determined better than that shift. (None, 0, False) when no
    other form fits better. The third value: whether the better form's saving is
    significant, beyond ``Z95^2`` times the residual variance times ``inflation`` (the
    profile interval's rule, :func:`_profile_se`); below it ``fit`` says the two forms
    fit about as well instead of suggesting the other (any smaller sum of squares was
    called "fits these samples better" before)."""
    rss = prob.rss(base - prob.exact(name, value))
    best, best_rss = None, rss
    for other in TIMING_FORMS:
        if other == name or other in searched:
            continue
        v = _search_one(prob, other, base)
        r = prob.rss(base - prob.exact(other, v))
        if r < best_rss:
            best, best_rss = other, r
    if best is None:
        return None, 0.0, False
    lo, hi = get_effect(name).search  # type: ignore[misc]
    h = 1e-3 * (hi - lo)
    jac = (prob.exact(name, value + h) - prob.exact(name, value - h)) / (2 * h)
    jj = prob.rss(jac)  # |J|^2 with the linear effects profiled out
    dof = max(prob.residual.size - prob.x.shape[2] - len(searched), 1)
    significant = rss - best_rss > Z95**2 * rss / dof * max(inflation, 1.0)
    return best, math.sqrt((rss - best_rss) / jj) if jj > 0 else float("inf"), significant


def _coupled_search(prob: _Problem, name: str, base: np.ndarray) -> float | None:
    """Best value of ``name`` with the torque gain (:data:`GAIN`) multiplying the timed
    torque (``g lag(tau, T)``, not ``lag(tau, T) + (g - 1) tau``): None without a gain
    among the linear effects."""
    if prob.gain_cols is None:
        return None
    lo, hi = get_effect(name).search  # type: ignore[misc]
    step = (hi - lo) / (GRID - 1)

    def cost(v: float) -> float:
        e = prob.exact(name, v)
        return prob.rss_coupled(base - e, e)

    grid = np.linspace(lo, hi, GRID)
    start = float(grid[int(np.argmin([cost(float(v)) for v in grid]))])
    return _refine(cost, lo, hi, start, 2 * step)


def _gain_share(coupled: float, value: float) -> float:
    """The standard-error share of the gain's form: the two forms taken as equally
    plausible, the second moment of their optima about the reported ``value`` is
    ``(0 + d^2) / 2`` (d = coupled - value), so ``|d| / sqrt(2)``."""
    return abs(coupled - value) / math.sqrt(2.0)


def _profile_se(prob: _Problem, name: str, values: dict[str, float], inflation: float) -> float:
    """The standard error of ``name``'s profile interval beside other searched effects:
    at each grid value the others searched again (and the linear effects refitted),
    the interval every value whose extra sum of squares is below ``Z95^2`` times the
    residual variance (times ``inflation``, the autocorrelation's); the larger distance
    from ``values[name]`` to its ends, over 1.96. A delay beside a servo lag trades
    along a curved valley that the linearised sandwich does not see."""
    others = [o for o in values if o != name]
    lo, hi = get_effect(name).search  # type: ignore[misc]

    found = {o: values[o] for o in others}

    def profile(v: float) -> float:
        # the others from where the last grid value left them (the grid is walked
        # outwards from the optimum), refined within a fifth of their range
        y = prob.residual - prob.exact(name, v)
        for o in others:
            rest = y - sum((prob.exact(q, w) for q, w in found.items() if q != o), np.zeros_like(y))
            a, b = get_effect(o).search  # type: ignore[misc]
            found[o] = _refine(
                lambda w, r=rest, o=o: prob.rss(r - prob.exact(o, w)),
                a,
                b,
                found[o],
                (b - a) / 5,
                1e-3 * (b - a),
            )
        return prob.rss(y - sum((prob.exact(q, w) for q, w in found.items()), np.zeros_like(y)))

    grid = np.linspace(lo, hi, PROFILE_GRID)
    rss = np.empty(PROFILE_GRID)
    start = int(np.argmin(np.abs(grid - values[name])))
    for side in (range(start, PROFILE_GRID), range(start - 1, -1, -1)):
        found = {o: values[o] for o in others}
        for i in side:
            rss[i] = profile(float(grid[i]))
    found = {o: values[o] for o in others}
    best = min(float(rss.min()), profile(values[name]))
    dof = max(prob.residual.size - prob.x.shape[2] - len(values), 1)
    inside = grid[rss - best <= Z95**2 * best / dof * max(inflation, 1.0)]
    if inside.size == 0:
        return 0.0
    return max(values[name] - float(inside.min()), float(inside.max()) - values[name]) / Z95


def search_effects(
    samples: Sequence[ResidualSamples], searched: Sequence[str], linear: Sequence[str] = ()
) -> dict[str, SearchResult]:
    """Estimate every effect of ``searched`` exactly (see module docstring).

    ``samples`` must carry every named effect's context and the regressors of
    ``linear`` (:func:`omavctl.learn.signal.residual_samples` with those effects).
    """
    prob = _Problem(samples, linear)
    values = {name: 0.0 for name in searched}

    def base_without(name: str) -> np.ndarray:
        y = prob.residual.copy()
        for other, v in values.items():
            if other != name and v != 0.0:
                y -= prob.exact(other, v)
        return y

    for _ in range(SWEEPS if len(searched) > 1 else 1):
        for name in searched:
            values[name] = _search_one(prob, name, base_without(name))
    out = {}
    for name in searched:
        base = base_without(name)
        se, inflation = _sandwich(prob, name, base, values[name])
        traded = None
        if len(searched) > 1:
            profile = _profile_se(prob, name, values, inflation)
            if profile > 1.5 * se:
                traded = ", ".join(o for o in searched if o != name)
            se = max(se, profile)
        better, delta, significant = _form_allowance(
            prob, name, base, values[name], searched, inflation
        )
        coupled = _coupled_search(prob, name, base)
        shift = 0.0 if coupled is None else _gain_share(coupled, values[name])
        lo, hi = get_effect(name).search  # type: ignore[misc]
        step = (hi - lo) / (GRID - 1)
        at_bound = min(values[name] - lo, hi - values[name]) < 0.05 * step
        out[name] = SearchResult(
            name,
            values[name],
            math.hypot(se, delta, shift),
            bool(at_bound),
            inflation,
            better,
            delta,
            coupled,
            shift,
            traded,
            significant,
        )
    return out


def gls_search(
    samples: Sequence[ResidualSamples],
    train_index: np.ndarray,
    start: dict[str, SearchResult],
    x_linear: np.ndarray,
    prior: tuple[np.ndarray, np.ndarray],
    z_train: np.ndarray,
    hyper: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> dict[str, SearchResult]:
    """The searched effects again, jointly with the GP: at the training points.

    The first search profiles only the linear effects out, so whatever the GP will
    explain (a smooth function of its inputs: rotor interference, say) biases it.
    Here, for a trial value, the residual at the training points (indices
    ``train_index`` into the stacked samples) minus the exact form is scored by
    the generalised least squares of the joint step
    (:func:`omavctl.learn.effect_fit.joint_effects`):
    ``J = sum_a r_a^T K_a^-1 r_a + |(theta - m) / s|^2`` with the linear effects'
    theta profiled (x_linear (m, 3, p) their regressors there, prior (m, s)),
    ``K_a`` the GP covariance with hyperparameters ``hyper`` = (target means,
    signal variances, length scales, noise variances) at the normalised inputs
    z_train (m, d). Standard error from the curvature: ``2 / J''`` (J is minus
    twice a log-likelihood), inflated by the first search's variance factor and
    at least its sandwich error. Coordinate descent over several effects.
    """
    from scipy.linalg import cho_solve

    mean, sv, ls, nv = hyper
    chol = [cholesky_of_k(z_train, sv[a], ls[a], nv[a]) for a in range(3)]
    residual = np.concatenate([s.residual for s in samples])[train_index]
    p = x_linear.shape[2]
    p_mean, p_std = prior
    kx = [cho_solve(chol[a], x_linear[:, a, :]) for a in range(3)]
    a_mat = np.diag(1.0 / p_std**2) + sum(x_linear[:, a, :].T @ kx[a] for a in range(3))
    values = {n: r.value for n, r in start.items()}
    exact_cache: dict[tuple[str, float], np.ndarray] = {}

    def exact(name: str, v: float) -> np.ndarray:
        key = (name, v)
        if key not in exact_cache:
            exact_cache[key] = np.concatenate([s.exact(name, v) for s in samples])[train_index]
        return exact_cache[key]

    def objective(name: str, v: float) -> float:
        y = residual - exact(name, v) - mean
        for other, w in values.items():
            if other != name:
                y = y - exact(other, w)
        ky = [cho_solve(chol[a], y[:, a]) for a in range(3)]
        j = sum(float(y[:, a] @ ky[a]) for a in range(3))
        if p:
            b = p_mean / p_std**2 + sum(x_linear[:, a, :].T @ ky[a] for a in range(3))
            theta = np.linalg.solve(a_mat, b)
            # min over theta of the quadratic form: J - b^T A^-1 b + m^T B^-1 m
            j += float(p_mean @ (p_mean / p_std**2)) - float(b @ theta)
        return j

    for _ in range(SWEEPS if len(values) > 1 else 1):
        for name in values:
            lo, hi = get_effect(name).search  # type: ignore[misc]
            grid = np.linspace(lo, hi, GRID)
            costs = [objective(name, float(v)) for v in grid]
            best = float(grid[int(np.argmin(costs))])
            values[name] = _refine(
                lambda v, n=name: objective(n, v), lo, hi, best, 2 * (hi - lo) / (GRID - 1)
            )
    return _curvature_results(objective, values, start)


def _curvature_results(
    objective: Callable[[str, float], float],
    values: dict[str, float],
    start: dict[str, SearchResult],
) -> dict[str, SearchResult]:
    """Each searched value with its standard error from the curvature of
    ``objective`` (minus twice a log-likelihood: ``se = sqrt(2 / J'')``)."""
    out = {}
    for name, v in values.items():
        lo, hi = get_effect(name).search  # type: ignore[misc]
        h = 2e-3 * (hi - lo)
        a, b = max(lo, v - h), min(hi, v + h)
        mid = 0.5 * (a + b)
        curv = (objective(name, b) - 2 * objective(name, mid) + objective(name, a)) / (
            (0.5 * (b - a)) ** 2
        )
        se = math.sqrt(2.0 / curv) if curv > 0 else float("inf")
        # the curvature treats the training points' misfit as white: inflate it as
        # the autocorrelated residuals inflate the first search's, and never report
        # less than that search's sandwich error
        first = start[name]
        # the gain's form: the spread from this value to the value found with the gain
        # on the timed torque (the first search's), as the first search allows it
        shift = 0.0 if first.coupled is None else _gain_share(first.coupled, v)
        se = max(math.hypot(se * math.sqrt(first.inflation), shift), first.stderr)
        step = (hi - lo) / (GRID - 1)
        at_bound = min(v - lo, hi - v) < 0.05 * step
        out[name] = SearchResult(
            name,
            v,
            se,
            bool(at_bound),
            first.inflation,
            first.better_form,
            first.form_allowance,
            first.coupled,
            max(shift, first.gain_allowance),
            first.traded,
            first.form_significant,
        )
    return out
