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
        "log's own rate"
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
