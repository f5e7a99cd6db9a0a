"""Numba kernels of the multiple-integral strapdown algorithms (Litmanovich 2002).

Private: arrays and scalars in, tuples or caller-allocated arrays out, no user errors. The
public wrappers in :mod:`biso_cosim.strapdown.algorithms` and
:mod:`biso_cosim.strapdown.navigator` validate the input and choose the algorithm ids.

Notation (Litmanovich 2002, eq. (1.14)): ``T`` the update interval; for the traditional
algorithms the rows of an increment array are the sub-interval increments ΔΘ_1..ΔΘ_m of
equal length T/m; for the smoothing and invariant algorithms row r−1 holds the r-fold
iterated integral ΔΘ^r over T (ΔΘ^1 = ΔΘ, units rad·s^(r−1)); the same for ΔV.
One-sample algorithms read row 0 only, which is ΔΘ in either form.

Every formula below is the paper's, with the corrections of docs/design.md §7 (re-derived in
exact rational arithmetic in ``tests/test_strapdown_algorithms.py``).
"""

from __future__ import annotations

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.frames import _qexp_rotvec, _qmul, _qnormalize, _qrot

# Algorithm ids. The names, equations and input forms are in algorithms.py (the registry).
CONING_ONE_SAMPLE = 0
CONING_TWO_SAMPLE = 1
CONING_TRADITIONAL3 = 2
CONING_TRADITIONAL3_MILLER = 3
CONING_SMOOTHING = 4
CONING_INVARIANT = 5

SCULLING_TRADITIONAL1 = 0
SCULLING_TRADITIONAL2 = 1
SCULLING_SMOOTHING = 2
SCULLING_INVARIANT_ACCEL1 = 3
SCULLING_INVARIANT_ACCEL0 = 4
SCULLING_INVARIANT_RATE1 = 5
SCULLING_INVARIANT_RATE0 = 6

POSITION_RECTANGLE = 0
POSITION_TRAPEZOID = 1
POSITION_EXACT = 2


# --------------------------------------------------------------------------------------
# 3-vector helpers on tuples
# --------------------------------------------------------------------------------------


@jit
def _row(a, i):
    return a[i, 0], a[i, 1], a[i, 2]


@jit
def _cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


@jit
def _lin(a, u, b, v):
    """a·u + b·v."""
    return (a * u[0] + b * v[0], a * u[1] + b * v[1], a * u[2] + b * v[2])


@jit
def _scale(a, u):
    return a * u[0], a * u[1], a * u[2]


@jit
def _lin3(a, u, b, v, c, w):
    """a·u + b·v + c·w."""
    return (
        a * u[0] + b * v[0] + c * w[0],
        a * u[1] + b * v[1] + c * w[1],
        a * u[2] + b * v[2] + c * w[2],
    )


@jit
def _sum_rows(a):
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for i in range(a.shape[0]):
        sx += a[i, 0]
        sy += a[i, 1]
        sz += a[i, 2]
    return sx, sy, sz


# --------------------------------------------------------------------------------------
# Coning correction δΘ_c, eq. (1.12)
# --------------------------------------------------------------------------------------


