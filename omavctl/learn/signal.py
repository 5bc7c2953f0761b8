"""Angular accelerations from body rates, and the residual the GP learns.

Two rules, used by every command that builds the residual (``fit``,
``evaluate``), so that the measured and the modelled accelerations are always
filtered alike:

1. **Measured angular acceleration** = Savitzky-Golay derivative of the body
   rate on the uniform grid (``scipy.signal.savgol_filter(deriv=1)``), computed
   per valid segment of a log; the ``window // 2`` samples at both ends of each
   segment (where the filter would extrapolate) are dropped.

2. **Held commands are filtered like the derivative** (:meth:`SavitzkyGolay.hold`,
   :mod:`omavctl.learn.savgol` derives its kernel): the measured derivative is
   compared with the nominal accelerations of the held periods weighted as the
   filter weights them. Without it the residual of an ideal plant
   is 0.03-0.06 rad/s^2 RMS at 100 Hz (half-sample delay); with it, only the
   gyro noise through the derivative filter remains (see ``docs/fit.md``).
   GP inputs (the commanded wrench) and effect regressors go through the same
   kernel, and so do desired accelerations when tracking errors are computed.

The filter itself (:class:`SavitzkyGolay`, :func:`usable_segments`, the default
window and order) lives in :mod:`omavctl.learn.savgol` and is re-exported here.
Arrays are time-major: shape (N, k) for N grid samples of a k-vector.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import ConfigError, LogError
from omavctl.learn.imu_lever import LeverArm, lever_of, without_lever
from omavctl.learn.savgol import (
    DEFAULT_SG_ORDER,
    DEFAULT_SG_WINDOW,
    SavitzkyGolay,
    usable_segments,
)
from omavctl.logs.types import FlightLog
from omavctl.physics.allocation import Allocation
from omavctl.physics.effects import Effect, EffectContext, get_effect
from omavctl.physics.mixer import motor_signals
from omavctl.physics.rigid_body import angular_acceleration
from omavctl.vehicle import Vehicle

__all__ = [
    "DEFAULT_FEATURES",
    "DEFAULT_SG_ORDER",
    "DEFAULT_SG_WINDOW",
    "FEATURES",
    "ResidualSamples",
    "SavitzkyGolay",
    "feature_names",
    "rate_noise",
    "residual_samples",
    "scaled_wrench",
    "usable_segments",
]

#: GP input feature sets: the scaled commanded wrench, optionally with body rates.
FEATURES = ("wrench", "wrench+rate", "wrench+dtorque", "wrench+rate+dtorque")
#: The default, chosen on the generalisation benchmark (``benchmarks/generalise.py``,
#: ``docs/generalisation.md``): with body rates (drag) and the torque command's
#: rate of change (lags, delays) the residual is a function of the GP's inputs on
#: any trajectory, and the GP no longer hurts on a flight it has not seen.
DEFAULT_FEATURES = "wrench+rate+dtorque"

#: Median gap (rad) between a log's arm tilts and the commanded ones above which the
#: logged tilts are taken for another convention and set aside (:func:`measured_tilt`).
#: A 0.1 s servo lag on attitude steps or a figure-8 leaves a median gap of 1-4 deg.
TILT_AGREEMENT = np.deg2rad(15.0)


def scaled_wrench(force: np.ndarray, torque: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """``u = [f / m, I^-1 tau]`` shape (N, 6) from force and torque shape (N, 3) each."""
    return np.concatenate([force / vehicle.mass, torque @ vehicle.inertia_inv.T], axis=-1)


def feature_names(features: str) -> tuple[str, ...]:
    """Names and units of the GP input columns for a feature set."""
    names = ("fx/m", "fy/m", "fz/m", "(I^-1 tau)x", "(I^-1 tau)y", "(I^-1 tau)z")
    rates = ("wx", "wy", "wz")
    dtorque = ("d/dt(I^-1 tau)x", "d/dt(I^-1 tau)y", "d/dt(I^-1 tau)z")
    if features == "wrench":
        return names
    if features == "wrench+rate":
        return (*names, *rates)
    if features == "wrench+dtorque":
        return (*names, *dtorque)
    if features == "wrench+rate+dtorque":
        return (*names, *rates, *dtorque)
    raise ConfigError(f"unknown --features '{features}' (known: {', '.join(FEATURES)})")


#: Memory for :meth:`ResidualSamples.exact`'s results per samples object (bytes).
EXACT_MEMO_BYTES = 64 * 2**20


@dataclass
class ResidualSamples:
    """The residual of one log on the kept grid samples (n of them).

    index (n,) grid indices into the log; t (n,) s; omega (n, 3) rad/s and
    u (n, 6) scaled commanded wrench, both through :meth:`SavitzkyGolay.hold`;
    omega_dot (n, 3) SG derivative of the body rate; nominal (n, 3) held
    nominal acceleration ``I^-1 (tau - omega x I omega)``; residual (n, 3) =
    omega_dot - nominal (rad/s^2); regressors: effect name -> (n, 3, p) held
    effect regressors; held: name -> (n, k) further roles through the same
    hold kernel (``extra`` of :func:`residual_samples`). Counts: total grid
    samples, samples invalid in gaps, dropped at segment edges, dropped in
    segments shorter than the window.
    """

    path: Path
    index: np.ndarray
    t: np.ndarray
    omega: np.ndarray
    u: np.ndarray
    omega_dot: np.ndarray
    nominal: np.ndarray
    residual: np.ndarray
    regressors: dict[str, np.ndarray] = field(default_factory=dict)
    held: dict[str, np.ndarray] = field(default_factory=dict)
    #: white-noise std (3,) of the logged body rate (rad/s), robust estimate
    #: from its second differences (:func:`rate_noise`)
    rate_noise: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    total: int = 0
    in_gaps: int = 0
    edge_dropped: int = 0
    short_dropped: int = 0
    #: per kept segment: its effect context and the slice of kept samples in it
    #: (for the exact nonlinear effect forms, :meth:`exact`)
    contexts: list[tuple[EffectContext, slice]] = field(default_factory=list, repr=False)
    sg: SavitzkyGolay | None = field(default=None, repr=False)
    #: which of the samples built by :func:`residual_samples` are kept (after
    #: :meth:`select`); None: all
    mask: np.ndarray | None = field(default=None, repr=False)
    #: (n, 6) rate of change of the scaled command u (SG derivative, held), 1/s
    du: np.ndarray = field(default_factory=lambda: np.empty((0, 6)))
    #: the accelerometer's lever arm estimated on this log for an effect of the measured
    #: force (:mod:`.imu_lever`); None without one (no such effect, no accelerometer, or
    #: too short a log)
    lever: LeverArm | None = field(default=None, repr=False)
    #: the aligned log these samples come from, where a caller keeps it (evaluate: the
    #: diagnosis reads the actuators' feedback from it, :mod:`.actuator_timing`)
    flight: FlightLog | None = field(default=None, repr=False, compare=False)
    #: why the log's measured arm tilts were set aside (the effects then see the
    #: commanded ones), for the log's notes; None when used or not recorded
    tilt_note: str | None = None
    #: :meth:`exact`'s results before the mask, by (effect name, value's bits): the lag
    #: and delay searches of fit and of the diagnosis ask for the same grid values again
    #: and again (a 16 s log's diagnosis: 3166 calls, 819 distinct, 3.4 of its 9.6 CPU s)
    _exact_memo: dict[tuple[str, str], np.ndarray] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @property
    def n(self) -> int:
        return int(self.index.size)

    def exact(self, name: str, value: float) -> np.ndarray:
        """Residual (n, 3) of effect ``name``'s exact nonlinear form at parameter ``value``,
        held like the measured residual (:meth:`omavctl.physics.effects.Effect.exact`)."""
        if self.sg is None or (not self.contexts and self.n > 0):
            raise ValueError("these samples were built without effect contexts")
        key = (name, float(value).hex())
        out = self._exact_memo.get(key)
        if out is None:
            effect = get_effect(name)
            out = self._held(lambda ctx: effect.exact(ctx, value))
            out = np.empty((0, 3)) if out is None else out
            if out.nbytes * (len(self._exact_memo) + 1) > EXACT_MEMO_BYTES:
                self._exact_memo.clear()  # a long log: keep at most that much
            self._exact_memo[key] = out
        return out.copy() if self.mask is None else out[self.mask]

    def held_of(self, fn: Callable[[EffectContext], np.ndarray | None]) -> np.ndarray | None:
        """``fn`` of each segment's effect context (per grid sample, (N_seg, ...)), held
        and kept like the residual: (n, ...); None when ``fn`` gives None for a segment
        or the samples were built without effect contexts."""
        if self.sg is None or (not self.contexts and self.n > 0):
            return None
        out = self._held(fn)
        return out if out is None or self.mask is None else out[self.mask]

    def _held(self, fn: Callable[[EffectContext], np.ndarray | None]) -> np.ndarray | None:
        """``fn`` of each context, held and kept per segment, before the mask (None: no
        segment, or ``fn`` gave None for one)."""
        assert self.sg is not None
        parts = []
        for ctx, keep in self.contexts:
            raw = fn(ctx)
            if raw is None:
                return None
            parts.append(self.sg.hold(raw)[keep])
        return np.concatenate(parts) if parts else None

    def select(self, keep: np.ndarray) -> ResidualSamples:
        """The samples where ``keep`` (n,) bool is True (counts and noise kept)."""
        if self.mask is None:
            mask = np.asarray(keep, dtype=bool).copy()
        else:
            mask = self.mask.copy()
            mask[np.flatnonzero(mask)] = keep
        return replace(
            self,
            mask=mask,
            index=self.index[keep],
            t=self.t[keep],
            omega=self.omega[keep],
            u=self.u[keep],
            omega_dot=self.omega_dot[keep],
            nominal=self.nominal[keep],
            residual=self.residual[keep],
            du=self.du[keep],
            regressors={k: v[keep] for k, v in self.regressors.items()},
            held={k: v[keep] for k, v in self.held.items()},
        )

    def inputs(self, features: str) -> np.ndarray:
        """GP inputs (n, d): ``u`` for "wrench", ``[u, omega]`` for "wrench+rate"."""
        feature_names(features)  # validates
        parts = [self.u]
        if "rate" in features.split("+"):
            parts.append(self.omega)
        if "dtorque" in features.split("+"):
            parts.append(self.du[:, 3:])
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=-1)


def rate_noise(second_differences: np.ndarray) -> np.ndarray:
    """White-noise std (3,) of a body rate from its second differences (m, 3).

    For white noise of std s the second difference has std ``sqrt(6) s``; the
    median absolute deviation (x 1.4826) ignores the few large differences of
    manoeuvres. The motion's own second differences (``dt^2`` times the change
    of angular acceleration) add to it: an upper estimate. NaN without data.
    """
    if second_differences.shape[0] == 0:
        return np.full(3, np.nan)
    d = second_differences
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return np.asarray(1.4826 * mad / np.sqrt(6.0), dtype=float)


def residual_samples(
    flight: FlightLog,
    vehicle: Vehicle,
    sg: SavitzkyGolay,
    effects: Sequence[str] = (),
    extra: Mapping[str, str] | None = None,
    allocation: Allocation | None = None,
) -> ResidualSamples:
    """Build the angular-acceleration residual of one aligned log.

    For each valid segment of ``flight`` with at least ``sg.window`` samples:
    SG derivative of ``body_rate``, held nominal acceleration from
    ``torque_command``, held scaled wrench, and the held regressors of the named
    ``effects`` (their :class:`EffectContext` gets the per-sample signals and
    ``sg.derivative``). ``extra`` maps output names to further roles to pass
    through :meth:`SavitzkyGolay.hold` (e.g. ``{"desired": "desired_acceleration"}``);
    they are stored in ``held`` under that name with shape (n, k).

    Raises LogError if the log lacks body_rate, force_command or torque_command
    (``read_log(..., required=...)`` already refuses such logs).
    """
    for role in ("body_rate", "force_command", "torque_command", *(extra or {}).values()):
        if not flight.has(role):
            raise LogError(f"the log has no {role} signal, needed for the residual", flight.path)
    kept, edge, short = usable_segments(flight.segments, sg.window)
    eff = [get_effect(name) for name in effects]
    alloc = allocation
    if eff and alloc is None:
        alloc = Allocation(vehicle)
    extra = dict(extra or {})
    parts = _Parts.empty(effects, extra)
    lever = lever_of(flight, sg, kept) if any(e.measured_state for e in eff) else None
    tilt, tilt_note = measured_tilt(flight, vehicle, alloc) if eff else (None, None)
    for segment in kept:
        _add_segment(parts, flight, vehicle, sg, segment, eff, alloc, extra, lever, tilt)
    out = _assemble(flight, parts, extra, sg, (edge, short))
    out.lever, out.tilt_note = lever, tilt_note
    return out


def measured_tilt(
    flight: FlightLog, vehicle: Vehicle, alloc: Allocation | None
) -> tuple[np.ndarray | None, str | None]:
    """The arms' measured tilts (N, 6) rad for the effects, or None, and a note when
    the log's tilts were set aside.

    Used on the omav's allocation (not a rotor list) when the log maps ``tilt`` and
    they follow the commanded tilts: a median gap over the valid samples above
    :data:`TILT_AGREEMENT` rad is another sign or zero convention, not a servo lag.
    """
    if alloc is None or vehicle.motors is not None or not flight.has("tilt"):
        return None, None
    tilt = flight.signals["tilt"]
    if tilt.shape[1] != vehicle.n_arms:
        return None, None
    rows = flight.valid & np.all(np.isfinite(tilt), axis=1)
    if not rows.any():
        return None, None
    wrench = np.concatenate([flight.signals["force_command"], flight.signals["torque_command"]], 1)
    commanded = alloc.allocate(wrench[rows]).tilt
    gap = np.abs((tilt[rows] - commanded + np.pi) % (2.0 * np.pi) - np.pi)
    median = float(np.median(gap))
    if median > TILT_AGREEMENT:
        return None, (
            f"tilt: the logged arm tilts are a median {np.degrees(median):.0f} deg from "
            "the commanded ones (another sign or zero?): the effects use the commanded tilts"
        )
    return tilt, None


@dataclass
class _Parts:
    """Per-segment pieces of :class:`ResidualSamples`, concatenated by :func:`_assemble`."""

    arrays: dict[str, list[np.ndarray]]
    regressors: dict[str, list[np.ndarray]]
    held: dict[str, list[np.ndarray]]
    second_differences: list[np.ndarray]
    contexts: list[tuple[EffectContext, slice]]

    @classmethod
    def empty(cls, effects: Sequence[str], extra: Mapping[str, str]) -> _Parts:
        keys = ("index", "omega", "u", "du", "omega_dot", "nominal", "residual")
        return cls(
            {k: [] for k in keys}, {name: [] for name in effects}, {n: [] for n in extra}, [], []
        )


def _add_segment(
    parts: _Parts,
    flight: FlightLog,
    vehicle: Vehicle,
    sg: SavitzkyGolay,
    segment: tuple[int, int, int, int],
    eff: Sequence[Effect],
    alloc: Allocation | None,
    extra: Mapping[str, str],
    lever: LeverArm | None = None,
    tilt: np.ndarray | None = None,
) -> None:
    """Append one kept segment ``(start, stop, keep_start, keep_stop)`` to ``parts``:
    derivative, held nominal acceleration, held inputs, effect regressors and roles
    (the measured force less the accelerometer's ``lever`` term, :mod:`.imu_lever`;
    the arms' measured ``tilt`` (N, 6) of the whole log, :func:`measured_tilt`)."""
    a, b, ka, kb = segment
    inertia, inertia_inv = vehicle.inertia, vehicle.inertia_inv
    omega = flight.signals["body_rate"][a:b]
    force = flight.signals["force_command"][a:b]
    torque = flight.signals["torque_command"][a:b]
    keep = slice(ka - a, kb - a)
    nominal = angular_acceleration(omega, torque, inertia, inertia_inv)
    omega_dot = sg.derivative(omega)
    held_nominal = sg.hold(nominal)
    parts.second_differences.append(np.diff(omega, 2, axis=0))
    parts.arrays["index"].append(np.arange(ka, kb))
    parts.arrays["omega"].append(sg.hold(omega)[keep])
    u = scaled_wrench(force, torque, vehicle)
    parts.arrays["u"].append(sg.hold(u)[keep])
    parts.arrays["du"].append(sg.hold(sg.derivative(u))[keep])
    parts.arrays["omega_dot"].append(omega_dot[keep])
    parts.arrays["nominal"].append(held_nominal[keep])
    parts.arrays["residual"].append((omega_dot - held_nominal)[keep])
    if eff:
        assert alloc is not None
        ctx = EffectContext(
            omega=omega,
            force=force,
            torque=torque,
            omega_dot_nominal=nominal,
            inertia=inertia,
            dt=sg.dt,
            allocation=alloc,
            derivative=sg.derivative,
            torque_normalised=vehicle.torque_normalised,
            fixed_rotors=vehicle.motors is not None and not vehicle.motors.tilting,
            motor=motor_signals(flight, vehicle, slice(a, b)),
            **_battery(flight, slice(a, b)),
            measured_force=without_lever(
                _measured_force(flight, vehicle.mass, slice(a, b)),
                omega,
                omega_dot,
                lever,
                vehicle.mass,
            ),
            measured_tilt=None if tilt is None else tilt[a:b],
        )
        for e in eff:
            parts.regressors[e.name].append(sg.hold(e.regressor(ctx))[keep])
        parts.contexts.append((ctx, keep))
    for name, role in extra.items():
        parts.held[name].append(sg.hold(flight.signals[role][a:b])[keep])


def _battery(flight: FlightLog, rows: slice) -> dict[str, Any]:
    """The battery voltage (n,) V over ``rows`` and its median over the flight's valid
    samples, as :class:`EffectContext` keywords (none when the log has no voltage)."""
    if not flight.has("battery_voltage"):
        return {}
    v = flight.signals["battery_voltage"][:, 0]
    ref = float(np.median(v[flight.valid])) if flight.valid.any() else float(np.median(v))
    return {"battery_voltage": v[rows], "battery_reference": ref}


def _measured_force(flight: FlightLog, mass: float, rows: slice) -> np.ndarray | None:
    """``mass`` times the specific force (n, 3) N over ``rows``, less its median over the
    flight's valid samples (the accelerometer's offset); None without an accelerometer."""
    if not flight.has("specific_force"):
        return None
    a = flight.signals["specific_force"]
    return mass * (a[rows] - np.median(a[flight.valid] if flight.valid.any() else a, axis=0))


def _cat(chunks: list[np.ndarray], tail: tuple[int, ...]) -> np.ndarray:
    """The chunks concatenated along time, or an empty (0, *tail) array."""
    return np.concatenate(chunks) if chunks else np.empty((0, *tail))


def _assemble(
    flight: FlightLog,
    parts: _Parts,
    extra: Mapping[str, str],
    sg: SavitzkyGolay,
    dropped: tuple[int, int],
) -> ResidualSamples:
    """The samples of every kept segment of ``flight`` together; ``dropped``: samples
    dropped at segment edges and in segments shorter than the window."""
    arrays = parts.arrays
    index = _cat(arrays["index"], ()).astype(np.int64)
    regressors = {
        name: _cat(chunks, (3, get_effect(name).n_theta))
        for name, chunks in parts.regressors.items()
    }
    held = {
        name: _cat(parts.held[name], (flight.signals[role].shape[1],))
        for name, role in extra.items()
    }
    return ResidualSamples(
        path=flight.path,
        index=index,
        t=flight.t[index],
        omega=_cat(arrays["omega"], (3,)),
        u=_cat(arrays["u"], (6,)),
        du=_cat(arrays["du"], (6,)),
        omega_dot=_cat(arrays["omega_dot"], (3,)),
        nominal=_cat(arrays["nominal"], (3,)),
        residual=_cat(arrays["residual"], (3,)),
        regressors=regressors,
        held=held,
        rate_noise=rate_noise(_cat(parts.second_differences, (3,))),
        total=int(flight.t.size),
        in_gaps=int((~flight.valid).sum()),
        edge_dropped=dropped[0],
        short_dropped=dropped[1],
        contexts=parts.contexts,
        sg=sg,
    )
