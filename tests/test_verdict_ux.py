"""What a new user reads in the verdict refers only to what they can see, and every
effect it names comes with the command that adds or tests it."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from omavctl.diagnose.claim_text import effect_to_test
from omavctl.diagnose.verdict import verdict
from omavctl.report.summary import render_evaluation


def _nothing_missing() -> dict[str, Any]:
    """An evaluation tree where no registered effect is missing."""
    return {
        "models": [{"name": "m.npz", "effects": {}}],
        "metrics": {"model": {"rmse": {"x": 0.1, "y": 0.2, "z": 0.1}}},
        "diagnosis": {
            "method": {"min_explained_variance": 0.15, "measurement_noise_std": 0.03},
            "missing": [],
            "missing_effects": [],
            "fit_command": None,
            "unexplained": [
                {"kind": "feature correlation", "axis": "y", "feature": "wz", "correlation": -0.47},
                {
                    "kind": "spectral peak",
                    "axis": "x",
                    "frequency_hz": 1.25,
                    "power_ratio": 30.0,
                    "power_share": 0.22,
                },
                {
                    "kind": "feature correlation",
                    "axis": "z",
                    "feature": "roll",
                    "correlation": 0.31,
                },
            ],
        },
    }


def _terminal(tree: dict[str, Any]) -> str:
    import io

    from rich.console import Console

    con = Console(width=400, record=True, file=io.StringIO())
    render_evaluation(con, tree, {})
    return con.export_text()


def test_the_terminal_verdict_shows_the_structure_it_refers_to():
    """The verdict said "(see Diagnosis)" in a terminal that has no Diagnosis: it says
    what the structure is instead."""
    tree = _nothing_missing()
    text = verdict(tree)[0].text
    assert "see Diagnosis" not in text
    assert text.endswith(
        "Some structure remains that no registered effect explains: the y error "
        "correlates with wz (r = -0.47); the x error has a spectral peak at 1.2 Hz, 22 % "
        "of its power; 1 more in the evaluation JSON (diagnosis.unexplained)."
    )
    shown = _terminal(tree)
    assert "correlates with wz (r = -0.47)" in shown and "Diagnosis" not in shown
    clean = copy.deepcopy(tree)
    clean["diagnosis"]["unexplained"] = []
    assert "structure" not in verdict(clean)[0].text


def _absorbed() -> dict[str, Any]:
    """Nothing missing, but the nominal residual is a CoM offset the GP has absorbed
    (the issue's case: physics-only error 2.76 rad/s², the model's 0.045)."""
    tree = _nothing_missing()
    diag = tree["diagnosis"]
    diag["unexplained"] = []
    diag["missing_effects"] = [
        {"name": "com_offset", "explained_variance": 0.02, "contribution_rms": 0.004}
    ]
    diag["learned"] = [
        {
            "name": "com_offset",
            "missing": True,
            "explained_variance": 0.97,
            "contribution_rms": 2.7,
            "ambiguous_with": [],
        },
        {"name": "gyro_bias", "missing": False, "explained_variance": 0.01},
    ]
    diag["effect_commands"] = {"com_offset": "omavctl fit f.bag --effects com_offset --out m+c.npz"}
    return tree


def test_an_effect_the_gp_absorbed_comes_with_the_command_that_makes_it_physical():
    tree = _absorbed()
    learned = [ln for ln in verdict(tree) if ln.key == "learned"]
    assert len(learned) == 1
    assert learned[0].text.startswith(
        "Not modelled as physics: com_offset, which the nominal model's residual looks like "
        "(it explains 97 % of it, 2.7 rad/s² RMS; the model leaves 0.004 rad/s² RMS of it)."
    )
    assert learned[0].command == "omavctl fit f.bag --effects com_offset --out m+c.npz"
    shown = _terminal(tree)
    assert "add it with: omavctl fit f.bag --effects com_offset --out m+c.npz" in shown
    # a look-alike of an effect the model already holds is not claimed as learned
    alike = copy.deepcopy(tree)
    alike["models"][0]["effects"] = {"rotor_interference": {}}
    alike["diagnosis"]["learned"][0]["ambiguous_with"] = ["rotor_interference"]
    assert not [ln for ln in verdict(alike) if ln.key == "learned"]
    # and a named missing effect is the next step: no second command
    named = copy.deepcopy(tree)
    named["diagnosis"]["missing"] = ["com_offset"]
    assert not [ln for ln in verdict(named) if ln.key == "learned"]


def test_the_json_and_report_carry_the_learned_effects_command():
    from omavctl.report.diagnosis import diagnosis_section
    from omavctl.report.document import Code
    from omavctl.report.summary import evaluation_json

    tree = _absorbed()
    out = evaluation_json(tree, {})
    assert out["fit_command"] is None  # a script's "what is missing" stays as it was
    assert out["effect_commands"] == tree["diagnosis"]["effect_commands"]
    assert any(v["key"] == "learned" and v["command"] for v in out["verdict"])
    codes = [b.text for b in diagnosis_section(tree, 0, "eval.json") if isinstance(b, Code)]
    assert codes == ["omavctl fit f.bag --effects com_offset --out m+c.npz"]


def test_an_effect_held_back_by_the_refit_test_says_its_number_and_the_test():
    """ "inertia was rejected by a refit test whose −1.60 appears in no table": the
    verdict says the number and the command, the report's ranking shows it."""
    from omavctl.report.diagnosis import _ranking_table

    tree = _nothing_missing()
    diag = tree["diagnosis"]
    diag["unexplained"] = []
    entry = {
        "name": "inertia_error",
        "explained_variance": 0.41,
        "refit_explained_variance": -1.60,
        "significant": True,
        "plausible": True,
        "above_noise": True,
        "missing": False,
    }
    diag["missing_effects"] = [entry]
    diag["refit_rejected"] = "inertia_error"
    diag["effect_commands"] = {"inertia_error": "omavctl fit f.bag --effects inertia_error"}
    first = verdict(tree)[0]
    assert first.text.startswith(
        "Nothing claimed as missing: inertia_error would explain 41 % of the model's "
        "remaining error on held-out data with parameters fitted to that error, but with the "
        "parameters fit --effects would estimate from the model's training points it "
        "explains -160 % (the error would grow): not claimed."
    )
    assert first.command == "omavctl fit f.bag --effects inertia_error"
    table = _ranking_table([entry], False, "missing")
    col = table.columns.index("explained as fit --effects would fit it")
    assert table.rows[0][col] == "-160.0 %"


