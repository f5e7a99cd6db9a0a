"""Quaternions, rotation matrices and attitude angles.

Conventions (the package's, stated once here and in the README):

* world frame ``w``: ENU (x East, y North, z Up);
* vehicle body frame ``b``: x forward, y left, z up (ISO 8855);
* quaternions are Hamilton, scalar first ``(w, x, y, z)``; ``q_wb`` maps body vectors to
  world vectors, ``v_w = q_wb ∘ v_b ∘ q_wb*``; ``mat_wb`` is the matrix of the same map;
* roll, pitch, yaw are the intrinsic z-y-x (yaw, then pitch, then roll) angles of ``q_wb``,
  right-handed about the body axes: positive roll lowers the right side, positive pitch
  lowers the nose (ISO 8855), yaw is counter-clockwise from East;
* compass heading is clockwise from North, in [0, 2π);
* the papers' (GOST 20058) angles: geographic frame x North, y Up, z East; body x forward,
  y up, z right; ``λ = q_gb`` built from heading ψ (about Up, positive from North toward
  West), pitch ϑ (nose up positive), roll γ (right side down positive), Aleshkin et al.
  (2024) eqs. (4) and (7). They relate to ours by ψ = yaw − π/2, ϑ = −pitch, γ = roll.

Each operation has a private scalar kernel (``_q*``: quaternion components in, a tuple
out) for use inside other numba kernels without allocation, and a public wrapper that
takes arrays of shape ``(4,)`` / ``(3,)`` or ``(N, 4)`` / ``(N, 3)``.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit

__all__ = [
    "quat_multiply",
    "quat_conjugate",
    "quat_normalize",
    "quat_rotate",
    "quat_to_matrix",
    "quat_from_matrix",
    "quat_from_rotvec",
    "quat_to_rotvec",
    "quat_from_euler",
    "euler_from_quat",
    "heading_from_quat",
    "heading_from_yaw",
    "gost_angles_from_quat",
    "quat_from_gost_angles",
    "quat_angle_between",
    "wrap_angle",
    "Q_NUE_ENU",
    "Q_FLU_FUR",
]

# Constant rotations between the papers' GOST frames and ours (see module docstring).
# Q_NUE_ENU maps ENU components to North-Up-East components: a rotation by -120° about
# (1, 1, 1), which leaves the (1, 1, 1) cross-link axis of Aleshkin et al. unchanged.
Q_NUE_ENU = np.array([0.5, -0.5, -0.5, -0.5])
# Q_FLU_FUR maps GOST body components (forward, up, right) to ours (forward, left, up):
# +90° about the forward axis.
Q_FLU_FUR = np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])

# Below this cos(pitch) the z-y-x decomposition is treated as gimbal-locked: roll is set
# to zero and yaw carries the whole rotation about the vertical (as scipy does).
_GIMBAL_COS = 1e-9


# --------------------------------------------------------------------------------------
# Scalar kernels
# --------------------------------------------------------------------------------------


@jit
def _qmul(aw, ax, ay, az, bw, bx, by, bz):
    """Hamilton product a ∘ b."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@jit
def _qrot(qw, qx, qy, qz, vx, vy, vz):
    """q ∘ v ∘ q* for a unit quaternion q (v_w from v_b when q = q_wb)."""
    # t = 2 q_vec × v;  v' = v + w t + q_vec × t   (15 multiplications, no product chain)
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (
        vx + qw * tx + (qy * tz - qz * ty),
        vy + qw * ty + (qz * tx - qx * tz),
        vz + qw * tz + (qx * ty - qy * tx),
    )


@jit
def _qrot_inv(qw, qx, qy, qz, vx, vy, vz):
    """q* ∘ v ∘ q: world vector into body axes when q = q_wb."""
    return _qrot(qw, -qx, -qy, -qz, vx, vy, vz)


@jit
def _qnormalize(w, x, y, z):
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return w / n, x / n, y / n, z / n


