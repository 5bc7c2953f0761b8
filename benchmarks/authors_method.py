"""The authors' motor time constant, re-implemented, on the shared Crazyflie logs.

Run: python benchmarks/authors_method.py [LOG_DIR] [--boot 400] [--block 1.0]

Eschmann, Albani, Loianno, "Data-Driven System Identification of Quadrotors
Subject to Motor Delays" (2024); their notebook is ``sysid.ipynb`` of
github.com/arplaboratory/data-driven-system-identification (MIT; read at commit
d26cef879640834a2d838d884a06cdca9137ab7b). This file is an
independent numpy/scipy re-implementation of the method as docs/real-motors.md
("Against the authors' method") summarises it; no code is copied. In short:

- the motor outputs ``u = PWM / 65536`` are taken as normalised rotor-speed
  set-points; the rotor speed is their first-order lag ``rpm = EMA(u, T_m)``;
- rotor thrust is a polynomial in ``rpm`` (exponents 0, 1, 2, or 2 alone),
  fitted by least squares to ``m a_z`` (accelerometer) on log10, 35-65 s;
- the roll/pitch torque is ``sum r_i x f_i`` over the rotors; on log15, 55-90 s,
  the angular acceleration (``np.gradient`` of the gyro) is regressed on it,
  one inverse inertia per axis; ``T_m`` is the value on a grid whose
  least-squares fit leaves the least squared residual (the MAP estimate under
  Gaussian noise and a flat prior; the notebook's cells for this step were not
  read, the abstract's "MAP" is all this step rests on, docs/real-motors.md);
- yaw: ``I_zz = 1.832 mean(I_xx, I_yy)`` is assumed, and the yaw-moment
  coefficient ``K_tau`` is the least-squares slope of ``I_zz dw_z`` on
  ``sum d_i f_i`` on log16, 32-38 s and 45-49 s.

Windows are in ``timestamp / 1000`` (s since the vehicle booted). The
uncertainty of ``T_m`` is a block bootstrap over time (blocks of ``--block`` s
resampled with replacement, the whole fit redone on each draw) and the two
halves of the window fitted apart. ``--lag-on torque`` moves the lag from the
rotor speed to the mixed torque (omavctl's ``motor_lag``), ``--derivative sg``
uses omavctl's Savitzky-Golay derivative (11 samples, order 2) instead of
``np.gradient``: the two differences between the methods, measured one at a time.
"""

from __future__ import annotations

import argparse
import gzip
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import lfilter, savgol_filter

LOG_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "arpl_crazyflie"
MASS = 0.027  # kg, the authors' value
ACC_Z_SCALE = 9.18  # m/s^2 per g on the z axis, as in their notebook (x, y: 9.81)
INERTIA_RATIO = 1.832  # I_zz / mean(I_xx, I_yy), assumed by the authors
ROTORS = np.array([[0.028, -0.028], [-0.028, -0.028], [-0.028, 0.028], [0.028, 0.028]])
YAW_DIRECTION = np.array([-1.0, 1.0, -1.0, 1.0])
WINDOWS = {
    "thrust": ("log10", [(35.0, 65.0)]),
    "roll_pitch": ("log15", [(55.0, 90.0)]),
    "yaw": ("log16", [(32.0, 38.0), (45.0, 49.0)]),
}
CURVES = {"0,1,2": (0, 1, 2), "2": (2,)}
GRID = np.arange(0.001, 0.2005, 0.001)  # s


@dataclass
class Segment:
    """One contiguous stretch of a log: ``t`` (N,) s, ``u`` (N, 4) normalised
    motor set-points, ``omega`` (N, 3) rad/s, ``acc`` (N, 3) m/s^2."""

    t: np.ndarray
    u: np.ndarray
    omega: np.ndarray
    acc: np.ndarray


def read_log(path: Path) -> np.ndarray:
    """The decoded CSV (timestamp ms, acc g, gyro deg/s, motor PWM) as an (N, 11) array."""
    with gzip.open(path, "rt") as f:
        return np.loadtxt(f, delimiter=",", skiprows=1)


def cut(raw: np.ndarray, windows: list[tuple[float, float]]) -> list[Segment]:
    """The samples strictly inside each window (s), split where the clock jumps
    by more than three median sample intervals (the notebook's gap rule)."""
    t_all = raw[:, 0] / 1000.0
    segments = []
    for start, end in windows:
        rows = raw[(t_all > start) & (t_all < end)]
        t = rows[:, 0] / 1000.0
        gaps = np.flatnonzero(np.diff(t) > 3 * np.median(np.diff(t))) + 1
        for part in np.split(np.arange(t.size), gaps):
            if part.size < 50:
                continue
            r = rows[part]
            acc = r[:, 1:4] * np.array([9.81, 9.81, ACC_Z_SCALE])
            segments.append(Segment(t[part], r[:, 7:11] / 65536.0, np.radians(r[:, 4:7]), acc))
    return segments


