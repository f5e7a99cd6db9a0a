"""Jitted kernels of the GNSS-aided estimators (``gnss_aided.py`` documents the method).

Arrays in, arrays out, never a user error: the wrapper in ``gnss_aided.py`` validates,
allocates and calls ``_gnss_batch``. Layouts of the coefficient and state arrays are built
once here from named parts, so the kernel's indices and the ``State`` names agree.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators._base import layout_offsets
from biso_cosim.estimators._kernels import _input_checks
from biso_cosim.estimators.reference import _mag_usable, _ref_vector
from biso_cosim.sensors.gnss import FIX_LAYOUT
from biso_cosim.frames import (
    _gost_angles_from_lambda,
    _gost_lambda_from_angles,
    _gost_lambda_from_q,
    _mat_from_q,
    _q_from_gost_lambda,
    _qexp_rotvec,
    _qmul,
    _qnormalize,
    _qrot,
)

MODE_COMPLEMENTARY, MODE_KALMAN = 0, 1
UNAIDED_COAST, UNAIDED_GRAVITY, UNAIDED_GYRO = 0, 1, 2
COUPLING_NONE, COUPLING_MAGNETIC = 0, 1

GNSS_UPDATE, GNSS_UNAIDED, GNSS_REJECTED = fl.GNSS_UPDATE, fl.GNSS_UNAIDED, fl.GNSS_REJECTED

# What happened to a fix or an unaided reference (column ``kind`` of the updates record).
KIND_GNSS, KIND_UNAIDED, KIND_ANCHOR, KIND_NONFINITE, KIND_TOO_OLD, KIND_GATE, KIND_GEOMETRY = range(7)
KIND_NAMES = ("gnss", "unaided", "anchor", "rejected_nonfinite", "rejected_too_old", "rejected_gate",
              "rejected_geometry")

MAX_FIX_AGE_S = 1.0
"""Oldest time of validity a fix may have when it arrives (the ring of past sums covers this)."""

PENDING_CAPACITY = 16
"""Fixes that may wait, between calls, for the IMU sample at which they arrive."""

# fix rows handed to the kernel: t_s, t_arrival_s, v_e, v_n, v_u, status (1 usable, 0 not finite)
FIX_COLS = 6
# updates record rows: t_s, t_applied_s, kind, interval_s, innovation (3), innovation σ (3), nis,
# correction of roll and pitch (2)
UPD_COLS = 13
RING_COLS = 10  # t, ΣĈf h (3), ΣN h (6: N_ϑ then N_γ)


# The coefficient array (``gnss_aided.gnss_coefficients`` fills it) and the state array; each
# index below is a plain module constant (numba freezes globals when it compiles).
COEF = layout_offsets((
    ("mode", 1), ("h", 1), ("t0", 1), ("g", 1), ("inv_t1", 1), ("inv_t1u", 1), ("k_head", 1), ("decl", 1),
    ("cdh", 1), ("sdh", 1), ("soft_inv", 9), ("hard", 3), ("window", 1), ("max_interval", 1),
    ("unaided", 1), ("coast", 1), ("coupling", 1), ("cos_limit", 1), ("q_gyro", 1), ("inv_tau_d", 1),
    ("q_drift", 1), ("decay", 1), ("p0_angle", 1), ("p0_drift", 1), ("vel_var", 3), ("accel_nd2", 1),
    ("floor2", 1), ("head_var", 1), ("unaided_var", 1), ("gate", 1), ("ring_len", 1), ("delay", 1),
    ("gyro_limit", 1), ("accel_limit", 1)))
C_MODE, C_H, C_T0, C_G = COEF["mode"], COEF["h"], COEF["t0"], COEF["g"]
C_INV_T1, C_INV_T1U, C_KHEAD = COEF["inv_t1"], COEF["inv_t1u"], COEF["k_head"]
C_DECL, C_CDH, C_SDH = COEF["decl"], COEF["cdh"], COEF["sdh"]
C_SOFT, C_HARD = COEF["soft_inv"], COEF["hard"]
C_WINDOW, C_MAXINT, C_UNAIDED, C_COAST = COEF["window"], COEF["max_interval"], COEF["unaided"], COEF["coast"]
C_COUPLING, C_COSLIM = COEF["coupling"], COEF["cos_limit"]
C_QG, C_INVTD, C_QD, C_DECAY = COEF["q_gyro"], COEF["inv_tau_d"], COEF["q_drift"], COEF["decay"]
C_P0A, C_P0D, C_VV, C_NA2 = COEF["p0_angle"], COEF["p0_drift"], COEF["vel_var"], COEF["accel_nd2"]
C_FL2, C_HV, C_UV, C_GATE = COEF["floor2"], COEF["head_var"], COEF["unaided_var"], COEF["gate"]
C_RING, C_DELAY = COEF["ring_len"], COEF["delay"]
C_GLIM, C_ALIM = COEF["gyro_limit"], COEF["accel_limit"]
C_SIZE = COEF["_size"]

STATE_PARTS = (
    ("initialized", 1), ("lam", 4), ("sample_index", 1), ("gyro_hold", 3), ("accel_hold", 3),
    ("gyro_bias_b", 3), ("covariance", 25), ("mag_w", 3), ("mag_w_ok", 1), ("sums", 9),
    ("anchor_has", 1), ("anchor_t", 1), ("anchor_v", 3), ("anchor_sums", 9),
    ("unaided_has", 1), ("unaided_t", 1), ("unaided_sums", 9),
    ("last_aided_t", 1), ("last_fix_t", 1), ("ring_head", 1), ("ring_count", 1),
    ("pending_count", 1), ("pending", FIX_COLS * PENDING_CAPACITY))
"""Named parts of the state (``State`` names); the ring of past sums follows them."""
STATE = layout_offsets(STATE_PARTS)
S_INIT, S_LAM, S_N = STATE["initialized"], STATE["lam"], STATE["sample_index"]
S_GYRO, S_ACC, S_BIAS, S_P = STATE["gyro_hold"], STATE["accel_hold"], STATE["gyro_bias_b"], STATE["covariance"]
S_MAGW, S_MAGOK, S_SUM = STATE["mag_w"], STATE["mag_w_ok"], STATE["sums"]
S_A_HAS, S_A_T, S_A_V, S_A_SUM = STATE["anchor_has"], STATE["anchor_t"], STATE["anchor_v"], STATE["anchor_sums"]
S_U_HAS, S_U_T, S_U_SUM = STATE["unaided_has"], STATE["unaided_t"], STATE["unaided_sums"]
S_LAST_AIDED, S_LAST_FIX = STATE["last_aided_t"], STATE["last_fix_t"]
S_HEAD, S_COUNT = STATE["ring_head"], STATE["ring_count"]
S_PEND_N, S_PEND = STATE["pending_count"], STATE["pending"]
S_SIZE = STATE["_size"]

NEVER = -1.0e300  # "long ago" for times of the last fix


# --------------------------------------------------------------------------------------
# Geometry: the paper's angles from the attitude, the N matrix, the magnetic heading
# --------------------------------------------------------------------------------------


@jit
def _tilt_terms(r20, r21, r22, cos_limit):
    """(sinγ, cosγ, tanϑ, cosϑ) of the paper's roll γ and pitch ϑ, trig-free from the last row
    of mat_wb (ϑ = −pitch, γ = roll; sinϑ = r20, sinγ cosϑ = r21, cosγ cosϑ = r22); cosϑ is
    held at ``cos_limit`` or above (the Euler-angle model is singular at ϑ = ±90°)."""
    cth = math.sqrt(r21 * r21 + r22 * r22)
    if cth < 1e-12:
        sg, cg = 0.0, 1.0
    else:
        sg, cg = r21 / cth, r22 / cth
    cth = max(cth, cos_limit)
    return sg, cg, r20 / cth, cth


@jit
def _n_columns(r00, r10, r20, fx, fy, fz):
    """N = ∂(Ĉ f)/∂(ϑ, γ) in ENU (two 3-vectors) for the world specific force f (ENU).

    ∂/∂ϑ rotates about the horizontal axis to the right of the heading, a = (fwd_N, −fwd_E, 0)/|·|;
    ∂/∂γ about the body's forward axis x_b = (r00, r10, r20): N_ϑ = a × f, N_γ = x_b × f.
    """
    hn = math.sqrt(r00 * r00 + r10 * r10)
    if hn > 1e-12:
        ax, ay = r10 / hn, -r00 / hn
    else:
        ax, ay = 0.0, 0.0
    return (ay * fz, -ax * fz, ax * fy - ay * fx,
            r10 * fz - r20 * fy, r20 * fx - r00 * fz, r00 * fy - r10 * fx)


@jit
def _mag_world(c, q0, q1, q2, q3, mx, my, mz):
    """The field (ENU) from a magnetometer sample after hard- and soft-iron compensation,
    T = (E + M)⁻¹ (T_c − P) (Ibrahim & Lukyanov eq. (5)), rotated by the estimate."""
    dx, dy, dz = mx - c[C_HARD], my - c[C_HARD + 1], mz - c[C_HARD + 2]
    s = C_SOFT
    bx = c[s] * dx + c[s + 1] * dy + c[s + 2] * dz
    by = c[s + 3] * dx + c[s + 4] * dy + c[s + 5] * dz
    bz = c[s + 6] * dx + c[s + 7] * dy + c[s + 8] * dz
    return _qrot(q0, q1, q2, q3, bx, by, bz)


@jit
def _wrap_pi(a):
    """Angle wrapped into [−π, π) (frames._wrap uses math.fmod, which numba does not compile)."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@jit
