"""Verdict sentences a user read as unclear or said twice (session 14's follow-ups): a
claim that took a held-back lag's joint step says whose share it quotes, and a worse
axis whose fitted parameter disagrees with the evaluated log says it in one sentence
with the part that rose."""

from __future__ import annotations

import copy
from typing import Any

from omavctl.diagnose.change import change_lines, scores_of_files
from omavctl.diagnose.verdict import verdict

RIVAL = (
    "command_delay's share is that of the joint step motor_lag passed first: a lag and a "
    "delay look alike to first order, both passed it, and estimated exactly on this flight "
    "motor_lag could not be pinned down while command_delay was, so command_delay takes "
    "its place"
)


def _rival_tree(missing: list[str]) -> dict[str, Any]:
    """report6 draw 61's second round, cut down: the joint step accepted motor_lag beside
    rotor_interference, the guard held the lag back and kept command_delay, its rival."""
    return {
        "models": [{"name": "m.npz", "effects": {"com_offset": {}}}],
        "metrics": {"model": {"rmse": {"x": 0.5, "y": 0.5, "z": 0.1}}},
        "diagnosis": {
            "method": {"min_explained_variance": 0.15},
            "missing": missing,
            "missing_effects": [
                {"name": "rotor_interference", "explained_variance": 0.55},
                {"name": "command_delay", "explained_variance": 0.02},
            ],
            "joint_steps": [
                {"name": "rotor_interference", "share": 0.737, "share_of_total": 0.737},
                {
                    "name": "motor_lag",
                    "share": 0.174,
                    "share_of_total": 0.0457,
                    "timing_rivals": ["command_delay"],
                },
            ],
            "fit_command": "omavctl fit f.bag --effects rotor_interference,command_delay",
            "unexplained": [],
        },
    }


def test_a_claim_that_took_a_held_back_lags_joint_step_says_whose_share_it_is():
    """It said only "(the fit command adds them together)": the step's shares were
    looked up by name, and the claim's name is not the step's."""
    text = verdict(_rival_tree(["rotor_interference", "command_delay"]))[0].text
    assert (
        "Also: command_delay (the fit command adds them together: estimated jointly from the "
        "fit flight as fit --effects would, they remove 78 % of the squared physics-only error "
        f"on held-out data, rotor_interference 74 %, command_delay 5 %; {RIVAL})."
    ) in text
    # the claim alone: the joint share of the step it took, and why it is that step's
    alone = verdict(_rival_tree(["command_delay"]))[0].text
    assert alone.startswith(
        "Missing: command_delay — estimated from the fit flight as fit --effects would, it "
        "removes 17 % of the squared physics-only error on held-out data that "
        "rotor_interference leaves, 5 % of the whole (the model's GP has absorbed it: it "
        f"explains 2 % of the model's remaining error); {RIVAL}."
    )
    # no command printed (several models evaluated): no "fit command" to point at
    bare = _rival_tree(["rotor_interference", "command_delay"])
    del bare["diagnosis"]["fit_command"]
    assert "Also: command_delay (fit them together: estimated jointly" in verdict(bare)[0].text
    # a step claimed under its own name says nothing of the sort
    own = _rival_tree(["rotor_interference", "motor_lag"])
    assert "share is that of" not in verdict(own)[0].text
    assert "motor_lag 5 %)." in verdict(own)[0].text


def _file(rmse: dict[str, float], physics: dict[str, float], effects: dict[str, Any]) -> dict:
    return {
        "models": [{"name": "m.npz", "effects": effects}],
        "metrics": {
            "nominal": {"rmse": {"x": 0.3, "y": 0.3, "z": 0.1}},
            "effects": {"rmse": physics},
            "model": {"rmse": rmse},
        },
        "diagnosis": {
            "method": {"measurement_noise_std": 0.001},
            "missing": ["rotational_drag"],
            "missing_effects": [
                {
                    "name": "rotational_drag",
                    "explained_variance": 0.5,
                    "explained_variance_per_axis": {"x": 0.5, "y": 0.9, "z": 0.2},
                    "parameters": {"D": [0.05, 0.05, 0.002], "D_stderr": [0.002, 0.002, 0.001]},
                }
            ],
        },
    }


