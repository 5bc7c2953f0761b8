"""The accelerometer's lever arm, estimated per log and removed from its force (issue 28).

An accelerometer at ``r`` (m, body FLU) from the centre of mass reads, beside the
specific force of the centre of mass, ``alpha x r + omega x (omega x r)``: on the
px4tools octocopter (docs/horizons.md, session 16) that term made the lateral force
follow the measured angular acceleration (correlation 0.72 on pitch), so ``drag_moment``
"predicted" the angular acceleration from a sensor that measures it, which no open-loop
rollout can carry forward. ``r`` is estimated per log by least squares of the held
lateral specific force on the held lever regressor ``[alpha]x + [omega]x^2`` (alpha the
Savitzky-Golay derivative of the body rate), with a constant per axis (the
accelerometer's offset and the mean drag), over the kept samples of every segment; its
95 % interval is the sandwich of the scores summed over 0.5 s blocks within segments
(the residual is autocorrelated; at least 10 blocks, else no estimate). The z row is
left out: the thrust moves the vertical force. Where ``r`` differs from 0 (a Wald test
at 95 %), the lever term at that ``r`` is removed from the measured force before
``drag_moment``'s regressor is formed: at fit, at evaluate and in the rollout (which
rolls forward the force without it). A log without an accelerometer is untouched (the
simulated draws).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from omavctl.learn.savgol import SavitzkyGolay

__all__ = [
    "REMOVE_LEVER",
    "LeverArm",
    "estimate_lever",
    "lever_matrix",
    "lever_of",
    "lever_provenance",
    "without_lever",
]

#: remove the estimated lever term from the measured force (False: keep the raw force, as
#: before session 16; for benchmarks/horizons_force.py)
REMOVE_LEVER = True
#: the blocks (s) whose summed scores the interval treats as independent
BLOCK_SECONDS = 0.5
#: fewer blocks than this and no lever is estimated (the force stays raw): the interval
#: needs them
MIN_BLOCKS = 10
#: the lever term is removed only when r differs from 0 at this level (a Wald test of
#: its three components: the chi-square quantile, 3 degrees of freedom, 95 %)
CHI2_3_95 = 7.814727903251178
#: the 95 % normal quantile
Z95 = 1.959963984540054


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (n, 3, 3) of vectors v (n, 3): ``skew(v) @ x = v x x``."""
    z = np.zeros(v.shape[0])
    rows = (
        (z, -v[:, 2], v[:, 1]),
        (v[:, 2], z, -v[:, 0]),
        (-v[:, 1], v[:, 0], z),
    )
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=1)