def test_the_refit_test_picks_the_effect_only_it_held_back():
    from omavctl.diagnose.diagnosis import _refit_rejected
    from omavctl.diagnose.scoring import EffectScore

    def score(name, ev, refit, significant=True):
        return EffectScore(
            name, ev, {}, {}, {}, 9.0 if significant else 1.0, significant, True,
            np.zeros((1, 3)), 1.0, True, refit,
        )  # fmt: skip

    assert _refit_rejected([score("a", 0.5, 0.1), score("b", 0.4, -1.6)]) == "b"
    assert _refit_rejected([score("a", 0.5, None), score("b", 0.4, -1.6, False)]) is None


def _pair(fall: float, same_flight: bool = True) -> list[tuple[dict[str, Any], str]]:
    """Two evaluation files: the first model's diagnosis claims nothing missing (a
    30 ms delay it scored below its thresholds); the second adds command_delay and its
    error falls by ``fall`` (sum over axes)."""
    before = _nothing_missing()
    before["diagnosis"]["unexplained"] = []
    before["diagnosis"]["method"].update({"min_t_value": 4.0, "min_contribution_rms": 0.09})
    before["diagnosis"]["missing_effects"] = [
        {
            "name": "command_delay",
            "explained_variance": 0.10,
            "t_value": 2.1,
            "contribution_rms": 0.05,
            "plausible": True,
            "refit_explained_variance": 0.08,
        }
    ]
    before["metrics"]["nominal"] = {"rmse": {"x": 0.9, "y": 1.6, "z": 0.16}}
    after = copy.deepcopy(before)
    after["models"][0]["effects"] = {"command_delay": {"delay": [0.03]}}
    after["metrics"]["model"]["rmse"] = {
        a: v * (1 - fall) for a, v in before["metrics"]["model"]["rmse"].items()
    }
    if not same_flight:
        after["metrics"]["nominal"]["rmse"]["x"] = 0.8
    return [(before, "eval.json"), (after, "eval-delay.json")]


def test_nothing_missing_is_never_said_above_a_measured_fall_with_an_effect_added():
    from omavctl.diagnose.change import report_verdict

    lines = report_verdict(_pair(0.388))
    texts = [ln.text for ln in lines]
    assert not any(t.startswith("Nothing") for t in texts[:-4]), texts
    assert lines[0].who == "eval.json" and lines[0].text == (
        "Missing: command_delay, measured — with it added (eval-delay.json) the model error "
        "on the same flight falls by 38.8 % (sum over axes), although this model's "
        "diagnosis claimed nothing missing (command_delay: it explained 10 % of the "
        "held-out error (15 % needed); t value 2.1 (4 needed); its part 0.05 rad/s² RMS, "
        "below the claim floor 0.09)."
    )
    assert "falls by 38.8 %" in lines[1].text
    # a small fall, or another flight, does not overrule the diagnosis
    assert report_verdict(_pair(0.03))[0].text.startswith("Nothing missing")
    assert report_verdict(_pair(0.388, same_flight=False))[0].text.startswith("Nothing missing")


def test_one_file_with_two_models_is_reconciled_in_the_terminal_and_report_alike():
    from omavctl.diagnose.change import report_verdict
    from omavctl.report.summary import evaluation_json

    (before, _), (after, _) = _pair(0.388)
    tree = copy.deepcopy(before)
    tree["models"] = [before["models"][0], {**after["models"][0], "name": "m2.npz"}]
    tree["metrics_by_model"] = [before["metrics"], after["metrics"]]
    report = [ln.text for ln in report_verdict([(tree, "eval.json")])]
    terminal = [v["text"] for v in evaluation_json(tree, {})["verdict"]]
    assert report == terminal
    assert terminal[0].startswith("Missing: command_delay, measured — with it added (m2.npz)")
    assert "Nothing missing" not in " ".join(terminal)


def test_an_axis_the_fit_flight_barely_excited_is_said_as_such_first():
    """ "goes 23 training ranges beyond the model's inputs: is the model this vehicle's?"
    when the fit flight simply did not yaw: the verdict says that first, and keeps the
    vehicle question for an input that is off by more than its own range here too."""
    from omavctl.diagnose.metrics import envelope_flags, training_envelope

    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 10.0, 400)
    train = np.stack([np.sin(t), 0.01 * np.sin(3 * t)], axis=1)  # wz barely moves
    flight = np.stack([np.sin(1.3 * t), 0.5 * np.sin(2 * t)], axis=1)  # wz moves 50x more
    err, std = rng.normal(0, 0.1, (400, 3)), np.full((400, 3), 0.1)
    env = training_envelope(train, flight, ["fx/m", "wz"], err, std)
    assert set(env["underexcited"]) == {"wz"}
    assert env["underexcited"]["wz"]["flight_span"] == pytest.approx(1.0, rel=0.01)
    flags = envelope_flags(env)
    assert [f["code"] for f in flags] == ["underexcited"]
    assert flags[0]["message"].startswith(
        "The fit flight barely excited wz (over 0.02 rad/s there, 1 rad/s here): this log goes 25 "
        "of those training ranges beyond the model's inputs because the fit flight did "
        "not move it"
    )
    tree = _nothing_missing()
    tree["envelope"], tree["flags"] = env, flags
    lines = verdict(tree)
    assert lines[0].key == "underexcited" and lines[1].key == "missing"
    assert not any("this vehicle's" in ln.text for ln in lines)
    # an input offset far beyond its training range, though it moves alike: the question
    shifted = np.stack([np.sin(t) + 30.0, 0.01 * np.sin(3 * t)], axis=1)
    env = training_envelope(train, shifted, ["fx/m", "wz"], err, std)
    assert env["underexcited"] == {}
    assert [f["code"] for f in envelope_flags(env)] == ["far_outside_training"]


