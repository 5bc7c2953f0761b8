"""What a fitted model records of how it was made (its ``provenance`` key).

Sources and their sha256, the filter, the k-medoids selection, the GP fitting
settings and their blocked validation, seed, time window, vehicle and command
units (``docs/file-formats.md``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from omavctl import __version__
from omavctl.learn.effect_fit import GAIN_EFFECT, GAIN_PRIOR_FACTOR, EffectFit, torque_gain
from omavctl.learn.fit_steps import FitOptions, GPFit
from omavctl.learn.flights import source_of
from omavctl.learn.points import KMEDOIDS_MAX_DIRECT
from omavctl.learn.validation import BLOCK_SECONDS, FOLDS, KEEP_RATIO, TARGET_COVERAGE

__all__ = ["fit_provenance"]


def fit_provenance(
    opts: FitOptions,
    kmethod: str,
    gp: GPFit,
    eff: EffectFit,
    n_total: int,
    first_pass: EffectFit,
    gain: tuple[np.ndarray, np.ndarray] | None,
) -> dict[str, Any]:
    """The provenance of a fit: options ``opts``, k-medoids method, GP fit, effects
    (``first_pass`` the least-squares estimates), samples used and, for a normalised
    torque command, the fitted gain and its standard error (3,) each."""
    vehicle, sg = opts.vehicle, opts.sg
    provenance = {
        "omavctl_version": __version__,
        "sources": [source_of(item) for item in opts.logs],
        "prior": opts.prior_source,
        "grid_rate_hz": vehicle.gains.rate_hz,
        "savitzky_golay": {
            "window": sg.window,
            "order": sg.order,
            "command_alignment": "hold kernel matching the derivative (docs/fit.md)",
        },
        "kmedoids": {
            "points": opts.points,
            "metric": "sqeuclidean",
            "method": "eager-swap PAM, seeded random start (omavctl.learn.kmedoids)",
            "selection": kmethod,
            "max_direct": KMEDOIDS_MAX_DIRECT,
        },
        "gp": _gp_provenance(opts, gp),
        "effects_explained_variance": [float(v) for v in eff.explained],
        "samples": n_total,
        "seed": opts.seed,
        "time_window": None if opts.time_window is None else list(opts.time_window),
        # evaluate's suggested refit command passes it as --vehicle
        "vehicle_path": vehicle.source if Path(vehicle.source).is_file() else None,
        "vehicle_abspath": (
            str(Path(vehicle.source).resolve()) if Path(vehicle.source).is_file() else None
        ),
        "command_units": dict(vehicle.command_units),
    }
    if gain is not None:
        provenance["torque_gain"] = _gain_provenance(*gain, first_pass)
    return provenance


def _gp_provenance(opts: FitOptions, gp: GPFit) -> dict[str, Any]:
    """Kernel, restarts, marginal likelihoods, noise floor and blocked validation."""
    axes = gp.axes
    return {
        "kernel": "ConstantKernel * RBF(ARD) + WhiteKernel on normalised inputs",
        "restarts": opts.restarts,
        "log_marginal_likelihood": [a.log_marginal_likelihood for a in axes],
        "noise_floor": [float(f) for f in gp.floor],
        "validation": {
            "method": f"blocked cross-validation, {BLOCK_SECONDS:g} s blocks in {FOLDS} "
            "folds; GP off where its held-out MSE is not below "
            f"{KEEP_RATIO:g} x physics-only; std widened to {TARGET_COVERAGE:.0%} "
            "held-out 2-sigma coverage",
            "gp_on": [a.gp_on for a in axes],
            "rmse_gp": [a.cv_rmse_gp for a in axes],
            "rmse_physics": [a.cv_rmse_physics for a in axes],
            "coverage": [a.cv_coverage for a in axes],
            "std_factor": [a.std_factor for a in axes],
            "latent_factor": [a.latent_factor for a in axes],
            "beyond_scale": [a.beyond_scale for a in axes],
            # the band inside the fit inputs: band_scale (1 + band_slope rho) on its
            # calibrated latent variance and noise, rho the latent share of the prior
            "band_scale": [a.band_scale for a in axes],
            "band_slope": [a.band_slope for a in axes],
            "band_noise_std": [
                a.band_noise_std if math.isfinite(a.band_noise_std) else None for a in axes
            ],
        },
    }


def _gain_provenance(
    gain: np.ndarray, gain_se: np.ndarray, first_pass: EffectFit
) -> dict[str, Any]:
    """The fitted torque-command gain (3,), its standard error and the first pass's."""
    ls_gain, ls_se = torque_gain(first_pass.estimates[GAIN_EFFECT])
    return {
        "effect": GAIN_EFFECT,
        "values": [float(g) for g in gain],
        "stderr": [float(g) for g in gain_se],
        "first_pass_least_squares": [float(g) for g in ls_gain],
        "first_pass_stderr": [float(g) for g in ls_se],
        "prior": f"theta = gain - 1 ~ N(gain_LS - 1, ({GAIN_PRIOR_FACTOR:g} gain_LS)^2) "
        "per axis, gain_LS the first-pass least-squares gain",
    }
