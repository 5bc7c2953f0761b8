"""drag_moment's measured force in rollouts on the px4tools octocopter (docs/horizons.md,
session 15): held at each window's start, rolled forward from the rolled-out attitude
(raw start sample, or its trailing mean: what ``evaluate`` does), or read along the
window (an oracle), against the same fit without drag_moment.

Fits on 6.5-15 s with the accelerometer mapped (``IMU_AccX..Z``, added to a copy of
``examples/px4tools-octocopter.yaml``), with and without ``--effects drag_moment``,
evaluates from 15 s. Prints per variant the one-step RMSE of physics + effects, the
0.5 s body-rate error (physics + effects and the full model) per axis, the band's
coverage per horizon, the lateral drag d the log gives, and how the drag regressor
follows the measured angular acceleration (an accelerometer off the centre of mass
reads ``alpha x r``). About a minute with the fits in --workdir, two without.

    python benchmarks/horizons_force.py [--workdir DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from unittest import mock

import numpy as np

import omavctl.diagnose.evaluate as ev
import omavctl.learn.rollout_residual as rr
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import load_model, save_model
from omavctl.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared/data/real/px4tools_octocopter/01_07_59.csv"
ACC = '  specific_force: {x: "IMU_AccX", y: "IMU_AccY", z: "IMU_AccZ"}  # m/s^2, FRD\n'


def _models(work: Path) -> tuple[Path, Path]:
    yaml = work / "octo.yaml"
    yaml.write_text((ROOT / "examples" / "px4tools-octocopter.yaml").read_text() + ACC)
    vehicle = load_vehicle(yaml)
    out = []
    for name, effects in (("base", None), ("drag_moment", ["drag_moment"])):
        path = work / f"{name}.npz"
        if not path.exists():
            fit = fit_model([REAL], vehicle, effects=effects, time_window=(6.5, 15.0))
            save_model(path, fit.model)
        out.append(path)
    return out[0], out[1]


def _row(name: str, model: Path) -> None:
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


def _why(model: Path) -> None:
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
    base, dm = _models(work)
    _row("without drag_moment", base)
    with mock.patch.object(rr, "PREDICT_FORCE", False):
        _row("drag_moment, force held (session 14)", dm)
    with mock.patch.object(rr, "START_MEAN", False):
        _row("drag_moment, rolled, raw start", dm)
    _row("drag_moment, rolled, mean start (now)", dm)
    with mock.patch.object(rr, "HOLD_MEASURED", False):
        _row("drag_moment, force read (oracle)", dm)
    _why(dm)


if __name__ == "__main__":
    main()
