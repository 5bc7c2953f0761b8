"""Effect units on vehicles with normalised commands, in the diagnosis and the report:
as ``fit`` shows them (omavctl/learn/fit_notes.py ``effect_unit``), not in metres or
newton metres the commands are not in (a CoM offset is then a torque per force)."""

from __future__ import annotations

import copy

from omavctl.diagnose.diagnosis_commands import display_units
from omavctl.diagnose.estimate_text import estimate_sentence
from omavctl.report.diagnosis import fitted_effect_items

TREE = {
    "missing": ["com_offset"],
    "missing_effects": [
        {"name": "com_offset", "units": {"r": "m"}},
        {"name": "rotational_drag", "units": {"D": "N m s^2"}},
        {"name": "inertia_error", "units": {"scale": "1"}},
    ],
    "not_pinned": [
        {"name": "drag_moment", "units": {"h": "m"}, "beside_lag": {"lag": "motor_lag"}}
    ],
    "learned_steps": [{"name": "motor_lag", "units": {"T_m": "s"}}],
    "fit_command": "omavctl fit ...",
}


def _units(tree):
    out = {e["name"]: e["units"] for e in tree["missing_effects"]}
    out.update({e["name"]: e["units"] for e in tree["not_pinned"] + tree["learned_steps"]})
    return out


def test_normalised_torque_units_in_every_entry_at_any_depth():
    tree = copy.deepcopy(TREE)
    display_units(tree, {"torque": "normalised", "force": "N"})
    assert _units(tree) == {
        "com_offset": {"r": "[torque unit]/N"},
        "rotational_drag": {"D": "[torque unit] s^2"},
        "inertia_error": {"scale": "1"},
        "drag_moment": {"h": "[torque unit]/N"},
        "motor_lag": {"T_m": "s"},  # a time whatever the command's unit (eyes6)
    }
    assert tree["fit_command"] == TREE["fit_command"]


def test_a_lag_on_normalised_commands_is_a_time_and_fit_gives_the_unit_free_value():
    """T_m was shown "s (x torque gain)". A simulated 50 ms motor lag whose torque
    command was logged divided by 0.2 gave T_m = 9.6 ms in the form the model predicts
    with (lag + (g - 1) x command: about T_m x gain) and 50.4 ms with the gain on the
    timed torque (g x lag); divided by 5, 213 and 49.6 ms. The unit is s, and on a
    normalised command fit says which value is the time, however small its gap."""
    from omavctl.learn.effect_search import SearchResult
    from omavctl.learn.fit_notes import effect_unit, search_notes

    normalised = {"torque": "normalised", "force": "normalised"}
    assert effect_unit("motor_lag", "s", normalised) == "s"
    assert effect_unit("servo_lag", "s", normalised) == "s"
    found = {"motor_lag": SearchResult("motor_lag", 0.0096, 0.029, False, coupled=0.0504,
                                       gain_allowance=0.029)}  # fmt: skip
    (_, note) = search_notes(found, normalised=True)
    assert note == (
        "motor_lag: T_m = 50.4 ms with the torque gain on the timed torque (g x lag): the "
        "time in s whatever the command's unit, the one to quote as the vehicle's; the "
        "9.6 ms above is of the form the model "
        "predicts with (lag + (g - 1) x command), which on normalised commands scales with "
        "their unit (about T_m x gain), and its standard error allows 29.0 ms for the "
        "difference"
    )
    # a small gap on N m commands says nothing (the forms agree where the gain is ~1);
    # on normalised ones the unit-free value is still given
    close = {"motor_lag": SearchResult("motor_lag", 0.049, 0.001, False, coupled=0.0496,
                                       gain_allowance=0.0004)}  # fmt: skip
    assert len(search_notes(close)) == 1
    assert "T_m = 49.6 ms with the torque gain" in search_notes(close, normalised=True)[1]


def test_physical_units_unchanged_and_force_normalised_offset():
    tree = copy.deepcopy(TREE)
    display_units(tree, {"torque": "N m", "force": "N"})
    assert tree == TREE
    display_units(tree, {"torque": "N m", "force": "normalised"})
    assert _units(tree)["com_offset"] == {"r": "N m/[force unit]"}
    assert _units(tree)["drag_moment"] == {"h": "m"}  # a measured force is in N


def test_the_verdict_sentence_and_the_report_say_the_unit():
    tree = copy.deepcopy(TREE)
    display_units(tree, {"torque": "normalised"})
    entry = {
        "name": "drag_moment",
        "units": tree["not_pinned"][0]["units"],
        "estimate": {"h": [0.044], "h_ci95": [[-0.001, 0.089]]},
    }
    assert "h = 0.044 [torque unit]/N (95 %:" in estimate_sentence(entry)
    model_effects = {"com_offset": {"r": [0.01, -0.02, 0.0], "r_stderr": [0.001] * 3}}
    text = str(fitted_effect_items(model_effects, True, True)[0])
    assert "r_x = 0.01 ± 0.001 [torque unit]/[force unit]" in text
    text = str(fitted_effect_items(model_effects, False)[0])
    assert "r_x = 0.01 ± 0.001 m" in text


