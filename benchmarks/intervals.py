"""Coverage of the effect parameters' 95 % intervals on simulated flights.

For every hidden effect (a known truth) and seed, a multi-sine wobble is
flown through the truth plant (the documented default imperfections
included), ``fit_model --effects <effect>`` estimates it, and the benchmark
counts whether each true parameter lies inside the reported 95 % interval;
beside it, the white-residual interval (ordinary least-squares standard
errors of the first pass, ``s^2 (A^T A)^-1``, the searched effects' without
their inflation) that the tool reported before. Printed per effect: the
fraction of truths inside each and the median half-width relative to the
truth; then the misspecified case (a first-order lag of the wrench searched
as a delay).

    python benchmarks/intervals.py [--seeds 6] [--duration 14] [--markdown FILE]

``make bench-intervals`` runs it and writes docs/intervals-results.md;
``tests/test_intervals.py`` pins a small subset.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from omavctl.learn.fit import fit_model
from omavctl.learn.fit_steps import first_pass
from omavctl.learn.flights import log_samples
from omavctl.learn.intervals import Z95
from omavctl.learn.signal import DEFAULT_SG_ORDER, DEFAULT_SG_WINDOW, SavitzkyGolay
from omavctl.logs import align
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import wobble
from omavctl.sim.truth import truth_from_tree
from omavctl.vehicle import Vehicle, default_vehicle

#: hidden effect -> (truth ``effects`` entry, parameter checked, its components)
CASES: dict[str, tuple[dict[str, Any], str]] = {
    "com_offset": ({"com_offset": {"r": [0.02, -0.015, 0.0]}}, "r"),
    "inertia_error": ({"inertia_error": {"scale": [1.18, 0.88, 1.22]}}, "scale"),
    "rotational_drag": ({"rotational_drag": {"D": [0.05, 0.05, 0.03]}}, "D"),
    "servo_lag": ({"servo_lag": {"T_s": 0.08}}, "T_s"),
    "motor_lag": ({"motor_lag": {"T_m": 0.05}}, "T_m"),
    "command_delay": ({"command_delay": {"tau_d": 0.03}}, "tau_d"),
}


@dataclass
class Draw:
    """One parameter component of one flight: truth, estimate, both intervals' half-widths."""

    effect: str
    seed: int
    truth: float
    value: float
    half: float
    white_value: float
    white_half: float

    @property
    def inside(self) -> bool:
        return abs(self.value - self.truth) <= self.half

    @property
    def white_inside(self) -> bool:
        return abs(self.white_value - self.truth) <= self.white_half


def flight(vehicle: Vehicle, truth: dict[str, Any], seed: int, duration: float) -> Any:  # FlightLog
    """A multi-sine wobble of ``duration`` s through the truth plant (seeded)."""
    ref = wobble(amplitude_deg=15.0, duration=duration, seed=seed)
    plant = truth_from_tree({"seed": seed, "effects": truth}, vehicle)
    return align(simulate(ref, vehicle, plant, seed=seed).log)


def white_first_pass(
    vehicle: Vehicle, log: Any, name: str, param: str
) -> tuple[np.ndarray, np.ndarray]:
    """First-pass estimate (size,) and white-residual standard error (size,) of ``name``."""
    sg = SavitzkyGolay(DEFAULT_SG_WINDOW, DEFAULT_SG_ORDER, 1.0 / vehicle.gains.rate_hz)
    samples, _ = log_samples(log, vehicle, sg)
    res = first_pass([samples], [name])
    if name in res.found:
        r = res.found[name]
        return np.array([r.value]), np.array([r.stderr / math.sqrt(r.inflation)])
    fp = res.first_pass
    assert fp.cov_white is not None
    phys = fp.estimates[name].effect.to_parameters(fp.theta, fp.cov_white)
    return phys[param][0], phys[param][1]


