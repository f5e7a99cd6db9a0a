"""biso_plus's kernel against a slow, plain twin: the per-sample step written straight from the
equations on the state array (one sample at a time, the whole state read and written back,
library-free series), in Python. The kernel keeps the state in registers, skips terms that
cannot change a rounded sum and writes the offset covariance as a triangle; the results must be
the same numbers, bit for bit."""

import dataclasses
import math

import numpy as np
import pytest

from biso_cosim import motions as mo
from biso_cosim.estimators import biso_plus as bp
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators import make_estimator
from biso_cosim.estimators._kernels import (
    MAG_PARALLEL_SIN,
    MAX_ACCEL,
    MAX_MAG,
    MAX_RATE,
    MIN_ACCEL,
    MIN_MAG,
    _X_FIRST,
    _input_checks,
    _qexp_fast,
)
from biso_cosim.frames import _mat_from_q, _qmul, _qrot

S, C = bp._S, bp._C
A = (1.0 / 3.0, 1.0 / 5.0, 1.0 / 7.0, 1.0 / 9.0, 1.0 / 11.0)


# --------------------------------------------------------------------------------------
# the plain twin
# --------------------------------------------------------------------------------------


def _qexp(rx, ry, rz):
    """e^{(0, r)/2}: the full Taylor series (no shortcut), or sin and cos."""
    t2 = rx * rx + ry * ry + rz * rz
    if t2 <= 0.01:
        x = 0.25 * t2
        x2 = x * x
        c = (1.0 - x / 2.0) + x2 * ((1.0 / 24.0 - x * (1.0 / 720.0)) + x2 * (1.0 / 40320.0))
        s = 0.5 * ((1.0 - x * (1.0 / 6.0)) + x2 * ((1.0 / 120.0 - x * (1.0 / 5040.0)) + x2 * (1.0 / 362880.0)))
        return c, s * rx, s * ry, s * rz
    angle = math.sqrt(t2)
    s = math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), s * rx, s * ry, s * rz


def _unit(w, x, y, z):
    z2 = w * w + x * x + y * y + z * z - 1.0
    n = 1.0 - z2 * (0.5 - 0.375 * z2) if abs(z2) < 1.0e-6 else 1.0 / math.sqrt(1.0 + z2)
    return w * n, x * n, y * n, z * n


def _atan_series(t2):
    return 1.0 - t2 * (A[0] - t2 * (A[1] - t2 * (A[2] - t2 * (A[3] - t2 * A[4]))))


def _atan2(y, x):
    if x > 0.0 and abs(y) <= 0.1 * x:
        t = y / x
        return t * _atan_series(t * t)
    return math.atan2(y, x)


def _angle_over_sine(s2, c):
    if c > 0.0 and s2 <= 0.01 * c * c:
        i = 1.0 / c
        return i * _atan_series(s2 * i * i)
    if s2 > 0.0:
        s = math.sqrt(s2)
        return math.atan2(s, c) / s
    return 0.0


def _norm2(v):
    return v[0] * v[0] + v[1] * v[1] + v[2] * v[2]


def _checks(g, a, m, held, imu_flags, glim, alim):
    """The input policy written out (flags, gyro to use, acc_ok, |f|², mag_ok); Python floats."""
    g, a, m = (tuple(float(x) for x in v) for v in (g, a, m))
    flags = 0
    n2 = _norm2(g)
    if math.isfinite(n2) and n2 < MAX_RATE ** 2:
        if max(abs(x) for x in g) >= glim or imu_flags & fl.IMU_GYRO_SATURATED:
            flags |= fl.SATURATED
    else:
        g = tuple(float(x) for x in held)
        flags |= fl.GYRO_INVALID
    f2 = _norm2(a)
    acc_ok = math.isfinite(f2) and MIN_ACCEL ** 2 < f2 < MAX_ACCEL ** 2
    if acc_ok and (max(abs(x) for x in a) >= alim or imu_flags & fl.IMU_ACCEL_SATURATED):
        acc_ok = False
        flags |= fl.SATURATED
    if not acc_ok:
        flags |= fl.ACCEL_INVALID
    e2 = _norm2((m[1] * a[2] - m[2] * a[1], m[2] * a[0] - m[0] * a[2], m[0] * a[1] - m[1] * a[0]))
    m2 = _norm2(m)
    mag_ok = math.isfinite(m2) and MIN_MAG ** 2 < m2 < MAX_MAG ** 2
    if imu_flags & fl.IMU_MAG_OVERFLOW:
        flags |= fl.SATURATED
        mag_ok = False
    if imu_flags & fl.IMU_MAG_INVALID:
        mag_ok = False
    mag_ok = mag_ok and acc_ok and e2 > (MAG_PARALLEL_SIN * MAG_PARALLEL_SIN) * m2 * f2
    if not mag_ok:
        flags |= fl.MAG_INVALID
    return flags, g, acc_ok, f2, mag_ok


