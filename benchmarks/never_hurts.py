"""A model that never hurts and a band that never overclaims, on flights of other kinds.

The cases of issue 26 that ``benchmarks/generalise.py``'s figure-8 / wobble pairs
do not hold: fit on a multi-sine or a chirp, judge on a figure-8 or on random
attitude steps, with a hidden effect (a wrench lag, a drag, an inertia error) or
none. Printed per case and axis: model RMSE over physics-only RMSE (target
<= 1.05) and the 2-sigma coverage of the model's band (target >= 0.85; wider
than needed outside the fit flight's inputs is accepted).

    python benchmarks/never_hurts.py [--cases NAME,...] [--workdir DIR] [--markdown FILE]

``tests/test_never_hurts.py`` pins the cases; docs/generalisation.md has the table.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from omavctl.sim.tasks import Envelope, _attitude_task, fig8, wobble
from omavctl.sim.trajectory import Trajectory

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.generalise import Outcome, _fmt, _outcome


def chirp(
    amplitude_deg: float = 20.0,
    f0: float = 0.1,
    f1: float = 1.0,
    duration: float = 16.0,
    ramp: float = 2.0,
) -> Trajectory:
    """Roll and pitch chirps (frequency linear from ``f0`` to ``f1`` Hz; pitch a
    quarter period behind), yaw a half-size chirp; a ``ramp`` s envelope at both ends.
    Angles, rates and accelerations exact."""
    t = np.arange(round(duration * 100) + 1) / 100.0
    e, de, dde, _ = Envelope(duration, ramp)(t)
    axes = []
    for scale, shift in ((1.0, 0.0), (1.0, np.pi / 2), (0.5, np.pi / 4)):
        a = np.deg2rad(amplitude_deg) * scale
        phase = 2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * duration)) + shift
        dphase = 2 * np.pi * (f0 + (f1 - f0) * t / duration)
        ddphase = 2 * np.pi * (f1 - f0) / duration
        s, c = np.sin(phase), np.cos(phase)
        v = a * e * s
        d1 = a * (de * s + e * dphase * c)
        d2 = a * (dde * s + 2 * de * dphase * c + e * ddphase * c - e * dphase**2 * s)
        axes.append((v, d1, d2))
    return _attitude_task(t, axes[0], axes[1], 1.0, yaw=axes[2])


def attitude_steps(
    amplitude_deg: float = 25.0,
    move: float = 0.3,
    hold: float = 1.2,
    duration: float = 16.0,
    seed: int = 3,
) -> Trajectory:
    """Random attitude steps: every ``hold`` s a new roll, pitch (and half-size yaw)
    target within +-amplitude, reached in ``move`` s along a quintic (rates and
    accelerations consistent with the angles); level at both ends."""
    t = np.arange(round(duration * 100) + 1) / 100.0
    rng = np.random.default_rng(seed)
    n = int(duration / hold)
    targets = rng.uniform(-1, 1, (n + 1, 3)) * np.deg2rad(amplitude_deg) * [1, 1, 0.5]
    targets[0] = targets[-1] = 0.0
    value, rate, acc = (np.zeros((t.size, 3)) for _ in range(3))
    for k in range(1, n + 1):
        s = np.clip((t - (k * hold - move)) / move, 0.0, 1.0)
        inside = ((s > 0) & (s < 1))[:, None]
        step = targets[k] - targets[k - 1]
        value += (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None] * step
        rate += inside * ((30 * s**2 - 60 * s**3 + 30 * s**4) / move)[:, None] * step
        acc += inside * ((60 * s - 180 * s**2 + 120 * s**3) / move**2)[:, None] * step
    axes = [(value[:, i], rate[:, i], acc[:, i]) for i in range(3)]
    return _attitude_task(t, axes[0], axes[1], 1.0, yaw=axes[2])


#: trajectory name -> generator (16 s each)
FLIGHTS: dict[str, Any] = {
    "fig8": lambda: fig8(roll_deg=20, pitch_deg=20, period=5.0, duration=16.0, ramp=2.0),
    "wobble": lambda: wobble(amplitude_deg=25, bandwidth=0.8, duration=16.0, ramp=2.0),
    "chirp": chirp,
    "steps": attitude_steps,
}
#: case -> (truth effects, fit flight, held-out flight)
CASES: dict[str, tuple[dict[str, Any], str, str]] = {
    "motor_lag wobble->fig8": ({"motor_lag": {"T_m": 0.035}}, "wobble", "fig8"),
    "motor_lag chirp->fig8": ({"motor_lag": {"T_m": 0.035}}, "chirp", "fig8"),
    "drag chirp->steps": ({"rotational_drag": {"D": [0.05, 0.05, 0.03]}}, "chirp", "steps"),
    "inertia chirp->steps": ({"inertia_error": {"scale": [1.18, 0.88, 1.22]}}, "chirp", "steps"),
    "none chirp->steps": ({}, "chirp", "steps"),
    "none chirp->fig8": ({}, "chirp", "fig8"),
    "none steps->chirp": ({}, "steps", "chirp"),
}


def fly(workdir: Path, case: str) -> tuple[Path, Path]:
    """Simulate a case's fit and held-out flights (CSV logs, kept across runs)."""
    from omavctl.logs import write_log
    from omavctl.sim.plant import simulate
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import default_vehicle

    effects, fit_on, held_out = CASES[case]
    vehicle = default_vehicle()
    truth = truth_from_tree({"effects": effects}, vehicle)
    tag = case.split(" ")[0]
    out = []
    for seed, name in ((1, fit_on), (2, held_out)):
        path = workdir / f"{tag}-{name}-{seed}.csv"
        if not path.exists():
            write_log(path, simulate(FLIGHTS[name](), vehicle, truth, seed=seed).log)
        out.append(path)
    return out[0], out[1]


