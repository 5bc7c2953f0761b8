"""Shared fixtures: the default vehicle, short simulated flights."""

from __future__ import annotations

import os

import numpy as np
import pytest
import scipy.linalg  # noqa: F401  (loads SciPy's own OpenBLAS, limited below)
from threadpoolctl import threadpool_limits

from omavctl.learn.model import ResidualGP
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import Vehicle, default_vehicle

#: One BLAS thread per test process. `make test` runs two pytest workers on CI's two
#: cores; OpenBLAS's default of one thread per core made four busy threads fight for two
#: cores (four of the slowest files on two workers: 307 -> 258 CPU seconds,
#: docs/testing.md). NumPy's and SciPy's OpenBLAS are both loaded here; the `omavctl`
#: processes that tests start inherit the variables.
BLAS_LIMIT = threadpool_limits(limits=1, user_api="blas")
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

#: Test files by their time on one worker, slowest first (session 18's `--durations`
#: runs on the 2-core CI machine: test_evaluate 220-330 s, the next ones 40-130 s each,
#: docs/testing.md "Session 19"). `make test` runs `pytest -n 2 --dist loadfile
#: --no-loadscope-reorder`: xdist then hands whole files to its two workers in collection
#: order, which :func:`pytest_collection_modifyitems` makes this order (the other files
#: after them, alphabetically). xdist's default order, most tests first, left these
#: one-to-six-test files (the two-flights test 78 s, test_fuzz 40-67 s, test_demo 40-70 s)
#: to the end, where one worker ran them while the other had nothing left.
SLOW_FIRST = (
    "test_evaluate.py",
    "test_generalise.py",
    "test_plan_fast.py",
    "test_motor_effects.py",
    "test_kill9.py",
    "test_generalise_two_flights.py",
    "test_plan_effects.py",
    "test_timing_and_control_loss.py",
    "test_demo.py",
    "test_fuzz.py",
    "test_report.py",
    "test_scripting.py",
    "test_browser.py",
    "test_intervals.py",
    "test_horizons.py",
    "test_robust.py",
    "test_motors.py",
    "test_control_loss.py",
    "test_never_hurts.py",
    "test_informative_bench.py",
    "test_real_logs.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The slowest files first (:data:`SLOW_FIRST`), each file's tests in their order."""
    rank = {name: i for i, name in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


NO_NOISE = {"gyro": 0.0, "attitude": 0.0, "position": 0.0, "velocity": 0.0}


@pytest.fixture(scope="session")
def vehicle() -> Vehicle:
    return default_vehicle()


@pytest.fixture(scope="session")
def short_fig8():
    return fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=6.0, ramp=1.0)


@pytest.fixture(scope="session")
def fig8_fitted(vehicle):
    """An 8 s 20 deg figure-8 task and a model fitted (40 points, no restarts) on one
    flight of it (truth seed 1): the plan tests' shared model, fitted once per worker
    (test_plan_fast, test_plan_region and test_plan_tilt each fitted the same one)."""
    from omavctl.learn.fit import fit_model
    from omavctl.logs import align

    task = fig8(roll_deg=20, pitch_deg=20, period=4.0, duration=8.0, ramp=1.5)
    flight = align(simulate(task, vehicle, truth_from_tree({"seed": 1}, vehicle), seed=1).log)
    return task, fit_model([flight], vehicle, points=40, restarts=0).model


def fly(vehicle: Vehicle, ref, truth: dict, seed: int = 0):
    """Simulate ``ref`` with a truth mapping; returns the SimulationResult."""
    return simulate(ref, vehicle, truth_from_tree(truth, vehicle), seed=seed)


def on_grid(series, times: np.ndarray) -> np.ndarray:
    """Values of a RawSeries at the given stamps (which must be among its stamps)."""
    idx = np.searchsorted(series.stamps, times - 1e-9)
    assert np.allclose(series.stamps[idx], times)
    return series.values[idx]


def rebuilt(model: ResidualGP, **changes) -> ResidualGP:
    """``model`` built again (its Cholesky factors anew) with some arguments changed:
    other training inputs or targets, hyperparameters or band calibration."""
    kwargs = {
        k: getattr(model, k)
        for k in (
            "vehicle", "features", "input_names", "inputs", "targets", "input_mean",
            "input_scale", "target_mean", "signal_variance", "length_scales",
            "noise_variance", "band_noise", "band_scale", "band_slope", "torque_growth",
            "range_growth", "latent_scale",
            "beyond_scale", "mean_shrink", "effects",
        )
    }  # fmt: skip
    return ResidualGP(**{**kwargs, **changes})
