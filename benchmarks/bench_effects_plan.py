"""Benchmark of ``plan --objective effects``: which second flight pins hidden effects down.

Run: python benchmarks/bench_effects_plan.py [--workdir DIR] [--seeds 1 2 3] [--out FILE]
(``make bench-effects`` writes docs/plan-effects-results.md).

Per seed s, every step the ``omavctl`` command a user would run:

1. truth: the default omav with its actuator imperfections (servo and motor lag,
   rotor spread, interference) plus hidden ``rotational_drag`` D = (0.05, 0.05,
   0.03) N m s^2 and a 30 ms ``command_delay``;
2. first flight: the figure-8 (26 deg, 8 s period), sensor-noise seed s;
   ``fit --effects rotational_drag,command_delay``;
3. three candidates for the second flight, from the same first model and plan seed:
   ``plan --objective effects --effects rotational_drag,command_delay``,
   ``plan --objective variance`` (the paper's), and the task flown again;
4. each flown through the same truth (noise seed 100 + s), then
   ``fit FIRST SECOND --effects ...``: the standard errors ``fit`` reports and the
   errors against the truth, per parameter and as geometric means of the
   relative values (relative to the true parameter).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EFFECTS = "rotational_drag,command_delay"
TRUTH = {"D": [0.05, 0.05, 0.03], "tau_d": 0.03}
TRUTH_YAML = """# bench_effects_plan.py: the default omav + hidden drag and command delay
seed: 1
effects:
  rotational_drag: {D: [0.05, 0.05, 0.03]}   # N m s^2
  command_delay: {tau_d: 0.03}               # s