def _heading_coupling(r00, r10, r20, be, bn, bu):
    """(P1, P2): heading error of the magnetic heading per unit pitch and roll error,
    δα = (B_N δB_E − B_E δB_N)/B_h² for δB = a × B (pitch) and x_b × B (roll)."""
    bh2 = be * be + bn * bn
    if bh2 < 1e-12:
        return 0.0, 0.0
    n = _n_columns(r00, r10, r20, be, bn, bu)
    return (bn * n[0] - be * n[1]) / bh2, (bn * n[3] - be * n[4]) / bh2


# --------------------------------------------------------------------------------------
# Small linear algebra
# --------------------------------------------------------------------------------------


@jit
def _inv3(m, out):
    """Inverse of a 3×3 matrix by the adjugate; returns the determinant (0: not inverted)."""
    a, b, cc = m[0, 0], m[0, 1], m[0, 2]
    d, e, f = m[1, 0], m[1, 1], m[1, 2]
    g, h, i = m[2, 0], m[2, 1], m[2, 2]
    c0, c1, c2 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c0 + b * c1 + cc * c2
    if det == 0.0 or not math.isfinite(det):
        return 0.0
    r = 1.0 / det
    out[0, 0], out[0, 1], out[0, 2] = c0 * r, (cc * h - b * i) * r, (b * f - cc * e) * r
    out[1, 0], out[1, 1], out[1, 2] = c1 * r, (a * i - cc * g) * r, (cc * d - a * f) * r
    out[2, 0], out[2, 1], out[2, 2] = c2 * r, (b * g - a * h) * r, (a * e - b * d) * r
    return det


