"""The reference attitude λ_k from the accelerometer and the magnetometer alone.

Aleshkin et al. (2024) correct the Poisson equation toward λ_k, an attitude computed each
sample from the specific force f and the magnetic field H (their eqs. (5)–(7)). Two
constructions are offered; they give the same quaternion (to rounding) wherever both are
defined:

``"euler"``
    the paper's route, with the corrections of DESIGN.md §5: in the paper's body axes
    (x forward, y up, z right) ``ϑ = atan2(f_x, √(f_y² + f_z²))``, ``γ = atan2(−f_z, f_y)``,
    ``ψ = atan2(H_y sinγ + H_z cosγ, H_x cosϑ − (H_y cosγ − H_z sinγ) sinϑ) − D``, then
    eq. (7). The printed (5) (arcsin, needs the horizontal field L) and (6) (sign of γ) are
    replaced; atan2 never returns NaN. Heading is undefined at ϑ = ±90°.
``"vector"``
    singularity-free and trig-free (TRIAD): up = f/|f|, east = (H × up)/|H × up|,
    north = up × east are the rows of the body→world matrix, turned into a quaternion by
    Shepperd's method, then rotated by the declination about Up. Defined for every
    attitude; several times cheaper (DESIGN.md §9).

Both map the magnetic heading to true heading with the declination D (east positive).
When the magnetometer sample is unusable (non-finite, zero, or parallel to f) the heading
of λ_k is taken from the current estimate, so that only tilt is corrected.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.frames import (
    _gost_angles_from_lambda,
    _gost_lambda_from_angles,
    _gost_lambda_from_q,
    _q_from_gost_lambda,
    _qmul,
    _qrot_inv,
)

__all__ = ["reference_attitude", "REFERENCE_METHODS"]

REFERENCE_METHODS = ("vector", "euler")
"""Names of the λ_k constructions; the kernel takes the index into this tuple."""

# Validity limits of one input sample (beyond any MEMS full scale, below float overflow).
MAX_RATE = 1.0e4  # rad/s
MIN_ACCEL, MAX_ACCEL = 1.0e-6, 1.0e6  # m/s²
MIN_MAG, MAX_MAG = 1.0e-6, 1.0e7  # µT
# sin of the angle between H and f below which the field gives no heading.
MAG_PARALLEL_SIN = 1.0e-6


@jit
def _vec_norm_ok(x, y, z, lo, hi):
    """(ok, norm): finite and lo < |v| < hi."""
    n2 = x * x + y * y + z * z
    if not math.isfinite(n2):
        return False, 0.0
    n = math.sqrt(n2)
    return (n > lo) and (n < hi), n


@jit
def _vec_ok(x, y, z, lo, hi):
    """Finite and lo < |v| < hi, without the square root."""
    n2 = x * x + y * y + z * z
    return math.isfinite(n2) and n2 > lo * lo and n2 < hi * hi


@jit
def _mag_usable(fx, fy, fz, mx, my, mz):
    """Whether the field (finite, non-zero) has a part across f (finite, non-zero): a heading."""
    cx = my * fz - mz * fy
    cy = mz * fx - mx * fz
    cz = mx * fy - my * fx
    m2 = mx * mx + my * my + mz * mz
    f2 = fx * fx + fy * fy + fz * fz
    return cx * cx + cy * cy + cz * cz > (MAG_PARALLEL_SIN * MAG_PARALLEL_SIN) * m2 * f2


@jit
def _q_from_rows(r00, r01, r02, r10, r11, r12, r20, r21, r22):
    """Shepperd's method for an orthonormal matrix (rows built so): unit to rounding, no
    renormalisation, one square root (frames._q_from_mat also normalises)."""
    trace = r00 + r11 + r22
    if trace >= r00 and trace >= r11 and trace >= r22:
        s = 2.0 * math.sqrt(1.0 + trace)
        i = 1.0 / s
        return 0.25 * s, (r21 - r12) * i, (r02 - r20) * i, (r10 - r01) * i
    if r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        i = 1.0 / s
        return (r21 - r12) * i, 0.25 * s, (r01 + r10) * i, (r02 + r20) * i
    if r11 >= r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        i = 1.0 / s
        return (r02 - r20) * i, (r01 + r10) * i, 0.25 * s, (r12 + r21) * i
    s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
    i = 1.0 / s
    return (r10 - r01) * i, (r02 + r20) * i, (r12 + r21) * i, 0.25 * s


@jit
def _ref_vector(ux, uy, uz, mx, my, mz, mag_ok, lw, lx, ly, lz, cdh, sdh):
    """λ_k by TRIAD from the unit up vector u (body) and the field m (body).

    ``cdh, sdh`` are cos(D/2), sin(D/2). Without a usable field the east axis comes from
    the estimate ``l`` (any non-zero quaternion).
    """
    if mag_ok:
        ex = my * uz - mz * uy
        ey = mz * ux - mx * uz
        ez = mx * uy - my * ux
    else:
        # Estimate's north in body axes, crossed with up, gives east; if the estimate's
        # north is vertical, its east is not: project that on the horizontal instead.
        nx, ny, nz = _qrot_inv(lw, lx, ly, lz, 0.0, 1.0, 0.0)
        s = 1.0 / (lw * lw + lx * lx + ly * ly + lz * lz)
        nx, ny, nz = nx * s, ny * s, nz * s
        ex = ny * uz - nz * uy
        ey = nz * ux - nx * uz
        ez = nx * uy - ny * ux
        if ex * ex + ey * ey + ez * ez < 0.01:
            ex, ey, ez = _qrot_inv(lw, lx, ly, lz, 1.0, 0.0, 0.0)
            ex, ey, ez = ex * s, ey * s, ez * s
            d = ex * ux + ey * uy + ez * uz
            ex, ey, ez = ex - d * ux, ey - d * uy, ez - d * uz
    en = 1.0 / math.sqrt(ex * ex + ey * ey + ez * ez)  # (the rows are then orthonormal)
    ex, ey, ez = ex * en, ey * en, ez * en
    nx = uy * ez - uz * ey
    ny = uz * ex - ux * ez
    nz = ux * ey - uy * ex
    # rows of mat_wb are the world axes (E, N, U) in body components
    qw, qx, qy, qz = _q_from_rows(ex, ey, ez, nx, ny, nz, ux, uy, uz)
    if mag_ok:
        # magnetic → true: rotate the world by −D about Up
        return _qmul(cdh, 0.0, 0.0, -sdh, qw, qx, qy, qz)
    return qw, qx, qy, qz


@jit
def _ref_euler(fx, fy, fz, mx, my, mz, mag_ok, lw, lx, ly, lz, decl):
    """λ_k by the corrected eqs. (5)–(7) of Aleshkin et al. (2024), in q_wb form."""
    # paper body axes (x forward, y up, z right) from ours (x forward, y left, z up)
    fpx, fpy, fpz = fx, fz, -fy
    theta = math.atan2(fpx, math.sqrt(fpy * fpy + fpz * fpz))
    gamma = math.atan2(-fpz, fpy)
    if mag_ok:
        hx, hy, hz = mx, mz, -my
        sg, cg = math.sin(gamma), math.cos(gamma)
        st, ct = math.sin(theta), math.cos(theta)
        psi = math.atan2(hy * sg + hz * cg, hx * ct - (hy * cg - hz * sg) * st) - decl
    else:
        n = math.sqrt(lw * lw + lx * lx + ly * ly + lz * lz)
        g0, g1, g2, g3 = _gost_lambda_from_q(lw / n, lx / n, ly / n, lz / n)
        psi = _gost_angles_from_lambda(g0, g1, g2, g3)[0]
    l0, l1, l2, l3 = _gost_lambda_from_angles(psi, theta, gamma)
    return _q_from_gost_lambda(l0, l1, l2, l3)


@jit
def _reference(method, fx, fy, fz, fn, mx, my, mz, mag_ok, lw, lx, ly, lz, decl, cdh, sdh):
    """λ_k (unit, q_wb) by ``method`` (index into REFERENCE_METHODS); fn = |f| > 0."""
    if method == 0:
        return _ref_vector(fx / fn, fy / fn, fz / fn, mx, my, mz, mag_ok, lw, lx, ly, lz, cdh, sdh)
    return _ref_euler(fx, fy, fz, mx, my, mz, mag_ok, lw, lx, ly, lz, decl)


@jit
def _batch_reference(method, accel, mag, decl, out):
    """λ_k of every row; rows without a valid accelerometer sample get NaN."""
    cdh, sdh = math.cos(0.5 * decl), math.sin(0.5 * decl)
    lw, lx, ly, lz = 1.0, 0.0, 0.0, 0.0
    for i in range(accel.shape[0]):
        fx, fy, fz = accel[i, 0], accel[i, 1], accel[i, 2]
        ok, fn = _vec_norm_ok(fx, fy, fz, MIN_ACCEL, MAX_ACCEL)
        if not ok:
            out[i, 0] = out[i, 1] = out[i, 2] = out[i, 3] = np.nan
            continue
        mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
        mag_ok = _vec_norm_ok(mx, my, mz, MIN_MAG, MAX_MAG)[0]
        if mag_ok:
            mag_ok = _mag_usable(fx, fy, fz, mx, my, mz)
        q = _reference(method, fx, fy, fz, fn, mx, my, mz, mag_ok, lw, lx, ly, lz, decl, cdh, sdh)
        # keep consecutive rows in one hemisphere (continuous sign)
        if q[0] * lw + q[1] * lx + q[2] * ly + q[3] * lz < 0.0:
            q = (-q[0], -q[1], -q[2], -q[3])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = q
        lw, lx, ly, lz = q


def reference_attitude(accel_b, mag_b, *, declination_rad: float = 0.0, method: str = "vector") -> np.ndarray:
    """λ_k for every sample: the attitude ``q_wb`` (N, 4) from accelerometer and magnetometer alone.

    Parameters
    ----------
    accel_b : (N, 3) specific force in m/s², body axes (x forward, y left, z up).
    mag_b : (N, 3) magnetic field in µT, body axes.
    declination_rad : magnetic declination D in rad, east positive.
    method : ``"vector"`` (TRIAD, no singularity) or ``"euler"`` (corrected eqs. (5)–(7)).

    Rows whose specific force is non-finite or zero are NaN; rows whose field is unusable
    keep the heading of the previous row (yaw 0 before the first). Consecutive rows are kept
    in one hemisphere (q and −q are the same attitude).
    """
    from biso_cosim.estimators._base import as_samples

    accel, mag = as_samples(("accel_b", accel_b), ("mag_b", mag_b))
    if method not in REFERENCE_METHODS:
        raise ValueError(f"method must be one of {REFERENCE_METHODS}, got {method!r}")
    decl = float(declination_rad)
    if not math.isfinite(decl):
        raise ValueError(f"declination_rad must be finite, got {declination_rad!r}")
    out = np.empty((accel.shape[0], 4))
    _batch_reference(REFERENCE_METHODS.index(method), accel, mag, decl, out)
    return out
