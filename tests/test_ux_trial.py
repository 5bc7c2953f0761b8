"""What a new user hit in a trial on real and synthetic motor-output logs (issues
#26, #27, #28): each finding's exact words, checked on the object that says them."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from omavctl.learn.flights import LogSummary, upsampling_note
from omavctl.logs.types import TopicInfo


def _flight(log_hz: float, grid_hz: float, command_hz: float | None = None) -> SimpleNamespace:
    topics = [TopicInfo("body_rate", "csv", 1000, 10.0, log_hz)]
    topics.append(TopicInfo("motor_command", "csv", 1000, 10.0, command_hz or log_hz))
    return SimpleNamespace(topics=topics, rate=grid_hz)


def test_fit_notes_a_log_much_faster_than_the_grid_and_names_the_setting():
    """A 500 Hz log fitted on a vehicle without controller.rate_hz is fitted on the
    100 Hz grid (a 30 ms motor lag came out 26.4 ± 0.5 ms) and fit said nothing."""
    vehicle = SimpleNamespace(topics={})
    assert upsampling_note(_flight(499.99999, 100.0), vehicle) == (
        "body rate and command logged at 500 Hz, 5.0× the 100 Hz grid (controller.rate_hz): "
        "the fit sees one sample in 5 and resolves timing effects (motor_lag, command_delay) on a "
        "10 ms grid; set controller: {rate_hz: 500} in the vehicle YAML to fit at the "
        "log's own rate, with --sg-window about 5× as many samples, so that the derivative's "
        "filter spans the same time (the same samples at the faster rate span less of it: on "
        "the Crazyflie at 1011 Hz the held-out GP error on y rose 11.7 -> 15.1 rad/s² with the "
        "window left at 11)"
    )
    assert upsampling_note(_flight(190.0, 100.0), vehicle) is None
    # the simulated omav: IMU at 200 Hz, commands on the 100 Hz grid: nothing thrown away
    assert upsampling_note(_flight(200.0, 100.0, 100.0), vehicle) is None
    assert upsampling_note(_flight(100.0, 100.0), vehicle) is None
    assert upsampling_note(_flight(83.3, 100.0), vehicle).startswith("body rate logged at 83.3")


def test_fit_counts_the_out_of_control_samples_in_its_samples_line():
    """ "3845 of 6000 samples used (0 invalid ...; 10 at segment edges ...)" with the
    2145 out-of-control samples only in a later note: the line adds up."""
    from omavctl.cli.fit import samples_line

    log = LogSummary(Path("hexa0.csv"), 6000, 3845, 0, 6, 4, [], 2145)
    assert samples_line(log) == (
        "hexa0.csv: 3845 of 6000 samples used (0 invalid: in gaps, on the ground or outside "
        "the time window; 10 at segment edges or in short segments; 2145 out of control)"
    )


def _betaflight_log(tmp_path: Path, motor_output: str) -> Path:
    """A blackbox_decode CSV (2 kHz, gyro in deg/s, DShot motors, vbat in V) and its
    header sidecar with ``motorOutput``."""
    import numpy as np

    rng = np.random.default_rng(0)
    head = "loopIteration, time (us), gyroADC[0] (deg/s), gyroADC[1] (deg/s), gyroADC[2] (deg/s)"
    rows = [f"{head}, vbatLatest (V), motor[0], motor[1], motor[2], motor[3]"]
    for i in range(600):
        gyro = ", ".join(f"{v:.2f}" for v in rng.normal(0.0, 60.0, 3))
        motors = ", ".join(str(int(v)) for v in 138 + 1909 * rng.random(4))
        rows.append(f"{i}, {1_000_000 + 500 * i}, {gyro}, {12.6 - 1e-4 * i:.4f}, {motors}")
    path = tmp_path / "LOG00001.01.csv"
    path.write_text("\n".join(rows) + "\n")
    (tmp_path / "LOG00001.01.headers.txt").write_text(
        f"H Firmware revision:Betaflight 4.2.0\nH looptime:125\nH motorOutput:{motor_output}\n"
    )
    return path


def test_inspect_suggests_the_battery_voltage_and_keeps_dshots_zero_at_48(tmp_path: Path):
    """On the Betaflight CSV inspect left out battery_voltage although vbatLatest is
    read in volts; then (session 19) it gave the header's motorOutput 138,2047 as the
    rotor list's range, taking the armed idle for zero thrust. Betaflight sets
    motorOutput's low end to 48 + (2047 - 48) x digitalIdleOffset (4.5 %: 138), where
    the motors spin: the suggestion keeps the preset's DShot 48..2047 and says why."""
    from omavctl.logs.inspection import inspect_log
    from omavctl.vehicle import load_vehicle

    log = _betaflight_log(tmp_path, "138,2047")
    ins = inspect_log(log)
    assert ins.suggested_columns["battery_voltage"] == "vbatLatest"
    text = ins.suggestion
    assert (
        "# the log's header says motorOutput 138.0..2047.0: the firmware's output window, "
        "from its armed idle (idle offset 4.50 % of 48.0..2047.0) to full, not the command "
        "of zero thrust: keep the range [48.0, 2047.0] (docs/logs.md)\ncolumns:\n"
    ) in text
    assert "\nmotors:" not in text and "138.0, 2047.0" not in text
    vfile = tmp_path / "v.yaml"
    vfile.write_text(text)
    veh = load_vehicle(vfile)
    assert veh.motors is not None and len(veh.motors.rotors) == 4
    assert {r.span for r in veh.motors.rotors} == {(48.0, 2047.0)}
    assert veh.columns["battery_voltage"] == "vbatLatest"
    # the header agreeing with the preset: nothing to add, no header line
    same = inspect_log(_betaflight_log(tmp_path, "48,2047")).suggestion
    assert "nothing to add" in same and "motorOutput" not in same


