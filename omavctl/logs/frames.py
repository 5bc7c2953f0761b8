"""Body and world frames of logged vectors: FLU (the contract) or FRD (PX4 style).

The contract (DESIGN.md section 3) has body vectors in FLU (x forward, y left,
z up) and the world z up. A vehicle with ``frame: FRD`` logs body vectors in
FRD (x forward, y right, z down) and the world in NED (x north, y east, z
down), as PX4 and ArduPilot do. Both pairs differ by a rotation of 180 deg
about x, ``F = diag(1, -1, -1)``:

- vectors (body rate, force and torque commands, velocity, desired
  accelerations, positions): ``v' = F v = (x, -y, -z)``;
- attitude: ``R' = F R F``; for ZYX Euler angles this is
  ``(roll, -pitch, -yaw)`` because ``F Rz(y) Ry(p) Rx(r) F = Rz(-y) Ry(-p) Rx(r)``;
  for a quaternion ``(w, x, y, z)`` it is ``(w, x, -y, -z)``.

The world after conversion is north-west-up, a z-up world as the contract
asks (x is kept, so headings stay comparable). Note that a positive thrust
*magnitude* logged for an FRD vehicle is a force along ``-z``: map it with
``scale: -1`` so that it becomes ``+z`` (up) after conversion.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.logs.types import ROLE_COLUMNS, RawLog, RawSeries

__all__ = ["FRAMES", "FRD_TO_FLU", "check_frame", "convert_frame", "flip_quaternion"]

#: Frames a vehicle's ``frame:`` key may name.
FRAMES: tuple[str, ...] = ("FLU", "FRD")

#: Per-component sign of the FRD -> FLU conversion of every three-component role
#: (vectors and ZYX Euler angles alike); shape (3,).
FRD_TO_FLU = np.array([1.0, -1.0, -1.0])

#: Roles that are converted: every role with three components (not tilt, rotor).
FRAME_ROLES: tuple[str, ...] = tuple(r for r, c in ROLE_COLUMNS.items() if len(c) == 3)


def check_frame(value: object, key: str = "frame") -> str:
    """The frame name ``value`` in upper case; :class:`ConfigError` naming ``key`` otherwise."""
    if isinstance(value, str) and value.strip().upper() in FRAMES:
        return value.strip().upper()
    raise ConfigError(f"key '{key}' must be {' or '.join(FRAMES)}, got {value!r}")


def flip_quaternion(q: np.ndarray) -> np.ndarray:
    """FRD/NED -> FLU/z-up of quaternions shape (n, 4) as (w, x, y, z): ``(w, x, -y, -z)``."""
    return np.asarray(q, dtype=float) * np.array([1.0, 1.0, -1.0, -1.0])


def convert_frame(raw: RawLog, frame: str) -> RawLog:
    """``raw`` with every signal in the contract frames (FLU body, z-up world).

    ``frame`` is the log's frame (:data:`FRAMES`); ``"FLU"`` returns ``raw``
    itself. Otherwise a new :class:`RawLog` (series values shape (n, 3)
    multiplied by :data:`FRD_TO_FLU`) with a note saying so.
    """
    frame = check_frame(frame)
    if frame == "FLU":
        return raw
    series = {
        role: RawSeries(s.stamps, np.asarray(s.values, dtype=float) * FRD_TO_FLU)
        if role in FRAME_ROLES
        else s
        for role, s in raw.series.items()
    }
    note = (
        "frame FRD: body vectors (FRD) and world (NED) converted to FLU / z-up "
        "by a 180 deg rotation about x: (x, -y, -z), Euler (roll, -pitch, -yaw)"
    )
    return replace(raw, series=series, notes=[*raw.notes, note])