@jit
def _matmul(a, b):
    """a @ b for small matrices (numba's @ needs SciPy's BLAS, which is not a run-time dependency)."""
    out = np.zeros((a.shape[0], b.shape[1]))
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            s = 0.0
            for m in range(a.shape[1]):
                s += a[i, m] * b[m, j]
            out[i, j] = s
    return out


@jit
def _error_model(sg, cg, tth, cth, wx, wy, wz):
    """The coefficients (A1, A2, A3, B1, B2, B3, B4) of eq. (4) linearised (docs/design.md §6):
    Δϑ̇ = A1Δγ + A2Δω_y + A3Δω_z, Δγ̇ = B1Δϑ + B2Δγ + Δω_x + B3Δω_y + B4Δω_z, for the
    rate ω = (ω_x, ω_y, ω_z) in the paper's body axes (x forward, y up, z right)."""
    a1 = wy * cg - wz * sg
    b1 = -a1 / (cth * cth)
    b2 = tth * (wy * sg + wz * cg)
    return a1, sg, cg, b1, b2, -tth * cg, tth * sg


@jit
def _propagate_covariance(c, p, work, a1, a2, a3, b1, b2, b3, b4):
    """P ← Φ P Φᵀ + Q_d over one sample interval h, second order in h:
    Φ = I + F h + ½F²h², Q_d = Q h + ½(F Q + Q Fᵀ) h² (Van Loan's integral to second order).

    F = [[F_a, F_b], [0, −I/τ]] with F_a = [[0, A1], [B1, B2]], F_b = [[0, A2, A3], [1, B3, B4]];
    Q = diag(Q_a, q_d I) with Q_a = N_g² G_a G_aᵀ, G_a = [[0, A2, A3], [1, B3, B4]]. The blocks
    are multiplied out (about a fifth of the work of dense 5×5 products); ``p`` is updated in place.
    """
    h = c[C_H]
    hh = 0.5 * h * h
    r = c[C_INVTD]
    # Φ_a = I + F_a h + ½F_a²h²; Φ_ab = F_b h + ½(F_a F_b − F_b/τ)h²; Φ_bb = d·I
    pa = work[0]
    pa[0, 0] = 1.0 + a1 * b1 * hh
    pa[0, 1] = a1 * h + a1 * b2 * hh
    pa[1, 0] = b1 * h + b2 * b1 * hh
    pa[1, 1] = 1.0 + b2 * h + (b1 * a1 + b2 * b2) * hh
    fb = work[1]
    fb[0, 0], fb[0, 1], fb[0, 2] = 0.0, a2, a3
    fb[1, 0], fb[1, 1], fb[1, 2] = 1.0, b3, b4
    pab = work[2]
    for j in range(3):
        pab[0, j] = fb[0, j] * h + (a1 * fb[1, j] - r * fb[0, j]) * hh
        pab[1, j] = fb[1, j] * h + (b1 * fb[0, j] + b2 * fb[1, j] - r * fb[1, j]) * hh
    d = 1.0 - r * h + r * r * hh
    # blocks of P: A = P_aa (2×2), B = P_ab (2×3), C = P_bb (3×3)
    u = work[3]  # U = Φ_a A + Φ_ab Bᵀ (2×2), V = Φ_a B + Φ_ab C (2×3) in columns 2..4
    for i in range(2):
        for j in range(2):
            s = pa[i, 0] * p[0, j] + pa[i, 1] * p[1, j]
            for m in range(3):
                s += pab[i, m] * p[j, 2 + m]
            u[i, j] = s
        for j in range(3):
            s = pa[i, 0] * p[0, 2 + j] + pa[i, 1] * p[1, 2 + j]
            for m in range(3):
                s += pab[i, m] * p[2 + m, 2 + j]
            u[i, 2 + j] = s
    # continuous Q_a, and q_d
    qg, qd = c[C_QG], c[C_QD]
    q00 = qg * (a2 * a2 + a3 * a3)
    q01 = qg * (a2 * b3 + a3 * b4)
    q11 = qg * (1.0 + b3 * b3 + b4 * b4)
    # Q_d,aa = Q_a h + ½(F_a Q_a + Q_a F_aᵀ)h²: F_a Q_a = [[A1 q01, A1 q11], [B1 q00 + B2 q01, B1 q01 + B2 q11]]
    fq00, fq01 = a1 * q01, a1 * q11
    fq10, fq11 = b1 * q00 + b2 * q01, b1 * q01 + b2 * q11
    qaa00 = q00 * h + (fq00 + fq00) * hh
    qaa01 = q01 * h + (fq01 + fq10) * hh
    qaa11 = q11 * h + (fq11 + fq11) * hh
    # P' blocks: aa = U Φ_aᵀ + V Φ_abᵀ, ab = d V, bb = d² C (+ Q_d)
    for i in range(2):
        for j in range(i, 2):
            s = u[i, 0] * pa[j, 0] + u[i, 1] * pa[j, 1]
            for m in range(3):
                s += u[i, 2 + m] * pab[j, m]
            p[i, j] = s
    p[0, 0] += qaa00
    p[0, 1] += qaa01
    p[1, 1] += qaa11
    p[1, 0] = p[0, 1]
    for i in range(2):
        for j in range(3):
            v = d * u[i, 2 + j] + qd * fb[i, j] * hh  # Q_d,ab = ½ q_d F_b h²
            p[i, 2 + j] = v
            p[2 + j, i] = v
    d2 = d * d
    for i in range(3):
        for j in range(3):
            p[2 + i, 2 + j] *= d2
        p[2 + i, 2 + i] += qd * h - r * qd * h * h  # Q_d,bb = q_d h − q_d h²/τ


