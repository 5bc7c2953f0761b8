"""How the report writes numbers: significant digits, percentages, per-axis values.

Every value may come from an evaluation file and so be anything: these helpers
write 'n/a' for what is not a number rather than raising.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, TypeGuard

from omavctl.diagnose.verdict import get_path as _get

__all__ = [
    "AXES",
    "as_list",
    "axes_of",
    "finite",
    "force_unit_unknown",
    "num",
    "pct",
    "percent_change",
    "relative_change",
    "torque_unit_unknown",
]

AXES = ("x", "y", "z")


def finite(v: Any) -> TypeGuard[int | float]:
    """A finite int or float (not a bool)."""
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def num(v: Any, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; 'n/a' for anything else."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return "n/a"
    if math.isnan(v):
        return "n/a"
    if math.isinf(v):
        return "∞" if v > 0 else "-∞"
    return f"{v:.{digits}g}"


def pct(v: Any) -> str:
    """A fraction in percent with one decimal; 'n/a' if not a finite number."""
    return f"{100 * v:.1f} %" if finite(v) else "n/a"


def relative_change(new: Any, old: Any) -> float | None:
    """``(new - old) / old`` as a fraction; None where undefined (not finite numbers,
    ``old`` not above 0), never NaN or infinite."""
    if not (finite(new) and finite(old)) or old <= 0:
        return None
    change = (new - old) / old
    return float(change) if math.isfinite(change) else None


def percent_change(new: Any, old: Any) -> str:
    """``(new - old) / old`` in percent, signed, one decimal ('n/a' if undefined)."""
    change = relative_change(new, old)
    return "n/a" if change is None else f"{100 * change:+.1f} %"


def axes_of(d: Any) -> list[Any]:
    """The x, y, z entries of a per-axis mapping (None where one is missing)."""
    return [_get(d, a) for a in AXES]


def torque_unit_unknown(tree: Mapping[str, Any]) -> bool:
    """Whether the evaluation says its torques are in unknown units."""
    return _get(tree, "units", "torque") == "unknown"


def force_unit_unknown(tree: Mapping[str, Any]) -> bool:
    """Whether the evaluation says its force command is in unknown units."""
    return _get(tree, "units", "force") == "unknown"


def as_list(v: Any) -> list[Any]:
    """``v`` as a list: a list or tuple's items, else ``[v]``."""
    return list(v) if isinstance(v, list | tuple) else [v]