def test_report_says_every_effect_its_fit_command_adds(tmp_path: Path):
    """`report` said "to add motor_lag to cf-eval.json's model:" above a command that
    adds motor_lag,motor_loss."""
    from rich.console import Console

    from omavctl.cli.report import _render_report

    cmd = "omavctl fit log10.csv --effects motor_lag,motor_loss --out m+motor_lag.npz"
    ev = SimpleNamespace(label="cf-eval.json", model_rmse={"x": 1.0, "y": 2.0, "z": 3.0},
                         missing=["motor_lag", "motor_loss"], fit_command=cmd,
                         models_rmse=[], model_names=[])  # fmt: skip
    summary = SimpleNamespace(verdict=[], evaluations=[ev], fmt="md", figures=0)
    con = Console(record=True, width=200)
    _render_report(con, summary, tmp_path / "r.md")
    text = con.export_text()
    assert f"to add motor_lag, motor_loss to cf-eval.json's model:\n  {cmd}\n" in text


def test_the_report_verdict_titles_a_sentence_once_and_sets_the_plan_command_in_code():
    """ "What is missing: Missing: motor_loss", and the separating plan command as
    plain text running on into "Add it with: omavctl fit ..."."""
    from omavctl.report.document import _md_inline
    from omavctl.report.top import verdict_section

    sep = "omavctl task fig8 --out m.fig8.csv && omavctl plan --model m.npz --out m.separate.csv"
    tree = {
        "diagnosis": {
            "missing": ["motor_loss"],
            "missing_effects": [
                {"name": "motor_loss", "explained_variance": 0.18, "ambiguous_with": ["com_offset"]}
            ],
            "separate_command": sep,
            "fit_command": "omavctl fit a.csv --effects motor_loss --out m+motor_loss.npz",
        }
    }
    items = [_md_inline(it) for it in verdict_section([(tree, None, "e.json")])[1].items]
    head = items[0]
    assert head.startswith("**Missing:** motor\\_loss — it explains 18 %")
    assert head.endswith(
        f"tells them apart: `{sep}`. Add it with: "
        "`omavctl fit a.csv --effects motor_loss --out m+motor_loss.npz`"
    )