# --------------------------------------------------------------------------------------
# Sums and the ring of past sums
# --------------------------------------------------------------------------------------


@jit
def _ring_push(c, st, ring, t):
    n = int(c[C_RING])
    head = (int(st[S_HEAD]) + 1) % n
    ring[head, 0] = t
    for a in range(9):
        ring[head, 1 + a] = st[S_SUM + a]
    st[S_HEAD] = head
    st[S_COUNT] = min(st[S_COUNT] + 1.0, float(n))


@jit
def _ring_at(c, st, ring, t, out):
    """Sums at time t, interpolated linearly between ring entries; False if t is not covered."""
    n = int(c[C_RING])
    count = int(st[S_COUNT])
    head = int(st[S_HEAD])
    if count == 0:
        return False
    newest = ring[head]
    if t > newest[0] + c[C_DELAY] + 1e-9:
        return False
    if t >= newest[0]:  # (only beyond it by less than the IMU delay: held)
        for a in range(9):
            out[a] = newest[1 + a]
        return True
    later = head
    for k in range(1, count):
        idx = (head - k) % n
        if ring[idx, 0] <= t:
            u = (t - ring[idx, 0]) / (ring[later, 0] - ring[idx, 0])
            for a in range(9):
                out[a] = ring[idx, 1 + a] + u * (ring[later, 1 + a] - ring[idx, 1 + a])
            return True
        later = idx
    return False


@jit
def _adjust_sums(c, st, ring, dth, dga):
    """After a tilt correction (dϑ, dγ), re-express every stored sum of Ĉf as if it had been
    computed with the corrected attitude: S ← S + (ΣN − ΣN_now)·δ (linear in δ), so that
    later differences of sums see one attitude error only."""
    nt0, nt1, nt2 = st[S_SUM + 3], st[S_SUM + 4], st[S_SUM + 5]
    ng0, ng1, ng2 = st[S_SUM + 6], st[S_SUM + 7], st[S_SUM + 8]
    n = int(c[C_RING])
    head = int(st[S_HEAD])
    for k in range(int(st[S_COUNT])):
        e = ring[(head - k) % n]
        e[1] += (e[4] - nt0) * dth + (e[7] - ng0) * dga
        e[2] += (e[5] - nt1) * dth + (e[8] - ng1) * dga
        e[3] += (e[6] - nt2) * dth + (e[9] - ng2) * dga
    for base in (S_A_SUM, S_U_SUM):
        st[base] += (st[base + 3] - nt0) * dth + (st[base + 6] - ng0) * dga
        st[base + 1] += (st[base + 4] - nt1) * dth + (st[base + 7] - ng1) * dga
        st[base + 2] += (st[base + 5] - nt2) * dth + (st[base + 8] - ng2) * dga


# --------------------------------------------------------------------------------------
# Corrections
# --------------------------------------------------------------------------------------


@jit
def _correct_tilt(st, dth, dga):
    """ϑ ← ϑ + dϑ, γ ← γ + dγ on the paper's angles of the attitude (heading kept)."""
    l0, l1, l2, l3 = _gost_lambda_from_q(st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3])
    psi, th, ga = _gost_angles_from_lambda(l0, l1, l2, l3)
    k = _gost_lambda_from_angles(psi, th + dth, ga + dga)
    q = _q_from_gost_lambda(k[0], k[1], k[2], k[3])
    if q[0] * st[S_LAM] + q[1] * st[S_LAM + 1] + q[2] * st[S_LAM + 2] + q[3] * st[S_LAM + 3] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3] = _qnormalize(q[0], q[1], q[2], q[3])


@jit
def _measurement(c, st, t_span, z0, z1, z2, nsum, upd, row, kind, t_s, t_now):
    """One measurement over a window of length t_span: z = ΔA (ENU, m/s²), the window's N
    (from the difference of ΣN, ``nsum``). Applies the correction of the variant; writes the
    update row; returns the kind actually recorded."""
    inv = 1.0 / t_span
    n0, n1, n2 = nsum[0] * inv, nsum[1] * inv, nsum[2] * inv  # N_ϑ
    g0, g1, g2 = nsum[3] * inv, nsum[4] * inv, nsum[5] * inv  # N_γ
    fe, fn, fu = nsum[6] * inv, nsum[7] * inv, nsum[8] * inv  # mean Ĉf over the window
    u = upd[row]
    u[0], u[1], u[3] = t_s, t_now, t_span
    u[4], u[5], u[6] = z0, z1, z2
    for a in range(7, UPD_COLS):
        u[a] = np.nan
    q0, q1, q2, q3 = st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3]
    r = _mat_from_q(q0, q1, q2, q3)
    cth = math.sqrt(r[7] * r[7] + r[8] * r[8])
    if cth < c[C_COSLIM] or fe * fe + fn * fn + fu * fu < 1.0:
        u[2] = KIND_GEOMETRY
        return KIND_GEOMETRY
    # heading: N0 = ∂(Ĉf)/∂ψ = up × f (rotation about Up, ψ counter-clockwise)
    h0, h1 = -fn, fe
    if c[C_COUPLING] == COUPLING_MAGNETIC and st[S_MAGOK] != 0.0:
        p1, p2 = _heading_coupling(r[0], r[3], r[6], st[S_MAGW], st[S_MAGW + 1], st[S_MAGW + 2])
        n0, n1 = n0 + h0 * p1, n1 + h1 * p1
        g0, g1 = g0 + h0 * p2, g1 + h1 * p2
    if c[C_MODE] == MODE_COMPLEMENTARY:
        # eq. (7): Δ̂ = −M z, M = (NᵀN)⁻¹Nᵀ; first-order loop with T1 over the window
        a11 = n0 * n0 + n1 * n1 + n2 * n2
        a12 = n0 * g0 + n1 * g1 + n2 * g2
        a22 = g0 * g0 + g1 * g1 + g2 * g2
        det = a11 * a22 - a12 * a12
        if det < 1e-6 * (a11 + a22) * (a11 + a22):
            u[2] = KIND_GEOMETRY
            return KIND_GEOMETRY
        b1 = n0 * z0 + n1 * z1 + n2 * z2
        b2 = g0 * z0 + g1 * z1 + g2 * z2
        e_th = -(a22 * b1 - a12 * b2) / det
        e_ga = -(a11 * b2 - a12 * b1) / det
        inv_t = c[C_INV_T1] if kind == KIND_GNSS else c[C_INV_T1U]
        k = 1.0 - math.exp(-t_span * inv_t)
        dth, dga = -k * e_th, -k * e_ga
    else:
        dth, dga = _kalman_update(c, st, t_span, z0, z1, z2, n0, n1, n2, g0, g1, g2, h0, h1, kind, u)
        if not math.isfinite(dth):
            u[2] = KIND_GATE
            return KIND_GATE
    u[2] = kind
    u[11], u[12] = dga, -dth  # roll = γ, pitch = −ϑ
    _correct_tilt(st, dth, dga)
    return kind