def test_a_misfitted_parameter_and_the_part_that_rose_are_one_sentence():
    """The worse axis said the parameter's misfit, then "; the physics-only error ...:
    the refitted effects made z worse, not the GP" as a second finding (or, where the GP
    rose, "not the effects" right after blaming the effect's estimate)."""
    drag = {"rotational_drag": {"D": [0.05, 0.05, 0.036], "D_stderr": [0.002, 0.002, 0.005]}}
    before = _file({"x": 0.1, "y": 0.2, "z": 0.04}, {"x": 0.3, "y": 0.3, "z": 0.05}, {})
    misfit = (
        "D_z is 0.036 ± 0.005 as fitted on the fit flight but 0.002 ± 0.001 from the "
        "evaluated log, 6.7 standard errors apart: the fit flight did not pin it down (fit on "
        "both logs, or plan a flight with plan --objective effects)"
    )
    # the physics-only error rose with the model's: the parameter is the cause
    after = _file({"x": 0.06, "y": 0.1, "z": 0.05}, {"x": 0.1, "y": 0.1, "z": 0.0625}, drag)
    line = change_lines(scores_of_files([(before, "a.json"), (after, "b.json")]))[1]
    assert line.text == (
        "Axis z got worse (+25.0 %): the refitted effects made z worse, not the GP (the "
        "physics-only error on z rose 0.05 → 0.0625 rad/s² (+25.0 %) and the model's error "
        f"relative to it went 0.80× → 0.80×), since {misfit}."
    )
    # the physics-only error fell, the GP's part rose: the misfit is a by-the-way
    gp = copy.deepcopy(after)
    gp["metrics"]["effects"]["rmse"]["z"] = 0.045
    line = change_lines(scores_of_files([(before, "a.json"), (gp, "b.json")]))[1]
    assert line.text.startswith(
        "Axis z got worse (+25.0 %): the refitted GP made z worse, not the effects (the "
        "physics-only error on z fell 0.05 → 0.045 rad/s² (−10.0 %) and the model's error "
        "relative to it went 0.80× → 1.11×), though D_z is 0.036 ± 0.005"
    )
    assert line.text.count("made z worse") == 1


def test_a_change_between_evaluations_of_different_samples_says_so():
    """A new user's report of an evaluation on one log and one on two logs read "With
    rotor_interference added: the model error falls by 53.4 %": the nominal errors,
    which do not depend on the model, showed the samples differed; the line says so."""
    before = _file({"x": 0.2, "y": 0.3, "z": 0.07}, {"x": 0.3, "y": 0.4, "z": 0.08}, {})
    after = _file({"x": 0.1, "y": 0.15, "z": 0.05}, {"x": 0.2, "y": 0.3, "z": 0.06}, {"a": {}})
    same = change_lines(scores_of_files([(before, "a.json"), (after, "b.json")]))[0].text
    assert same == (
        "With a added (a.json → b.json): the model error falls by 47.4 % (sum over axes) — "
        "x −50.0 %, y −50.0 %, z −28.6 %."
    )
    after["metrics"]["nominal"]["rmse"] = {"x": 0.933, "y": 1.08, "z": 0.142}
    other = change_lines(scores_of_files([(before, "a.json"), (after, "b.json")]))[0].text
    assert other == same[:-1] + (
        "; but not on the same samples (the nominal model's error differs: x 0.3 → 0.933, "
        "y 0.3 → 1.08, z 0.1 → 0.142 rad/s²), so this compares the flights as much as the "
        "models: evaluate both models on one flight (evaluate LOG --model A --model B) to "
        "compare them."
    )
    del after["metrics"]["nominal"]  # an older file without it: nothing to go by
    assert change_lines(scores_of_files([(before, "a.json"), (after, "b.json")]))[0].text == same


def test_a_fall_of_the_sum_over_axes_names_the_axes_that_rose():
    """A new user's report read "the model error falls by 2.9 % (sum over axes) — x
    +9.9 %, y +0.4 %, z −19.0 %": two axes of three got worse under a headline that
    said it fell; the headline now names them."""
    before = _file({"x": 0.2, "y": 0.3, "z": 0.5}, {"x": 0.3, "y": 0.4, "z": 0.6}, {})
    after = _file({"x": 0.22, "y": 0.301, "z": 0.4}, {"x": 0.3, "y": 0.4, "z": 0.6}, {"a": {}})
    lines = change_lines(scores_of_files([(before, "a.json"), (after, "b.json")]))
    assert lines[0].text == (
        "With a added (a.json → b.json): the model error falls by 7.9 % (sum over axes), "
        "but rises on x and y — x +10.0 %, y +0.3 %, z −20.0 %."
    )
    assert [ln.text.split(" (")[0] for ln in lines[1:]] == ["Axis x got worse"]