@jit
def _coning(algorithm, th, T):
    """δΘ_c of one interval from the increments ``th`` (m, 3) of the algorithm's form."""
    if algorithm == CONING_ONE_SAMPLE:
        return 0.0, 0.0, 0.0
    if algorithm == CONING_TWO_SAMPLE:
        # Classic two-sample algorithm (linear rate model; Miller 1983): (2/3) ΔΘ1 × ΔΘ2.
        return _scale(2.0 / 3.0, _cross(_row(th, 0), _row(th, 1)))
    if algorithm == CONING_TRADITIONAL3 or algorithm == CONING_TRADITIONAL3_MILLER:
        # (2.10): X (ΔΘ1 × ΔΘ3) + Y ΔΘ2 × (ΔΘ3 − ΔΘ1); X, Y = 33/80, 57/80 for the
        # quadratic rate model, 9/20, 27/40 optimised for coning (Miller 1983).
        if algorithm == CONING_TRADITIONAL3:
            x, y = 33.0 / 80.0, 57.0 / 80.0
        else:
            x, y = 9.0 / 20.0, 27.0 / 40.0
        t1, t2, t3 = _row(th, 0), _row(th, 1), _row(th, 2)
        return _lin(x, _cross(t1, t3), y, _cross(t2, _lin(1.0, t3, -1.0, t1)))
    if algorithm == CONING_SMOOTHING:
        # (3.7): (6/T²)(ΔΘ¹ × ΔΘ³) − (3/T) ΔΘ² × ((4/T²) ΔΘ³ − ΔΘ¹)
        t1, t2, t3 = _row(th, 0), _row(th, 1), _row(th, 2)
        inner = _lin(4.0 / (T * T), t3, -1.0, t1)
        return _lin(6.0 / (T * T), _cross(t1, t3), -3.0 / T, _cross(t2, inner))
    # CONING_INVARIANT, (4.8) with the last factor 30/T³ (printed 30/T²):
    # (18/T²)(ΔΘ¹ × ΔΘ³) − (3/(2T)) ΔΘ² × ((44/T²) ΔΘ³ − 3 ΔΘ¹)
    #   − (30/T³)(ΔΘ¹ − (6/T) ΔΘ² + (12/T²) ΔΘ³) × ΔΘ⁴
    t1, t2, t3, t4 = _row(th, 0), _row(th, 1), _row(th, 2), _row(th, 3)
    T2 = T * T
    inner = _lin(44.0 / T2, t3, -3.0, t1)
    c_hat = _lin3(1.0, t1, -6.0 / T, t2, 12.0 / T2, t3)  # (T³/60)·Ĉ_ω of (3.4)
    return _lin3(18.0 / T2, _cross(t1, t3), -1.5 / T, _cross(t2, inner), -30.0 / (T2 * T), _cross(c_hat, t4))


# --------------------------------------------------------------------------------------
# Sculling correction δV_s, eq. (1.8)
# --------------------------------------------------------------------------------------


@jit
def _sculling(algorithm, th, dv, T):
    """δV_s of one interval from ``th`` (m_θ, 3) and ``dv`` (m_v, 3) of the algorithm's form."""
    if algorithm == SCULLING_TRADITIONAL1:
        # (2.4): ½ ΔΘ × ΔV (constant models)
        return _scale(0.5, _cross(_row(th, 0), _row(dv, 0)))
    if algorithm == SCULLING_TRADITIONAL2:
        # (2.3) with the coefficient 2/3 (printed 1/3):
        # ½ ΔΘ × ΔV + (2/3)[(ΔΘ1 × ΔV2) − (ΔΘ2 × ΔV1)]
        t1, t2 = _row(th, 0), _row(th, 1)
        v1, v2 = _row(dv, 0), _row(dv, 1)
        total = _cross(_lin(1.0, t1, 1.0, t2), _lin(1.0, v1, 1.0, v2))
        return _lin3(0.5, total, 2.0 / 3.0, _cross(t1, v2), -2.0 / 3.0, _cross(t2, v1))
    if algorithm == SCULLING_SMOOTHING:
        # (3.6): ½ (ΔΘ¹ × ΔV¹) − (1/T)[(ΔΘ¹ × ΔV²) − (ΔΘ² × ΔV¹)]
        t1, t2 = _row(th, 0), _row(th, 1)
        v1, v2 = _row(dv, 0), _row(dv, 1)
        return _lin3(0.5, _cross(t1, v1), -1.0 / T, _cross(t1, v2), 1.0 / T, _cross(t2, v1))
    if algorithm == SCULLING_INVARIANT_ACCEL1:
        # (4.4): ΔΘ¹ × ΔV¹ + (6/T²)(ΔΘ² − (2T/3) ΔΘ¹) × ΔV² − (12/T³)(ΔΘ² − (T/2) ΔΘ¹) × ΔV³
        t1, t2 = _row(th, 0), _row(th, 1)
        v1, v2, v3 = _row(dv, 0), _row(dv, 1), _row(dv, 2)
        a = _cross(_lin(1.0, t2, -2.0 * T / 3.0, t1), v2)
        b = _cross(_lin(1.0, t2, -0.5 * T, t1), v3)
        return _lin3(1.0, _cross(t1, v1), 6.0 / (T * T), a, -12.0 / (T * T * T), b)
    if algorithm == SCULLING_INVARIANT_ACCEL0:
        # (4.5): ΔΘ¹ × (ΔV¹ − ΔV²/T)
        return _cross(_row(th, 0), _lin(1.0, _row(dv, 0), -1.0 / T, _row(dv, 1)))
    if algorithm == SCULLING_INVARIANT_RATE1:
        # (4.6): −(6/T²) ΔΘ² × (ΔV² − (2T/3) ΔV¹) + (12/T³) ΔΘ³ × (ΔV² − (T/2) ΔV¹)
        t2, t3 = _row(th, 1), _row(th, 2)
        v1, v2 = _row(dv, 0), _row(dv, 1)
        a = _cross(t2, _lin(1.0, v2, -2.0 * T / 3.0, v1))
        b = _cross(t3, _lin(1.0, v2, -0.5 * T, v1))
        return _lin(-6.0 / (T * T), a, 12.0 / (T * T * T), b)
    # SCULLING_INVARIANT_RATE0, (4.7): (1/T)(ΔΘ² × ΔV¹)
    return _scale(1.0 / T, _cross(_row(th, 1), _row(dv, 0)))