@jit
def _kalman_update(c, st, t_span, z0, z1, z2, n0, n1, n2, g0, g1, g2, h0, h1, kind, u):
    """Closed-loop update of the five-state filter with H = [−N | 0]; returns the tilt
    correction (NaN, NaN when the normalised innovation exceeds the gate)."""
    p = np.empty((5, 5))
    for i in range(5):
        for j in range(5):
            p[i, j] = st[S_P + 5 * i + j]
    hm = np.zeros((3, 5))
    hm[0, 0], hm[1, 0], hm[2, 0] = -n0, -n1, -n2
    hm[0, 1], hm[1, 1], hm[2, 1] = -g0, -g1, -g2
    # R: GNSS velocity difference and accelerometer white noise over the window, a floor,
    # and (without the coupling) the heading error seen through N0 = up × f
    rm = np.zeros((3, 3))
    if kind == KIND_GNSS:
        for a in range(3):
            rm[a, a] = 2.0 * c[C_VV + a] / (t_span * t_span)
    else:
        for a in range(3):
            rm[a, a] = c[C_UV]
    for a in range(3):
        rm[a, a] += c[C_NA2] / t_span + c[C_FL2]
    if c[C_COUPLING] == COUPLING_NONE:
        hv = c[C_HV]
        rm[0, 0] += hv * h0 * h0
        rm[0, 1] += hv * h0 * h1
        rm[1, 0] += hv * h0 * h1
        rm[1, 1] += hv * h1 * h1
    pht = _matmul(p, hm.T)  # P Hᵀ (5, 3)
    s = _matmul(hm, pht)
    for i in range(3):
        for j in range(3):
            s[i, j] += rm[i, j]
    s_inv = np.empty((3, 3))
    if _inv3(s, s_inv) <= 0.0:
        return np.nan, np.nan
    nis = 0.0
    z = (z0, z1, z2)
    for i in range(3):
        for j in range(3):
            nis += z[i] * s_inv[i, j] * z[j]
    u[7], u[8], u[9], u[10] = math.sqrt(s[0, 0]), math.sqrt(s[1, 1]), math.sqrt(s[2, 2]), nis
    if nis > c[C_GATE]:
        return np.nan, np.nan
    k = _matmul(pht, s_inv)  # (5, 3)
    if kind == KIND_UNAIDED:
        # the gravity reference must not teach the drifts the vehicle's accelerations: tilt only
        # (a suboptimal gain; the Joseph form keeps P right for any gain)
        for i in range(2, 5):
            for j in range(3):
                k[i, j] = 0.0
    x = np.zeros(5)
    for i in range(5):
        x[i] = k[i, 0] * z0 + k[i, 1] * z1 + k[i, 2] * z2
    # Joseph form: P = (I − KH) P (I − KH)ᵀ + K R Kᵀ
    ikh = _matmul(k, hm)
    for i in range(5):
        for j in range(5):
            ikh[i, j] = (1.0 if i == j else 0.0) - ikh[i, j]
    p = _matmul(_matmul(ikh, p), ikh.T)
    krk = _matmul(_matmul(k, rm), k.T)
    for i in range(5):
        for j in range(5):
            st[S_P + 5 * i + j] = 0.5 * (p[i, j] + p[j, i] + krk[i, j] + krk[j, i])
    # drift states are in the paper's body axes (x, up, right); ours are (x, left, up)
    st[S_BIAS] += x[2]
    st[S_BIAS + 1] -= x[4]
    st[S_BIAS + 2] += x[3]
    return -x[0], -x[1]


# --------------------------------------------------------------------------------------
# The step
# --------------------------------------------------------------------------------------


@jit
def _init_covariance(c, st):
    for i in range(25):
        st[S_P + i] = 0.0
    st[S_P], st[S_P + 6] = c[C_P0A], c[C_P0A]
    st[S_P + 12], st[S_P + 18], st[S_P + 24] = c[C_P0D], c[C_P0D], c[C_P0D]


