"""Attitude errors and the figures of a run's summary.

Errors are estimate minus truth, each wrapped into (−180°, 180°]: roll, pitch (ISO 8855,
see :mod:`biso_cosim.frames`) and compass heading; ``total`` is the angle of the rotation
between the two attitudes (never negative).
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim.frames import euler_from_quat, heading_from_yaw, quat_angle_between, wrap_angle

__all__ = ["ANGLES", "attitude_angles_deg", "angle_errors_deg", "error_stats", "start_end_difference"]

ANGLES = ("roll", "pitch", "heading")


def attitude_angles_deg(q_wb: np.ndarray) -> dict[str, np.ndarray]:
    """Roll, pitch and compass heading (degrees) of each attitude."""
    e = euler_from_quat(q_wb)
    return {
        "roll": np.degrees(e[:, 0]),
        "pitch": np.degrees(e[:, 1]),
        "heading": np.degrees(heading_from_yaw(e[:, 2])),
    }


def angle_errors_deg(q_est: np.ndarray, q_true: np.ndarray) -> dict[str, np.ndarray]:
    """Estimate minus truth per angle (degrees, wrapped) and the total attitude error."""
    est = attitude_angles_deg(q_est)
    true = attitude_angles_deg(q_true)
    out = {name: np.degrees(wrap_angle(np.radians(est[name] - true[name]))) for name in ANGLES}
    out["total"] = np.degrees(quat_angle_between(q_est, q_true))
    return out


def error_stats(errors_deg: dict[str, np.ndarray], t_s: np.ndarray) -> dict[str, dict[str, float]]:
    """RMS, largest magnitude (and when) and mean of each error series."""
    stats = {}
    for name, err in errors_deg.items():
        i = int(np.argmax(np.abs(err)))
        stats[name] = {
            "rms_deg": float(np.sqrt(np.mean(err * err))),
            "max_abs_deg": float(abs(err[i])),
            "max_at_s": float(t_s[i]),
            "mean_deg": float(np.mean(err)),
        }
    return stats


def _circular_mean_deg(a_deg: np.ndarray) -> float:
    a = np.radians(a_deg)
    return math.degrees(math.atan2(np.mean(np.sin(a)), np.mean(np.cos(a))))


def start_end_difference(t_s: np.ndarray, angles_deg: dict[str, np.ndarray], start: tuple[float, float],
                         end: tuple[float, float]) -> dict[str, float]:
    """End value minus start value of each angle (degrees, wrapped), each value the circular
    mean over its time window ``(t_from, t_to)`` (the car stands still in both)."""
    s = (t_s >= start[0]) & (t_s <= start[1])
    e = (t_s >= end[0]) & (t_s <= end[1])
    if not s.any() or not e.any():
        raise ValueError("start or end window holds no samples")
    out = {}
    for name in ANGLES:
        diff = _circular_mean_deg(angles_deg[name][e]) - _circular_mean_deg(angles_deg[name][s])
        out[name] = float(np.degrees(wrap_angle(np.radians(diff))))
    return out
