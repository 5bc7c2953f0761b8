"""The words a report's verdict puts before a command (what a new user read, session 12).

`omavctl report eval.json eval-drag.json` wrote "To test command_delay instead ... Add it
with: omavctl fit ... --effects ...,command_delay" where `evaluate` had said "test it
with": re-labelling each file's lines dropped whether the command adds a claimed effect
or only tests a look-alike. And the plain text ran the plan command on into the next
sentence ("... --out m.separate.csv Add it with: ...").
"""

from __future__ import annotations

import copy
from typing import Any

from omavctl.diagnose.change import report_verdict
from omavctl.diagnose.verdict import Line, verdict
from tests.test_verdict_ux import ambiguous_drag


def _ambiguous(rmse_y: float) -> dict[str, Any]:
    """rotational_drag missing, command_delay its look-alike, model y error ``rmse_y``."""
    tree = ambiguous_drag()
    tree["metrics"]["model"]["rmse"]["y"] = rmse_y
    tree["metrics"]["nominal"] = {"rmse": {"x": 0.9, "y": 1.6, "z": 0.16}}
    return tree


def test_a_report_keeps_test_it_with_for_a_look_alike():
    first = _ambiguous(0.28)
    second = copy.deepcopy(first)
    second["models"][0]["effects"] = {"rotational_drag": {"D": [0.05, 0.05, 0.03]}}
    second["metrics"]["model"]["rmse"]["y"] = 0.04
    own = {ln.text: ln.add_words for ln in verdict(first) if ln.command}
    lines = report_verdict([(first, "eval.json"), (second, "eval-drag.json")])
    test = [ln for ln in lines if ln.text.startswith("To test command_delay instead")]
    assert len(test) == 2  # the first file's look-alike and the last file's own verdict
    assert {ln.add_words for ln in test} == {"Test it with"} == {own[test[0].text]}
    assert test[0].plain().startswith("eval.json: To test command_delay instead")
    assert "Test it with: omavctl fit f.bag --effects command_delay" in test[0].plain()
    claim = next(ln for ln in lines if ln.text.startswith("Missing: rotational_drag"))
    assert claim.add_words == "Add it with"


def test_a_sentence_that_ends_in_a_command_gets_its_full_stop():
    plan = "omavctl plan --task m.fig8.csv --objective effects --out m.separate.csv"
    line = Line(
        "missing", f"To plan a flight that tells them apart: {plan}", command="omavctl fit f"
    )
    assert line.plain() == (
        f"To plan a flight that tells them apart: {plan}. Add it with: omavctl fit f"
    )
    done = Line("missing", "Missing: x.", command="omavctl fit f")
    assert done.plain() == "Missing: x. Add it with: omavctl fit f"


def test_an_input_moved_around_another_level_is_a_mismatch_not_an_unexcited_input():
    """A PX4 octocopter model (normalised thrust: fz/m near 0.2 in training) on an omav
    log (fz/m 8.4 to 11.3 m/s^2) said the log goes 383 training ranges beyond "because
    the fit flight did not move it, not ... because model and log differ"."""
    import numpy as np

    from omavctl.diagnose.metrics import envelope_flags, training_envelope

    t = np.linspace(0.0, 10.0, 400)
    train = np.stack([np.sin(t), 0.2 + 0.01 * np.sin(3 * t)], axis=1)
    err, std = np.full((400, 3), 0.05), np.full((400, 3), 0.1)
    around = np.stack([np.sin(1.3 * t), 0.2 + 0.5 * np.sin(2 * t)], axis=1)
    elsewhere = np.stack([np.sin(1.3 * t), 9.8 + 1.5 * np.sin(2 * t)], axis=1)
    env = training_envelope(train, around, ["fx/m", "fz/m"], err, std)
    assert set(env["underexcited"]) == {"fz/m"}
    assert [f["code"] for f in envelope_flags(env)] == ["underexcited"]
    env = training_envelope(train, elsewhere, ["fx/m", "fz/m"], err, std)
    assert env["underexcited"] == {}
    (flag,) = envelope_flags(env)
    assert flag["code"] == "far_outside_training"
    assert flag["message"].startswith(
        "The log goes 555 training ranges beyond the model's"
    )  # (11.3 - 0.21) / 0.02


def test_a_pinned_interval_never_prints_an_end_at_the_null():
    """A Crazyflie fit printed inertia_error scale_x 1.103 [1, 1.21], pinned down (its
    interval [1.00009, 1.206] excludes scale = 1), in the fit table and the verdict."""
    from omavctl.cli.fit import _interval_text
    from omavctl.diagnose.estimate_text import estimate_sentence
    from omavctl.learn.intervals import interval_ends

    assert interval_ends(1.0000934, 1.2061241, 1.0) == ("1.0001", "1.2061", 5)
    assert interval_ends(0.0, 0.7242, 0.0) == ("0", "0.724", 3)  # cut at 0: the null
    assert interval_ends(1.0000934, 1.2061241) == ("1", "1.21", 3)  # no null: as before
    ends = (1.0000934, 1.2061241)
    assert _interval_text(ends, True, ("inertia_error", "scale", 0)) == "[1.0001, 1.2061]"
    entry = {
        "name": "inertia_error",
        "units": {"scale": "1"},
        "estimate": {"scale": [1.1031], "scale_ci95": [list(ends)], "scale_pinned": [True]},
    }
    assert "scale = 1.1031 (95 %: 1.0001 to 1.2061)" in estimate_sentence(entry)
    # the report's model lines (2 digits) too
    from omavctl.report.params import _interval_note

    params = {"scale_ci95": [list(ends)], "scale_pinned": [True]}
    assert _interval_note(params, "scale", 0, "inertia_error") == " [1.0001, 1.2061]"
    params = {"scale_ci95": [[0.8, 1.2]], "scale_pinned": [False]}
    assert _interval_note(params, "scale", 0, "inertia_error").startswith(" [0.8, 1.2]: ")


