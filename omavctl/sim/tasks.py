"""Task trajectories: attitude figure-8, position circle, pitching manoeuvre,
multi-sine wobble, frequency sweep (chirp), random attitude steps.

Every task starts and ends at rest: its motion is multiplied by a smooth
envelope (quintic smoothstep ramps of ``ramp`` seconds), and all derivatives
are analytic, so body rates and angular accelerations are consistent with the
angles (``omega = W(eta) eta_dot``, ``omega_dot = W eta_ddot + W_dot eta_dot``).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError
from omavctl.physics.rigid_body import euler_rates_to_body
from omavctl.sim.trajectory import COLUMNS, LIMITS, Trajectory

_LIMITS = np.array([LIMITS[c] for c in COLUMNS])

__all__ = [
    "TASKS",
    "Envelope",
    "chirp",
    "circle",
    "fig8",
    "heave",
    "pitch",
    "steps",
    "wobble",
    "yaw",
]


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic 0 -> 1 on ``u`` in [0, 1] (clipped outside) and its first two
    derivatives with respect to ``u``, each shaped like ``u``."""
    x = np.clip(u, 0.0, 1.0)
    inside = (u > 0) & (u < 1)
    v = 10 * x**3 - 15 * x**4 + 6 * x**5
    d1 = np.where(inside, 30 * x**2 - 60 * x**3 + 30 * x**4, 0.0)
    d2 = np.where(inside, 60 * x - 180 * x**2 + 120 * x**3, 0.0)
    return v, d1, d2


