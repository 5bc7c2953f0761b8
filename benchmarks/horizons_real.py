"""Issue 28's must-show rows on the shared real logs, from the examples' models.

    make -C examples crazyflie betaflight px4tools B=DIR   # fits the models (~15 min)
    python benchmarks/horizons_real.py DIR OUT.md           # evaluates them (~4 min)

Per evaluation (the examples' fits and judged windows): the full model's 0.5 s
body-rate error over physics + effects' per axis, the band's 2σ coverage at each
horizon over all axes with the worst axis in brackets, and the model's one-step 2σ
coverage per axis. Results: docs/horizons.md (session 32).
"""

import sys
from pathlib import Path

from omavctl.diagnose.evaluate import evaluate

S = Path(__file__).resolve().parents[2] / "shared/data/real"
CF = S / "arpl_crazyflie"
BF = S / "betaflight_cs110"


Case = tuple[str, list[Path], Path, tuple[float, float | None] | None]


def cases(R: Path) -> list[Case]:
    """(name, models, judged log, time window) of every evaluation, models under R."""
    return [
        (
            "px4tools (fit 6.5-15 s, judged 15 s-)",
            [R / "px4tools/gp.npz"],
            S / "px4tools_octocopter/01_07_59.csv",
            (15.0, None),
        ),
        ("Crazyflie window base", [R / "crazyflie/base.npz"], CF / "log15", (15.76, 50.76)),
        ("Crazyflie window lag", [R / "crazyflie/lag.npz"], CF / "log15", (15.76, 50.76)),
        ("Crazyflie halves base", [R / "crazyflie/half-base.npz"], CF / "log15", (33.26, 50.76)),
        ("Crazyflie halves lag", [R / "crazyflie/half-lag.npz"], CF / "log15", (33.26, 50.76)),
        ("Crazyflie halves drag", [R / "crazyflie/half-drag.npz"], CF / "log15", (33.26, 50.76)),
        (
            "Betaflight smooth -> better",
            [R / "betaflight/example_smooth_tune.npz"],
            BF / "better_tune.csv.gz",
            None,
        ),
        (
            "Betaflight better -> smooth",
            [R / "betaflight/better_tune.npz"],
            BF / "example_smooth_tune.csv.gz",
            None,
        ),
    ]


def main() -> None:
    out = []
    for name, models, log, win in cases(Path(sys.argv[1])):
        t = evaluate(models, [log], time_window=win, with_diagnosis=False).tree
        h = t["horizons"]
        full, eff = h["table"]["model"], h["table"]["effects"]
        ratio = "/".join(
            f"{full[-1]['rate_error'][a] / eff[-1]['rate_error'][a]:.2f}" for a in "xyz"
        )
        cov = ", ".join(
            f"{100 * r['coverage']['all']:.0f} ({100 * min(r['coverage'][a] for a in 'xyz'):.0f})"
            for r in full
        )
        one = "/".join(f"{100 * t['metrics']['model']['coverage_2sigma'][a]:.0f}" for a in "xyz")
        line = f"| {name} | {ratio} | {cov} % | {one} % |"
        print(line, flush=True)
        out.append(line)
    Path(sys.argv[2]).write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
