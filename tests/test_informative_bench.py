"""The statistics of benchmarks/informative.py on synthetic inputs (milliseconds), and
its held-out errors against evaluate's on a short flight (seconds)."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest
from scipy import stats

from benchmarks import informative_calls as calls
from benchmarks.informative_md import comparisons, correlation, oracle
from benchmarks.informative_stats import (
    gain,
    mean_interval,
    random_draws,
    seed_interval,
    spearman,
)
from omavctl.diagnose.evaluate import evaluate
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.logs import write_log
from tests.conftest import fly


def test_gain_is_the_share_of_the_baseline_error_removed() -> None:
    assert gain(2.0, 1.5) == pytest.approx(25.0)
    assert gain(2.0, 3.0) == pytest.approx(-50.0)
    with pytest.raises(ValueError, match="baseline error must be positive"):
        gain(0.0, 1.0)


def test_mean_interval_is_the_student_t_interval() -> None:
    iv = mean_interval([10.0, 12.0, 14.0, 16.0])
    # mean 13, s = sqrt(20/3), t(0.975, 3) = 3.182446
    half = 3.182446305284263 * math.sqrt(20 / 3) / 2
    assert (iv.mean, iv.n) == (13.0, 4)
    assert iv.low == pytest.approx(13 - half) and iv.high == pytest.approx(13 + half)
    assert iv.text() == f"+13.0 % [{13 - half:+.1f}, {13 + half:+.1f}]"


def test_mean_interval_covers_the_true_mean_about_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(0)
    hits = sum(
        (iv := mean_interval(rng.normal(5.0, 3.0, 6))).low < 5.0 < iv.high for _ in range(2000)
    )
    assert 0.93 < hits / 2000 < 0.97


def test_seed_interval_is_over_the_seed_means() -> None:
    """Six draws of two seeds: the interval is the t-interval of the two seed means (1
    degree of freedom), far wider than the six draws' own, which takes them as
    independent though a seed's draws share their flights and pool."""
    gains = [10.0, 12.0, 11.0, 30.0, 28.0, 29.0]
    seeds = [5, 5, 5, 6, 6, 6]
    iv = seed_interval(gains, seeds)
    half = stats.t.ppf(0.975, 1) * np.std([11.0, 29.0], ddof=1) / math.sqrt(2)
    assert iv.n == 2 and iv.mean == pytest.approx(20.0)
    assert (iv.low, iv.high) == pytest.approx((20.0 - half, 20.0 + half))
    per_draw = mean_interval(gains)
    assert per_draw.n == 6 and per_draw.high - per_draw.low < (iv.high - iv.low) / 5
    with pytest.raises(ValueError, match="lengths differ: 6 values, 5 seeds"):
        seed_interval(gains, seeds[:5])


def test_the_random_flights_differ_between_the_effect_sets_of_a_seed() -> None:
    """Seeded by the seed alone, all six effect sets of seed 5 flew pool index 14."""
    pool = list(range(30))
    sets = ["drag", "inertia", "delay", "com", "drag+delay", "inertia+com"]
    first = {name: random_draws(pool, 5, name, 4) for name in sets}
    assert len({d[0] for d in first.values()}) >= 4
    assert all(len(set(d)) == 4 and set(d) <= set(pool) for d in first.values())
    assert random_draws(pool, 5, "drag", 4) == first["drag"]  # reproducible
    assert random_draws(pool, 6, "drag", 4) != first["drag"]


def test_target_needs_the_mean_and_the_lower_end() -> None:
    assert mean_interval([11.0, 12.0, 13.0]).holds(10.0)
    assert not mean_interval([-30.0, 20.0, 50.0]).holds(10.0)  # mean 13.3, interval spans 0
    assert not mean_interval([5.0, 6.0, 7.0]).holds(10.0)  # sure, but small
    one = mean_interval([40.0])
    assert not one.holds(10.0) and one.text() == "+40.0 % (one draw, no interval)"
    with pytest.raises(ValueError, match="finite"):
        mean_interval([1.0, math.nan])


