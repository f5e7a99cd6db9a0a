"""A slow, plain NumPy/SciPy twin of the GNSS-aided estimators (tests only).

Written from the equations in ``gnss_aided.py``'s docstring with independent machinery:
scipy rotations for the attitude and its Euler angles, the paper's GOST matrices
C_gb = R_y(ψ) R_z(ϑ) R_x(γ) and their derivatives for N, the exact Van Loan discretisation
(matrix exponential) for the covariance, full histories of the sums instead of a ring.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm
from scipy.spatial.transform import Rotation as Rot

from biso_cosim.estimators.gnss_aided import error_matrix


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a, d=False):
    c, s = math.cos(a), math.sin(a)
    if d:
        return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rx(a, d=False):
    c, s = math.cos(a), math.sin(a)
    if d:
        return np.array([[0.0, 0.0, 0.0], [0.0, -s, -c], [0.0, c, -s]])
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def gost_angles(r: Rot) -> tuple[float, float, float]:
    yaw, pitch, roll = r.as_euler("ZYX")
    return yaw - math.pi / 2, -pitch, roll


def from_gost(psi: float, theta: float, gamma: float) -> Rot:
    return Rot.from_euler("ZYX", [psi + math.pi / 2, -theta, gamma])


def n_matrix(r: Rot, f_b: np.ndarray) -> np.ndarray:
    """(3, 2) ∂(C f)/∂(ϑ, γ) in ENU from the GOST matrices (N-U-E → E-N-U)."""
    psi, th, ga = gost_angles(r)
    fg = np.array([f_b[0], f_b[2], -f_b[1]])
    cols = []
    for dc in (_ry(psi) @ _rz(th, True) @ _rx(ga), _ry(psi) @ _rz(th) @ _rx(ga, True)):
        v = dc @ fg
        cols.append([v[2], v[0], v[1]])
    return np.array(cols).T


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def reference_run(params, fs, q0, gyro, accel, mag, fixes, exact=True):
    """q (N, 4) of the estimator ``params`` started at ``q0``, with ``fixes`` rows
    (t_s, t_arrival, v_e, v_n, v_u) (all valid, sorted); clean IMU samples assumed. The
    covariance step is Van Loan's exact one, or (``exact=False``) its second-order expansion."""
    from biso_cosim.estimators.gnss_aided import GnssKalmanParams

    kalman = isinstance(params, GnssKalmanParams)
    h = 1.0 / fs
    soft_inv = np.linalg.inv(np.eye(3) if params.mag_soft_iron is None else np.asarray(params.mag_soft_iron))
    hard = np.zeros(3) if params.mag_hard_iron_ut is None else np.asarray(params.mag_hard_iron_ut)
    k_head = 0.0 if math.isinf(params.t2_s) else 1.0 - math.exp(-h / params.t2_s)
    up = np.array([0.0, 0.0, params.gravity_mps2])
    r = Rot.from_quat(np.roll(q0, -1))
    b = np.zeros(3)
    if kalman:
        sd2 = params.drift_sigma_rad_s ** 2
        p = np.diag([params.angle_sigma0_rad ** 2] * 2 + [sd2] * 3)
        tau = params.drift_tau_s
        sv = params.gnss_vel_sigma_mps
        vel_var = np.array([sv[0] ** 2, sv[0] ** 2, sv[1] ** 2])
    s_sum, n_sum = np.zeros(3), np.zeros(6)
    hist_t, hist_s, hist_n = [], [], []
    anchor = None  # (t, v, S, NS)
    unaided = None
    last_aided = -1e300
    out = np.empty((gyro.shape[0], 4))
    fi = 0

    def apply(delta):
        """The tilt correction δ = (dϑ, dγ), and the stored sums re-expressed with it."""
        nonlocal r
        psi, th, ga = gost_angles(r)
        r = from_gost(psi, th + delta[0], ga + delta[1])
        now = n_sum.reshape(2, 3).T @ delta
        for j in range(len(hist_s)):
            hist_s[j] = hist_s[j] + hist_n[j].reshape(2, 3).T @ delta - now
        for anc in (anchor, unaided):
            if anc is not None:
                anc[2] = anc[2] + anc[3].reshape(2, 3).T @ delta - now

    def measure(dt, z, nbar, fbar, gnss):
        """The correction (dϑ, dγ) of one window, or None when the gate refuses it."""
        nonlocal p, b
        if not kalman:
            e = -np.linalg.pinv(nbar) @ z
            t1 = params.t1_s if gnss else params.t1_unaided_s
            return -(1.0 - math.exp(-dt / t1)) * e
        hm = np.zeros((3, 5))
        hm[:, :2] = -nbar
        rm = np.diag((2 * vel_var / dt ** 2) if gnss else np.full(3, params.unaided_accel_sigma_mps2 ** 2))
        rm += np.eye(3) * (params.accel_noise_density ** 2 / dt + params.accel_sigma_mps2 ** 2)
        n0 = np.cross([0.0, 0.0, 1.0], fbar)
        rm += params.heading_sigma_rad ** 2 * np.outer(n0, n0)
        s = hm @ p @ hm.T + rm
        if z @ np.linalg.solve(s, z) > params.gate:
            return None
        k = p @ hm.T @ np.linalg.inv(s)
        if not gnss:
            k[2:] = 0.0
        x = k @ z
        ikh = np.eye(5) - k @ hm
        p = ikh @ p @ ikh.T + k @ rm @ k.T
        b = b + np.array([x[2], -x[4], x[3]])
        return -x[:2]

    for i in range(gyro.shape[0]):
        t = params.t0_s + i * h
        if i > 0:
            w = gyro[i] - b
            r = r * Rot.from_rotvec(w * h)
            if kalman:
                _, th, ga = gost_angles(r)
                f = error_matrix(th, ga, [w[0], w[2], -w[1]], tau)
                g = np.zeros((5, 6))
                g[0, 1:3] = f[0, 3:5]
                g[1, 0], g[1, 1:3] = 1.0, f[1, 3:5]
                g[2:, 3:] = np.eye(3)
                qc = np.diag([params.gyro_noise_density ** 2] * 3 + [2 * sd2 / tau] * 3)
                gq = g @ qc @ g.T
                if exact:
                    vl = expm(np.block([[-f, gq], [np.zeros((5, 5)), f.T]]) * h)
                    phi, qd = vl[5:, 5:].T, vl[5:, 5:].T @ vl[:5, 5:]
                else:
                    phi = np.eye(5) + f * h + f @ f * h * h / 2
                    qd = gq * h + (f @ gq + gq @ f.T) * h * h / 2
                p = phi @ p @ phi.T + qd
                b = b * math.exp(-h / tau)
        if i > 0:  # the first sample is q0 exactly
            bw = r.apply(soft_inv @ (mag[i] - hard))
            r = Rot.from_rotvec([0.0, 0.0, k_head * _wrap(math.atan2(bw[0], bw[1]) - params.declination_rad)]) * r
        if i == 0:
            hist_t.append(t - 0.5 * h - params.imu_delay_s)
            hist_s.append(s_sum.copy())
            hist_n.append(n_sum.copy())
        s_sum = s_sum + r.apply(accel[i]) * h
        n_sum = n_sum + n_matrix(r, accel[i]).T.ravel() * h
        hist_t.append(t + 0.5 * h - params.imu_delay_s)
        hist_s.append(s_sum.copy())
        hist_n.append(n_sum.copy())
        while i > 0 and fi < len(fixes) and fixes[fi][1] <= t + 1e-9:
            ts, v = fixes[fi][0], np.asarray(fixes[fi][2:5], dtype=float)
            fi += 1
            hs, hn = np.array(hist_s), np.array(hist_n)
            s_j = np.array([np.interp(ts, hist_t, hs[:, a]) for a in range(3)])
            n_j = np.array([np.interp(ts, hist_t, hn[:, a]) for a in range(6)])
            last_aided, unaided = t, None
            if anchor is not None and ts - anchor[0] <= params.max_interval_s:
                dt = ts - anchor[0]
                if dt < params.window_s - 1e-9:
                    continue
                z = (v - anchor[1]) / dt + up - (s_j - anchor[2]) / dt
                delta = measure(dt, z, ((n_j - anchor[3]) / dt).reshape(2, 3).T, (s_j - anchor[2]) / dt, True)
                if delta is None:
                    continue  # the gate keeps the old anchor
                anchor = [ts, v, s_j, n_j]
                apply(delta)
            else:
                anchor = [ts, v, s_j, n_j]
        if i == 0:
            pass
        elif t - last_aided > params.max_interval_s and params.unaided != "gyro" and not (
                params.unaided == "coast" and t - last_aided <= params.coast_s):
            if unaided is None:
                unaided = [t, None, s_sum.copy(), n_sum.copy()]
            elif t - unaided[0] >= params.window_s - 1e-9:
                dt = t - unaided[0]
                fbar = (s_sum - unaided[2]) / dt
                delta = measure(dt, up - fbar, ((n_sum - unaided[3]) / dt).reshape(2, 3).T, fbar, False)
                unaided = [t, None, s_sum.copy(), n_sum.copy()]
                if delta is not None:
                    apply(delta)
        elif t - last_aided > params.max_interval_s:
            unaided = None
        out[i] = np.roll(r.as_quat(), 1)
    return out
