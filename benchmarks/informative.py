"""Does the planned flight teach the model more than flying the task again or a random one?

Run: python benchmarks/informative.py [--workdir DIR] [--effects drag delay ...]
[--seeds 1 2] [--candidates 50] [--jobs 2] [--workers 2] [--out docs/informative.md]
(``make informative`` runs the defaults and writes docs/informative.md).

Per draw (a hidden effect set of :data:`EFFECT_SETS` x a seed s), every step the
``omavctl`` command a user would run, run by the command-line application in worker
processes that stay up (``--workers`` at once; the steps that do not need each other's
outputs run at once), and of ``evaluate`` only the metrics the benchmark reads
(:mod:`benchmarks.informative_calls`: the same numbers, a fraction of the time):

1. truth: the default omav's actuator imperfections plus the hidden effect(s);
   task: the figure-8 (26 deg, 8 s period, ``--duration`` s);
2. first flight of the task (noise seed s) -> ``fit`` -> the first model;
3. ``plan --task --model --candidates K --scores`` (variance objective, plan seed s;
   the defaults ``--region pool --tilt-margin 10``; ``--plan-args`` adds options to
   both plans, e.g. a wider candidate family ``--amplitude 3``), and a baseline plan on
   the same candidates and simulations (``--baseline-plan``): ``--region task`` (the paper's
   test points around the task: the objective before issue 29) or ``uncapped``
   (``--tilt-margin 90``: the default before the tilt margin);
4. second flights, all with noise seed 100 + s: the task again; the planned
   reference (and the baseline plan's choice); one random candidate of the
   same pool (a draw among the candidates feasible for the planned flight's limits, the
   tilt margin included: the same deviation distribution; seeded by the seed and the
   effect set, ``informative_stats.random_draws``: draws cached before that was so used
   the seed alone, one random flight for every effect set of a seed); ``--pool-extra``
   further random candidates of the pool (all of them ``drawn`` in result.json: the
   mean over them is a steadier random candidate than one), so that the best of all
   flown candidates by realised error is the oracle (a lower bound of the room the
   selection has); with ``--with-effects`` also ``plan --objective effects``;
5. ``fit FIRST SECOND`` -> refitted model; ``evaluate``'s RMSE on held-out flights:
   the task flown once more (noise seed 200 + s) and the region's flights, a faster
   figure-8 (20/30 deg, 6 s) and a wobble (15 deg); RMSE = mean over the axes;
6. closed loop: ``simulate --model`` flies the task with the refitted model in the
   controller (noise seed 300 + s); the mean |a* - omega_dot| over the axes
   (``tracking`` of ``evaluate``, the measure of docs/results.md).

The pool candidates are rebuilt from the ``--scores`` coefficients (9 significant
digits: within 1e-6 of the planned reference). A draw whose ``result.json`` exists
in the workdir is read, not rerun, so an interrupted run resumes.

Gains are per cent of the baseline's error, mean over draws with a 95 % t-interval
(:mod:`benchmarks.informative_stats`).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.informative_calls import cost, heldout, omavctl, start, stop
from benchmarks.informative_kept import add_kept, read_scores
from benchmarks.informative_md import markdown
from benchmarks.informative_stats import random_draws
from omavctl.planning.candidates import deviated_references
from omavctl.sim.trajectory import Trajectory, read_trajectory, write_trajectory

#: name -> the truth file's ``effects:`` entries (single effects and pairs)
EFFECT_SETS: dict[str, dict[str, str]] = {
    "drag": {"rotational_drag": "{D: [0.05, 0.05, 0.03]}"},
    "inertia": {"inertia_error": "{scale: [1.2, 1.2, 1.1]}"},
    "delay": {"command_delay": "{tau_d: 0.03}"},
    "com": {"com_offset": "{r: [0.01, -0.01, 0.0]}"},
    "drag+delay": {"rotational_drag": "{D: [0.05, 0.05, 0.03]}", "command_delay": "{tau_d: 0.03}"},
    "inertia+com": {
        "inertia_error": "{scale: [1.2, 1.2, 1.1]}",
        "com_offset": "{r: [0.01, -0.01, 0.0]}",
    },
}
#: held-out flights: name -> ``omavctl task`` arguments (the task itself is "task")
REGION = {
    "fast": ["fig8", "--roll", "20", "--pitch", "30", "--period", "6"],
    "wobble": ["wobble", "--amplitude", "15", "--seed", "3"],
}
#: what follows this line in --out was written by hand and is kept on regeneration
MARKER = "<!-- reading of the numbers above, by hand: kept when the page is regenerated -->"
TASK = ["fig8", "--roll", "26", "--pitch", "26", "--period", "8"]


def _rmse(rmse: dict[str, float]) -> float:
    """Mean over the axes of a model's RMSE per axis (``evaluate``'s), rad/s^2."""
    return float(np.mean(list(rmse.values())))


def _setup(w: Path, effects: dict[str, str], seed: int, duration: float) -> dict[str, Path]:
    """Truth file, task and held-out references and flights; the first flight."""
    truth = w / "truth.yaml"
    body = "".join(f"  {k}: {v}\n" for k, v in effects.items())
    truth.write_text(f"# benchmarks/informative.py\nseed: 1\neffects:\n{body}")
    dur = ["--duration", str(duration)]
    paths = {"truth": truth, "task": w / "task.csv"}
    omavctl("task", *TASK, *dur, "--out", str(paths["task"]))
    held = {"task": paths["task"]}
    for name, args in REGION.items():
        held[name] = w / f"{name}.csv"
        omavctl("task", *args, *dur, "--out", str(held[name]))
    flights = []
    for i, (name, ref) in enumerate(held.items()):
        paths[f"held-{name}"] = w / f"held-{name}-flight.csv"
        flights.append((ref, truth, 200 + seed + i, paths[f"held-{name}"]))
    paths["first"] = w / "first-flight.csv"
    flights.append((paths["task"], truth, seed, paths["first"]))
    _together([(_fly, *f) for f in flights])
    return paths


def _together(calls: list[tuple]) -> list:
    """``fn(*args)`` for every ``(fn, *args)`` of ``calls`` at once (each waits for a
    worker process: :mod:`benchmarks.informative_calls`); their results in order."""
    with ThreadPoolExecutor(max(len(calls), 1)) as ex:
        futures = [ex.submit(fn, *args) for fn, *args in calls]
        return [f.result() for f in futures]


def _fly(reference: Path, truth: Path, seed: int, out: Path, model: Path | None = None) -> None:
    """``simulate`` a reference through the truth (with a model in the controller)."""
    extra = ["--model", str(model)] if model is not None else []
    args = ["--reference", str(reference), "--truth", str(truth), "--seed", str(seed)]
    omavctl("simulate", *args, *extra, "--out", str(out))


def _judge(model: Path, paths: dict[str, Path], seed: int, w: Path, tag: str) -> dict:
    """Held-out RMSE per flight and closed-loop tracking of the task with ``model``
    (``evaluate``'s numbers: :func:`benchmarks.informative_calls.heldout`)."""
    names = ("task", *REGION)
    track = w / f"track-{tag}.csv"
    calls = [(heldout, model, paths[f"held-{name}"]) for name in names]
    *errors, _ = _together(
        [*calls, (_fly, paths["task"], paths["truth"], 300 + seed, track, model)]
    )
    out: dict = {name: _rmse(e["rmse"]) for name, e in zip(names, errors, strict=True)}
    out["region"] = float(np.mean([out[name] for name in REGION]))
    out["tracking"] = float(heldout(model, track)["tracking"]["mean"])
    return out


def _second(reference: Path, paths: dict[str, Path], seed: int, w: Path, tag: str) -> dict:
    """Fly ``reference``, refit on the first and this flight, judge the refitted model."""
    flight, model = w / f"second-{tag}.csv", w / f"refit-{tag}.npz"
    _fly(reference, paths["truth"], 100 + seed, flight)
    fit = omavctl("fit", str(paths["first"]), str(flight), "--seed", str(seed), "--out", str(model))
    out = _judge(model, paths, seed, w, tag)
    out["gp_on"] = [bool(fit["axes"][a]["gp_on"]) for a in "xyz"]
    return out


def _pool(w: Path, task: Path, chosen: list[int], scores: Path) -> dict[int, Path]:
    """Write the chosen candidates of ``plan --scores`` as references; index -> path."""
    coeffs, _ = read_scores(scores)
    refs = deviated_references(read_trajectory(task), coeffs[chosen])
    out = {}
    for k, ref in zip(chosen, refs, strict=True):
        out[k] = w / f"cand-{k}.csv"
        write_trajectory(out[k], Trajectory(ref))
    return out


def _plan(
    paths: dict[str, Path], w: Path, seed: int, cfg: argparse.Namespace, kind: str, tag: str = ""
) -> dict:
    """``plan`` the second flight (variance or effects objective; ``tag`` "-task": the
    baseline plan, with ``--region task`` or, for ``--baseline-plan uncapped``,
    ``--tilt-margin 90``); its JSON object."""
    args = ["--task", str(paths["task"]), "--model", str(paths["model"])]
    args += ["--candidates", str(cfg.candidates), "--sims", str(cfg.sims), "--seed", str(seed)]
    args += ["--objective", kind, "--jobs", "1", "--scores", str(w / f"scores-{kind}{tag}.csv")]
    args += shlex.split(cfg.plan_args)
    if tag == "-task":  # the second plan of a draw: --baseline-plan
        args += ["--region", "task"] if cfg.baseline_plan == "task-region" else []
        args += ["--tilt-margin", "90"] if cfg.baseline_plan == "uncapped" else []
    return omavctl("plan", *args, "--out", str(w / f"plan-{kind}{tag}.csv"))


def run_draw(w: Path, name: str, seed: int, cfg: argparse.Namespace) -> dict:
    """One draw (module docstring) in directory ``w``; its numbers.

    A draw whose ``result.json`` is already there (same settings) is read, not rerun.
    """
    done = w / "result.json"
    if done.is_file():
        return json.loads(done.read_text())
    began = time.perf_counter()
    w.mkdir(parents=True, exist_ok=True)
    paths = _setup(w, EFFECT_SETS[name], seed, cfg.duration)
    paths["model"] = w / "first.npz"
    omavctl("fit", str(paths["first"]), "--seed", str(seed), "--out", str(paths["model"]))
    first, planned, paper = _together(
        [
            (_judge, paths["model"], paths, seed, w, "first"),
            (_plan, paths, w, seed, cfg, "variance"),
            (_plan, paths, w, seed, cfg, "variance", "-task"),
        ]
    )
    res: dict = {"effects": name, "seed": seed, "first": first}
    _, cost = read_scores(w / "scores-variance.csv")
    _, cost_paper = read_scores(w / "scores-variance-task.csv")
    feasible = np.flatnonzero(np.isfinite(cost))
    drawn = random_draws(feasible.tolist(), seed, name, 1 + cfg.pool_extra)
    best, best_paper = int(planned["best"]), int(paper["best"])
    refs = _pool(w, paths["task"], sorted({best, best_paper, *drawn}), w / "scores-variance.csv")
    again, *seconds = _together(
        [(_second, paths["task"], paths, seed, w, "task")]
        + [(_second, ref, paths, seed, w, f"cand-{k}") for k, ref in refs.items()]
    )
    res["task_again"] = again
    res["pool"] = {
        str(k): {**second, "cost": float(cost[k]), "cost_task_region": float(cost_paper[k])}
        for k, second in zip(refs, seconds, strict=True)
    }
    res.update(best=best, random=drawn[0], drawn=drawn, task_cost=float(planned["task_cost"]))
    res.update(best_task_region=best_paper, task_cost_task_region=float(paper["task_cost"]))
    res.update(
        plan_args=cfg.plan_args,
        baseline_plan=cfg.baseline_plan,
        max_tilt_deg=float(planned["max_tilt_deg"]),
    )
    if cfg.with_effects:
        _plan(paths, w, seed, cfg, "effects")
        res["effects_plan"] = _second(w / "plan-effects.csv", paths, seed, w, "effects")
    res["seconds"] = time.perf_counter() - began
    done.write_text(json.dumps(res, indent=1))
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=Path("build/informative"))
    ap.add_argument("--effects", nargs="+", default=list(EFFECT_SETS), choices=list(EFFECT_SETS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--candidates", type=int, default=50)
    ap.add_argument("--sims", type=int, default=4)
    ap.add_argument("--pool-extra", type=int, default=3, help="random pool candidates also flown")
    ap.add_argument("--plan-args", default="", metavar="ARGS",
                    help="further options of both plans, e.g. '--amplitude 3' (the candidate "
                    "family; the pool, random candidate and oracle follow it)")  # fmt: skip
    ap.add_argument("--with-effects", action="store_true", help="also plan --objective effects")
    ap.add_argument("--baseline-plan", choices=["task-region", "uncapped"], default="task-region",
                    help="the second plan each draw flies: --region task, or the default "
                    "region without the tilt margin (--tilt-margin 90)")  # fmt: skip
    ap.add_argument("--jobs", type=int, default=2, help="draws run at once")
    ap.add_argument("--workers", type=int, default=2,
                    help="worker processes: the steps (flights, fits, plans, evaluations) "
                    "of all draws that run at once, one BLAS thread each")  # fmt: skip
    ap.add_argument("--out", type=Path, default=None, help="Markdown results (docs/informative.md)")
    ap.add_argument("--also", nargs="*", default=[], metavar="EFFECTS:SEED",
                    help="further draws beyond --effects x --seeds, e.g. drag:2")  # fmt: skip
    cfg = ap.parse_args(argv)
    draws = [(name, s) for s in cfg.seeds for name in cfg.effects]
    for item in cfg.also:
        name, _, seed = item.partition(":")
        if name not in EFFECT_SETS or not seed.isdigit():
            ap.error(
                f"--also {item}: expected EFFECTS:SEED with EFFECTS one of {list(EFFECT_SETS)}"
            )
        draws.append((name, int(seed)))
    began = time.perf_counter()
    start(cfg.workers)
    try:
        with ThreadPoolExecutor(cfg.jobs) as ex:
            futures = [ex.submit(run_draw, cfg.workdir / f"{n}-s{s}", n, s, cfg) for n, s in draws]
            results = [f.result() for f in futures]
    finally:
        stop()
    for kind, (n, cpu, wall) in sorted(cost().items(), key=lambda kv: -kv[1][1]):
        print(f"{kind:18s} {n:4.0f} steps  CPU {cpu:7.1f} s  wall {wall:7.1f} s", file=sys.stderr)
    results = [
        add_kept(cfg.workdir / f"{n}-s{s}", r) for (n, s), r in zip(draws, results, strict=True)
    ]
    text = markdown(results, vars(cfg), time.perf_counter() - began, argv or sys.argv[1:])
    print(text)
    if cfg.out is not None:
        old = cfg.out.read_text() if cfg.out.is_file() else ""
        if MARKER in old:  # the reading written by hand below the numbers stays
            text += "\n" + MARKER + old.split(MARKER, 1)[1]
        cfg.out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
