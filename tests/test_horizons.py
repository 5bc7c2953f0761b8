"""evaluate --horizons: open-loop prediction of body rate and attitude over horizons.

A noiseless flight through an ideal plant with a rotational drag, predicted by
a model that holds exactly that drag (and no GP), must be rolled out with
~zero error at every horizon; holding the state must err as computed by hand;
no window may cross an excluded span; the table survives the evaluation JSON;
a fitted model's band covers a held-out flight.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.diagnose.evalio import load_evaluation, write_evaluation
from omavctl.diagnose.evaluate import evaluate
from omavctl.diagnose.horizon_findings import findings
from omavctl.diagnose.horizons import GridSignals, horizon_table, window_starts
from omavctl.learn.fit import fit_model
from omavctl.learn.model import EffectEstimate, ResidualGP
from omavctl.learn.model_file import save_model
from omavctl.learn.signal import ResidualSamples, feature_names
from omavctl.logs import write_log
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from tests.conftest import NO_NOISE, rebuilt

runner = CliRunner()
DRAG = [0.05, 0.05, 0.03]
#: ``evaluate`` without the diagnosis (about 4-8 CPU s) for the tests that read only the
#: horizons table and the metrics, which the diagnosis does not change
NO_DIAGNOSIS = {"with_diagnosis": False}


def _model(vehicle, effects=None) -> ResidualGP:
    """A model without a GP (signal variance 0) holding ``effects`` exactly."""
    names = feature_names("wrench")
    d = len(names)
    return ResidualGP(
        vehicle=vehicle,
        features="wrench",
        input_names=tuple(names),
        inputs=np.eye(2, d),
        targets=np.zeros((2, 3)),
        input_mean=np.zeros(d),
        input_scale=np.ones(d),
        target_mean=np.zeros(3),
        signal_variance=np.zeros(3),
        length_scales=np.ones((3, d)),
        noise_variance=np.full(3, 1e-6),
        effects=effects or {},
    )


@pytest.fixture(scope="module")
def exact(tmp_path_factory, vehicle):
    """A noiseless ideal-plant flight with drag, the exact model and a drag-less one."""
    tmp = tmp_path_factory.mktemp("horizons")
    tree = {"ideal": True, "noise": NO_NOISE, "effects": {"rotational_drag": {"D": DRAG}}}
    log = tmp / "flight.csv"
    ref = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.0)
    write_log(log, simulate(ref, vehicle, truth_from_tree(tree, vehicle), seed=1).log)
    drag = EffectEstimate("rotational_drag", {"D": np.array(DRAG)}, {"D": np.zeros(3)})
    truth_model, physics_model = tmp / "truth.npz", tmp / "physics.npz"
    save_model(truth_model, _model(vehicle, {"rotational_drag": drag}))
    save_model(physics_model, _model(vehicle))
    return tmp, log, truth_model, physics_model


def test_the_exact_truth_model_rolls_out_with_zero_error(exact):
    _, log, truth_model, _ = exact
    h = evaluate([truth_model], [log], **NO_DIAGNOSIS).tree["horizons"]
    assert h["steps"] == [1, 10, 50] and h["windows"] > 300 and h["attitude"]
    for row in h["table"]["model"]:
        assert row["rate_error"]["norm"] < 2e-3 * max(1.0, row["steps"] / 10), row
        assert row["attitude_error"] < 1e-5 * row["steps"], row
    # the drag matters: physics alone is off by far more at 0.5 s
    nominal = h["table"]["nominal"][-1]
    assert nominal["rate_error"]["norm"] > 100 * h["table"]["model"][-1]["rate_error"]["norm"]
    # effects alone are the truth too here (the GP is off)
    for eff, full in zip(h["table"]["effects"], h["table"]["model"], strict=True):
        assert eff["rate_error"] == pytest.approx(full["rate_error"], rel=1e-9)


def _synthetic(n: int, gap_at: int, dt: float) -> tuple[ResidualSamples, GridSignals]:
    """Samples whose grid indices jump by 5 after position ``gap_at`` (an excluded
    span); body rate [a t, b t^2, 0] on the grid time, torque zero."""
    index = np.arange(n)
    index[gap_at:] += 5
    t = index * dt
    omega = np.stack([0.7 * t, 0.3 * t**2, np.zeros(n)], axis=1)
    z3, z6 = np.zeros((n, 3)), np.zeros((n, 6))
    s = ResidualSamples(Path("synthetic"), index, t, omega, z6, z3, z3, z3, du=z6)
    s.rate_noise = np.zeros(3)
    return s, GridSignals(body_rate=omega, torque=z3, attitude=None)


def test_holding_the_state_errs_as_computed_by_hand(vehicle):
    dt, n, gap = 0.01, 300, 150
    s, g = _synthetic(n, gap, dt)
    h = horizon_table([_model(vehicle)], [s], [g], 100.0, (0.01, 0.1, 0.5))
    starts = np.concatenate([np.arange(0, gap - 50), np.arange(gap, n - 50)])
    assert h["windows"] == starts.size == 200
    t0 = s.t[starts]
    for row in h["table"]["naive"]:
        k = row["steps"]
        hor = k * dt
        assert row["rate_error"]["x"] == pytest.approx(0.7 * hor, rel=1e-9)
        by_hand = np.mean(0.3 * (2 * t0 * hor + hor**2))
        assert row["rate_error"]["y"] == pytest.approx(by_hand, rel=1e-9)
        sums = [
            np.hypot(0.7 * j * dt, 0.3 * (2 * t0 * j * dt + (j * dt) ** 2)) for j in range(1, k + 1)
        ]
        assert row["rate_error_sum"] == pytest.approx(np.mean(np.sum(sums, axis=0)), rel=1e-9)
        assert row["attitude_error"] is None
    errors = [row["rate_error"]["norm"] for row in h["table"]["naive"]]
    assert errors == sorted(errors) and errors[-1] > 10 * errors[0]


def test_windows_never_cross_an_excluded_span():
    rng = np.random.default_rng(3)
    index = np.cumsum(1 + (rng.random(2000) < 0.01) * rng.integers(1, 30, 2000))
    for k, stride in ((1, 1), (10, 3), (50, 1)):
        p = window_starts(index, k, stride)
        assert p.size > 0 and np.all(p % stride == 0)
        spans = index[p[:, None] + np.arange(k + 1)]
        assert np.all(np.diff(spans, axis=1) == 1)
        # and every start that fits is used
        ok = [q for q in range(0, index.size - k, stride) if index[q + k] - index[q] == k]
        assert p.tolist() == ok


def test_the_table_survives_the_evaluation_json(exact, tmp_path):
    _, log, truth_model, physics_model = exact
    result = evaluate([truth_model, physics_model], [log], horizons=(0.02, 0.3), horizon_stride=4)
    out = tmp_path / "e.json"
    write_evaluation(out, result)
    text = out.read_text()
    assert "NaN" not in text and "Infinity" not in text
    tree, _ = load_evaluation(out)
    h = tree["horizons"]
    assert h == json.loads(json.dumps(result.tree["horizons"]))
    assert h["steps"] == [2, 30] and h["stride"] == 4
    assert [p["key"] for p in h["predictors"]] == [
        "naive",
        "nominal",
        "effects",
        "model",
        "effects_1",
        "model_1",
    ]
    # the drag-less model is physics only: its rows are the nominal ones
    assert h["table"]["model_1"][-1]["rate_error"] == pytest.approx(
        h["table"]["nominal"][-1]["rate_error"]
    )
    assert len(h["curves"]["model"]["x"]) == 31


def test_bad_horizons_are_refused_in_one_line(exact, tmp_path):
    _, log, truth_model, _ = exact
    for text, message in (
        (
            "0.1,abc",
            "error: --horizons must be seconds separated by commas (e.g. 0.01,0.1,0.5) "
            "or none, got '0.1,abc'",
        ),
        ("0.001", "error: --horizons: 0.001 s is shorter than one step of the 100 Hz grid"),
        ("0.1,-1", "error: --horizons: -1 is not a positive number of seconds"),
    ):
        out = tmp_path / "bad.json"
        res = runner.invoke(
            app,
            [
                "evaluate",
                str(log),
                "--model",
                str(truth_model),
                "--out",
                str(out),
                "--horizons",
                text,
            ],
        )
        assert res.exit_code == 2, res.output
        assert res.stderr.strip() == message
        assert not out.exists()


@pytest.fixture(scope="module")
def fitted(tmp_path_factory, vehicle):
    """A fit flight, another flight of its task and one of another figure-8 (drag and the
    default actuator imperfections), and a model fitted on the first."""
    tmp = tmp_path_factory.mktemp("fitted")
    truth = truth_from_tree({"seed": 1, "effects": {"rotational_drag": {"D": DRAG}}}, vehicle)
    logs = {
        "fit": (fig8(duration=10.0, ramp=1.0), 1),
        "same": (fig8(duration=10.0, ramp=1.0), 2),
        "other": (fig8(roll_deg=20, pitch_deg=25, period=6.0, duration=8.0, ramp=1.0), 3),
    }
    for name, (ref, seed) in logs.items():
        write_log(tmp / f"{name}.csv", simulate(ref, vehicle, truth, seed=seed).log)
    model = tmp / "m.npz"
    save_model(model, fit_model([tmp / "fit.csv"], vehicle, points=80, restarts=0).model)
    return tmp, model


def test_the_band_covers_a_held_out_flight(fitted):
    """On another flight of the fit flight's task (other noise, not fitted on) the band
    covers >= 85 % at every horizon and axis; on a flight of another figure-8 it is as
    calibrated as the model's one-step band, whose calibration it inherits."""
    tmp, model = fitted
    same = evaluate([model], [tmp / "same.csv"], horizon_stride=2, **NO_DIAGNOSIS).tree
    for row in same["horizons"]["table"]["model"]:
        assert min(row["coverage"].values()) >= 0.85, row
    other = evaluate([model], [tmp / "other.csv"], horizon_stride=2, **NO_DIAGNOSIS).tree
    one_step = other["metrics"]["model"]["coverage_2sigma"]
    for row in other["horizons"]["table"]["model"]:
        for a in "xyz":
            assert row["coverage"][a] >= one_step[a] - 0.05, (a, row, one_step)
    # the full model sees further than hold-the-state and physics only
    for tree in (same, other):
        table = tree["horizons"]["table"]
        last = {key: table[key][-1]["rate_error"]["norm"] for key in ("naive", "nominal", "model")}
        assert last["model"] < 0.5 * min(last["naive"], last["nominal"])


