"""What a refit keeps of the second flight: the share of its training points from it.

``fit`` picks its training points (k-medoids) among the samples of all its logs, so
every training input of the model is one sample's GP input exactly: each is
attributed to the flight that holds it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from omavctl.learn.signal import SavitzkyGolay, residual_samples
from omavctl.logs import read_vehicle_log
from omavctl.vehicle import default_vehicle

#: the refits of one draw directory: result key -> (second flight, refitted model)
CHAINS = {"task_again": "task", "effects_plan": "effects"}


def inputs(flight: Path, features: str) -> np.ndarray:
    """GP inputs (n, d) of a simulated flight, as ``fit`` computes them (SG 11/2)."""
    vehicle = default_vehicle()
    samples = residual_samples(
        read_vehicle_log(flight, vehicle), vehicle, SavitzkyGolay(11, 2, 0.01)
    )
    return samples.inputs(features)


def kept_share(model: Path, first: Path, second: Path) -> float:
    """Share of ``model``'s training points that are samples of ``second`` (not ``first``)."""
    with np.load(model, allow_pickle=False) as z:
        train, features = z["train_inputs"], str(z["features"])
    d_first = cKDTree(inputs(first, features)).query(train)[0]
    d_second = cKDTree(inputs(second, features)).query(train)[0]
    return float(np.mean(d_second < d_first))


def add_kept(w: Path, result: dict) -> dict:
    """Add ``kept`` to every refit of the draw in directory ``w`` that lacks it."""
    first = w / "first-flight.csv"
    chains = [(result[k], tag) for k, tag in CHAINS.items() if k in result]
    chains += [(c, f"cand-{k}") for k, c in result["pool"].items()]
    for chain, tag in chains:
        if "kept" not in chain:
            chain["kept"] = kept_share(w / f"refit-{tag}.npz", first, w / f"second-{tag}.csv")
    (w / "result.json").write_text(json.dumps(result, indent=1))
    return result
