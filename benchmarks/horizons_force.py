"""drag_moment's measured force in rollouts on the px4tools octocopter (docs/horizons.md,
sessions 15 and 16): on the raw force (before session 16) and on the force less the
accelerometer's lever term (what fit and evaluate do now), each held at the window's
start, rolled forward from the rolled-out attitude (what evaluate does) or read along
the window (an oracle), against the same fit without drag_moment.

Fits on 6.5-15 s with the accelerometer mapped (``IMU_AccX..Z``, added to a copy of
``examples/px4tools-octocopter.yaml``): without drag_moment, with it on the raw force,
with it on the force less the lever term; evaluates from 15 s. Prints per variant the
one-step RMSE of physics + effects, the 0.5 s body-rate error (physics + effects and the
full model) per axis, the band's coverage per horizon; the diagnosis of the model
without drag_moment (is drag_moment claimed, where is it ranked); the lever arm each
half gives; how the drag regressor follows the measured angular acceleration; adding
drag_moment paired on the same windows (one-step, 0.01 s and 0.5 s per axis, the 0.5 s
change with its standard error, the findings) and the fitted h with its interval.
About 3 minutes with the fits in --workdir, 6 without.

    python benchmarks/horizons_force.py [--workdir DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from unittest import mock

import numpy as np

import omavctl.diagnose.evaluate as ev
import omavctl.diagnose.horizon_findings as hf
import omavctl.learn.imu_lever as il
import omavctl.learn.rollout_residual as rr
from omavctl.diagnose.verdict import verdict
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import load_model, save_model
from omavctl.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared/data/real/px4tools_octocopter/01_07_59.csv"
ACC = '  specific_force: {x: "IMU_AccX", y: "IMU_AccY", z: "IMU_AccZ"}  # m/s^2, FRD\n'


def _models(work: Path) -> tuple[Path, Path, Path]:
    """Without drag_moment; with it on the raw force (session 15); with it on the force
    less the accelerometer's lever term (session 16, what fit does)."""
    yaml = work / "octo.yaml"
    yaml.write_text((ROOT / "examples" / "px4tools-octocopter.yaml").read_text() + ACC)
    vehicle = load_vehicle(yaml)
    out = []
    cases = (("base", None, True), ("drag_moment", ["drag_moment"], False),
             ("drag_moment-lever", ["drag_moment"], True))  # fmt: skip
    for name, effects, lever in cases:
        path = work / f"{name}.npz"
        if not path.exists():
            with mock.patch.object(il, "REMOVE_LEVER", lever):
                fit = fit_model([REAL], vehicle, effects=effects, time_window=(6.5, 15.0))
            save_model(path, fit.model)
        out.append(path)
    return out[0], out[1], out[2]


def _row(name: str, model: Path) -> dict:
    tree = ev.evaluate([model], [REAL], time_window=(15.0, None)).tree
    one = tree["metrics"]["effects"]["rmse"]
    h = tree["horizons"]
    last = {k: h["table"][k][-1]["rate_error"] for k in ("effects", "model")}
    cov = " ".join(
        "/".join(f"{100 * r['coverage'][a]:.0f}" for a in "xyz") for r in h["table"]["model"]
    )
    print(
        f"{name:<34} one-step {one['x']:.3f}/{one['y']:.3f} rad/s^2 | 0.5 s effects "
        + "/".join(f"{last['effects'][a]:.4f}" for a in ("x", "y", "norm"))
        + " model "
        + "/".join(f"{last['model'][a]:.4f}" for a in ("x", "y", "norm"))
        + f" rad/s | coverage {cov} %"
    )
    return tree


def _verdict(name: str, tree: dict) -> None:
    """What the diagnosis claims, where it ranks drag_moment, the verdict's first line."""
    d = tree["diagnosis"]
    names = [e.get("name") for e in d.get("missing_effects", [])]
    rank = names.index("drag_moment") + 1 if "drag_moment" in names else None
    first = verdict(tree)[0].text
    print(
        f"  verdict ({name}): missing {d.get('missing')}, learned {d.get('learned_claims')}; "
        f"drag_moment ranked {rank} of {len(names)} candidates; first line: {first[:160]}"
    )


