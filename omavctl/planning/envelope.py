"""Where a planned reference goes, beside the task: what to check before flying it."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["TILT_WARNING_DEG", "YAW_WARNING_DEG", "envelope", "envelope_lines", "envelope_warnings"]

#: A planned roll or pitch beyond this (deg), and beyond twice the task's, is warned of.
TILT_WARNING_DEG = 45.0
#: A planned yaw turned through beyond this (deg), and beyond twice the task's, is warned
#: of (a new user's plan turned through 164 deg for a task that turns none, unwarned at 180).
YAW_WARNING_DEG = 90.0


def envelope(traj: Any) -> dict[str, float]:
    """Largest |roll| and |pitch|, the yaw turned through (deg, unwrapped) and the largest
    body rate (rad/s) of a reference (:class:`~omavctl.sim.trajectory.Trajectory`:
    ``euler`` (N, 3) rad, ``body_rate`` (N, 3) rad/s)."""
    deg = np.rad2deg(np.unwrap(traj.euler, axis=0))
    return {
        "max_abs_roll_deg": float(np.abs(deg[:, 0]).max()),
        "max_abs_pitch_deg": float(np.abs(deg[:, 1]).max()),
        "yaw_range_deg": float(np.ptp(deg[:, 2])),
        "max_body_rate": float(np.linalg.norm(traj.body_rate, axis=1).max()),
    }


def envelope_lines(result: Any) -> list[str]:
    """Where the planned reference goes beside the task: what a flight engineer checks
    before flying it; warnings (lines starting ``warning:``) when it tilts, turns yaw
    or rotates much further than the task."""
    if result.best < 0:
        return []
    plan, task = envelope(result.best_trajectory()), envelope(result.task)
    lines = [
        f"planned reference: |roll| <= {plan['max_abs_roll_deg']:.0f} deg, |pitch| <= "
        f"{plan['max_abs_pitch_deg']:.0f} deg, yaw through {plan['yaw_range_deg']:.0f} deg, "
        f"body rate <= {plan['max_body_rate']:.2f} rad/s (the task: "
        f"{task['max_abs_roll_deg']:.0f}, {task['max_abs_pitch_deg']:.0f}, "
        f"{task['yaw_range_deg']:.0f} deg, {task['max_body_rate']:.2f} rad/s)"
    ]
    if plan["yaw_range_deg"] > max(YAW_WARNING_DEG, 2.0 * task["yaw_range_deg"]):
        lines.append(
            f"warning: the planned reference turns yaw through {plan['yaw_range_deg']:.0f} "
            "deg: check the flight area and cables before flying it, or lower --amplitude "
            "(slow deviations integrate to large angles)"
        )
    tilt = max(plan["max_abs_roll_deg"], plan["max_abs_pitch_deg"])
    task_tilt = max(task["max_abs_roll_deg"], task["max_abs_pitch_deg"])
    if tilt > max(TILT_WARNING_DEG, 2.0 * task_tilt):
        lines.append(
            f"warning: the planned reference tilts to {tilt:.0f} deg, "
            f"{tilt / max(task_tilt, 1e-9):.1f}x the task's {task_tilt:.0f}: check the vehicle "
            "can fly it (actuator limits, flight area), or lower --amplitude or plan with "
            f"--max-tilt {max(TILT_WARNING_DEG, 2.0 * task_tilt):.0f} (candidates that tilt "
            "further are rejected)"
        )
    if plan["max_body_rate"] > max(3.0, 3.0 * task["max_body_rate"]):
        lines.append(
            f"warning: the planned reference rotates at up to {plan['max_body_rate']:.1f} "
            f"rad/s, {plan['max_body_rate'] / max(task['max_body_rate'], 1e-9):.0f}x the task's: "
            "check the vehicle can fly it, or lower --amplitude or --max-freq"
        )
    return lines


def envelope_warnings(result: Any) -> list[str]:
    """The warnings of :func:`envelope_lines`, without ``warning: ``."""
    return [
        ln.removeprefix("warning: ") for ln in envelope_lines(result) if ln.startswith("warning: ")
    ]