def test_spearman_on_synthetic_ranks() -> None:
    x = [1.0, 2.0, 3.0, 4.0, 5.0]
    assert spearman(x, [10.0, 20.0, 30.0, 40.0, 50.0]) == pytest.approx(1.0)
    assert spearman(x, [5.0, 4.0, 3.0, 2.0, 1.0]) == pytest.approx(-1.0)
    y = [2.0, 1.0, 4.0, 3.0, 5.0]  # 1 - 6 * 4 / (5 * 24) = 0.8
    assert spearman(x, y) == pytest.approx(0.8)
    assert spearman(x, y) == pytest.approx(stats.spearmanr(x, y).statistic)
    assert math.isnan(spearman([1.0, 2.0], [2.0, 1.0]))
    assert math.isnan(spearman(x, [1.0] * 5))
    with pytest.raises(ValueError, match="lengths differ"):
        spearman(x, x[:3])


def _draw(first: float, task: float, pool: dict[int, tuple[float, float]]) -> dict:
    """A synthetic draw: pool index -> (cost, region error); best = lowest cost, random = 0."""

    def errors(region: float) -> dict:
        return {"tracking": region, "region": region, "task": region, "gp_on": [True] * 3}

    return {
        "first": errors(first),
        "task_again": errors(task),
        "pool": {str(k): {**errors(e), "cost": c} for k, (c, e) in pool.items()},
        "best": min(pool, key=lambda k: pool[k][0]),
        "random": 0,
    }


def test_comparisons_and_correlation_of_synthetic_draws() -> None:
    # cost ranks the candidates exactly as the error they leave: Spearman of cost with
    # the removed error is -1 per draw and pooled
    draws = [
        _draw(2.0, 1.0, {0: (3.0, 0.9), 1: (1.0, 0.5), 2: (2.0, 0.7)}),
        _draw(4.0, 2.0, {0: (6.0, 1.8), 1: (2.0, 1.0), 2: (4.0, 1.4)}),
    ]
    assert oracle(draws[0])["region"] == 0.5
    rows = {(name, label): g for name, label, g in comparisons(draws)}
    assert rows[("planned vs the task flown again", "closed-loop tracking of the task")] == [
        pytest.approx(50.0),
        pytest.approx(50.0),
    ]
    room = rows[("oracle vs one random candidate (room)", "model RMSE, region's held-out flights")]
    assert room == [pytest.approx(100 * 0.4 / 0.9), pytest.approx(100 * 0.8 / 1.8)]
    per, pooled, n = correlation(draws)
    assert per == [pytest.approx(-1.0), pytest.approx(-1.0)]
    assert pooled == pytest.approx(-1.0) and n == 6


def test_kept_share_attributes_every_training_point_to_its_flight(tmp_path) -> None:
    from benchmarks.informative_kept import kept_share
    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model
    from omavctl.logs import write_log
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8, wobble
    from omavctl.sim.truth import load_truth
    from omavctl.vehicle import default_vehicle

    vehicle = default_vehicle()
    truth = load_truth(None, vehicle)
    first, second = tmp_path / "first.csv", tmp_path / "second.csv"
    write_log(first, simulate(fig8(duration=4.0), vehicle, truth, seed=1).log)
    write_log(second, simulate(wobble(duration=4.0), vehicle, truth, seed=2).log)
    shares, inputs = [], {}
    for name, logs in (("a", [first]), ("b", [second]), ("ab", [first, second])):
        model = fit_model(logs, vehicle, points=30, seed=0, restarts=0).model
        save_model(tmp_path / f"{name}.npz", model)
        shares.append(kept_share(tmp_path / f"{name}.npz", first, second))
        inputs[name] = model.inputs
    assert shares[0] == 0.0 and shares[1] == 1.0
    # two logs: each keeps the 30 points a fit on it alone picks
    assert shares[2] == 0.5
    assert np.array_equal(inputs["ab"], np.concatenate([inputs["a"], inputs["b"]]))