def _paired(base: Path, model: Path) -> None:
    """Adding drag_moment, model against base on the same windows: per axis the one-step
    RMSE of physics + effects, its body-rate error at the first and last horizon, the
    last's paired change with its standard error, and the findings."""
    tree = ev.evaluate([base, model], [REAL], time_window=(15.0, None)).tree
    h = tree["horizons"]
    one = [tree["metrics_by_model"][j]["effects"]["rmse"] for j in (0, 1)]
    for axis in ("x", "y", "z", "norm"):
        a, b = h["table"]["effects"], h["table"]["effects_1"]
        se = hf.paired_se(a[-1], b[-1], axis)
        step = "" if axis == "norm" else f"one-step {one[0][axis]:.3f} -> {one[1][axis]:.3f}, "
        print(
            f"  {axis}: {step}{h['seconds'][0]:g} s {a[0]['rate_error'][axis]:.4f} -> "
            f"{b[0]['rate_error'][axis]:.4f}, {h['seconds'][-1]:g} s "
            f"{a[-1]['rate_error'][axis]:.4f} -> {b[-1]['rate_error'][axis]:.4f} "
            f"(change {b[-1]['rate_error'][axis] - a[-1]['rate_error'][axis]:+.4f} "
            f"± {se if se is None else round(se, 4)}) rad/s"
        )
    print(f"  findings: {[f['code'] + ' ' + str(f.get('axis')) for f in h.get('findings', [])]}")


def _lever(model: Path) -> None:
    """The accelerometer's lever arm each half gives (the log's note, as fit and evaluate
    say it)."""
    m = load_model(model)
    rate, sg = ev._grid(m)
    for window in ((6.5, 15.0), (15.0, None)):
        notes = ev._read_log(REAL, m.vehicle, rate, sg, window)[2]["notes"]
        print(f"  {window}: " + next(n for n in notes if n.startswith("accelerometer lever")))


def _why(model: Path) -> None:
    """The lateral drag of the judged log and how drag_moment's regressor follows the
    measured angular acceleration (after the lever term is removed, when it is)."""
    m = load_model(model)
    rate, sg = ev._grid(m)
    s, g, _, _ = ev._read_log(REAL, m.vehicle, rate, sg, (15.0, None))
    win = rr.gather([s], [g], round(0.5 * rate), 1)
    got = rr._measured(m, win, [s])
    assert got is not None
    x = s.regressors["drag_moment"][:, :, 0]
    corr = [np.corrcoef(x[:, a], s.omega_dot[:, a])[0, 1] for a in range(2)]
    print(
        f"lateral drag d from the judged log: {got.drag:.3g} 1/s; drag regressor against the "
        f"measured angular acceleration, corr x/y: {corr[0]:.2f}/{corr[1]:.2f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="horizons-force-"))
    work.mkdir(parents=True, exist_ok=True)
    base, dm, dml = _models(work)
    with mock.patch.object(il, "REMOVE_LEVER", False):
        _verdict("raw force", _row("without drag_moment, raw force", base))
        with mock.patch.object(rr, "PREDICT_FORCE", False):
            _row("drag_moment, raw force, held (s14)", dm)
        _row("drag_moment, raw force, rolled (s15)", dm)
        with mock.patch.object(rr, "HOLD_MEASURED", False):
            _row("drag_moment, raw force, oracle", dm)
        _why(dm)
    _verdict("lever removed", _row("without drag_moment, lever removed", base))
    _lever(base)
    with mock.patch.object(rr, "PREDICT_FORCE", False):
        _row("drag_moment, lever removed, held", dml)
    _row("drag_moment, lever removed, rolled (now)", dml)
    with mock.patch.object(rr, "HOLD_MEASURED", False):
        _row("drag_moment, lever removed, oracle", dml)
    _why(dml)
    print("adding drag_moment, paired on the same windows (physics + effects):")
    with mock.patch.object(il, "REMOVE_LEVER", False):
        print(" raw force (session 15):")
        _paired(base, dm)
    print(" lever removed (now):")
    _paired(base, dml)
    for name, path in (("raw force", dm), ("lever removed", dml)):
        est = load_model(path).effects["drag_moment"]
        lo, hi = est.interval95()["h"][0]
        print(f"  h fitted, {name}: {est.values['h'][0]:.4g} (95 %: {lo:.4g} to {hi:.4g})")


if __name__ == "__main__":
    main()
