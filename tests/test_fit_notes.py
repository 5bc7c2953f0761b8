"""What fit's summary says about a torque gain that comes out negative."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omavctl.learn.fit_notes import unit_notes
from omavctl.vehicle import load_vehicle


def _vehicle(tmp_path: Path):
    path = tmp_path / "v.yaml"
    path.write_text("preset: quad-x-betaflight\n")
    return load_vehicle(path)


def test_a_negative_gain_from_motor_outputs_names_the_motor_lag(tmp_path: Path) -> None:
    """On a Betaflight log the gain came out negative on x and y; the note blamed only
    the sign and frame, which the docs had checked. A torque lagging its command by
    more than a quarter period correlates negatively with it: the note names the lag
    when the fit has none, and not when it has one."""
    veh = _vehicle(tmp_path)
    gain, se = np.array([-0.01, -0.02, 0.3]), np.array([0.01, 0.01, 0.05])
    (bad,) = [n for n in unit_notes(veh, [], gain, se) if "not positive" in n]
    assert bad.startswith("torque command gain not positive on axis x, y: check the sign")
    assert "--effects motor_lag" in bad
    (bad,) = [n for n in unit_notes(veh, [], gain, se, ["motor_lag"]) if "not positive" in n]
    assert "motor_lag" not in bad
    assert not [n for n in unit_notes(veh, [], np.abs(gain), se) if "not positive" in n]


def test_a_band_widened_by_a_factor_that_rounds_to_one_is_not_noted() -> None:
    """Eyes3 (fit on the tool's own fig8 flight): "axis x: predictive std widened x1.00
    to cover 95% of held-out time blocks (was 95%)" said nothing; a factor that rounds
    to 1.00 is not noted, a real widening still is."""
    from omavctl.learn.hyperparameters import _axis_notes
    from omavctl.learn.validation import AxisValidation

    def notes(std: float, latent: float = 1.0) -> list[str]:
        v = AxisValidation(1.0, 2.0, 0.95, std, True, 1.0, latent_factor=latent)
        return _axis_notes("x", v)

    assert notes(1.004, 1.003) == []
    assert notes(1.04, 1.2) == [
        "axis x: predictive std widened x1.04 to cover 95% of held-out time blocks (was 95%)",
        "axis x: extrapolation uncertainty widened x1.20 (held-out regions of input space)",
    ]