@jit
def _qexp_rotvec(rx, ry, rz):
    """Unit quaternion of the rotation vector r (angle |r| about r/|r|)."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    half = 0.5 * angle
    if angle < 1e-4:
        # Taylor series: sin(h)/angle = ½(1 − h²/6 + h⁴/120), exact to double precision here.
        h2 = half * half
        s = 0.5 * (1.0 - h2 / 6.0 + h2 * h2 / 120.0)
        c = 1.0 - 0.5 * h2 + h2 * h2 / 24.0
    else:
        s = math.sin(half) / angle
        c = math.cos(half)
    return c, s * rx, s * ry, s * rz


@jit
def _qlog_rotvec(w, x, y, z):
    """Rotation vector of a unit quaternion, angle in [0, π]."""
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    vn = math.sqrt(x * x + y * y + z * z)
    angle = 2.0 * math.atan2(vn, w)
    if vn < 1e-12:
        scale = 2.0 / w  # small angle: angle / vn → 2 / w
    else:
        scale = angle / vn
    return scale * x, scale * y, scale * z


@jit
def _mat_from_q(w, x, y, z):
    """Rotation matrix of a unit quaternion, row by row (r00, r01, ..., r22)."""
    return (
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
        2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
        2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y),
    )


@jit
def _q_from_mat(r00, r01, r02, r10, r11, r12, r20, r21, r22):
    """Unit quaternion (w ≥ 0) of a rotation matrix, Shepperd's method (stable everywhere)."""
    trace = r00 + r11 + r22
    if trace >= r00 and trace >= r11 and trace >= r22:
        s = 2.0 * math.sqrt(1.0 + trace)
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return _qnormalize(w, x, y, z)


@jit
def _euler_from_q(w, x, y, z):
    """(roll, pitch, yaw) of q_wb, intrinsic z-y-x; roll = 0 at gimbal lock."""
    r20 = 2.0 * (x * z - w * y)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    r10 = 2.0 * (x * y + w * z)
    r00 = 1.0 - 2.0 * (y * y + z * z)
    cos_pitch = math.sqrt(r00 * r00 + r10 * r10)
    pitch = math.atan2(-r20, cos_pitch)
    if cos_pitch < _GIMBAL_COS:
        r01 = 2.0 * (x * y - w * z)
        r11 = 1.0 - 2.0 * (x * x + z * z)
        return 0.0, pitch, math.atan2(-r01, r11)
    return math.atan2(r21, r22), pitch, math.atan2(r10, r00)


