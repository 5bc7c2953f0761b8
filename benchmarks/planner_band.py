"""The planner's band beside the model's: what ``plan`` leaves out and how much it is.

    python benchmarks/planner_band.py MODEL.npz [MODEL.npz ...]

Per model, the mean over axes and points of three variances ((rad/s^2)^2) at three
sets of inputs (the training inputs; the same spread 1.3x and 2x about their mean,
reaching beyond the training box): ``planner`` the band the planner's cost integrates
(:meth:`omavctl.planning.gp.GPAxes.band_variance`: the calibrated posterior variance
and its growth beyond the box), ``latent`` the model's own latent variance
(``gp_predict`` without noise: the same plus what weighing the mean adds,
``mean_shrink``) and ``with noise`` the model's band for a new measurement
(``gp_predict(noise=True)``: plus ``band_noise`` inside the fit inputs, rising to
``noise_variance`` with the torque and reach growth beyond them,
``omavctl/learn/band.py``); ``noise share`` is the part of the last that is noise.
Why the planner leaves the noise out: ``GPAxes.band_variance``'s docstring.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def compare(path: str) -> list[str]:
    """The table's lines for one model file."""
    from omavctl.learn.model_file import load_model
    from omavctl.planning.gp import GPAxes

    model = load_model(path)
    gp = GPAxes.from_model(model)
    x = np.asarray(model.inputs, float)
    centre = x.mean(axis=0)
    lines = [
        f"{path}: band_noise {np.round(model.band_noise, 5)}, "
        f"noise_variance {np.round(model.noise_variance, 5)}"
    ]
    for name, spread in (("training inputs", 1.0), ("1.3x about the mean", 1.3), ("2x", 2.0)):
        z = centre + spread * (x - centre)
        planner = float(gp.band_variance(model.normalise(z)).mean())
        latent = float(np.mean(model.gp_predict(z, noise=False)[1]))
        full = float(np.mean(model.gp_predict(z, noise=True)[1]))
        lines.append(
            f"  {name:20s} planner {planner:.3e}  latent {latent:.3e}  with noise "
            f"{full:.3e}  noise share {1 - latent / full:.0%}"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+", help="model files (.npz from fit)")
    args = ap.parse_args(argv)
    for path in args.models:
        print("\n".join(compare(path)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