"""
KINDS = ("effects", "variance", "task")
#: Largest angular-acceleration deviation of both plans' candidates, rad/s^2.
AMPLITUDE = 6.0


def omavctl(*args: str) -> dict:
    """Run ``omavctl ARGS --json -q`` in a child process; its JSON object."""
    cmd = [sys.executable, "-m", "omavctl", *args, "--json", "-q"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stdout}\n{done.stderr}")
    return json.loads(done.stdout)


def omavctl_in_process(*args: str) -> dict:
    """``omavctl``'s JSON as :func:`omavctl` returns it, run in this process (typer's
    test runner): the same commands and numbers without a Python start per command
    (about 1.3 CPU seconds each, 11 a seed; tests/test_plan_effects.py uses it)."""
    from typer.testing import CliRunner

    from omavctl.cli import app

    done = CliRunner().invoke(app, [*args, "--json", "-q"])
    if done.exit_code != 0:
        raise RuntimeError(f"omavctl {' '.join(args)} failed:\n{done.output}")
    return json.loads(done.stdout)


def _parameters(fit: dict) -> dict[str, tuple[float, float, float]]:
    """label -> (estimate, standard error, truth) from ``fit --json``."""
    eff = fit["effects"]
    drag, delay = eff["rotational_drag"], eff["command_delay"]
    out = {
        f"D[{i}]": (drag["values"]["D"][i], drag["stderr"]["D"][i], TRUTH["D"][i]) for i in range(3)
    }
    out["tau_d"] = (delay["values"]["tau_d"][0], delay["stderr"]["tau_d"][0], TRUTH["tau_d"])
    return out


def _summary(params: dict[str, tuple[float, float, float]]) -> dict:
    rel_se = [se / abs(t) for _, se, t in params.values()]
    rel_err = [abs(v - t) / abs(t) for v, _, t in params.values()]
    return {
        "parameters": {
            k: {"value": v, "stderr": se, "truth": t} for k, (v, se, t) in params.items()
        },
        "rel_se_gmean": math.exp(sum(math.log(x) for x in rel_se) / len(rel_se)),
        "max_rel_error": max(rel_err),
        "rel_errors": dict(zip(params, rel_err, strict=True)),
    }


def run_case(
    workdir: Path,
    seed: int = 1,
    duration: float = 20.0,
    candidates: int = 40,
    sims: int = 4,
    amplitude: float = AMPLITUDE,
    ideal: bool = False,
    run: Callable[..., dict] | None = None,
    points: int | None = None,
) -> dict:
    """One seed of the benchmark (module docstring) in ``workdir``; its numbers.

    ``ideal``: actuators without imperfections (no lags, interference, spread,
    backlash), so that the hidden delay is the plant's only delay. ``run``: how each
    command runs (default :func:`omavctl`, a child process per command). ``points``:
    the refits' ``--points`` (per log; fit's default when None).
    """
    command = run or omavctl
    w = Path(workdir)
    w.mkdir(parents=True, exist_ok=True)
    truth = w / "truth.yaml"
    truth.write_text(
        TRUTH_YAML
        + ("ideal: true                # actuators without imperfections\n" if ideal else "")
    )
    task, first = w / "fig8.csv", w / "first.csv"
    command(
        "task",
        "fig8",
        "--roll",
        "26",
        "--pitch",
        "26",
        "--period",
        "8",
        "--duration",
        str(duration),
        "--out",
        str(task),
    )
    command(
        "simulate",
        "--reference",
        str(task),
        "--truth",
        str(truth),
        "--seed",
        str(seed),
        "--out",
        str(first),
    )
    model = w / "first.npz"
    before = command(
        "fit", str(first), "--effects", EFFECTS, "--seed", str(seed), "--out", str(model)
    )
    plan_args = [
        "--task",
        str(task),
        "--model",
        str(model),
        "--candidates",
        str(candidates),
        "--sims",
        str(sims),
        "--amplitude",
        str(amplitude),
        "--seed",
        str(seed),
    ]
    out: dict = {"seed": seed, "first": _summary(_parameters(before)), "plans": {}}
    for kind in KINDS:
        reference = task
        if kind != "task":
            reference = w / f"plan-{kind}.csv"
            extra = ["--effects", EFFECTS] if kind == "effects" else []
            # the variance plan as docs/plan-effects-results.md measured it: before the
            # default --tilt-margin 10 (with it, on the test's 12 s draw, the variance plan
            # picked the effects plan's candidate: standard errors 0.207 both)
            extra += ["--tilt-margin", "90"] if kind == "variance" else []
            t0 = time.perf_counter()
            planned = command(
                "plan",
                *plan_args,
                "--objective",
                kind,
                *extra,
                "--scores",
                str(w / f"scores-{kind}.csv"),
                "--out",
                str(reference),
            )
            out["plans"][kind] = {
                "seconds": time.perf_counter() - t0,
                "best": planned["best"],
                "expected": planned.get("effects"),
            }
        second = w / f"second-{kind}.csv"
        command(
            "simulate",
            "--reference",
            str(reference),
            "--truth",
            str(truth),
            "--seed",
            str(100 + seed),
            "--out",
            str(second),
        )
        refit = command(
            "fit",
            str(first),
            str(second),
            "--effects",
            EFFECTS,
            "--seed",
            str(seed),
            *(["--points", str(points)] if points else []),
            "--out",
            str(w / f"second-{kind}.npz"),
        )
        out[kind] = _summary(_parameters(refit))
    out["se_ratio_vs_task"] = out["task"]["rel_se_gmean"] / out["effects"]["rel_se_gmean"]
    out["se_ratio_vs_variance"] = out["variance"]["rel_se_gmean"] / out["effects"]["rel_se_gmean"]
    return out


def markdown(results: list[dict], seconds: float) -> str:
    """The results as a Markdown section (docs/plan-effects-results.md)."""
    lines = [
        "# `plan --objective effects`: benchmark results",
        "",
        "Generated by `make bench-effects` (`benchmarks/bench_effects_plan.py`; protocol in "
        "its docstring and in [plan-effects.md](plan-effects.md)). Hidden: rotational drag "
        "D = (0.05, 0.05, 0.03) N m s² and a 30 ms command delay, on top of the default "
        "actuator imperfections. Each second flight is added to the same first figure-8 "
        "flight and `fit --effects rotational_drag,command_delay` runs on both. Standard "
        "errors are those `fit` reports; relative = divided by the true value; errors are "
        f"against the truth. Wall time {seconds:.0f} s.",
        "",
        "| seed | second flight | rel. SE (geo. mean) | D[0] | D[1] | D[2] | tau_d, ms | "
        "largest rel. error |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        for kind in ("first", *KINDS):
            s = r[kind]
            p = s["parameters"]
            cells = [
                f"{p[f'D[{i}]']['value']:.4f} ± {p[f'D[{i}]']['stderr']:.4f}" for i in range(3)
            ]
            cells.append(f"{1e3 * p['tau_d']['value']:.1f} ± {1e3 * p['tau_d']['stderr']:.1f}")
            name = {"first": "(first flight only)", "task": "the task again"}.get(
                kind, f"{kind} plan"
            )
            lines.append(
                f"| {r['seed']} | {name} | {s['rel_se_gmean']:.3f} | {' | '.join(cells)} | "
                f"{100 * s['max_rel_error']:.1f} % |"
            )
    lines += [
        "",
        "| seed | SE ratio task / effects | SE ratio variance / effects |",
        "|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| {r['seed']} | {r['se_ratio_vs_task']:.2f} | {r['se_ratio_vs_variance']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=ROOT / "build" / "bench-effects")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--candidates", type=int, default=40)
    ap.add_argument("--sims", type=int, default=4)
    ap.add_argument("--amplitude", type=float, default=AMPLITUDE)
    ap.add_argument("--out", type=Path, default=None, help="Write the Markdown results here.")
    ap.add_argument(
        "--ideal", action="store_true", help="ideal actuators: the hidden delay is the only one"
    )
    args = ap.parse_args()
    t0 = time.perf_counter()
    results = []
    for s in args.seeds:
        r = run_case(
            args.workdir / f"s{s}",
            s,
            candidates=args.candidates,
            sims=args.sims,
            amplitude=args.amplitude,
            ideal=args.ideal,
        )
        print(json.dumps({k: r[k] for k in ("seed", "se_ratio_vs_task", "se_ratio_vs_variance")}))
        for kind in ("first", *KINDS):
            print(
                f"  {kind:9s} rel SE {r[kind]['rel_se_gmean']:.3f}  max rel error "
                f"{100 * r[kind]['max_rel_error']:.1f} %  {r[kind]['rel_errors']}"
            )
        results.append(r)
    text = markdown(results, time.perf_counter() - t0)
    (args.workdir / "results.json").write_text(json.dumps(results, indent=1))
    if args.out is not None:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
