"""Scorecard version 2 (docs/scorecard.md): its draws, planned flights and a pluggable
simulator.

What version 2 changes against version 1 (whose split, records and tables stay):

- sizes are multiples of the claim floor on the held-out flight
  (:mod:`benchmarks.scorecard_sizes`), so most hidden-effect draws are at or above it;
- ``planned`` is a trajectory family: the flight is ``omavctl plan``'s reference
  around the other flight's task, as the user's loop produces it. A planned held-out
  flight is planned with the first model (``fit`` on the fit flight, then ``plan``,
  then the flight); a planned fit flight with a pilot model fitted on the held-out
  flight (the user flew the task, fitted, planned, flew the plan and fits on it);
- ``evaluate`` runs with ``--horizons none``: the open-loop horizon table is a third
  of an evaluation's time and nothing the scoring reads depends on it.

Any split may fly its flights through another simulator (``--simulator``).
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.scorecard_sizes import draw_size

#: ``plan`` options of a planned flight: a small candidate pool keeps it ~20 s
PLAN_OPTIONS = ("--candidates", "6", "--sims", "2", "--test-points", "200", "--jobs", "1")
#: what ``evaluate`` skips in version 2 (the scoring reads none of it)
EVALUATE_OPTIONS = ("--horizons", "none")
PLACEHOLDERS = ("{reference}", "{truth}", "{out}", "{seed}")


def draw_spec_v2(split_name: str, split: dict[str, Any], index: int, effects: list[str]) -> Any:
    """Version 2's draw (the JSON-ready spec of :func:`scorecard_draws.draw_spec`)."""
    from benchmarks.scorecard_draws import (
        FORMATS,
        TIMINGS,
        _families,
        _task_options,
        truth_tree,
    )

    seed = split["seed_base"] + index
    rng = np.random.default_rng([seed, 0x5C2])
    n_hidden = int(rng.choice([0, 1, 2], p=[0.2, 0.5, 0.3]))
    pool = sorted(split.get("effects", effects))  # a split may draw from fewer effects
    names = sorted(str(x) for x in rng.choice(pool, n_hidden, replace=False))
    fams = _families(split, rng)
    timing = str(rng.choice(sorted(TIMINGS)))
    noise = float(rng.uniform(0.5, 2.0))
    fmts = [str(x) for x in rng.choice(sorted(FORMATS), 2)]
    # a planned flight flies around the other flight's task
    bases = [
        fams[1] if fams[0] == "planned" else fams[0],
        fams[0] if fams[1] == "planned" else fams[1],
    ]
    multiples, hidden = {}, {}
    for n in names:
        m, hidden[n] = draw_size(n, bases[1], noise, rng)
        multiples[n] = None if np.isnan(m) else round(m, 4)
    truth = truth_tree(hidden, noise, timing, rng)
    flights = []
    for role, fam, base, fmt in zip(("fit", "held"), fams, bases, fmts, strict=True):
        options = _task_options(base, rng)  # drawn for a planned flight too (the stream)
        f = {
            "role": role,
            "family": fam,
            "options": [] if fam == "planned" else options,  # it flies the other's task
            "format": FORMATS[fmt],
            "log": f"{role}{fmt}",
            "seed": int(rng.integers(0, 2**31)),
        }
        if fam == "planned":
            f["base"] = base
            f["plan"] = [*PLAN_OPTIONS, "--seed", str(int(rng.integers(0, 10_000)))]
        flights.append(f)
    return {
        "split": split_name,
        "version": 2,
        "index": index,
        "seed": seed,
        "hidden": hidden,
        "multiples": multiples,
        "timing": timing,
        "noise_scale": round(noise, 4),
        "truth": truth,
        "flights": flights,
    }


def simulator_argv(template: str, reference: str, truth: str, out: str, seed: int) -> list[str]:
    """The command line of an external simulator: ``template`` split as a shell would,
    each placeholder ({reference}, {truth}, {out}, {seed}) replaced in every word.
    Raises ValueError when {reference} or {out} is missing."""
    missing = [p for p in ("{reference}", "{out}") if p not in template]
    if missing:
        raise ValueError(f"--simulator {template!r} has no {' or '.join(missing)}")
    values = dict(zip(PLACEHOLDERS, (reference, truth, out, str(seed)), strict=True))
    argv = []
    for word in shlex.split(template):
        for key, value in values.items():
            word = word.replace(key, value)
        argv.append(word)
    return argv


def run_simulator(argv: list[str], d: Path, out: str, log: list[dict[str, Any]]) -> None:
    """Run an external simulator in ``d``; StepFailed if it fails or writes no log."""
    from benchmarks.scorecard_draws import StepFailed

    start = time.perf_counter()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    try:
        proc = subprocess.run(argv, cwd=d, env=env, capture_output=True, text=True, check=False)
    except OSError as exc:
        raise StepFailed(f"{shlex.join(argv)}: {exc.strerror or exc}") from None
    log.append({"command": shlex.join(argv), "seconds": round(time.perf_counter() - start, 2)})
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise StepFailed(f"{shlex.join(argv)}: exit {proc.returncode}: {last}")
    if not (d / out).exists():
        raise StepFailed(f"{shlex.join(argv)}: wrote no log at {out}")


def simulate(
    f: dict[str, Any], ref: str, d: Path, log: list[dict[str, Any]], simulator: str | None
) -> None:
    """Fly reference ``ref`` to flight ``f``'s log: ``omavctl simulate`` or ``simulator``."""
    from benchmarks.scorecard_draws import omavctl

    if simulator:
        run_simulator(
            simulator_argv(simulator, ref, "truth.yaml", f["log"], f["seed"]), d, f["log"], log
        )
        return
    # the draw's own log from an earlier run: simulate replaces only a log that bears
    # omavctl's mark, which logs an older omavctl wrote lack
    own = d / f["log"]
    if own.is_dir():
        shutil.rmtree(own)
    elif own.exists():
        own.unlink()
    omavctl(
        ["simulate", "--reference", ref, "--truth", "truth.yaml", "--seed", str(f["seed"]),
         "--out", f["log"]],
        d,
        log,
    )  # fmt: skip


def plan_argv(f: dict[str, Any], task: str, model: str) -> list[str]:
    """``omavctl plan`` arguments of planned flight ``f`` around ``task`` with ``model``."""
    return ["plan", "--task", task, "--model", model, "--out", f"{f['role']}-ref.csv", *f["plan"]]


def fly_planned(
    spec: dict[str, Any], d: Path, log: list[dict[str, Any]], simulator: str | None
) -> dict[str, Any] | None:
    """Plan and fly the draw's planned flight (the other one is flown already). Returns
    the first fit's ``--json`` object when it was made here (a planned held-out
    flight is planned with it), else None."""
    from benchmarks.scorecard_draws import omavctl

    fit, held = spec["flights"]
    if held["family"] == "planned":
        first = omavctl(["fit", fit["log"], "--out", "m0.npz"], d, log)
        omavctl(plan_argv(held, "fit-ref.csv", "m0.npz"), d, log)
        simulate(held, "held-ref.csv", d, log, simulator)
        return first
    omavctl(["fit", held["log"], "--out", "pilot.npz"], d, log)
    omavctl(plan_argv(fit, "held-ref.csv", "pilot.npz"), d, log)
    simulate(fit, "fit-ref.csv", d, log, simulator)
    return None
