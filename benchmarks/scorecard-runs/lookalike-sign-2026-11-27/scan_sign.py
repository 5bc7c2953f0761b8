"""Hook: for every joint-selection trial that passes all bars but the block t, print
its block sign count and whether the sign test at 0.05/8 would pass."""
import sys, os
from math import comb
import numpy as np
import omavctl.diagnose.joint as jt
INFO = {}
orig_trial = jt._trial
def _trial(model, name, accepted, regressors, physics, sq_before, blocks):
    t = orig_trial(model, name, accepted, regressors, physics, sq_before, blocks)
    sq_after = ((physics - t.pred) ** 2).sum(axis=1)
    g = jt.block_sums(sq_before, blocks) - jt.block_sums(sq_after, blocks)
    n, k = g.size, int((g > 0).sum())
    p = sum(comb(n, j) for j in range(k, n + 1)) / 2**n
    INFO[id(t)] = (k, n, p, list(accepted))
    return t
jt._trial = _trial
orig_ps = jt._passes
def _passes(t, left, total, floor, hac=None):
    ok = orig_ps(t, left, total, floor, hac)
    if id(t) in INFO and hac is None:
        k, n, p, acc = INFO[id(t)]
        rest = (t.plausible and t.part_high >= floor and t.gain >= jt.MIN_SHARE * left
                and t.gain >= jt.MIN_SHARE_OF_TOTAL * total)
        if rest:
            print(f"[sign] acc={acc} {t.name} share {t.gain/left:.3f} t {t.block_t:.2f} blocks {k}/{n} p {p:.4f} part/floor {t.contribution_rms/floor:.2f} ok={ok} signok={p <= 0.05/8}", file=sys.stderr)
    return ok
jt._passes = _passes
from omavctl.cli.app import app
os.chdir(sys.argv[1])
app(sys.argv[2:], standalone_mode=False)