def test_a_fall_measured_after_an_effect_held_back_names_why_it_was_held_back():
    """`evaluate --model gp.npz --model gp-ri.npz` (a new user's trial): "although this
    model's diagnosis claimed nothing missing (rotor_interference: it passed its tests but
    another was preferred)" when the diagnosis had held it back as not pinned down."""
    from omavctl.diagnose.change import verdict_of_models

    def metrics(rmse: float) -> dict[str, Any]:
        return {
            "nominal": {"rmse": {a: 0.3 for a in "xyz"}},
            "model": {"rmse": {a: rmse for a in "xyz"}},
        }

    tree = {
        "models": [
            {"name": "gp.npz", "effects": {}},
            {"name": "gp-ri.npz", "effects": {"rotor_interference": {}}},
        ],
        "metrics": metrics(0.2),
        "metrics_by_model": [metrics(0.2), metrics(0.1)],
        "diagnosis": {
            "method": {"min_explained_variance": 0.15, "min_t_value": 4.0},
            "missing": [],
            "missing_effects": [
                {"name": "rotor_interference", "explained_variance": 0.23, "t_value": 14.5}
            ],
            "not_pinned": [{"name": "rotor_interference", "estimate": {}, "axes": ["x", "y"]}],
            "unexplained": [],
        },
    }
    assert verdict_of_models(tree)[0].text == (
        "Missing: rotor_interference, measured — with it added (gp-ri.npz) the model error on "
        "the same flight falls by 50.0 % (sum over axes), although this model's diagnosis "
        "claimed nothing missing (rotor_interference: estimated on this flight as fit would, "
        "its 95 % interval did not exclude the value at which it is absent: not pinned down)."
    )


def test_a_worst_segment_barely_above_the_flights_error_is_not_called_a_failure():
    """`Fails most at 1.8–2.8 s of d2.bag: y error 0.337 rad/s² RMS, 1.1× its overall`
    (a new user's wobble flight) sent them looking at a second that is like the rest."""
    seg = {
        "log": "d2.bag",
        "start": 1.8,
        "end": 2.8,
        "rmse": {"x": 0.2, "y": 0.337, "z": 0.07},
        "attitude_deg": [1.0, 1.0, 0.0],
        "rate": [0.4, 0.1, 0.0],
    }
    tree = {
        "metrics": {"model": {"rmse": {"x": 0.205, "y": 0.298, "z": 0.074}}},
        "worst_segments": [seg],
        "diagnosis": {"missing": [], "missing_effects": [], "unexplained": []},
    }
    (line,) = [ln for ln in verdict(tree) if ln.key == "fails"]
    assert line.text == (
        "No part of the flight stands out: the worst segment, 1.8–2.8 s of d2.bag (near "
        "level, rolling at 0.40 rad/s), has a y error of 0.337 rad/s² RMS, only 1.1× its "
        "overall."
    )
    seg["rmse"] = {"x": 0.337, "y": 0.2, "z": 0.07}  # "an x error", not "a x error"
    tree["metrics"]["model"]["rmse"]["x"] = 0.3
    (line,) = [ln for ln in verdict(tree) if ln.key == "fails"]
    assert "(near level, rolling at 0.40 rad/s), has an x error of 0.337 rad/s² RMS" in line.text
    seg["rmse"] = {"x": 0.2, "y": 0.337, "z": 0.07}
    tree["metrics"]["model"]["rmse"]["x"] = 0.205
    tree["metrics"]["model"]["rmse"]["y"] = 0.2  # 1.7×: it stands out
    (line,) = [ln for ln in verdict(tree) if ln.key == "fails"]
    assert line.text.startswith("Fails most at 1.8–2.8 s of d2.bag: y error 0.337 rad/s² RMS")