def test_evaluate_says_when_the_horizons_ran_with_a_larger_stride_than_asked():
    """`stride_requested: 1` in the JSON, stride 8 used, and the terminal said nothing."""
    from rich.console import Console

    from omavctl.report.horizons import render_horizons

    row = {"seconds": 0.01, "steps": 1, "rate_error": {"x": 1.0, "y": 1.0, "z": 1.0, "norm": 1.7}}
    h = {"steps": [1], "seconds": [0.01], "band_sigma": 2.0, "windows": 3884, "attitude": False,
         "predictors": [{"key": "naive", "kind": "naive", "model": None}],
         "table": {"naive": [row]}, "findings": [], "stride": 8, "stride_requested": 1}  # fmt: skip
    con = Console(record=True, width=400)
    render_horizons(con, {"horizons": h})
    said = " ".join(con.export_text().split())  # the title wraps to the table's width
    assert said.startswith(
        "open-loop error over horizons (3884 windows, a start every 8 samples rather than "
        "at every one: the log is long and the windows are held in memory at once): mean norm "
        "of the body-rate error, rad/s (no attitude in the log; in brackets: the share of "
        "windows whose body-rate error lies inside the full model's 2σ band, over the three "
        "axes, with an axis under 85 % named)"
    )
    con = Console(record=True, width=400)
    render_horizons(con, {"horizons": {**h, "stride_requested": 4}})
    said = " ".join(con.export_text().split())
    assert "a start every 8 samples rather than every 4 (--horizon-stride): " in said
    con = Console(record=True, width=400)
    render_horizons(con, {"horizons": {**h, "stride": 1}})
    said = " ".join(con.export_text().split())
    assert said.startswith("open-loop error over horizons (3884 windows): mean norm")
    # --horizons 30 on a 20 s log: no table, and the terminal said nothing
    why = "no stretch of 3001 consecutive usable samples (30 s) in the logs: no horizon table"
    none = {**h, "table": {}, "findings": [{"code": "no_windows", "message": why}]}
    con = Console(record=True, width=400)
    render_horizons(con, {"horizons": none})
    assert " ".join(con.export_text().split()) == f"open-loop error over horizons: {why}"


def test_an_unpinned_interval_is_worded_by_what_it_holds():
    """ "D_z = 1.08 (95 %: 0.809 to 1.34, cannot be pinned down)": an interval that
    excludes 0 called not pinned down. It lies outside drag's plausible 0 to 1."""
    from omavctl.diagnose.estimate_text import estimate_sentence
    from omavctl.learn.intervals import pinned_down, unpinned_words

    assert not pinned_down("rotational_drag", "D", [[0.809, 1.34]])[0]
    assert unpinned_words("rotational_drag", "D", (0.809, 1.34), 2) == (
        "outside the plausible 0 to 1: not this effect alone, something else on this axis"
    )
    holds_zero = unpinned_words("rotational_drag", "D", (-0.01, 0.05), 0)
    assert holds_zero == "cannot be pinned down from this flight"
    entry = {
        "name": "rotational_drag",
        "units": {"D": "N m s^2"},
        "estimate": {"D": [0.0375, 0.0322, 1.08], "D_pinned": [True, True, False],
                     "D_ci95": [[0.0334, 0.0416], [0.0263, 0.0381], [0.809, 1.34]]},
    }  # fmt: skip
    text = estimate_sentence(entry, None)
    assert "D_z = 1.08 N m s^2 (95 %: 0.809 to 1.34 N m s^2, outside the plausible 0 to 1:" in text
    assert "pinned down" not in text
    # the report's parameter lines say the same
    from omavctl.report.params import _interval_note

    params = {"D": [0.0375, 0.0322, 1.08], "D_ci95": entry["estimate"]["D_ci95"],
              "D_pinned": [True, True, False]}  # fmt: skip
    assert _interval_note(params, "D", 2, "rotational_drag") == (
        " [0.809, 1.34]: outside the plausible 0 to 1: not this effect alone, something else "
        "on this axis"
    )