def test_the_fused_float32_mean_matches_the_model(fitted):
    """The rollouts' float32 GP mean agrees with the model's float64 one (the mean as
    fitted: a model that weighs its mean by its band is rolled out with gp_predict)."""
    from omavctl.learn.gp_mean import FusedMean
    from omavctl.learn.model_file import load_model

    model = rebuilt(load_model(fitted[1]), mean_shrink=np.zeros(3))
    rng = np.random.default_rng(0)
    z = model.inputs[rng.integers(0, model.n_train, 500)]
    z = z + 0.3 * rng.standard_normal(z.shape) * model.input_scale
    want, _ = model.gp_predict(z, variance=False)
    got = FusedMean(model)(z)
    assert np.abs(got - want).max() < 1e-4 * max(1.0, np.abs(want).max())
    assert np.abs(want).max() > 1e-3  # a GP that predicts something


def test_logs_without_a_long_enough_stretch_get_no_table_not_an_error(vehicle):
    s, g = _synthetic(80, 40, 0.01)  # two stretches of 40 samples, none of 51
    h = horizon_table([_model(vehicle)], [s], [g], 100.0)
    assert h["windows"] == 0 and h["table"] == {}
    assert [f["code"] for f in h["findings"]] == ["no_windows"]
    assert "no stretch of 51 consecutive usable samples (0.5 s)" in h["findings"][0]["message"]
    # a shorter horizon fits
    assert horizon_table([_model(vehicle)], [s], [g], 100.0, (0.1,))["windows"] == 2 * 30