def test_a_worse_axis_and_the_disagree_line_say_one_parameters_disagreement_once():
    """`evaluate held.bag --model a.npz --model b.npz` (b adds rotational_drag, fitted on
    fit.bag): "Axis z got worse: ... D_z is 0.036 ± 0.005 as fitted on the fit flight but
    0.002 ± 0.001 from the evaluated log, 6.7 standard errors apart" and, lines later,
    "With b.npz: the fit flight and this one disagree: rotational_drag's D_z = 0.036 ±
    0.005 as fitted, 0.0021 ± 0.001 on this flight (6.6 ...)": one parameter on one pair
    of flights, said twice with two sets of numbers. The disagree line (both estimates as
    fit --effects makes them, the flights named) says it; the worse axis points to it."""
    from omavctl.diagnose.change import report_verdict, verdict_of_models

    drag = {"rotational_drag": {"D": [0.05, 0.05, 0.036], "D_stderr": [0.002, 0.002, 0.005]}}
    before = _file({"x": 0.1, "y": 0.2, "z": 0.04}, {"x": 0.3, "y": 0.3, "z": 0.05}, {})
    after = _file({"x": 0.06, "y": 0.1, "z": 0.05}, {"x": 0.1, "y": 0.1, "z": 0.0625}, drag)
    here = {"D": [0.05, 0.05, 0.0021], "D_stderr": [0.002, 0.002, 0.001]}
    learned = [
        {
            "name": "rotational_drag",
            "units": {"D": "1/rad"},
            "explained_variance_per_axis": {"x": 0.5, "y": 0.9, "z": 0.2},
            "estimate": here,
        }
    ]
    tree = copy.deepcopy(before)
    tree["models"] = [before["models"][0], {**after["models"][0], "name": "b.npz"}]
    tree["models"][1]["fit_flight"] = {"logs": ["fit.bag"], "time_window": None}
    tree["logs"] = [{"name": "held.bag"}]
    tree["metrics_by_model"] = [before["metrics"], after["metrics"]]
    tree["diagnosis"]["learned"] = learned
    disagree = (
        "rotational_drag's D_z = 0.036 ± 0.005 1/rad as fitted, 0.0021 ± 0.001 1/rad on this "
        "flight (6.6 combined standard errors apart)"
    )
    pointer = (
        "since rotational_drag's D_z as fitted on the fit flight disagrees with its estimate "
        "on the evaluated log (both, with their standard errors, in the line below that says "
        "the fit flight and this one disagree)."
    )
    texts = [ln.text for ln in verdict_of_models(tree)]
    assert sum("0.036 ± 0.005" in t for t in texts) == 1
    (worse,) = [t for t in texts if t.startswith("Axis z got worse")]
    assert worse.endswith(pointer)
    (said,) = [t for t in texts if "disagree:" in t]
    assert said.startswith(f"With b.npz: the fit flight and this one disagree: {disagree}.")
    assert texts.index(worse) < texts.index(said)
    # a report of the two evaluation files of that flight: the same, once
    last = {**copy.deepcopy(after), "logs": [{"name": "held.bag"}]}
    last["models"][0]["fit_flight"] = {"logs": ["fit.bag"], "time_window": None}
    last["diagnosis"]["learned"] = learned
    texts = [ln.text for ln in report_verdict([(before, "a.json"), (last, "b.json")])]
    assert sum("0.036 ± 0.005" in t for t in texts) == 1
    (worse,) = [t for t in texts if t.startswith("Axis z got worse")]
    assert worse.endswith(pointer)
    # the first file of another flight: the change is about another pair of flights
    other = copy.deepcopy(before)
    other["metrics"]["nominal"]["rmse"]["z"] = 0.2
    texts = [ln.text for ln in report_verdict([(other, "a.json"), (last, "b.json")])]
    assert sum("0.036 ± 0.005" in t for t in texts) == 2


