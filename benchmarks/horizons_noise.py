"""The horizon band's gyro-noise term on the real PX4 log (docs/horizons.md, the band).

The px4tools octocopter (gyro recorded at about 83 Hz, aligned on the 100 Hz
grid): fit on 6.5-15 s (or ``--model``), evaluate from 15 s, with the band's
noise term three ways: the grid's estimate with independent samples (before),
the recorded samples' MAD std through the interpolation weights, and the
recorded samples' 95 % scale through them (what ``evaluate`` does). Prints the
noise and the coverage per horizon and axis.

    python benchmarks/horizons_noise.py [--model M.npz] [--workdir DIR]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from unittest import mock

import omavctl.diagnose.evaluate as ev
import omavctl.learn.recorded_noise as rn
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.learn.signal import rate_noise
from omavctl.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared/data/real/px4tools_octocopter/01_07_59.csv"


def _before(flight, index, grid_std):
    return rn.independent_noise(grid_std, index)


def _row(name: str, model: Path) -> None:
    h = ev.evaluate([model], [REAL], time_window=(15.0, None)).tree["horizons"]
    noise = h["rate_noise"][0]
    s_r = "/".join(f"{noise[a]:.2g}" for a in "xyz")
    cov = ", ".join(
        f"{r['seconds']:g} s " + "/".join(f"{100 * r['coverage'][a]:.1f}" for a in "xyz") + " %"
        for r in h["table"]["model"]
    )
    print(f"{name:<44} s_r {s_r} rad/s; coverage x/y/z: {cov}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, default=None)
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args()
    model = args.model
    if model is None:
        work = args.workdir or Path(tempfile.mkdtemp(prefix="horizons-noise-"))
        model = work / "px4tools-gp.npz"
        if not model.exists():
            vehicle = load_vehicle(ROOT / "examples" / "px4tools-octocopter.yaml")
            save_model(model, fit_model([REAL], vehicle, time_window=(6.5, 15.0)).model)
    with mock.patch.object(ev, "recorded_noise", _before):
        _row("grid estimate, independent (before)", model)
    with mock.patch.object(rn, "band_scale", rate_noise):
        _row("recorded samples, MAD std, interpolation", model)
    _row("recorded samples, 95 % scale, interpolation", model)


if __name__ == "__main__":
    main()
