"""The report's per-axis figures give each body axis its own y scale (eyes6): on a
Crazyflie the yaw error (about 1.5 rad/s² RMS) was drawn as a flat line under the
roll and pitch errors (26 and 40 rad/s²) on the one scale the three axes shared."""

from __future__ import annotations

import numpy as np

from omavctl.report.figures import _error_fig, error_limits, style


def _errors() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(400) * 0.01
    wave = np.sin(2 * np.pi * 1.5 * t)
    err = np.stack([30.0 * wave, 40.0 * wave, 1.5 * wave], axis=1)
    return t, err


def test_each_axis_of_the_error_figure_has_its_own_scale():
    t, err = _errors()
    # 1.25 x the 99.5th percentile of its own |error|, wave amplitude ~1
    np.testing.assert_allclose(error_limits(err), [37.5, 50.0, 1.875], rtol=2e-3)
    with style():
        fig = _error_fig(t, err, np.ones_like(err), [], 0.01, "title")
    tops = [ax.get_ylim()[1] for ax in fig.axes[:3]]
    np.testing.assert_allclose(tops, error_limits(err))
    assert tops[2] < tops[0] / 10  # yaw is not drawn on roll's scale
    # a column of NaN only (an axis the log lacks) gets the floor, not an error
    err[:, 2] = np.nan
    assert error_limits(err)[2] == 1e-6


def test_each_axis_of_the_before_after_figure_has_its_own_panel_and_scale():
    """The Crazyflie halves' z (1.46 -> 2.07 rad/s², 42 % worse) was a sliver under y's
    39.9 on the one scale the three axes' bars shared."""
    from omavctl.report.figures import _before_after_fig

    with style():
        rmse = [[26.43, 39.92, 1.458], [15.58, 19.79, 2.072]]
        fig = _before_after_fig(["base.json", "lag.json"], rmse)
    tops = [ax.get_ylim()[1] for ax in fig.axes]
    np.testing.assert_allclose(tops, [26.43 * 1.3, 39.92 * 1.3, 2.072 * 1.3])
    assert [ax.get_title() for ax in fig.axes] == ["axis x", "axis y", "axis z"]
    assert "+42.1 %" in [t.get_text().split("\n")[-1] for t in fig.axes[2].texts]