def test_a_change_that_does_not_hold_rolled_out_says_so_in_the_verdict():
    """Crazyflie halves, `evaluate --model base.npz --model base+motor_lag.npz`: the
    verdict said "With motor_lag added: the model error falls by 44.8 %", and only
    below the horizons table did it say that the lag model's 0.5 s body-rate error was
    1.97 -> 5.16 (x) and 2.35 -> 7 (y) rad/s. The verdict now says it after the
    change; without that finding (or for physics + effects alone) nothing is added."""
    from omavctl.diagnose.change import verdict_of_models

    def rows(x: tuple[float, ...], y: tuple[float, ...]) -> list[dict[str, Any]]:
        return [{"rate_error": {"x": a, "y": b, "z": 0.01}} for a, b in zip(x, y, strict=True)]

    lag = {"motor_lag": {"T_m": [0.064], "T_m_stderr": [0.0097]}}
    before = _file({"x": 26.4, "y": 39.9, "z": 1.46}, {"x": 36.4, "y": 42.2, "z": 1.51}, {})
    after = _file({"x": 15.6, "y": 19.8, "z": 2.07}, {"x": 16.1, "y": 20.4, "z": 2.24}, lag)
    tree = copy.deepcopy(before)
    tree["models"] = [{"name": "base.npz", "effects": {}}, {"name": "lag.npz", "effects": lag}]
    tree["metrics_by_model"] = [before["metrics"], after["metrics"]]
    hurts = [
        {"code": "effect_added_hurts_long", "model": 1, "axis": a, "value": 2.6,
         "message": f"model 1: {a}: the full model of model 1 against model 0 lowers ..."}
        for a in ("x", "y")
    ]  # fmt: skip
    tree["horizons"] = {
        "seconds": [0.01, 0.1, 0.5],
        "table": {"model": rows((0.244, 1.51, 1.97), (0.247, 1.8, 2.35)),
                  "model_1": rows((0.127, 1.22, 5.16), (0.15, 1.46, 7.0))},
        "findings": hurts,
    }  # fmt: skip
    texts = [ln.text for ln in verdict_of_models(tree)]
    fall = next(i for i, t in enumerate(texts) if t.startswith("With motor_lag added"))
    (rolled,) = [t for t in texts if t.startswith("Rolled out open loop")]
    assert texts.index(rolled) > fall
    assert rolled == (
        "Rolled out open loop, lag.npz does worse than base.npz on x, y, although better "
        "one step ahead: the body-rate error at 0.5 s goes x 1.97 → 5.16, y 2.35 → 7 rad/s "
        "(at 0.01 s x 0.244 → 0.127, y 0.247 → 0.15; beyond 2 standard errors): the change "
        "above is the one-step angular acceleration's and does not hold that far ahead (the "
        "horizons table; docs/horizons.md)."
    )
    # holding the state errs x 1.99, y 2.33 at 0.5 s: the lag model is worse than that too
    tree["horizons"]["table"]["naive"] = rows((0.3, 1.6, 1.99), (0.3, 1.9, 2.33))
    (rolled,) = [t for t in verdict_of_models(tree) if t.text.startswith("Rolled out")]
    assert rolled.text.endswith(
        "(the horizons table; docs/horizons.md); there, on those axes, it does worse than "
        "holding the state (x 1.99, y 2.33 rad/s; the table's ranking is by the norm over "
        "the axes)."
    )
    for f in hurts:  # nominal + effects only: the full model is what the change quotes
        f["message"] = f["message"].replace("the full model", "nominal + effects")
    assert not [t for t in verdict_of_models(tree) if t.text.startswith("Rolled out")]