def test_markdown_says_which_target_holds() -> None:
    from benchmarks.informative_md import markdown

    draws = []
    for i, scale in enumerate((1.0, 2.0, 0.5)):  # exact in binary: no rank ties broken
        d = _draw(2.0 * scale, 1.0 * scale, {0: (3.0, 0.9 * scale), 1: (1.0, 0.5 * scale)})
        ranking = {"amplitude": 0.5, "frequency": -0.25}
        draws.append({**d, "effects": "drag", "seed": i, "seconds": 1.0, "task_cost": 4.0})
        draws[-1]["ranking"] = ranking
    cfg = {"effects": ["drag"], "seeds": [0, 1, 2], "duration": 20.0, "candidates": 2}
    text = markdown(draws, {**cfg, "sims": 4, "pool_extra": 1}, 60.0, ["--seeds", "0", "1", "2"])
    # planned halves the task-again error in every draw (interval of zero width) and
    # beats the random candidate by 44 %; the oracle is the planned flight itself
    assert (
        "planned vs the task flown again, closed-loop tracking ≥ 10 %: +50.0 % [+50.0, +50.0]"
        in text
    )
    assert "region's held-out flights ≥ 10 %: +44.4 % [+44.4, +44.4] — **holds**" in text
    assert (
        "| oracle vs planned | closed-loop tracking of the task | +0.0 % [+0.0, +0.0] | no |"
        in text
    )
    assert "pooled over 6 flown candidates -1.00; per draw n/a, n/a, n/a." in text
    # region errors 0.9 and 0.5 (x scale): span 0.4 / 0.7 of the mean; cost 1 vs task's 4
    assert "span 57 % of their mean (per draw 57, 57, 57 %)" in text
    assert "cost is 75 % below the task's own" in text
    assert "RMS amplitude +0.50, +0.50, +0.50; with its mean frequency -0.25," in text
    # three seeds of one draw each: clustered by seed, the same gains and intervals
    assert "The same gains clustered by seed (3 seeds:" in text
    assert text.count("| planned vs the task flown again | closed-loop tracking of the task |") == 2


def test_pool_ranking_finds_what_the_cost_rewards(tmp_path) -> None:
    from benchmarks.informative_kept import pool_ranking, read_scores

    rng = np.random.default_rng(0)
    coeffs = np.stack([rng.uniform(0.1, 2, (8, 3, 2)), rng.uniform(-1, 1, (8, 3, 2))], -1)
    amplitude = np.sqrt((coeffs[..., 1] ** 2).mean(axis=(1, 2)))
    cost = 1.0 + amplitude  # the cost grows with the deviation only
    cost[3] = np.inf  # infeasible: left out
    ranking = pool_ranking(coeffs, cost)
    assert ranking["amplitude"] == pytest.approx(1.0)
    assert -1.0 < ranking["frequency"] < 1.0
    # the --scores CSV round trip: coefficient columns f_x1, A_x1, ... and empty infeasible cost
    names = [f"{k}_{a}{p}" for a in "xyz" for p in (1, 2) for k in ("f", "A")]
    rows = ["candidate," + ",".join(names) + ",cost,feasible"]
    for k in range(8):
        ok = np.isfinite(cost[k])
        vals = ",".join(repr(float(v)) for v in coeffs[k].reshape(-1))
        rows.append(f"{k},{vals},{float(cost[k]) if ok else ''},{'true' if ok else 'false'}")
    (tmp_path / "scores.csv").write_text("\n".join(rows) + "\n")
    back, back_cost = read_scores(tmp_path / "scores.csv")
    np.testing.assert_array_equal(back, coeffs)
    np.testing.assert_array_equal(back_cost, cost)


def test_the_region_task_plan_is_compared_with_its_own_cost_ranking() -> None:
    """With the ``--region task`` plan's choice and cost in the draws: its rows in the
    table, and the Spearman of each cost with the removed error, here +1 for the task
    cost (ranks the wrong way) and -1 for the pool cost."""
    from benchmarks.informative_md import markdown

    draws = []
    for i, scale in enumerate((1.0, 2.0, 0.5)):
        d = _draw(2.0 * scale, 1.0 * scale, {0: (3.0, 0.9 * scale), 1: (1.0, 0.5 * scale)})
        for c, paper_cost in zip(d["pool"].values(), (1.0, 3.0), strict=True):
            c["cost_task_region"] = paper_cost
        d.update(effects="drag", seed=i, seconds=1.0, task_cost=4.0, best_task_region=0)
        draws.append(d)
    rows = {(name, label): g for name, label, g in comparisons(draws)}
    region = "model RMSE, region's held-out flights"
    assert (
        rows[("planned vs the --region task plan", region)] == [pytest.approx(100 * 0.4 / 0.9)] * 3
    )
    assert rows[("--region task plan vs one random candidate", region)] == [0.0] * 3
    assert correlation(draws, "cost_task_region")[1] == pytest.approx(1.0)
    cfg = {"effects": ["drag"], "seeds": [0, 1, 2], "duration": 20.0, "candidates": 2}
    text = markdown(draws, {**cfg, "sims": 4, "pool_extra": 1}, 60.0, ["--seeds", "0"])
    assert "Spearman of the `--region task` cost with the region error" in text
    assert "(`--region pool`) with the region error the refit removes" in text
    assert "| planned | --region task plan | oracle |" in text
    for d in draws:  # the same draws, flown with benchmark --baseline-plan uncapped
        d["baseline_plan"] = "uncapped"
    rows = {(name, label): g for name, label, g in comparisons(draws)}
    assert rows[("planned vs the uncapped plan", region)] == [pytest.approx(100 * 0.4 / 0.9)] * 3
    text = markdown(draws, {**cfg, "sims": 4, "pool_extra": 1}, 60.0, ["--seeds", "0"])
    assert "Spearman of the uncapped plan's cost (`--tilt-margin 90`) with the region" in text
    assert "| planned | uncapped plan | oracle |" in text and "--region task" not in text


