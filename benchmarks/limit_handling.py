"""biso_plus at the handling limit: a hard driver (``vehicle.handling.limit_drive``: pure pursuit
with a short look-ahead, full throttle or full brake) on a route at 9 m/s² of lateral
acceleration, beyond the tyres' linear range; biso_plus in the loop with the wheel odometry
(the front wheels × radius × cos steer, as ``biso-cosim run``) and the car's parameters, once
with the car's linear range a_l (the guard) and once without (a_l = 0, as before); VQF and
imufusion on the same IMU stream (as ``biso-cosim compare`` runs them). Then the error of each
term of biso_plus's compensation of the vehicle's acceleration against the true motion.

    nice python benchmarks/limit_handling.py                    # figure8, 40 s (about 30 s wall)
    nice python benchmarks/limit_handling.py --route slalom --duration 60 --speed 16

Prints two Markdown tables (docs/vehicle.md, "At the limit").
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.signal import lfilter

from biso_cosim import peers
from biso_cosim.estimators import make_estimator
from biso_cosim.frames import quat_conjugate, quat_rotate
from biso_cosim.metrics import angle_errors_deg
from biso_cosim.units import G0
from biso_cosim.vehicle.handling import limit_drive


def _lp(x: np.ndarray, fs: float, tau: float) -> np.ndarray:
    """First-order low-pass of time constant tau (s) along axis 0, started at x[0]."""
    a = 1.0 - math.exp(-1.0 / (fs * tau))
    return lfilter([a], [1.0, a - 1.0], x, axis=0, zi=(1.0 - a) * x[:1])[0]


def _ddt(x: np.ndarray, fs: float) -> np.ndarray:
    return np.concatenate([np.zeros_like(x[:1]), np.diff(x, axis=0)]) * fs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--route", default="figure8")
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--speed", type=float, default=14.0)
    ap.add_argument("--lateral", type=float, default=9.0)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    sim, res, cmds = limit_drive(a.route, duration_s=a.duration, speed_mps=a.speed, lateral_accel_mps2=a.lateral,
                                 seed=a.seed)
    fs = float(res.sensor["output_rate_hz"])
    decl = math.radians(res.site["declination_deg"])
    gyro, accel, mag = res.imu.gyro_b, res.imu.accel_b, res.imu.mag_b
    odo = sim.odometry_mps(res.truth)
    vp = sim.vehicle.estimator_defaults()
    truth = res.truth
    print(f"{a.route}, {a.duration:g} s, seed {a.seed}: lateral specific force up to "
          f"{np.abs(truth.specific_force_b[:, 1]).max():.1f} m/s² (a_l = {vp['linear_accel_mps2']:.2f} m/s²), "
          f"speed up to {truth.speed_mps.max():.1f} m/s\n")
    no_guard = make_estimator("biso_plus", fs, declination_rad=decl, **(vp | {"linear_accel_mps2": 0.0}))
    methods = {
        "biso_plus (a_l of the car)": res.estimates["biso_plus"][0],
        "biso_plus a_l = 0 (no guard)": no_guard.update(gyro, accel, mag, speed_mps=odo).q_wb,
        "vqf": peers.vqf(gyro, accel, mag, fs, decl),
        "imufusion": peers.imufusion(gyro, accel, mag, fs, decl, gyroscope_range=250.0),
    }
    print("| method | roll RMS / max ° | pitch RMS / max ° | heading RMS / max ° |")
    print("|---|---|---|---|")
    for name, q in methods.items():
        e = angle_errors_deg(q, truth.q_wb)
        print(f"| {name} | " + " | ".join(f"{np.sqrt(np.mean(e[k] ** 2)):.2f} / {np.max(np.abs(e[k])):.2f}"
                                          for k in ("roll", "pitch", "heading")) + " |")

    # the compensation's terms against the truth (biso_plus's model: rear axle at r_v with the
    # speed v = odometry and the sideslip v_y = −(D_r/g₀)|v| f_y; all low-passed as in the kernel)
    w = truth.omega_b
    d = -np.asarray(vp["speed_point_b_m"])
    d_r = vp["rear_slip_gradient_rad_per_g"] / G0
    u_true = quat_rotate(quat_conjugate(truth.q_wb), truth.vel_w)
    v_axle = u_true - np.cross(w, d)  # the rear axle's velocity, body axes
    tau = 0.05
    fy_lp = _lp(accel[:, 1], fs, tau)
    vy = -d_r * np.abs(odo) * fy_lp
    zero = np.zeros_like(odo)
    terms = {
        "odometry's v̇ (front wheels braked beyond their peak slip)":
            np.c_[_lp(_ddt(odo, fs), fs, tau) - _lp(_ddt(v_axle[:, 0], fs), fs, tau), zero, zero],
        "ω × odometry's speed error (front slip angle, cos steer, braking slip)":
            np.cross(w, np.c_[odo - v_axle[:, 0], zero, zero]),
        "ω × sideslip velocity error (model D_r f_y against the true v_y)": np.cross(w, np.c_[zero, vy - v_axle[:, 1], zero]),
        "sideslip rate error (model's v̇_y against the true)":
            np.c_[zero, _lp(_ddt(vy, fs), fs, tau) - _lp(_ddt(v_axle[:, 1], fs), fs, tau), zero],
        "the axle's vertical velocity (heave, pitch; taken as 0)":
            np.cross(w, np.c_[zero, zero, -v_axle[:, 2]]) + np.c_[zero, zero, -_lp(_ddt(v_axle[:, 2], fs), fs, tau)],
    }
    moving = v_axle[:, 0] > 3.0
    print("\nCompensation error per term, m/s², low-passed with τ_av = 1 s (the tilt low-pass), "
          "over the samples at > 3 m/s; x / y / z body axes:\n")
    print("| term | RMS x / y / z | largest x / y / z |")
    print("|---|---|---|")
    for name, e in terms.items():
        e1 = np.stack([_lp(e[:, k], fs, 1.0) for k in range(3)], -1)[moving]
        print(f"| {name} | " + " / ".join(f"{x:.2f}" for x in np.sqrt(np.mean(e1 ** 2, 0))) + " | "
              + " / ".join(f"{x:.2f}" for x in np.abs(e1).max(0)) + " |")
    beta = np.degrees(np.arctan2(v_axle[:, 1], v_axle[:, 0]))[moving]
    beta_m = np.degrees(np.arctan2(vy, np.abs(odo)))[moving]
    print(f"\nrear axle's slip angle at > 3 m/s: true RMS {np.sqrt(np.mean(beta ** 2)):.1f}°, largest "
          f"{np.abs(beta).max():.1f}°; the model's RMS {np.sqrt(np.mean(beta_m ** 2)):.1f}°, largest "
          f"{np.abs(beta_m).max():.1f}°")
    err = (odo - v_axle[:, 0])[moving]
    brake = np.repeat(cmds[:, 2], int(round(fs / sim.vehicle.control_rate_hz)))[:len(odo)][moving] > 0.0
    print(f"odometry − the rear axle's forward speed: RMS {np.sqrt(np.mean(err ** 2)):.2f} m/s, largest "
          f"{np.abs(err).max():.2f} m/s; braking ({100 * brake.mean():.0f} % of the time) RMS "
          f"{np.sqrt(np.mean(err[brake] ** 2)):.2f} m/s, otherwise {np.sqrt(np.mean(err[~brake] ** 2)):.2f} m/s")


if __name__ == "__main__":
    main()