def test_a_two_file_report_says_the_change_does_not_hold_rolled_out_as_one_file_does():
    """`report base.json lag.json` (the Crazyflie halves, each file one model on log15's
    second half) said "With motor_lag added: the model error falls by 44.8 %" and not
    the line `evaluate --model base.npz --model lag.npz` gives after it (eyes6): the
    lag model's 0.5 s body-rate error x 1.97 -> 5.16, y 2.35 -> 7 rad/s. Said from
    the two files' full models when they are of the same samples and their paired
    chunk means put the rise beyond 2 standard errors; not on z (within them)."""
    from omavctl.diagnose.change import report_verdict

    def rows(x: tuple[float, ...], y: tuple[float, ...], dz: float) -> list[dict[str, Any]]:
        # chunk means: x and y rise by about their mean at every chunk, z scatters
        return [
            {
                "rate_error": {"x": a, "y": b, "z": 0.1 + dz},
                "rate_error_chunks": {
                    "x": [a * (1 + 0.01 * k) for k in range(6)],
                    "y": [b * (1 + 0.01 * k) for k in range(6)],
                    "z": [0.1 + dz * (-1) ** k * 5 for k in range(6)],
                },
            }
            for a, b in zip(x, y, strict=True)
        ]

    lag = {"motor_lag": {"T_m": [0.064], "T_m_stderr": [0.0097]}}
    before = _file({"x": 26.4, "y": 39.9, "z": 1.46}, {"x": 36.4, "y": 42.2, "z": 1.51}, {})
    after = _file({"x": 15.6, "y": 19.8, "z": 2.07}, {"x": 16.1, "y": 20.4, "z": 2.24}, lag)
    secs = [0.01, 0.1, 0.5]
    base_rows = rows((0.244, 1.51, 1.97), (0.247, 1.8, 2.35), 0.0)
    lag_rows = rows((0.127, 1.22, 5.16), (0.15, 1.46, 7.0), -0.01)
    before["horizons"] = {"seconds": secs, "table": {"model": base_rows}}
    after["horizons"] = {"seconds": secs, "table": {"model": lag_rows}}
    # the z error falls at 0.01 s and rises at 0.5 s, but within its standard error
    after["horizons"]["table"]["model"][-1]["rate_error"]["z"] = 0.12
    lines = report_verdict([(before, "base.json"), (after, "lag.json")])
    texts = [ln.text for ln in lines]
    fall = next(i for i, t in enumerate(texts) if t.startswith("With motor_lag added"))
    (rolled,) = [ln for ln in lines if ln.text.startswith("Rolled out open loop")]
    assert texts.index(rolled.text) > fall and rolled.who == "base.json → lag.json"
    assert rolled.text.startswith(
        "Rolled out open loop, lag.json does worse than base.json on x, y, although better "
        "one step ahead: the body-rate error at 0.5 s goes x 1.97 → 5.16, y 2.35 → 7 rad/s "
        "(at 0.01 s x 0.244 → 0.127, y 0.247 → 0.15; beyond 2 standard errors): "
    )
    # the files given the other way round: the same line (the change is effects added)
    back = report_verdict([(after, "lag.json"), (before, "base.json")])
    assert rolled.text in [ln.text for ln in back]
    # not of the same samples: the files compare flights, and nothing is said
    after["metrics"]["nominal"]["rmse"]["z"] = 0.2
    assert not [ln for ln in report_verdict([(before, "b"), (after, "l")]) if "Rolled" in ln.text]


def test_a_value_the_fit_flight_did_not_pin_and_this_one_does_is_said():
    """Own tune draw own-inertia 12: a drag's D_z fitted on a steps flight that hardly yaws
    (-0.0074, 95 %: 0 to 0.379, not pinned) while the held-out flight pins 0.121 (0.0963 to
    0.145) and keeps a z error of 0.51 rad/s² under "Nothing missing"; 1.5 combined
    standard errors apart, so the disagree line said nothing."""
    from omavctl.diagnose.fit_vs_flight import pinned_here_line

    fitted = {"D": [0.05, 0.05, -0.0074], "D_stderr": [0.002, 0.002, 0.086],
              "D_ci95": [[0.046, 0.054], [0.046, 0.054], [0.0, 0.379]],
              "D_pinned": [True, True, False]}  # fmt: skip
    here = {"D": [0.05, 0.05, 0.121], "D_stderr": [0.002, 0.002, 0.011],
            "D_ci95": [[0.046, 0.054], [0.046, 0.054], [0.0963, 0.145]],
            "D_pinned": [True, True, True]}  # fmt: skip
    entry = {"name": "rotational_drag", "units": {"D": "N m s^2"}, "estimate": here,
             "explained_variance_per_axis": {"x": 0.46, "y": 0.0, "z": 0.83}}  # fmt: skip
    tree = {
        "models": [{"name": "m.npz", "effects": {"rotational_drag": fitted},
                    "fit_flight": {"logs": ["fit.mcap"], "time_window": None}}],
        "logs": [{"name": "held.bag"}],
        "diagnosis": {"learned": [entry]},
    }  # fmt: skip
    line = pinned_here_line(tree)
    assert line is not None and line.key == "pinned_here"
    assert line.text == (
        "This flight pins down what the fit flight did not: rotational_drag's D_z = -0.0074 "
        "± 0.086 N m s^2 as fitted (95 %: 0 to 0.379), 0.121 ± 0.011 N m s^2 here (95 %: "
        "0.0963 to 0.145). Fitted on fit.mcap, which did not pin it down; estimated on "
        "held.bag as fit --effects would. The model's value is one the fit flight could not "
        "check: fit on both flights together (omavctl fit takes several logs) to pin it in "
        "the model."
    )
    # beside the model it was added to (a new user's --model cf.npz --model cf+lag.npz)
    two = {**tree, "models": [{"name": "base.npz", "effects": {}}, {**tree["models"][0]}]}
    line = pinned_here_line(two)
    assert line is not None and line.text.startswith(
        "With m.npz, this flight pins down what the fit flight did not: rotational_drag's D_z"
    )
    here["D_ci95"][2] = [-0.01, 0.145]  # this flight's interval holds the model's value
    assert pinned_here_line(tree) is None
    here["D_ci95"][2] = [0.0963, 0.145]
    entry["explained_variance_per_axis"]["z"] = 0.01  # not claimed on z here
    assert pinned_here_line(tree) is None