def run_case(name: str, seed: int, duration: float, points: int) -> list[Draw]:
    """Every checked component of ``name`` on one seeded flight."""
    vehicle = default_vehicle()
    truth, param = CASES[name]
    log = flight(vehicle, truth, seed, duration)
    with threadpool_limits(1):
        est = fit_model([log], vehicle, effects=[name], points=points, restarts=0, seed=seed)
    e = est.model.effects[name]
    wv, wse = white_first_pass(vehicle, log, name, param)
    true = np.atleast_1d(np.asarray(truth[name][param], float))
    out = []
    for j, t in enumerate(true):
        if t == 0.0:
            continue
        out.append(
            Draw(
                name,
                seed,
                float(t),
                float(e.values[param][j]),
                Z95 * float(e.stderr[param][j]),
                float(wv[j]),
                Z95 * float(wse[j]),
            )
        )
    return out


def table(draws: list[Draw]) -> list[str]:
    """Markdown rows: per effect, coverage and median relative half-width."""
    rows = [
        "| effect | parameters | inside the 95 % interval | median half-width | "
        "inside the white (OLS) interval | its median half-width |",
        "|---|---|---|---|---|---|",
    ]
    for name in CASES:
        ds = [d for d in draws if d.effect == name]
        if not ds:
            continue
        inside = sum(d.inside for d in ds)
        white = sum(d.white_inside for d in ds)
        half = float(np.median([d.half / abs(d.truth) for d in ds]))
        whalf = float(np.median([d.white_half / abs(d.truth) for d in ds]))
        rows.append(
            f"| {name} | {len(ds)} | {inside}/{len(ds)} ({inside / len(ds):.0%}) | "
            f"{half:.1%} of the truth | {white}/{len(ds)} ({white / len(ds):.0%}) | "
            f"{whalf:.1%} |"
        )
    inside = sum(d.inside for d in draws)
    white = sum(d.white_inside for d in draws)
    rows.append(
        f"| all | {len(draws)} | {inside}/{len(draws)} ({inside / len(draws):.0%}) | | "
        f"{white}/{len(draws)} ({white / len(draws):.0%}) | |"
    )
    return rows


def misspecified(seeds: list[int], duration: float, points: int) -> list[str]:
    """A 35 ms first-order lag of the whole wrench (motor lag) fitted as a delay."""
    vehicle = default_vehicle()
    rows = [
        "| seed | delay fitted to a 35 ms motor lag | 95 % interval | "
        "delay fitted to a 30 ms delay | 95 % interval |",
        "|---|---|---|---|---|",
    ]
    for seed in seeds:
        cells = []
        for truth in ({"motor_lag": {"T_m": 0.035}}, {"command_delay": {"tau_d": 0.03}}):
            log = flight(vehicle, truth, seed, duration)
            with threadpool_limits(1):
                fit = fit_model(
                    [log], vehicle, effects=["command_delay"], points=points, restarts=0
                )
            e = fit.model.effects["command_delay"]
            v, se = float(e.values["tau_d"][0]), float(e.stderr["tau_d"][0])
            cells += [f"{v * 1e3:.1f} ms", f"± {Z95 * se * 1e3:.1f} ms"]
        rows.append(f"| {seed} | " + " | ".join(cells) + " |")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--duration", type=float, default=14.0)
    ap.add_argument("--points", type=int, default=80)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--markdown", default=None)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    draws: list[Draw] = []
    for name in args.cases.split(","):
        for seed in range(args.seeds):
            draws += run_case(name, seed, args.duration, args.points)
            d = draws[-1]
            print(
                f"{name} seed {seed}: {d.value:.4g} ± {d.half:.2g} (white {d.white_value:.4g} "
                f"± {d.white_half:.2g}) truth {d.truth:.4g}",
                file=sys.stderr,
            )
    lines = table(draws)
    lines += ["", *misspecified(list(range(min(args.seeds, 3))), args.duration, args.points)]
    lines += ["", f"{args.seeds} seeds, {args.duration:g} s wobble flights, "
              f"{args.points} training points, {time.perf_counter() - t0:.0f} s"]  # fmt: skip
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