@jit
def _reject(upd, row, ts, t_now, kind):
    """Record a fix that is not used (no innovation); returns the rows written (1)."""
    u = upd[min(row, upd.shape[0] - 1)]
    u[0], u[1], u[2] = ts, t_now, kind
    for a in range(3, UPD_COLS):
        u[a] = np.nan
    return 1


@jit
def _process_fix(c, st, ring, fx, upd, row, t_now, sums):
    """Use one fix (row of ``fx``) at time t_now; returns (flags, rows written)."""
    ts = fx[0]
    row = min(row, upd.shape[0] - 1)  # (the wrapper sizes upd; never write past it)
    if fx[5] == 0.0:
        return GNSS_REJECTED, _reject(upd, row, ts, t_now, KIND_NONFINITE)
    if not _ring_at(c, st, ring, ts, sums):
        return GNSS_REJECTED, _reject(upd, row, ts, t_now, KIND_TOO_OLD)
    st[S_LAST_AIDED] = t_now
    st[S_U_HAS] = 0.0
    flags = 0
    written = 0
    move_anchor = True
    dt = ts - st[S_A_T]
    if st[S_A_HAS] != 0.0 and dt <= c[C_MAXINT]:
        if dt < c[C_WINDOW] - 1e-9:
            return 0, 0  # the window is not complete: wait for a later fix
        g = c[C_G]
        inv = 1.0 / dt
        z0 = (fx[2] - st[S_A_V]) * inv - (sums[0] - st[S_A_SUM]) * inv
        z1 = (fx[3] - st[S_A_V + 1]) * inv - (sums[1] - st[S_A_SUM + 1]) * inv
        z2 = (fx[4] - st[S_A_V + 2]) * inv + g - (sums[2] - st[S_A_SUM + 2]) * inv
        nsum = np.empty(9)
        for a in range(6):
            nsum[a] = sums[3 + a] - st[S_A_SUM + 3 + a]
        for a in range(3):
            nsum[6 + a] = sums[a] - st[S_A_SUM + a]
        kind = _measurement(c, st, dt, z0, z1, z2, nsum, upd, row, KIND_GNSS, ts, t_now)
        written = 1
        if kind == KIND_GNSS:
            flags = GNSS_UPDATE
        else:
            flags = GNSS_REJECTED
            move_anchor = kind != KIND_GATE  # an outlier must not become the next anchor
    else:
        written = _reject(upd, row, ts, t_now, KIND_ANCHOR)
    if move_anchor:
        st[S_A_HAS], st[S_A_T] = 1.0, ts
        st[S_A_V], st[S_A_V + 1], st[S_A_V + 2] = fx[2], fx[3], fx[4]
        for a in range(9):
            st[S_A_SUM + a] = sums[a]
    if flags == GNSS_UPDATE:
        u = upd[row]
        _adjust_sums(c, st, ring, -u[12], u[11])
    return flags, written


@jit
def _unaided(c, st, ring, upd, row, t):
    """Without GNSS for longer than max_interval: the gravity reference (A_GNSS = 0) over
    windows of the same length, with T1_unaided or the unaided noise (at once with
    'gravity', after coasting on the gyro for coast_s with 'coast', never with 'gyro');
    returns rows written."""
    policy = c[C_UNAIDED]
    if policy == UNAIDED_GYRO or (policy == UNAIDED_COAST and t - st[S_LAST_AIDED] <= c[C_COAST]):
        st[S_U_HAS] = 0.0
        return 0
    if st[S_U_HAS] == 0.0:
        st[S_U_HAS], st[S_U_T] = 1.0, t
        for a in range(9):
            st[S_U_SUM + a] = st[S_SUM + a]
        return 0
    dt = t - st[S_U_T]
    if dt < c[C_WINDOW] - 1e-9:
        return 0
    row = min(row, upd.shape[0] - 1)
    inv = 1.0 / dt
    nsum = np.empty(9)
    for a in range(6):
        nsum[a] = st[S_SUM + 3 + a] - st[S_U_SUM + 3 + a]
    for a in range(3):
        nsum[6 + a] = st[S_SUM + a] - st[S_U_SUM + a]
    z0, z1, z2 = -nsum[6] * inv, -nsum[7] * inv, c[C_G] - nsum[8] * inv
    kind = _measurement(c, st, dt, z0, z1, z2, nsum, upd, row, KIND_UNAIDED, t, t)
    st[S_U_T] = t
    for a in range(9):
        st[S_U_SUM + a] = st[S_SUM + a]
    if kind == KIND_UNAIDED:
        u = upd[row]
        _adjust_sums(c, st, ring, -u[12], u[11])
    return 1


