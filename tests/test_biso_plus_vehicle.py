"""biso_plus on the car with slip-based tyres (issue 26): the two things the tyres do to its
speed input, each driven on a short route of the co-simulation.

* Wheel slip: over corrugations (80 m of 0.8 m waves, 2 cm, at 12 m/s: 15 Hz, the wheel-hop band)
  the driven rear wheels leave the road, spin up under the drive torque and are pulled back
  when they land; the wheel odometry then changes at tens of m/s², which the car's body (and
  its accelerometer) does not. Compensated with that v̇, the tilt reference pitches by tens
  of degrees; detected (v̇ against the accelerometer's forward specific force) it does not.
* Sideslip: in a steady bend the rear axle slides outward by its slip angle, α_r = D_r·a_y/g
  (single-track model), so the velocity of the rear axle is not (v, 0, 0); the missing
  −ω_z·v_y tilts the compensated specific force in pitch by ω_z v_y/g.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

from biso_cosim.cosim import run_route
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators import make_estimator
from biso_cosim.frames import quat_conjugate, quat_rotate
from biso_cosim.metrics import angle_errors_deg
from biso_cosim.routes.route import parse_route
from biso_cosim.units import G0
from biso_cosim.vehicle.model import car_spec, vehicle_parameters
from biso_cosim.vehicle.tyres import TYRES

WASHBOARD_X_M = (100.0, 180.0)


def _lp(x: np.ndarray, fs_hz: float, tau_s: float) -> np.ndarray:
    """First-order low-pass of time constant tau_s (s) along axis 0, started at x[0]."""
    a = 1.0 - math.exp(-1.0 / (fs_hz * tau_s))
    return lfilter([a], [1.0, a - 1.0], x, axis=0, zi=(1.0 - a) * x[:1])[0]


def _drive(route, duration_s: float) -> dict:
    """The run's samples, wheel odometry of the rear axle (the mean of its wheels' rates times
    the radius, as ``compare.route_dataset``) and the truth of the rear axle's velocity."""
    res = run_route(route, duration_s=duration_s, seed=0, estimators=("poisson",))
    model = car_spec().compile()
    lever = model.site("rear_axle").pos - model.site("imu").pos
    radius = vehicle_parameters(model)["wheel_radius_m"]
    return {"fs": float(res.sensor["output_rate_hz"]), "t": res.t_s, "gyro": res.imu.gyro_b,
            "accel": res.imu.accel_b, "mag": res.imu.mag_b, "q_true": res.truth.q_wb,
            "decl": math.radians(res.site["declination_deg"]), "lever": tuple(float(x) for x in lever),
            "odometry": 0.5 * (res.truth.wheel_rates[:, 2] + res.truth.wheel_rates[:, 3]) * radius,
            "v_axle_b": quat_rotate(quat_conjugate(res.truth.q_wb), res.truth.vel_w) + np.cross(res.truth.omega_b, lever),
            "x_m": res.truth.pos_w[:, 0]}


def _run(d: dict, speed_mps: np.ndarray | None = None, **params):
    est = make_estimator("biso_plus", d["fs"], declination_rad=d["decl"], speed_point_b_m=d["lever"], **params)
    out = est.update(d["gyro"], d["accel"], d["mag"], speed_mps=d["odometry"] if speed_mps is None else speed_mps)
    return out, angle_errors_deg(out.q_wb, d["q_true"])


@pytest.fixture(scope="module")
def washboard() -> dict:
    route = parse_route({
        "name": "washboard", "description": "a straight with 80 m of corrugations", "closed": False,
        "tyres": "magic_formula", "driving": {"default_speed_mps": 12.0, "max_lateral_accel_mps2": 2.5},
        "waypoint": [{"x_m": 0.0, "y_m": 0.0, "speed_mps": 12.0}, {"x_m": 400.0, "y_m": 0.0}],
        "terrain": {"resolution_m": 0.5, "feature": [
            {"type": "washboard", "x0_m": WASHBOARD_X_M[0], "y0_m": 0.0, "x1_m": WASHBOARD_X_M[1], "y1_m": 0.0,
             "amplitude_m": 0.02, "wavelength_m": 0.8}]}}, source="<test>")
    d = _drive(route, 28.0)
    assert d["x_m"][-1] > WASHBOARD_X_M[1] + 10.0, "the car did not cross the washboard"
    return d


def test_wheels_spin_on_a_washboard_and_the_tilt_does_not_follow(washboard):
    d = washboard
    on = (d["x_m"] > WASHBOARD_X_M[0] + 5.0) & (d["x_m"] < WASHBOARD_X_M[1])
    # cruising before the waves (the acceleration's end, at 62 m, has its own short wheel transient)
    before = (d["x_m"] > WASHBOARD_X_M[0] - 30.0) & (d["x_m"] < WASHBOARD_X_M[0] - 5.0)
    assert on.sum() > 1000 and before.sum() > 300 and d["v_axle_b"][before, 0].min() > 11.5
    # the mechanism: the odometry is the wheels', not the body's, and changes faster than any car
    v_x = d["v_axle_b"][:, 0]
    dv_odometry = _lp(np.r_[0.0, np.diff(d["odometry"])] * d["fs"], d["fs"], 0.05)
    f_x = _lp(d["accel"][:, 0], d["fs"], 0.05)
    assert np.abs(d["odometry"] - v_x)[before].max() < 0.5  # the drive slip of a rolling tyre, a few %
    assert np.abs(dv_odometry - f_x)[before].max() < 1.0
    assert np.abs(d["odometry"] - v_x)[on].max() > 1.0, "the wheels did not leave the road"
    assert np.abs(dv_odometry - f_x)[on].max() > 10.0
    # its consequence when the odometry's v̇ is compensated regardless: tens of degrees of pitch
    _, err_blind = _run(d, speed_slip_accel_mps2=1.0e9)
    assert np.abs(err_blind["pitch"]).max() > 10.0
    # detected: the pitch as good as with the true forward speed
    out, err = _run(d)
    _, err_true = _run(d, speed_mps=v_x)
    pitch_rms = float(np.sqrt(np.mean(err["pitch"] ** 2)))
    assert np.abs(err["pitch"]).max() < 1.0
    assert pitch_rms < 2.0 * float(np.sqrt(np.mean(err_true["pitch"] ** 2))) + 0.05
    assert (out.flags[on] & fl.ACCEL_GATED).any() and not (out.flags[before] & fl.ACCEL_GATED).any()


