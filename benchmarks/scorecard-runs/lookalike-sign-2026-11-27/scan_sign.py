"""Hook on ``omavctl evaluate``: every joint-selection trial that passes every bar but
the blocks' t is printed with its blocks' sign count and whether a one-sided sign test
at 0.05 / 8 passes (docs/scorecard.md, session 24).

    python scan_sign.py DRAWDIR evaluate HELD --model m0.npz --out X.json --horizons none
"""

from __future__ import annotations

import os
import sys
from math import comb
from typing import Any

import omavctl.diagnose.joint as jt
from omavctl.cli.app import app

INFO: dict[int, tuple[int, int, float, list[str]]] = {}
_trial = jt._trial
_passes = jt._passes


def trial(
    model: Any, name: str, accepted: Any, regressors: Any, physics: Any, sq_before: Any, blocks: Any
) -> Any:
    t = _trial(model, name, accepted, regressors, physics, sq_before, blocks)
    sq_after = ((physics - t.pred) ** 2).sum(axis=1)
    g = jt.block_sums(sq_before, blocks) - jt.block_sums(sq_after, blocks)
    n, k = g.size, int((g > 0).sum())
    INFO[id(t)] = (k, n, sum(comb(n, j) for j in range(k, n + 1)) / 2**n, list(accepted))
    return t


def passes(t: Any, left: float, total: float, floor: float, hac: float | None = None) -> bool:
    ok = _passes(t, left, total, floor, hac)
    if id(t) in INFO and hac is None:
        k, n, p, acc = INFO[id(t)]
        rest = (
            t.plausible
            and t.part_high >= floor
            and t.gain >= jt.MIN_SHARE * left
            and t.gain >= jt.MIN_SHARE_OF_TOTAL * total
        )
        if rest:
            print(
                f"[sign] acc={acc} {t.name} share {t.gain / left:.3f} t {t.block_t:.2f} "
                f"blocks {k}/{n} p {p:.4f} part/floor {t.contribution_rms / floor:.2f} "
                f"ok={ok} signok={p <= 0.05 / 8}",
                file=sys.stderr,
            )
    return ok


if __name__ == "__main__":
    jt._trial = trial
    jt._passes = passes
    os.chdir(sys.argv[1])
    app(sys.argv[2:], standalone_mode=False)