def test_a_falling_model_error_says_when_its_physics_rose():
    """A new user refitted on a flight planned with --objective effects: "From gp.npz to
    gp-eff.npz: the model error falls by 13.5 %" while the table showed physics + effects
    x 0.035 -> 0.058, y 0.069 -> 0.094: the refitted effects predicted worse alone."""
    from omavctl.diagnose.change import verdict_of_models

    drag = {"rotational_drag": {"D": [0.05, 0.05, 0.03], "D_stderr": [0.002, 0.002, 0.005]}}
    before = _file(
        {"x": 0.034, "y": 0.064, "z": 0.051}, {"x": 0.035, "y": 0.0685, "z": 0.076}, drag
    )
    after = _file(
        {"x": 0.0345, "y": 0.049, "z": 0.043}, {"x": 0.0576, "y": 0.094, "z": 0.0727}, drag
    )
    tree = copy.deepcopy(before)
    tree["models"] = [before["models"][0], {**after["models"][0], "name": "gp-eff.npz"}]
    tree["metrics_by_model"] = [before["metrics"], after["metrics"]]
    (line,) = [ln for ln in verdict_of_models(tree) if ln.text.startswith("From m.npz")]
    assert line.text.endswith(
        "; its nominal + effects error rose on x (+64.6 %), y (+37.2 %): there the refitted "
        "effects alone predict worse, the GP carries the fall."
    )
    # a Crazyflie's motor lag (a new user): physics x, y fell by half and z rose 48 %,
    # the model's z rose too (+42 %): the fall is the physics', z's rise not the GP's
    lag = copy.deepcopy(tree)
    lag["metrics_by_model"][0]["model"]["rmse"] = {"x": 26.4, "y": 39.9, "z": 1.458}
    lag["metrics_by_model"][0]["effects"]["rmse"] = {"x": 36.4, "y": 42.2, "z": 1.507}
    lag["metrics_by_model"][1]["model"]["rmse"] = {"x": 15.6, "y": 19.8, "z": 2.072}
    lag["metrics_by_model"][1]["effects"]["rmse"] = {"x": 16.1, "y": 20.4, "z": 2.236}
    lines = [ln.text for ln in verdict_of_models(lag)]
    (line,) = [t for t in lines if t.startswith("From m.npz")]
    assert "GP carries" not in line and "but rises on z" in line
    assert any(t.startswith("Axis z got worse (+42.1 %)") for t in lines)
    tree["metrics_by_model"][1]["effects"]["rmse"] = {"x": 0.036, "y": 0.07, "z": 0.07}
    (line,) = [ln for ln in verdict_of_models(tree) if ln.text.startswith("From m.npz")]
    assert "nominal + effects error rose" not in line.text  # under 20 %: not said


def test_a_worse_axis_names_a_kept_effects_parameter_the_refit_moved():
    """A new user added com_offset to a Betaflight model and x got 97 % worse; the line
    blamed com_offset's r_x (indistinguishable from 0) while the refit had moved the
    kept inertia_error's scale_x -7.91 -> -4.39 (its gain -0.126 -> -0.228)."""
    from omavctl.diagnose.change import verdict_of_models

    kept = {"scale": [-7.91, -35.7, 2.45], "scale_stderr": [51.5, 375.0, 2.9]}
    before = _file(
        {"x": 20.2, "y": 7.34, "z": 8.83},
        {"x": 20.4, "y": 7.34, "z": 8.78},
        {"inertia_error": kept},
    )
    moved = {**kept, "scale": [-4.39, -36.3, 2.45], "scale_systematic": [0.3, 60.0, 0.8]}
    com = {"r": [-1.52e-05, 0.002, 0.0], "r_stderr": [0.0014, 0.05, 0.05]}
    tree = copy.deepcopy(before)
    tree["models"].append(
        {"name": "m+com.npz", "effects": {"inertia_error": moved, "com_offset": com}}
    )
    tree["metrics_by_model"] = [
        before["metrics"],
        {**before["metrics"], "model": {"rmse": {"x": 39.8, "y": 7.13, "z": 8.83}},
         "effects": {"rmse": {"x": 40.6, "y": 7.13, "z": 8.78}}},
    ]  # fmt: skip
    (line,) = [ln.text for ln in verdict_of_models(tree) if ln.text.startswith("Axis x got")]
    assert "its fitted r_x = -1.52e-05 ± 0.0014 is indistinguishable from 0" in line
    assert "the refit moved inertia_error's scale_x -7.91 → -4.39" in line
    assert "scale_y" not in line and "systematic" not in line  # moved 2 %; not a parameter
    assert line.endswith("the refitted effects made x worse, not the GP.")