@jit
def _step(c, st, ring, work, sums, gx, gy, gz, ax, ay, az, mx, my, mz, imu_flags, fx, ptr, upd, row):
    """Advance by one IMU sample; returns (flags, next fix index, next update row)."""
    # the package's per-sample policy (_kernels.py): held gyro, saturation, flags; mag_ok needs a
    # usable accel too
    flags, gx, gy, gz, acc_ok, f2, mag_ok, _, _, _, _ = _input_checks(
        gx, gy, gz, ax, ay, az, mx, my, mz, st[S_GYRO], st[S_GYRO + 1], st[S_GYRO + 2], imu_flags,
        c[C_GLIM], c[C_ALIM])
    st[S_GYRO], st[S_GYRO + 1], st[S_GYRO + 2] = gx, gy, gz
    fnorm = math.sqrt(f2)
    if acc_ok:
        st[S_ACC], st[S_ACC + 1], st[S_ACC + 2] = ax, ay, az
    else:  # the last valid sample stands in for the sums
        ax, ay, az = st[S_ACC], st[S_ACC + 1], st[S_ACC + 2]
    h = c[C_H]
    t = c[C_T0] + st[S_N] * h
    st[S_N] += 1.0
    init = st[S_INIT]
    fresh = init != 1.0  # the initialising sample: its attitude is the initial one, no correction
    kalman = c[C_MODE] == MODE_KALMAN
    if init == 0.0 and not acc_ok:
        # nothing to start from yet; fixes that arrive now cannot be placed (rejected, too old)
        while ptr < fx.shape[0] and fx[ptr, 1] <= t + 1e-9:
            row += _reject(upd, row, fx[ptr, 0], t, KIND_TOO_OLD)
            ptr += 1
        return flags | fl.UNINITIALIZED, ptr, row
    if init == 0.0:
        # the first valid sample: tilt from the accelerometer, heading from the compensated field
        m = _mag_world(c, 1.0, 0.0, 0.0, 0.0, mx, my, mz) if mag_ok else (0.0, 0.0, 0.0)
        f_ok = mag_ok and _mag_usable(ax, ay, az, m[0], m[1], m[2])  # (after the iron compensation)
        q = _ref_vector(ax / fnorm, ay / fnorm, az / fnorm, m[0], m[1], m[2], f_ok,
                        1.0, 0.0, 0.0, 0.0, c[C_CDH], c[C_SDH])
        st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3] = q
        st[S_INIT] = 1.0
        _init_covariance(c, st)
    elif init == 2.0:  # q0 from reset(): the attitude at this sample
        st[S_INIT] = 1.0
        _init_covariance(c, st)
    else:
        wx, wy, wz = gx - st[S_BIAS], gy - st[S_BIAS + 1], gz - st[S_BIAS + 2]
        e = _qexp_rotvec(wx * h, wy * h, wz * h)
        q = _qmul(st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3], e[0], e[1], e[2], e[3])
        st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3] = _qnormalize(q[0], q[1], q[2], q[3])
        if kalman:
            r = _mat_from_q(st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3])
            sg, cg, tth, cth = _tilt_terms(r[6], r[7], r[8], c[C_COSLIM])
            # paper body axes: (x forward, y up, z right) = (x, z, −y) of ours
            coef = _error_model(sg, cg, tth, cth, wx, wz, -wy)
            _propagate_covariance(c, st[S_P:S_P + 25].reshape(5, 5), work,
                                  coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6])
            d = c[C_DECAY]
            st[S_BIAS], st[S_BIAS + 1], st[S_BIAS + 2] = d * st[S_BIAS], d * st[S_BIAS + 1], d * st[S_BIAS + 2]
    q0, q1, q2, q3 = st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3]
    # heading, eq. (6) in feedback form: ψ̇ = ψ̇_kinematic + (ψ_m − ψ)/T2
    if mag_ok:
        be, bn, bu = _mag_world(c, q0, q1, q2, q3, mx, my, mz)
        bh2 = be * be + bn * bn
        if bh2 > 1e-6 * (bh2 + bu * bu) and math.isfinite(bh2):
            st[S_MAGW], st[S_MAGW + 1], st[S_MAGW + 2], st[S_MAGOK] = be, bn, bu, 1.0
            dpsi = 0.0 if fresh else c[C_KHEAD] * _wrap_pi(math.atan2(be, bn) - c[C_DECL])
            if dpsi != 0.0:
                e = _qexp_rotvec(0.0, 0.0, dpsi)
                q = _qmul(e[0], e[1], e[2], e[3], q0, q1, q2, q3)
                q0, q1, q2, q3 = _qnormalize(q[0], q[1], q[2], q[3])
                st[S_LAM], st[S_LAM + 1], st[S_LAM + 2], st[S_LAM + 3] = q0, q1, q2, q3
        else:
            mag_ok = False
    if not mag_ok:
        flags |= fl.MAG_INVALID
    # ∫Ĉf dt and ∫N dt by the midpoint rule (sample i stands for (t_i − h/2, t_i + h/2]), in the
    # ring at the time they reach, shifted back by the IMU's delay
    if fresh:  # the start of the first interval, so that a fix of that instant can be placed
        _ring_push(c, st, ring, t - 0.5 * h - c[C_DELAY])
    r = _mat_from_q(q0, q1, q2, q3)
    fe = r[0] * ax + r[1] * ay + r[2] * az
    fn = r[3] * ax + r[4] * ay + r[5] * az
    fu = r[6] * ax + r[7] * ay + r[8] * az
    nc = _n_columns(r[0], r[3], r[6], fe, fn, fu)
    st[S_SUM] += fe * h
    st[S_SUM + 1] += fn * h
    st[S_SUM + 2] += fu * h
    for a in range(6):
        st[S_SUM + 3 + a] += nc[a] * h
    _ring_push(c, st, ring, t + 0.5 * h - c[C_DELAY])
    if fresh:  # fixes that arrive now are used at the next sample
        return flags | (GNSS_UNAIDED if t - st[S_LAST_AIDED] > c[C_MAXINT] else 0), ptr, row
    # fixes that have arrived by now
    while ptr < fx.shape[0] and fx[ptr, 1] <= t + 1e-9:
        add, written = _process_fix(c, st, ring, fx[ptr], upd, row, t, sums)
        flags |= add
        row += written
        ptr += 1
    if t - st[S_LAST_AIDED] > c[C_MAXINT]:
        flags |= GNSS_UNAIDED
        row += _unaided(c, st, ring, upd, row, t)
    return flags, ptr, row