def _rear_slip_gradient_rad_per_g() -> float:
    """W_r/C_αr of the reference car's rear tyres at their static load (Gillespie 1992, ch. 6;
    K_yα = p_Ky1 F_z0 sin(2 atan(F_z/(p_Ky2 F_z0))), Pacejka 2012 §4.3)."""
    p = vehicle_parameters()
    w_r = p["cg_behind_front_axle_m"] / p["wheelbase_m"] * p["total_mass_kg"] * G0 / 2
    return w_r / (TYRES.pky1 * TYRES.fz0_n * math.sin(2.0 * math.atan(w_r / (TYRES.pky2 * TYRES.fz0_n))))


def test_the_rear_axle_slides_in_a_steady_bend_and_its_sideslip_is_compensated():
    from biso_cosim.vehicle.handling import circle_route

    with warnings.catch_warnings():  # the circle's lateral-acceleration cap is beyond the car's, on purpose
        warnings.simplefilter("ignore")
        route = dataclasses.replace(circle_route(40.0, 12.0, 3), tyres="magic_formula")
    d = _drive(route, 30.0)
    steady = d["t"] > 20.0
    v = d["v_axle_b"][steady]
    beta_deg = math.degrees(float(np.mean(np.arctan2(v[:, 1], v[:, 0]))))
    f_y = float(np.mean(d["accel"][steady, 1]))
    d_r = _rear_slip_gradient_rad_per_g()
    assert 3.0 < f_y < 4.5  # about 0.36 g
    # the single-track model's slip angle of the rear axle, outward of the bend
    assert beta_deg < -1.0
    assert -math.degrees(d_r * f_y / G0) == pytest.approx(beta_deg, rel=0.1)
    # the no-sideslip assumption pitches the estimate by about ω_z v_y/g; the model removes it
    _, err0 = _run(d)
    _, err = _run(d, rear_slip_gradient_rad_per_g=d_r)
    pitch0 = abs(float(np.mean(err0["pitch"][steady])))
    expected = math.degrees(abs(float(np.mean(v[:, 1] * d["gyro"][steady, 2]))) / G0)
    assert pitch0 == pytest.approx(expected, rel=0.3)
    assert abs(float(np.mean(err["pitch"][steady]))) < 0.2 * pitch0
    assert float(np.sqrt(np.mean(err["roll"][steady] ** 2))) <= float(np.sqrt(np.mean(err0["roll"][steady] ** 2)))


def test_at_the_limit_the_sideslip_leaves_the_model_and_the_gyro_holds_the_tilt():
    """A hard driver at 9-10 m/s² of lateral acceleration on figure8 (``limit_drive``: the steering
    swinging, full throttle or full brake): the rear axle slides far beyond the single-track
    model's slip angle D_r f_y, whose sideslip velocity and rate then enter the compensation
    wrong by several m/s²; ungated, the tilt follows them. Beyond the tyres' linear range a_l
    (the car's, ``VehicleSim.estimator_defaults``) biso_plus holds the tilt with the gyro."""
    from biso_cosim.vehicle.handling import limit_drive

    sim, res, _ = limit_drive("figure8", duration_s=20.0)
    vp = sim.vehicle.estimator_defaults()
    a_l = vp["linear_accel_mps2"]
    assert 5.5 < a_l < 6.5  # 0.63 g: the rear tyre's secant stiffness 10 % below K_yα
    fy = res.truth.specific_force_b[:, 1]
    assert np.abs(fy).max() > 1.4 * a_l
    # the rear axle's slip angle against the model's
    lever = np.asarray(vp["speed_point_b_m"])
    v = quat_rotate(quat_conjugate(res.truth.q_wb), res.truth.vel_w) + np.cross(res.truth.omega_b, lever)
    moving = v[:, 0] > 3.0
    beta = np.degrees(np.abs(np.arctan2(v[moving, 1], v[moving, 0])))
    beta_model = math.degrees(vp["rear_slip_gradient_rad_per_g"]) * np.abs(fy[moving]).max() / G0
    assert beta.max() > 2.5 * beta_model
    fs = float(res.sensor["output_rate_hz"])
    odometry = sim.odometry_mps(res.truth)
    unguarded = make_estimator("biso_plus", fs, declination_rad=math.radians(res.site["declination_deg"]),
                               **(vp | {"linear_accel_mps2": 0.0}))
    err0 = angle_errors_deg(unguarded.update(res.imu.gyro_b, res.imu.accel_b, res.imu.mag_b,
                                             speed_mps=odometry).q_wb, res.truth.q_wb)
    assert np.abs(err0["roll"]).max() > 8.0
    err = res.errors("biso_plus")
    assert np.abs(err["roll"]).max() < 2.0 and np.abs(err["pitch"]).max() < 2.0
    assert np.abs(err["heading"]).max() < 3.5  # the start's (2.6°), as without the guard
    flags = res.estimates["biso_plus"][1]
    assert (flags[np.abs(fy) > 1.2 * a_l] & fl.ACCEL_GATED).all()
