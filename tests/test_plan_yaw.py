"""plan's yaw margin: candidates turn at most --yaw-margin from the task's yaw."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.base.errors import OmavctlError
from omavctl.planning.candidates import deviated_references, sample_coefficients, yaw_deviation_deg
from omavctl.planning.planner import PlanSettings, _proposer
from omavctl.sim.tasks import fig8


@pytest.fixture(scope="module")
def task():
    return fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.5)


def test_yaw_deviation_is_the_references_yaw_minus_the_tasks(task) -> None:
    """Known before simulating: the largest |yaw| difference of the built references."""
    c = sample_coefficients(np.random.default_rng(0), 40, 2, 0.1, 2.0, 3.0)
    refs = deviated_references(task, c)
    expected = np.rad2deg(np.abs(refs[..., 6] - task.euler[None, :, 2]).max(axis=1))
    np.testing.assert_allclose(yaw_deviation_deg(task, c), expected, rtol=1e-9, atol=1e-9)
    assert expected.max() > 90 and expected.min() < 5  # low frequencies turn far


@pytest.mark.parametrize("search", ["random", "cem"])
def test_the_margin_redraws_the_candidates_that_turn_beyond_it(task, search) -> None:
    settings = PlanSettings(candidates=40, amplitude=3.0, search=search)
    sizes, free = _proposer(settings, np.random.default_rng(1), task)
    assert (yaw_deviation_deg(task, free(sizes[0], [], [])) > 10).sum() >= 2
    capped = PlanSettings(candidates=40, amplitude=3.0, search=search, yaw_margin_deg=10.0)
    sizes, propose = _proposer(capped, np.random.default_rng(1), task)
    first = propose(sizes[0], [], [])
    assert first.shape == (sizes[0], 3, 2, 2)
    assert yaw_deviation_deg(task, first).max() <= 10.0
    if search == "cem":  # later generations sample the fitted mixture, also within
        costs = np.linspace(1.0, 2.0, sizes[0])
        later = propose(sizes[1], [first], [costs])
        assert later.shape[0] == sizes[1] and yaw_deviation_deg(task, later).max() <= 10.0


def test_an_impossible_margin_says_what_to_change(task) -> None:
    settings = PlanSettings(candidates=5, amplitude=3.0, yaw_margin_deg=0.0)
    sizes, propose = _proposer(settings, np.random.default_rng(0), task)
    with pytest.raises(OmavctlError) as err:
        propose(sizes[0], [], [])
    assert str(err.value) == (
        "--yaw-margin 0: too few candidates turn less than that from the task's yaw: "
        "raise it or lower --amplitude"
    )
