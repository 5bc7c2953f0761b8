"""The held-out physics-only error profiled over the time constants of lags and delays
(:mod:`omavctl.diagnose.timing_pair`, :mod:`omavctl.diagnose.timing_mixed`).

At each time constant the exact forms are subtracted and the nuisance effects' (the
defaults' look-alikes, and a linear partner) regressor columns are fitted by least
squares. Their design is factored once (an SVD with ``numpy.linalg.lstsq``'s cutoff),
so each of a profile's hundreds of evaluations is two products, not a new solve; a
partner's parameters are held to their null bounds (:func:`~omavctl.diagnose.joint.null_bounds`:
a drag is not negative) by bounded least squares (``scipy.optimize.lsq_linear``) where
the free fit leaves them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from omavctl.diagnose.joint import (
    DEFAULT_LOOK_ALIKES,
    MIN_HAC_T,
    MIN_SHARE,
    null_bounds,
    plausible_theta,
)
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples
from omavctl.physics.effects import get_effect

__all__ = ["GRID", "PAIR_GRID", "TIMING", "Profile", "TimingFit", "profile_for", "search_end"]

#: The lags and delays: their exact forms are searched over their time constants.
TIMING = ("command_delay", "motor_lag", "servo_lag")
#: Values on each time constant's grid (from 0 to the end of its search interval), then
#: refined by bounded searches.
GRID = 31
#: The same for each time constant of a pair (its grid has PAIR_GRID² points).
PAIR_GRID = 16


@dataclass
class TimingFit:
    """One lag or delay, or a pair, profiled on the held-out flight."""

    names: tuple[str, ...]
    #: best time constants (s), one per name
    values: tuple[float, ...]
    #: fraction of the error the look-alikes leave that the fit removes
    share: float
    #: per member: share of what the other member alone leaves that it removes, the
    #: RMS of its exact form (rad/s²) and the Newey-West t of its per-sample gain
    member_share: tuple[float, ...] = ()
    part: tuple[float, ...] = ()
    hac: tuple[float, ...] = ()
    #: the lags or delays of the other passing fits this flight cannot tell from it
    ambiguous_with: list[str] = field(default_factory=list)
    #: per member, the lags, delays or partners of ``ambiguous_with`` that replace it
    alike_of: dict[str, list[str]] = field(default_factory=dict)
    #: per-sample squared error (n,) the fit leaves
    after: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def passes(self, floor: float, dt: float) -> bool:
        """Each member's bars (:mod:`omavctl.diagnose.timing_pair`)."""
        return all(
            s >= MIN_SHARE and p >= floor and t >= MIN_HAC_T and v >= dt
            for s, p, t, v in zip(self.member_share, self.part, self.hac, self.values, strict=True)
        )

    def plausible(self) -> bool:
        """Every time constant within its effect's plausible range."""
        pairs = zip(self.names, self.values, strict=True)
        return all(plausible_theta(n, np.array([v])) for n, v in pairs)

    def to_json(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "values_s": [float(v) for v in self.values],
            "share": float(self.share),
            "member_share": list(self.member_share),
            "part": list(self.part),
            "hac_t": [min(t, 1e6) for t in self.hac],
            "ambiguous_with": self.ambiguous_with,
            "alike_of": self.alike_of,
            "bars": {"min_share": MIN_SHARE, "min_hac_t": MIN_HAC_T},
        }


