"""Claims held back together are held back one at a time, the last-ranked first
(omavctl/diagnose/selection.py, ``one_at_a_time``): two look-alikes estimated together
can each have an interval that holds its null while the better one alone is pinned
down."""

from __future__ import annotations

import numpy as np

from omavctl.diagnose.claims import Guarded
from omavctl.diagnose.selection import one_at_a_time

Z95 = 1.959963984540054


def _least_squares_guard(columns: dict[str, np.ndarray], y: np.ndarray):
    """A guard on a linear fit of y (n,) on the named columns (n,) together: a claim is
    kept when its coefficient's 95 % interval (white residuals) excludes 0; ``calls``
    records every set of names it was asked about."""
    calls: list[list[str]] = []

    def guard(names: list[str]) -> Guarded:
        calls.append(list(names))
        x = np.stack([columns[n] for n in names], axis=1)
        beta, *_ = np.linalg.lstsq(x, y, rcond=None)
        e = y - x @ beta
        s2 = float(e @ e) / (len(y) - len(names))
        se = np.sqrt(s2 * np.diag(np.linalg.inv(x.T @ x)))
        away = np.abs(beta) > Z95 * se
        kept = [n for n, a in zip(names, away, strict=True) if a]
        held = [
            {"name": n, "estimate": {"b": float(b)}}
            for n, b, a in zip(names, beta, away, strict=True)
            if not a
        ]
        return Guarded(kept=kept, held_back=held)

    return guard, calls


def _case(seed: int = 0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 20, 400)
    a = np.sin(1.3 * t) + 0.5 * np.sin(0.4 * t)
    alike = a + 0.002 * rng.normal(size=t.size)  # a look-alike: nearly the same column
    other = np.cos(2.1 * t)  # an effect the vehicle lacks
    y = 0.3 * a + 0.3 * rng.normal(size=t.size)
    return {"hidden": a, "alike": alike, "absent": other}, y


def test_two_look_alikes_held_back_together_keep_the_better_one():
    columns, y = _case()
    guard, calls = _least_squares_guard(columns, y)
    together = guard(["hidden", "alike", "absent"])
    assert together.kept == []  # estimated together, every interval holds 0
    calls.clear()
    out = one_at_a_time(guard, ["hidden", "alike", "absent"])
    assert out.kept == ["hidden"]
    assert sorted(h["name"] for h in out.held_back) == ["absent", "alike"]
    # the last-ranked of those held back is held back alone, the rest guarded again
    assert calls == [["hidden", "alike", "absent"], ["hidden", "alike"], ["hidden"]]


def test_a_single_held_back_claim_is_not_retried():
    columns, y = _case(1)
    guard, calls = _least_squares_guard(columns, y)
    out = one_at_a_time(guard, ["hidden", "absent"])
    assert out.kept == ["hidden"] and [h["name"] for h in out.held_back] == ["absent"]
    assert calls == [["hidden", "absent"]]
