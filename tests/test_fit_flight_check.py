"""A claim made on the fit flight's estimate is checked as ``fit`` would make it there.

Session 34's new-user trial on the Crazyflie (log15 at 15.8-50.8 s judged on log16):
the verdict said "the fit flight shows it (8 ms, its 95 % interval excluding 0)" of a
command delay, and the fit it printed said "tau_d = 7.48 ± 21 ms ... cannot be pinned
down from this flight". The diagnosis now reads the model's fit logs, when they are
still there and unchanged, and estimates the effect there as the printed command would
(:mod:`omavctl.diagnose.fit_flight_check`).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from omavctl.diagnose.claim_text import held_out_not_pinned_sentence
from omavctl.diagnose.fit_flight_check import checked_on_fit_flight, fit_flight_estimate_json
from omavctl.diagnose.logread import _grid, fit_flight_reader
from omavctl.diagnose.verdict import _held_why
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import load_model, save_model
from omavctl.logs import write_log
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import steps
from omavctl.sim.truth import truth_from_tree

TRUE_DELAY = 0.03


@pytest.fixture(scope="module")
def fitted(tmp_path_factory, vehicle) -> tuple[Path, Path]:
    """Attitude steps with a hidden 30 ms delay, written as CSV, and a model fitted on
    the file without effects (as ``omavctl fit``: its provenance names the file). (On a
    12 s figure-8 fit itself does not pin the delay down: 34 +- 22 ms.)"""
    tmp = tmp_path_factory.mktemp("fit_flight")
    truth = truth_from_tree(
        {"seed": 1, "effects": {"command_delay": {"tau_d": TRUE_DELAY}}}, vehicle
    )
    task = steps(duration=12.0)
    log = tmp / "fit.csv"
    write_log(log, simulate(task, vehicle, truth, seed=1).log)
    model = tmp / "m.npz"
    save_model(model, fit_model([log], vehicle, points=60, restarts=0).model)
    return log, model


def test_the_fit_flight_is_read_again_and_the_effect_estimated_as_fit_would(fitted):
    _, path = fitted
    model = load_model(path)
    read = fit_flight_reader(model)
    samples = read()
    assert samples is not None and len(samples) == 1 and samples[0].n > 500
    assert read() is samples  # read once
    _, sg = _grid(model)
    est = fit_flight_estimate_json(read, model, "command_delay", sg)
    assert est is not None
    (low, high), (pinned,) = est["tau_d_ci95"][0], est["tau_d_pinned"]
    assert pinned and low <= TRUE_DELAY <= high, est
    entry, stands = checked_on_fit_flight({"name": "command_delay"}, read, model, sg)
    assert stands and entry["fit_flight_checked"] and entry["fit_flight_fit"] == est


def test_a_fit_log_gone_or_changed_is_not_read_and_the_claim_says_it_was_not_checked(
    fitted, tmp_path
):
    log, path = fitted
    model = load_model(path)
    moved = tmp_path / "fit.csv"
    moved.write_bytes(log.read_bytes() + b"\n")  # another file's bytes at the named path
    model.provenance["sources"][0]["abspath"] = str(moved)
    assert fit_flight_reader(model)() is None
    model.provenance["sources"][0]["abspath"] = str(tmp_path / "gone.csv")
    assert fit_flight_reader(model)() is None
    _, sg = _grid(model)
    entry, stands = checked_on_fit_flight(
        {"name": "command_delay"}, fit_flight_reader(model), model, sg
    )
    assert stands and entry == {"name": "command_delay", "fit_flight_checked": False}
    step = {"name": "command_delay", "held_out_not_pinned": True, "fit_flight_value": 0.008}
    said = held_out_not_pinned_sentence({**step, "fit_flight_checked": False})
    assert said.startswith(
        " This flight alone does not pin its value down; the fit flight shows it (8 ms by "
        "least squares at the model's training points, its 95 % interval excluding 0; the "
        "fit logs could not be read to estimate it as fit --effects would, whose interval, "
        "robust to the flight's autocorrelation, may be wider;"
    )


def test_the_sentences_quote_the_fit_flights_estimate_as_fit_makes_it():
    units = {"tau_d": "s"}
    fit = {"tau_d": [0.0312], "tau_d_ci95": [[0.0251, 0.0373]], "tau_d_pinned": [True]}
    step = {
        "name": "command_delay",
        "units": units,
        "held_out_not_pinned": True,
        "fit_flight_value": 0.029,
        "fit_flight_checked": True,
        "fit_flight_fit": fit,
    }
    assert held_out_not_pinned_sentence(step).startswith(
        " This flight alone does not pin its value down; the fit flight shows it (estimated "
        "there as fit --effects would, tau_d = 0.0312 s (95 %: 0.0251 to 0.0373 s); the GP "
        "shrinks it"
    )
    # held back: the fit flight, estimated as fit would, does not pin it down either
    cf = {"tau_d": [0.00752], "tau_d_ci95": [[0.0, 0.0487]], "tau_d_pinned": [False]}
    diag = {
        "learned_held": {"command_delay": "fit_flight_not_pinned"},
        "fit_flight_unpinned": {"command_delay": cf},
        "learned": [{"name": "command_delay", "units": units}],
    }
    why = _held_why(diag, "command_delay")
    assert why.startswith(
        ": this flight does not pin it down, and the fit flight, estimated as fit --effects "
        "would, does not either (its 95 % interval holds the value at which it is absent; "
        "the model's training points alone had excluded it): tau_d = 0.00752 s (95 %: below "
        "0.0487 s"
    ), why