def _offset_update(c, st, mx, my, mz):
    qw, qx, qy, qz = st[S["q_i"]:S["q_i"] + 4]
    p = st[S["offset_cov"]:S["offset_cov"] + 36].reshape(6, 6)
    bi, off = S["field_i"], S["mag_offset_b"]
    if st[S["offset_started"]] == 0.0:
        st[S["offset_started"]] = 1.0
        st[bi:bi + 3] = _qrot(qw, qx, qy, qz, mx, my, mz)
        r = np.array(_mat_from_q(qw, qx, qy, qz)).reshape(3, 3)
        so = p[3, 3]
        p[:3, :3] = so * np.eye(3)
        p[:3, 3:] = -so * r
        p[3:, :3] = -so * r.T
        return
    for i in range(3):
        p[i, i] += c[C["q_field"]]
        p[3 + i, 3 + i] += c[C["q_offset"]]
    for comp in range(3):
        e = [0.0, 0.0, 0.0]
        e[comp] = 1.0
        h = list(_qrot(qw, qx, qy, qz, *e)) + e
        ph = [0.0] * 6
        for i in range(6):
            s = 0.0
            for j in range(6):
                s += p[i, j] * h[j]
            ph[i] = s
        den = c[C["r_mag"]]
        for i in range(6):
            den += h[i] * ph[i]
        r = (mx, my, mz)[comp] - (h[0] * st[bi] + h[1] * st[bi + 1] + h[2] * st[bi + 2] + st[off + comp])
        if r * r > 25.0 * den:
            continue
        for i in range(3):
            st[bi + i] += ph[i] * r / den
            st[off + i] += ph[3 + i] * r / den
        for i in range(6):
            for j in range(6):
                p[i, j] -= ph[i] * ph[j] / den


def _bias_update(c, st, hm, e, w):
    b = S["bias_cov"]
    p00, p01, p02, p11, p12, p22 = st[b], st[b + 1], st[b + 2], st[b + 4], st[b + 5], st[b + 8]
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = hm
    lim = c[C["bias_limit"]]
    e0, e1, e2 = (min(max(x, -lim), lim) for x in e)
    a00 = p00 * h00 + p01 * h01 + p02 * h02
    a10 = p01 * h00 + p11 * h01 + p12 * h02
    a20 = p02 * h00 + p12 * h01 + p22 * h02
    a01 = p00 * h10 + p01 * h11 + p02 * h12
    a11 = p01 * h10 + p11 * h11 + p12 * h12
    a21 = p02 * h10 + p12 * h11 + p22 * h12
    a02 = p00 * h20 + p01 * h21 + p02 * h22
    a12 = p01 * h20 + p11 * h21 + p12 * h22
    a22 = p02 * h20 + p12 * h21 + p22 * h22
    s00 = h00 * a00 + h01 * a10 + h02 * a20 + w[0]
    s01 = h00 * a01 + h01 * a11 + h02 * a21
    s02 = h00 * a02 + h01 * a12 + h02 * a22
    s11 = h10 * a01 + h11 * a11 + h12 * a21 + w[1]
    s12 = h10 * a02 + h11 * a12 + h12 * a22
    s22 = h20 * a02 + h21 * a12 + h22 * a22 + w[2]
    i00 = s11 * s22 - s12 * s12
    i01 = s02 * s12 - s01 * s22
    i02 = s01 * s12 - s02 * s11
    i11 = s00 * s22 - s02 * s02
    i12 = s01 * s02 - s00 * s12
    i22 = s00 * s11 - s01 * s01
    det = s00 * i00 + s01 * i01 + s02 * i02
    if not det > 0.0:
        return
    inv = 1.0 / det
    k = [[a00 * i00 + a01 * i01 + a02 * i02, a00 * i01 + a01 * i11 + a02 * i12, a00 * i02 + a01 * i12 + a02 * i22],
         [a10 * i00 + a11 * i01 + a12 * i02, a10 * i01 + a11 * i11 + a12 * i12, a10 * i02 + a11 * i12 + a12 * i22],
         [a20 * i00 + a21 * i01 + a22 * i02, a20 * i01 + a21 * i11 + a22 * i12, a20 * i02 + a21 * i12 + a22 * i22]]
    a = [[a00, a01, a02], [a10, a11, a12], [a20, a21, a22]]
    for r in range(3):
        x = st[S["gyro_bias_b"] + r] + (k[r][0] * e0 + k[r][1] * e1 + k[r][2] * e2) * inv
        st[S["gyro_bias_b"] + r] = min(max(x, -lim), lim)
    new = {}
    for r, q in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        old = (p00, p01, p02, None, p11, p12, None, None, p22)[3 * r + q]
        new[r, q] = old - (k[r][0] * a[q][0] + k[r][1] * a[q][1] + k[r][2] * a[q][2]) * inv
    for (r, q), v in new.items():
        st[b + 3 * r + q] = st[b + 3 * q + r] = v


