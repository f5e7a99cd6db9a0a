"""The drivetrain (biso_cosim/vehicle/drivetrain.py): the kernel against a plain reference,
its power, rev limit and gears, and the MuJoCo car's performance against the class's
published figures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from biso_cosim.vehicle.drivetrain import (DRIVETRAIN, RPM_PER_RAD_S, DrivetrainParams, _drivetrain_controls,
                                           _engine_torque_nm, drivetrain_coefficients, resistance_force,
                                           traction_torque_nm, wheel_torque)

R, M, SHARE, HL = 0.316, 1300.0, 0.4, 0.2


def reference(drive, omega_rear, omega_front, p=DRIVETRAIN):
    """The method of the module docstring written plainly: (torque, gear)."""
    if drive == 0.0:
        return 0.0, 0

    def engine(rpm):
        if rpm > p.rev_limit_rpm:
            return 0.0
        torque = float(np.interp(rpm, p.torque_curve_rpm, p.torque_curve_nm))
        return min(torque, p.max_power_w / (rpm / RPM_PER_RAD_S))

    sign = math.copysign(1.0, drive)
    rear, front = sign * omega_rear, sign * omega_front
    ratios = [p.reverse_ratio] if drive < 0 else list(p.gear_ratios)
    best, gear = 0.0, 0
    for g, ratio in enumerate(ratios):
        overall = ratio * p.final_drive
        rpm = abs(rear) * overall * RPM_PER_RAD_S
        torque = 0.0 if rpm > p.rev_limit_rpm else p.efficiency * overall * engine(max(rpm, p.launch_rpm))
        if torque > best:
            best, gear = torque, (-1 if drive < 0 else g + 1)
    traction = p.traction_friction * M * 9.80665 * SHARE / (1 - p.traction_friction * HL) * R
    torque = min(abs(drive) * p.peak_wheel_torque_nm, best, traction)
    slip = (rear - front) / max(abs(front), p.slip_speed_floor_rad_s)
    factor = min(max((p.slip_cut - slip) / (p.slip_cut - p.slip_target), 0.0), 1.0)
    return sign * torque * factor, gear


def test_kernel_equals_the_plain_reference():
    rng = np.random.default_rng(0)
    c = drivetrain_coefficients(DRIVETRAIN, mass_kg=M, wheel_radius_m=R, rear_load_share=SHARE,
                                cg_height_over_wheelbase=HL)
    for _ in range(3000):
        drive = float(rng.choice([rng.uniform(-1, 1), 1.0, -1.0, 0.0]))
        front = float(rng.uniform(-60.0, 260.0))
        rear = front * float(rng.uniform(0.7, 1.6)) + float(rng.normal(0.0, 2.0))
        want, want_gear = reference(drive, rear, front)
        got, _ = _drivetrain_controls(c, drive, np.array([front, front, rear, rear]))
        assert got == pytest.approx(want, rel=1e-12, abs=1e-9)
        if drive != 0.0 and want != 0.0:
            torque, gear = wheel_torque(drive, rear, front)
            assert gear == want_gear


def test_engine_power_never_exceeds_85_kw_and_the_rev_limit_cuts_the_fuel():
    c = drivetrain_coefficients(DRIVETRAIN, mass_kg=M, wheel_radius_m=R)
    rpm = np.linspace(500.0, 7000.0, 13001)
    torque = np.array([_engine_torque_nm(c, n) for n in rpm])
    power = torque * rpm / RPM_PER_RAD_S
    assert power.max() <= 85_000.0 * (1 + 1e-12)
    assert power.max() == pytest.approx(85_000.0)  # reached over the 5000-5500 rpm band
    band = (rpm >= 5000.0) & (rpm <= 5500.0)
    assert power[band] == pytest.approx(85_000.0, rel=2e-3)
    assert np.all(torque[(rpm >= 2000.0) & (rpm <= 3500.0)] == 200.0)  # the plateau
    assert np.all(torque[rpm > 6200.0] == 0.0)
    # at the wheels: no gear beyond the rev limit, no more than 85 kW times the efficiency
    for omega in np.linspace(0.5, 260.0, 600):
        t, gear = wheel_torque(1.0, omega, omega)
        assert t * omega <= 85_000.0 * DRIVETRAIN.efficiency * (1 + 1e-12)
        if gear:
            overall = DRIVETRAIN.gear_ratios[gear - 1] * DRIVETRAIN.final_drive
            assert omega * overall * RPM_PER_RAD_S <= DRIVETRAIN.rev_limit_rpm
    top = DRIVETRAIN.rev_limit_rpm / RPM_PER_RAD_S / (DRIVETRAIN.gear_ratios[-1] * DRIVETRAIN.final_drive)
    assert wheel_torque(1.0, top * 1.001, top * 1.001) == (0.0, 0)


def test_the_gear_is_the_one_with_the_most_wheel_torque_and_goes_up_with_speed():
    gears = []
    for v in np.linspace(0.5, 60.0, 500):
        omega = v / R
        _, gear = wheel_torque(1.0, omega, omega)
        gears.append(gear)
        rpm = [omega * i * DRIVETRAIN.final_drive * RPM_PER_RAD_S for i in DRIVETRAIN.gear_ratios]
        assert rpm[gear - 1] <= DRIVETRAIN.rev_limit_rpm
    assert gears == sorted(gears) and gears[0] == 1 and set(gears) >= {1, 2, 3, 4, 5}
    # first gear up to its rev limit (6200 rpm: 46 km/h), then second
    first = DRIVETRAIN.rev_limit_rpm / RPM_PER_RAD_S / (DRIVETRAIN.gear_ratios[0] * DRIVETRAIN.final_drive) * R
    assert wheel_torque(1.0, 0.99 * first / R, 0.99 * first / R)[1] == 1
    assert wheel_torque(1.0, 1.01 * first / R, 1.01 * first / R)[1] == 2
    assert wheel_torque(-1.0, -3.0, -3.0)[1] == -1  # reverse


def test_drive_fraction_launch_traction_control_and_no_engine_braking():
    c = drivetrain_coefficients(DRIVETRAIN, mass_kg=M, wheel_radius_m=R, rear_load_share=SHARE,
                                cg_height_over_wheelbase=HL)
    traction = traction_torque_nm(DRIVETRAIN, mass_kg=M, wheel_radius_m=R, rear_load_share=SHARE,
                                  cg_height_over_wheelbase=HL)
    # from rest the clutch slips at the launch speed (200 N·m in first gear), limited by traction
    assert _drivetrain_controls(c, 1.0, np.zeros(4))[0] == pytest.approx(min(DRIVETRAIN.peak_wheel_torque_nm, traction))
    # a small demand is given as asked: u·T_peak
    assert _drivetrain_controls(c, 0.1, np.full(4, 10.0))[0] == pytest.approx(0.1 * DRIVETRAIN.peak_wheel_torque_nm)
    # no drive, no torque (no engine braking); the resistances oppose the motion
    torque, resistance = _drivetrain_controls(c, 0.0, np.full(4, 30.0))
    assert torque == 0.0 and resistance < 0.0
    # spinning rear wheels: the torque is cut to nothing at s_cut
    assert _drivetrain_controls(c, 1.0, np.array([10.0, 10.0, 15.0, 15.0]))[0] == 0.0


def test_the_traction_control_catches_one_spinning_rear_wheel_but_not_a_bend():
    """The slip is the faster rear wheel's against the front wheel of its side: one wheel
    spinning up (the open differential's unloaded inner wheel) is cut as both would be,
    where the mean of the two would let it spin; in a bend each rear wheel runs on a smaller
    radius than the front one of its side, so cornering is no slip."""
    c = drivetrain_coefficients(DRIVETRAIN, mass_kg=M, wheel_radius_m=R, rear_load_share=SHARE,
                                cg_height_over_wheelbase=HL)
    free = _drivetrain_controls(c, 0.2, np.full(4, 60.0))[0]
    assert free == pytest.approx(0.2 * DRIVETRAIN.peak_wheel_torque_nm)
    # the inner rear wheel at 25 % slip, the outer rolling: mean slip 12.5 % (barely cut), cut by 25 %'s
    s_t, s_c = DRIVETRAIN.slip_target, DRIVETRAIN.slip_cut
    one = _drivetrain_controls(c, 0.2, np.array([60.0, 60.0, 75.0, 60.0]))[0]
    assert one == pytest.approx(free * (s_c - 0.25) / (s_c - s_t))
    assert _drivetrain_controls(c, 0.2, np.array([60.0, 60.0, 60.0, 75.0]))[0] == pytest.approx(one)
    # a bend of radius 8 m at the rear axle (wheelbase 2.64 m, track 1.54 m), rolling without
    # slip: each wheel's speed is its radius; the outer rear turns 4 % faster than the front mean
    L, T, r_axle = 2.64, 1.54, 8.0
    rates = np.array([math.hypot(r_axle - T / 2, L), math.hypot(r_axle + T / 2, L), r_axle - T / 2, r_axle + T / 2])
    assert rates[3] / rates[:2].mean() > 1.035
    assert _drivetrain_controls(c, 0.2, 8.0 * rates)[0] == pytest.approx(0.2 * DRIVETRAIN.peak_wheel_torque_nm)


def test_driving_resistances():
    v = 30.0
    want = 0.5 * 1.225 * DRIVETRAIN.drag_area_m2 * v * v + DRIVETRAIN.rolling_resistance * M * 9.80665
    assert resistance_force(v, mass_kg=M) == pytest.approx(-want)
    assert resistance_force(-v, mass_kg=M) == pytest.approx(want)
    assert resistance_force(0.0, mass_kg=M) == 0.0


def test_bad_parameters_name_the_field():
    with pytest.raises(ValueError, match="max_power_w"):
        drivetrain_coefficients(DrivetrainParams(max_power_w=-1.0), mass_kg=M, wheel_radius_m=R)
    with pytest.raises(ValueError, match="torque_curve_rpm must increase"):
        drivetrain_coefficients(DrivetrainParams(torque_curve_rpm=(1, 3, 2, 4, 5, 6, 7, 8)), mass_kg=M,
                                wheel_radius_m=R)
    with pytest.raises(ValueError, match="drive must be in"):
        wheel_torque(1.5, 0.0, 0.0)


def test_the_mujoco_car_performs_like_its_class():
    """Full throttle from rest (``biso-cosim vehicle performance``) against the published
    figures of 85 kW compact hatchbacks (0-100 km/h 9.3-10.2 s, 193-204 km/h)."""
    from biso_cosim.routes import car_limits
    from biso_cosim.vehicle.performance import measure_performance

    perf = measure_performance(duration_s=120.0)
    assert 8.0 <= perf.zero_to_100_s <= 11.0
    assert 175.0 <= perf.top_speed_mps * 3.6 <= 215.0
    assert perf.max_slip_after_1s < 0.15
    assert perf.max_rear_wheel_speed_mps < 1.02 * perf.top_speed_mps
    # the route limits' top speed is the drivetrain's, which the car reaches
    assert perf.top_speed_mps == pytest.approx(car_limits().top_speed_mps, rel=0.02)


def _route(waypoints, **driving):
    from biso_cosim.routes.route import parse_route

    return parse_route({"format": 1, "name": "t", "description": "test", "closed": False,
                        "driving": {"start_wait_s": 0.0, **driving}, "waypoint": waypoints}, source="t.toml")


def test_routes_asking_more_than_the_drivetrain_are_capped_or_warned_naming_the_waypoint():
    from biso_cosim.routes import RouteWarning, car_limits

    car = car_limits()
    with pytest.warns(RouteWarning, match=r"waypoint\[1\] reverses at 25 m/s.*top speed in reverse"):
        route = _route([{"x_m": 0.0, "y_m": 0.0}, {"x_m": 400.0, "y_m": 0.0, "reverse": True},
                        {"x_m": 0.0, "y_m": 0.0, "reverse": True}], default_speed_mps=25.0)
    assert route.waypoints[1].speed_mps == pytest.approx(car.reverse_top_speed_mps)
    assert 14.0 < car.reverse_top_speed_mps < 17.0  # the reverse gear at 6200 rpm
    with pytest.warns(RouteWarning, match=r"waypoint\[1\]: at its speed of 45 m/s the car accelerates at most 0\.\d\d"):
        _route([{"x_m": 0.0, "y_m": 0.0}, {"x_m": 100.0, "y_m": 0.0, "speed_mps": 45.0}, {"x_m": 3000.0, "y_m": 0.0}],
               accel_mps2=2.0)
    with pytest.warns(RouteWarning, match=r"waypoint\[0\]\.speed_mps = 500 m/s.*top speed \(54\.7 m/s\)"):
        _route([{"x_m": 0.0, "y_m": 0.0, "speed_mps": 500.0}, {"x_m": 3000.0, "y_m": 0.0}])
    # the car's full-throttle acceleration: traction-limited from rest, nothing left at the top speed
    assert car.full_throttle_accel_mps2(0.0) == pytest.approx(4.3, abs=0.1)
    assert car.full_throttle_accel_mps2(car.top_speed_mps) == pytest.approx(0.0, abs=0.01)


def test_a_fast_route_is_driven_at_what_the_engine_gives():
    """50 m/s asked at 2 m/s²: the driver's command ramps at the car's full-throttle
    acceleration, so the car follows it (no wound-up overshoot) and stays on the road."""
    import warnings

    from biso_cosim.vehicle.sim import VehicleSim

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        route = _route([{"x_m": 0.0, "y_m": 0.0}, {"x_m": 3000.0, "y_m": 0.0}], default_speed_mps=50.0,
                       accel_mps2=2.0, decel_mps2=2.0)
    sim = VehicleSim(route)
    speeds, commands, cross = [], [], []
    for _ in range(int(60 * sim.control_rate_hz)):
        sim.drive()
        truth = sim.step()
        speeds.append(truth.speed_mps[-1])
        commands.append(sim.driver.state.speed_cmd_mps)
        cross.append(sim.driver.state.cross_track_m)
    speeds, commands = np.array(speeds), np.array(commands)
    assert speeds.max() < 50.0 * 1.02
    assert np.max(commands - speeds) < 2.0  # the command never runs away from the car
    assert np.max(np.abs(cross)) < 0.5
    assert speeds.max() > 45.0


def test_docs_vehicle_shows_the_parameters_in_force():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "vehicle.md").read_text()
    assert DrivetrainParams.table() in text, "run: biso-cosim vehicle params, and paste it into docs/vehicle.md"