def lever_matrix(omega: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """L (n, 3, 3) with ``L @ r = alpha x r + omega x (omega x r)`` (m/s^2 per m) at body
    rates omega (n, 3) rad/s and angular accelerations alpha (n, 3) rad/s^2."""
    w = _skew(np.asarray(omega, float))
    return _skew(np.asarray(alpha, float)) + w @ w


@dataclass(frozen=True)
class LeverArm:
    """The accelerometer's offset r (3,) m from the centre of mass (body FLU), its
    standard error (3,) m (the block sandwich) and the number of samples it was
    estimated on."""

    r: np.ndarray
    stderr: np.ndarray
    samples: int
    #: the Wald statistic of r = 0 (chi-square, 3 degrees of freedom)
    wald: float = 0.0

    @property
    def pinned(self) -> bool:
        """Whether r differs from 0 at 95 % (:data:`CHI2_3_95`): only then is it removed."""
        return self.wald > CHI2_3_95

    def interval(self) -> np.ndarray:
        """95 % intervals (3, 2) m."""
        half = Z95 * self.stderr
        return np.stack([self.r - half, self.r + half], axis=-1)

    def note(self) -> str:
        """One line for the log's notes, in mm."""
        lo, hi = (1e3 * self.interval()).T
        parts = ", ".join(
            f"{a} {1e3 * v:+.1f} ({x:+.1f} to {y:+.1f})"
            for a, v, x, y in zip("xyz", self.r, lo, hi, strict=True)
        )
        what = (
            "its alpha x r + omega x (omega x r) is removed from the measured force "
            "drag_moment reads"
            if self.pinned and REMOVE_LEVER
            else "not distinguishable from 0 (95 %): the measured force is left as logged"
            if not self.pinned
            else "the measured force is left as logged (REMOVE_LEVER off)"
        )
        return (
            f"accelerometer lever arm from the centre of mass, mm (95 %): {parts}, estimated "
            f"on {self.samples} samples; {what}"
        )


def estimate_lever(
    parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, slice]], sg: SavitzkyGolay
) -> LeverArm | None:
    """r from the segments' ``(omega, alpha, accel, keep)``: body rate (n, 3) rad/s, its
    Savitzky-Golay derivative (n, 3) rad/s^2, specific force (n, 3) m/s^2, each over a
    whole segment, and the slice of its kept samples; ``sg`` the Savitzky-Golay filter
    whose ``hold`` smooths both sides alike. None with fewer than :data:`MIN_BLOCKS`
    blocks of :data:`BLOCK_SECONDS` or a non-finite estimate; the covariance is the
    sandwich of the scores summed over those blocks (``sg.dt`` the grid step)."""
    xs, ys, seg = [], [], []
    block = max(round(BLOCK_SECONDS / sg.dt), 1)
    for i, (omega, alpha, accel, keep) in enumerate(parts):
        n = omega.shape[0]
        held = sg.hold(lever_matrix(omega, alpha).reshape(n, 9)).reshape(n, 3, 3)[keep]
        x = np.zeros((held.shape[0], 3, 5))
        x[:, :2, :3] = held[:, :2]
        x[:, 0, 3] = x[:, 1, 4] = 1.0  # a constant per axis
        y = np.zeros((held.shape[0], 3))
        y[:, :2] = sg.hold(accel)[keep][:, :2]
        xs.append(x)
        ys.append(y)
        seg.append(i * 10**6 + np.arange(held.shape[0]) // block)
    if not xs:
        return None
    x, y, s = np.concatenate(xs), np.concatenate(ys), np.concatenate(seg)
    if np.unique(s).size < MIN_BLOCKS:
        return None
    a = x.reshape(-1, 5)
    coef = np.linalg.lstsq(a, y.reshape(-1), rcond=None)[0]
    scores = np.einsum("nap,na->np", x, y - x @ coef)  # (n, 5)
    _, inv = np.unique(s, return_inverse=True)
    summed = np.zeros((int(inv.max()) + 1, 5))
    np.add.at(summed, inv, scores)
    bread = np.linalg.pinv(a.T @ a)
    cov = bread @ (summed.T @ summed) @ bread
    se = np.sqrt(np.maximum(np.diag(cov)[:3], 0.0))
    if not (np.all(np.isfinite(coef)) and np.all(np.isfinite(se))):
        return None
    wald = float(coef[:3] @ np.linalg.pinv(cov[:3, :3]) @ coef[:3])
    return LeverArm(coef[:3], se, int(x.shape[0]), wald)


def lever_of(flight: Any, sg: SavitzkyGolay, segments: Sequence[tuple[int, int, int, int]]) -> (
    LeverArm | None
):  # fmt: skip
    """:func:`estimate_lever` over a log's kept ``segments`` ``(start, stop, keep_start,
    keep_stop)`` (a :class:`~omavctl.logs.types.FlightLog` with ``body_rate``); None
    without a ``specific_force`` role; the estimate's :meth:`LeverArm.note` is added to
    the log's notes (once)."""
    if not flight.has("specific_force"):
        return None
    parts = []
    for a, b, ka, kb in segments:
        omega = flight.signals["body_rate"][a:b]
        accel = flight.signals["specific_force"][a:b]
        parts.append((omega, sg.derivative(omega), accel, slice(ka - a, kb - a)))
    lever = estimate_lever(parts, sg)
    if lever is not None and lever.note() not in flight.notes:
        flight.notes.append(lever.note())
    return lever


def without_lever(
    force: np.ndarray | None,
    omega: np.ndarray,
    alpha: np.ndarray,
    lever: LeverArm | None,
    mass: float,
) -> np.ndarray | None:
    """The measured force (n, 3) N less ``mass (alpha x r + omega x (omega x r))`` at body
    rates omega (n, 3) and angular accelerations alpha (n, 3); unchanged without a force,
    a lever, one not :attr:`LeverArm.pinned` or with :data:`REMOVE_LEVER` off."""
    if force is None or lever is None or not lever.pinned or not REMOVE_LEVER:
        return force
    return force - mass * (lever_matrix(omega, alpha) @ lever.r)


def lever_provenance(levers: Sequence[tuple[str, LeverArm | None]]) -> list[dict[str, Any]]:
    """What a model file records of the lever arm its measured-force effect was fitted
    with (``provenance.imu_lever``, docs/schemas.md): per log (name, its lever or None)
    ``r`` and ``stderr`` (m, body FLU; null without an estimate) and ``removed``, whether
    its term was taken from the force before the effect's regressor was formed."""
    out: list[dict[str, Any]] = []
    for name, lever in levers:
        if lever is None:
            out.append({"log": name, "r": None, "stderr": None, "removed": False})
            continue
        out.append(
            {
                "log": name,
                "r": [float(v) for v in lever.r],
                "stderr": [float(v) for v in lever.stderr],
                "removed": bool(lever.pinned and REMOVE_LEVER),
            }
        )
    return out
