"""What the horizon table's band says in words: too narrow, or wider than needed.

Reads the full model's rows of an evaluation's ``horizons.table``
(:mod:`omavctl.diagnose.horizons`, docs/schemas.md): per horizon ``coverage`` (``x``,
``y``, ``z``, ``all``: the share of body rates inside the band) and ``band_halfwidth``
(mean half-width per axis, rad/s) beside ``rate_error`` (mean |error| per axis). Every
coverage is compared as the table prints it, in whole percent.

- ``band_narrow``: the band holds less than :data:`MIN_COVERAGE` of the body rates,
  pooled or on an axis (a new user's Crazyflie window printed 85 % at 0.5 s with y at
  74.5 %, and nothing said it);
- ``band_wide``: on an axis the band holds at least :data:`WIDE_COVERAGE` and its std
  is at least :data:`WIDE_FACTOR` times what the errors show (Betaflight: x's 0.5 s
  band 5.7x, beside a calibrated z).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = [
    "MIN_COVERAGE",
    "WIDE_COVERAGE",
    "WIDE_FACTOR",
    "axis_factors",
    "band_findings",
    "narrow_axes",
    "open_loop_narrow",
    "wide_factor",
]

#: the least band coverage at any horizon, pooled or on an axis, before a finding says
#: the band is too narrow
MIN_COVERAGE = 0.85
#: a band whose std is at least this many times what the errors show is called wide
WIDE_FACTOR = 2.0
#: ... on an axis where it holds at least this share of the body rates
WIDE_COVERAGE = 0.99
#: A band this many times wider than its errors show is too wide to use, not only safe:
#: a new user's Crazyflie window judged on another log printed "653.6x ... safe, not
#: tight" (its flight went nine training ranges beyond the model's yaw rate).
USELESS_FACTOR = 10.0
#: mean |e| of a zero-mean normal error is sqrt(2 / pi) of its std
_MEAN_ABS = math.sqrt(2.0 / math.pi)
AXES = ("x", "y", "z")


def _shown(value: float) -> int:
    """A share as the table prints it: whole percent (84.6 % is 85 %)."""
    return round(100 * value)


def axis_factors(row: Mapping[str, Any], sigma: float = 2.0) -> dict[str, float]:
    """Per axis, the band's std over the std its errors show at one horizon row of a
    full model: ``band_halfwidth / sigma`` against the mean |error| over sqrt(2/pi) (the
    mean |e| of a normal error is sqrt(2/pi) of its std; 1: calibrated). Axes without a
    band or with a zero error are left out."""
    half, err = row.get("band_halfwidth") or {}, row.get("rate_error") or {}
    out = {}
    for a in AXES:
        e, h = err.get(a), half.get(a)
        if e is not None and h is not None and float(e) > 0:
            out[a] = float(h) / sigma / (float(e) / _MEAN_ABS)
    return out


def wide_factor(row: Mapping[str, Any]) -> float | None:
    """The smallest of :func:`axis_factors` over the axes (``row``'s ``band_sigma``,
    default 2); None unless every axis has one."""
    factors = axis_factors(row, float(row.get("band_sigma", 2.0)))
    return min(factors.values()) if len(factors) == len(AXES) else None


def narrow_axes(row: Mapping[str, Any]) -> list[str]:
    """The axes whose coverage, as the table prints it, is under :data:`MIN_COVERAGE`."""
    cov = row.get("coverage") or {}
    low = _shown(MIN_COVERAGE)
    return [a for a in AXES if cov.get(a) is not None and _shown(float(cov[a])) < low]


def _narrow_rows(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """The rows whose band holds less than :data:`MIN_COVERAGE`, pooled or on an axis."""
    low = _shown(MIN_COVERAGE)
    return [
        r
        for r in rows
        if r.get("coverage") is not None
        and (_shown(float(r["coverage"]["all"])) < low or narrow_axes(r))
    ]


def _held(row: Mapping[str, Any]) -> str:
    """'43 % of the body rates' or '85 % of the body rates but y 75 %'."""
    cov = row["coverage"]
    axes = narrow_axes(row)
    text = f"{_shown(float(cov['all']))} % of the body rates"
    return text + (
        f" but {', '.join(f'{a} {_shown(float(cov[a]))} %' for a in axes)}" if axes else ""
    )


def band_findings(rows: Sequence[Mapping[str, Any]], sigma: float) -> list[dict[str, Any]]:
    """``band_narrow`` and ``band_wide`` findings of a full model's horizon ``rows``."""
    out = []
    for row in _narrow_rows(rows):
        cov, axes = row["coverage"], narrow_axes(row)
        shares = [float(cov["all"]), *(float(cov[a]) for a in axes)]
        out.append(
            {
                "code": "band_narrow",
                "axis": axes[0] if len(axes) == 1 else None,
                "value": min(shares),
                "message": f"at {row['seconds']:g} s the full model's {sigma:g}σ band holds "
                f"{_held(row)} (below {_shown(MIN_COVERAGE)} %): it is too narrow there",
            }
        )
    for row in rows:
        cov = row.get("coverage") or {}
        wide = {
            a: f
            for a, f in axis_factors(row, sigma).items()
            if f >= WIDE_FACTOR
            and cov.get(a) is not None
            and _shown(float(cov[a])) >= _shown(WIDE_COVERAGE)
        }
        if not wide:
            continue
        on = ", ".join(f"{a} {f:.1f}x (holds {_shown(float(cov[a]))} %)" for a, f in wide.items())
        how = (
            "far too wide to use: it says little about these errors (the band's std over "
            "the std its errors imply; beyond the model's inputs it grows with how far the "
            "flight goes)"
            if max(wide.values()) >= USELESS_FACTOR
            else "safe, not tight (the band's std over the std its errors imply; a "
            "controller or planner reading it would be more cautious than this flight needs)"
        )
        out.append(
            {
                "code": "band_wide",
                "axis": next(iter(wide)) if len(wide) == 1 else None,
                "value": max(wide.values()),
                "message": f"at {row['seconds']:g} s the full model's {sigma:g}σ band is "
                f"wider than its errors show on {on}: {how}",
            }
        )
    return out


def open_loop_narrow(tree: Mapping[str, Any] | None) -> str:
    """Where the first model's open-loop band (the horizon table's full model) is too
    narrow, pooled or on an axis, in words for the verdict's uncertainty sentence; ''
    where it is not, or the evaluation has no horizon table."""
    table = (tree or {}).get("table") or {}
    rows = _narrow_rows(table.get("model") or [])
    if not rows:
        return ""
    held = [_held(r) for r in rows]
    held[1:] = [h.replace(" of the body rates", "") for h in held[1:]]
    at = ", ".join(f"{h} at {r['seconds']:g} s" for h, r in zip(held, rows, strict=True))
    sigma = (tree or {}).get("band_sigma", 2)
    return (
        f"the open-loop {sigma:g}σ band is too narrow: it holds {at} "
        f"({_shown(MIN_COVERAGE)} % needed; the horizon table)"
    )
