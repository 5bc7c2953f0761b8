"""After a draw: what each refit keeps of its second flight, and what the planner's cost
rewards in the pool.

``fit`` picks its training points (k-medoids) among the samples of all its logs, so
every training input of the model is one sample's GP input exactly: each is
attributed to the flight that holds it.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.informative_stats import spearman
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


def read_scores(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (K, 3, P, 2) and cost (K,; inf when infeasible) of ``plan --scores``."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    names = [k for k in rows[0] if k[:2] in ("f_", "A_")]
    coeffs = np.array([[float(r[k]) for k in names] for r in rows])
    cost = np.array([float(r["cost"]) if r["feasible"] == "true" else np.inf for r in rows])
    return coeffs.reshape(len(rows), 3, len(names) // 6, 2), cost


def pool_ranking(coefficients: np.ndarray, cost: np.ndarray) -> dict[str, float]:
    """Spearman of the cost (K,; inf = infeasible) with the candidates' RMS deviation
    amplitude and mean frequency, coefficients (K, 3, P, 2), over the feasible ones."""
    ok = np.isfinite(cost)
    amplitude = np.sqrt((coefficients[ok, ..., 1] ** 2).mean(axis=(1, 2)))
    frequency = coefficients[ok, ..., 0].mean(axis=(1, 2))
    return {
        "amplitude": spearman(cost[ok], amplitude),
        "frequency": spearman(cost[ok], frequency),
    }


def add_kept(w: Path, result: dict) -> dict:
    """Add ``kept`` to every refit of the draw in directory ``w`` that lacks it, and the
    pool's ``ranking`` (:func:`pool_ranking`)."""
    result["ranking"] = pool_ranking(*read_scores(w / "scores-variance.csv"))
    first = w / "first-flight.csv"
    chains = [(result[k], tag) for k, tag in CHAINS.items() if k in result]
    chains += [(c, f"cand-{k}") for k, c in result["pool"].items()]
    for chain, tag in chains:
        if "kept" not in chain:
            chain["kept"] = kept_share(w / f"refit-{tag}.npz", first, w / f"second-{tag}.csv")
    (w / "result.json").write_text(json.dumps(result, indent=1))
    return result
