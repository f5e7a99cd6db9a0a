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
from biso_cosim.estimators._base import Estimator, check_finite, param
from biso_cosim.estimators.biso import _input_checks
from biso_cosim.estimators.reference import _ref_vector
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


_C_H, _C_KPRP, _C_KIRP, _C_KPY, _C_KIY, _C_ILIM, _C_G, _C_SD, _C_CD, _C_CDH, _C_SDH = range(11)
_C_SIZE = 11
STATE_LAYOUT = (("initialized", 1), ("lam", 4), ("dcm", 9), ("omega_i", 3), ("gyro_hold", 3))
_S_INIT, _S_LAM, _S_R, _S_WI, _S_GYRO = 0, 1, 5, 14, 17
_S_SIZE = 20


def dcm_pi_coefficients(p: DcmPiParams, fs_hz: float) -> np.ndarray:
    c = np.zeros(_C_SIZE)
    c[_C_H] = 1.0 / fs_hz
    for idx, name in ((_C_KPRP, "kp_rp"), (_C_KIRP, "ki_rp"), (_C_KPY, "kp_yaw"), (_C_KIY, "ki_yaw"),
                      (_C_ILIM, "integral_limit_rad_s")):
        c[idx] = check_finite(name, getattr(p, name), low=0.0)
    c[_C_G] = check_finite("gravity_mps2", p.gravity_mps2, low=0.0, low_open=True)
    d = check_finite("declination_rad", p.declination_rad)
    c[_C_SD], c[_C_CD], c[_C_CDH], c[_C_SDH] = math.sin(d), math.cos(d), math.cos(0.5 * d), math.sin(0.5 * d)
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


