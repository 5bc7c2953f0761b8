"""Base inputs in the motor-level log formats, made from a simulated flight: a
gzip-compressed wide CSV, a Crazyflie SD-card log (cfusdlog version 2) and a
Betaflight blackbox CSV as ``blackbox_decode`` writes it."""

from __future__ import annotations

import gzip
import struct
import zlib
from pathlib import Path

import numpy as np

from omavctl.logs import RawLog


def _rates_and_motors(raw: RawLog) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps (n,) s, body rates (n, 3) deg/s and four motor-like columns (n, 4) 0..1."""
    rate = raw.series["body_rate"]
    t = np.asarray(rate.stamps, dtype=float)
    w = np.degrees(np.asarray(rate.values, dtype=float))
    force = raw.series["force_command"]
    thrust = np.interp(t, force.stamps, np.linalg.norm(force.values, axis=1))
    level = thrust / max(float(thrust.max()), 1e-9)
    motors = np.clip(level[:, None] * np.array([0.6, 0.62, 0.58, 0.61]), 0.0, 1.0)
    return t, w, motors


def write_gzip_csv(plain: Path, out: Path) -> None:
    out.write_bytes(gzip.compress(plain.read_bytes()))


def write_cfusdlog(raw: RawLog, out: Path) -> None:
    """One fixed-frequency event: gyro.x/y/z (f, deg/s), motor.m1..m4 (I, 0..65535)."""
    t, w, motors = _rates_and_motors(raw)
    names = [f"gyro.{a}(f)" for a in "xyz"] + [f"motor.m{i}(I)" for i in range(1, 5)]
    data = bytearray(struct.pack("<BHH", 0xBC, 2, 1) + struct.pack("<H", 0xFFFF))
    data += b"fixedFrequency\0" + struct.pack("<H", len(names))
    data += b"".join(n.encode() + b"\0" for n in names)
    for k in range(t.size):
        pwm = (motors[k] * 65535).astype(int)
        data += struct.pack("<HQ", 0xFFFF, int(1e6 + t[k] * 1e6))
        data += struct.pack("<3f4I", *w[k], *pwm)
    data += struct.pack("<I", zlib.crc32(bytes(data)))
    out.write_bytes(bytes(data))


def write_betaflight_csv(raw: RawLog, out: Path) -> None:
    """``blackbox_decode`` style: units in the names, DShot motors 48..2047."""
    t, w, motors = _rates_and_motors(raw)
    head = "loopIteration, time (us), gyroADC[0], gyroADC[1], gyroADC[2], vbatLatest (V), "
    head += ", ".join(f"motor[{i}]" for i in range(4)) + ", flightModeFlags (flags)"
    rows = [head]
    for k in range(t.size):
        dshot = ", ".join(str(int(48 + m * 1999)) for m in motors[k])
        mode = "ANGLE_MODE" if k % 50 == 0 else ""
        rows.append(f"{k}, {int(1e6 + t[k] * 1e6)}, {w[k, 0]:.1f}, {w[k, 1]:.1f}, "
                    f"{w[k, 2]:.1f}, 16.2, {dshot}, {mode}")  # fmt: skip
    out.write_text("\n".join(rows) + "\n")
