"""BROAD's error measures (Laidig, Caruso, Cereatti, Seel 2021, *Data* 6(7):72, §4).

Frames: the estimate ``q_est`` and the reference ``q_ref`` both map sensor axes to the same
Earth frame (ENU here; BROAD's reference is aligned to the IMU and to magnetic north, so no
further alignment is applied). The error is expressed in the Earth frame,

    e = q_est ∘ q_ref⁻¹          (BROAD's ``calculateErrorQuatEarth``)

and split into a rotation about the vertical and the rest:

* total       = 2·acos(|e_w|)                 the whole rotation angle between the two attitudes;
* heading     = 2·atan(|e_z| / |e_w|)         the angle of e's rotation about Up;
* inclination = 2·acos(√(e_w² + e_z²))        the angle of the remaining rotation about a
                                              horizontal axis.

With e = q_z(δ) ∘ q_h(ε) (q_h about a horizontal axis) one has e_w = cos(δ/2)·cos(ε/2) and
e_z = sin(δ/2)·cos(ε/2), so heading = |δ| and inclination = |ε| exactly, whichever order
the two factors come in. ``atan2`` replaces BROAD's ``atan(|e_z/e_w|)``: equal wherever e_w ≠ 0,
and defined (0) for a pure 180° tilt, where BROAD's quotient is 0/0.

The score of a trial is the RMSE of each error over the movement samples, reference
dropouts (NaN rows) skipped (BROAD's ``calculateRMSE``: ``nanmean``); the score of a group
of trials is the mean of the per-trial RMSEs (BROAD's ``getAveragedRmseValues``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ERRORS", "error_quat_earth", "broad_errors_rad", "rmse_deg", "trial_rmse_deg"]

ERRORS = ("total", "heading", "inclination")
"""The three error measures, in the order of BROAD's tables."""


def _unit_rows(name: str, q) -> np.ndarray:
    a = np.asarray(q, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 4:
        raise ValueError(f"{name} must have shape (N, 4) (w, x, y, z), got {a.shape}")
    with np.errstate(invalid="ignore", divide="ignore"):
        return a / np.linalg.norm(a, axis=1, keepdims=True)


def error_quat_earth(q_est, q_ref) -> np.ndarray:
    """``e = q_est ∘ q_ref⁻¹`` per row (N, 4), both normalised first; NaN rows stay NaN."""
    p = _unit_rows("q_est", q_est)
    q = _unit_rows("q_ref", q_ref)
    if p.shape != q.shape:
        raise ValueError(f"q_est has {p.shape[0]} rows but q_ref has {q.shape[0]}")
    pw, px, py, pz = p.T
    qw, qx, qy, qz = q.T
    qx, qy, qz = -qx, -qy, -qz  # q_ref⁻¹ of a unit quaternion
    e = np.empty_like(p)
    e[:, 0] = pw * qw - px * qx - py * qy - pz * qz
    e[:, 1] = pw * qx + px * qw + py * qz - pz * qy
    e[:, 2] = pw * qy - px * qz + py * qw + pz * qx
    e[:, 3] = pw * qz + px * qy - py * qx + pz * qw
    with np.errstate(invalid="ignore", divide="ignore"):
        return e / np.linalg.norm(e, axis=1, keepdims=True)


def broad_errors_rad(q_est, q_ref) -> dict[str, np.ndarray]:
    """Total, heading and inclination error of every sample (rad, ≥ 0; NaN where q_ref is NaN)."""
    e = error_quat_earth(q_est, q_ref)
    w, z = np.abs(e[:, 0]), np.abs(e[:, 3])
    return {
        "total": 2.0 * np.arccos(np.clip(w, 0.0, 1.0)),
        "heading": 2.0 * np.arctan2(z, w),
        "inclination": 2.0 * np.arccos(np.clip(np.sqrt(w * w + z * z), 0.0, 1.0)),
    }


def rmse_deg(errors_rad: np.ndarray, mask: np.ndarray | None = None) -> float:
    """RMS in degrees of the samples under ``mask`` (all if None), NaN samples skipped; NaN if none is left."""
    x = np.asarray(errors_rad, dtype=np.float64)
    if mask is not None:
        x = x[np.asarray(mask, dtype=bool)]
    x = x[np.isfinite(x)]
    return math.degrees(math.sqrt(float(np.mean(x * x)))) if x.size else float("nan")


def trial_rmse_deg(q_est, q_ref, movement=None) -> dict[str, float]:
    """``{"total", "heading", "inclination"}`` RMSE in degrees over the movement samples."""
    errs = broad_errors_rad(q_est, q_ref)
    if movement is not None:
        movement = np.asarray(movement)
        if movement.shape != (errs["total"].shape[0],):
            raise ValueError(f"movement must have shape ({errs['total'].shape[0]},), got {movement.shape}")
    return {k: rmse_deg(errs[k], movement) for k in ERRORS}