# --------------------------------------------------------------------------------------
# Displacement correction δS_s, eq. (5.4)
# --------------------------------------------------------------------------------------


@jit
def _displacement(algorithm, th, dv, T):
    """δS_s = ∫∫ ΔΘ(t_k, τ) × a(τ) dτ dt of one interval, eq. (5.4).

    The paper gives no formulas, only that they follow "by the smoothing and invariant
    approaches like δV_s" (§5). Ours follow each sculling algorithm's own model; writing
    δS_s = ∫ (T − τ) ΔΘ(t_k, τ) × a(τ) dτ and integrating by parts as for (4.1), (4.2):
    acceleration-invariant δS_s = ΔΘ¹ × ΔV² − 2 ω_{k+1} × ΔV³ + 3 ω̇_{k+1} × ΔV⁴ − …,
    rate-invariant δS_s = ΔΘ³ × a_{k+1} − 2 ΔΘ⁴ × ȧ_{k+1} + …, with the end-point values
    from the smoothing fit (3.5). Coefficients re-derived in the tests.
    """
    if algorithm == SCULLING_TRADITIONAL1:
        # constant models: (T/6) ΔΘ¹ × ΔV¹
        return _scale(T / 6.0, _cross(_row(th, 0), _row(dv, 0)))
    if algorithm == SCULLING_SMOOTHING:
        # linear models fitted by (3.5), integrated exactly against (T − τ):
        # (T/15)(ΔΘ¹×ΔV¹) − (3/10)(ΔΘ¹×ΔV²) + (1/5)(ΔΘ²×ΔV¹) + (3/(5T))(ΔΘ²×ΔV²)
        t1, t2 = _row(th, 0), _row(th, 1)
        v1, v2 = _row(dv, 0), _row(dv, 1)
        a = _lin3(T / 15.0, _cross(t1, v1), -0.3, _cross(t1, v2), 0.2, _cross(t2, v1))
        return _lin(1.0, a, 0.6 / T, _cross(t2, v2))
    if algorithm == SCULLING_INVARIANT_ACCEL1:
        # ΔΘ¹×ΔV² − 2 ω̂_{k+1}×ΔV³ + 3 ω̂'_{k+1}×ΔV⁴,
        # ω̂_{k+1} = 4ΔΘ¹/T − 6ΔΘ²/T², ω̂'_{k+1} = 6ΔΘ¹/T² − 12ΔΘ²/T³   (from (3.5))
        t1, t2 = _row(th, 0), _row(th, 1)
        v2, v3, v4 = _row(dv, 1), _row(dv, 2), _row(dv, 3)
        T2 = T * T
        w_end = _lin(4.0 / T, t1, -6.0 / T2, t2)
        wdot_end = _lin(6.0 / T2, t1, -12.0 / (T2 * T), t2)
        return _lin3(1.0, _cross(t1, v2), -2.0, _cross(w_end, v3), 3.0, _cross(wdot_end, v4))
    if algorithm == SCULLING_INVARIANT_ACCEL0:
        # ΔΘ¹ × (ΔV² − 2ΔV³/T)
        return _cross(_row(th, 0), _lin(1.0, _row(dv, 1), -2.0 / T, _row(dv, 2)))
    if algorithm == SCULLING_INVARIANT_RATE1:
        # ΔΘ³ × â_{k+1} − 2 ΔΘ⁴ × â'_{k+1}, with â from ΔV¹, ΔV² as ω̂ above
        t3, t4 = _row(th, 2), _row(th, 3)
        v1, v2 = _row(dv, 0), _row(dv, 1)
        T2 = T * T
        a_end = _lin(4.0 / T, v1, -6.0 / T2, v2)
        adot_end = _lin(6.0 / T2, v1, -12.0 / (T2 * T), v2)
        return _lin(1.0, _cross(t3, a_end), -2.0, _cross(t4, adot_end))
    # SCULLING_INVARIANT_RATE0: ΔΘ³ × ΔV¹ / T
    return _scale(1.0 / T, _cross(_row(th, 2), _row(dv, 0)))