def test_the_plans_expectation_is_set_beside_the_realised_gain() -> None:
    from benchmarks.informative_md import expected_vs_realised

    # planned cost 1 against the task's 4 and the random candidate's 9: the model
    # expects its RMS error to fall by 50 % and 67 %; realised on the region: task again
    # 1.0 -> planned 0.5 (50 %), random 0.9 -> 0.5 (44 %)
    d = _draw(2.0, 1.0, {0: (9.0, 0.9), 1: (1.0, 0.5)})
    d["task_cost"] = 4.0
    out = expected_vs_realised([d])
    assert out["task again"] == ([pytest.approx(50.0)], [pytest.approx(50.0)])
    assert out["random"] == ([pytest.approx(100 * 2 / 3)], [pytest.approx(100 * 0.4 / 0.9)])


def test_tilt_analysis_bins_by_extra_tilt_and_compares_within_the_margin(tmp_path) -> None:
    """benchmarks/informative_tilt.py on a synthetic draw: candidates that tilt beyond
    the margin leave a worse refit; within it the cost ranks the region error exactly,
    so its Spearman is -1 and its pick is the best there."""
    from benchmarks.informative_tilt import before_after, by_tilt, flown
    from omavctl.planning.candidates import sample_coefficients
    from omavctl.sim.tasks import fig8
    from omavctl.sim.trajectory import write_trajectory

    task = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.5)
    write_trajectory(tmp_path / "task.csv", task)
    coeffs = sample_coefficients(np.random.default_rng(0), 8, 2, 0.1, 2.0, 1.0)
    cost = 1.0 + 0.1 * np.arange(8)
    names = [f"{k}_{a}{p}" for a in "xyz" for p in (1, 2) for k in ("f", "A")]
    rows = ["candidate," + ",".join(names) + ",cost,feasible"]
    for k in range(8):
        vals = ",".join(repr(float(v)) for v in coeffs[k].reshape(-1))
        rows.append(f"{k},{vals},{float(cost[k])!r},true")
    (tmp_path / "scores-variance.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "result.json").write_text("{}")
    # extra tilts of seed 0: 52.7, 0.1, 30.7, 18.0, 1.7, 4.9, 2.1, 2.0 deg
    extra = {0: 52.7, 1: 0.1, 2: 30.7, 3: 18.0, 4: 1.7, 5: 4.9, 6: 2.1, 7: 2.0}

    def errors(e: float) -> dict:
        return {"tracking": e, "region": e, "task": e}

    within = {1: 1.0, 4: 1.2, 5: 1.4}  # region error grows with the cost within 10 deg
    pool = {k: errors(within.get(k, 1.8)) for k in (0, 1, 2, 4, 5)}
    result = {"first": errors(2.0), "pool": {str(k): v for k, v in pool.items()}}
    result.update(best=0, random=5)
    (tmp_path / "result.json").write_text(json.dumps(result))
    _, cands, _, ex = flown(tmp_path)
    assert sorted(cands) == [0, 1, 2, 4, 5]
    np.testing.assert_allclose([ex[k] for k in extra], list(extra.values()), atol=0.1)
    lines = by_tilt([tmp_path])
    assert lines[0] == "5 flown candidates of 1 draws"
    assert "  extra tilt in (20, 90] deg, n = 2: +10.0 % [+10.0, +10.0]" in lines
    assert "  extra tilt in (-90, 5] deg, n = 3: +40.0 % [+15.2, +64.8]" in lines
    spear, before, after = before_after([tmp_path], 10.0)
    assert "within +10 deg (draws with 3 or more) -1.00" in spear
    # before: the lowest cost (0) tilts 52.7 deg beyond: worse than the random one (5)
    assert before.startswith("planned vs the random candidate, region: -28.6 % (one draw")
    # after: the pick (1) against the mean of 4 and 5 (1.3): 23.1 %, the oracle's too
    assert after.startswith("margin 10: its pick vs a random candidate within it, region: +23.1 %")


def test_heldout_is_what_evaluate_reports(tmp_path, vehicle, short_fig8) -> None:
    """The benchmark's held-out errors (a worker process, evaluate without the diagnosis
    and the horizons) are evaluate's own numbers, to the bit: the RMSE per axis of the
    model and the closed-loop tracking (docs/informative.md, "The cost of a draw")."""
    truth = {"effects": {"rotational_drag": {"D": [0.05, 0.05, 0.03]}}}
    logs = [tmp_path / "fit.csv", tmp_path / "held.csv"]
    for seed, log in enumerate(logs):
        write_log(log, fly(vehicle, short_fig8, truth, seed=seed).log)
    model = tmp_path / "m.npz"
    save_model(model, fit_model([logs[0]], vehicle, points=40, restarts=0).model)
    full = evaluate([model], [logs[1]]).tree
    assert full["diagnosis"] is not None and full["horizons"] is not None
    try:
        got = calls.heldout(model, logs[1])
    finally:
        calls.stop()
    assert got["rmse"] == full["metrics"]["model"]["rmse"]
    assert got["tracking"] == full["tracking"] and got["tracking"]["mean"] > 0
    assert calls.cost()["evaluate"][0] >= 1


def test_plan_args_reach_both_plans_of_a_draw(tmp_path, monkeypatch) -> None:
    """``--plan-args`` (the candidate family, e.g. a wider amplitude) is appended to the
    planned and the baseline plan's command lines alike, so the pool, the random candidate
    and the oracle all come from the same family; without it the plans are unchanged."""
    import benchmarks.informative as inf

    seen: list[tuple[str, ...]] = []
    monkeypatch.setattr(inf, "omavctl", lambda *args: seen.append(args) or {})
    paths = {"task": tmp_path / "task.csv", "model": tmp_path / "first.npz"}
    for extra, baseline in (("--amplitude 3 --max-freq 1.5", "uncapped"), ("", "task-region")):
        cfg = argparse.Namespace(candidates=30, sims=4, plan_args=extra, baseline_plan=baseline)
        seen.clear()
        inf._plan(paths, tmp_path, 5, cfg, "variance")
        inf._plan(paths, tmp_path, 5, cfg, "variance", "-task")
        planned, baseline_plan = (list(a) for a in seen)
        for args in (planned, baseline_plan):
            assert args[0] == "plan" and ("--amplitude" in args) == bool(extra)
            if extra:
                i = args.index("--amplitude")
                assert args[i : i + 4] == ["--amplitude", "3", "--max-freq", "1.5"]
        assert ("--tilt-margin" in baseline_plan) == (baseline == "uncapped")


def test_the_random_candidates_mean_is_over_every_drawn_pool_candidate() -> None:
    """With the draws' random pool candidates listed (``drawn``), planned and oracle are
    also compared with their mean: here (0.9 + 0.7) / 2 = 0.8 against the planned 0.5,
    while the one random candidate (0.9) gives a larger gain; the rows are absent for
    draws that do not list them."""
    draws = [_draw(2.0, 1.0, {0: (3.0, 0.9), 1: (1.0, 0.5), 2: (2.0, 0.7)}) for _ in range(2)]
    region = "model RMSE, region's held-out flights"
    assert ("planned vs the random candidates' mean", region) not in {
        (n, label) for n, label, _ in comparisons(draws)
    }
    for d in draws:
        d["drawn"] = [0, 2]
    rows = {(name, label): g for name, label, g in comparisons(draws)}
    assert rows[("planned vs the random candidates' mean", region)] == [pytest.approx(37.5)] * 2
    assert (
        rows[("oracle vs the random candidates' mean (room)", region)] == [pytest.approx(37.5)] * 2
    )
    assert rows[("planned vs one random candidate", region)] == [pytest.approx(100 * 0.4 / 0.9)] * 2