def test_a_long_log_gets_a_larger_stride(vehicle, monkeypatch):
    import omavctl.diagnose.horizons as hz

    monkeypatch.setattr(hz, "MAX_WINDOW_SAMPLES", 5100)
    s, g = _synthetic(300, 150, 0.01)
    h = horizon_table([_model(vehicle)], [s], [g], 100.0)
    assert h["stride_requested"] == 1 and h["stride"] == 3  # 300 x 51 / 5100
    assert h["windows"] == 34 + 34  # starts 0, 3, .. 99 and 150, 153, .. 249


def _tree(errors: dict[str, list[float]], name: str = "a.bag") -> dict:
    """A minimal evaluation with a horizon table of the given error norms (all axes)."""
    from omavctl.diagnose.horizon_findings import findings

    preds = [
        {"key": k, "kind": k, "model": None if k in ("naive", "nominal") else 0} for k in errors
    ]

    def row(k: int, e: float) -> dict:
        return {"seconds": k / 100, "steps": k, "rate_error": {"x": e, "y": e, "z": e, "norm": e},
                "coverage": {"x": 0.9, "y": 0.9, "z": 0.9, "all": 0.9}}  # fmt: skip

    h = {
        "steps": [1, 50], "seconds": [0.01, 0.5], "band_sigma": 2.0, "predictors": preds,
        "table": {k: [row(1, v[0]), row(50, v[1])] for k, v in errors.items()},
    }  # fmt: skip
    h["findings"] = findings(h)
    return {"horizons": h, "logs": [{"name": name, "sha256": name, "t0": 0.0}]}