def test_the_report_gives_the_spreads_part_and_says_why_the_interval_is_wide():
    """A fitted CoM offset whose interval the rotors' thrust spread widens: the report
    gives the spread's part beside the standard error, and where the flight's own
    interval excludes 0 it names the spread, not the flight, as the reason."""
    from omavctl.learn.intervals import SPREAD_WORDS

    effects = {
        "com_offset": {
            "r": [0.0036, 0.0, 0.0],
            "r_stderr": [0.0003, 0.0, 0.0],
            "r_systematic": [0.0018, 0.0, 0.0],
            "r_ci95": [[-0.00006, 0.0073], [0.0, 0.0], [0.0, 0.0]],
            "r_ci95_statistical": [[0.003, 0.0042], [0.0, 0.0], [0.0, 0.0]],
            "r_pinned": [False, False, False],
            "excited": [True, False, False],
        }
    }
    text = str(fitted_effect_items(effects, False)[0])
    assert f"r_x = 0.0036 ± 0.0003 (± 0.0018 spread) m [-6e-05, 0.0073]: {SPREAD_WORDS}" in text


def test_the_ranking_tables_say_which_residual_their_parameters_were_fitted_to():
    """The report quoted r_y three times with three values (the verdict's estimate, the
    fitted model, the ranking): each ranking's header says what its numbers are."""
    from omavctl.report.diagnosis import _ranking_table

    alone = {"r": [0.004, -0.008, 0.0], "r_stderr": [0.0003] * 3, "r_ci95": [[0.0034, 0.0046]] * 3}
    entry = {"name": "com_offset", "parameters": alone}
    table = _ranking_table([entry], False, "missing")
    assert table.columns[4] == (
        "parameters on the model's remaining error, each effect alone: a size of what the GP "
        "left, not the vehicle's value (no interval)"
    )
    assert table.rows[0][4].lines == ("r_x = 0.004", "r_y = -0.008", "r_z = 0")  # no ±, no [ ]
    fitted = {**entry, "estimate": {"r": [0.0036, -0.003, 0.0]}}
    columns = _ranking_table([fitted], False, "learned").columns
    assert "parameters on the nominal residual, as fit --effects estimates them" in columns[4]


def test_the_report_says_what_a_spread_is_and_which_interval_held_an_effect_back():
    """Seen in a rendered report (session 19): '(± 0.0019 spread)' beside every fitted
    parameter, never said what it was; and 'Not claimed, cannot be pinned down (the 95 %
    interval holds the value of no effect): inertia_error' above a table whose scale_y
    interval [1.02, 1.04] excludes 1 (that table fits each effect alone)."""
    from omavctl.learn.intervals import SPREAD_MEANING
    from omavctl.report.diagnosis import diagnosis_section, spread_legend
    from omavctl.report.document import Document, to_markdown

    fitted = {
        "scale": [1.0167, 0.9886, 0.992],
        "scale_stderr": [0.0253, 0.0664, 0.07],
        "scale_systematic": [0.0169, 0.0356, 0.0302],
        "scale_ci95": [[0.957, 1.076], [0.841, 1.136], [0.843, 1.141]],
        "scale_pinned": [False, False, False],
    }
    alone = {"scale": [1.012, 1.03, 0.9912], "scale_stderr": [0.0063, 0.0043, 0.0032]}
    alone["scale_ci95"] = [[0.999, 1.02], [1.02, 1.04], [0.985, 0.998]]
    diag = {
        "not_pinned": [{"name": "inertia_error", "units": {"scale": "1"}, "estimate": fitted}],
        "missing_effects": [{"name": "inertia_error", "parameters": alone}],
        "learned": [{"name": "com_offset", "estimate": {"r": [0.0155], "r_systematic": [0.0018]}}],
    }
    doc = Document("t", diagnosis_section({"diagnosis": diag}, 0, "eval.json"))
    text = to_markdown(doc).replace("\\", "")
    assert "Not claimed, cannot be pinned down from this flight: inertia_error (scale_x = " in text
    assert "scale_y = 0.9886 ± 0.066 (± 0.036 spread) [0.841, 1.14]; scale_z" in text
    assert "the table below fits each effect alone" in text
    assert text.count(SPREAD_MEANING) == 1  # under the ranking that shows a spread only
    # nothing missing: no 'after the top missing effect' above what the error keeps
    diag["unexplained"] = [{"axis": "y", "kind": "feature correlation", "correlation": -0.45}]
    text = to_markdown(Document("t", diagnosis_section({"diagnosis": diag}, 0, "e")))
    assert "Structure the model's error keeps, which no registered effect explains:" in text
    # the same words under a model's fitted effects (the report's summary)
    assert spread_legend([alone, fitted]) == [SPREAD_MEANING + "."]
    assert spread_legend([alone, {"r": [0.1], "r_systematic": [0.0]}]) == []


def test_a_component_no_flight_excites_is_not_called_at_its_bound():
    """Crazyflie log16 with a log15 model (session 19): fit's estimate of com_offset
    carries no 'excited' flags, and a quad's r_z (no force along z moves it) read
    'r_z = 0 m (at its bound: no std. error)' in the ranking and the held-back line;
    the same effect's ranking entry on the same log has the flags."""
    from omavctl.report.diagnosis import diagnosis_section
    from omavctl.report.document import Document, to_markdown

    est = {"r": [0.001, 0.0003, 0.0], "r_stderr": [0.0022, 0.002, 0.0]}
    est["r_ci95"] = [[-0.007, 0.009], [-0.008, 0.009], [0.0, 0.0]]
    learned = {"name": "com_offset", "estimate": est, "units": {"r": "m"}}
    learned["parameters"] = {"r": [0.00099, 0.00049, 0.0], "excited": [True, True, False]}
    diag = {
        "not_pinned": [{"name": "com_offset", "units": {"r": "m"}, "estimate": est}],
        "learned": [learned],
    }
    text = to_markdown(Document("t", diagnosis_section({"diagnosis": diag}, 0, "e")))
    text = text.replace("\\", "")
    assert "at its bound" not in text
    assert text.count("not excited: r_z") == 2  # the held-back line and the ranking