def test_the_json_verdict_says_which_command_only_tests_a_look_alike():
    """`evaluate --json` and `report --json` gave a look-alike's test command and the
    claimed effect's fit command alike ({key, text, command}): a script piping the
    verdict's commands to a shell could not tell a claim from a test."""
    from omavctl.report.summary import evaluation_json

    out = evaluation_json(_ambiguous(0.28), {})
    commanded = [(v["command"], v["test"]) for v in out["verdict"] if v["command"]]
    assert commanded == [
        ("omavctl fit f.bag --effects rotational_drag", False),
        ("omavctl fit f.bag --effects command_delay", True),
    ]


def test_a_share_of_what_the_look_alikes_leave_says_so_and_gives_the_whole():
    """Session 33's new-user trial (hidden drag and a 30 ms delay, fig8 -> steps): the
    verdict led "Missing: command_delay — ... it removes 71 % of the squared
    physics-only error on held-out data" and went on "they remove 99 %, command_delay
    2 %, com_offset 98 %". The 71 % was of what com_offset's least-squares fit on the
    held-out flight leaves (the delay's step judged beside the look-alikes, first in
    joint_steps); the 2 % is of the whole. The lead sentence now says both."""
    from tests.test_verdict_ux import ambiguous_drag

    tree = ambiguous_drag()
    tree["models"][0]["effects"] = {"rotor_interference": {}}
    diag = tree["diagnosis"]
    diag["missing"] = ["command_delay", "com_offset"]
    diag["missing_effects"] = [
        {"name": "command_delay", "explained_variance": -0.01},
        {"name": "com_offset", "explained_variance": 0.09},
    ]
    diag["joint_steps"] = [
        {"name": "command_delay", "share": 0.711, "share_of_total": 0.0152},
        {"name": "com_offset", "share": 0.977, "share_of_total": 0.977},
    ]
    diag["fit_command"] = "omavctl fit f.bag --effects command_delay,com_offset"
    text = next(ln for ln in verdict(tree) if ln.key == "missing").plain()
    assert text.startswith(
        "Missing: command_delay — estimated from the fit flight as fit --effects would, it "
        "removes 71 % of the squared physics-only error on held-out data that com_offset, "
        "the look-alike of a rotorcraft's imperfections, leaves at its least-squares fit "
        "there, 2 % of the whole (the model's GP has absorbed it: it explains none of the "
        "model's remaining error)."
    ), text
    assert "they remove 99 % of the squared physics-only error" in text
    # a later step of the forward selection: of what the steps before it leave
    diag["joint_steps"].reverse()
    diag["missing"] = ["command_delay", "com_offset"]
    text = next(ln for ln in verdict(tree) if ln.key == "missing").plain()
    assert "on held-out data that com_offset leaves, 2 % of the whole (the model's" in text
    # a share of the whole says nothing more
    diag["joint_steps"][1]["share"] = 0.0152
    text = next(ln for ln in verdict(tree) if ln.key == "missing").plain()
    assert "it removes 2 % of the squared physics-only error on held-out data (the" in text


def test_an_effect_within_the_noise_is_said_not_nothing_missing():
    """Session 34's new-user trial (a figure-8 with a drag the model lacked, judged on
    steps): "Nothing missing: no registered effect explains 15 % or more of the model's
    remaining error" while rotational_drag explained 24 % (t 8.2), its part 0.023 rad/s²
    RMS within the log's noise 0.029. Adding it then cut the error 21 %."""
    from tests.test_verdict_ux import _nothing_missing

    tree = _nothing_missing()
    diag = tree["diagnosis"]
    diag["method"].update(measurement_noise_std=0.029, min_contribution_rms=0.086)
    diag["missing_effects"] = [
        {
            "name": "rotational_drag",
            "explained_variance": 0.239,
            "explained_variance_per_axis": {"x": 0.386, "y": 0.333, "z": 0.0},
            "contribution_rms": 0.023,
            "significant": True,
            "plausible": True,
            "missing": False,
            "above_noise": False,
        }
    ]
    diag["effect_commands"] = {"rotational_drag": "omavctl fit f.bag --effects rotational_drag"}
    line = verdict(tree)[0]
    assert line.text.startswith(
        "Nothing claimed as missing: rotational_drag explains 24 % of the model's remaining "
        "error on held-out data, but its part, 0.023 rad/s² RMS, is within the log's own "
        "measurement noise (0.029; a claim needs 0.086, three times it): too small to claim "
        "from this flight, not shown absent."
    ), line.text
    # its test command is printed once: here, or by the line of an effect held on an axis
    axis = [ln for ln in verdict(tree) if ln.key == "axis"]
    commands = [ln.command for ln in verdict(tree) if ln.command]
    assert commands == ["omavctl fit f.bag --effects rotational_drag"]
    assert (line.command is None) == bool(axis) and (line.test or line.command is None)
    # an effect with a part above the noise is the noise floor's sentence, as before
    diag["missing_effects"][0]["contribution_rms"] = 0.05
    diag["below_noise"] = "rotational_drag"
    assert verdict(tree)[0].text.startswith(
        "Nothing claimed as missing: rotational_drag would explain 24 %"
    )
    # nothing that explains a claim's share: "Nothing missing", as before
    diag["missing_effects"][0].update(explained_variance=0.1, contribution_rms=0.023)
    diag["below_noise"] = None
    assert verdict(tree)[0].text.startswith("Nothing missing: no registered effect explains 15 %")