def test_the_signature_slope_agrees_with_the_diagnosis_estimate():
    """The com_offset signature showed a flat slope (-0.000379 against one column of the
    raw regressor, x axis ±100 without unit) beside a verdict of 54 % on y: the figure
    now plots the part of the error the diagnosis' estimate explains (rad/s², the
    regressor as scored times the reported r), whose slope is 1 where the verdict says
    the effect explains the error, and near 0 where it explains nothing."""
    from omavctl.diagnose.scoring import score_effects
    from omavctl.physics.effects import get_effect
    from omavctl.report.figures import signature_figure, signature_slopes

    rng = np.random.default_rng(3)
    n = 1200
    t = np.arange(n) * 0.01
    force = np.stack([3 * np.sin(0.7 * t), 3 * np.cos(1.1 * t), 9.8 + np.sin(0.3 * t)], axis=1)
    inertia_inv = np.diag([1 / 0.08, 1 / 0.09, 1 / 0.15])
    x = np.stack([np.cross(np.eye(3)[j], force) @ inertia_inv.T for j in range(3)], axis=-1)
    r_true = np.array([0.0, -0.015, 0.0])  # only r_y: torque on x and z, not on y
    residual = x @ r_true + rng.normal(0.0, 0.02, (n, 3))
    blocks = (t // 2.0).astype(int)
    (score,) = score_effects(residual, {"com_offset": x}, blocks)
    r = np.array(score.parameters["r"])
    assert r[1] == pytest.approx(-0.015, rel=0.05)
    # the plotted quantity is the regressor times the reported estimate, in rad/s²
    assert np.allclose(score.contribution, x @ r)
    slopes = signature_slopes(score.contribution, residual)
    for i, axis in enumerate("xyz"):
        if score.explained_per_axis[axis] > 0.5:
            assert slopes[i] == pytest.approx(1.0, abs=0.05), (axis, slopes)
    assert score.explained_per_axis["x"] > 0.5 and score.explained_per_axis["z"] > 0.5
    # an error the effect does not follow has a flat signature
    assert abs(signature_slopes(score.contribution, rng.normal(0, 0.02, (n, 3)))[0]) < 0.05
    assert get_effect("com_offset").parameters[0].unit == "m"
    png = signature_figure(
        score.contribution, residual, "com_offset", score.explained_per_axis, "t"
    )
    assert png is not None and png.startswith(b"\x89PNG")


def test_a_learned_effect_already_offered_as_a_test_is_not_given_twice():
    tree = _absorbed()
    tree["diagnosis"]["below_noise"] = "com_offset"
    learned = next(ln for ln in verdict(tree) if ln.key == "learned")
    assert learned.command is None and learned.text.endswith("Its fit command is the one above.")


def test_a_learned_effect_the_second_model_adds_is_not_offered_again():
    """evaluate --model gp.npz --model gp+com_offset.npz: the first model's verdict
    offered com_offset; the second adds it and the error falls, so the verdict says
    the measurement and does not point to a command it no longer shows."""
    from omavctl.diagnose.change import report_verdict
    from omavctl.report.summary import evaluation_json

    tree = _absorbed()
    tree["diagnosis"]["below_noise"] = "com_offset"
    tree["metrics"]["nominal"] = {"rmse": {"x": 6.7, "y": 0.47, "z": 0.39}}
    second = {"rmse": {"x": 0.06, "y": 0.15, "z": 0.04}}
    tree["models"].append({"name": "gp+com_offset.npz", "effects": {"com_offset": {}}})
    tree["metrics_by_model"] = [tree["metrics"], {**tree["metrics"], "model": second}]
    texts = [v["text"] for v in evaluation_json(tree, {})["verdict"]]
    assert texts[0].startswith("Missing: com_offset, measured — with it added (gp+com_offset.npz)")
    assert not any(t.startswith("Not modelled as physics") for t in texts)
    assert [ln.text for ln in report_verdict([(tree, "eval.json")])] == texts


def ambiguous_drag() -> dict[str, Any]:
    """An evaluation naming rotational_drag missing, command_delay its look-alike."""
    tree = _nothing_missing()
    diag = tree["diagnosis"]
    diag["unexplained"] = []
    diag["missing"] = ["rotational_drag"]
    diag["missing_effects"] = [
        {"name": "rotational_drag", "explained_variance": 0.31, "ambiguous_with": ["command_delay"]}
    ]
    diag["fit_command"] = "omavctl fit f.bag --effects rotational_drag"
    diag["effect_commands"] = {
        "rotational_drag": "omavctl fit f.bag --effects rotational_drag",
        "command_delay": "omavctl fit f.bag --effects command_delay",
    }
    return tree


def test_an_effect_named_as_a_look_alike_comes_with_the_command_that_tests_it():
    """ "Ambiguous with command_delay" named an effect without a way to test it."""
    tree = ambiguous_drag()
    lines = verdict(tree)
    assert "Ambiguous with command_delay" in lines[0].text
    assert lines[1].text == (
        "To test command_delay instead (its signature looks like rotational_drag's), fit "
        "with it and compare both models on a flight neither saw."
    )
    assert lines[1].command == "omavctl fit f.bag --effects command_delay"
    assert lines[1].add_words == "Test it with"  # a test of the look-alike, not a claim
    named = {
        w.strip(".,()").removesuffix("'s") for ln in lines for w in ln.text.split() if "_" in w
    }
    commanded = {ln.subject or "rotational_drag" for ln in lines if ln.command}
    assert named <= commanded


def test_nothing_missing_is_reconciled_also_below_the_flags_said_first():
    """Flags (a model no better than physics on an axis) come before the "missing"
    sentence: it is reconciled there too."""
    from omavctl.report.summary import evaluation_json

    (before, _), (after, _) = _pair(0.388)
    tree = copy.deepcopy(before)
    tree["flags"] = [{"code": "worse_than_physics", "axis": "x", "message": "axis x: worse"}]
    tree["models"] = [before["models"][0], {**after["models"][0], "name": "m2.npz"}]
    tree["metrics_by_model"] = [before["metrics"], after["metrics"]]
    texts = [v["text"] for v in evaluation_json(tree, {})["verdict"]]
    assert texts[0] == "With m.npz: axis x: worse"  # which model it is about
    assert "Nothing missing" not in " ".join(texts)
    assert any(t.startswith("Missing: command_delay, measured") for t in texts)


def test_a_component_on_an_axis_the_effect_does_not_explain_is_not_quoted():
    """The demo's held-out figure-8 hardly turns in yaw: the drag explains x 8 %,
    y 78 % and none of z, where 'as fit would' finds D_z = 0.225 (0.164 to 0.286) for
    a true 0.03. A claim made on x and y quotes D_x and D_y and says D_z is not
    claimed, instead of an interval that misses the truth by six standard errors."""
    from omavctl.diagnose.estimate_text import estimate_sentence

    entry = {
        "units": {"D": "N m s^2"},
        "estimate": {
            "D": [0.0446, 0.0463, 0.225],
            "D_ci95": [[-0.0583, 0.148], [0.0311, 0.0615], [0.164, 0.286]],
            "D_pinned": [False, True, True],
        },
    }
    text = estimate_sentence(entry, {"x", "y"})
    assert "D_y = 0.0463 N m s^2 (95 %: 0.0311 to 0.0615 N m s^2)" in text
    assert "0.225" not in text
    assert text.endswith(" D_z not claimed: the effect explains under 5 % of the z error here.")
    assert "D_z = 0.225 N m s^2 (95 %: 0.164 to 0.286 N m s^2)" in estimate_sentence(entry)


def test_an_axis_share_of_a_few_per_cent_is_not_a_claim_on_that_axis():
    """After this session's band changes the demo's drag explained x 3 %, y 73 %,
    z 2 %, and the verdict quoted D_z = 0.225 again (its interval six standard errors
    from the truth): a share under 5 % of an axis's error is not a claim there."""
    from omavctl.diagnose.verdict import verdict

    estimate = {
        "D": [0.0446, 0.0463, 0.225],
        "D_ci95": [[-0.0583, 0.148], [0.0311, 0.0615], [0.164, 0.286]],
        "D_pinned": [False, True, True],
    }
    diag = {
        "missing": ["rotational_drag"],
        "missing_effects": [
            {
                "name": "rotational_drag",
                "explained_variance": 0.22,
                "explained_variance_per_axis": {"x": 0.03, "y": 0.73, "z": 0.02},
            }
        ],
        "learned": [{"name": "rotational_drag", "units": {"D": "N m s^2"}, "estimate": estimate}],
    }
    (line,) = [ln for ln in verdict({"diagnosis": diag}) if ln.key == "missing"]
    assert "(the axes weighted alike: x 3 %, y 73 %, z 2 %)" in line.text
    assert "D_y = 0.0463 N m s^2" in line.text and "0.225" not in line.text
    assert "D_x, D_z not claimed: the effect explains under 5 % of the x, z errors here." in (
        line.text
    )


def test_two_models_in_either_order_read_as_effects_added_to_the_subset():
    """`evaluate --model new.npz --model old.npz` (the new model first, to diagnose it)
    printed "From new.npz to old.npz, motor_lag removed: ... rises" and then "the added
    effect and the refitted GP changed together": the model whose effects are a subset
    is "before" in every line, whatever the order, and the verdict says which model
    its other lines are about."""
    from omavctl.diagnose.change import verdict_of_models

    (before, _), (after, _) = _pair(0.388)
    after["metrics"]["model"]["rmse"]["z"] = 0.15  # one axis worse with the effect
    old = {**before["models"][0], "name": "old.npz"}
    new = {**after["models"][0], "name": "new.npz"}

    def lines(models, metrics):
        tree = copy.deepcopy(after if models[0] is new else before)
        tree["models"], tree["metrics_by_model"] = models, metrics
        return [ln.text for ln in verdict_of_models(tree) if ln.key == "change"]

    new_first = lines([new, old], [after["metrics"], before["metrics"]])
    old_first = lines([old, new], [before["metrics"], after["metrics"]])
    assert new_first[0] == old_first[0]
    assert new_first[0].startswith(
        "With command_delay added (old.npz → new.npz): the model error falls by"
    )
    assert (
        new_first[1]
        == old_first[1]
        == (
            "Axis z got worse (+50.0 %): the files do not say why: the added effect and the "
            "refitted GP changed together."
        )
    )
    assert new_first[2] == (
        "The lines below are about new.npz (the first --model), with effects command_delay."
    )
    assert old_first[2] == "The lines below are about old.npz (the first --model), with no effects."
    assert not any("removed" in t for t in new_first)


def test_a_learned_effect_the_flight_does_not_confirm_is_offered_as_a_test():
    """When nothing is missing the learned claim's test runs (``learned_claims`` in the
    diagnosis); an effect it did not take is still named, but as a test, not a claim:
    on the Betaflight tunes `motor_loss` and `battery_sag` were suggested with "add it
    with" and, fitted, pinned nothing down."""
    tree = _absorbed()
    tree["diagnosis"]["learned_claims"] = []
    (line,) = [ln for ln in verdict(tree) if ln.key == "learned"]
    assert line.text.endswith(
        " Not claimed: this flight does not confirm it (not pinned down away from its null, "
        "or adding it does not lower the held-out physics-only error)."
    )
    assert line.add_words == "Test it with" and line.plain().endswith(
        "Test it with: omavctl fit f.bag --effects com_offset --out m+c.npz"
    )
    assert "test it with: omavctl fit f.bag --effects com_offset" in _terminal(tree)
    # the diagnosis says which test held it back (real-data check item 7: the px4tools
    # octocopter's com_offset read "not pinned down ..., or ... does not lower ...")
    for why, words in (
        ("not_pinned", "its 95 % interval on this flight holds the value at which it is absent"),
        ("no_fall", "it is pinned down away from its null, but estimated from the fit flight"),
    ):
        tree["diagnosis"]["learned_held"] = {"com_offset": why}
        (line,) = [ln for ln in verdict(tree) if ln.key == "learned"]
        assert f" Not claimed: this flight does not confirm it: {words}" in line.text
        assert " or adding it" not in line.text


def test_the_fit_flights_estimate_and_this_flights_are_said_to_disagree():
    """Real-data check item 10 (Crazyflie): the verdict quoted T_m = 60.7 ms on log15, the
    printed command fitted 9.5 +- 16.1 ms on the hover logs, 2.1 combined standard
    errors apart, and no page said so. The evaluation of the fitted model holds both
    (the model's, and the diagnosis's estimate on this flight): the verdict says they
    disagree and where each comes from; the first verdict says where its command fits."""
    from omavctl.diagnose.fit_vs_flight import disagree_line, elsewhere_clause

    lag = {"T_m": [0.0095], "T_m_stderr": [0.0161], "stderr_method": "hac"}
    here = {"T_m": [0.0607], "T_m_stderr": [0.0187]}
    tree = {
        "models": [
            {
                "name": "lag.npz",
                "effects": {"motor_lag": lag},
                "fit_flight": {"logs": ["log10", "log16"], "time_window": None},
            }
        ],
        "logs": [{"name": "log15"}],
        "time_window": [15.76, 50.76],
        "diagnosis": {"learned": [{"name": "motor_lag", "units": {"T_m": "s"}, "estimate": here}]},
    }
    line = disagree_line(tree)
    assert line is not None and line.key == "disagree"
    assert line.text.startswith(
        "The fit flight and this one disagree: motor_lag's T_m = 0.0095 ± 0.016 s as "
        "fitted, 0.0607 ± 0.019 s on this flight (2.1 combined standard errors apart). "
        "Fitted on log10, log16; estimated on log15, 15.76–50.76 s as fit --effects would"
    )
    assert line in verdict(tree)
    # within 2 combined standard errors (the Crazyflie halves: 63.8 +- 9.7 against 66.4
    # ms) nothing is said
    tree["models"][0]["effects"]["motor_lag"] = {**lag, "T_m": [0.0638], "T_m_stderr": [0.0097]}
    assert disagree_line(tree) is None
    assert elsewhere_clause(tree) == (
        " The command below estimates it on the fit flight (log10, log16), not on this one: "
        "its value there can differ; evaluated here, the new model says if it does."
    )
    tree["models"][0]["fit_flight"] = {"logs": ["log15"], "time_window": [15.76, 50.76]}
    assert elsewhere_clause(tree) == ""  # fitted on this very flight: the same estimate


def test_nothing_claimed_offers_its_command_as_a_test_not_as_an_addition():
    """A new user's first verdict (fit with defaults on the omav, judged on a wobble):
    "Nothing claimed as missing. Not claimed: rotor_interference ..." was followed by
    "add it with:" and ``"test": false``, contradicting the sentence. Each way nothing
    is claimed (not pinned down, below the claim floor, held back by the refit test)
    offers its command as a test, in the terminal, the JSON and the report."""
    from omavctl.report.summary import evaluation_json

    cmd = "omavctl fit f.bag --effects rotor_interference"
    unpinned = _nothing_missing()
    unpinned["diagnosis"]["not_pinned"] = [
        {
            "name": "rotor_interference",
            "units": {"rotor_rotor": "1"},
            "estimate": {"rotor_rotor": 0.25, "rotor_rotor_ci95": [0.0, 0.53]},
            "axes": None,
        }
    ]
    unpinned["diagnosis"]["effect_commands"] = {"rotor_interference": cmd}
    below = _nothing_missing()
    below["diagnosis"]["method"]["min_contribution_rms"] = 0.09
    below["diagnosis"].update(below_noise="rotor_interference", test_command=cmd)
    below["diagnosis"]["missing_effects"] = [
        {"name": "rotor_interference", "explained_variance": 0.3, "contribution_rms": 0.05}
    ]
    refit = _nothing_missing()
    refit["diagnosis"].update(refit_rejected="rotor_interference")
    refit["diagnosis"]["effect_commands"] = {"rotor_interference": cmd}
    refit["diagnosis"]["missing_effects"] = [
        {"name": "rotor_interference", "explained_variance": 0.3, "refit_explained_variance": -0.2}
    ]
    for tree in (unpinned, below, refit):
        first = verdict(tree)[0]
        assert first.text.startswith("Nothing claimed as missing")
        assert (first.command, first.test) == (cmd, True)
        # the effect evaluate writes test_command for (it was below_noise's only, and
        # null in the JSON beside "test it with" for the other two)
        assert effect_to_test(tree["diagnosis"]) == "rotor_interference"
        assert first.plain().endswith(f" Test it with: {cmd}")
        assert f"    test it with: {cmd}" in _terminal(tree)
        assert "add it with" not in _terminal(tree)
        (line,) = [v for v in evaluation_json(tree, {})["verdict"] if v["key"] == "missing"]
        assert (line["command"], line["test"]) == (cmd, True)
    # nothing near a claim: no command, so nothing to test
    plain = verdict(_nothing_missing())[0]
    assert (plain.command, plain.test) == (None, False)
    assert effect_to_test(_nothing_missing()["diagnosis"]) is None
    # a claim made: only the noise floor's effect is still offered as a test
    unpinned["diagnosis"]["missing"] = ["rotational_drag"]
    assert effect_to_test(unpinned["diagnosis"]) is None
    below["diagnosis"]["missing"] = ["rotational_drag"]
    assert effect_to_test(below["diagnosis"]) == "rotor_interference"


def test_report_does_not_title_the_which_model_sentence_as_a_change():
    """The px4tools loop's report (two --model in one evaluation) read "Error change: The
    lines below are about gp.npz (the first --model) ...": that sentence is a pointer, so
    the report gives it no bold head; the other lines keep theirs."""
    from omavctl.report.document import _md_inline
    from omavctl.report.top import verdict_section

    (before, _), (after, _) = _pair(0.388)
    tree = copy.deepcopy(before)
    old = {**before["models"][0], "name": "old.npz"}
    new = {**after["models"][0], "name": "new.npz"}
    tree["models"], tree["metrics_by_model"] = [old, new], [before["metrics"], after["metrics"]]
    items = [_md_inline(it) for it in verdict_section([(tree, None, "e.json")])[1].items]
    pointer = [it for it in items if "The lines below are about" in it]
    assert pointer == ["The lines below are about old.npz (the first --model), with no effects."], (
        items
    )
    assert items[0].startswith("**Missing:** command\\_delay, measured — with it added"), items


def test_two_models_each_flag_names_its_model_and_a_later_model_is_flagged_too():
    """docs/real-data-check.md items 13 and 16 (the Crazyflie halves, the Betaflight
    pair): with two --model the "predicting none would do as well" flag was given for
    the first model only, and a flag about the first model stood, unnamed, above "The
    lines below are about <first> (the first --model)"."""
    from omavctl.diagnose.change import verdict_of_models

    (before, _), (after, _) = _pair(0.388)
    full = {"coverage_2sigma": {a: 0.95 for a in "xyz"}}
    m0 = {
        "zero": {"rmse": {"x": 1.0, "y": 1.0, "z": 0.05}},
        "effects": {"rmse": {"x": 0.1, "y": 0.2, "z": 0.1}},
        "model": {"rmse": {"x": 0.1, "y": 0.2, "z": 0.1}, **full},
    }
    m1 = copy.deepcopy(m0)
    m1["zero"]["rmse"]["z"] = 0.5
    m1["model"]["rmse"] = {"x": 0.06, "y": 0.12, "z": 0.6}  # z above its zero
    m1["effects"]["rmse"] = {"x": 0.06, "y": 0.12, "z": 0.6}
    tree = copy.deepcopy(before)
    tree["models"] = [
        {**before["models"][0], "name": "old.npz"},
        {**after["models"][0], "name": "new.npz"},
    ]
    tree["metrics"], tree["metrics_by_model"] = m0, [m0, m1]
    tree["flags"] = [
        {"code": "no_better_than_zero", "axis": "z", "message": "axis z: the first's flag"}
    ]
    texts = [ln.text for ln in verdict_of_models(tree)]
    pointer = texts.index("The lines below are about old.npz (the first --model), with no effects.")
    assert texts[0] == "With old.npz: axis z: the first's flag", texts
    (later,) = [t for t in texts if t.startswith("With new.npz: ")]
    assert later.startswith(
        "With new.npz: axis z: the model's error (0.6 rad/s² RMS) is not below the angular "
        "acceleration itself (0.5): predicting none would do as well"
    )
    assert texts.index(later) < pointer


def test_the_report_shows_the_signature_of_the_effects_the_verdict_discusses():
    """Real-data check item 8 (px4tools): the only signature figure was command_delay's
    (the top candidate, 3 %, never named); com_offset, the learned effect the verdict
    discusses, had none."""
    from omavctl.diagnose.diagnosis_commands import discussed

    diag = {
        "missing": [],
        "learned_claims": [],
        "not_pinned": [],
        "missing_effects": [{"name": "command_delay"}, {"name": "com_offset"}],
        "learned": [
            {"name": "inertia_error", "missing": True},
            {"name": "com_offset", "missing": True},
        ],
    }
    assert discussed(diag, ["inertia_error"]) == ["com_offset"]
    # and the one the verdict holds back on one axis (Betaflight: command_delay, y 34 %)
    held = {**diag, "method": {"min_explained_variance": 0.15}}
    held["missing_effects"] = [
        {"name": "command_delay", "explained_variance_per_axis": {"y": 0.34}},
        {"name": "com_offset"},
    ]
    assert discussed(held, ["inertia_error"]) == ["com_offset", "command_delay"]
    assert discussed({**diag, "learned": []}, ["inertia_error"]) == ["command_delay"]
    assert discussed({**diag, "missing": ["motor_lag"]}, []) == ["motor_lag"]


def test_a_material_share_of_one_axis_is_named_as_held_back_with_its_reason():
    """Real-data check item 14 (Betaflight): command_delay explained 34 % of the y error
    on held-out blocks (4 % over all axes, under the 15 % floor, which is on the total),
    and the verdict named it nowhere."""
    tree = _nothing_missing()
    tree["diagnosis"]["missing_effects"] = [
        {
            "name": "command_delay",
            "explained_variance": 0.04,
            "explained_variance_per_axis": {"x": 0.01, "y": 0.34, "z": 0.03},
            "significant": True,
            "plausible": True,
        },
        {"name": "rotational_drag", "explained_variance_per_axis": {"x": 0.12, "y": 0.1}},
    ]
    tree["diagnosis"]["effect_commands"] = {"command_delay": "omavctl fit b.csv --out m+d.npz"}
    (line,) = [ln for ln in verdict(tree) if ln.key == "axis"]
    assert line.text == (
        "Not claimed although it explains 34 % of the y error on held-out blocks: "
        "command_delay, because over all axes it explains 4 %, under the 15 % of the total "
        "a claim needs."
    )
    assert line.plain().endswith("Test it with: omavctl fit b.csv --out m+d.npz")
    # a negative delay at t 0 (a new user's Betaflight log): both reasons, nothing to test
    tree["diagnosis"]["missing_effects"][0].update(significant=False, t_value=0.0, plausible=False)
    (line,) = [ln for ln in verdict(tree) if ln.key == "axis"]
    assert line.text.endswith(
        "because over all axes it explains 4 %, under the 15 % of the total a claim needs, "
        "and its estimate is not significant (t = 0, under the 4 a claim needs) and outside "
        "the effect's plausible "
        "range."
    )
    assert line.command is None
    # named already (held back, or claimed): not said twice
    tree["diagnosis"]["not_pinned"] = [{"name": "command_delay"}]
    assert not [ln for ln in verdict(tree) if ln.key == "axis"]


def test_the_likewise_effects_of_the_one_axis_share_come_with_their_shares():
    """Betaflight (real-data check item 14) read "Likewise: com_offset, motor_lag.": the
    first held-back effect came with its share of the axis, the others with none."""
    tree = _nothing_missing()
    tree["diagnosis"]["missing_effects"] = [
        {
            "name": "command_delay",
            "explained_variance": 0.13,
            "explained_variance_per_axis": {"y": 0.34},
        },
        {
            "name": "com_offset",
            "explained_variance": 0.05,
            "explained_variance_per_axis": {"x": 0.18, "y": 0.02, "z": 0.21},
        },
        {
            "name": "motor_lag",
            "explained_variance": 0.04,
            "explained_variance_per_axis": {"y": 0.16},
        },
    ]
    (line,) = [ln for ln in verdict(tree) if ln.key == "axis"]
    assert line.text.endswith(
        "a claim needs. Likewise: com_offset (18 % of the x error, 21 % of the z error), "
        "motor_lag (16 % of the y error)."
    )
    # with the first's command the others are told how to be tested (a new user found no
    # command for them in the terminal)
    tree["diagnosis"]["effect_commands"] = {
        n: f"omavctl fit f.csv --effects {n}" for n in ("command_delay", "com_offset")
    }
    (line,) = [ln for ln in verdict(tree) if ln.key == "axis"]
    assert line.text.endswith(
        "motor_lag (16 % of the y error). Test each the same way, its name in place of "
        "command_delay."
    )
    assert line.plain().endswith("Test it with: omavctl fit f.csv --effects command_delay")


def test_the_ranking_says_why_an_effect_the_model_holds_stands_below_one_it_lacks():
    """Real-data check item 9 (px4tools): "What the nominal model's residual resembles",
    best first, listed com_offset (26 %) above inertia_error (42 %), which the model
    holds: the order is claimed-first, and the report now says so and which test failed."""
    from omavctl.report.diagnosis import diagnosis_section
    from omavctl.report.document import Document, to_markdown

    tree = _nothing_missing()
    tree["models"][0]["effects"] = {"inertia_error": {}}
    tree["diagnosis"]["learned"] = [
        {"name": "com_offset", "missing": True, "explained_variance": 0.261},
        {
            "name": "inertia_error",
            "missing": False,
            "explained_variance": 0.418,
            "significant": True,
            "plausible": False,
        },
    ]
    text = to_markdown(Document("r", diagnosis_section(tree, 0, "eval.json")))
    text = text.replace("\\_", "_")
    assert "`inertia_error` *(in the model)*" in text
    assert (
        "inertia_error (in the model) stands below com_offset: the order is the effects that "
        "pass every test first, then by share, and inertia_error does not pass them here: its "
        "estimate is outside the effect's plausible range."
    ) in " ".join(text.split())


def test_the_report_ranking_marks_every_effect_the_verdict_names_missing(monkeypatch):
    """Eyes3 (motor_lag hidden, fig8 -> wobble): the verdict named com_offset,
    rotor_interference and motor_lag missing, while the report's ranking said "no" for
    the last two (motor_lag at 0 %: the joint selection named it) and its bar chart drew
    them as "not missing": each now says which later step claimed it, with its numbers,
    in the report and in the verdict's "Also:"."""
    from omavctl.report import figures as rf
    from omavctl.report.diagnosis import diagnosis_section
    from omavctl.report.document import Document, to_markdown
    from omavctl.report.top import _candidates_blocks

    tree = _nothing_missing()
    diag = tree["diagnosis"]
    diag["unexplained"] = []
    diag["missing"] = ["com_offset", "rotor_interference", "motor_lag"]
    diag["missing_effects"] = [
        {"name": "com_offset", "explained_variance": 0.246, "missing": True},
        {"name": "rotor_interference", "explained_variance": 0.147, "missing": False},
        {"name": "motor_lag", "explained_variance": 0.0, "missing": False},
    ]
    diag["missing_steps"] = [
        {"name": "com_offset", "explained_variance": 0.246},
        {"name": "rotor_interference", "explained_variance": 0.183},
    ]
    diag["joint_steps"] = [{"name": "motor_lag", "share": 0.812, "share_of_total": 0.112}]
    diag["fit_command"] = "omavctl fit f.bag --effects com_offset,rotor_interference,motor_lag"
    text = to_markdown(Document("r", diagnosis_section(tree, 0, "eval.json")))
    assert "\\`fit --effects\\`" not in text  # shown with its backticks in the HTML too
    text = " ".join(text.replace("\\_", "_").split())
    assert (
        "named by a later step: rotor_interference: step 2 of the forward selection: it "
        "explains 18 % of the model's remaining error that com_offset leaves; motor_lag: the "
        "joint selection: estimated from the fit flight as fit --effects would, it removes "
        "81 % of the held-out physics-only error left before it (11 % of the whole)."
    ) in text
    assert "**MISSING** (step 2) | – |" in text and "**MISSING** (joint selection) | – |" in text
    assert "| no |" not in text  # no claimed effect says "no" any more
    # its part: "0.016 (below 3x noise)" of the model's error read as a claim under the
    # floor; the joint selection's part of the physics-only error stands beside it
    diag["missing_effects"][2].update(contribution_rms=0.016, above_noise=False)
    diag["joint_steps"][0]["contribution_rms"] = 0.25
    again = " ".join(to_markdown(Document("r", diagnosis_section(tree, 0, "e"))).split())
    assert "| 0.016 (below 3× noise); 0.25 of the physics-only error | " in again
    assert "#### Command that adds com_offset, rotor_interference, motor_lag" in text
    # the names apart, as everywhere else ("Missing: A B C" ran them together)
    assert "Missing: **com_offset**, **rotor_interference**, **motor_lag**" in text
    said = next(ln for ln in verdict(tree) if ln.key == "missing").plain()
    assert (
        "Also: rotor_interference, motor_lag (the fit command adds them together; "
        "rotor_interference: step 2 of the forward selection: it explains 18 %"
    ) in said
    drawn: dict[str, Any] = {}
    monkeypatch.setattr(rf, "candidates_figure", lambda e, t, later: drawn.update(later) or b"")
    (block,) = _candidates_blocks(tree, "eval.json", figures=True)
    assert drawn == {"rotor_interference": "step 2", "motor_lag": "joint selection"}
    assert block.caption.endswith(
        "; rotor_interference, motor_lag claimed by a later selection step (section 5)."
    )


def test_no_better_than_zero_on_several_axes_is_one_line():
    """Eyes3 (Crazyflie log15 -> log10): the verdict opened with the same 300-character
    sentence three times, once per axis; it is one line with each axis's numbers, the
    advice once (the JSON keeps one flag per axis for scripts)."""
    from omavctl.diagnose.metrics import quality_flags

    tree = _nothing_missing()
    metrics = {
        "zero": {"rmse": {"x": 9.54, "y": 8.97, "z": 1.68}},
        "model": {
            "rmse": {"x": 11.6, "y": 16.9, "z": 2.32},
            "coverage_2sigma": {a: 0.95 for a in "xyz"},
        },
        "effects": {"rmse": {"x": 11.6, "y": 16.9, "z": 2.32}},
    }
    tree["flags"] = quality_flags(metrics, [], ["motor_lag"])
    assert len(tree["flags"]) == 3
    lines = [ln for ln in verdict(tree) if "predicting none" in ln.text]
    assert [(ln.key, ln.text) for ln in lines] == [
        (
            "worse",
            "axes x, y, z: the model's error (x 11.6, y 16.9, z 2.32 rad/s² RMS) is not below "
            "the angular acceleration itself (x 9.54, y 8.97, z 1.68): predicting none would "
            "do as well; the diagnosis names what the physics lacks (motor_lag): add it "
            "first; if the error stays, check the command's gain, sign and frame, and whether "
            "the flight moves the vehicle enough for its commands to show",
        )
    ]
    # a new user's Crazyflie: motor_lag explains x 34 %, y 35 %, z 0 %: z is not told to
    # add it first (adding it left z no better than predicting none)
    shares = {"motor_lag": {"x": 0.34, "y": 0.35, "z": 0.0}}
    tree["flags"] = quality_flags(metrics, [], ["motor_lag"], shares)
    by_axis = {f["axis"]: f["message"] for f in tree["flags"]}
    assert "names what the physics lacks (motor_lag)" in by_axis["x"]
    assert by_axis["z"].endswith(
        "predicting none would do as well; check the command's gain, sign and frame, and "
        "whether the flight moves the vehicle enough for its commands to show"
    )
    from omavctl.diagnose.diagnosis_commands import claim_shares

    ranked = {
        "missing_effects": [
            {"name": "motor_lag", "explained_variance_per_axis": shares["motor_lag"]}
        ]
    }
    assert claim_shares(ranked) == shares and claim_shares(None) == {}


def test_two_models_the_first_models_own_sentence_names_its_model():
    """Eyes3 (`evaluate flight-02.bag --model gp.npz --model gp+com_offset+...npz`): the
    verdict opened "Missing: com_offset ..." above the change line and the pointer
    "The lines below are about gp.npz", so it read as the better model's lack; it now
    says which model it is about, as the first model's leading flags do."""
    from omavctl.diagnose.change import verdict_of_models

    (before, _), (after, _) = _pair(0.388)
    tree = copy.deepcopy(before)
    tree["diagnosis"]["missing"] = ["com_offset"]
    tree["diagnosis"]["missing_effects"] = [{"name": "com_offset", "explained_variance": 0.25}]
    old = {**before["models"][0], "name": "old.npz"}
    new = {**after["models"][0], "name": "new.npz"}
    tree["models"], tree["metrics_by_model"] = [old, new], [before["metrics"], after["metrics"]]
    texts = [ln.text for ln in verdict_of_models(tree)]
    assert texts[0].startswith("With old.npz: Missing: com_offset — it explains 25 %"), texts
    assert texts[2] == "The lines below are about old.npz (the first --model), with no effects."


def test_a_later_model_with_other_effects_is_not_said_to_disagree_with_this_flight():
    """Crazyflie halves, `evaluate --model base.npz --model base+motor_lag.npz`: "With
    base+motor_lag.npz: the fit flight and this one disagree: inertia_error's scale_z =
    1.51 ± 0.29 as fitted, 3.56 ± 0.63 on this flight": 3.56 is the estimate with the
    first model's effects (no lag), 1.51 was fitted beside the lag. The models differ,
    not the flights: a parameter is compared only where its estimate was made with the
    model's own effects (the lag the later model adds, not the scale both hold)."""
    from omavctl.diagnose.fit_vs_flight import disagree_line, disagreeing

    base = {"scale": [1.2, 1.1, 3.3], "scale_stderr": [0.1, 0.1, 0.6]}
    lag = {"scale": [1.10, 1.15, 1.51], "scale_stderr": [0.053, 0.11, 0.29]}
    here = {"scale": [1.2, 1.1, 3.56], "scale_stderr": [0.1, 0.1, 0.63]}
    entry = {"name": "inertia_error", "units": {"scale": "1"}, "estimate": here,
             "explained_variance_per_axis": {"x": 0.67, "y": 0.69, "z": 0.61}}  # fmt: skip
    tree = {
        "models": [
            {"name": "base.npz", "effects": {"inertia_error": base}},
            {
                "name": "base+motor_lag.npz",
                "effects": {"inertia_error": lag, "motor_lag": {"T_m": [0.064]}},
            },
        ],
        "logs": [{"name": "log15"}],
        "diagnosis": {"learned": [entry]},
    }
    assert disagree_line(tree) is None
    assert disagreeing(tree, 1) == set()
    # the effect the later model adds was estimated with its set: compared
    tree["models"][1]["effects"]["motor_lag"] = {"T_m": [0.064], "T_m_stderr": [0.0097]}
    lag_here = {"T_m": [0.021], "T_m_stderr": [0.0017]}
    tree["diagnosis"]["learned"].append(
        {"name": "motor_lag", "units": {"T_m": "s"}, "estimate": lag_here}
    )
    line = disagree_line(tree)
    assert line is not None and "motor_lag's T_m = 0.064 ± 0.0097 s as fitted" in line.text
    assert "inertia_error" not in line.text
    assert disagreeing(tree, 1) == {("motor_lag", "T_m")}
    # the same effects as the first model: compared (the first model's too)
    tree["models"][1]["effects"] = {"inertia_error": lag}
    line = disagree_line(tree)
    assert line is not None and line.text.startswith(
        "With base+motor_lag.npz: the fit flight and this one disagree: inertia_error's "
        "scale_z = 1.51 ± 0.29 as fitted, 3.56 ± 0.63 on this flight (3.0 combined "
        "standard errors apart)."
    )
    assert disagreeing(tree, 1) == {("inertia_error", "scale_z")}


def test_a_second_models_narrow_band_is_said_with_its_name():
    """evaluate --model half-base.npz --model half-lag.npz on the Crazyflie halves: "can be
    trusted" was said of the first model only, while the recommended lag model covered x
    82 %, y 85 %; the later model's band now has its own line, named."""
    from omavctl.diagnose.change import verdict_of_models

    tree = _absorbed()
    tree["metrics"]["model"]["coverage"] = {"x": 0.96, "y": 0.95, "z": 0.97}
    second = {**tree["metrics"]["model"], "coverage": {"x": 0.82, "y": 0.85, "z": 0.94}}
    tree["models"].append({"name": "half-lag.npz", "effects": {"com_offset": {}}})
    tree["metrics_by_model"] = [tree["metrics"], {**tree["metrics"], "model": second}]
    texts = [ln.text for ln in verdict_of_models(tree)]
    assert (
        "With half-lag.npz, the uncertainty is a little narrow on x, y: x 82 %, y 85 % of the "
        "samples lie within the predicted 2σ (95 % expected); use its error bars with care "
        "there (within 2σ: x 82 %, y 85 %, z 94 %)."
    ) in texts
    tree["metrics_by_model"][1]["model"]["coverage"] = {"x": 0.95, "y": 0.96, "z": 0.95}
    texts = [ln.text for ln in verdict_of_models(tree)]
    assert not any(t.startswith("With half-lag.npz, the uncertainty") for t in texts)


def test_an_effect_the_gp_learned_is_not_said_again_as_held_back_on_one_axis():
    """A new user's verdict said com_offset "is pinned down away from its null" (the
    learned line) and, a line later, "Not claimed although it explains 61 % of the x
    error ...: com_offset, because its estimate is not significant (t = 4)", a t of
    3.9x under the bar of 4, printed as the bar. The learned line discusses it alone;
    the one-axis line goes on to the next effect, and a t under the bar prints so."""
    tree = _absorbed()
    diag = tree["diagnosis"]
    diag["missing_effects"] = [
        {
            "name": "com_offset",
            "explained_variance": 0.10,
            "explained_variance_per_axis": {"x": 0.61},
            "significant": False,
            "t_value": 3.96,
        },
        {
            "name": "rotational_drag",
            "explained_variance": 0.05,
            "explained_variance_per_axis": {"x": 0.28},
            "significant": False,
            "t_value": 1.5,
        },
    ]
    lines = verdict(tree)
    (learned,) = [ln for ln in lines if ln.key == "learned"]
    (axis,) = [ln for ln in lines if ln.key == "axis"]
    assert learned.subject == "com_offset"
    assert axis.text.startswith(
        "Not claimed although it explains 28 % of the x error on held-out blocks: "
        "rotational_drag, because"
    )
    assert "com_offset" not in axis.text
    from omavctl.diagnose.axis_share import failed_test

    why = failed_test(diag["missing_effects"][0], 0.05)
    assert why == "its estimate is not significant (t = 3.96, under the 4 a claim needs)"