@jit
def _gnss_batch(c, st, gyro, accel, mag, imu_flags, fx, q_out, flags_out, bias_out, sigma_out, upd):
    """``_step`` over every row; fixes ``fx`` (sorted by arrival) are used at their arrival
    sample; those arriving after the last sample wait in the state. Returns update rows.
    The ring of past sums is the tail of the state array; ``imu_flags`` is empty when the
    sensor's flags are not given."""
    has_imu_flags = imu_flags.shape[0] > 0
    ring = st[S_SIZE:].reshape(-1, RING_COLS)
    work = np.zeros((4, 3, 5))
    sums = np.zeros(9)
    ptr, row = 0, 0
    for i in range(gyro.shape[0]):
        f, ptr, row = _step(c, st, ring, work, sums, gyro[i, 0], gyro[i, 1], gyro[i, 2], accel[i, 0], accel[i, 1],
                            accel[i, 2], mag[i, 0], mag[i, 1], mag[i, 2],
                            imu_flags[i] if has_imu_flags else 0, fx, ptr, upd, row)
        flags_out[i] = f
        for j in range(4):
            q_out[i, j] = st[S_LAM + j]
        if bias_out.shape[0]:
            for j in range(3):
                bias_out[i, j] = st[S_BIAS + j]
        if sigma_out.shape[0]:
            sigma_out[i, 0] = math.sqrt(st[S_P + 6])  # roll = γ
            sigma_out[i, 1] = math.sqrt(st[S_P])  # pitch = −ϑ
    left = min(fx.shape[0] - ptr, PENDING_CAPACITY)  # (the wrapper guarantees it; never overrun)
    st[S_PEND_N] = left
    for i in range(left):
        for a in range(FIX_COLS):
            st[S_PEND + FIX_COLS * i + a] = fx[ptr + i, a]
    return row


# ``GnssLoopArrays.counts``: the update rows of the last call, and what stopped it (0: nothing)
LOOP_ROWS, LOOP_FAULT = 0, 1
LOOP_FAULT_STREAM, LOOP_FAULT_WAITING, LOOP_FAULT_UPDATES = 1, 2, 3


@jit
def _loop_fault(arrays, fault, value):
    arrays.counts[LOOP_ROWS] = 0
    arrays.counts[LOOP_FAULT] = fault
    arrays.counts[LOOP_FAULT + 1] = value


@jit
def gnss_loop(arrays, samples):
    """``update`` in the co-simulation's period call (``biso_cosim.loop``): the period's
    samples, the sensor's flags as ``imu_flags`` and the receiver's fixes ``samples.gnss``
    (rows of ``FIX_LAYOUT``) merged with those waiting in the state, as ``_fix_rows`` merges
    them; ``_gnss_batch`` on them with an updates buffer of the size ``update`` gives it, so
    the same numbers bit for bit. ``update``'s refusals the receiver of the loop can meet
    (a fix that does not continue the stream, too many fixes waiting) stop the call before
    anything changes and are recorded in ``counts`` (``loop_estimate`` raises them)."""
    c, st = arrays.coef, arrays.state
    fs = arrays.fs_hz
    k = samples.gyro_b.shape[0]
    gnss = samples.gnss
    m = gnss.shape[0]
    if m and not gnss[0, FIX_LAYOUT.t_s] > st[S_LAST_FIX]:
        _loop_fault(arrays, LOOP_FAULT_STREAM, 0)
        return
    n_pending = int(st[S_PEND_N])
    n_valid = 0
    for j in range(m):
        if gnss[j, FIX_LAYOUT.valid] != 0.0:
            n_valid += 1
    fx = np.empty((n_pending + n_valid, FIX_COLS))
    for i in range(n_pending):
        for a in range(FIX_COLS):
            fx[i, a] = st[S_PEND + FIX_COLS * i + a]
    i = n_pending
    v = FIX_LAYOUT.vel_w
    for j in range(m):
        if gnss[j, FIX_LAYOUT.valid] != 0.0:
            fx[i, 0], fx[i, 1] = gnss[j, FIX_LAYOUT.t_s], gnss[j, FIX_LAYOUT.t_arrival_s]
            finite = True
            for a in range(3):
                fx[i, 2 + a] = gnss[j, v + a]
                finite = finite and math.isfinite(gnss[j, v + a])
            fx[i, 5] = 1.0 if finite else 0.0
            i += 1
    rows = fx.shape[0]
    t_last = c[C_T0] + (st[S_N] + k - 1) / fs
    if rows and (k == 0 or fx[rows - 1, 1] > t_last + 1e-9):
        waiting = rows
        if k:
            waiting = 0
            for i in range(rows):
                if fx[i, 1] > t_last + 1e-9:
                    waiting += 1
        if waiting > PENDING_CAPACITY:
            _loop_fault(arrays, LOOP_FAULT_WAITING, waiting)
            return
    capacity = rows + int(math.ceil(k / (c[C_WINDOW] * fs))) + 2
    if capacity > arrays.updates.shape[0]:
        _loop_fault(arrays, LOOP_FAULT_UPDATES, capacity)
        return
    arrays.counts[LOOP_ROWS] = _gnss_batch(c, st, samples.gyro_b, samples.accel_b, samples.mag_b, samples.imu_flags, fx,
                                           arrays.q_wb[:k], arrays.flags[:k], arrays.gyro_bias_b[:k],
                                           arrays.tilt_sigma_rad[:k], arrays.updates[:capacity])
    arrays.counts[LOOP_FAULT] = 0
    if m:
        st[S_LAST_FIX] = gnss[m - 1, FIX_LAYOUT.t_s]