def test_report_prints_the_verdicts_commands_as_evaluate_does(tmp_path: Path):
    """`evaluate` printed each command on a line of its own ("    add it with: ..."),
    `report` ran it on at the end of the sentence ("... Add it with: omavctl fit ..."):
    the same verdict in two layouts, the command hard to pick out of the report's."""
    from rich.console import Console

    from omavctl.cli.report import _render_report
    from omavctl.diagnose.verdict_lines import Line
    from omavctl.report.summary import render_evaluation

    cmd = "omavctl fit f.bag --effects rotor_interference --out m+r.npz"
    line = Line("missing", "Nothing claimed as missing.", "e.json", cmd, test=True)
    ev = SimpleNamespace(label="e.json", model_rmse={"x": 1.0, "y": 2.0, "z": 3.0},
                         missing=[], fit_command=None, models_rmse=[], model_names=[])  # fmt: skip
    summary = SimpleNamespace(verdict=[line], evaluations=[ev], fmt="md", figures=0)
    con = Console(record=True, width=200)
    _render_report(con, summary, tmp_path / "r.md")
    text = con.export_text()
    assert f"  e.json: Nothing claimed as missing.\n    test it with: {cmd}\n" in text
    tree = {
        "diagnosis": {
            "missing": [],
            "not_pinned": [{"name": "rotor_interference", "estimate": {}, "axes": None}],
            "effect_commands": {"rotor_interference": cmd},
        }
    }
    con = Console(record=True, width=400)
    render_evaluation(con, tree, {})
    assert f"\n    test it with: {cmd}\n" in con.export_text()


def test_the_verdict_names_each_rotors_loss_as_fit_and_the_report_do():
    """The Betaflight verdict (smooth tune + motor_lag, evaluated on the better tune)
    said "l = 0.0169 (...); l = -0.0173 (...); l = -0.0169 (...); l = 0.0173 (...)":
    four losses, no rotor named, where fit's table and the report's ranking say l_0 ..
    l_3. A rotor beyond the vehicle's (its interval of zero width) is left out."""
    from omavctl.diagnose.estimate_text import estimate_sentence

    values = [0.0169, -0.0173, -0.0169, 0.0173] + [0.0] * 8
    cis = [[-0.0183, 0.0521], [-0.0525, 0.0179], [-0.0376, 0.00385], [-0.0138, 0.0484]]
    est = {"l": values, "l_ci95": cis + [[0.0, 0.0]] * 8, "l_pinned": [False] * 12}
    text = estimate_sentence({"name": "motor_loss", "estimate": est, "units": {"l": "1"}})
    for i, v in enumerate(values[:4]):
        assert f"l_{i} = {v:.3g} (95 %: " in text
    assert "l_4" not in text and "; l = " not in text and ": l = " not in text


def test_a_model_written_before_the_thrust_tolerance_is_flagged_where_intervals_are(
    tmp_path: Path, vehicle
):
    """A model file from before session 19 holds a vehicle without
    rotor.thrust_tolerance, read as 0: evaluate quoted its intervals without the
    systematic part and said nothing. Now one flag, in the verdict, names the file; a
    current file (the tolerance stored, 0.03) and a normalised vehicle without rotors
    (nothing to spread) get none."""
    import json

    import numpy as np

    from omavctl.diagnose.model_flags import spread_flags
    from omavctl.diagnose.verdict_lines import flag_lines
    from omavctl.learn.model_file import load_model, save_model
    from omavctl.vehicle import _build
    from tests.test_horizons import _model

    save_model(current := tmp_path / "current.npz", _model(vehicle))
    arrays = dict(np.load(current))
    tree = json.loads(str(arrays["vehicle"]))
    del tree["rotor"]["thrust_tolerance"]
    arrays["vehicle"] = np.array(json.dumps(tree))
    np.savez(old := tmp_path / "old.npz", **arrays)
    models = [load_model(current), load_model(old)]
    assert [m.vehicle.thrust_tolerance for m in models] == [0.03, 0.0]
    (flag,) = spread_flags(models, [current, old])
    assert flag["code"] == "no_thrust_tolerance" and flag["message"] == (
        f"{old}: written before omavctl read the rotors' thrust tolerance (its vehicle has "
        "no rotor.thrust_tolerance), so the 95 % intervals quoted for it hold no "
        "thrust-spread part and may be too narrow: refit the model (omavctl fit on the same "
        "logs) to add it"
    )
    assert [ln.text for ln in flag_lines({"flags": [flag]})] == [flag["message"]]
    tree["command_units"] = {"torque": "normalised", "force": "normalised"}
    normalised = _model(_build(tree, None, "test"))
    assert spread_flags([normalised], ["px4.npz"]) == []