# --------------------------------------------------------------------------------------
# Attitude step: rotation vector (1.11) and quaternion update
# --------------------------------------------------------------------------------------


@jit
def _rotation_vector(increments, T, coning_id):
    """Φ = ΔΘ + δΘ_c, eq. (1.11); ΔΘ is the sum of the rows for the traditional
    (sub-interval) algorithms and row 0 (ΔΘ¹) for the smoothing and invariant ones."""
    if coning_id >= CONING_SMOOTHING:
        total = _row(increments, 0)
    else:
        total = _sum_rows(increments)
    return _lin(1.0, total, 1.0, _coning(coning_id, increments, T))


@jit
def _attitude_step(qw, qx, qy, qz, increments, T, coning_id):
    """q_wb(k+1) = q_wb(k) ∘ exp(Φ(k, k+1)), normalised; Φ by (1.11).

    ``increments`` (m, 3) in the form of the coning algorithm ``coning_id`` (see
    ``biso_cosim.strapdown.list_algorithms``); ``T`` the interval in s (used by the smoothing
    and invariant algorithms only). Returns the four components of the new q_wb.
    """
    phi = _rotation_vector(increments, T, coning_id)
    d = _qexp_rotvec(phi[0], phi[1], phi[2])
    q = _qmul(qw, qx, qy, qz, d[0], d[1], d[2], d[3])
    return _qnormalize(q[0], q[1], q[2], q[3])


# --------------------------------------------------------------------------------------
# Navigator: attitude, velocity (1.3), (1.6) and position (5.1) / trapezoid / (5.2)
# --------------------------------------------------------------------------------------


@jit
def _navigate(q, v, p, dtheta, dv, T, g, coning_id, sculling_id, position_id, multiple,
              out_q, out_v, out_p):
    """Integrate N intervals in place on the state ``q`` (4,), ``v`` (3,), ``p`` (3,).

    ``dtheta``, ``dv`` (N, m, 3) are sub-interval increments (``multiple`` false) or multiple
    integrals (``multiple`` true). One-sample algorithms are given the totals. The state
    after interval k is written to row k of ``out_q``, ``out_v``, ``out_p``.
    """
    tot_th = np.empty((1, 3))
    tot_v = np.empty((1, 3))
    half_T2 = 0.5 * T * T
    for k in range(dtheta.shape[0]):
        th = dtheta[k]
        a = dv[k]
        if multiple:
            d_theta = _row(th, 0)
            d_v = _row(a, 0)
        else:
            d_theta = _sum_rows(th)
            d_v = _sum_rows(a)
        tot_th[0, 0], tot_th[0, 1], tot_th[0, 2] = d_theta
        tot_v[0, 0], tot_v[0, 1], tot_v[0, 2] = d_v
        th_c = tot_th if coning_id == CONING_ONE_SAMPLE else th
        one_sample_v = sculling_id == SCULLING_TRADITIONAL1
        th_s = tot_th if one_sample_v else th
        v_s = tot_v if one_sample_v else a

        # velocity (1.3), (1.6): V(k+1) = V(k) + C(k)[ΔV + δV_s] + g T, with C(k) at t_k
        dvs = _sculling(sculling_id, th_s, v_s, T)
        dv_w = _qrot(q[0], q[1], q[2], q[3], d_v[0] + dvs[0], d_v[1] + dvs[1], d_v[2] + dvs[2])
        v_new = (v[0] + dv_w[0] + g[0] * T, v[1] + dv_w[1] + g[1] * T, v[2] + dv_w[2] + g[2] * T)

        if position_id == POSITION_RECTANGLE:  # (5.1)
            for i in range(3):
                p[i] += v[i] * T
        elif position_id == POSITION_TRAPEZOID:
            for i in range(3):
                p[i] += 0.5 * (v[i] + v_new[i]) * T
        else:
            # (5.2) with V(k), not V̇(k) as printed: S(k+1) = S(k) + V(k) T + δS(k, k+1),
            # δS (5.3) = C(k)[ΔV² + δS_s] + g T²/2, δS_s by (5.4)
            dss = _displacement(sculling_id, th_s, v_s, T)
            ds_w = _qrot(q[0], q[1], q[2], q[3], a[1, 0] + dss[0], a[1, 1] + dss[1], a[1, 2] + dss[2])
            for i in range(3):
                p[i] += v[i] * T + ds_w[i] + g[i] * half_T2
        v[0], v[1], v[2] = v_new

        # attitude (1.11) last: velocity and position use C(k) of the interval's start
        phi_c = _coning(coning_id, th_c, T)
        d = _qexp_rotvec(d_theta[0] + phi_c[0], d_theta[1] + phi_c[1], d_theta[2] + phi_c[2])
        qn = _qmul(q[0], q[1], q[2], q[3], d[0], d[1], d[2], d[3])
        q[0], q[1], q[2], q[3] = _qnormalize(qn[0], qn[1], qn[2], qn[3])

        for i in range(4):
            out_q[k, i] = q[i]
        for i in range(3):
            out_v[k, i] = v[i]
            out_p[k, i] = p[i]


