"""Trajectory CSV (tasks and planned references), DESIGN.md section 4.

Columns ``t,x,y,z,roll,pitch,yaw,vx,vy,vz,wx,wy,wz,ax,ay,az,dwx,dwy,dwz``:
time (s) on a uniform grid, position (m, world), ZYX Euler angles (rad),
velocity (m/s, world), body rates (rad/s), linear acceleration (m/s^2, world),
body angular acceleration (rad/s^2). Header row; SI units.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from omavctl.base.atomic import write_text_atomic
from omavctl.base.errors import LogError, TrajectoryError

__all__ = [
    "COLUMNS",
    "SCHEMA",
    "Trajectory",
    "check_replaceable",
    "read_trajectory",
    "refuse_as_logs",
    "write_trajectory",
]

SCHEMA = "omavctl.trajectory/1"
COLUMNS = "t x y z roll pitch yaw vx vy vz wx wy wz ax ay az dwx dwy dwz".split()
_UNIFORM_RTOL = 1e-6
#: Largest plausible magnitude per column group (SI units): a value beyond it is
#: a corrupt file, not a flight (t: s, position: m, angles: rad, velocity: m/s,
#: body rates: rad/s, accelerations: m/s^2 and rad/s^2).
_GROUP_LIMITS = {
    ("t",): 1e6,
    ("x", "y", "z"): 1e4,
    ("roll", "pitch"): 10.0,
    ("yaw",): 1e3,
    ("vx", "vy", "vz"): 1e3,
    ("wx", "wy", "wz"): 100.0,
    ("ax", "ay", "az"): 1e3,
    ("dwx", "dwy", "dwz"): 1e4,
}
LIMITS = {c: lim for cols, lim in _GROUP_LIMITS.items() for c in cols}


@dataclass(frozen=True)
class Trajectory:
    """A reference trajectory: ``data`` shape (N, 19) in :data:`COLUMNS` order."""

    data: np.ndarray

    @property
    def t(self) -> np.ndarray:
        return self.data[:, 0]

    @property
    def position(self) -> np.ndarray:
        return self.data[:, 1:4]

    @property
    def euler(self) -> np.ndarray:
        return self.data[:, 4:7]

    @property
    def velocity(self) -> np.ndarray:
        return self.data[:, 7:10]

    @property
    def body_rate(self) -> np.ndarray:
        return self.data[:, 10:13]

    @property
    def acceleration(self) -> np.ndarray:
        return self.data[:, 13:16]

    @property
    def angular_acceleration(self) -> np.ndarray:
        return self.data[:, 16:19]

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @classmethod
    def from_parts(
        cls,
        t: np.ndarray,
        position: np.ndarray,
        euler: np.ndarray,
        velocity: np.ndarray,
        body_rate: np.ndarray,
        acceleration: np.ndarray,
        angular_acceleration: np.ndarray,
    ) -> Trajectory:
        """Assemble from arrays: t (N,), the rest (N, 3)."""
        return cls(
            np.column_stack(
                [t, position, euler, velocity, body_rate, acceleration, angular_acceleration]
            )
        )

    def sample(self, times: np.ndarray) -> np.ndarray:
        """Linear interpolation of every column at ``times`` (M,) -> (M, 19); held at ends."""
        out = np.empty((times.size, len(COLUMNS)))
        out[:, 0] = times
        for j in range(1, len(COLUMNS)):
            out[:, j] = np.interp(times, self.t, self.data[:, j])
        return out


def read_trajectory(path: str | Path) -> Trajectory:
    """Read and validate a trajectory CSV (exact columns, finite, uniform time grid)."""
    p = Path(path)
    try:
        text = p.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise TrajectoryError("file not found", p) from None
    except IsADirectoryError:
        raise TrajectoryError("is a directory, not a trajectory CSV", p) from None
    except OSError as err:
        raise TrajectoryError(f"cannot read: {err.strerror or err}", p) from None
    except UnicodeDecodeError:
        raise TrajectoryError("not a trajectory CSV: it is not UTF-8 text", p) from None
    text = text.removeprefix("\ufeff")
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise TrajectoryError("empty file: expected a header row and samples", p)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if (
        missing
        and not set(COLUMNS[1:]) & set(header)  # t aside, none of a trajectory's columns
        and any(h.startswith("body_rate") for h in header)
    ):
        # a flight log (omavctl simulate --out x.csv), not a reference (a new user's plan)
        raise TrajectoryError(
            "a flight log (body_rate columns), not a trajectory: --task and --reference take "
            "the CSV that omavctl task writes (t, x, y, z, roll, pitch, yaw and their rates)",
            p,
        )
    if missing:
        raise TrajectoryError(f"missing columns: {', '.join(missing)}", p)
    extra = [c for c in header if c not in COLUMNS]
    if extra:
        raise TrajectoryError(f"unexpected columns: {', '.join(extra)}", p)
    idx = [header.index(c) for c in COLUMNS]
    body = [r for r in rows[1:] if r]
    if len(body) < 2:
        raise TrajectoryError("fewer than 2 samples", p)
    data = np.empty((len(body), len(COLUMNS)))
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise TrajectoryError(f"row {i + 2} has {len(row)} fields, header has {len(header)}", p)
        for j, k in enumerate(idx):
            try:
                data[i, j] = float(row[k])
            except ValueError:
                raise TrajectoryError(
                    f"row {i + 2}, column '{COLUMNS[j]}': not a number: {row[k]!r}", p
                ) from None
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise TrajectoryError(f"row {i + 2}, column '{COLUMNS[j]}': not finite", p)
    limits = np.array([LIMITS[c] for c in COLUMNS])
    beyond = np.abs(data) > limits
    if beyond.any():
        i, j = np.argwhere(beyond)[0]
        raise TrajectoryError(
            f"row {i + 2}, column '{COLUMNS[j]}': {data[i, j]:.6g} is beyond the plausible "
            f"range ±{limits[j]:g}",
            p,
        )
    dt = np.diff(data[:, 0])
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise TrajectoryError(f"time not increasing at row {i + 3}", p)
    if np.max(np.abs(dt - dt.mean())) > _UNIFORM_RTOL * max(dt.mean(), 1e-9) + 1e-9:
        i = int(np.argmax(np.abs(dt - dt[0]) > _UNIFORM_RTOL * dt[0] + 1e-9))
        raise TrajectoryError(
            f"non-uniform time grid: step {dt[i]:.6g} s at row {i + 3}, expected {dt[0]:.6g} s",
            p,
        )
    return Trajectory(data)


def format_trajectory(traj: Trajectory) -> str:
    """CSV text of a trajectory (deterministic: same array, same bytes)."""
    buf = io.StringIO()
    buf.write(",".join(COLUMNS) + "\n")
    np.savetxt(buf, traj.data, delimiter=",", fmt="%.12g")
    return buf.getvalue()


def _is_trajectory(p: Path) -> bool | None:
    """Whether the existing, non-empty file ``p`` starts with this module's header;
    None when it is not a non-empty file or cannot be read."""
    try:
        if not p.is_file() or p.stat().st_size == 0:
            return None
        with p.open("rb") as fh:
            first = fh.readline(4096).decode("utf-8", "replace")
    except OSError:
        return None
    return [h.strip() for h in first.strip().split(",")] == COLUMNS


def check_replaceable(path: str | Path) -> None:
    """Refuse an existing, non-empty file at ``path`` that is not a trajectory CSV (its
    first line not this module's header): ``task`` and ``plan`` replace a trajectory
    (their own earlier output), never a flight log or another file the user keeps
    under that name."""
    p = Path(path)
    if _is_trajectory(p) is False:
        raise TrajectoryError(
            "exists and is not a trajectory CSV; choose another name (or remove it)", p
        )


def refuse_as_logs(paths: list[Path]) -> None:
    """Refuse a trajectory CSV given where a flight log belongs (``fit``, ``evaluate``):
    a new user's ``fit fig8.csv`` said only that the body-rate columns were missing."""
    import shlex

    for p in paths:
        if _is_trajectory(Path(p)):
            raise LogError(
                "a trajectory CSV (what task and plan write), not a flight log: fly it "
                f"first (omavctl simulate --reference {shlex.quote(str(p))} --out LOG)",
                p,
            )


def write_trajectory(path: str | Path, traj: Trajectory) -> None:
    """Write a trajectory CSV atomically (refuses non-finite values)."""
    if not np.all(np.isfinite(traj.data)):
        raise TrajectoryError("refusing to write non-finite values", path)
    write_text_atomic(path, format_trajectory(traj))