def ema(u: np.ndarray, time_constant: float, dt: float) -> np.ndarray:
    """First-order lag of ``u`` (N, k) along axis 0, started at ``u[0]`` (no
    transient), at the fixed step ``dt``; the identity for a zero constant."""
    if time_constant <= 0:
        return u.copy()
    alpha = np.exp(-dt / time_constant)
    return lfilter([1.0 - alpha], [1.0, -alpha], u, axis=0, zi=alpha * u[:1])[0]


def angular_acceleration(seg: Segment, derivative: str) -> np.ndarray:
    """The body angular acceleration (N, 3): ``np.gradient`` of the gyro on its
    own time stamps (the notebook's), or a Savitzky-Golay derivative."""
    if derivative == "sg":
        dt = float(np.median(np.diff(seg.t)))
        return savgol_filter(seg.omega, 11, 2, deriv=1, delta=dt, axis=0)
    return np.gradient(seg.omega, seg.t, axis=0)


def powers(rpm: np.ndarray, exponents: tuple[int, ...]) -> np.ndarray:
    """Per-rotor regressors of the thrust curve: (N, 4, len(exponents))."""
    return np.stack([rpm**e for e in exponents], axis=-1)


def lagged(seg: Segment, time_constant: float) -> np.ndarray:
    """The rotor speeds (N, 4) the set-points give through the motor lag."""
    return ema(seg.u, time_constant, float(np.median(np.diff(seg.t))))


def fit_thrust_curve(
    segments: list[Segment], time_constant: float, exponents: tuple[int, ...]
) -> np.ndarray:
    """Thrust-curve coefficients (len(exponents),): ``m a_z = sum_i f(rpm_i)``."""
    rows = np.concatenate(
        [powers(lagged(s, time_constant), exponents).sum(axis=1) for s in segments]
    )
    target = np.concatenate([MASS * s.acc[:, 2] for s in segments])
    coef, *_ = np.linalg.lstsq(rows, target, rcond=None)
    return coef


def torques(
    seg: Segment, time_constant: float, coef: np.ndarray, exponents: tuple[int, ...], lag_on: str
) -> np.ndarray:
    """Body torque (N, 3) of the rotors: roll, pitch from the geometry, yaw as
    ``sum d_i f_i`` (normalised, K_tau still to scale). ``lag_on`` is 'rpm'
    (the authors') or 'torque' (the lag after the thrust curve and the mixer)."""
    rpm = lagged(seg, time_constant) if lag_on == "rpm" else seg.u
    thrust = powers(rpm, exponents) @ coef
    tau = np.c_[thrust @ ROTORS[:, 1], -(thrust @ ROTORS[:, 0]), thrust @ YAW_DIRECTION]
    if lag_on == "torque":
        tau = ema(tau, time_constant, float(np.median(np.diff(seg.t))))
    return tau


def block_statistics(x: np.ndarray, y: np.ndarray, t: np.ndarray, block: float) -> np.ndarray:
    """Per time block the sums ``xx, xy, yy`` per axis: (blocks, 3, axes)."""
    ids = np.floor((t - t[0]) / block).astype(int)
    stats = np.zeros((ids.max() + 1, 3, x.shape[1]))
    for k, prod in enumerate((x * x, x * y, y * y)):
        np.add.at(stats[:, k], ids, prod)
    return stats


def residual(stats: np.ndarray) -> np.ndarray:
    """Least-squares residual sum per axis from summed statistics (..., 3, axes)."""
    return stats[..., 2, :] - stats[..., 1, :] ** 2 / stats[..., 0, :]


@dataclass
class Scan:
    """The roll/pitch fit over the grid: ``stats`` (grid, blocks, 3, 2) block
    sums and the grid's thrust curves ``coefs`` (grid, n_exponents)."""

    stats: np.ndarray
    coefs: np.ndarray

    def loss(self, blocks: np.ndarray | None = None) -> np.ndarray:
        """Residual sum of squares over roll and pitch per grid point (grid,)."""
        s = self.stats if blocks is None else self.stats[:, blocks]
        return residual(s.sum(axis=1)).sum(axis=-1)

    def inverse_inertia(self, i: int) -> np.ndarray:
        """The least-squares ``1 / I`` of roll and pitch at grid point ``i`` (2,)."""
        s = self.stats[i].sum(axis=0)
        return s[1] / s[0]


def scan_roll_pitch(
    thrust_segs: list[Segment],
    rp_segs: list[Segment],
    exponents: tuple[int, ...],
    block: float,
    lag_on: str = "rpm",
    derivative: str = "gradient",
) -> Scan:
    """Fit the thrust curve and the roll/pitch inertia at every grid ``T_m``."""
    accel = [angular_acceleration(s, derivative)[:, :2] for s in rp_segs]
    stats, coefs = [], []
    for tm in GRID:
        coef = fit_thrust_curve(thrust_segs, tm, exponents)
        per = [
            block_statistics(torques(s, tm, coef, exponents, lag_on)[:, :2], a, s.t, block)
            for s, a in zip(rp_segs, accel, strict=True)
        ]
        stats.append(np.concatenate(per))
        coefs.append(coef)
    return Scan(np.array(stats), np.array(coefs))