def _step(c, st, g, a, m, speed, speed_given, imu_flags):
    """One sample on the state array, straight from the equations (module docstring)."""
    h = c[C["h"]]
    held = st[S["gyro_hold"]:S["gyro_hold"] + 3].copy()
    flags, g, acc_ok, f2, mag_ok = _checks(g, a, m, held, imu_flags, c[C["gyro_range"]], c[C["accel_range"]])
    gx, gy, gz = g
    ax, ay, az = a = tuple(float(x) for x in a)
    mx, my, mz = (float(x) for x in m)
    st[S["gyro_hold"]:S["gyro_hold"] + 3] = g
    if st[S["initialized"]] != 1.0:
        if st[S["initialized"]] == 0.0 and not acc_ok:
            return flags | fl.UNINITIALIZED
        bp._biso_plus_start(c, st, gx, gy, gz, ax, ay, az, math.sqrt(f2), mx, my, mz, acc_ok, mag_ok, speed,
                            speed_given)
        return flags
    st[S["time_s"]] += h
    t = st[S["time_s"]]
    # gyro strapdown of q_I
    b = tuple(float(x) for x in st[S["gyro_bias_b"]:S["gyro_bias_b"] + 3])
    w = (gx - b[0], gy - b[1], gz - b[2])
    eb = _qexp(w[0] * h, w[1] * h, w[2] * h)
    qi = _qmul(*_unit(*st[S["q_i"]:S["q_i"] + 4]), *eb)
    st[S["q_i"]:S["q_i"] + 4] = qi
    qc = tuple(st[S["q_c"]:S["q_c"] + 4])
    lam = _qmul(*qc, *qi)
    # speed
    a_v, fs = c[C["a_speed"]], c[C["fs"]]
    wd, wp = S["angular_accel_lp"], S["gyro_prev"]
    for k in range(3):
        st[wd + k] += a_v * ((w[k] - st[wp + k]) * fs - st[wd + k])
        st[wp + k] = w[k]
    v_ok = speed_given and math.isfinite(speed)
    comp = (0.0, 0.0, 0.0)
    d_r = c[C["rear_slip"]]
    lin2 = c[C["linear_accel2"]]  # a_l² of the tyres' linear range (0: no limit)
    if acc_ok:  # the forward and lateral specific force, low-passed (the lateral one used with D_r or a_l)
        st[S["forward_accel_lp"]] += a_v * (ax - st[S["forward_accel_lp"]])
        if d_r != 0.0 or lin2 > 0.0:
            st[S["lateral_accel_lp"]] += a_v * (ay - st[S["lateral_accel_lp"]])
    limited = False
    vu = speed  # the speed of r_v used
    if v_ok:
        if st[S["speed_prev_ok"]] != 0.0:
            st[S["dvdt"]] += a_v * ((speed - st[S["speed_prev"]]) * fs - st[S["dvdt"]])
        st[S["speed_prev"]] = speed
        # wheel slip: v̇ against the accelerometer's forward specific force, then held for t_s
        slipping = False
        if abs(st[S["dvdt"]] - st[S["forward_accel_lp"]]) > c[C["slip_accel"]]:
            st[S["speed_slip_s"]] = c[C["slip_hold"]]
            slipping = True
        elif st[S["speed_slip_s"]] > 0.0:
            st[S["speed_slip_s"]] -= h
            slipping = st[S["speed_slip_s"]] > 0.0
        if slipping:  # the speed carried on by the forward acceleration f_x − g (R̂ᵀ e_z)_x
            a_fwd = ax - c[C["g"]] * _mat_from_q(*lam)[6] if acc_ok else 0.0
            st[S["speed_held"]] += h * a_fwd
            vu = st[S["speed_held"]]
            flags |= fl.ACCEL_GATED
        else:
            st[S["speed_held"]] = speed
        # beyond the tyres' linear range, and for t_l after: no say in the tilt
        if lin2 > 0.0:
            if st[S["forward_accel_lp"]] ** 2 + st[S["lateral_accel_lp"]] ** 2 > lin2:
                st[S["linear_limit_s"]] = c[C["linear_hold"]]
                limited = True
            elif st[S["linear_limit_s"]] > 0.0:
                st[S["linear_limit_s"]] -= h
                limited = st[S["linear_limit_s"]] > 0.0
        dx, dy, dz = -c[C["r_v"]], -c[C["r_v"] + 1], -c[C["r_v"] + 2]
        wx, wy, wz = w
        ux, uy, uz = vu + wy * dz - wz * dy, wz * dx - wx * dz, wx * dy - wy * dx
        dvy = 0.0
        if d_r != 0.0:  # the axle's sideslip v_y = −(D_r/g₀) |v| f_y and its low-passed rate
            vy = -d_r * abs(vu) * st[S["lateral_accel_lp"]]
            if st[S["speed_prev_ok"]] != 0.0:
                st[S["lateral_dvdt"]] += a_v * ((vy - st[S["lateral_speed_prev"]]) * fs - st[S["lateral_dvdt"]])
            st[S["lateral_speed_prev"]] = vy
            uy += vy
            dvy = st[S["lateral_dvdt"]]
        qx_, qy_, qz_ = st[wd:wd + 3]
        comp = (a_fwd if slipping else st[S["dvdt"]] + (qy_ * dz - qz_ * dy) + (wy * uz - wz * uy),
                (qz_ * dx - qx_ * dz) + (wz * ux - wx * uz) + dvy,
                (qx_ * dy - qy_ * dx) + (wx * uy - wy * ux))
        flags |= fl.ACCEL_COMPENSATED
    st[S["speed_prev_ok"]] = 1.0 if v_ok else 0.0
    # rest
    ar = c[C["a_rest"]]
    wl, al = S["rest_gyro_lp"], S["rest_accel_lp"]
    for k in range(3):
        st[wl + k] = st[wl + k] + ar * (g[k] - st[wl + k])
    wl0, wl1, wl2 = st[wl:wl + 3]
    bpd = max(st[S["bias_cov"]], st[S["bias_cov"] + 4], st[S["bias_cov"] + 8])
    rest = False
    if acc_ok:
        for k in range(3):
            st[al + k] = st[al + k] + ar * (a[k] - st[al + k])
        dw2 = (gx - wl0) ** 2 + (gy - wl1) ** 2 + (gz - wl2) ** 2
        da2 = (ax - st[al]) ** 2 + (ay - st[al + 1]) ** 2 + (az - st[al + 2]) ** 2
        thw = c[C["rest_w"]]
        still = dw2 < thw * thw and da2 < c[C["rest_a"]] * c[C["rest_a"]]
        if still:
            thr = thw + 3.0 * math.sqrt(bpd)
            still = (wl0 - b[0]) ** 2 + (wl1 - b[1]) ** 2 + (wl2 - b[2]) ** 2 < thr * thr
        if v_ok:
            still = still and abs(vu) < c[C["rest_v"]]
        st[S["rest_time_s"]] = st[S["rest_time_s"]] + h if still else 0.0
        rest = st[S["rest_time_s"]] >= c[C["rest_time"]]
    if rest:
        flags |= fl.REST
    # tilt
    ex = ey = ez = 0.0
    if acc_ok:
        fx, fy, fz = ax - comp[0], ay - comp[1], az - comp[2]
        gate = c[C["inv_gate_g"]] if v_ok else c[C["inv_gate_free_g"]]
        d = abs(math.sqrt(fx * fx + fy * fy + fz * fz) - c[C["g"]]) * gate
        weight = 0.0 if limited else 1.0 / (1.0 + d * d)
        if weight < 0.5:
            flags |= fl.ACCEL_GATED
        alpha = c[C["a_accv"]] if v_ok else c[C["a_acc"]]
        start = h > alpha * (t + h)
        if start:
            alpha = h / (t + h)
        fi = _qrot(*qi, fx, fy, fz)
        flp = S["accel_lp_i"]
        b0, b1, b2, a1, a2 = c[C["acc_bw"]:C["acc_bw"] + 5]
        if b0 != 0.0 and not (v_ok or start):  # Butterworth, transposed direct form II
            z1, z2 = S["accel_bw_i"], S["accel_bw_i"] + 3
            if st[S["accel_bw_ready"]] == 0.0:  # from the first order's output, at its steady state
                st[S["accel_bw_ready"]] = 1.0
                for k in range(3):
                    st[z1 + k] = (1.0 - b0) * st[flp + k]
                    st[z2 + k] = (b2 - a2) * st[flp + k]
            if weight < 1.0:
                fi = tuple(st[flp + k] + weight * (fi[k] - st[flp + k]) for k in range(3))
            for k in range(3):
                y = b0 * fi[k] + st[z1 + k]
                st[z1 + k] = b1 * fi[k] - a1 * y + st[z2 + k]
                st[z2 + k] = b2 * fi[k] - a2 * y
                st[flp + k] = y
        else:
            st[S["accel_bw_ready"]] = 0.0
            alpha *= weight
            for k in range(3):
                st[flp + k] = st[flp + k] + alpha * (fi[k] - st[flp + k])
        nx, ny, nz = _qrot(*qc, *st[flp:flp + 3])
        ang = _angle_over_sine(nx * nx + ny * ny, nz)
        ex, ey = ny * ang, -nx * ang
    # heading, disturbance, offset
    mag_w = 1.0
    if mag_ok:
        if c[C["offset_on"]] != 0.0 and bpd < c[C["offset_bias2"]]:
            st[S["offset_count"]] += 1.0
            if st[S["offset_count"]] >= c[C["offset_n"]]:
                st[S["offset_count"]] = 0.0
                _offset_update(c, st, mx, my, mz)
        o = st[S["mag_offset_b"]:S["mag_offset_b"] + 3]
        m_used = (mx - o[0], my - o[1], mz - o[2])
        if c[C["inv_offset_test"]] != 0.0 and c[C["offset_on"]] != 0.0 and not v_ok:
            # the offset's norm test: variances of |m − o| and |m| over the last Θ_o of rotation
            a = min(1.0, math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) * h * c[C["inv_offset_test"]])
            j = S["offset_norm_test"]
            n1, n0 = math.sqrt(_norm2(m_used)), math.sqrt(_norm2((mx, my, mz)))
            if st[j] == 0.0:
                st[j], st[j + 2] = n1, n0
            for k, n in ((j, n1), (j + 2, n0)):
                st[k] += a * (n - st[k])
                st[k + 1] += a * ((n - st[k]) ** 2 - st[k + 1])
            if not st[j + 1] < st[j + 3]:  # the raw norm is as steady: no offset shows in it
                m_used = (mx, my, mz)
            elif c[C["offset_shrink2"]] > 0.0:  # used, shrunk toward 0 by |o|²/(|o|² + σ_s²)
                o2 = o[0] * o[0] + o[1] * o[1] + o[2] * o[2]
                sh = o2 / (o2 + c[C["offset_shrink2"]])
                m_used = (mx - sh * o[0], my - sh * o[1], mz - sh * o[2])
        mwx, mwy, mwz = _qrot(*lam, *m_used)
        mh = math.sqrt(mwx * mwx + mwy * mwy)
        norm = math.sqrt(mh * mh + mwz * mwz)
        tc = S["tilt_corr_start"]
        if st[S["field_known"]] == 2.0 and st[tc] ** 2 + st[tc + 1] ** 2 > c[C["dip_tol"]] ** 2:
            # provisional, and the tilt corrected by more than θ_δ since: field and heading again
            st[S["field_known"]] = 0.0
            st[S["heading_start_s"]] = t
            st[tc] = st[tc + 1] = 0.0
        if st[S["field_known"]] == 0.0:
            st[S["field_norm"]] = norm if c[C["b_norm"]] < 0.0 else c[C["b_norm"]]
            if math.isnan(c[C["dip"]]):
                st[S["field_dip"]] = math.atan2(-mwz, mh)
                cs = (mh / norm, -mwz / norm) if norm > 0.0 else (1.0, 0.0)
            else:
                st[S["field_dip"]], cs = c[C["dip"]], (c[C["dip_c"]], c[C["dip_s"]])
            st[S["field_dip_cs"]:S["field_dip_cs"] + 2] = cs
            st[S["field_known"]] = 1.0 if t >= c[C["t0"]] else 2.0  # before the tilt settled: provisional
        c0, s0 = st[S["field_dip_cs"]:S["field_dip_cs"] + 2]
        dcos = mh * c0 - mwz * s0
        dsin = -mwz * c0 - mh * s0
        bn = st[S["field_norm"]]
        if not v_ok:  # the heading's weight σ_h²/(σ_h² + κ D + (|B| |ω| τ_m)²)
            dn = norm - bn
            st[S["mag_disturbance"]] += c[C["a_dist"]] * (dn * dn - st[S["mag_disturbance"]])
            r_head = c[C["r_head"]]
            mag_w = r_head / (r_head + c[C["kappa"]] * st[S["mag_disturbance"]]
                              + bn * bn * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) * c[C["tau_m2"]])
        if abs(norm - bn) > c[C["b_tol"]] * bn or dcos < c[C["cos_dip_tol"]] * norm:
            flags |= fl.MAG_DISTURBED
            st[S["mag_rejected_s"]] += h
            if st[S["field_known"]] == 2.0:  # a provisional field: this one, and the heading's start again
                st[S["heading_start_s"]] = t
                st[S["tilt_corr_start"]] = st[S["tilt_corr_start"] + 1] = 0.0
                st[S["field_known"]] = st[S["mag_rejected_s"]] = 0.0
            elif st[S["mag_rejected_s"]] > c[C["reject_max"]]:
                st[S["field_known"]] = st[S["mag_rejected_s"]] = 0.0
        else:
            st[S["mag_rejected_s"]] = 0.0
            if st[S["field_known"]] == 2.0 and t >= c[C["t0"]]:
                st[S["field_known"]] = 1.0
            af = c[C["a_field"]]
            if c[C["b_norm"]] < 0.0:
                st[S["field_norm"]] += af * (norm - st[S["field_norm"]])
            if math.isnan(c[C["dip"]]):
                e = af * _atan2(dsin, dcos)
                st[S["field_dip"]] += e
                ce, se = 1.0 - 0.5 * e * e, e * (1.0 - e * e * (1.0 / 6.0))
                st[S["field_dip_cs"]:S["field_dip_cs"] + 2] = c0 * ce - s0 * se, s0 * ce + c0 * se
            if mh > 0.0:
                cdh, sdh = c[C["cdh"]], c[C["sdh"]]
                cd, sd = cdh * cdh - sdh * sdh, 2.0 * sdh * cdh
                ez = _atan2(mwx * cd - mwy * sd, mwy * cd + mwx * sd)
    # correction
    kt, kh, kp = c[C["k_t"]], c[C["k_h"]], c[C["k_p"]]
    th = st[S["heading_start_s"]]
    tw = c[C["t0"]] if th == 0.0 else h  # the held heading's weight: τ_a at the start, a sample later
    head_start = kh * ((t - th) + tw) < 1.0
    if head_start:
        kh = 1.0 / ((t - th) + tw)
    if mag_w != 1.0:
        kh *= mag_w
    u = (kt * ex + kp * (ez - ey), kt * ey + kp * (ex - ez), kh * ez + kp * (ey - ex))
    if st[S["field_known"]] == 2.0:
        st[S["tilt_corr_start"]] += u[0] * h
        st[S["tilt_corr_start"] + 1] += u[1] * h
    if u != (0.0, 0.0, 0.0):
        qc = _qmul(*_qexp(u[0] * h, u[1] * h, u[2] * h), *_unit(*qc))
        st[S["q_c"]:S["q_c"] + 4] = qc
        lam = _qmul(*qc, *qi)
    # gyro bias
    bc = S["bias_cov"]
    for k in (0, 4, 8):
        if st[bc + k] < c[C["bias_p0"]]:
            st[bc + k] += c[C["bias_v"]]
    r = _mat_from_q(*lam)
    alpha = c[C["a_accv"]] if v_ok else c[C["a_acc"]]
    rl, rb = S["rot_lp"], S["rot_bias_lp"]
    for k in range(9):
        st[rl + k] = st[rl + k] + alpha * (r[k] - st[rl + k])
    for k in range(3):
        st[rb + k] = st[rb + k] + alpha * ((r[3 * k] * b[0] + r[3 * k + 1] * b[1] + r[3 * k + 2] * b[2]) - st[rb + k])
    hm = tuple(st[rl:rl + 9])
    if rest:
        wr = c[C["bias_w_rest"]]
        _bias_update(c, st, (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), (wl0 - b[0], wl1 - b[1], wl2 - b[2]),
                     (wr, wr, wr))
    elif acc_ok and t > c[C["t0"]]:
        e = [st[rb + k] - (hm[3 * k] * b[0] + hm[3 * k + 1] * b[1] + hm[3 * k + 2] * b[2]) - u[k] for k in range(3)]
        wm = c[C["bias_w_motion"]]
        if v_ok:
            wv = c[C["bias_w_vertical"]] if ez != 0.0 else c[C["bias_w_vertical"]] * 1e6
        else:  # without speed: the heading's variance, and not during its start
            wvf = c[C["bias_w_vertical_free"]]
            wv = wvf / mag_w if ez != 0.0 and not head_start else wvf * 1e6
        _bias_update(c, st, hm, e, (wm, wm, wv))
    st[S["lam"]:S["lam"] + 4] = _unit(*lam)
    return flags


