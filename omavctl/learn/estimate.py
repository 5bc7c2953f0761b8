"""The estimate of one physical effect's parameters: values, standard errors, 95 % intervals.

:class:`EffectEstimate` is what ``fit`` reports per effect and the model file
holds (:mod:`omavctl.learn.model_file`); :mod:`omavctl.learn.intervals` says how
its standard errors are made and when an interval pins a parameter down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from omavctl.learn.intervals import parameter_interval95, pinned_down
from omavctl.physics.effects import Effect, get_effect

__all__ = ["GAIN_EFFECT", "GAIN_PRIOR_FACTOR", "EffectEstimate", "systematic_from_json"]

#: The effect whose ``scale`` is the inverse command gain of a normalised torque command.
GAIN_EFFECT = "inertia_error"
#: Prior std of that gain's theta (= gain - 1) in the joint fit, as a multiple of the
#: gain (:func:`omavctl.learn.effect_fit.effect_prior` says why).
GAIN_PRIOR_FACTOR = 3.0


@dataclass(frozen=True)
class EffectEstimate:
    """Fitted parameters of one registry effect.

    ``values[p]`` and ``stderr[p]`` have shape (size,) per parameter name ``p``
    of the effect, in the registry's units. ``stderr_method``: how the standard
    errors were obtained: ``"hac"`` (autocorrelation-robust, model schema 2 on)
    or ``"white"`` (white residuals, optimistic: files of schema 1). ``fitted``:
    the regression coefficients (p,) the model predicts with, where they differ
    from the parameters' (a torque effect fitted beside ``inertia_error``: the
    parameters are physical, the coefficients see the nominal inertia,
    :mod:`omavctl.learn.physical`); None: ``to_theta(values)``. ``systematic[p]``
    (size,): the part of the parameter's uncertainty that no flight of this vehicle
    averages away, the rotors' thrust spread within the vehicle's tolerance
    (:mod:`omavctl.learn.spread`); None: none computed. The standard error is the
    flight's alone; the 95 % interval holds both.
    """

    name: str
    values: dict[str, np.ndarray]
    stderr: dict[str, np.ndarray]
    stderr_method: str = "hac"
    fitted: np.ndarray | None = None
    systematic: dict[str, np.ndarray] | None = None

    def total_stderr(self) -> dict[str, np.ndarray]:
        """Per parameter (size,): the standard error and the systematic part in
        quadrature (the standard error without a systematic part)."""
        if self.systematic is None:
            return self.stderr
        return {
            k: np.hypot(se, self.systematic.get(k, np.zeros_like(se)))
            for k, se in self.stderr.items()
        }

    def interval95(self, systematic: bool = True) -> dict[str, np.ndarray]:
        """95 % interval (size, 2) per parameter: value -/+ 1.96 standard errors, the
        systematic part added in quadrature unless ``systematic`` is False (the flight's
        statistics alone: is there a torque of this shape?); NaN where not finite, cut at
        the parameter's physical bound (:func:`omavctl.learn.intervals.interval95`: a
        lag's is not negative); an inertia scale's made on its gain and mapped back,
        unbounded above (inf) when the gain cannot be told from 0
        (:func:`omavctl.learn.intervals.parameter_interval95`)."""
        se = self.total_stderr() if systematic else self.stderr
        return {k: parameter_interval95(self.name, k, v, se[k]) for k, v in self.values.items()}

    def pinned(self, systematic: bool = True) -> dict[str, np.ndarray]:
        """bool (size,) per parameter: its 95 % interval determines it (narrower than
        the plausible range, excluding the value of no effect;
        :func:`omavctl.learn.intervals.pinned_down`); the flight's statistics alone
        when ``systematic`` is False."""
        return {k: pinned_down(self.name, k, iv) for k, iv in self.interval95(systematic).items()}

    @property
    def effect(self) -> Effect:
        return get_effect(self.name)

    @property
    def theta(self) -> np.ndarray:
        """Regression coefficients (p,) of the effect's regressor: ``fitted`` when set."""
        if self.fitted is not None:
            return np.asarray(self.fitted, float)
        return self.effect.to_theta(self.values)

    @property
    def theta_stderr(self) -> np.ndarray:
        """Standard errors (p,) of :attr:`theta`: each parameter moved by its standard
        error through ``to_theta`` (exact where theta is the parameter); NaN when a
        parameter's is not finite."""
        return self._through_theta(self.stderr)

    @property
    def theta_systematic(self) -> np.ndarray:
        """The systematic part (p,) of :attr:`theta`'s uncertainty (the rotors' thrust
        spread), as :attr:`theta_stderr` carries the standard errors; 0 without one."""
        if self.systematic is None:
            return np.zeros_like(self.effect.to_theta(self.values))
        return self._through_theta(self.systematic)

    def _through_theta(self, sds: dict[str, np.ndarray]) -> np.ndarray:
        """Standard deviations ``sds`` per parameter carried to theta (p,) through
        ``to_theta``, one parameter component at a time."""
        base = self.effect.to_theta(self.values)
        var = np.zeros_like(base)
        for name, se in sds.items():
            for j in range(np.size(se)):
                if not np.isfinite(se[j]):
                    var[:] = np.nan
                    continue
                moved = {k: np.array(v, dtype=float, copy=True) for k, v in self.values.items()}
                moved[name][j] += se[j]
                var += (self.effect.to_theta(moved) - base) ** 2
        return np.sqrt(var)

    def to_json(self) -> dict[str, Any]:
        """Values, standard errors (``P_stderr``), 95 % intervals (``P_ci95``, [low,
        high] each) and whether each is pinned down (``P_pinned``); what is not finite
        (a parameter the data cannot determine) is null: JSON never holds NaN or
        Infinity. With a systematic part: ``P_systematic`` and ``P_ci95_statistical``,
        the interval of the flight's statistics alone (``P_ci95`` holds both).
        ``stderr_method`` says how the errors were obtained; ``theta_fitted`` the
        coefficients the model predicts with, when set."""
        out: dict[str, Any] = {"stderr_method": self.stderr_method}
        intervals, pinned = self.interval95(), self.pinned()
        flight = self.interval95(systematic=False) if self.systematic is not None else None
        for p in self.effect.parameters:
            out[p.name] = [float(x) for x in self.values[p.name]]
            out[f"{p.name}_stderr"] = _finite(self.stderr[p.name])
            out[f"{p.name}_ci95"] = [_finite(row) for row in intervals[p.name]]
            out[f"{p.name}_pinned"] = [bool(x) for x in pinned[p.name]]
            if self.systematic is not None and flight is not None:
                out[f"{p.name}_systematic"] = _finite(self.systematic[p.name])
                out[f"{p.name}_ci95_statistical"] = [_finite(row) for row in flight[p.name]]
        if self.fitted is not None:
            out["theta_fitted"] = [float(x) for x in self.fitted]
        return out


def _finite(values: Any) -> list[float | None]:
    """Floats, None where not finite (JSON holds no NaN)."""
    return [float(x) if math.isfinite(x) else None for x in values]


def systematic_from_json(params: Any, effect: Effect) -> dict[str, np.ndarray] | None:
    """An effect's optional ``P_systematic`` per parameter (files before it: None); a
    value that is not a finite, non-negative number of the parameter's size is read
    as 0 (the interval is then the statistical one, as such files had)."""
    if not any(f"{p.name}_systematic" in params for p in effect.parameters):
        return None
    out = {}
    for p in effect.parameters:
        try:
            v = np.asarray(params.get(f"{p.name}_systematic"), dtype=float).reshape(p.size)
        except (TypeError, ValueError):
            v = np.zeros(p.size)
        out[p.name] = np.where(np.isfinite(v) & (v >= 0) & (v < 1e12), v, 0.0)
    return out
