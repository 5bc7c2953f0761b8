"""Seconds to evaluate a model on a 60 s log (all metrics and the diagnosis).

Run: python benchmarks/bench_evaluate.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from omavctl.diagnose.evaluate import evaluate
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.logs import write_log
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import load_truth
from omavctl.vehicle import default_vehicle


def main() -> None:
    vehicle = default_vehicle()
    truth = load_truth(None, vehicle)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        write_log(d / "fit.csv", simulate(fig8(duration=20.0), vehicle, truth, seed=1).log)
        save_model(d / "m.npz", fit_model([d / "fit.csv"], vehicle).model)
        ref = fig8(roll_deg=20, pitch_deg=30, period=6.0, duration=60.0)
        write_log(d / "eval.bag", simulate(ref, vehicle, truth, seed=2).log)
        start = time.perf_counter()
        result = evaluate([d / "m.npz"], [d / "eval.bag"])
        elapsed = time.perf_counter() - start
    n = result.series["t"].size
    print(f"evaluate a 60 s log ({n} samples, 200 training points): {elapsed:.2f} s")


if __name__ == "__main__":
    main()