def bootstrap(scan: Scan, draws: int, seed: int = 0) -> np.ndarray:
    """``T_m`` (draws,) from block-bootstrap resamples of the window."""
    rng = np.random.default_rng(seed)
    n = scan.stats.shape[1]
    return np.array(
        [GRID[np.argmin(scan.loss(np.asarray(rng.integers(0, n, size=n))))] for _ in range(draws)]
    )


def yaw_moment(
    yaw_segs: list[Segment], tm: float, coef: np.ndarray, exponents: tuple[int, ...], izz: float
) -> tuple[float, float]:
    """``K_tau`` (slope of ``I_zz dw_z`` on the normalised yaw torque) and its R^2."""
    x = np.concatenate([torques(s, tm, coef, exponents, "rpm")[:, 2] for s in yaw_segs])
    y = np.concatenate([angular_acceleration(s, "gradient")[:, 2] * izz for s in yaw_segs])
    k = float(x @ y / (x @ x))
    return k, 1.0 - float(np.sum((y - k * x) ** 2) / np.sum(y**2))


def estimate(
    logs: dict[str, np.ndarray],
    name: str,
    args: argparse.Namespace,
    source: tuple[str, list[tuple[float, float]]] = WINDOWS["roll_pitch"],
) -> dict[str, float]:
    """One run of the method with the curve ``name``, roll and pitch fitted on
    ``source`` (log, windows): T_m, its bootstrap interval, the inertia, the
    thrust curve and the yaw moment."""
    exponents = CURVES[name]
    thrust_segs = cut(logs["log10"], WINDOWS["thrust"][1])
    rp_segs = cut(logs[source[0]], source[1])
    scan = scan_roll_pitch(
        thrust_segs, rp_segs, exponents, args.block, args.lag_on, args.derivative
    )
    i = int(np.argmin(scan.loss()))
    draws = bootstrap(scan, args.boot)
    inertia = 1.0 / scan.inverse_inertia(i)
    out = {
        "T_m": float(GRID[i]),
        "low": float(np.percentile(draws, 2.5)),
        "high": float(np.percentile(draws, 97.5)),
        "sd": float(np.std(draws)),
        "Ixx": float(inertia[0]),
        "Iyy": float(inertia[1]),
        "coef": scan.coefs[i],
        "at_edge": bool(i in (0, GRID.size - 1)),
    }
    izz = INERTIA_RATIO * float(np.mean(inertia))
    yaw_segs = cut(logs["log16"], WINDOWS["yaw"][1])
    out["K_tau"], out["yaw_r2"] = yaw_moment(yaw_segs, out["T_m"], scan.coefs[i], exponents, izz)
    return out


def report(label: str, r: dict[str, float]) -> str:
    """One printed line of an estimate."""
    coef = ", ".join(f"{c:.4g}" for c in np.atleast_1d(r["coef"]))
    edge = "  (at the grid's edge)" if r["at_edge"] else ""
    return (
        f"{label:<44} T_m {1000 * r['T_m']:6.1f} ms"
        f"  95 % [{1000 * r['low']:5.1f}, {1000 * r['high']:5.1f}]"
        f" sd {1000 * r['sd']:4.1f}  Ixx {r['Ixx']:.3e}  Iyy {r['Iyy']:.3e}"
        f"  curve [{coef}]  K_tau {r['K_tau']:.3e} (yaw R2 {r['yaw_r2']:.2f}){edge}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("log_dir", nargs="?", default=str(LOG_DIR))
    parser.add_argument("--boot", type=int, default=400, help="bootstrap draws")
    parser.add_argument("--block", type=float, default=1.0, help="bootstrap block, s")
    parser.add_argument("--lag-on", choices=("rpm", "torque"), default="rpm")
    parser.add_argument("--derivative", choices=("gradient", "sg"), default="gradient")
    parser.add_argument("--curves", default="0,1,2;2", help="thrust curves, ';'-separated")
    args = parser.parse_args()
    logs = {
        name: read_log(Path(args.log_dir) / f"{name}.csv.gz")
        for name in ("log10", "log15", "log16")
    }
    print(
        f"lag on {args.lag_on}, derivative {args.derivative},"
        f" blocks {args.block:g} s, {args.boot} draws"
    )
    for name in args.curves.split(";"):
        print(report(f"curve [{name}], log15 55-90 s", estimate(logs, name, args)))
        others = {
            "log15 first half 55-72.5 s": ("log15", [(55.0, 72.5)]),
            "log15 second half 72.5-90 s": ("log15", [(72.5, 90.0)]),
            "hover: log10 35-65 s": WINDOWS["thrust"],
            "yaw log16 windows": WINDOWS["yaw"],
        }
        for label, source in others.items():
            print(report(f"curve [{name}], {label}", estimate(logs, name, args, source)))


if __name__ == "__main__":
    main()
