"""A model that never hurts and a band that never overclaims on a flight of another
kind (benchmarks/never_hurts.py, pinned): the GP mean reverts to zero where it does
not stand out from its own uncertainty, and the noise is at least what the GP fails
to predict on held-out data."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.never_hurts import CASES, run_case
from omavctl.learn.mean_shrink import MEAN_SHRINK, shrink_mean
from omavctl.learn.model_file import load_model, save_model
from tests.test_model import _refused, _rewrite, make_model


def test_shrink_weighs_the_mean_by_how_far_it_stands_beyond_its_band():
    mean = np.array([[1.0, 1.0, 1.0], [1.0, -2.0, 0.5]])
    latent = np.array([[0.0, 0.25, 100.0], [0.25, 0.01, 0.0]])
    kappa = np.array([4.0, 4.0, 4.0])
    out, added = shrink_mean(mean, latent, kappa)
    # no latent variance: the mean as it is; a mean at its 2-sigma half-width: half
    assert out[0, 0] == 1.0 and out[1, 2] == 0.5
    assert out[0, 1] == pytest.approx(0.5) and out[1, 0] == pytest.approx(0.5)
    assert abs(out[0, 2]) < 0.01  # far from the data: back to zero (physics only)
    assert out[1, 1] == pytest.approx(-2.0 * 4.0 / 4.04)  # 10 latent stds: 99 %
    # the band keeps the unshrunk mean within it: the variance gains the shift squared
    np.testing.assert_allclose(added, (mean - out) ** 2)
    same, none = shrink_mean(mean, latent, np.zeros(3))
    np.testing.assert_array_equal(same, mean)
    np.testing.assert_array_equal(none, 0.0)


def test_the_model_mean_reverts_to_zero_away_from_its_data(vehicle):
    model = make_model(vehicle)
    near = model.inputs[:5]
    far = model.inputs[:5] + 6 * model.input_scale  # far beyond every input
    raw_near, var_near = model.gp_predict(near)
    raw_far, var_far = model.gp_predict(far)
    model.mean_shrink = np.full(3, MEAN_SHRINK)
    m_near, _ = model.gp_predict(near)
    m_far, v_far = model.gp_predict(far)
    # at the data a mean that stands out keeps its value; a small one moves within its band
    big = np.abs(raw_near) > 10 * np.sqrt(var_near)
    assert big.sum() >= 5
    np.testing.assert_allclose(m_near[big], raw_near[big], rtol=0.04)
    assert np.all(np.abs(m_near - raw_near) <= np.sqrt(var_near))
    assert np.abs(raw_far).max() > 0.05 and np.abs(m_far).max() < 0.02 * np.abs(raw_far).max()
    assert np.all(v_far >= var_far)  # the band holds the unshrunk mean as well
    np.testing.assert_allclose(model.mean(near), m_near)  # the controller's mean too


def test_mean_shrink_round_trips_and_is_checked(vehicle, tmp_path):
    model = make_model(vehicle)
    model.mean_shrink = np.array([4.0, 0.0, 4.0])
    good = tmp_path / "good.npz"
    save_model(good, model)
    np.testing.assert_array_equal(load_model(good).mean_shrink, [4.0, 0.0, 4.0])
    with np.load(good, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files if k != "mean_shrink"}
    old = tmp_path / "old.npz"
    np.savez(old, **arrays)
    np.testing.assert_array_equal(load_model(old).mean_shrink, np.zeros(3))  # as before
    negative = tmp_path / "negative.npz"
    _rewrite(good, negative, mean_shrink=np.array([4.0, -1.0, 4.0]))
    assert _refused(negative) == f"{negative}: key 'mean_shrink' must not be negative"


#: case -> (axis, before): the axis that failed before, and its figure then
PINNED = {
    "none steps->chirp": (2, "ratio 1.94"),
    "inertia chirp->steps": (1, "coverage 0.71"),
    "none chirp->fig8": (1, "coverage 0.74"),
}


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("never_hurts")
    # the metrics alone: the test reads the ratio and the coverage, which the diagnosis
    # does not change (3 x 8 CPU s less)
    return {case: run_case(tmp, case, diagnose=False) for case in PINNED}


@pytest.mark.parametrize("case", sorted(PINNED))
def test_never_worse_than_physics_and_the_band_covers(outcomes, case):
    """Fit on one kind of flight, judged on another (issue 26's cases: a GP fitted on
    attitude steps was 1.94x worse than physics on a chirp's yaw; fitted on a chirp,
    its band covered 0.71 and 0.74 of steps' and a figure-8's pitch)."""
    assert case in CASES
    o = outcomes[case]
    axis, before = PINNED[case]
    print(case, "ratio", o.ratio.round(3), "coverage", o.coverage.round(3))
    print(f"  axis {'xyz'[axis]} before: {before}")
    assert np.all(o.ratio <= 1.05)
    assert np.all(o.coverage >= 0.85)