def _reference(est, gyro, accel, mag, speed=None, imu_flags=None):
    c, st = est.coefficients.copy(), est.get_state().values.copy()
    n = gyro.shape[0]
    q, flags, bias = np.empty((n, 4)), np.empty(n, dtype=np.int64), np.empty((n, 3))
    for i in range(n):
        v = np.nan if speed is None else float(speed[i])
        sf = 0 if imu_flags is None else int(imu_flags[i])
        flags[i] = _step(c, st, gyro[i], accel[i], mag[i], v, speed is not None, sf)
        q[i] = st[S["lam"]:S["lam"] + 4]
        bias[i] = st[S["gyro_bias_b"]:S["gyro_bias_b"] + 3]
    return q, flags, bias, st


# --------------------------------------------------------------------------------------
# tests
# --------------------------------------------------------------------------------------


def _tumble(n, seed, hard_iron=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    m = mo.make_motion("tumble", n / 200.0, 200.0, seed=seed, rate_scale=0.5)
    gyro = m.omega_b + [0.01, -0.02, 0.005] + 0.003 * rng.normal(size=(n, 3))
    accel = m.specific_force_b + 0.05 * rng.normal(size=(n, 3))
    mag = m.mag_b + 0.3 * rng.normal(size=(n, 3)) + hard_iron
    return gyro, accel, mag, rng


# (parameters, data, flags that must occur, whether the offset filter must have run)
CASES = {
    "tumble, defaults": ({}, "tumble", 0, False),
    "tumble, hard iron learned": ({"mag_offset_bias_sigma_rad_s": 0.05}, "iron", 0, True),
    "tumble, hard iron, short norm-test window": (
        {"mag_offset_bias_sigma_rad_s": 0.05, "mag_offset_test_angle_rad": 0.3}, "iron", 0, True),
    "tumble, hard iron, norm test without the shrink": (
        {"mag_offset_bias_sigma_rad_s": 0.05, "mag_offset_shrink_ut": 0.0}, "iron", 0, True),
    "tumble, hard iron, no norm test": (
        {"mag_offset_bias_sigma_rad_s": 0.05, "mag_offset_test_angle_rad": 0.0}, "iron", 0, True),
    "tumble, speed with gaps, NaN samples, sensor flags, full scales": (
        {"gyro_range_rad_s": 3.0, "accel_range_mps2": 40.0, "declination_rad": 0.2,
         "speed_point_b_m": (-1.0, 0.2, 0.0), "mag_offset_bias_sigma_rad_s": 0.05},
        "dirty", fl.ACCEL_COMPENSATED | fl.SATURATED | fl.GYRO_INVALID | fl.ACCEL_INVALID | fl.MAG_INVALID, True),
    "magnet, cross-link and given field": (
        {"k_p": 3.0, "field_norm_ut": 50.0, "dip_rad": 1.1}, "magnet", fl.MAG_DISTURBED, False),
    "tumble, gated first order, time skew": (
        {"tilt_lp_order": 1, "accel_gate_free": 1.0, "mag_time_skew_s": 0.02}, "tumble", 0, False),
    "tumble, gated Butterworth, time skew": (
        {"accel_gate_free": 0.003, "mag_time_skew_s": 0.02}, "tumble", fl.ACCEL_GATED, False),
    "static with bias (rest), q0 given": ({"estimate_mag_offset": False, "tau_acc_s": 0.0}, "static", fl.REST, False),
    "started in motion: provisional field and heading learned again": ({}, "moving_start", 0, False),
    "circle: wheel spin-ups, sideslip, speed gaps": (
        {"speed_point_b_m": (-1.2, 0.0, 0.0), "rear_slip_gradient_rad_per_g": 0.08, "speed_slip_hold_s": 0.2},
        "wheel", fl.ACCEL_COMPENSATED | fl.ACCEL_GATED, False),
    "circle: slides beyond the tyres' linear range": (
        {"speed_point_b_m": (-1.2, 0.0, 0.0), "rear_slip_gradient_rad_per_g": 0.08, "linear_accel_mps2": 5.0,
         "linear_hold_s": 0.3}, "slide", fl.ACCEL_COMPENSATED | fl.ACCEL_GATED, False),
}


@pytest.mark.parametrize("case", list(CASES))
def test_kernel_equals_the_plain_step_bit_for_bit(case):
    params, kind, must_flag, offset_runs = CASES[case]
    est = make_estimator("biso_plus", 200.0, **params)
    n = 1500  # beyond the start (τ_a = 3 s), many offset updates (every 20th sample)
    speed = imu_flags = None
    if kind in ("tumble", "iron", "dirty"):
        gyro, accel, mag, rng = _tumble(n, 3, (0.0, 0.0, 0.0) if kind == "tumble" else (4.0, -3.0, 2.0))
        if kind == "dirty":
            for arr in (gyro, accel, mag):
                arr[rng.integers(0, n, 15), rng.integers(0, 3, 15)] = np.nan
            accel[rng.integers(0, n, 5)] = [60.0, 0.0, 0.0]  # beyond the declared full scale
            speed = 3.0 + np.sin(np.arange(n) / 100.0)
            speed[rng.integers(0, n, 40)] = np.nan
            imu_flags = (rng.integers(0, 16, n) * (rng.random(n) < 0.02)).astype(np.int64)
    elif kind in ("wheel", "slide"):  # a wheel spinning up and landing every 2 s, the speed sometimes missing
        m = mo.make_motion("circle", n / 200.0, 200.0, imu_ahead_m=1.2)
        rng = np.random.default_rng(5)
        gyro = m.omega_b + 0.002 * rng.normal(size=(n, 3))
        accel = m.specific_force_b + 0.05 * rng.normal(size=(n, 3))
        mag = m.mag_b + 0.3 * rng.normal(size=(n, 3))
        speed = np.asarray(m.info["speed_mps"], dtype=np.float64).copy()
        phase = np.arange(n) % 400
        speed[phase < 30] += 0.1 * phase[phase < 30]  # spin-up at 20 m/s², then back at once
        speed[rng.integers(0, n, 10)] = np.nan
        if kind == "slide":  # 3.3 m/s² of the circle, 0.5 s in 2 s at 8.3 m/s² (beyond a_l = 5)
            accel[(phase >= 150) & (phase < 250), 1] += 5.0
    elif kind in ("magnet", "moving_start"):
        m = mo.make_motion(kind, n / 200.0, 200.0)
        gyro, accel, mag = m.omega_b.copy(), m.specific_force_b.copy(), m.mag_b.copy()
    else:
        m = mo.make_motion("static", n / 200.0, 200.0)
        gyro, accel, mag = m.omega_b + [0.02, -0.015, 0.01], m.specific_force_b.copy(), m.mag_b.copy()
        est.reset(q0=m.q_wb[0])
    kw = {}
    if speed is not None:
        kw["speed_mps"] = speed
    if imu_flags is not None:
        kw["imu_flags"] = imu_flags
    q, flags, bias, st = _reference(est, gyro, accel, mag, speed, imu_flags)
    out = est.update(gyro, accel, mag, **kw)
    np.testing.assert_array_equal(out.flags, flags)
    np.testing.assert_array_equal(out.q_wb, q)
    np.testing.assert_array_equal(out.gyro_bias_b, bias)
    np.testing.assert_array_equal(est.get_state().values, st)
    # the paths the case is for were taken
    for bit in (1 << k for k in range(31)):
        assert not must_flag & bit or np.any(flags & bit), bit
    assert (st[S["offset_started"]] == 1.0) == offset_runs
    # the offset's norm test ran wherever the offset is estimated and the test is on
    runs_test = params.get("estimate_mag_offset", True) and params.get("mag_offset_test_angle_rad", 1.0) != 0.0
    assert (st[S["offset_norm_test"] + 3] > 0.0) == runs_test
    assert kind != "moving_start" or st[S["heading_start_s"]] > 0.0  # the start in motion's path taken


def test_first_order_exponential_is_the_same_number():
    """Below _X_FIRST the terms in x² of e^{(0, r)/2} cannot change a rounded sum: the shortcut
    returns the full series' numbers exactly (and above it, the full series is used)."""
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.random(20000) * _X_FIRST, 10.0 ** rng.uniform(-30, np.log10(_X_FIRST), 20000),
                        rng.uniform(_X_FIRST, 1e-6, 2000)])
    d = rng.normal(size=(x.size, 3))
    r = d / np.linalg.norm(d, axis=1)[:, None] * (2.0 * np.sqrt(x))[:, None]  # (|r|/2)² = x
    for row in r:
        assert _qexp_fast(*row) == _qexp(*row)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 1e200, 0.0])