@dataclass(frozen=True)
class Envelope:
    """Smooth 0 -> 1 -> 0 window: quintic ramps of ``ramp`` s at both ends of ``duration``."""

    duration: float
    ramp: float

    def _up(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        r = self.ramp
        x = np.clip(t / r, 0.0, 1.0)
        v, d1, d2 = _smoothstep(t / r)
        d1, d2 = d1 / r, d2 / r**2
        integ = np.where(t < r, r * (2.5 * x**4 - 3 * x**5 + x**6), r / 2 + (t - r))
        return v, d1, d2, integ

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Value, first and second derivative, and integral from 0, each (N,)."""
        up, d_up, dd_up, i_up = self._up(t)
        tr = self.duration - t
        dn, d_dn, dd_dn, i_dn = self._up(tr)
        total = self._up(np.array([self.duration]))[3][0]
        value = up * dn
        d1 = d_up * dn - up * d_dn
        d2 = dd_up * dn - 2 * d_up * d_dn + up * dd_dn
        # up and dn never overlap below 1 (duration >= 2 ramp), so
        # up*dn = up + dn - 1 and its integral from 0 is
        integral = i_up + (total - i_dn) - t
        return value, d1, d2, integral


#: Most samples a task may have (a day at 100 Hz is 8.6 million).
MAX_SAMPLES = 10_000_000


def _check(duration: float, ramp: float, rate: float) -> None:
    if not 1.0 <= rate <= 10_000.0:
        raise ConfigError(f"--rate must be between 1 and 10000 Hz, got {rate}")
    if duration * rate > MAX_SAMPLES:
        raise ConfigError(
            f"--duration ({duration:g} s) at --rate {rate:g} Hz gives more than "
            f"{MAX_SAMPLES} samples"
        )
    if not duration > 0:
        raise ConfigError(f"--duration must be > 0 s, got {duration:g}")
    if ramp <= 0:
        raise ConfigError(f"--ramp must be > 0, got {ramp}")
    if duration < 2 * ramp:
        raise ConfigError(f"--duration ({duration} s) must be at least twice --ramp ({ramp} s)")


def _grid(duration: float, rate: float) -> np.ndarray:
    n = round(duration * rate) + 1
    return np.arange(n) / rate


def _windowed_sine(
    t: np.ndarray, env: Envelope, amp: float, omega: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``amp * e(t) * sin(omega t)`` and its first two derivatives."""
    e, de, dde, _ = env(t)
    s, c = np.sin(omega * t), np.cos(omega * t)
    v = amp * e * s
    d1 = amp * (de * s + e * omega * c)
    d2 = amp * (dde * s + 2 * de * omega * c - e * omega**2 * s)
    return v, d1, d2


def _attitude_task(
    t: np.ndarray,
    roll: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    pitch: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    height: float,
    yaw: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Trajectory:
    """Constant-position task from roll, pitch and yaw (value, rate, acceleration)
    each (N,); an axis given as None stays at 0."""
    z = np.zeros_like(t)
    r = roll if roll is not None else (z, z, z)
    p = pitch if pitch is not None else (z, z, z)
    y = yaw if yaw is not None else (z, z, z)
    eta, deta, ddeta = (np.column_stack([r[i], p[i], y[i]]) for i in range(3))
    w, dw = euler_rates_to_body(eta, deta, ddeta)
    assert dw is not None
    pos = np.zeros((t.size, 3))
    pos[:, 2] = height
    zeros = np.zeros((t.size, 3))
    return Trajectory.from_parts(t, pos, eta, zeros, w, zeros, dw)


def _plausible(func: Callable[..., Trajectory]) -> Callable[..., Trajectory]:
    """Refuse options that make a task beyond the trajectory CSV's plausible ranges
    (or overflow), naming the generator's options."""
    options = ", ".join(
        "--" + n.removesuffix("_deg").replace("_", "-") for n in inspect.signature(func).parameters
    )

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Trajectory:
        try:
            traj = func(*args, **kwargs)
        except (OverflowError, FloatingPointError):
            traj = None
        bad = None if traj is None else ~np.isfinite(traj.data) | (np.abs(traj.data) > _LIMITS)
        if traj is None or bad is None or bad.any():
            what = ""
            if traj is not None and bad is not None:
                i, j = np.argwhere(bad)[0]
                what = f" ({COLUMNS[j]} = {traj.data[i, j]:.3g}, plausible ±{_LIMITS[j]:g})"
            raise ConfigError(f"the options give a task beyond plausible values{what}: {options}")
        return traj

    return wrapper


@_plausible
def fig8(
    roll_deg: float = 26.0,
    pitch_deg: float = 26.0,
    period: float = 8.0,
    duration: float = 24.0,
    rate: float = 100.0,
    ramp: float = 2.0,
    height: float = 1.0,
) -> Trajectory:
    """Attitude figure-8 at constant position (the paper's task).

    ``roll = A_r e(t) sin(2 pi t / period)``, ``pitch = A_p e(t) sin(4 pi t / period)``:
    the (roll, pitch) path traces an eight once per period.
    """
    _check(duration, ramp, rate)
    if period <= 0:
        raise ConfigError(f"--period must be > 0, got {period}")
    t = _grid(duration, rate)
    env = Envelope(duration, ramp)
    w0 = 2 * np.pi / period
    r = _windowed_sine(t, env, np.deg2rad(roll_deg), w0)
    p = _windowed_sine(t, env, np.deg2rad(pitch_deg), 2 * w0)
    return _attitude_task(t, r, p, height)


@_plausible
def pitch(
    amplitude_deg: float = 60.0,
    max_acceleration: float = 1.0,
    duration: float = 30.0,
    rate: float = 100.0,
    ramp: float = 3.0,
    height: float = 1.0,
) -> Trajectory:
    """Pitching manoeuvre as in the paper: ``pitch = A e(t) sin(w t)`` with the
    frequency chosen so the peak pitch acceleration ``A w^2`` is ``max_acceleration``
    (rad/s^2); 60 deg and 1 rad/s^2 give a 6.4 s period."""
    _check(duration, ramp, rate)
    amp = np.deg2rad(amplitude_deg)
    if amp <= 0 or max_acceleration <= 0:
        raise ConfigError("--amplitude and --max-acceleration must be > 0")
    if amp >= np.pi / 2:
        raise ConfigError("--amplitude must be below 90 deg (Euler-angle singularity)")
    t = _grid(duration, rate)
    env = Envelope(duration, ramp)
    p = _windowed_sine(t, env, amp, float(np.sqrt(max_acceleration / amp)))
    return _attitude_task(t, None, p, height)


@_plausible
def circle(
    radius: float = 1.0,
    period: float = 6.0,
    duration: float = 24.0,
    rate: float = 100.0,
    ramp: float = 3.0,
    height: float = 1.0,
) -> Trajectory:
    """Horizontal circle at level attitude starting from the origin.

    The phase ``phi(t) = (2 pi / period) * integral of e(t)`` ramps the speed
    smoothly; ``p = [R sin phi, R (1 - cos phi), height]``.
    """
    _check(duration, ramp, rate)
    if radius <= 0 or period <= 0:
        raise ConfigError("--radius and --period must be > 0")
    t = _grid(duration, rate)
    e, de, _, ie = Envelope(duration, ramp)(t)
    w0 = 2 * np.pi / period
    phi, dphi, ddphi = w0 * ie, w0 * e, w0 * de
    s, c = np.sin(phi), np.cos(phi)
    pos = np.column_stack([radius * s, radius * (1 - c), np.full_like(t, height)])
    vel = np.column_stack([radius * c * dphi, radius * s * dphi, np.zeros_like(t)])
    acc = np.column_stack(
        [
            radius * (c * ddphi - s * dphi**2),
            radius * (s * ddphi + c * dphi**2),
            np.zeros_like(t),
        ]
    )
    zeros = np.zeros((t.size, 3))
    return Trajectory.from_parts(t, pos, zeros, vel, zeros, acc, zeros)


@_plausible
def yaw(
    amplitude_deg: float = 30.0,
    period: float = 4.0,
    duration: float = 20.0,
    rate: float = 100.0,
    ramp: float = 2.0,
    height: float = 1.0,
) -> Trajectory:
    """Yaw oscillation at level attitude and constant position:
    ``yaw = A e(t) sin(2 pi t / period)``.

    An omav makes yaw torque by tilting its arms together, at small tilt
    angles: the manoeuvre that shows the tilt servos' dynamics (``servo_lag``)
    without the tilt-dependent rotor interference of large attitudes.
    """
    _check(duration, ramp, rate)
    if period <= 0 or amplitude_deg <= 0:
        raise ConfigError("--amplitude and --period must be > 0")
    t = _grid(duration, rate)
    y = _windowed_sine(t, Envelope(duration, ramp), np.deg2rad(amplitude_deg), 2 * np.pi / period)
    return _attitude_task(t, None, None, height, yaw=y)


@_plausible
def heave(
    amplitude: float = 0.2,
    period: float = 3.0,
    duration: float = 20.0,
    rate: float = 100.0,
    ramp: float = 2.0,
    height: float = 1.0,
) -> Trajectory:
    """Vertical oscillation at level attitude: ``z = height + A e(t) sin(2 pi t / period)``.

    The collective thrust varies (peak vertical acceleration ``A (2 pi / period)^2``)
    with no tilt: torques proportional to thrust (``com_offset``) show without
    tilt-dependent interference.
    """
    _check(duration, ramp, rate)
    if period <= 0 or amplitude <= 0:
        raise ConfigError("--amplitude and --period must be > 0")
    t = _grid(duration, rate)
    h, dh, ddh = _windowed_sine(t, Envelope(duration, ramp), amplitude, 2 * np.pi / period)
    zeros = np.zeros((t.size, 3))
    pos, vel, acc = zeros.copy(), zeros.copy(), zeros.copy()
    pos[:, 2], vel[:, 2], acc[:, 2] = height + h, dh, ddh
    return Trajectory.from_parts(t, pos, zeros, vel, zeros, acc, zeros)


@_plausible
def wobble(
    amplitude_deg: float = 15.0,
    bandwidth: float = 0.8,
    duration: float = 20.0,
    rate: float = 100.0,
    ramp: float = 2.0,
    height: float = 1.0,
    seed: int = 0,
) -> Trajectory:
    """Multi-sine attitude wobble: roll, pitch and yaw each a sum of three sines.

    Frequencies are drawn (``seed``) between 0.15 ``bandwidth`` and ``bandwidth``
    Hz, phases at random, amplitudes summing to ``amplitude_deg`` per axis
    (yaw half of it). Not periodic within a flight: an identification flight
    whose wrench history differs from a figure-8's at equal wrench, for testing
    that a model transfers between trajectories.
    """
    _check(duration, ramp, rate)
    if amplitude_deg <= 0 or bandwidth <= 0:
        raise ConfigError("--amplitude and --bandwidth must be > 0")
    t = _grid(duration, rate)
    env = Envelope(duration, ramp)
    rng = np.random.default_rng([seed, 0xB0B])
    axes = []
    for scale in (1.0, 1.0, 0.5):
        freq = rng.uniform(0.15 * bandwidth, bandwidth, 3)
        phase = rng.uniform(0.0, 2 * np.pi, 3)
        weight = rng.uniform(0.5, 1.0, 3)
        weight = weight / weight.sum() * np.deg2rad(amplitude_deg) * scale
        total = [np.zeros_like(t) for _ in range(3)]
        for f, ph, a in zip(freq, phase, weight, strict=True):
            e, de, dde, _ = env(t)
            s, c = np.sin(2 * np.pi * f * t + ph), np.cos(2 * np.pi * f * t + ph)
            w = 2 * np.pi * f
            total[0] = total[0] + a * e * s
            total[1] = total[1] + a * (de * s + e * w * c)
            total[2] = total[2] + a * (dde * s + 2 * de * w * c - e * w**2 * s)
        axes.append((total[0], total[1], total[2]))
    return _attitude_task(t, axes[0], axes[1], height, yaw=axes[2])


@_plausible
def chirp(
    amplitude_deg: float = 12.0,
    f_start: float = 0.1,
    f_end: float = 0.8,
    duration: float = 24.0,
    rate: float = 100.0,
    ramp: float = 2.0,
    height: float = 1.0,
) -> Trajectory:
    """Roll/pitch/yaw frequency sweep: a linear chirp from ``f_start`` to ``f_end`` Hz.

    Phase ``phi(t) = 2 pi (f_start t + (f_end - f_start) t^2 / (2 duration))``;
    ``roll = A e(t) sin(phi)``, ``pitch = A e(t) sin(phi + pi/2)`` and
    ``yaw = A/2 e(t) sin(phi + pi/4)``: every axis sees every frequency of the
    band once, so a lag or a delay shows as a phase that grows with frequency.
    """
    _check(duration, ramp, rate)
    if amplitude_deg <= 0:
        raise ConfigError(f"--amplitude must be > 0, got {amplitude_deg:g}")
    if not 0 < f_start < f_end:
        raise ConfigError(
            f"--f-start and --f-end must be 0 < start < end, got {f_start:g}, {f_end:g}"
        )
    t = _grid(duration, rate)
    e, de, dde, _ = Envelope(duration, ramp)(t)
    sweep = (f_end - f_start) / duration
    phi = 2 * np.pi * (f_start * t + 0.5 * sweep * t**2)
    dphi = 2 * np.pi * (f_start + sweep * t)
    ddphi = 2 * np.pi * sweep
    amp = np.deg2rad(amplitude_deg)
    axes = []
    for scale, offset in ((1.0, 0.0), (1.0, np.pi / 2), (0.5, np.pi / 4)):
        s, c = np.sin(phi + offset), np.cos(phi + offset)
        a = amp * scale
        v = a * e * s
        d1 = a * (de * s + e * dphi * c)
        d2 = a * (dde * s + 2 * de * dphi * c + e * (ddphi * c - dphi**2 * s))
        axes.append((v, d1, d2))
    return _attitude_task(t, axes[0], axes[1], height, yaw=axes[2])


@_plausible
def steps(
    amplitude_deg: float = 15.0,
    hold: float = 2.0,
    transition: float = 1.0,
    duration: float = 20.0,
    rate: float = 100.0,
    ramp: float = 2.0,
    height: float = 1.0,
    seed: int = 0,
) -> Trajectory:
    """Random attitude steps: roll, pitch and yaw jump to new levels every ``hold`` s.

    Levels are drawn (``seed``) uniformly within +-``amplitude_deg`` (yaw half of
    it); each change is a quintic smoothstep of ``transition`` s (continuous rate
    and acceleration, peak acceleration 5.8 x step / transition^2, so flyable).
    The flight rests for ``ramp`` s at both ends and its last step returns to level.
    """
    _check(duration, ramp, rate)
    if amplitude_deg <= 0:
        raise ConfigError(f"--amplitude must be > 0, got {amplitude_deg:g}")
    if not 0 < hold < duration:
        raise ConfigError(f"--hold must be > 0 and below --duration, got {hold:g}")
    if not 0 < transition <= hold:
        raise ConfigError(
            f"--transition must be > 0 and at most --hold ({hold:g} s), got {transition:g}"
        )
    room = (duration - 2 * ramp - transition) / hold
    if not room >= 1:  # also a NaN option
        raise ConfigError(
            f"--duration ({duration:g} s) leaves no room for two steps of --hold {hold:g} s "
            f"between the --ramp ({ramp:g} s) rests"
        )
    n_steps = int(np.floor(room)) + 1
    t = _grid(duration, rate)
    rng = np.random.default_rng([seed, 0x57E9])
    amp = np.deg2rad(amplitude_deg)
    levels = rng.uniform(-amp, amp, (n_steps - 1, 3)) * np.array([1.0, 1.0, 0.5])
    levels = np.vstack([np.zeros(3), levels, np.zeros(3)])
    jumps = np.diff(levels, axis=0)  # (n_steps, 3)
    starts = ramp + hold * np.arange(n_steps)
    u = (t[:, None] - starts[None, :]) / transition  # (N, n_steps)
    s, ds, dds = _smoothstep(u)
    axes = [
        (s @ jumps[:, k], ds @ jumps[:, k] / transition, dds @ jumps[:, k] / transition**2)
        for k in range(3)
    ]
    return _attitude_task(t, axes[0], axes[1], height, yaw=axes[2])


#: Task generators by name (CLI subcommands are derived from this).
TASKS = {
    "fig8": fig8,
    "circle": circle,
    "pitch": pitch,
    "yaw": yaw,
    "heave": heave,
    "wobble": wobble,
    "chirp": chirp,
    "steps": steps,
}