def test_the_findings_and_the_report_name_a_model_that_wins_early_and_loses_late():
    from omavctl.report.horizons import _side_by_side

    errors = {"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "effects": [0.01, 0.1]}
    gp_hurts = _tree({**errors, "model": [0.008, 0.2]})
    codes = [f["code"] for f in gp_hurts["horizons"]["findings"]]
    assert codes.count("gp_hurts_long") == 3 and codes.count("gp_worse_long") == 3
    assert "ranking_changes" in codes and "band_narrow" not in codes
    x = next(f for f in gp_hurts["horizons"]["findings"] if f["code"] == "gp_hurts_long")
    assert x["message"] == (
        "x: the GP lowers the 0.01 s body-rate error (0.01 -> 0.008 rad/s) but raises it "
        "at 0.5 s (0.1 -> 0.2 rad/s)"
    )
    # one file's report section and its --json name the GP that helps early and hurts late
    from omavctl.report.horizons import _evaluation_blocks, horizons_json

    gp_hurts["horizons"].update(windows=100, stride=1)
    section = [str(i) for b in _evaluation_blocks(gp_hurts, "one.json", False)
               if hasattr(b, "items") for i in b.items]  # fmt: skip
    assert x["message"] in section
    out = horizons_json(gp_hurts)
    assert out is not None
    assert [(f["code"], f["axis"]) for f in out["findings"] if f["code"] == "gp_hurts_long"] == [
        ("gp_hurts_long", "x"), ("gp_hurts_long", "y"), ("gp_hurts_long", "z")]  # fmt: skip
    good = _tree({**errors, "model": [0.009, 0.05]})
    assert [f["code"] for f in good["horizons"]["findings"]] == []
    blocks = _side_by_side([(gp_hurts, {}, "one.json"), (good, {}, "two.json")])
    notes = [str(item) for b in blocks if hasattr(b, "items") for item in b.items]
    assert notes[0] == (
        "one.json: full model wins at 0.01 s (0.008 vs 0.009 rad/s) and loses at 0.5 s "
        "(0.2 vs 0.05) to two.json: full model"
    )
    assert any(n.startswith("one.json: x: the GP lowers") for n in notes)
    # on other logs the two files' models are not compared
    other = _tree({**errors, "model": [0.009, 0.05]}, name="b.bag")
    blocks = _side_by_side([(gp_hurts, {}, "one.json"), (other, {}, "two.json")])
    notes = [str(item) for b in blocks if hasattr(b, "items") for item in b.items]
    assert not any("wins at" in n for n in notes)


def test_a_diverging_rollout_is_written_as_null_not_nan(vehicle, tmp_path):
    """A model far from the log (a huge negative drag) blows its rollout up: the table
    holds inf (the evaluation file writes null), and nothing warns or fails."""
    import warnings

    s, g = _synthetic(300, 150, 0.01)
    s.regressors = {"rotational_drag": np.zeros((s.n, 3, 3))}
    g = GridSignals(body_rate=g.body_rate * 40.0, torque=g.torque, attitude=None)
    drag = EffectEstimate("rotational_drag", {"D": np.full(3, -1e3)}, {"D": np.zeros(3)})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h = horizon_table([_model(vehicle, {"rotational_drag": drag})], [s], [g], 100.0)
    assert not np.isfinite(h["table"]["model"][-1]["rate_error"]["norm"])
    assert np.isfinite(h["table"]["naive"][-1]["rate_error"]["norm"])


def test_json_output_carries_the_table(exact, tmp_path):
    _, log, truth_model, _ = exact
    out = tmp_path / "e.json"
    args = ["evaluate", str(log), "--model", str(truth_model), "--out", str(out)]
    res = runner.invoke(app, [*args, "--horizons", "0.05,0.2", "--horizon-stride", "3", "--json"])
    assert res.exit_code == 0, res.output
    obj = json.loads(res.stdout)
    h = obj["horizons"]
    assert h["steps"] == [5, 20] and h["stride"] == 3 and "curves" not in h
    # the file's table, but for the chunk means behind the standard errors
    written = json.loads(out.read_text())["horizons"]["table"]
    assert all("rate_error_chunks" in row for rows in written.values() for row in rows)
    for rows in written.values():
        for row in rows:
            del row["rate_error_chunks"]
    assert h["table"] == written
    assert "open-loop error over horizons" in res.stderr
    res = runner.invoke(app, [*args, "--horizons", "none", "--json"])
    assert res.exit_code == 0 and json.loads(res.stdout)["horizons"] is None


def test_an_evaluation_written_before_the_horizons_is_still_reported(exact, tmp_path):
    from omavctl.report.evaluation import render_report

    _, log, truth_model, _ = exact
    result = evaluate([truth_model], [log], horizons=(0.1,))
    write_evaluation(tmp_path / "new.json", result)
    tree, series = load_evaluation(tmp_path / "new.json")
    old = {k: v for k, v in tree.items() if k != "horizons"}
    md = render_report([(old, series, "old.json"), (tree, series, "new.json")], "md")
    assert "old.json: no horizon table (written before evaluate had one" in md
    assert "new.json: " in md and "| full model |" in md


def test_measured_rotor_speeds_and_tilts_drive_the_rollout(tmp_path):
    """An omav flight whose motors lag (T_m 0.05 s), logged with and without its
    commanded wrench: without it, evaluate mixes the measured rotor speeds and tilt
    angles (the omav's /omav/actuators) into the wrench the rollout integrates, so a
    model that knows no lag rolls out the lagged wrench the vehicle felt."""
    from omavctl.vehicle import load_vehicle

    (tmp_path / "omav.yaml").write_text("preset: omav\n")
    omav = load_vehicle(tmp_path / "omav.yaml")
    ref = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.0)
    tree = {"ideal": True, "noise": NO_NOISE, "effects": {"motor_lag": {"T_m": 0.05}}}
    log = simulate(ref, omav, truth_from_tree(tree, omav), seed=1).log
    write_log(tmp_path / "commanded.csv", log)
    for role in ("force_command", "torque_command"):
        log.series.pop(role)
    write_log(tmp_path / "measured.csv", log)
    save_model(tmp_path / "m.npz", _model(omav))
    err = {}
    for name in ("commanded", "measured"):
        h = evaluate([tmp_path / "m.npz"], [tmp_path / f"{name}.csv"], **NO_DIAGNOSIS).tree[
            "horizons"
        ]
        assert h["windows"] > 700
        err[name] = [row["rate_error"]["norm"] for row in h["table"]["model"]]
    # measured 0.017 rad/s at 0.5 s against 0.19 from the commanded wrench (lag unmodelled)
    assert err["measured"][-1] < 0.15 * err["commanded"][-1]
    assert err["commanded"][-1] > 0.1


