"""Physics of the car: steady circle, rest, grades and banks, terrain, steering geometry."""

import math

import mujoco
import numpy as np
import pytest

from biso_cosim.frames import euler_from_quat, quat_rotate
from biso_cosim.routes import parse_route
from biso_cosim.vehicle.driver import DriverCommand
from biso_cosim.vehicle.model import CarIndex, build_model, car_spec, vehicle_parameters
from biso_cosim.vehicle.sim import Truth, VehicleSim
from biso_cosim.vehicle.terrain import Bank, Hill, Ridge, Terrain

G = 9.80665


def circle_route(radius_m, speed_mps, laps, terrain=()):
    """A circle of ``radius_m`` centred at the origin: a square with fillets of half its side."""
    r = radius_m
    return parse_route({
        "name": "circle", "description": "test circle", "closed": True, "laps": laps,
        "driving": {"default_speed_mps": speed_mps, "max_lateral_accel_mps2": 20.0, "start_wait_s": 0.5},
        "waypoint": [
            {"x_m": r, "y_m": 0.0}, {"x_m": r, "y_m": r, "radius_m": r}, {"x_m": -r, "y_m": r, "radius_m": r},
            {"x_m": -r, "y_m": -r, "radius_m": r}, {"x_m": r, "y_m": -r, "radius_m": r},
        ],
        "terrain": {"feature": list(terrain)},
    })


def drive(sim, seconds):
    parts = []
    for _ in range(int(round(seconds * sim.control_rate_hz))):
        sim.drive()
        parts.append(sim.step())
    return Truth.concatenate(parts)


@pytest.fixture(scope="module")
def circle_run():
    sim = VehicleSim(circle_route(30.0, 8.0, laps=3))
    truth = drive(sim, 40.0)
    return sim, truth


def test_steady_circle_yaw_rate_and_lateral_specific_force(circle_run):
    sim, truth = circle_run
    steady = truth.t_s > 20.0  # well into the second lap, speed and steering settled
    pos = truth.pos_w[steady, :2]
    # radius of the IMU site's own circle (least-squares circle fit)
    A = np.column_stack([2 * pos, np.ones(len(pos))])
    cx, cy, c = np.linalg.lstsq(A, np.sum(pos**2, axis=1), rcond=None)[0]
    radius = math.sqrt(c + cx * cx + cy * cy)
    speed = np.linalg.norm(truth.vel_w[steady], axis=1)
    assert np.std(speed) < 0.05 and abs(radius - 30.0) < 2.5
    v = float(np.mean(speed))
    roll = euler_from_quat(truth.q_wb[steady])[:, 0]
    gyro_z = float(np.mean(truth.omega_b[steady, 2]))
    f_lat = float(np.mean(truth.specific_force_b[steady, 1]))
    assert gyro_z == pytest.approx(v / radius, rel=0.02)
    expected = v * v / radius + G * math.sin(float(np.mean(roll)))
    assert f_lat == pytest.approx(expected, rel=0.03)
    # counter-clockwise circle: the body rolls outward (right side down, roll > 0), about 4.5°
    # per g of lateral acceleration (the README's figure)
    gradient = math.degrees(np.mean(roll)) / (v * v / radius / G)
    assert 4.0 < gradient < 5.0


def test_at_rest_accelerometer_reads_g_up():
    sim = VehicleSim(circle_route(30.0, 8.0, laps=1))
    truth = sim.step(200)  # the driver has not moved the car: settled, brakes on
    np.testing.assert_allclose(truth.specific_force_b.mean(axis=0), [0.0, 0.0, G], atol=2e-3)
    np.testing.assert_allclose(truth.omega_b, 0.0, atol=1e-4)
    np.testing.assert_allclose(euler_from_quat(truth.q_wb[-1])[:2], 0.0, atol=2e-3)