@jit
def _q_from_euler(roll, pitch, yaw):
    """q_wb = q_z(yaw) ∘ q_y(pitch) ∘ q_x(roll)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        cy * cp * cr + sy * sp * sr,
        cy * cp * sr - sy * sp * cr,
        cy * sp * cr + sy * cp * sr,
        sy * cp * cr - cy * sp * sr,
    )


@jit
def _wrap(angle):
    """Angle wrapped into (−π, π] (floor-based: numba has no math.fmod)."""
    two_pi = 2.0 * math.pi
    a = math.pi - (math.pi - angle - two_pi * math.floor((math.pi - angle) / two_pi))
    return math.pi if a <= -math.pi else a


@jit
def _heading_from_yaw(yaw):
    """Compass heading (clockwise from North, [0, 2π)) of an ENU yaw."""
    two_pi = 2.0 * math.pi
    h = 0.5 * math.pi - yaw
    h -= two_pi * math.floor(h / two_pi)
    return 0.0 if h >= two_pi else h  # rounding can land exactly on 2π


@jit
def _gost_lambda_from_q(w, x, y, z):
    """λ = q_gb in the GOST frames: Q_NUE_ENU ∘ q_wb ∘ Q_FLU_FUR."""
    a = _qmul(0.5, -0.5, -0.5, -0.5, w, x, y, z)
    h = math.sqrt(0.5)
    return _qmul(a[0], a[1], a[2], a[3], h, h, 0.0, 0.0)


@jit
def _q_from_gost_lambda(l0, l1, l2, l3):
    """Inverse of _gost_lambda_from_q: q_wb = Q_NUE_ENU* ∘ λ ∘ Q_FLU_FUR*."""
    a = _qmul(0.5, 0.5, 0.5, 0.5, l0, l1, l2, l3)
    h = math.sqrt(0.5)
    return _qmul(a[0], a[1], a[2], a[3], h, -h, 0.0, 0.0)


@jit
def _gost_angles_from_lambda(l0, l1, l2, l3):
    """(ψ, ϑ, γ) from λ, Aleshkin et al. (2024) eq. (4) with atan2.

    The printed DCM has the wrong (2,2) entry (docs/design.md §5); with C = λ's matrix from geographic
    to body, ϑ = asin(C12) and the printed quotients for γ and ψ hold with entry (2,2) =
    2λ0² + 2λ2² − 1 and the signs of (4).
    """
    s_theta = 2.0 * (l1 * l2 + l0 * l3)
    c22 = 2.0 * (l0 * l0 + l2 * l2) - 1.0
    c23 = 2.0 * (l2 * l3 - l0 * l1)
    c11 = 2.0 * (l0 * l0 + l1 * l1) - 1.0
    c13 = 2.0 * (l1 * l3 - l0 * l2)
    cos_theta = math.sqrt(c11 * c11 + c13 * c13)
    theta = math.atan2(s_theta, cos_theta)
    if cos_theta < _GIMBAL_COS:
        # Roll set to zero; heading from the remaining rotation about the vertical.
        c31 = 2.0 * (l1 * l3 + l0 * l2)
        c33 = 2.0 * (l0 * l0 + l3 * l3) - 1.0
        return math.atan2(c31, c33), theta, 0.0
    return math.atan2(-c13, c11), theta, math.atan2(-c23, c22)


@jit
def _gost_lambda_from_angles(psi, theta, gamma):
    """Aleshkin et al. (2024) eq. (7)."""
    cp, sp = math.cos(0.5 * psi), math.sin(0.5 * psi)
    ct, st = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cg, sg = math.cos(0.5 * gamma), math.sin(0.5 * gamma)
    return (
        cp * ct * cg - sp * st * sg,
        cp * ct * sg + sp * st * cg,
        sp * ct * cg + cp * st * sg,
        cp * st * cg - sp * ct * sg,
    )


# --------------------------------------------------------------------------------------
# Batch kernels over rows
# --------------------------------------------------------------------------------------


@jit
def _batch_qmul(p, q, out):
    for i in range(out.shape[0]):
        r = _qmul(p[i, 0], p[i, 1], p[i, 2], p[i, 3], q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = r


@jit
def _batch_qrot(q, v, out):
    for i in range(out.shape[0]):
        r = _qrot(q[i, 0], q[i, 1], q[i, 2], q[i, 3], v[i, 0], v[i, 1], v[i, 2])
        out[i, 0], out[i, 1], out[i, 2] = r


@jit
def _batch_mat_from_q(q, out):
    for i in range(out.shape[0]):
        w, x, y, z = _qnormalize(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        r = _mat_from_q(w, x, y, z)
        for k in range(9):
            out[i, k // 3, k % 3] = r[k]


@jit
def _batch_q_from_mat(m, out):
    for i in range(out.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = _q_from_mat(
            m[i, 0, 0], m[i, 0, 1], m[i, 0, 2],
            m[i, 1, 0], m[i, 1, 1], m[i, 1, 2],
            m[i, 2, 0], m[i, 2, 1], m[i, 2, 2],
        )


@jit
def _batch_q_from_rotvec(r, out):
    for i in range(out.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = _qexp_rotvec(r[i, 0], r[i, 1], r[i, 2])


@jit
def _batch_rotvec_from_q(q, out):
    for i in range(out.shape[0]):
        w, x, y, z = _qnormalize(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        out[i, 0], out[i, 1], out[i, 2] = _qlog_rotvec(w, x, y, z)


@jit
def _batch_euler_from_q(q, out):
    for i in range(out.shape[0]):
        w, x, y, z = _qnormalize(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        out[i, 0], out[i, 1], out[i, 2] = _euler_from_q(w, x, y, z)


@jit
def _batch_q_from_euler(e, out):
    for i in range(out.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = _q_from_euler(e[i, 0], e[i, 1], e[i, 2])


@jit
def _batch_gost_from_q(q, out):
    for i in range(out.shape[0]):
        w, x, y, z = _qnormalize(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        lam = _gost_lambda_from_q(w, x, y, z)
        out[i, 0], out[i, 1], out[i, 2] = _gost_angles_from_lambda(lam[0], lam[1], lam[2], lam[3])


@jit
def _batch_q_from_gost(a, out):
    for i in range(out.shape[0]):
        lam = _gost_lambda_from_angles(a[i, 0], a[i, 1], a[i, 2])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = _q_from_gost_lambda(lam[0], lam[1], lam[2], lam[3])


@jit
def _batch_angle_between(p, q, out):
    for i in range(out.shape[0]):
        pw, px, py, pz = _qnormalize(p[i, 0], p[i, 1], p[i, 2], p[i, 3])
        qw, qx, qy, qz = _qnormalize(q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        d = _qmul(pw, -px, -py, -pz, qw, qx, qy, qz)
        vn = math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3])
        out[i] = 2.0 * math.atan2(vn, abs(d[0]))


# --------------------------------------------------------------------------------------
# Public wrappers
# --------------------------------------------------------------------------------------


def _rows(array, width: int, name: str) -> tuple[np.ndarray, bool]:
    """Return ``array`` as a contiguous float64 (N, width) array and whether it was one row."""
    a = np.asarray(array, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == width:
        return np.ascontiguousarray(a.reshape(1, width)), True
    if a.ndim == 2 and a.shape[1] == width:
        return np.ascontiguousarray(a), False
    raise ValueError(f"{name} must have shape ({width},) or (N, {width}), got {a.shape}")


def _same_rows(a: np.ndarray, b: np.ndarray, names: str) -> tuple[np.ndarray, np.ndarray]:
    """Broadcast a single row against N rows."""
    if a.shape[0] == b.shape[0]:
        return a, b
    if a.shape[0] == 1:
        return np.ascontiguousarray(np.broadcast_to(a, (b.shape[0], a.shape[1]))), b
    if b.shape[0] == 1:
        return a, np.ascontiguousarray(np.broadcast_to(b, (a.shape[0], b.shape[1])))
    raise ValueError(f"{names} have different numbers of rows: {a.shape[0]} and {b.shape[0]}")


def _unwrap(out: np.ndarray, single: bool) -> np.ndarray:
    return out[0] if single else out


def quat_multiply(p, q) -> np.ndarray:
    """Hamilton product ``p ∘ q`` of (4,) or (N, 4) quaternions (w, x, y, z)."""
    p2, sp = _rows(p, 4, "p")
    q2, sq = _rows(q, 4, "q")
    p2, q2 = _same_rows(p2, q2, "p and q")
    out = np.empty((p2.shape[0], 4))
    _batch_qmul(p2, q2, out)
    return _unwrap(out, sp and sq)


def quat_conjugate(q) -> np.ndarray:
    """Conjugate ``q*`` (the inverse of a unit quaternion)."""
    q2, single = _rows(q, 4, "q")
    out = q2 * np.array([1.0, -1.0, -1.0, -1.0])
    return _unwrap(out, single)


def quat_normalize(q) -> np.ndarray:
    """Unit quaternion in the direction of ``q``; a zero quaternion is an error."""
    q2, single = _rows(q, 4, "q")
    norm = np.linalg.norm(q2, axis=1, keepdims=True)
    if np.any(norm == 0.0) or not np.all(np.isfinite(norm)):
        raise ValueError("q must be finite and non-zero to be normalised")
    return _unwrap(q2 / norm, single)


def quat_rotate(q_ab, vec_b) -> np.ndarray:
    """Rotate ``vec_b`` into frame a: ``vec_a = q_ab ∘ vec_b ∘ q_ab*`` (q must be unit)."""
    q2, sq = _rows(q_ab, 4, "q_ab")
    v2, sv = _rows(vec_b, 3, "vec_b")
    q2 = np.ascontiguousarray(q2)
    if q2.shape[0] != v2.shape[0]:
        if q2.shape[0] == 1:
            q2 = np.ascontiguousarray(np.broadcast_to(q2, (v2.shape[0], 4)))
        elif v2.shape[0] == 1:
            v2 = np.ascontiguousarray(np.broadcast_to(v2, (q2.shape[0], 3)))
        else:
            raise ValueError(f"q_ab and vec_b have different numbers of rows: {q2.shape[0]} and {v2.shape[0]}")
    out = np.empty((q2.shape[0], 3))
    _batch_qrot(q2, v2, out)
    return _unwrap(out, sq and sv)


def quat_to_matrix(q_ab) -> np.ndarray:
    """Rotation matrix ``mat_ab`` (3, 3) or (N, 3, 3) with ``vec_a = mat_ab @ vec_b``."""
    q2, single = _rows(q_ab, 4, "q_ab")
    out = np.empty((q2.shape[0], 3, 3))
    _batch_mat_from_q(q2, out)
    return _unwrap(out, single)


def quat_from_matrix(mat_ab) -> np.ndarray:
    """Unit quaternion (w ≥ 0) of a rotation matrix (3, 3) or (N, 3, 3)."""
    m = np.asarray(mat_ab, dtype=np.float64)
    single = m.ndim == 2
    if m.shape[-2:] != (3, 3) or m.ndim not in (2, 3):
        raise ValueError(f"mat_ab must have shape (3, 3) or (N, 3, 3), got {m.shape}")
    m = np.ascontiguousarray(m.reshape(-1, 3, 3))
    out = np.empty((m.shape[0], 4))
    _batch_q_from_mat(m, out)
    return _unwrap(out, single)


def quat_from_rotvec(rotvec) -> np.ndarray:
    """Unit quaternion of a rotation vector (rad): angle |r| about r/|r|."""
    r2, single = _rows(rotvec, 3, "rotvec")
    out = np.empty((r2.shape[0], 4))
    _batch_q_from_rotvec(r2, out)
    return _unwrap(out, single)


def quat_to_rotvec(q) -> np.ndarray:
    """Rotation vector (rad) of a quaternion; the angle is in [0, π]."""
    q2, single = _rows(q, 4, "q")
    out = np.empty((q2.shape[0], 3))
    _batch_rotvec_from_q(q2, out)
    return _unwrap(out, single)


def quat_from_euler(roll, pitch, yaw) -> np.ndarray:
    """``q_wb`` from roll, pitch, yaw (rad, intrinsic z-y-x, see module docstring)."""
    e = np.stack(np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (roll, pitch, yaw))), axis=-1)
    single = e.ndim == 1
    e2 = np.ascontiguousarray(e.reshape(-1, 3))
    out = np.empty((e2.shape[0], 4))
    _batch_q_from_euler(e2, out)
    return _unwrap(out, single)


def euler_from_quat(q_wb) -> np.ndarray:
    """(roll, pitch, yaw) in rad, shape (3,) or (N, 3); roll is set to 0 at gimbal lock."""
    q2, single = _rows(q_wb, 4, "q_wb")
    out = np.empty((q2.shape[0], 3))
    _batch_euler_from_q(q2, out)
    return _unwrap(out, single)


def heading_from_yaw(yaw) -> np.ndarray | float:
    """Compass heading in rad, clockwise from North, in [0, 2π), of an ENU yaw."""
    h = np.mod(0.5 * np.pi - np.asarray(yaw, dtype=np.float64), 2.0 * np.pi)
    h = np.where(h >= 2.0 * np.pi, 0.0, h)
    return float(h) if h.ndim == 0 else h


def heading_from_quat(q_wb) -> np.ndarray | float:
    """Compass heading in rad, clockwise from North, in [0, 2π)."""
    return heading_from_yaw(euler_from_quat(q_wb)[..., 2])


def gost_angles_from_quat(q_wb) -> np.ndarray:
    """The papers' (ψ, ϑ, γ) in rad (GOST 20058, see module docstring), shape (3,) or (N, 3)."""
    q2, single = _rows(q_wb, 4, "q_wb")
    out = np.empty((q2.shape[0], 3))
    _batch_gost_from_q(q2, out)
    return _unwrap(out, single)


def quat_from_gost_angles(psi, theta, gamma) -> np.ndarray:
    """``q_wb`` from the papers' heading ψ, pitch ϑ, roll γ (rad), via eq. (7) of Aleshkin et al."""
    a = np.stack(np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (psi, theta, gamma))), axis=-1)
    single = a.ndim == 1
    a2 = np.ascontiguousarray(a.reshape(-1, 3))
    out = np.empty((a2.shape[0], 4))
    _batch_q_from_gost(a2, out)
    return _unwrap(out, single)


def quat_angle_between(p, q) -> np.ndarray | float:
    """Angle in rad, [0, π], of the rotation that takes attitude p to attitude q."""
    p2, sp = _rows(p, 4, "p")
    q2, sq = _rows(q, 4, "q")
    p2, q2 = _same_rows(p2, q2, "p and q")
    out = np.empty(p2.shape[0])
    _batch_angle_between(p2, q2, out)
    return float(out[0]) if (sp and sq) else out


def wrap_angle(angle) -> np.ndarray | float:
    """Angle(s) wrapped into (−π, π]."""
    a = np.asarray(angle, dtype=np.float64)
    w = np.pi - np.mod(np.pi - a, 2.0 * np.pi)
    return float(w) if w.ndim == 0 else w