@jit
def _dcm_step(c, st, gx, gy, gz, ax, ay, az, mx, my, mz):
    flags, gx, gy, gz, acc_ok, fn, mag_ok = _input_checks(st, _S_GYRO, gx, gy, gz, ax, ay, az, mx, my, mz)
    if st[_S_INIT] != 1.0:
        if st[_S_INIT] == 0.0:
            if not acc_ok:
                return flags | fl.UNINITIALIZED
            q = _ref_vector(ax / fn, ay / fn, az / fn, mx, my, mz, mag_ok, 1.0, 0.0, 0.0, 0.0, c[_C_CDH], c[_C_SDH])
            r = _mat_from_q(q[0], q[1], q[2], q[3])
            for i in range(9):
                st[_S_R + i] = r[i]
            for i in range(4):
                st[_S_LAM + i] = q[i]
        st[_S_INIT] = 1.0
        return flags
    h = c[_C_H]
    r = st[_S_R:_S_R + 9]  # rows of R (body → world): r[0:3] east, r[3:6] north, r[6:9] up in body
    ex = ey = ez = 0.0  # ω_P = K_P e (body axes)
    ix = iy = iz = 0.0  # K_I e
    if acc_ok:
        # roll–pitch error f̂ × r_z, weighted by the closeness of |f| to g
        wgt = min(max(1.0 - 2.0 * abs(1.0 - fn / c[_C_G]), 0.0), 1.0)
        fx, fy, fz = ax / fn, ay / fn, az / fn
        px = wgt * (fy * r[8] - fz * r[7])
        py = wgt * (fz * r[6] - fx * r[8])
        pz = wgt * (fx * r[7] - fy * r[6])
        ex, ey, ez = c[_C_KPRP] * px, c[_C_KPRP] * py, c[_C_KPRP] * pz
        ix, iy, iz = c[_C_KIRP] * px, c[_C_KIRP] * py, c[_C_KIRP] * pz
    if mag_ok:
        # field in world axes; its horizontal direction against magnetic north (sin D, cos D)
        wx_ = r[0] * mx + r[1] * my + r[2] * mz
        wy_ = r[3] * mx + r[4] * my + r[5] * mz
        hn = math.sqrt(wx_ * wx_ + wy_ * wy_)
        if hn > 0.0:
            # sine of the turn about Up (r_z in body axes) that brings the field to D
            s = (wx_ * c[_C_CD] - wy_ * c[_C_SD]) / hn
            ex += c[_C_KPY] * s * r[6]
            ey += c[_C_KPY] * s * r[7]
            ez += c[_C_KPY] * s * r[8]
            ix += c[_C_KIY] * s * r[6]
            iy += c[_C_KIY] * s * r[7]
            iz += c[_C_KIY] * s * r[8]
    lim = c[_C_ILIM]
    st[_S_WI] = min(max(st[_S_WI] + ix * h, -lim), lim)
    st[_S_WI + 1] = min(max(st[_S_WI + 1] + iy * h, -lim), lim)
    st[_S_WI + 2] = min(max(st[_S_WI + 2] + iz * h, -lim), lim)
    wx, wy, wz = (gx + ex + st[_S_WI]) * h, (gy + ey + st[_S_WI + 1]) * h, (gz + ez + st[_S_WI + 2]) * h
    # R ← R (I + [w]×)
    n = np.empty(9)
    for i in range(3):
        a, b, d = r[3 * i], r[3 * i + 1], r[3 * i + 2]
        n[3 * i] = a + b * wz - d * wy
        n[3 * i + 1] = b + d * wx - a * wz
        n[3 * i + 2] = d + a * wy - b * wx
    # renormalisation (P&B eqs. 18–21) on the rows X = n[0:3], Y = n[3:6]
    err = n[0] * n[3] + n[1] * n[4] + n[2] * n[5]
    x0, x1, x2 = n[0] - 0.5 * err * n[3], n[1] - 0.5 * err * n[4], n[2] - 0.5 * err * n[5]
    y0, y1, y2 = n[3] - 0.5 * err * n[0], n[4] - 0.5 * err * n[1], n[5] - 0.5 * err * n[2]
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    sx = 0.5 * (3.0 - (x0 * x0 + x1 * x1 + x2 * x2))
    sy = 0.5 * (3.0 - (y0 * y0 + y1 * y1 + y2 * y2))
    sz = 0.5 * (3.0 - (z0 * z0 + z1 * z1 + z2 * z2))
    r[0], r[1], r[2] = x0 * sx, x1 * sx, x2 * sx
    r[3], r[4], r[5] = y0 * sy, y1 * sy, y2 * sy
    r[6], r[7], r[8] = z0 * sz, z1 * sz, z2 * sz
    q = _q_from_mat(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8])
    # keep the quaternion's sign continuous
    if q[0] * st[_S_LAM] + q[1] * st[_S_LAM + 1] + q[2] * st[_S_LAM + 2] + q[3] * st[_S_LAM + 3] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    for i in range(4):
        st[_S_LAM + i] = q[i]
    return flags


@jit
def _dcm_batch(c, st, gyro, accel, mag, q_out, flags_out, bias_out):
    for i in range(gyro.shape[0]):
        flags_out[i] = _dcm_step(c, st, gyro[i, 0], gyro[i, 1], gyro[i, 2], accel[i, 0], accel[i, 1], accel[i, 2],
                                 mag[i, 0], mag[i, 1], mag[i, 2])
        for j in range(4):
            q_out[i, j] = st[_S_LAM + j]
        for j in range(3):
            bias_out[i, j] = -st[_S_WI + j]


class DcmPiEstimator(Estimator):
    """DCM with PI drift correction (Premerlani & Bizard 2009); see the module docstring."""

    method = "dcm_pi"
    Params = DcmPiParams
    state_layout = STATE_LAYOUT
    estimates_bias = True

    def _coefficients(self, params: DcmPiParams, fs_hz: float) -> np.ndarray:
        return dcm_pi_coefficients(params, fs_hz)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        return dcm_pi_initial_state(q0)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:
        _dcm_batch(coef, state, gyro, accel, mag, q_out, flags, bias)
