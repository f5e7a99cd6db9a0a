"""The reference attitude λ_k from the accelerometer and the magnetometer alone.

Aleshkin et al. (2024) correct the Poisson equation toward λ_k, an attitude computed each
sample from the specific force f and the magnetic field H (their eqs. (5)–(7)). Two
constructions are offered; they give the same quaternion (to rounding) wherever both are
defined:

``"euler"``
    the paper's route, with the corrections of docs/design.md §5: in the paper's body axes
    (x forward, y up, z right) ``ϑ = atan2(f_x, √(f_y² + f_z²))``, ``γ = atan2(−f_z, f_y)``,
    ``ψ = atan2(H_y sinγ + H_z cosγ, H_x cosϑ − (H_y cosγ − H_z sinγ) sinϑ) − D``, then
    eq. (7). The printed (5) (arcsin, needs the horizontal field L) and (6) (sign of γ) are
    replaced; atan2 never returns NaN. Heading is undefined at ϑ = ±90°.
``"vector"``
    singularity-free and trig-free (TRIAD): up = f/|f|, east = (H × up)/|H × up|,
    north = up × east are the rows of the body→world matrix, turned into a quaternion by
    Shepperd's method (run on the unnormalised rows: ``_kernels._q_from_up_east``), then
    rotated by the declination about Up. Defined for every attitude; several times cheaper
    (docs/design.md §9).

Both map the magnetic heading to true heading with the declination D (east positive).
When the magnetometer sample is unusable (non-finite, zero, or parallel to f) the heading
of λ_k is taken from the current estimate, so that only tilt is corrected.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators._kernels import (  # noqa: F401  (the limits are imported from here by other kernels)
    MAG_PARALLEL_SIN,
    MAX_ACCEL,
    MAX_MAG,
    MAX_RATE,
    MIN_ACCEL,
    MIN_MAG,
    _accel_ok,
    _mag_ok,
    _q_from_up_east,
    _rotate_true_north,
)
from biso_cosim.frames import (
    _gost_angles_from_lambda,
    _gost_lambda_from_angles,
    _gost_lambda_from_q,
    _q_from_gost_lambda,
    _qrot_inv,
)

__all__ = ["reference_attitude", "REFERENCE_METHODS"]

REFERENCE_METHODS = ("vector", "euler")
"""Names of the λ_k constructions; the kernel takes the index into this tuple."""


@jit(inline="always")
def _vec_norm_ok(x, y, z, lo, hi):
    """(ok, norm): finite and lo < |v| < hi."""
    n2 = x * x + y * y + z * z
    if not math.isfinite(n2):
        return False, 0.0
    n = math.sqrt(n2)
    return (n > lo) and (n < hi), n


@jit(inline="always")
def _vec_ok(x, y, z, lo, hi):
    """Finite and lo < |v| < hi, without the square root."""
    n2 = x * x + y * y + z * z
    return math.isfinite(n2) and n2 > lo * lo and n2 < hi * hi


@jit(inline="always")
def _mag_usable(fx, fy, fz, mx, my, mz):
    """Whether the field (finite, non-zero) has a part across f (finite, non-zero): a heading."""
    cx = my * fz - mz * fy
    cy = mz * fx - mx * fz
    cz = mx * fy - my * fx
    m2 = mx * mx + my * my + mz * mz
    f2 = fx * fx + fy * fy + fz * fz
    return cx * cx + cy * cy + cz * cz > (MAG_PARALLEL_SIN * MAG_PARALLEL_SIN) * m2 * f2


@jit(inline="always")
def _east_from_estimate(fx, fy, fz, f2, lw, lx, ly, lz):
    """East (unnormalised, ⊥ f) of the estimate l (any non-zero quaternion): its north in body
    axes crossed with up; where the estimate's north is (nearly) along f, its east projected
    on the plane across f instead."""
    nx, ny, nz = _qrot_inv(lw, lx, ly, lz, 0.0, 1.0, 0.0)  # |n| = |l|²
    ex = ny * fz - nz * fy
    ey = nz * fx - nx * fz
    ez = nx * fy - ny * fx
    l2 = lw * lw + lx * lx + ly * ly + lz * lz
    if ex * ex + ey * ey + ez * ez < 0.01 * f2 * l2 * l2:
        ex, ey, ez = _qrot_inv(lw, lx, ly, lz, 1.0, 0.0, 0.0)
        d = (ex * fx + ey * fy + ez * fz) / f2
        ex, ey, ez = ex - d * fx, ey - d * fy, ez - d * fz
    return ex, ey, ez


@jit(inline="always")
def _ref_triad(fx, fy, fz, f2, ex, ey, ez, e2, mag_ok, lw, lx, ly, lz, cdh, sdh):
    """λ_k by TRIAD: up along the specific force f, east along E = m × f (body axes, any
    lengths; |f|², |E|² given), the magnetic attitude turned to true north (cos D/2, sin D/2).
    Without a usable field (``mag_ok`` false) east comes from the estimate l instead."""
    if mag_ok:
        qw, qx, qy, qz = _q_from_up_east(fx, fy, fz, f2, ex, ey, ez, e2)
        return _rotate_true_north(cdh, sdh, qw, qx, qy, qz)
    ex, ey, ez = _east_from_estimate(fx, fy, fz, f2, lw, lx, ly, lz)
    return _q_from_up_east(fx, fy, fz, f2, ex, ey, ez, ex * ex + ey * ey + ez * ez)


@jit(inline="always")
def _ref_vector(ux, uy, uz, mx, my, mz, mag_ok, lw, lx, ly, lz, cdh, sdh):
    """λ_k by TRIAD from the up direction u and the field m (body axes; any lengths).

    ``cdh, sdh`` are cos(D/2), sin(D/2). Without a usable field (``mag_ok`` false) the east
    axis comes from the estimate ``l`` (any non-zero quaternion).
    """
    ex = my * uz - mz * uy
    ey = mz * ux - mx * uz
    ez = mx * uy - my * ux
    return _ref_triad(ux, uy, uz, ux * ux + uy * uy + uz * uz, ex, ey, ez, ex * ex + ey * ey + ez * ez, mag_ok,
                      lw, lx, ly, lz, cdh, sdh)


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


@jit(inline="always")
def _reference(method, fx, fy, fz, f2, ex, ey, ez, e2, mx, my, mz, mag_ok, lw, lx, ly, lz, decl, cdh, sdh):
    """λ_k (unit, q_wb) by ``method`` (index into REFERENCE_METHODS); |f|² = f2 > 0, E = m × f."""
    if method == 0:
        return _ref_triad(fx, fy, fz, f2, ex, ey, ez, e2, mag_ok, lw, lx, ly, lz, cdh, sdh)
    return _ref_euler(fx, fy, fz, mx, my, mz, mag_ok, lw, lx, ly, lz, decl)


@jit
def _batch_reference(method, accel, mag, decl, out):
    """λ_k of every row; rows without a valid accelerometer sample get NaN."""
    cdh, sdh = math.cos(0.5 * decl), math.sin(0.5 * decl)
    lw, lx, ly, lz = 1.0, 0.0, 0.0, 0.0
    for i in range(accel.shape[0]):
        fx, fy, fz = accel[i, 0], accel[i, 1], accel[i, 2]
        ok, f2 = _accel_ok(fx, fy, fz)
        if not ok:
            out[i, 0] = out[i, 1] = out[i, 2] = out[i, 3] = np.nan
            continue
        mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
        ex, ey, ez = my * fz - mz * fy, mz * fx - mx * fz, mx * fy - my * fx
        e2 = ex * ex + ey * ey + ez * ez
        mag_ok, m2 = _mag_ok(mx, my, mz)
        mag_ok = mag_ok and e2 > (MAG_PARALLEL_SIN * MAG_PARALLEL_SIN) * m2 * f2
        q = _reference(method, fx, fy, fz, f2, ex, ey, ez, e2, mx, my, mz, mag_ok, lw, lx, ly, lz, decl, cdh, sdh)
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