def test_report_shows_each_models_rmse_of_a_file_with_several(tmp_path: Path):
    """`report halves-both.json` (evaluate --model half-base.npz --model half-lag.npz)
    printed one row, the file's name beside the first model's RMSE only; the HTML summary
    listed both model names beside those numbers."""
    from rich.console import Console

    from omavctl.cli.report import _render_report
    from omavctl.report.document import Document, to_markdown
    from omavctl.report.evaluation import EvaluationSummary
    from omavctl.report.overview import overview_table

    first, second = {"x": 26.43, "y": 39.92, "z": 1.458}, {"x": 15.58, "y": 19.79, "z": 2.072}
    ev = EvaluationSummary("both.json", "both.json", first, first, ["motor_lag"], None,
                           [first, second], ["half-base.npz", "half-lag.npz"])  # fmt: skip
    summary = SimpleNamespace(
        verdict=[], evaluations=[ev], fmt="md", figures=0, change=lambda: None
    )
    con = Console(record=True, width=200)
    _render_report(con, summary, tmp_path / "r.md")
    rows = [" ".join(ln.replace("│", " ").split()) for ln in con.export_text().splitlines()]
    assert "both.json: half-base.npz 26.43 39.92 1.458 motor_lag" in rows
    assert "both.json: half-lag.npz 15.58 19.79 2.072" in rows
    metrics = [{"model": {"rmse": r}} for r in (first, second)]
    tree = {"logs": [{"name": "log15"}], "metrics": {"nominal": {"rmse": first}, **metrics[0]},
            "models": [{"name": "half-base.npz"}, {"name": "half-lag.npz"}],
            "metrics_by_model": metrics, "diagnosis": {"missing": ["motor_lag"]}}  # fmt: skip
    text = to_markdown(Document("r", overview_table([(tree, {"t": [0.0, 0.01]}, "both.json")])))
    lines = [ln for ln in text.splitlines() if ln.startswith("| both.json")]
    assert len(lines) == 2
    assert "half-lag.npz" in lines[1] and "| 15.58 | 19.79 | 2.072 |" in lines[1]
    assert "half-lag.npz" not in lines[0] and "| 26.43 | 39.92 | 1.458 |" in lines[0]


def test_the_horizon_table_names_its_models_files():
    """The horizon table labelled rows '(model 0)' .. '(model 3)' where every other table
    names the files (a new user)."""
    from omavctl.report.horizons import models_legend

    tree = {"models": [{"name": "gp.npz"}, {"name": "gp-eff.npz"}]}
    assert models_legend(tree, 2) == "model 0: gp.npz, model 1: gp-eff.npz"
    assert models_legend(tree, 1) == "" and models_legend({"models": []}, 2) == ""


