"""A quad's per-rotor and per-axis parameters as the report and fit show them (eyes6):
the Crazyflie report's ranking said "l_1, l_2, l_3 ... not excited: l_0, l_4, ..., l_11"
for motor_loss. The flags were the Helmert contrasts' (contrast 0, the rotors' common
loss, is never excited), read as the losses': l_0 = -(l_1 + l_2 + l_3) is determined,
and l_4 .. l_11 are rotors a quad does not have. A CoM offset's r_z, which no thrust
along z shows, is named with why."""

from __future__ import annotations

import io

import numpy as np
from rich.console import Console

from omavctl.diagnose.scoring import _parameters
from omavctl.learn.estimate import EffectEstimate
from omavctl.physics.effects import get_effect
from omavctl.report.params import _param_lines

#: the Crazyflie halves' ranking row (log15 second half, halves-base.json): contrasts
#: 1..3 excited, the losses l_1..l_3 as shown, l_0 the negative of their sum
CONTRASTS = [False, True, True, True] + [False] * 8
LOSSES = [0.002749, -0.003065, 0.04017, -0.03985] + [0.0] * 8


def test_the_excited_flags_are_the_losses_not_their_contrasts():
    loss = get_effect("motor_loss")
    flags = loss.excited_parameters(np.array(CONTRASTS)).tolist()
    assert flags == [True] * 4 + [False] * 8
    assert loss.excited_parameters(np.array(flags)).tolist() == flags  # idempotent
    theta = loss.to_theta({"l": np.array(LOSSES)})
    params = _parameters(loss, theta, np.eye(12) * 1e-4, np.array(CONTRASTS))
    assert params["excited"] == flags
    np.testing.assert_allclose(params["l"][:4], LOSSES[:4], atol=1e-5)


def test_the_report_shows_every_rotor_of_the_quad_and_no_other():
    # a file written before this change holds the contrasts' flags: it reads alike
    for flags in (CONTRASTS, [True] * 4 + [False] * 8):
        lines = _param_lines({"l": LOSSES, "excited": flags}, {"l": "1"}, False, "motor_loss")
        assert [str(x) for x in lines] == [
            "l_0 = 0.002749",
            "l_1 = -0.003065",
            "l_2 = 0.04017",
            "l_3 = -0.03985",
        ]
    lines = _param_lines(
        {"r": [0.0014, -0.0033, 0.0], "excited": [True, True, False]},
        {"r": "m"},
        False,
        "com_offset",
    )
    assert lines[-1].text == (
        "not excited: r_z (only a force along x or y shows it, which a multirotor's thrust "
        "along z never gives)"
    )


def test_fit_leaves_out_the_rotors_the_vehicle_lacks_and_says_why_r_z_is_not_excited():
    from types import SimpleNamespace

    from omavctl.cli.fit import _effects_table

    loss = EffectEstimate(
        "motor_loss", {"l": np.array(LOSSES)}, {"l": np.array([0.024] * 4 + [0.0] * 8)}
    )
    com = EffectEstimate(
        "com_offset", {"r": np.array([0.0014, -0.0033, 0.0])}, {"r": np.array([0.01, 0.01, 0])}
    )
    summary = SimpleNamespace(
        effects={"motor_loss": loss, "com_offset": com},
        command_units={"torque": "N m", "force": "N"},
        torque_gain=None,
        torque_gain_stderr=None,
        logs=["quad.csv"],
    )
    con = Console(width=300, record=True, file=io.StringIO())
    con.print(_effects_table(summary))
    rows = {ln.split("│")[2].strip(): ln for ln in con.export_text().splitlines() if "│" in ln}
    assert [k for k in rows if k.startswith("l_")] == ["l_0", "l_1", "l_2", "l_3"]
    assert (
        "not excited by these logs: only a force along x or y shows it, which a "
        "multirotor's thrust along z never gives"
    ) in rows["r_z"]
