"""A loss at the longest horizon is named only beyond its standard error.

The horizon table keeps, per predictor and horizon, the mean error of each
chunk of window start times; the findings compare two predictors on the same
windows by the paired difference of their chunk means. A rise within two
standard errors is sampling error and is not called a loss; adding an effect
(model 1 against model 0) that wins at one step and loses at 0.5 s beyond it is
named, and the report repeats it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omavctl.diagnose.horizon_findings import findings, paired_se
from omavctl.diagnose.horizons import GridSignals, horizon_table
from omavctl.learn.signal import ResidualSamples
from omavctl.report.horizons import _side_by_side, horizons_json

KEYS = ("naive", "nominal", "effects", "model", "effects_1", "model_1")


def _tree(errors: dict[str, list[float]], spread: float, seed: int = 0) -> dict:
    """Two models' horizon tables (0.01 and 0.5 s) with the given mean errors (every
    axis) and 20 chunk means per row spread by ``spread`` around them (each chunk's
    deviation shared by every predictor but for an independent part of ``spread``)."""
    rng = np.random.default_rng(seed)
    common = rng.standard_normal((2, 20))
    preds = [
        {"key": k, "kind": k.split("_")[0], "model": None if k in KEYS[:2] else int("_" in k)}
        for k in errors
    ]

    def row(i: int, k: int, e: float) -> dict:
        own = rng.standard_normal(20)
        chunks = e + spread * (common[i] + own - (common[i] + own).mean())
        per_axis = {a: chunks.tolist() for a in ("x", "y", "z", "norm")}
        return {"seconds": k / 100, "steps": k,
                "rate_error": {"x": e, "y": e, "z": e, "norm": e},
                "rate_error_chunks": per_axis,
                "coverage": {"x": 0.95, "y": 0.95, "z": 0.95, "all": 0.95}}  # fmt: skip

    h = {
        "steps": [1, 50], "seconds": [0.01, 0.5], "band_sigma": 2.0, "predictors": preds,
        "table": {k: [row(0, 1, v[0]), row(1, 50, v[1])] for k, v in errors.items()},
    }  # fmt: skip
    h["findings"] = findings(h)
    return {"horizons": h, "logs": [{"name": "a.bag", "sha256": "a", "t0": 0.0}]}


BASE = {
    "naive": [0.02, 0.5],
    "nominal": [0.03, 0.9],
    "effects": [0.01, 0.1],
    "model": [0.005, 0.05],
}


def test_adding_an_effect_that_loses_at_half_a_second_is_named_beyond_its_error():
    # physics + effects of model 1: lower at 0.01 s, +0.01 rad/s at 0.5 s
    errors = {**BASE, "effects_1": [0.009, 0.11], "model_1": [0.004, 0.04]}
    tight = _tree(errors, spread=0.001)
    found = [f for f in tight["horizons"]["findings"] if f["code"] == "effect_added_hurts_long"]
    assert [f["axis"] for f in found] == ["x", "y", "z"] and {f["model"] for f in found} == {1}
    se = paired_se(tight["horizons"]["table"]["effects"][1],
                   tight["horizons"]["table"]["effects_1"][1], "x")  # fmt: skip
    assert se is not None and 0.0002 < se < 0.0006  # sqrt(2) 0.001 / sqrt(20)
    assert found[0]["message"] == (
        "model 1: x: nominal + effects of model 1 against model 0 lowers the 0.01 s "
        f"body-rate error (0.01 -> 0.009 rad/s) but raises it at 0.5 s (0.1 -> 0.11 rad/s, "
        f"+0.01 ± {se:.2g} rad/s)"
    )
    other = _tree(BASE, 0.001)
    blocks = _side_by_side([(tight, {}, "one.json"), (other, {}, "two.json")])
    notes = [str(item) for b in blocks if hasattr(b, "items") for item in b.items]
    assert any(n.startswith("one.json: model 1: x: nominal + effects of model 1") for n in notes)
    # the same rise among chunks spread 20x wider is within its standard error: no loss
    wide = _tree(errors, spread=0.02)
    codes = [f["code"] for f in wide["horizons"]["findings"]]
    assert "effect_added_hurts_long" not in codes
    blocks = _side_by_side([(wide, {}, "one.json"), (other, {}, "two.json")])
    notes = [str(item) for b in blocks if hasattr(b, "items") for item in b.items]
    assert not any("nominal + effects of model 1" in n for n in notes)


def test_a_gp_rise_within_its_standard_error_is_not_a_loss():
    errors = {**BASE, "model": [0.008, 0.101]}  # +1 % at 0.5 s
    assert "gp_hurts_long" not in [f["code"] for f in _tree(errors, 0.01)["horizons"]["findings"]]
    codes = [f["code"] for f in _tree(errors, 0.0001)["horizons"]["findings"]]
    assert codes.count("gp_hurts_long") == 3


def _tree_without_chunks(errors: dict[str, list[float]]) -> dict:
    tree = _tree(errors, 0.01)
    for rows in tree["horizons"]["table"].values():
        for r in rows:
            del r["rate_error_chunks"]
    tree["horizons"]["findings"] = findings(tree["horizons"])
    return tree


def test_files_without_chunk_means_keep_the_plain_comparison():
    errors = {**BASE, "model": [0.008, 0.101]}
    codes = [f["code"] for f in _tree_without_chunks(errors)["horizons"]["findings"]]
    assert codes.count("gp_hurts_long") == 3


def test_the_table_has_chunk_means_and_standard_errors(vehicle):
    """Windows of one log, grouped by start time into chunks of 1 s (two 0.5 s
    horizons): each chunk's mean is the mean of its windows' errors, the standard error
    is the chunks' spread over their number's root; --json leaves the chunks out."""
    from omavctl.learn.model import ResidualGP
    from tests.test_horizons import _model

    n, dt = 800, 0.01
    rng = np.random.default_rng(4)
    t = np.arange(n) * dt
    omega = np.stack([np.sin(t), 0.1 * rng.standard_normal(n), np.zeros(n)], 1)
    z3, z6 = np.zeros((n, 3)), np.zeros((n, 6))
    s = ResidualSamples(Path("s"), np.arange(n), t, omega, z6, z3, z3, z3, du=z6)
    s.rate_noise = np.zeros(3)
    model: ResidualGP = _model(vehicle)
    h = horizon_table([model], [s], [GridSignals(omega, z3, None)], 100.0)
    assert h["chunk_seconds"] == pytest.approx(1.0)
    row = h["table"]["naive"][-1]
    starts = np.arange(n - 50)
    err = np.abs(omega[starts + 50, 1] - omega[starts, 1])
    means = [err[starts // 100 == c].mean() for c in range(8)]
    assert row["rate_error_chunks"]["y"] == pytest.approx(means)
    assert row["rate_error_se"]["y"] == pytest.approx(np.std(means, ddof=1) / np.sqrt(8))
    assert row["rate_error"]["y"] == pytest.approx(err.mean())
    out = horizons_json({"horizons": h})
    assert out is not None and "rate_error_chunks" not in out["table"]["naive"][-1]
    assert "rate_error_se" in out["table"]["naive"][-1]