def test_the_ranking_puts_predictors_with_the_same_error_in_one_place():
    """Without effects, physics only and physics + effects are the same predictor: the
    ranking read 'hold the state, physics only, physics + effects' as if they differed
    (a new user's Crazyflie report). They now share a place."""
    tree = _tree({"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "effects": [0.03, 0.9],
                  "model": [0.01, 0.95]})  # fmt: skip
    (rank,) = [f for f in tree["horizons"]["findings"] if f["code"] == "ranking_changes"]
    assert rank["message"] == (
        "best to worst at 0.01 s: full model, hold the state, nominal = nominal + "
        "effects; at 0.5 s: hold the state, nominal = nominal + effects, full model"
    )


def test_a_log_without_attitude_gets_no_attitude_column():
    """The Crazyflie log has no attitude: its table had an 'attitude' column of empty
    cells and a terminal title naming 'attitude rad'."""
    import io

    from rich.console import Console

    from omavctl.report.horizons import _table, render_horizons

    tree = _tree({"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "model": [0.01, 0.4]})
    tree["horizons"]["windows"] = 10
    table = _table(tree["horizons"])
    assert "attitude, rad" not in table.columns and len(table.rows[0]) == 1 + 3 * 2
    # every column carries its unit: the Markdown report's "0.01 s ahead rate" had none
    assert table.columns[1:4] == ["rate, rad/s", "per axis", "2σ"]
    out = io.StringIO()
    render_horizons(Console(file=out, width=200), tree)
    text = " ".join(out.getvalue().split())  # the title wraps to the table's width
    assert "(no attitude in the log; in brackets" in text and "attitude rad" not in text
    tree["horizons"]["attitude"] = True
    assert "attitude, rad" in _table(tree["horizons"]).columns


def test_horizon_notes_say_no_change_that_rounds_to_nothing_and_compare_as_printed():
    """ "the GP lowers the 0.01 s body-rate error (0.696 -> 0.696 rad/s)" and "holds
    85 % ... (below 85 %)": a change that rounds to nothing is not a change, a band is
    compared as printed, and an axis whose GP the rollouts leave out is not said to
    be raised by the GP."""
    errors = {"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "effects": [0.6962, 0.1]}
    tree = _tree({**errors, "model": [0.6961, 0.2]})
    assert not any(f["code"] == "gp_hurts_long" for f in tree["horizons"]["findings"])
    h = _tree({**errors, "effects": [0.01, 0.1], "model": [0.008, 0.2]})["horizons"]
    h["predictors"][-1]["rollout_gp"] = {"x": 0.0, "y": 1.0, "z": 1.0}
    h["table"]["model"][0]["coverage"]["all"] = 0.846  # printed "85 %"
    h["table"]["model"][1]["coverage"]["all"] = 0.844
    found = findings(h)
    hurts = [f["axis"] for f in found if f["code"] == "gp_hurts_long"]
    assert hurts == ["y", "z"]  # x: "the rollouts leave the GP mean out" instead
    assert any(f["code"] == "gp_left_out" and f["axis"] == "x" for f in found)
    narrow = [f["message"] for f in found if f["code"] == "band_narrow"]
    assert narrow == [
        "at 0.5 s the full model's 2σ band holds 84 % of the body rates (below 85 %): "
        "it is too narrow there"
    ]


def test_the_verdict_band_sentence_says_where_the_open_loop_band_is_too_narrow():
    """Crazyflie: "Uncertainty can be trusted" one step ahead (91/93/96 %) above a
    horizon table whose open-loop band holds 43 % at 0.01 s."""
    from omavctl.diagnose.verdict import verdict

    tree = _tree({"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "effects": [0.01, 0.1],
                  "model": [0.009, 0.05]})  # fmt: skip
    tree["metrics"] = {"model": {"coverage_2sigma": {"x": 0.91, "y": 0.93, "z": 0.96}}}
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line == "Uncertainty can be trusted: within 2σ x 91 %, y 93 %, z 96 % (95 % expected)."
    tree["horizons"]["table"]["model"][0]["coverage"]["all"] = 0.43
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line == (
        "Uncertainty can be trusted one step ahead: within 2σ x 91 %, y 93 %, z 96 % (95 % "
        "expected); the open-loop 2σ band is too narrow: it holds 43 % of the body rates at "
        "0.01 s (85 % needed; the horizon table)."
    )
    # 89 % is "a little narrow" (80-90 %), also beside a cautious axis
    tree["metrics"]["model"] = {
        "coverage_2sigma": {"x": 1.0, "y": 0.96, "z": 0.89},
        "mean_std": {"x": 3.0, "y": 1.0, "z": 1.0},
        "rmse": {"x": 1.0, "y": 1.0, "z": 1.0},
    }
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line.startswith(
        "Uncertainty cautious on x: the band is wider than needed, the predicted σ more than "
        "twice the actual error (within 2σ: x 100 %, y 96 %, z 89 %); a little narrow on z; "
        "the open-loop"
    )


def test_a_printed_tie_that_swaps_is_no_ranking_change():
    """A new user read 'best to worst at 0.02 s: ..., physics only, hold the state; at
    1 s: ..., hold the state, physics only' of two predictors both printed 0.0334 at
    0.02 s: docs/horizons.md says a change that rounds to nothing is not a finding."""
    tree = _tree({"naive": [0.03341, 0.5], "nominal": [0.03338, 0.6], "effects": [0.02, 0.3],
                  "model": [0.01, 0.2]})  # fmt: skip
    assert not [f for f in tree["horizons"]["findings"] if f["code"] == "ranking_changes"]
    tree = _tree({"naive": [0.0331, 0.5], "nominal": [0.0338, 0.4], "effects": [0.02, 0.3],
                  "model": [0.01, 0.2]})  # fmt: skip
    (rank,) = [f for f in tree["horizons"]["findings"] if f["code"] == "ranking_changes"]
    assert rank["message"].endswith("at 0.5 s: full model, nominal + effects, nominal, "
                                    "hold the state")  # fmt: skip


def test_the_band_is_called_wide_or_narrow_per_axis_as_printed():
    """A new user read "holds 100 %" at 0.5 s with the band 3-4x the error and no word on
    it; then, on Betaflight, x's band 5.7x too wide beside a calibrated z (a rule over
    every axis stayed silent), and on a Crazyflie window "85 %" pooled with y at 74.5 %.
    Each axis is judged, its coverage as printed: a calibrated band (std what the errors
    show: half-width 2 sqrt(pi/2) = 2.51x the mean |error|) is not wide."""
    import math

    from omavctl.diagnose.horizon_findings import findings, open_loop_narrow, wide_factor

    h = _tree({"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "effects": [0.01, 0.1],
               "model": [0.01, 0.1]})["horizons"]  # fmt: skip
    calibrated = 2.0 * math.sqrt(math.pi / 2.0)
    early, late = h["table"]["model"]
    early["band_halfwidth"] = {a: calibrated * 0.01 for a in "xyz"}
    late["band_halfwidth"] = {"x": 0.9, "y": 0.8, "z": calibrated * 0.1}  # 3.6x, 3.2x, 1x
    late["coverage"] = {"x": 1.0, "y": 0.989, "z": 0.9, "all": 0.96}  # y prints 99 %
    assert wide_factor({**early, "band_sigma": 2.0}) == pytest.approx(1.0)
    (wide,) = [f for f in findings(h) if f["code"] == "band_wide"]
    assert wide["value"] == pytest.approx(0.9 / calibrated / 0.1)
    assert wide["message"] == (
        "at 0.5 s the full model's 2σ band is wider than its errors show on x 3.6x (holds "
        "100 %), y 3.2x (holds 99 %): safe, not tight (the band's std over the std its "
        "errors imply; a controller or planner reading it would be more cautious than this "
        "flight needs)"
    )
    late["band_halfwidth"]["x"] = 3.0  # 12x: too wide to use, not only safe
    (wide,) = [f for f in findings(h) if f["code"] == "band_wide"]
    assert wide["message"].endswith(
        "y 3.2x (holds 99 %): far too wide to use: it says little about these errors (the "
        "band's std over the std its errors imply; beyond the model's inputs it grows with "
        "how far the flight goes)"
    )
    late["band_halfwidth"]["x"] = 0.9
    late["coverage"]["y"] = 0.98  # wide on average, yet it misses samples: not "wide"
    (wide,) = [f for f in findings(h) if f["code"] == "band_wide"]
    assert wide["axis"] == "x"
    # pooled 85 % as printed, y 75 %: too narrow on y, in the finding and the verdict
    late["coverage"] = {"x": 0.95, "y": 0.75, "z": 0.85, "all": 0.847}
    (narrow,) = [f for f in findings(h) if f["code"] == "band_narrow"]
    assert narrow["axis"] == "y" and narrow["value"] == pytest.approx(0.75)
    assert narrow["message"] == (
        "at 0.5 s the full model's 2σ band holds 85 % of the body rates but y 75 % "
        "(below 85 %): it is too narrow there"
    )
    assert open_loop_narrow(h) == (
        "the open-loop 2σ band is too narrow: it holds 85 % of the body rates but y 75 % "
        "at 0.5 s (85 % needed; the horizon table)"
    )


def test_holding_the_state_that_beats_every_model_is_said():
    """Betaflight: hold the state 0.146 against 0.207 rad/s at 0.01 s and 1.45 against
    6.76 at 0.5 s, and no finding said it (only a ranking line, on one of the files)."""
    from omavctl.diagnose.horizon_findings import findings

    h = _tree({"naive": [0.005, 0.05], "nominal": [0.03, 0.9], "effects": [0.01, 0.1],
               "model": [0.008, 0.2]})["horizons"]  # fmt: skip
    (hold,) = [f for f in findings(h) if f["code"] == "hold_beats_models"]
    assert hold["value"] == 0.5
    assert hold["message"] == (
        "holding the state predicts the body rates better than every model at 0.01, 0.5 s "
        "(at 0.5 s 0.05 rad/s against 0.1 for the best, nominal + effects): rolled out open "
        "loop that far, no model here is worth its prediction on this flight"
    )
    h = _tree({"naive": [0.02, 0.05], "nominal": [0.03, 0.9], "effects": [0.01, 0.1],
               "model": [0.008, 0.2]})["horizons"]  # fmt: skip
    (hold,) = [f for f in findings(h) if f["code"] == "hold_beats_models"]
    assert "better than every model at 0.5 s (" in hold["message"]
    h = _tree({"naive": [0.02, 0.5], "nominal": [0.03, 0.9], "effects": [0.01, 0.1],
               "model": [0.008, 0.2]})["horizons"]  # fmt: skip
    assert not [f for f in findings(h) if f["code"] == "hold_beats_models"]


def test_beyond_the_fit_flights_inputs_the_band_grows_as_the_one_step_band(tmp_path, vehicle):
    """A model fitted without the vehicle's drag on a gentle figure-8, judged on one of
    three times its tilt (far beyond its inputs): its one-step band widens there with
    the growth beyond the inputs (:func:`omavctl.learn.band.growth_variance`) and covers;
    the rollout integrates that growth as an error of the function, so the horizon band
    covers too. Without it the band held 13-34 % on x and y at every horizon, while the
    one-step band held 94-100 % (the first models of the scorecard's tune draws, fit on
    steps and judged on figure-8s: docs/horizons.md, session 32)."""
    from omavctl.diagnose.evaluate import _grid, _read_log
    from omavctl.learn.band import growth_variance
    from omavctl.learn.model_file import load_model
    from omavctl.learn.rollout_residual import function_std

    truth = truth_from_tree(
        {"seed": 1, "effects": {"rotational_drag": {"D": [0.1, 0.08, 0.05]}}}, vehicle
    )
    gentle = fig8(roll_deg=10, pitch_deg=10, period=8.0, duration=10.0, ramp=1.0)
    wide = fig8(roll_deg=30, pitch_deg=30, period=5.0, duration=8.0, ramp=1.0)
    write_log(tmp_path / "fit.csv", simulate(gentle, vehicle, truth, seed=1).log)
    write_log(tmp_path / "other.csv", simulate(wide, vehicle, truth, seed=3).log)
    model = tmp_path / "m.npz"
    save_model(model, fit_model([tmp_path / "fit.csv"], vehicle, points=80, restarts=0).model)
    tree = evaluate([model], [tmp_path / "other.csv"], horizon_stride=2, **NO_DIAGNOSIS).tree
    one_step = tree["metrics"]["model"]["coverage_2sigma"]
    assert min(one_step.values()) >= 0.9, one_step
    for row in tree["horizons"]["table"]["model"]:
        for a in "xyz":
            assert row["coverage"][a] >= min(0.9, one_step[a] - 0.05), (a, row["coverage"])
    # the growth is the one-step band's, added to the function the rollout integrates:
    # zero at the fit flight's own inputs, where nothing changed
    m = load_model(model)
    assert np.all(growth_variance(m, m.inputs) == 0.0)
    samples = _read_log(tmp_path / "other.csv", m.vehicle, *_grid(m), None)[0]
    grows = growth_variance(m, samples.inputs(m.features))
    assert np.mean(grows[:, 0] > 0) > 0.5
    assert np.all(function_std(m, samples) ** 2 >= grows * (1 - 1e-9))


def test_the_tables_name_an_axis_the_band_fails_beside_the_pooled_share():
    """A new user read '0.207 (95%)' while the band failed an axis the pooled share hid;
    the terminal, the report and the docs also defined the share three ways. The cell
    names every axis under 85 % as printed (84.6 % prints 85 %: not named)."""
    from omavctl.report.horizons import COVERAGE_WORDS, coverage_cell

    assert coverage_cell({"x": 0.95, "y": 0.745, "z": 0.846, "all": 0.847}) == "85%, y 74%"
    assert coverage_cell({"x": 0.95, "y": 0.745, "z": 0.8, "all": 0.83}, " ") == (
        "83 %, y 74 %, z 80 %"
    )
    assert coverage_cell({"x": 0.95, "y": 0.95, "z": 0.95, "all": 0.95}) == "95%"
    assert COVERAGE_WORDS.startswith("the share of windows whose body-rate error lies inside")


def test_holding_the_state_that_beats_every_model_reaches_the_verdict():
    """On the Betaflight tunes holding the state beat every model at every horizon, and
    only the horizon section said so: the verdict, in the terminal and the report,
    spoke of one-step errors alone."""
    from omavctl.diagnose.verdict import verdict
    from omavctl.report.document import _md_inline
    from omavctl.report.top import verdict_section

    tree = _tree({"naive": [0.5, 1.45], "nominal": [0.9, 58.9], "model": [0.7, 6.76]})
    tree["diagnosis"] = {"missing": [], "missing_effects": [], "method": {}}
    tree["horizons"]["findings"] = findings(tree["horizons"])
    (line,) = [ln for ln in verdict(tree) if ln.key == "horizons"]
    assert line.text.startswith(
        "Open loop: holding the state predicts the body rates better than every model at "
        "0.01, 0.5 s (at 0.5 s 1.45 rad/s against 6.76 for the best, full model)"
    )
    assert line.text.endswith("on this flight (the horizon table).")
    items = [_md_inline(it) for it in verdict_section([(tree, None, "a.json")])[1].items]
    assert any(it.startswith("**Open loop:** holding the state predicts") for it in items), items
    # without the finding there is no such line
    tree["horizons"]["findings"] = []
    assert not [ln for ln in verdict(tree) if ln.key == "horizons"]