@pytest.mark.parametrize("yaw_deg", [0.0, 37.0])
def test_at_rest_on_a_hill_specific_force_is_gravity_in_body_axes(yaw_deg):
    """Parked on a slope: f_b = q_wb* (0, 0, g) q_wb, and the pitch follows the grade."""
    hill = Hill(x_m=0.0, y_m=0.0, radius_m=40.0, height_m=4.0)
    model, _ = build_model(Terrain((hill,)))
    data = mujoco.MjData(model)
    ix = CarIndex.of(model)
    yaw = math.radians(yaw_deg)
    # centre of mass on the flank, 20 m from the top, nose pointing up the hill
    cx, cy = -20.0 * math.cos(yaw), -20.0 * math.sin(yaw)
    data.qpos[:3] = (cx, cy, hill.height(cx, cy) + 0.9)
    data.qpos[3:7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    data.ctrl[ix.brakes] = 1.0
    for _ in range(3000):
        mujoco.mj_step(model, data)
    q = data.sensordata[ix.quat].copy()
    f = data.sensordata[ix.accel].copy()
    expected = quat_rotate(np.array([q[0], -q[1], -q[2], -q[3]]), [0.0, 0.0, G])
    np.testing.assert_allclose(f, expected, atol=0.02)
    # grade along the car: the slope between its axles
    rear = data.sensordata[ix.rear_axle_pos]
    ground = Terrain((hill,))
    xa, ya = rear[:2]
    xb, yb = xa + 2.64 * math.cos(yaw), ya + 2.64 * math.sin(yaw)
    grade = (ground.height(xb, yb) - ground.height(xa, ya)) / 2.64
    pitch = euler_from_quat(q)[1]
    assert pitch < 0  # nose up
    assert pitch == pytest.approx(-math.atan(grade), abs=math.radians(0.6))


def test_terrain_in_mujoco_matches_the_analytic_heights():
    terrain = Terrain((Hill(30.0, 5.0, 20.0, 2.0), Ridge(100, -50, 100, 50, 30, 3),
                       Bank(200, 0, 40, 8, 0, 180, 10), Hill(60, 5, 20, 1)))
    model, patches = build_model(terrain)
    assert len(patches) == 2  # the two hills overlap: one patch; the ridge and bank another
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    rng = np.random.default_rng(0)
    chassis = model.body("chassis").id
    geomid = np.zeros(1, np.int32)
    errors = []
    for x, y in zip(rng.uniform(-50, 300, 1500), rng.uniform(-100, 100, 1500)):
        dist = mujoco.mj_ray(model, data, np.array([x, y, 50.0]), np.array([0, 0, -1.0]), None, 1, chassis, geomid)
        errors.append(50.0 - dist - terrain.height(x, y))
    # MuJoCo interpolates linearly on the 0.5 m grid: at the kinks of the bank's edges (slope
    # changes by tan 10°) the error is up to |Δslope|·res/4 ≈ 2.2 cm; elsewhere far smaller
    assert np.max(np.abs(errors)) < 0.025
    assert np.sqrt(np.mean(np.square(errors))) < 1e-3


def test_bank_tilts_the_road_by_its_angle():
    bank = Bank(cx_m=0.0, cy_m=0.0, radius_m=50.0, width_m=8.0, start_deg=0.0, end_deg=180.0, bank_deg=8.0)
    t = Terrain((bank,))
    gx, gy = t.gradient(0.0, 50.0)  # top of the curve, mid-sector: the road runs west-east
    assert math.degrees(math.atan(gy)) == pytest.approx(8.0, abs=1e-6)
    assert abs(gx) < 1e-9
    assert t.height(0.0, -50.0) == 0.0  # outside the sector


def test_ackermann_polynomials_fit_the_geometry():
    spec_xml = car_spec().to_xml()
    model = car_spec().compile()
    params = vehicle_parameters(model)
    L, T = params["wheelbase_m"], params["track_m"]
    delta = np.linspace(-0.6, 0.6, 2001)
    inner = np.arctan2(L * np.tan(delta), L - 0.5 * T * np.tan(delta))
    outer = np.arctan2(L * np.tan(delta), L + 0.5 * T * np.tan(delta))
    for name, exact in (("ackermann_left", inner), ("ackermann_right", outer)):
        coef = model.eq(name).data[:5]
        approx = np.polynomial.polynomial.polyval(delta, coef)
        assert np.max(np.abs(approx - exact)) < math.radians(0.05), name
    assert "ackermann_left" in spec_xml


def test_vehicle_parameters_are_those_of_a_compact_car():
    p = vehicle_parameters()
    assert p["total_mass_kg"] == pytest.approx(1300.0) and p["sprung_mass_kg"] == pytest.approx(1160.0)
    assert p["wheelbase_m"] == pytest.approx(2.64) and p["track_m"] == pytest.approx(1.54)
    # the whole car's centre of mass lies below the sprung mass's (the wheels are low)
    unsprung_height = 0.316  # wheel centres
    expected = (1160.0 * p["sprung_cg_height_m"] + 140.0 * unsprung_height) / 1300.0
    assert p["cg_height_m"] == pytest.approx(expected, abs=0.01)
    # the static ride height puts the suspension at zero travel: springs carry the sprung weight
    load = p["sprung_mass_kg"] * G * (1 - p["cg_behind_front_axle_m"] / p["wheelbase_m"]) / 2
    assert load / p["spring_front_n_per_m"] == pytest.approx(0.1497, abs=5e-4)
    # ride frequency of the front corners about 1.3 Hz
    assert math.sqrt(p["spring_front_n_per_m"] / (load / G)) / (2 * math.pi) == pytest.approx(1.3, abs=0.05)


def test_chunked_stepping_is_deterministic_and_time_stamped():
    route = circle_route(20.0, 6.0, laps=1)
    a = VehicleSim(route)
    b = VehicleSim(route)
    ta = drive(a, 3.0)
    tb = drive(b, 3.0)
    np.testing.assert_array_equal(ta.q_wb, tb.q_wb)
    np.testing.assert_allclose(np.diff(ta.t_s), 1e-3, atol=1e-12)
    assert ta.t_s[0] == 0.0
    a.reset()
    np.testing.assert_array_equal(drive(a, 3.0).specific_force_b, ta.specific_force_b)


def test_observe_route_tracks_the_rear_axle_as_the_driver_does():
    """An agent drives (here a constant left turn): the progress and cross-track error that
    ``observe_route`` records are the driver's ``track`` at the rear axle."""
    route = circle_route(20.0, 6.0, laps=1)
    observed, tracked = VehicleSim(route), VehicleSim(route)
    for _ in range(100):  # 2 s
        for car in (observed, tracked):
            car.apply(DriverCommand(steer_rad=0.2, drive=0.4, brake=0.0))
            car.step()
        observed.observe_route()
        tracked.driver.track(tracked.data.sensordata[tracked.index.rear_axle_pos][:2].tolist())
        assert observed.driver.state.array.tolist() == tracked.driver.state.array.tolist()
    assert observed.driver.state.s_m > 3.0 and observed.driver.state.cross_track_m != 0.0


def test_a_control_period_from_the_sensor_history_equals_mj_step_calls_bit_for_bit():
    """``step`` runs a period as mj_step(m, d, n) and reads the rows from the sensors'
    history: the same sensor rows and the same final state as a Python loop of ``mj_step``
    with the controls held, for whole and odd-sized periods, and periods longer than the
    history (stepped in parts)."""
    route = circle_route(20.0, 6.0, laps=1)
    a, b = VehicleSim(route), VehicleSim(route)
    size = mujoco.mj_stateSize(a.model, mujoco.mjtState.mjSTATE_INTEGRATION)
    for n in (None, None, 7, 20, 1, 33, 250):
        a.drive()
        b.drive()
        truth = a.step(n)
        rows = []
        for _ in range(b.steps_per_control if n is None else n):
            mujoco.mj_step(b.model, b.data)
            rows.append(b.data.sensordata.copy())
        b.steps_done += len(rows)
        np.testing.assert_array_equal(truth.packed, b.truth_of(np.array(rows), b.steps_done - len(rows)).packed)
        sa, sb = np.empty(size), np.empty(size)
        mujoco.mj_getState(a.model, a.data, sa, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_getState(b.model, b.data, sb, mujoco.mjtState.mjSTATE_INTEGRATION)
        np.testing.assert_array_equal(sa, sb)
        np.testing.assert_array_equal(a.data.sensordata, b.data.sensordata)


def test_sensor_history_of_the_model():
    """``history_steps``: every sensor keeps that many samples (none by default); bad values
    are refused naming the argument."""
    terrain = Terrain(())
    plain, _ = build_model(terrain)
    model, _ = build_model(terrain, history_steps=20)
    assert plain.nhistory == 0 and (model.sensor_history[:, 0] == 20).all()
    assert model.nhistory == model.nsensor * (2 + 20) + 20 * model.nsensordata  # [user, newest, times, values]
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="history_steps must be an int >= 0"):
            build_model(terrain, history_steps=bad)


def test_a_clock_set_back_does_not_confuse_the_history():
    """MuJoCo advances a sensor's history ring only past its newest time stamp: after the
    clock is set back (here by hand, without ``restore_physics``) the rows of the next
    period are still those of plain mj_step calls (the period is stepped again), and the
    rings start afresh for the periods after it."""
    route = circle_route(20.0, 6.0, laps=1)
    a, b = VehicleSim(route), VehicleSim(route)
    for sim in (a, b):
        drive(sim, 1.0)
        sim.data.time = 0.5
    check_rows_as_mj_step(a, b, periods=3)
    assert a.periods_with_warnings == 0  # (no warning: the clock)


def test_a_state_restored_by_hand_one_period_back_is_stepped_again():
    """Back by exactly one period (the state restored with mj_setState, not through
    ``CoSimulation.set_state``): every stamp of the rings is then one MuJoCo already holds,
    and the rows are still those of plain mj_step calls."""
    route = circle_route(20.0, 6.0, laps=1)
    a, b = VehicleSim(route), VehicleSim(route)
    spec = int(mujoco.mjtState.mjSTATE_INTEGRATION) & ~int(mujoco.mjtState.mjSTATE_HISTORY)  # the rings stay
    for sim in (a, b):
        drive(sim, 1.0)
        saved = np.empty(mujoco.mj_stateSize(sim.model, spec))
        mujoco.mj_getState(sim.model, sim.data, saved, spec)
        sensordata = sim.data.sensordata.copy()
        drive(sim, 1.0 / sim.control_rate_hz)
        mujoco.mj_setState(sim.model, sim.data, saved, spec)
        sim.data.sensordata[:] = sensordata
    check_rows_as_mj_step(a, b, periods=3)


def check_rows_as_mj_step(a, b, periods):
    """``a.step()`` against the same periods stepped one mj_step at a time on ``b``."""
    for period in range(periods):
        a.drive()
        b.drive()
        truth = a.step()
        rows = []
        for _ in range(b.steps_per_control):
            mujoco.mj_step(b.model, b.data)
            rows.append(b.data.sensordata.copy())
        np.testing.assert_array_equal(truth.packed, b.truth_of(np.array(rows), b.steps_done).packed)
        b.steps_done += len(rows)


def test_a_period_with_a_mujoco_warning_steps_on_as_mj_step_does(tmp_path, monkeypatch):
    """A MuJoCo warning may come with a change of the data behind the sensor history: the
    period is then stepped again one mj_step at a time, so the rows are those of plain
    mj_step calls (here a non-finite control, which MuJoCo zeroes and goes on)."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warnings to MUJOCO_LOG.TXT here
    route = circle_route(20.0, 6.0, laps=1)
    a, b = VehicleSim(route), VehicleSim(route)
    for sim in (a, b):
        sim.drive()
        sim.data.ctrl[sim.index.steer] = np.nan  # the next mj_step warns and zeroes the controls
    truth = a.step()
    rows = []
    for _ in range(b.steps_per_control):
        mujoco.mj_step(b.model, b.data)
        rows.append(b.data.sensordata.copy())
    np.testing.assert_array_equal(truth.packed, b.truth_of(np.array(rows), 0).packed)
    assert a.periods_with_warnings == 1
    a.reset()
    drive(a, 2.0)
    assert a.periods_with_warnings == 0


def test_a_state_mujoco_would_reset_raises_physics_diverged_at_its_step(tmp_path, monkeypatch):
    """A diverged state, on which MuJoCo resets the data and goes on: PhysicsDiverged at the
    step it happened, by step and by step_rows alike; a reset car drives again."""
    from biso_cosim.vehicle.sim import PhysicsDiverged

    monkeypatch.chdir(tmp_path)
    sim = VehicleSim(circle_route(20.0, 6.0, laps=1))
    for _ in range(2):
        sim.drive()
        sim.step()
    sim.drive()
    sim.data.qvel[0] = 1e11  # beyond mjMAXVAL
    with pytest.raises(PhysicsDiverged, match=r"^the physics became unstable at t = 0\.0400 s: MuJoCo found a "
                                              r"non-finite or huge velocity \(dof 0\) and reset the state$") as caught:
        sim.step()
    assert caught.value.t_s == pytest.approx(0.04)
    sim.reset()
    drive(sim, 1.0)
    assert np.all(np.isfinite(sim.data.qpos))