def test_input_checks_without_a_separate_finiteness_test(bad):
    """NaN, ±inf and overflowing squares fail the range comparisons themselves."""
    g, a, m = np.array([0.1, 0.2, 0.3]), np.array([0.1, 0.2, 9.8]), np.array([20.0, 1.0, -40.0])
    held = np.array([0.01, 0.02, 0.03])
    for which in range(3):
        args = [g.copy(), a.copy(), m.copy()]
        args[which][1] = bad
        want = _checks(args[0], args[1], args[2], held, 0, math.inf, math.inf)
        got = _input_checks(*args[0], *args[1], *args[2], *held, 0, math.inf, math.inf)
        assert got[0] == want[0] and tuple(got[1:4]) == tuple(want[1]) and got[4] == want[2] and got[6] == want[4]


@pytest.mark.parametrize("fs_hz", [100.0, 333.0, 1000.0])
def test_jitted_derivation_equals_the_python_reference_bit_for_bit(fs_hz):
    """``biso_plus_derive`` (numba, ``retune``'s kernel) writes ``biso_plus_coefficients``'
    numbers bit for bit, over random records (every real parameter scaled at random, both
    low-pass orders, the optional fields set or None); an invalid value writes nothing and
    names its index."""
    rng = np.random.default_rng(int(fs_hz))
    base = bp.BisoPlusParams()
    real = [name for name in bp._V_INDEX if name != "declination_rad"]
    for trial in range(40):
        changes = {name: getattr(base, name) * float(rng.uniform(0.2, 5.0)) for name in real}
        changes["tau_acc_s"] = 0.0 if trial == 0 else changes["tau_acc_s"]  # (no low-pass)
        changes["mag_dip_tol_rad"] = float(rng.uniform(0.01, 4.0))  # (both sides of π: the cosine or never)
        changes.update(declination_rad=float(rng.uniform(-0.5, 0.5)), tilt_lp_order=int(rng.integers(1, 3)),
                       accel_gate_free=None if trial % 2 else float(rng.uniform(0.1, 1.0)),
                       field_norm_ut=None if trial % 3 else float(rng.uniform(20.0, 60.0)),
                       dip_rad=None if trial % 4 else float(rng.uniform(-1.2, 1.2)),
                       estimate_mag_offset=bool(trial % 5), speed_point_b_m=tuple(rng.normal(0.0, 1.0, 3)),
                       gyro_range_rad_s=None if trial % 2 else 34.9, accel_range_mps2=None if trial % 3 else 78.4)
        p = dataclasses.replace(base, **changes)
        reference = bp.biso_plus_coefficients(p, fs_hz)
        derived = np.full_like(reference, 7.0)
        assert bp.biso_plus_derive(bp.biso_plus_values(p, fs_hz), derived) == -1
        assert derived.tobytes() == reference.tobytes(), trial
    values = bp.biso_plus_values(base, fs_hz)
    for name, bad in (("k_tilt", -1.0), ("accel_gate", 0.0), ("declination_rad", math.nan), ("tau_field_s", math.inf)):
        v, c = values.copy(), np.full(bp._C_SIZE, 7.0)
        v[bp._V_INDEX[name]] = bad
        assert bp.biso_plus_derive(v, c) == bp._V_INDEX[name] and np.all(c == 7.0)


def test_retune_by_the_kernel_is_set_params_and_refuses_as_it():
    """``retune`` of real parameters given as floats goes by the kernel: the record and the
    coefficients of ``set_params``; a bad value raises set_params' message and changes nothing."""
    a, b = make_estimator("biso_plus", 500.0), make_estimator("biso_plus", 500.0)
    for changes in ({"k_tilt": 3.0, "k_heading": 0.2, "tau_acc_s": 2.0}, {"declination_rad": 0.1}, {"k_tilt": 0.5}):
        a.retune(**changes)
        b.set_params(**changes)
        assert a.params == b.params and a.coefficients.tobytes() == b.coefficients.tobytes()
    params, coef = a.params, a.coefficients
    with pytest.raises(ValueError, match="k_tilt must be >= 0.0, got -1.0"):
        a.retune(k_tilt=-1.0, k_heading=0.3)
    with pytest.raises(ValueError, match="accel_gate must be > 0.0"):
        a.retune(accel_gate=0.0)
    assert a.params is params and a.coefficients.tobytes() == coef.tobytes()