def test_a_nominal_model_worse_than_zero_is_said():
    """Two new users read 'zero 0.3624' above 'nominal 0.9192' (the demo's x) without a
    word: the physics without the model's effects predicts worse than nothing there."""
    from omavctl.report.summary import nominal_note

    zero, nominal = {"x": 0.3624, "y": 0.5, "z": 0.2}, {"x": 0.9192, "y": 0.52, "z": 0.1}
    assert nominal_note(zero, nominal) == (
        "nominal is worse than predicting no acceleration on x (0.9192 against 0.3624 "
        "rad/s^2): the physics without the model's effects is far off there, and the effects "
        "and the GP carry the model (an effect kept out of the nominal physics does this, as "
        "the omav's rotor_interference; so does a command gain, sign or frame that is off)"
    )
    assert nominal_note(zero, {"x": 0.39, "y": 0.5, "z": 0.1}) is None  # within 1.1x
    assert nominal_note({}, nominal) is None  # files before the zero row


def test_the_before_after_comparison_reads_each_model_of_a_file_with_several():
    """`report eval1.json eval-com.json` (eval-com.json evaluated with gp.npz and
    gp+com_offset.npz): the terminal's change line read the last model's -51.8 % on x,
    while the HTML comparison table and bar chart read eval-com.json's first model (the
    same gp.npz as eval1.json: +0.0 % on every axis), and `report --json` gave only that
    first model's RMSE (a new user)."""
    from omavctl.report.comparison import comparison_section, model_rows
    from omavctl.report.document import Document, to_markdown

    base, added = (
        {"x": 0.083, "y": 0.1135, "z": 0.09188},
        {"x": 0.04003, "y": 0.03212, "z": 0.03402},
    )
    nominal = {"nominal": {"rmse": {"x": 5.457, "y": 5.228, "z": 0.9954}}}
    one = {"logs": [{"name": "test.bag"}], "models": [{"name": "gp.npz"}],
           "metrics": {**nominal, "model": {"rmse": base}}}  # fmt: skip
    two = {"logs": [{"name": "test.bag"}],
           "models": [{"name": "gp.npz"}, {"name": "gp+com_offset.npz"}],
           "metrics": {**nominal, "model": {"rmse": base}},
           "metrics_by_model": [{"model": {"rmse": base}}, {"model": {"rmse": added}}]}  # fmt: skip
    evals = [(one, {}, "eval1.json"), (two, {}, "eval-com.json")]
    rows = model_rows(evals)
    assert [r[1] for r in rows] == [
        "eval1.json", "eval-com.json: gp.npz", "eval-com.json: gp+com_offset.npz"
    ]  # fmt: skip
    assert rows[2][3] == [0.04003, 0.03212, 0.03402]
    text = to_markdown(Document("r", comparison_section(evals, figures=False)))
    last = [ln for ln in text.splitlines() if "gp+com\\_offset.npz" in ln]
    assert len(last) == 1 and last[0].startswith("| eval-com.json | gp+com\\_offset.npz")
    assert "| 0.04003 | -51.8 % | 0.03212 | -71.7 % | 0.03402 | -63.0 % |" in last[0]


def test_report_json_gives_each_models_rmse_of_a_file_with_several(tmp_path: Path):
    """`report --json` gave a file's first model's RMSE only (``model_rmse``); each
    ``--model``'s is in ``models`` (a new user)."""
    from omavctl.cli.report import _report_json
    from omavctl.report.evaluation import EvaluationSummary

    first, second = {"x": 0.083, "y": 0.11, "z": 0.09}, {"x": 0.04, "y": 0.032, "z": 0.034}
    ev = EvaluationSummary("both.json", "both.json", first, first, [], None,
                           [first, second], ["gp.npz", "gp+com_offset.npz"])  # fmt: skip
    summary = SimpleNamespace(verdict=[], evaluations=[ev], fmt="html", figures=0,
                              change=lambda: None)  # fmt: skip
    (entry,) = _report_json(summary, tmp_path / "r.html")["evaluations"]
    assert entry["model_rmse"] == first
    assert entry["models"] == [
        {"name": "gp.npz", "model_rmse": first},
        {"name": "gp+com_offset.npz", "model_rmse": second},
    ]
