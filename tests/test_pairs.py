"""Effects fitted in pairs: a torque effect beside an inertia scale is reported in
physical units (``omavctl/learn/physical.py``), its interval holding the truth that
the additive coefficient's missed, the model still predicting with that coefficient;
two timing forms searched together get the profile interval of the pair
(``effect_search._profile_se``). docs/intervals.md, "Effects fitted in pairs"."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from omavctl.base.errors import ModelError
from omavctl.learn.effect_fit import estimate_effects
from omavctl.learn.effect_search import _Problem, _sandwich, search_effects
from omavctl.learn.estimate import EffectEstimate
from omavctl.learn.fit_notes import search_notes
from omavctl.learn.flights import log_samples
from omavctl.learn.intervals import Z95
from omavctl.learn.model_file import _effects_from_json
from omavctl.learn.physical import physical_map, to_physical
from omavctl.learn.signal import SavitzkyGolay
from omavctl.logs import align
from omavctl.physics.effects import get_effect
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import wobble
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import default_vehicle

SCALE = np.array([1.43, 1.43, 1.35])
DRAG = np.array([0.8, 0.8, 0.75])


@pytest.fixture(scope="module")
def drag_beside_inertia():
    """An 8 s wobble through the default plant with a 35-43 % heavier inertia and a
    drag: the first pass of ``fit --effects inertia_error,rotational_drag``."""
    vehicle = default_vehicle()
    truth = {"effects": {"inertia_error": {"scale": SCALE.tolist()},
                         "rotational_drag": {"D": DRAG.tolist()}}}  # fmt: skip
    ref = wobble(amplitude_deg=15.0, duration=8.0, seed=0)
    log = align(simulate(ref, vehicle, truth_from_tree(truth, vehicle), seed=0).log)
    s = log_samples(log, vehicle, SavitzkyGolay(11, 2, 0.01))[0]
    return s, estimate_effects([s], ["inertia_error", "rotational_drag"])


def test_a_drag_beside_an_inertia_scale_is_physical_and_its_interval_holds_it(
    drag_beside_inertia,
):
    """Before, the drag came out as seen through the nominal inertia, D / scale
    (0.56 for 0.8), its interval a few per cent wide: it missed the truth on every
    axis. Now the reported D holds the truth on the excited axes (x, y), and the
    coefficient the model predicts with is still the additive one."""
    _, fit = drag_beside_inertia
    est = fit.estimates["rotational_drag"]
    d, se = est.values["D"], est.stderr["D"]
    assert est.fitted is not None
    additive = est.fitted  # the old report: its interval, from the additive covariance
    additive_se = np.sqrt(np.diag(fit.cov))[3:6]
    assert np.all(np.abs(additive - DRAG) > Z95 * additive_se)
    np.testing.assert_allclose(additive, fit.theta[3:6])
    assert np.all(np.abs(d - DRAG)[:2] <= Z95 * se[:2]), (d, se)
    # the drag is diagonal: its physical value is exactly the coefficient times the scale
    np.testing.assert_allclose(d, additive * fit.estimates["inertia_error"].values["scale"])
    np.testing.assert_allclose(est.theta, additive)
    # the scale is reported as before, and is not converted
    assert fit.estimates["inertia_error"].fitted is None


def test_the_physical_map_is_exact_for_a_diagonal_effect_and_counts_the_scale():
    """The delta method: a drag's variance gains the scale's share, the parameters
    of effects that are not torques are unchanged; no map without a scale, nor for a
    normalised command."""
    rng = np.random.default_rng(0)
    n = 400
    x = np.zeros((n, 3, 6))
    for k in range(3):
        x[:, k, k] = rng.normal(size=n)  # the scale's regressor on axis k
        x[:, k, 3 + k] = rng.normal(size=n)  # the drag's
    names = ["inertia_error", "rotational_drag"]
    pm = physical_map(x, names, normalised=False)
    assert pm is not None
    assert physical_map(x, names, normalised=True) is None
    assert physical_map(x[:, :, 3:], ["rotational_drag"], normalised=False) is None
    theta = np.array([-0.3, -0.3, -0.25, 0.56, 0.56, 0.56])
    cov = np.diag([1e-4] * 3 + [4e-4] * 3)
    phys, cov_p = to_physical(theta, cov, pm)
    np.testing.assert_allclose(phys[:3], theta[:3])
    np.testing.assert_allclose(phys[3:], theta[3:] / (1 + theta[:3]))
    g = 1 + theta[:3]
    expected = 4e-4 / g**2 + (theta[3:] / g**2) ** 2 * 1e-4
    np.testing.assert_allclose(np.diag(cov_p)[3:], expected)


def test_the_model_file_keeps_the_coefficients_it_predicts_with(drag_beside_inertia):
    """``theta_fitted`` goes through the model file's JSON; a wrong one is refused."""
    _, fit = drag_beside_inertia
    est = fit.estimates["rotational_drag"]
    tree = {"rotational_drag": est.to_json()}
    back = _effects_from_json(tree, Path("m.npz"), 2)["rotational_drag"]
    np.testing.assert_allclose(back.theta, est.theta)
    np.testing.assert_allclose(back.values["D"], est.values["D"])
    plain = EffectEstimate("rotational_drag", {"D": np.ones(3)}, {"D": np.ones(3)})
    assert "theta_fitted" not in plain.to_json()
    tree["rotational_drag"]["theta_fitted"] = [0.1, 0.2]
    with pytest.raises(ModelError, match="theta_fitted is not 3 finite number"):
        _effects_from_json(tree, Path("m.npz"), 2)