class Profile:
    """The held-out physics-only error (n, 3) less the nuisance effects' least-squares
    fit, after the exact forms of some lags or delays at given time constants."""

    def __init__(
        self,
        samples: Sequence[ResidualSamples],
        physics: np.ndarray,
        nuisance: Sequence[str],
        bounded: Sequence[str] = (),
    ) -> None:
        self.samples, self.physics = samples, physics
        n = physics.shape[0]
        cols = [np.concatenate([s.regressors[a] for s in samples]) for a in nuisance]
        self.a = np.concatenate(cols, axis=2).reshape(3 * n, -1) if cols else None
        # the columns of ``bounded`` effects are held to their null bounds (a drag is not
        # negative); a far end of their plausible range is left to ``plausible``
        widths = [c.shape[2] for c in cols]
        self.lo, self.hi = null_bounds(nuisance, widths)
        free = np.repeat(np.array([a not in bounded for a in nuisance], bool), widths)
        self.lo[free], self.hi[free] = -np.inf, np.inf
        self.u = self.pinv = None
        if self.a is not None:
            u, sv, vt = np.linalg.svd(self.a, full_matrices=False)
            keep = sv > np.finfo(float).eps * max(self.a.shape) * (sv[0] if sv.size else 0.0)
            self.u = u[:, keep]
            self.pinv = vt[keep].T / sv[keep]  # coef = pinv @ (u.T @ r)
        self.cache: dict[tuple[str, float], np.ndarray] = {}

    def exact(self, name: str, t: float) -> np.ndarray:
        key = (name, round(float(t), 9))
        if key not in self.cache:
            self.cache[key] = (
                np.concatenate([s.exact(name, float(t)) for s in self.samples])
                if t > 0
                else np.zeros_like(self.physics)
            )
        return self.cache[key]

    def left_coef(
        self, names: Sequence[str], values: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per-sample squared error (n,) left at these time constants, and the nuisance
        columns' least-squares coefficients (k,) (empty without nuisance)."""
        y = self.physics - sum(
            (self.exact(m, v) for m, v in zip(names, values, strict=True)),
            np.zeros_like(self.physics),
        )
        coef = np.zeros(0)
        if self.u is not None and self.pinv is not None and self.a is not None:
            r = y.reshape(-1)
            proj = self.u.T @ r
            coef = self.pinv @ proj
            if np.all((coef >= self.lo) & (coef <= self.hi)):
                y = (r - self.u @ proj).reshape(y.shape)
            else:  # a bounded column beyond its range: bounded least squares
                coef = lsq_linear(self.a, r, bounds=(self.lo, self.hi), method="bvls").x
                y = (r - self.a @ coef).reshape(y.shape)
        return np.asarray((y**2).sum(axis=1)), coef

    def left(self, names: Sequence[str], values: Sequence[float]) -> np.ndarray:
        """Per-sample squared error (n,) left at these time constants."""
        return self.left_coef(names, values)[0]

    def ss(self, names: Sequence[str], values: Sequence[float]) -> float:
        return float(self.left(names, values).sum())

    def best(self, names: Sequence[str]) -> tuple[float, ...]:
        """The time constants (one per name) of least error: grid, then each refined."""
        ends = [search_end(n) for n in names]
        size = GRID if len(names) == 1 else PAIR_GRID
        axes = [np.linspace(0.0, e, size) for e in ends]
        grids = np.meshgrid(*axes, indexing="ij")
        points = np.stack([g.ravel() for g in grids], axis=1)
        ss = [self.ss(names, p) for p in points]
        values = [float(v) for v in points[int(np.argmin(ss))]]
        for _ in range(2):
            for i in range(len(names)):

                def cost(v: float, i: int = i) -> float:
                    return self.ss(names, [*values[:i], v, *values[i + 1 :]])

                step = ends[i] / (size - 1)
                lo, hi = max(values[i] - step, 0.0), min(values[i] + step, ends[i])
                res = minimize_scalar(cost, bounds=(lo, hi), method="bounded")
                if res.fun < cost(values[i]):
                    values[i] = float(res.x)
        return tuple(values)


def profile_for(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    extra: Sequence[str] = (),
) -> Profile:
    """The profile with the defaults' look-alikes the model lacks (and the samples carry)
    as nuisance effects, then ``extra``, whose parameters are held to their null bounds
    (the look-alikes' are free: nuisance, whatever their values)."""
    alikes = [a for a in sorted(DEFAULT_LOOK_ALIKES) if a not in model.effects]
    alikes = [a for a in alikes if a in samples[0].regressors]
    return Profile(samples, physics, [*alikes, *extra], bounded=extra)


def search_end(name: str) -> float:
    """The end of a lag's or delay's search interval (s)."""
    search = get_effect(name).search
    return float(search[1]) if search is not None else 0.3