def test_a_report_of_two_files_compares_the_last_files_last_model():
    """`report base.json both.json`, both.json evaluated with the base model and the one
    with the lag: the verdict said "the model error rises by 0.0 %" (both.json's first
    model, the base model again) and left out both.json's own change lines."""
    from omavctl.diagnose.change import report_verdict

    lag = {"motor_lag": {"T_m": [0.064], "T_m_stderr": [0.01]}}
    base = _file({"x": 26.4, "y": 39.9, "z": 1.46}, {"x": 36.4, "y": 42.2, "z": 1.51}, {})
    after = _file({"x": 15.6, "y": 19.8, "z": 2.07}, {"x": 16.1, "y": 20.4, "z": 2.24}, lag)
    both = copy.deepcopy(base)
    both["models"].append({**after["models"][0], "name": "m+lag.npz"})
    both["metrics_by_model"] = [base["metrics"], after["metrics"]]
    lines = report_verdict([(base, "base.json"), (both, "both.json")])
    steps = [ln.text for ln in lines if ln.who == "base.json → both.json"]
    assert steps[0].startswith("With motor_lag added: the model error falls by 44.")
    assert "x −40.9 %, y −50.4 %, z +41.8 %" in steps[0]
    own = [ln.text for ln in lines if ln.who == "both.json" and ln.key == "change"]
    assert any(t.startswith("With motor_lag added (m.npz → m+lag.npz)") for t in own)


def test_three_models_in_one_evaluation_show_every_step_not_only_first_to_last():
    """`evaluate --model a --model b --model c` wrote one change line, a → c: a step
    b → c that made z worse hid behind the overall fall (the report of three files
    already gave every step). Now each step, then first to last."""
    from omavctl.diagnose.change import verdict_of_models

    drag = {"rotational_drag": {"D": [0.05, 0.05, 0.036]}}
    both = {**drag, "com_offset": {"r": [0.001, 0.0, 0.0]}}
    a = _file({"x": 0.1, "y": 0.2, "z": 0.04}, {"x": 0.3, "y": 0.3, "z": 0.05}, {})
    b = _file({"x": 0.06, "y": 0.1, "z": 0.036}, {"x": 0.1, "y": 0.1, "z": 0.04}, drag)
    c = _file({"x": 0.058, "y": 0.095, "z": 0.039}, {"x": 0.09, "y": 0.1, "z": 0.04}, both)
    tree = copy.deepcopy(a)
    tree["models"] = [{"name": "a.npz", "effects": {}}, {"name": "b.npz", "effects": drag},
                      {"name": "c.npz", "effects": both}]  # fmt: skip
    tree["metrics_by_model"] = [a["metrics"], b["metrics"], c["metrics"]]
    texts = [ln.text for ln in verdict_of_models(tree) if ln.key == "change"]
    falls = [t for t in texts if t.startswith("With ")]
    assert [t.split(":")[0] for t in falls] == [
        "With rotational_drag added (a.npz → b.npz)",
        "With com_offset added (b.npz → c.npz)",
        "With rotational_drag, com_offset added (a.npz → c.npz)",
    ]
    assert "z +8.3 %" in falls[1] and "but rises on z" in falls[1]
    assert any(t.startswith("Axis z got worse (+8.3 %)") for t in texts)
    # two models: one line, as before
    tree["models"], tree["metrics_by_model"] = tree["models"][:2], tree["metrics_by_model"][:2]
    texts = [ln.text for ln in verdict_of_models(tree) if ln.key == "change"]
    assert [t.split(":")[0] for t in texts if t.startswith("With ")] == [
        "With rotational_drag added (a.npz → b.npz)"
    ]
