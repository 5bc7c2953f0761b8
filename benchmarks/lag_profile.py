"""The profile of a searched lag: the residual against the time constant, gain refitted.

Run: python benchmarks/lag_profile.py VEHICLE.yaml LOG[,LOG...] [START:END]
     [--effect motor_lag] [--lags 0,0.005,...]

The logs are read as ``fit`` reads them, with ``--effects inertia_error,<effect>``
(the torque gain of a normalised command). Per time constant ``T``, printed:

- ``rss``: the residual sum of squares after the exact form at ``T`` with the gain
  refitted by least squares (the profile ``fit``'s first search minimises; the
  gain's regressor is the *commanded* torque: ``lag(tau, T) + theta tau``);
- ``fixed``: the same with the gain held at its value at that profile's optimum
  (what a standard error conditional on the gain would see);
- ``coupled``: the gain's regressor on the *timed* torque (``g lag(tau, T)``, the
  physical form; :func:`omavctl.learn.effect_search._coupled_search`);
- the roll / pitch gains of both forms.

Below the table: each profile's 95 % interval ``{T : dRSS / (s^2 c) <= 3.84}`` (``s^2``
the residual variance at the optimum, ``c`` the variance inflation of the
autocorrelated residuals, HAC over white, from the search's sandwich), and what
``fit``'s first search reports (value, standard error, the coupled value and its
allowance). No GP: the first search alone.
"""

from __future__ import annotations

import argparse

import numpy as np

from omavctl.learn.effect_search import _Problem, search_effects
from omavctl.learn.flights import read_samples
from omavctl.learn.signal import SavitzkyGolay
from omavctl.logs import parse_time_window
from omavctl.vehicle import load_vehicle

CHI2_95 = 3.841458820694124


def _gains(prob: _Problem, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Least-squares theta (p,) of y (n, 3) on x (n, 3, p)."""
    theta, *_ = np.linalg.lstsq(x.reshape(-1, x.shape[2]), y.reshape(-1), rcond=None)
    return np.asarray(theta)


def _interval(lags: np.ndarray, rss: np.ndarray, s2c: float) -> str:
    """The values of the fine grid whose dRSS / (s^2 c) stays within the chi-square 95 %
    bound, and the best."""
    inside = lags[(rss - rss.min()) / s2c <= CHI2_95]
    edge = " (reaches the grid's end)" if inside.max() >= lags.max() else ""
    best = lags[int(np.argmin(rss))]
    lo, hi = inside.min() * 1e3, inside.max() * 1e3
    return f"best {best * 1e3:.0f} ms, 95 % {lo:.0f} .. {hi:.0f} ms{edge}"


def _profiles(
    prob: _Problem, name: str, lags: np.ndarray, theta_at: np.ndarray
) -> list[tuple[float, float, float, np.ndarray, np.ndarray]]:
    """Per lag: rss (gain refitted), fixed (gain held at theta_at), coupled, and the
    gains (p,) of the first and the coupled form."""
    rows = []
    for lag in lags:
        e = prob.exact(name, float(lag))
        y = prob.residual - e
        th = _gains(prob, y, prob.x)
        fixed = y - prob.x @ theta_at
        xc = prob.x.copy()
        xc[:, :, prob.gain_cols] += prob.gain_shift(e)
        thc = _gains(prob, y, xc)
        rows.append((prob.rss(y), float(np.sum(fixed**2)), prob.rss_coupled(y, e), th, thc))
    return rows


def profile(
    vehicle_path: str, logs: list[str], window: str | None, name: str, lags: list[float]
) -> None:
    vehicle = load_vehicle(vehicle_path)
    tw = parse_time_window(window) if window else None
    sg = SavitzkyGolay(11, 2, 1.0 / vehicle.gains.rate_hz)
    samples, _ = read_samples(logs, vehicle, sg, tw, 1, lambda *a: None)
    linear = ["inertia_error"]
    prob = _Problem(samples, linear)
    n = prob.residual.shape[0]
    found = search_effects(samples, [name], linear)[name]
    theta_at = _gains(prob, prob.residual - prob.exact(name, found.value), prob.x)
    grid = np.asarray(sorted(set(lags) | {found.value}), float)
    rows = _profiles(prob, name, grid, theta_at)
    print(f"{', '.join(logs)} {window or ''}: {n} samples, {name}")
    print("   T ms |        rss |      fixed |    coupled | gain roll/pitch | coupled gain")
    for lag, (r, f, c, th, thc) in zip(grid, rows, strict=True):
        print(
            f"{lag * 1e3:7.1f} | {r:10.4g} | {f:10.4g} | {c:10.4g} | "
            f"{1 + th[0]:6.3f} {1 + th[1]:6.3f}  | {1 + thc[0]:6.3f} {1 + thc[1]:6.3f}"
        )
    dof = max(3 * n - prob.x.shape[2] - 1, 1)
    fine = np.arange(0.0, 0.2001, 0.001)  # 1 ms steps
    rows = _profiles(prob, name, fine, theta_at)
    for k, label in enumerate(("rss", "fixed", "coupled")):
        prof = np.array([r[k] for r in rows])
        s2c = prof.min() / dof * found.inflation
        print(f"profile {label:8s} (1 ms grid): {_interval(fine, prof, s2c)}")
    print(f"variance inflation of the autocorrelated residuals c = {found.inflation:.1f}")
    coupled_txt = "none" if found.coupled is None else f"{found.coupled * 1e3:.1f} ms"
    print(
        f"first search: {found.value * 1e3:.1f} ± {found.stderr * 1e3:.1f} ms; "
        f"coupled {coupled_txt}, allowance {found.gain_allowance * 1e3:.1f} ms; "
        f"form allowance {found.form_allowance * 1e3:.1f} ms ({found.better_form})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("vehicle")
    parser.add_argument("logs", help="comma-separated logs")
    parser.add_argument("window", nargs="?", default=None, help="START:END, s from the log start")
    parser.add_argument("--effect", default="motor_lag")
    parser.add_argument(
        "--lags", default="0,0.005,0.01,0.015,0.02,0.03,0.04,0.05,0.065,0.08,0.1,0.15,0.2,0.3"
    )
    args = parser.parse_args()
    lags = [float(x) for x in args.lags.split(",")]
    profile(args.vehicle, args.logs.split(","), args.window, args.effect, lags)


if __name__ == "__main__":
    main()