def run_case(workdir: Path, case: str, points: int = 100, diagnose: bool = True) -> Outcome:
    """Fit on the case's fit flight with ``fit``'s defaults (``points``, 1 restart),
    evaluate on its held-out flight (without the horizons table, which no
    :class:`Outcome` reads; ``diagnose`` False: without the diagnosis, ``missing`` None,
    which changes neither the metrics nor the envelope)."""
    from omavctl.diagnose.evaluate import evaluate
    from omavctl.learn.fit import fit_model
    from omavctl.learn.model_file import save_model

    fit_log, held = fly(workdir, case)
    result = fit_model([fit_log], points=points, restarts=1)
    model = workdir / f"{case.replace(' ', '_').replace('>', '')}.npz"
    save_model(model, result.model)
    tree = evaluate([model], [held], horizons=(), with_diagnosis=diagnose).tree
    _, fit_on, held_out = CASES[case]
    return _outcome(tree, result.model, case, "100Hz-held", fit_on, held_out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--workdir", type=Path, default=None)
    parser.add_argument("--markdown", type=Path, default=None)
    args = parser.parse_args(argv)
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="never_hurts-"))
    workdir.mkdir(parents=True, exist_ok=True)
    rows = []
    with threadpool_limits(1):
        for case in args.cases.split(","):
            start = time.perf_counter()
            o = run_case(workdir, case)
            line = (
                f"| {case} | {_fmt(o.physics_rmse, 3)} | {_fmt(o.ratio)} | {_fmt(o.coverage)} "
                f"| {o.outside:.2f} | {_fmt(o.coverage_inside)} | {', '.join(o.missing) or '—'} |"
            )
            rows.append(line)
            print(line, f"({time.perf_counter() - start:.0f} s)", flush=True)
    if args.markdown:
        head = (
            "| case | physics | ratio | coverage | outside | coverage inside | missing |\n"
            "|---|---|---|---|---|---|---|\n"
        )
        args.markdown.write_text(head + "\n".join(rows) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