def test_the_exact_forms_memo_gives_what_a_fresh_computation_gives(drag_beside_inertia):
    """ResidualSamples.exact remembers its results (the lag searches ask for the same
    values again): the same array as samples that remember nothing, per value, through
    a mask, and a caller that writes into its result changes nothing remembered."""
    s, _ = drag_beside_inertia
    fresh = replace(s)  # a new object: nothing remembered
    first = s.exact("motor_lag", 0.05)
    first += 1.0
    np.testing.assert_array_equal(s.exact("motor_lag", 0.05), fresh.exact("motor_lag", 0.05))
    assert not np.array_equal(s.exact("motor_lag", 0.05), s.exact("motor_lag", 0.06))
    keep = np.arange(s.n) % 3 > 0
    np.testing.assert_array_equal(
        s.select(keep).exact("motor_lag", 0.06), replace(s).exact("motor_lag", 0.06)[keep]
    )


def test_a_delay_beside_a_servo_lag_has_the_profile_interval_of_the_pair():
    """A 48 ms delay and a 100 ms servo lag trade on a wobble: the search puts the
    whole timing in the delay (~106 ms, the lag 0). The sandwich, each member with the
    other held, said +- 1.7 ms and missed both truths; with the partner searched again
    at each grid value the profile holds both and says they were traded; the lag is
    not pinned down."""
    vehicle = default_vehicle()
    truth = {"command_delay": {"tau_d": 0.048}, "servo_lag": {"T_s": 0.1}}
    ref = wobble(amplitude_deg=15.0, duration=8.0, seed=0)
    plant = truth_from_tree({"seed": 0, "effects": truth}, vehicle)
    log = align(simulate(ref, vehicle, plant, seed=0).log)
    s = log_samples(log, vehicle, SavitzkyGolay(11, 2, 0.01))[0]
    found = search_effects([s], list(truth), [])
    prob = _Problem([s], [])
    for name, r in found.items():
        true = next(iter(truth[name].values()))
        base = prob.residual - prob.exact(
            *next((o, f.value) for o, f in found.items() if o != name)
        )
        held, _ = _sandwich(prob, name, base, r.value)
        assert abs(r.value - true) > Z95 * math.hypot(held, r.form_allowance), name
        assert abs(r.value - true) <= Z95 * r.stderr, (name, r.value, r.stderr)
        assert r.traded == next(o for o in truth if o != name)
        p = get_effect(name).parameters[0].name
        est = EffectEstimate(name, {p: np.array([r.value])}, {p: np.array([r.stderr])})
        assert est.pinned()[p][0] == (name == "command_delay")  # some timing: > 0
    notes = search_notes(found)
    assert any(n.startswith("servo_lag: traded with command_delay on these samples") for n in notes)


def test_a_model_whose_effect_predicts_with_other_coefficients_is_schema_3(tmp_path):
    """A reader of schema 2 would predict with the physical parameters: such a file is
    written as omavctl.model/3 (refused there as newer), read back with its
    coefficients; a model without them stays omavctl.model/2."""
    from conftest import rebuilt
    from test_model import make_model

    from omavctl.learn.model_file import load_model, save_model

    model = make_model(default_vehicle(), features="wrench+rate", effects=True)
    est = model.effects["rotational_drag"]
    fitted = EffectEstimate(est.name, est.values, est.stderr, fitted=0.7 * est.theta)
    path = tmp_path / "m.npz"
    save_model(path, rebuilt(model, effects={"rotational_drag": fitted}))
    with np.load(path, allow_pickle=False) as npz:
        assert str(npz["schema"]) == "omavctl.model/3"
    back = load_model(path).effects["rotational_drag"]
    np.testing.assert_allclose(back.theta, 0.7 * est.theta)
    np.testing.assert_allclose(back.values["D"], est.values["D"])
    save_model(path, model)
    with np.load(path, allow_pickle=False) as npz:
        assert str(npz["schema"]) == "omavctl.model/2"