# --------------------------------------------------------------------------------------
# Batch kernels behind the public correction functions
# --------------------------------------------------------------------------------------
# The dispatch is outside the loop: each branch calls the inlined loop with a literal id, so
# that the compiler folds the algorithm choice away (2-4x faster than one loop that tests the
# id at every interval).


@jit(inline="always")
def _fill_coning(algorithm, increments, T, out):
    for k in range(increments.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = _coning(algorithm, increments[k], T)


@jit(inline="always")
def _fill_sculling(algorithm, dtheta, dv, T, out):
    for k in range(dtheta.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = _sculling(algorithm, dtheta[k], dv[k], T)


@jit(inline="always")
def _fill_displacement(algorithm, dtheta, dv, T, out):
    for k in range(dtheta.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = _displacement(algorithm, dtheta[k], dv[k], T)


@jit
def _batch_coning(algorithm, increments, T, out):
    if algorithm == CONING_ONE_SAMPLE:
        _fill_coning(CONING_ONE_SAMPLE, increments, T, out)
    elif algorithm == CONING_TWO_SAMPLE:
        _fill_coning(CONING_TWO_SAMPLE, increments, T, out)
    elif algorithm == CONING_TRADITIONAL3:
        _fill_coning(CONING_TRADITIONAL3, increments, T, out)
    elif algorithm == CONING_TRADITIONAL3_MILLER:
        _fill_coning(CONING_TRADITIONAL3_MILLER, increments, T, out)
    elif algorithm == CONING_SMOOTHING:
        _fill_coning(CONING_SMOOTHING, increments, T, out)
    else:
        _fill_coning(CONING_INVARIANT, increments, T, out)


@jit
def _batch_sculling(algorithm, dtheta, dv, T, out):
    if algorithm == SCULLING_TRADITIONAL1:
        _fill_sculling(SCULLING_TRADITIONAL1, dtheta, dv, T, out)
    elif algorithm == SCULLING_TRADITIONAL2:
        _fill_sculling(SCULLING_TRADITIONAL2, dtheta, dv, T, out)
    elif algorithm == SCULLING_SMOOTHING:
        _fill_sculling(SCULLING_SMOOTHING, dtheta, dv, T, out)
    elif algorithm == SCULLING_INVARIANT_ACCEL1:
        _fill_sculling(SCULLING_INVARIANT_ACCEL1, dtheta, dv, T, out)
    elif algorithm == SCULLING_INVARIANT_ACCEL0:
        _fill_sculling(SCULLING_INVARIANT_ACCEL0, dtheta, dv, T, out)
    elif algorithm == SCULLING_INVARIANT_RATE1:
        _fill_sculling(SCULLING_INVARIANT_RATE1, dtheta, dv, T, out)
    else:
        _fill_sculling(SCULLING_INVARIANT_RATE0, dtheta, dv, T, out)


@jit
def _batch_displacement(algorithm, dtheta, dv, T, out):
    if algorithm == SCULLING_TRADITIONAL1:
        _fill_displacement(SCULLING_TRADITIONAL1, dtheta, dv, T, out)
    elif algorithm == SCULLING_SMOOTHING:
        _fill_displacement(SCULLING_SMOOTHING, dtheta, dv, T, out)
    elif algorithm == SCULLING_INVARIANT_ACCEL1:
        _fill_displacement(SCULLING_INVARIANT_ACCEL1, dtheta, dv, T, out)
    elif algorithm == SCULLING_INVARIANT_ACCEL0:
        _fill_displacement(SCULLING_INVARIANT_ACCEL0, dtheta, dv, T, out)
    elif algorithm == SCULLING_INVARIANT_RATE1:
        _fill_displacement(SCULLING_INVARIANT_RATE1, dtheta, dv, T, out)
    else:
        _fill_displacement(SCULLING_INVARIANT_RATE0, dtheta, dv, T, out)
