"""The verdict sentences from evaluation trees: missing or not, the before/after change
with the reason for a worse axis, where the model fails, trust in its uncertainty,
flags and excluded spans of newer evaluations (keys treated as empty when absent)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from omavctl.diagnose.change import change_lines, report_verdict, scores_of_files
from omavctl.diagnose.verdict import activity, verdict
from omavctl.report.diagnosis import _param_lines


def _tree(rmse: dict, coverage: dict, missing: list[str], effects: dict | None = None) -> dict:
    return {
        "models": [{"name": "m.npz", "effects": effects or {}}],
        "metrics": {
            "model": {
                "rmse": rmse,
                "coverage_2sigma": coverage,
                "mean_std": {a: 0.05 for a in "xyz"},
            }
        },
        "worst_segments": [
            {
                "log": "f.bag",
                "start": 1.06,
                "end": 2.05,
                "rmse": {"x": 0.1, "y": 0.56, "z": 0.05},
                "attitude_deg": [17.0, 12.6, 0.1],
                "rate": [0.2, 0.69, 0.22],
                "u": [2.2, 2.8, 9.3, 1.1, 2.3, 0.7],
            }
        ],
        "diagnosis": {
            "method": {"min_explained_variance": 0.15, "measurement_noise_std": 0.029},
            "missing": missing,
            "missing_effects": [
                {
                    "name": "rotational_drag",
                    "explained_variance": 0.51,
                    "explained_variance_per_axis": {"x": 0.56, "y": 0.97, "z": 0.0},
                    "ambiguous_with": [],
                }
            ],
            "fit_command": "omavctl fit 'my log.bag' --effects rotational_drag"
            if missing
            else None,
            "unexplained": [],
        },
    }


BEFORE = _tree(
    {"x": 0.088, "y": 0.294, "z": 0.0465}, {"x": 0.85, "y": 0.41, "z": 0.97}, ["rotational_drag"]
)
AFTER = _tree(
    {"x": 0.060, "y": 0.114, "z": 0.0581},
    {"x": 0.95, "y": 0.90, "z": 0.95},
    [],
    {"rotational_drag": {"D": [0.046, 0.049, 0.036], "D_stderr": [0.0065, 0.0031, 0.079]}},
)  # fmt: skip


def test_missing_effect_first_with_its_command():
    lines = verdict(BEFORE)
    assert lines[0].key == "missing"
    assert lines[0].text.startswith("Missing: rotational_drag — it explains 51 %")
    assert "(the axes weighted alike: x 56 %, y 97 %)" in lines[0].text
    assert lines[0].command == "omavctl fit 'my log.bag' --effects rotational_drag"
    assert (
        lines[0].plain().endswith("Add it with: omavctl fit 'my log.bag' --effects rotational_drag")
    )


def test_nothing_missing_says_so():
    assert verdict(AFTER)[0].text.startswith("Nothing missing: no registered effect explains 15 %")


def test_where_it_fails_names_what_the_vehicle_did():
    fails = next(line for line in verdict(BEFORE) if line.key == "fails")
    assert "1.1–2.0 s of f.bag" in fails.text and "y error 0.56" in fails.text
    assert "pitching at 0.69 rad/s" in fails.text and "tilted" in fails.text
    level = activity({"attitude_deg": [1, 2, 0], "rate": [0.01, 0.02, 0.01], "u": [0, 0, 14.7]})
    assert level == "near level, barely rotating, thrust 1.50 g"
    slight = activity({"attitude_deg": [4, 6, 0], "rate": [0.01, 0.02, 0.01]})
    assert slight == "slightly tilted (|roll| 4°, |pitch| 6°), barely rotating"
    assert activity({"attitude_deg": [20, 6, 0]}).startswith("tilted (|roll| 20°, |pitch| 6°)")


def test_a_log_without_attitude_says_the_tilt_is_unknown_not_level():
    """An IMU-only log (Crazyflie, Betaflight) read "while near level, rolling at
    1.52 rad/s": its attitude series is zeros. evaluate gives such a segment no
    attitude, and the verdict says the tilt is unknown."""
    import numpy as np

    from omavctl.diagnose.evaluate import _failures

    n = 400
    t = np.arange(n) * 0.01
    err = np.zeros((n, 3))
    err[100:150, 0] = 5.0
    series = {
        "t": t,
        "log": np.zeros(n, dtype=int),
        "measured": err,
        "nominal": np.zeros((n, 3)),
        "mean_0": np.zeros((n, 3)),
        "attitude": np.zeros((n, 3)),
        "omega": np.tile([1.52, 0.1, 0.0], (n, 1)),
        "u": np.zeros((n, 6)),
    }
    seg = _failures(series, {}, ["log15"], 0.01, True, [False])["worst_segments"][0]
    assert seg["attitude_deg"] is None
    assert activity(seg) == "rolling at 1.52 rad/s, tilt unknown (no attitude in the log)"
    logged = _failures(series, {}, ["log15"], 0.01, True, [True])["worst_segments"][0]
    assert activity(logged) == "near level, rolling at 1.52 rad/s"


def test_overconfidence_below_80_percent_and_trust_above():
    unc = next(line for line in verdict(BEFORE) if line.key == "uncertainty")
    assert unc.text.startswith("Uncertainty overconfident on y: only y 41 % of the samples")
    trusted = next(line for line in verdict(AFTER) if line.key == "uncertainty")
    assert trusted.text.startswith("Uncertainty can be trusted")
    narrow = copy.deepcopy(AFTER)
    narrow["metrics"]["model"]["coverage_2sigma"]["z"] = 0.86
    line = next(ln.text for ln in verdict(narrow) if ln.key == "uncertainty")
    assert line.startswith("Uncertainty a little narrow on z: z 86 % of the samples lie within")
    # the newer key name 'coverage' is read as well
    newer = copy.deepcopy(AFTER)
    newer["metrics"]["model"]["coverage"] = newer["metrics"]["model"].pop("coverage_2sigma")
    newer["metrics"]["model"]["coverage"]["z"] = 0.5
    assert "overconfident on z" in next(ln.text for ln in verdict(newer) if ln.key == "uncertainty")


def test_a_band_that_holds_every_sample_is_called_cautious():
    """A band holding 100 % of the held-out samples got "can be trusted" and nothing
    more: wider than needed is accepted (issue 26), but the user should know."""
    tree = copy.deepcopy(AFTER)
    tree["metrics"]["model"]["coverage_2sigma"]["z"] = 0.9961
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line == (
        "Uncertainty can be trusted: within 2σ x 95 %, y 90 %, z 100 % (95 % expected); "
        "the band is cautious on z (100 % inside): wider than needed."
    )
    tree["metrics"]["model"]["coverage_2sigma"]["z"] = 0.994  # 99 %: nothing more said
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line.endswith("z 99 % (95 % expected).")
    # a band with the predicted σ more than twice the error already says it is cautious
    tree["metrics"]["model"]["coverage_2sigma"]["z"] = 1.0
    tree["metrics"]["model"]["mean_std"]["z"] = 0.5
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line.startswith("Uncertainty cautious on z: the band is wider than needed")
    assert line.count("cautious") == 1  # said once, not again as '(100 % inside)'


def test_a_band_a_hundred_times_the_error_is_called_too_wide_to_use():
    """A new user's Crazyflie window judged on another log (session 34): mean predicted
    σ 1314 and 1347 rad/s² against errors of 11.5 and 9.9 (the flight went nine training
    ranges beyond the model's yaw rate) read "Uncertainty cautious on x, y: ... the
    predicted σ more than twice the actual error"."""
    tree = copy.deepcopy(AFTER)
    model = tree["metrics"]["model"]
    model["coverage_2sigma"] = {"x": 1.0, "y": 1.0, "z": 0.984}
    model["mean_std"] = {"x": 1313.9, "y": 1347.0, "z": 46.7}
    model["rmse"] = {"x": 11.45, "y": 9.93, "z": 10.46}
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line == (
        "Uncertainty too wide to use on x, y: the predicted σ is x 115x, y 136x the actual "
        "error (within 2σ: x 100 %, y 100 %, z 98 %); its error bars say little here."
    )
    model["mean_std"] = {"x": 91.6, "y": 1.0, "z": 1.0}  # 8x: cautious, as before
    line = next(ln.text for ln in verdict(tree) if ln.key == "uncertainty")
    assert line.startswith("Uncertainty cautious on x: the band is wider than needed")


def test_before_after_per_axis_with_the_reason_for_the_worse_axis():
    lines = change_lines(scores_of_files([(BEFORE, "before.json"), (AFTER, "after.json")]))
    head = lines[0].text
    assert head.startswith(
        "With rotational_drag added (before.json → after.json): the model error falls by"
    )
    assert "x −31.8 %" in head and "y −61.2 %" in head and "z +24.9 %" in head
    assert len(lines) == 2 and lines[1].text.startswith("Axis z got worse (+24.9 %)")
    reason = lines[1].text
    assert "rotational_drag explained 0 % of the z error" in reason
    assert "D_z = 0.036 ± 0.079 is indistinguishable from 0" in reason
    assert "within 2.0× the measurement noise" in reason


def test_a_worse_axis_says_the_share_was_of_the_earlier_models_error():
    """Eyes3 (Crazyflie log15 -> log10): the first verdict claimed motor_lag learned by
    the GP ("it removes 50 % of the squared physics-only error"); after adding it, the
    change line said "motor_lag explained 0 % of the x error", which read as a
    contradiction: the 0 % is of the earlier model's remaining error, which its GP had
    already taken."""
    before = copy.deepcopy(BEFORE)
    before["diagnosis"]["learned_claims"] = ["rotational_drag"]
    lines = change_lines(scores_of_files([(before, "before.json"), (AFTER, "after.json")]))
    assert (
        "rotational_drag explained 0 % of the z error the earlier model left (its GP had "
        "learned it); "
    ) in lines[1].text


def test_a_worse_axis_with_no_reason_in_the_files_claims_none():
    """An added effect whose parameter on the worse axis is well determined and that
    explained a share of its error: the files do not say why the axis got worse, and
    the line must not invent that the effect does not act there."""
    before = copy.deepcopy(BEFORE)
    before["diagnosis"]["missing_effects"][0]["explained_variance_per_axis"]["z"] = 0.2
    after = copy.deepcopy(AFTER)
    after["models"][0]["effects"]["rotational_drag"]["D_stderr"][2] = 0.001
    before["diagnosis"]["method"]["measurement_noise_std"] = 0.001
    lines = change_lines(scores_of_files([(before, "before.json"), (after, "after.json")]))
    assert lines[1].text == (
        "Axis z got worse (+24.9 %): the files do not say why: the added effect and the "
        "refitted GP changed together."
    )


def test_a_worse_axis_says_whether_the_physics_or_the_gp_part_rose():
    """The real Crazyflie halves (docs/real-motors.md): with motor_lag added the yaw
    error rose 1.46 -> 2.07 rad/s^2, the physics-only error as much (1.51 -> 2.24); the
    line blamed the refitted GP. It now says which factor of model = physics x (model /
    physics) rose, from the physics-only error of both files."""

    def worse(physics0: float, physics1: float, model1: float = 0.0581) -> str:
        before, after = copy.deepcopy(BEFORE), copy.deepcopy(AFTER)
        before["diagnosis"]["method"]["measurement_noise_std"] = 0.001
        before["metrics"]["effects"] = {"rmse": {"x": 0.2, "y": 0.5, "z": physics0}}
        after["metrics"]["effects"] = {"rmse": {"x": 0.1, "y": 0.2, "z": physics1}}
        after["metrics"]["model"]["rmse"]["z"] = model1
        scores = scores_of_files([(before, "before.json"), (after, "after.json")])
        return change_lines(scores)[-1].text

    assert worse(0.0481, 0.0714) == (  # 0.0465 -> 0.0581 (+24.9 %), physics +48.4 %
        "Axis z got worse (+24.9 %): rotational_drag explained 0 % of the z error the "
        "earlier model left; its "
        "fitted D_z = 0.036 ± 0.079 is indistinguishable from 0; the physics-only error on z "
        "rose 0.0481 → 0.0714 rad/s² (+48.4 %) and the model's error relative to it went "
        "0.97× → 0.81×: the refitted effects made z worse, not the GP."
    )
    gp = worse(0.0481, 0.0470)
    assert gp.endswith(
        "the physics-only error on z fell 0.0481 → 0.047 rad/s² (−2.3 %) and the model's "
        "error relative to it went 0.97× → 1.24×: the refitted GP made z worse, not the "
        "effects."
    )
    both = worse(0.0481, 0.0538)  # +11.9 % of the +24.9 %
    assert both.endswith("both the refitted effects and the GP made z worse.")


def test_flags_and_excluded_spans_when_present():
    tree = copy.deepcopy(AFTER)
    tree["flags"] = [
        {"code": "worse_than_physics", "axis": "z", "message": "the GP is worse than physics"},
        {"code": "overconfident", "axis": "y", "message": "said by the uncertainty line"},
    ]
    tree["excluded_spans"] = [
        {"start": 3.0, "end": 3.5, "reason": "out of control"},
        {"start": 7.0, "end": 7.25, "reason": "out of control"},
    ]
    lines = verdict(tree)
    texts = {line.key: line.text for line in lines}
    assert texts["worse"] == "axis z: the GP is worse than physics"
    assert texts["excluded"] == "Kept out of the metrics: 2 span(s), 0.8 s (out of control)."
    assert sum(line.key in ("flag", "worse") for line in lines) == 1
    # a model that does not help is said before "nothing missing" (a new user read the
    # all-clear first on a model no better than predicting zero)
    assert [ln.key for ln in lines[:2]] == ["worse", "missing"]
    tree["flags"].append({"code": "training_data", "message": "the model's own training log"})
    assert [ln.key for ln in verdict(tree)[:3]] == ["training", "worse", "missing"]


def test_an_effect_below_the_noise_floor_is_named_not_claimed():
    """Everything of a missing effect but the noise floor (the diagnosis' ``below_noise``):
    the verdict says which effect, how much it would explain, why it is not claimed and
    the fit that tests it."""
    tree = copy.deepcopy(AFTER)
    tree["diagnosis"]["method"]["min_contribution_rms"] = 0.087
    tree["diagnosis"]["below_noise"] = "rotational_drag"
    tree["diagnosis"]["test_command"] = "omavctl fit f.bag --effects rotational_drag"
    entry = tree["diagnosis"]["missing_effects"][0]
    entry.update(explained_variance=0.269, contribution_rms=0.042, above_noise=False)
    line = verdict(tree)[0]
    assert line.key == "missing" and line.command == "omavctl fit f.bag --effects rotational_drag"
    assert line.text == (
        "Nothing claimed as missing: rotational_drag would explain 27 % of the model's "
        "remaining error on held-out data, but its part, 0.042 rad/s² RMS, is above the "
        "log's noise (0.029) and below the 0.087 a claim needs (three times it). To test "
        "it, fit with it and compare both models on a flight neither saw."
    )
    tree["diagnosis"]["below_noise"] = None  # older files, or nothing near: as before
    line = verdict(tree)[0]
    assert line.text.startswith("Nothing missing: no registered effect explains")
    assert line.command is None


def test_the_diagnosis_holds_back_an_effect_only_by_the_noise_floor_when_above_the_noise():
    from omavctl.diagnose.diagnosis import _below_noise
    from omavctl.diagnose.scoring import EffectScore

    def score(name, rms, **kw):
        base = dict(
            name=name, explained_variance=0.27, explained_per_axis={}, parameters={},
            units={}, t_value=34.9, significant=True, plausible=True,
            contribution=np.zeros((1, 3)), contribution_rms=rms, above_noise=False,
        )  # fmt: skip
        return EffectScore(**{**base, **kw})

    noise = 0.029
    assert _below_noise([score("a", 0.042)], noise) == "a"
    assert _below_noise([score("a", 0.023), score("b", 0.04)], noise) == "b"  # within noise
    assert _below_noise([score("a", 0.042, plausible=False)], noise) is None
    assert _below_noise([score("a", 0.042, refit_explained_variance=-0.1)], noise) is None
    assert _below_noise([score("a", 0.042, explained_variance=0.1)], noise) is None
    assert _below_noise([score("a", 0.2, above_noise=True)], noise) is None  # claimed instead


def test_report_verdict_names_the_files():
    lines = report_verdict([(BEFORE, "before.json"), (AFTER, "after.json")])
    assert [line.who for line in lines[:3]] == [
        "before.json",
        "before.json → after.json",
        "before.json → after.json",
    ]
    assert "(after.json)" not in lines[1].text  # the line already says which files
    assert lines[3].who == "after.json" and lines[3].key == "missing"


def test_empty_tree_does_not_fail():
    assert verdict({})[0].text.startswith("Nothing missing")
    assert change_lines(scores_of_files([({}, "a"), ({}, "b")])) == []


def test_parameter_at_a_bound_is_not_shown_as_plus_minus_zero():
    lines = _param_lines({"tau": [0.2], "tau_stderr": [0.0]}, {"tau": "s"}, False)
    assert lines == ("tau = 0.2 s (at its bound: no std. error)",)
    lines = _param_lines({"D": [0.04, 0.0, 0.0], "D_stderr": [0.004, 0.0, 0.0]}, {}, False)
    assert lines[0] == "D_x = 0.04 ± 0.004"
    assert lines[1] == "D_y = 0 (at its bound: no std. error)"
    # a rounding-sized spread is no standard error either
    lines = _param_lines({"tau_d": [-0.02], "tau_d_stderr": [1e-17]}, {"tau_d": "s"}, False)
    assert lines == ("tau_d = -0.02 s (at its bound: no std. error)",)


def test_activity_speaks_of_thrust_in_g_only_when_the_force_is_in_newtons():
    from omavctl.diagnose.verdict import activity

    seg = {"attitude_deg": [1.0, 1.0, 0.0], "rate": [0.0, 0.0, 0.0], "u": [0.0, 0.0, 14.7]}
    assert activity(seg).endswith("thrust 1.50 g")
    # a normalised throttle (PX4 thrust 0..1): its u is not an acceleration
    assert "thrust" not in activity({**seg, "thrust_known": False})


def test_an_input_constant_in_training_is_named_not_measured_in_its_zero_range():
    """A normalised thrust has no x or y part in training: a log where it does (a model
    of another vehicle, or another command mapping) is outside the envelope by a
    distance no range measures. Named as such, with finite numbers only."""
    from omavctl.diagnose.metrics import envelope_flags, training_envelope

    rng = np.random.default_rng(0)
    train = np.column_stack([np.zeros(50), rng.uniform(-1.0, 1.0, 50)])
    flight = np.column_stack([np.r_[np.zeros(30), np.full(10, 0.4)], rng.uniform(-1, 1, 40)])
    flight[:5, 1] = 3.0  # 1 training range beyond on the varied input
    err, std = np.zeros((40, 3)), np.ones((40, 3))
    env = training_envelope(train, flight, ["fx/m", "u"], err, std)
    json.dumps(env, allow_nan=False)
    assert env["unvaried"] == {"fx/m": pytest.approx(0.4)}
    lo, hi = train[:, 1].min(), train[:, 1].max()
    assert env["beyond"] == {"u": pytest.approx((3.0 - hi) / (hi - lo))}
    assert env["outside_fraction"] == pytest.approx(15 / 40)
    tree = copy.deepcopy(AFTER)
    tree["envelope"], tree["flags"] = env, envelope_flags(env)  # as evaluate writes them
    line = next(ln.text for ln in verdict(tree) if ln.key == "envelope")
    assert line.startswith("38 % of the samples lie outside the inputs the model was trained on")
    assert "furthest, in training ranges beyond them: u 1." in line
    assert "not varied in training, varied here: fx/m" in line
    assert "band still covers" not in line  # no comfort from a band that far out
    assert envelope_flags(env) == [
        {
            "code": "far_outside_training",
            "axis": None,
            "value": None,
            "message": "The log varies fx/m, constant in training: is the model this "
            "vehicle's, and are the log's units and frame the model's?",
        }
    ]
    env["unvaried"] = {}
    assert envelope_flags(env) == []  # 1 training range beyond: an ordinary excursion
    env["beyond"] = {"u": 12.0}
    assert envelope_flags(env)[0]["message"].startswith(
        "The log goes 12 training ranges beyond the model's inputs (u): is the model"
    )


def test_a_named_com_offset_says_what_else_looks_like_it():
    """A CoM offset is what a thrust spread and the rotors' interference also look like
    at small tilts: the verdict that names it says so; drag has no such look-alike. It
    names the effect: after a long "Also: ..." clause (eyes3) "its" read as the last
    effect named there."""
    tree = copy.deepcopy(BEFORE)
    tree["diagnosis"]["missing"] = ["com_offset"]
    tree["diagnosis"]["missing_effects"][0]["name"] = "com_offset"
    text = verdict(tree)[0].text
    assert text.startswith("Missing: com_offset — it explains 51 %")
    assert text.endswith(
        "A residual of com_offset's shape is also left by a thrust spread between the rotors "
        "and the "
        "rotors' interference at small tilts (rotor_interference), which also shift where "
        "the thrust acts."
    )
    assert "also left by" not in verdict(BEFORE)[0].text


def test_a_worse_axis_whose_fitted_parameter_disagrees_with_the_evaluated_log_says_so():
    """The fit flight fixed D_z at 0.036 ± 0.005; the evaluated log gives 0.002 ± 0.001:
    the estimate is the reason the axis got worse, and the line says what to do."""
    before = copy.deepcopy(BEFORE)
    before["diagnosis"]["missing_effects"][0]["explained_variance_per_axis"]["z"] = 0.2
    before["diagnosis"]["missing_effects"][0]["parameters"] = {
        "D": [0.05, 0.05, 0.002],
        "D_stderr": [0.002, 0.002, 0.001],
    }
    after = copy.deepcopy(AFTER)
    after["models"][0]["effects"]["rotational_drag"]["D_stderr"][2] = 0.005
    lines = change_lines(scores_of_files([(before, "before.json"), (after, "after.json")]))
    assert lines[1].text == (
        "Axis z got worse (+24.9 %): D_z is 0.036 ± 0.005 as fitted on the fit flight but "
        "0.002 ± 0.001 from the evaluated log, 6.7 standard errors apart: the fit flight did "
        "not pin it down (fit on both logs, or plan a flight with plan --objective effects)."
    )


def test_three_files_show_every_step_not_only_first_to_last():
    """A step that made an axis worse is said even when first to last improved it."""
    middle = copy.deepcopy(AFTER)
    middle["metrics"]["model"]["rmse"] = {"x": 0.060, "y": 0.114, "z": 0.0406}
    last = copy.deepcopy(AFTER)
    last["metrics"]["model"]["rmse"] = {"x": 0.058, "y": 0.110, "z": 0.0451}
    lines = report_verdict([(BEFORE, "e1.json"), (middle, "e2.json"), (last, "e3.json")])
    changes = [(ln.who, ln.text) for ln in lines if ln.key == "change"]
    whos = [w for w, _ in changes]
    assert whos[0] == "e1.json → e2.json" and whos[-1] == "e1.json → e3.json"
    assert ("e2.json → e3.json", "Axis z got worse (+11.1 %): ") in [
        (w, t[: len("Axis z got worse (+11.1 %): ")]) for w, t in changes
    ]
    assert not any(w == "e1.json → e3.json" and t.startswith("Axis z") for w, t in changes)
    # each file but the last says first what it lacked (why the next one was fitted)
    assert [ln.who for ln in lines if ln.key == "missing"] == ["e1.json", "e2.json", "e3.json"]


def test_report_verdict_keeps_what_a_file_lacked_behind_a_leading_warning():
    """A file whose verdict leads with a warning (the model no better than predicting
    none) still says what it lacked: that is why the next model was fitted (a new
    user's Crazyflie report showed the warning and dropped 'Missing: motor_lag')."""
    before = copy.deepcopy(BEFORE)
    before["flags"] = [
        {
            "code": "no_better_than_zero",
            "axis": "y",
            "message": "axis y: the model's error (45.8 rad/s² RMS) is not below the angular "
            "acceleration itself (43.8): predicting none would do as well",
        }
    ]
    lines = report_verdict([(before, "a.json"), (AFTER, "b.json")])
    mine = [ln for ln in lines if ln.who == "a.json"]
    assert "predicting none would do as well" in mine[0].text
    assert [ln.key for ln in mine].count("missing") == 1
    (missing,) = [ln for ln in mine if ln.key == "missing"]
    assert missing.text.startswith("Missing: rotational_drag")
    # a file whose first line already is the missing one is not repeated
    plain = [ln for ln in report_verdict([(BEFORE, "a.json"), (AFTER, "b.json")])]
    assert [ln.key for ln in plain if ln.who == "a.json"] == ["missing"]


def test_report_verdict_keeps_an_earlier_files_effect_held_back_on_one_axis():
    """A new user's terminal said "Not claimed although it explains 28 % of the y error
    ...: rotational_drag" with its test command; the report of both evaluations dropped
    it, the only word left on a drag the vehicle had. An earlier file keeps that line,
    unless the next file's model holds the effect."""
    before = copy.deepcopy(BEFORE)
    before["diagnosis"]["missing_effects"].append(
        {
            "name": "command_delay",
            "explained_variance": 0.13,
            "explained_variance_per_axis": {"y": 0.34},
        }
    )
    before["diagnosis"]["effect_commands"] = {"command_delay": "omavctl fit f.bag --effects c"}
    (terminal,) = [ln for ln in verdict(before) if ln.key == "axis"]
    lines = report_verdict([(before, "a.json"), (AFTER, "b.json")])
    (kept,) = [ln for ln in lines if ln.key == "axis"]
    assert (kept.who, kept.text, kept.command) == ("a.json", terminal.text, terminal.command)
    assert kept.text.startswith("Not claimed although it explains 34 % of the y error")
    after = copy.deepcopy(AFTER)
    after["models"][0]["effects"]["command_delay"] = {"tau_d": [0.03]}
    lines = report_verdict([(before, "a.json"), (after, "b.json")])
    assert not [ln for ln in lines if ln.key == "axis" and ln.who == "a.json"]


def test_a_sum_over_the_axes_that_does_not_move_is_said_unchanged():
    """A new user read "the model error rises by 0.0 % (sum over axes) — x +4.8 %, y
    −16.1 %, z +11.2 %": a sum within 0.1 % is unchanged, and the axes that rose are
    named as when the sum falls."""
    after = copy.deepcopy(AFTER)
    before = copy.deepcopy(BEFORE)
    before["metrics"]["model"]["rmse"] = {"x": 0.1, "y": 0.2, "z": 0.1}
    after["metrics"]["model"]["rmse"] = {"x": 0.1048, "y": 0.184, "z": 0.1112}
    lines = report_verdict([(before, "a.json"), (after, "b.json")])
    (change,) = [ln for ln in lines if ln.key == "change" and ln.text.startswith("With ")]
    assert change.text.startswith(
        "With rotational_drag added: the model error summed over the axes is unchanged "
        "(within 0.1 %), but rises on x and z — x +4.8 %, y −8.0 %, z +11.2 %"
    ), change.text


def test_the_summary_table_gives_r2_against_the_measured_signal_too():
    """R² against the nominal model can read 0.81 on an axis where the model does no
    better than predicting no acceleration (the nominal model far worse than that): the
    table adds R² against the measured acceleration, 1 - (RMSE / RMS)²."""
    from omavctl.report.overview import _metrics_table

    rmse = {"x": 19.5, "y": 45.8, "z": 1.9}
    tree = {
        "metrics": {
            "zero": {"rmse": {"x": 37.1, "y": 43.8, "z": 1.46}},
            "nominal": {"rmse": {"x": 97.1, "y": 86.1, "z": 2.72}, "r2": {a: 0.0 for a in "xyz"}},
            "model": {"rmse": rmse, "r2": {"x": 0.96, "y": 0.81, "z": 0.51}},
        }
    }
    table = _metrics_table(tree)
    (row,) = [r for r in table.rows if str(r[0]).startswith("R² (share of the measured")]
    model = row[-3:]
    assert [float(str(v)) for v in model] == pytest.approx(
        [1 - (19.5 / 37.1) ** 2, 1 - (45.8 / 43.8) ** 2, 1 - (1.9 / 1.46) ** 2], rel=1e-3
    )
    assert float(str(model[1])) < 0  # no better than predicting none: below zero


def test_a_claim_of_the_joint_selection_quotes_its_share_of_the_physics_only_error():
    """A report draw read 'Missing: com_offset — it explains -3 % of the model's
    remaining error': the claim came from the joint selection on the physics-only
    error (85 %), the model's own share is what its GP left. The verdict now quotes
    the claim's share and says the GP absorbed the effect."""
    tree = copy.deepcopy(BEFORE)
    diag = tree["diagnosis"]
    diag["missing"] = ["rotational_drag"]
    diag["missing_effects"][0]["explained_variance"] = -0.03
    diag["joint_steps"] = [{"name": "rotational_drag", "share": 0.853, "share_of_total": 0.853}]
    (line,) = [ln for ln in verdict(tree) if ln.key == "missing"]
    assert line.text.startswith(
        "Missing: rotational_drag — estimated from the fit flight as fit --effects would, it "
        "removes 85 % of the squared physics-only error on held-out data (the model's GP has "
        "absorbed it: it explains none of the model's remaining error)."
    )
    # a claim of the ranking keeps its share of the model's remaining error
    (line,) = [ln for ln in verdict(BEFORE) if ln.key == "missing"]
    assert line.text.startswith("Missing: rotational_drag — it explains 51 % of the model's")


def test_the_coefficients_the_model_predicts_with_are_no_parameter():
    # a learned com_offset in the ranking of the nominal residual (Crazyflie log16,
    # session 19) carries theta_fitted: it was printed as 'theta_fitted_x = 0.0001226'
    estimate = {
        "r": [0.001, 0.0003, 0.0],
        "r_stderr": [0.0022, 0.002, 0.0],
        "stderr_method": "hac",
        "theta_fitted": [0.0001226, 2.8e-05, 0.0],
    }
    lines = _param_lines(estimate, {"r": "m"}, False, "com_offset")
    assert [str(x).split(" =")[0] for x in lines] == ["r_x", "r_y", "r_z"]


def test_a_scale_is_indistinguishable_from_1_not_from_0():
    """A new user's report: "its fitted scale_z = 2.45 ± 2.9 is indistinguishable from 0"
    beside fit's interval [0.716, ∞): a scale is absent at 1."""
    scale = {"inertia_error": {"scale": [1.3, 1.2, 2.45], "scale_stderr": [0.01, 0.01, 2.9]}}
    after = _tree({"x": 0.060, "y": 0.114, "z": 0.0581}, {"x": 0.95, "y": 0.90, "z": 0.95},
                  [], scale)  # fmt: skip
    before = copy.deepcopy(BEFORE)
    before["diagnosis"]["missing_effects"][0]["name"] = "inertia_error"
    lines = change_lines(scores_of_files([(before, "before.json"), (after, "after.json")]))
    reason = next(ln.text for ln in lines if ln.text.startswith("Axis z got worse"))
    assert "scale_z = 2.45 ± 2.9 is indistinguishable from 1 (absent)" in reason
    assert "from 0" not in reason
