"""Seconds for the horizon table of a 60 s log at 100 Hz: 0.5 s windows at stride 1.

Every window is rolled out at once (:mod:`omavctl.physics.open_loop`); the model
is fit's default (GP on the wrench, the body rate and the torque rate, so the GP
is evaluated at the rolled-out body rate twice per step), 200 training points.
For comparison, the same rollouts one window at a time for 100 windows,
extrapolated to all of them.

Run: python benchmarks/bench_horizons.py
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from omavctl.diagnose.evaluate import _grid, _read_logs
from omavctl.diagnose.horizons import horizon_table
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import load_model, save_model
from omavctl.logs import write_log
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import load_truth
from omavctl.vehicle import default_vehicle

UNBATCHED = 100


def main() -> None:
    vehicle = default_vehicle()
    truth = load_truth(None, vehicle)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        write_log(d / "fit.csv", simulate(fig8(duration=20.0), vehicle, truth, seed=1).log)
        save_model(d / "m.npz", fit_model([d / "fit.csv"], vehicle).model)
        ref = fig8(roll_deg=20, pitch_deg=30, period=6.0, duration=60.0)
        write_log(d / "eval.csv", simulate(ref, vehicle, truth, seed=2).log)
        model = load_model(d / "m.npz")
        rate, sg = _grid(model)
        samples, grids, _, _ = _read_logs([d / "eval.csv"], model.vehicle, rate, sg, None, None)
    start, cpu = time.perf_counter(), time.process_time()
    table = horizon_table([model], samples, grids, rate, (0.01, 0.1, 0.5), stride=1)
    batched, batched_cpu = time.perf_counter() - start, time.process_time() - cpu
    windows = table["windows"]
    # one window at a time: the stride makes each call hold a single window
    part = [s.select(s.index < s.index[0] + UNBATCHED + 50) for s in samples]
    start, cpu = time.perf_counter(), time.process_time()
    for offset in range(UNBATCHED):
        keep = [s.select(s.index >= s.index[0] + offset) for s in part]
        horizon_table([model], keep, _cut(grids, part, keep), rate, (0.5,), stride=10_000)
    single = (time.perf_counter() - start) / UNBATCHED * windows
    single_cpu = (time.process_time() - cpu) / UNBATCHED * windows
    n = samples[0].n
    print(
        f"horizon table of a 60 s log ({n} samples, {model.n_train} training points, GP "
        f"features {model.features}): {windows} windows of 0.5 s at stride 1, 4 predictors"
    )
    load = os.getloadavg()[0]
    print(f"  batched: {batched:.2f} s wall, {batched_cpu:.2f} s CPU (load average {load:.1f})")
    print(
        f"  one window at a time (from {UNBATCHED} windows): {single:.0f} s wall, "
        f"{single_cpu:.0f} s CPU"
    )
    model_row = table["table"]["model"]
    for key in ("naive", "nominal", "effects", "model"):
        cells = ", ".join(
            f"{r['seconds']:g} s {r['rate_error']['norm']:.3g}" for r in table["table"][key]
        )
        print(f"  {key:8s} body-rate error norm, rad/s: {cells}")
    cov = ", ".join(f"{r['seconds']:g} s {100 * r['coverage']['all']:.0f} %" for r in model_row)
    print(f"  full model 2σ coverage: {cov}")


def _cut(grids, part, keep):
    """The grid signals of ``keep`` (samples selected from ``part``, from grids)."""
    from omavctl.diagnose.horizons import GridSignals

    out = []
    for g, s_all, s in zip(grids, part, keep, strict=True):
        sel = s_all.index.searchsorted(s.index)
        out.append(
            GridSignals(
                body_rate=g.body_rate[: s_all.n][sel],
                torque=g.torque[: s_all.n][sel],
                attitude=None if g.attitude is None else g.attitude[: s_all.n][sel],
            )
        )
    return out


if __name__ == "__main__":
    main()
