"""DCM with proportional-integral drift correction: the baseline the BISO paper compares with.

Premerlani W., Bizard P. (2009), *Direction Cosine Matrix IMU: Theory* (Aleshkin et al. 2024,
ref. [8]). The direction cosine matrix R (body → ENU here) is integrated from the corrected
gyro rate, ``R ← R (I + [ω_c h]×)`` (their eq. 17, first order), then renormalised (their
eqs. 18–21: the orthogonality error of the first two rows is shared between them, the third
row is their cross product, each row is scaled by the Taylor step ½(3 − r·r)). The drift
correction is a PI controller on two error vectors in body axes:

* roll–pitch: ``e_rp = f̂ × r_z`` with f̂ the unit specific force and r_z the third row of R
  (world up in body axes), weighted by ``clamp(1 − 2|1 − |f|/g|, 0, 1)`` (their
  acceleration-dependent weighting);
* yaw: the sine of the angle between the horizontal magnetic field (in world axes, with the
  declination) and magnetic north, along r_z.

``ω_c = ω + k_P e + ω_I``, ``ω_I ← ω_I + k_I e h`` (their eqs. 25–27); the bias estimate is −ω_I.
The first valid sample initialises R from the accelerometer and magnetometer (TRIAD).
Gains are in SI (1/s, 1/s²); P&B's numbers depend on their sensor units and rates.

Input policy as the faithful BISO (flags GYRO_INVALID, ACCEL_INVALID, MAG_INVALID,
UNINITIALIZED; output never NaN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators._base import (
    Estimator,
    accel_range_param,
    check_finite,
    gyro_range_param,
    layout_offsets,
    param,
    saturation_limits,
)
from biso_cosim.estimators._kernels import _input_checks
from biso_cosim.estimators.reference import _ref_triad
from biso_cosim.frames import _mat_from_q, _q_from_mat
from biso_cosim.units import G0

__all__ = ["DcmPiParams", "DcmPiEstimator"]


@dataclass(frozen=True)
class DcmPiParams:
    """Parameters of the DCM PI baseline (each documented once, here)."""

    kp_rp: float = param(1.0, symbol="K_P,rp", unit="1/s", doc="proportional gain of the roll–pitch correction",
                         source="Premerlani & Bizard (2009) eq. 26; second-order loop ω_n = 0.2 rad/s, ζ = 2.5")
    ki_rp: float = param(0.04, symbol="K_I,rp", unit="1/s²", doc="integral gain of the roll–pitch correction",
                         source="as above")
    kp_yaw: float = param(1.0, symbol="K_P,y", unit="1/s", doc="proportional gain of the yaw correction",
                          source="as above")
    ki_yaw: float = param(0.04, symbol="K_I,y", unit="1/s²", doc="integral gain of the yaw correction",
                          source="as above")
    integral_limit_rad_s: float = param(0.2, symbol="|ω_I|max", unit="rad/s",
                                        doc="bound of the integral term (anti-windup)", source="assumption")
    gravity_mps2: float = param(G0, symbol="g", unit="m/s²", doc="gravity of the acceleration weighting", source="")
    declination_rad: float = param(0.0, symbol="D", unit="rad", doc="magnetic declination, east positive",
                                   source="")
    gyro_range_rad_s: float | None = gyro_range_param()
    accel_range_mps2: float | None = accel_range_param()


_COEF_LAYOUT = (("h", 1), ("kp_rp", 1), ("ki_rp", 1), ("kp_yaw", 1), ("ki_yaw", 1), ("i_limit", 1), ("g", 1),
                ("sd", 1), ("cd", 1), ("cdh", 1), ("sdh", 1), ("gyro_limit", 1), ("accel_limit", 1))
_C = layout_offsets(_COEF_LAYOUT)
(_C_H, _C_KPRP, _C_KIRP, _C_KPY, _C_KIY, _C_ILIM, _C_G, _C_SD, _C_CD, _C_CDH, _C_SDH, _C_GLIM, _C_ALIM) = (
    _C[name] for name, _ in _COEF_LAYOUT)
_C_SIZE = _C["_size"]
STATE_LAYOUT = (("initialized", 1), ("lam", 4), ("dcm", 9), ("omega_i", 3), ("gyro_hold", 3))
_S = layout_offsets(STATE_LAYOUT)
_S_INIT, _S_LAM, _S_R, _S_WI, _S_GYRO = (_S[name] for name, _ in STATE_LAYOUT)
_S_SIZE = _S["_size"]


def dcm_pi_coefficients(p: DcmPiParams, fs_hz: float) -> np.ndarray:
    c = np.zeros(_C_SIZE)
    c[_C_H] = 1.0 / fs_hz
    for idx, name in ((_C_KPRP, "kp_rp"), (_C_KIRP, "ki_rp"), (_C_KPY, "kp_yaw"), (_C_KIY, "ki_yaw"),
                      (_C_ILIM, "integral_limit_rad_s")):
        c[idx] = check_finite(name, getattr(p, name), low=0.0)
    c[_C_G] = check_finite("gravity_mps2", p.gravity_mps2, low=0.0, low_open=True)
    d = check_finite("declination_rad", p.declination_rad)
    c[_C_SD], c[_C_CD], c[_C_CDH], c[_C_SDH] = math.sin(d), math.cos(d), math.cos(0.5 * d), math.sin(0.5 * d)
    c[_C_GLIM], c[_C_ALIM] = saturation_limits(p)
    return c


def dcm_pi_initial_state(q0: np.ndarray | None) -> np.ndarray:
    st = np.zeros(_S_SIZE)
    st[_S_LAM] = 1.0
    st[_S_R:_S_R + 9] = np.eye(3).ravel()
    if q0 is not None:
        st[_S_INIT] = 2.0
        st[_S_LAM:_S_LAM + 4] = q0
        st[_S_R:_S_R + 9] = np.array(_mat_from_q(*q0))
    return st


@jit(error_model="numpy")
def _dcm_batch(c, st, gyro, accel, mag, imu_flags, q_out, flags_out, bias_out):
    """The DCM update over every row; the state is held in local variables over the loop."""
    n = gyro.shape[0]
    has_flags = imu_flags.shape[0] == n
    h = c[_C_H]
    kprp, kirp, kpy, kiy, lim, g0 = c[_C_KPRP], c[_C_KIRP], c[_C_KPY], c[_C_KIY], c[_C_ILIM], c[_C_G]
    sd, cd = c[_C_SD], c[_C_CD]
    init = st[_S_INIT]
    lw, lx, ly, lz = st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3]
    # rows of R (body → world): (r0, r1, r2) east, (r3, r4, r5) north, (r6, r7, r8) up, in body axes
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = (st[_S_R], st[_S_R + 1], st[_S_R + 2], st[_S_R + 3], st[_S_R + 4],
                                          st[_S_R + 5], st[_S_R + 6], st[_S_R + 7], st[_S_R + 8])
    wix, wiy, wiz = st[_S_WI], st[_S_WI + 1], st[_S_WI + 2]
    hx, hy, hz = st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2]
    for i in range(n):
        sf = imu_flags[i] if has_flags else 0
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
        flags, gx, gy, gz, acc_ok, f2, mag_ok, ex, ey, ez, e2 = _input_checks(
            gyro[i, 0], gyro[i, 1], gyro[i, 2], ax, ay, az, mx, my, mz, hx, hy, hz, sf, c[_C_GLIM], c[_C_ALIM])
        hx, hy, hz = gx, gy, gz
        if init == 0.0 and acc_ok:  # the first valid sample: R from the accelerometer and magnetometer
            lw, lx, ly, lz = _ref_triad(ax, ay, az, f2, ex, ey, ez, e2, mag_ok, 1.0, 0.0, 0.0, 0.0,
                                        c[_C_CDH], c[_C_SDH])
            r0, r1, r2, r3, r4, r5, r6, r7, r8 = _mat_from_q(lw, lx, ly, lz)
            init = 1.0
        elif init == 0.0:
            flags |= fl.UNINITIALIZED
        elif init == 2.0:  # q0 from reset(): the attitude at this sample
            init = 1.0
        else:
            px = py = pz = 0.0  # ω_P = K_P e (body axes)
            ix = iy = iz = 0.0  # K_I e
            if acc_ok:
                # roll–pitch error f̂ × r_z, weighted by the closeness of |f| to g
                fn = math.sqrt(f2)
                wgt = min(max(1.0 - 2.0 * abs(1.0 - fn / g0), 0.0), 1.0)
                fx, fy, fz = ax / fn, ay / fn, az / fn
                ux = wgt * (fy * r8 - fz * r7)
                uy = wgt * (fz * r6 - fx * r8)
                uz = wgt * (fx * r7 - fy * r6)
                px, py, pz = kprp * ux, kprp * uy, kprp * uz
                ix, iy, iz = kirp * ux, kirp * uy, kirp * uz
            if mag_ok:
                # field in world axes; its horizontal direction against magnetic north (sin D, cos D)
                we = r0 * mx + r1 * my + r2 * mz
                wn = r3 * mx + r4 * my + r5 * mz
                hn = math.sqrt(we * we + wn * wn)
                if hn > 0.0:
                    # sine of the turn about Up (r_z in body axes) that brings the field to D
                    sy = (we * cd - wn * sd) / hn
                    px, py, pz = px + kpy * sy * r6, py + kpy * sy * r7, pz + kpy * sy * r8
                    ix, iy, iz = ix + kiy * sy * r6, iy + kiy * sy * r7, iz + kiy * sy * r8
            wix = min(max(wix + ix * h, -lim), lim)
            wiy = min(max(wiy + iy * h, -lim), lim)
            wiz = min(max(wiz + iz * h, -lim), lim)
            wx, wy, wz = (gx + px + wix) * h, (gy + py + wiy) * h, (gz + pz + wiz) * h
            # R ← R (I + [w]×), then the renormalisation of P&B eqs. 18–21 on the rows X, Y
            n0, n1, n2 = r0 + r1 * wz - r2 * wy, r1 + r2 * wx - r0 * wz, r2 + r0 * wy - r1 * wx
            n3, n4, n5 = r3 + r4 * wz - r5 * wy, r4 + r5 * wx - r3 * wz, r5 + r3 * wy - r4 * wx
            err = n0 * n3 + n1 * n4 + n2 * n5
            x0, x1, x2 = n0 - 0.5 * err * n3, n1 - 0.5 * err * n4, n2 - 0.5 * err * n5
            y0, y1, y2 = n3 - 0.5 * err * n0, n4 - 0.5 * err * n1, n5 - 0.5 * err * n2
            z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
            sx = 0.5 * (3.0 - (x0 * x0 + x1 * x1 + x2 * x2))
            sy_ = 0.5 * (3.0 - (y0 * y0 + y1 * y1 + y2 * y2))
            sz = 0.5 * (3.0 - (z0 * z0 + z1 * z1 + z2 * z2))
            r0, r1, r2 = x0 * sx, x1 * sx, x2 * sx
            r3, r4, r5 = y0 * sy_, y1 * sy_, y2 * sy_
            r6, r7, r8 = z0 * sz, z1 * sz, z2 * sz
            qw, qx, qy, qz = _q_from_mat(r0, r1, r2, r3, r4, r5, r6, r7, r8)
            if qw * lw + qx * lx + qy * ly + qz * lz < 0.0:  # keep the quaternion's sign continuous
                qw, qx, qy, qz = -qw, -qx, -qy, -qz
            lw, lx, ly, lz = qw, qx, qy, qz
        flags_out[i] = flags
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = lw, lx, ly, lz
        bias_out[i, 0], bias_out[i, 1], bias_out[i, 2] = -wix, -wiy, -wiz
    st[_S_INIT] = init
    st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3] = lw, lx, ly, lz
    st[_S_R], st[_S_R + 1], st[_S_R + 2], st[_S_R + 3], st[_S_R + 4] = r0, r1, r2, r3, r4
    st[_S_R + 5], st[_S_R + 6], st[_S_R + 7], st[_S_R + 8] = r5, r6, r7, r8
    st[_S_WI], st[_S_WI + 1], st[_S_WI + 2] = wix, wiy, wiz
    st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2] = hx, hy, hz


@jit
def _dcm_loop(arrays, samples):
    """DCM-PI on a period's samples (``biso_cosim.loop``): ``update`` with the sensor's flags
    as ``imu_flags``."""
    k = samples.gyro_b.shape[0]
    _dcm_batch(arrays.coef, arrays.state, samples.gyro_b, samples.accel_b, samples.mag_b, samples.imu_flags,
               arrays.q_wb[:k], arrays.flags[:k], arrays.gyro_bias_b[:k])


class DcmPiEstimator(Estimator):
    """DCM with PI drift correction (Premerlani & Bizard 2009); see the module docstring."""

    method = "dcm_pi"
    Params = DcmPiParams
    state_layout = STATE_LAYOUT
    estimates_bias = True
    inputs = ("imu_flags",)
    loop_kernel = _dcm_loop

    def _coefficients(self, params: DcmPiParams, fs_hz: float) -> np.ndarray:
        return dcm_pi_coefficients(params, fs_hz)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        return dcm_pi_initial_state(q0)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:
        _dcm_batch(coef, state, gyro, accel, mag, extra["imu_flags"], q_out, flags, bias)
