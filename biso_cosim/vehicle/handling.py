"""Handling of the car with slip-based tyres, against published figures of its class.

``biso-cosim vehicle handling --out DIR`` runs these with ``tyres="magic_formula"``
(``vehicle.tyres``) and writes ``handling.md`` (each figure next to its published class
range and source), ``handling.json`` and the plots:

* ISO 4138 steady-state circular driving, constant-radius method: the scripted driver holds a
  circle of ``radius_m`` at a series of constant speeds; from the steady part of each run the
  lateral acceleration a_y = v·r (v forward speed, r yaw rate), the steering angle δ (the
  driver's command: the steering-wheel angle over the steering ratio; the road wheels turn
  less by the compliance steer), the radius R = v/r and the sideslip angle β at the centre
  of mass. The test driver holds the radius: the scripted driver's pure pursuit plus an
  integral of the cross-track error (at most 0.04 rad: beyond the front tyres' peak more
  steering gives less force). The understeer gradient is the slope of δ − L/R against
  a_y/g (ISO 4138, the steering angle less the Ackermann angle) over the linear range
  a_y ≤ ``linear_limit_g``; the sideslip gradient the slope of β. The limit lateral
  acceleration is the highest steady a_y; the limit is progressive when δ grows with a_y
  over the runs that hold the radius and the faster runs keep the a_y with the rear axle's
  sideslip on its trend (``progressive_limit``).
* ISO 7401 step steer at 80 km/h to 4 m/s²: the yaw-rate and lateral-acceleration response
  times (from 50 % of the steering step to 90 % of the steady value), the yaw rate's peak
  time and overshoot, from the steering command. No published class range is checked here
  (none verified); the linear
  bicycle model with the tyres' cornering stiffnesses is the reference (tests/test_tyres.py).
* braking from 100 km/h on a straight, flat road (the brakes of every wheel at full
  command, the ABS of ``tyres.ChassisParams`` holding each wheel's slip): the stopping distance.
* the cost of a physics step with the tyre plugin against today's (Coulomb) step.

Published ranges (see ``PUBLISHED``) are of compact cars; each has its source.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["PUBLISHED", "SteadyPoint", "steady_circle", "understeer_fit", "progressive_limit", "limit_lateral_accel",
           "braking_distance", "handling_report"]

G = 9.80665
# the speed loop of the steady-circle runs: ramp, proportional (1/s) and integral (1/s²) gains
_RAMP_MPS2, _SPEED_KP, _SPEED_KI = 2.0, 1.5, 0.5
# the steady-circle runs' radius loop: integral of the cross-track error, rad of steer per m·s
_RADIUS_KI = 0.01
# ... at most this much (anti-windup: beyond the front tyres' peak more steering gives less force)
_RADIUS_MAX_RAD = 0.04

PUBLISHED = {
    "understeer_gradient_deg_per_g": ((2.0, 4.0), "issue 26: a compact hatchback of the class (ISO 4138: the "
                                      "steering-wheel angle over the steering ratio, δ − L/R against a_y)"),
    "max_lateral_accel_g": ((0.8, 0.9), "commonly quoted steady-state limit of passenger cars on summer tyres, "
                            "dry asphalt (not checked against a single source)"),
    "roll_gradient_deg_per_g": ((4.0, 5.0), "this car's documented value, about 4.5 °/g from its springs and "
                                "anti-roll bars (car.xml header), kept with either tyre model"),
    "stopping_distance_100_m": ((34.0, 40.0), "magazine braking tests (ADAC, auto motor und sport) of compact cars "
                                "of the class from 100 km/h on dry asphalt, with ABS"),
}
"""(low, high) and source of each figure."""


def circle_route(radius_m: float, speed_mps: float, laps: int):
    """A counter-clockwise circle of ``radius_m`` centred at the origin (a square with fillets of
    half its side, as tests/test_vehicle.py's), driven at ``speed_mps``."""
    from biso_cosim.routes.route import parse_route

    r = radius_m
    return parse_route({
        "name": "circle", "description": f"ISO 4138 circle, radius {r:g} m", "closed": True, "laps": laps,
        "driving": {"default_speed_mps": speed_mps, "max_lateral_accel_mps2": 20.0, "start_wait_s": 0.5,
                    "accel_mps2": 2.0},
        "waypoint": [
            {"x_m": r, "y_m": 0.0}, {"x_m": r, "y_m": r, "radius_m": r}, {"x_m": -r, "y_m": r, "radius_m": r},
            {"x_m": -r, "y_m": -r, "radius_m": r}, {"x_m": r, "y_m": -r, "radius_m": r},
        ],
    }, source="<handling>")


@dataclass(frozen=True)
class SteadyPoint:
    """The steady state of one constant-speed run on the circle (means over its last seconds)."""

    target_speed_mps: float
    speed_mps: float
    yaw_rate_rad_s: float
    lateral_accel_g: float
    steer_rad: float
    """the steering-wheel angle over the steering ratio (the driver's command: ISO 4138's δ)"""
    road_wheel_rad: float
    """the road wheels' bicycle angle (the steering hinge, less the compliance steer)"""
    radius_m: float
    sideslip_cg_deg: float
    sideslip_rear_axle_deg: float
    roll_deg: float
    """the body's roll angle (ISO 8855: positive right side down, outward in a left turn)"""
    steady: bool
    """True if the speed and the yaw rate held (std below 2 % of their means)."""


def _body_velocity(truth) -> np.ndarray:
    """IMU-site velocity in body axes (n, 3)."""
    from biso_cosim.frames import quat_rotate

    q = truth.q_wb
    conj = np.column_stack([q[:, 0], -q[:, 1], -q[:, 2], -q[:, 3]])
    return np.array([quat_rotate(c, v) for c, v in zip(conj, truth.vel_w)])


def steady_circle(speed_mps: float, *, radius_m: float = 40.0, tyres: str = "magic_formula",
                  settle_s: float = 8.0, window_s: float = 6.0, **car) -> SteadyPoint:
    """One constant-speed run on the circle; the steady state over the last ``window_s``.
    ``car``: ``tyre_params``, ``chassis_params`` of ``VehicleSim`` (default the reference car's)."""
    from biso_cosim.frames import euler_from_quat
    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.sim import Truth, VehicleSim

    ramp_s = speed_mps / _RAMP_MPS2 + 1.0
    duration = ramp_s + settle_s + window_s
    laps = int(math.ceil(speed_mps * duration / (2 * math.pi * radius_m))) + 1
    sim = VehicleSim(circle_route(radius_m, speed_mps, laps), tyres=tyres, **car)
    rows = []
    # the driver steers; the speed is held by a PI loop of its own (the route's speed profile
    # caps the speed in curves at the car's route limit, below the tyres' limit)
    dt = 1.0 / sim.control_rate_hz
    mass, radius = sim.parameters["total_mass_kg"], sim.index.wheel_radius_m
    peak = sim.parameters["max_drive_torque_nm"]
    integral, target, held = 0.0, 0.0, 0.0
    commands = []
    for k in range(int(round(duration * sim.control_rate_hz))):
        command = sim.drive()
        if k * dt > 0.5:
            # the test driver holds the radius: the pure pursuit's steering plus an integral of
            # the cross-track error (left positive: steer left while right of the circle)
            held = min(max(held - _RADIUS_KI * sim.driver.state.cross_track_m * dt, -_RADIUS_MAX_RAD), _RADIUS_MAX_RAD)
            steer = min(max(command.steer_rad + held, -0.6), 0.6)
            commands.append(steer)
            target = min(target + _RAMP_MPS2 * dt, speed_mps)
            error = target - float(sim.data.sensordata[sim.index.rear_axle_vel_b.start])
            integral += error * dt
            accel = _SPEED_KP * error + _SPEED_KI * integral
            sim.apply(DriverCommand(steer_rad=steer, drive=min(max(mass * accel * radius / peak, 0.0), 1.0),
                                    brake=0.0))
        else:
            commands.append(command.steer_rad)
        rows.append(sim.step()[-1])
    truth = Truth.concatenate(rows)
    last = truth.t_s > truth.t_s[-1] - window_s
    v_b = _body_velocity(truth[np.flatnonzero(last)])
    omega = truth.omega_b[last]
    # at the centre of mass (the chassis origin) and the rear axle: v + ω × (p − p_imu)
    imu, axle = sim.index.imu_pos_b, sim.index.rear_axle_b
    v_cg = v_b + np.cross(omega, -imu)
    v_axle = v_b + np.cross(omega, axle - imu)
    speed = float(np.mean(v_cg[:, 0]))
    r = float(np.mean(omega[:, 2]))
    steady = bool(np.std(v_cg[:, 0]) < 0.02 * abs(speed) and np.std(omega[:, 2]) < 0.02 * abs(r))
    return SteadyPoint(
        target_speed_mps=float(speed_mps), speed_mps=speed, yaw_rate_rad_s=r, lateral_accel_g=speed * r / G,
        steer_rad=float(np.mean(np.asarray(commands)[last])),
        road_wheel_rad=float(np.mean(truth.steer_rad[last])), radius_m=speed / r,
        sideslip_cg_deg=math.degrees(float(np.mean(np.arctan2(v_cg[:, 1], v_cg[:, 0])))),
        sideslip_rear_axle_deg=math.degrees(float(np.mean(np.arctan2(v_axle[:, 1], v_axle[:, 0])))),
        roll_deg=math.degrees(float(np.mean(euler_from_quat(truth.q_wb[last])[:, 0]))), steady=steady)


def understeer_fit(points: list[SteadyPoint], wheelbase_m: float, linear_limit_g: float = 0.4, *,
                   road_wheel: bool = False) -> dict[str, float]:
    """ISO 4138: slopes of δ − L/R, of β and of the roll angle against a_y/g (least squares over the steady
    points with a_y ≤ ``linear_limit_g``), in °/g; δ the steering command (the steering-wheel
    angle over the ratio, ISO 4138's), or with ``road_wheel`` the road wheels' angle (the
    tyres' share alone, without the compliance steer)."""
    use = [p for p in points if p.steady and p.lateral_accel_g <= linear_limit_g]
    if len(use) < 2:
        raise ValueError(f"need two steady points below {linear_limit_g} g, got {len(use)}")
    ay = np.array([p.lateral_accel_g for p in use])
    excess = np.degrees([(p.road_wheel_rad if road_wheel else p.steer_rad) - wheelbase_m / p.radius_m for p in use])
    beta = np.array([p.sideslip_cg_deg for p in use])
    roll = np.array([p.roll_deg for p in use])
    return {"understeer_gradient_deg_per_g": float(np.polyfit(ay, excess, 1)[0]),
            "sideslip_gradient_deg_per_g": float(np.polyfit(ay, beta, 1)[0]),
            "roll_gradient_deg_per_g": float(np.polyfit(ay, roll, 1)[0]),
            "points_in_fit": len(use)}


def progressive_limit(points: list[SteadyPoint], held: list[SteadyPoint]) -> bool:
    """ISO 4138's limit behaviour, as a yes/no: the steering grows with a_y over the runs that
    held the circle, and beyond them (faster runs) the car keeps at least 85 % of its highest
    a_y without its rear axle breaking away: the rear-axle sideslip within 2° of the trend of
    the held runs (β_rear against a_y through the last two held runs, extrapolated to each
    faster run's a_y: an understeering car at its limit runs wide with a_y growing a little,
    and its rear-axle sideslip with it; a breakaway leaves the trend)."""
    if len(held) < 2:
        return False
    steer = [p.steer_rad for p in held]
    if not all(b >= a for a, b in zip(steer, steer[1:])):
        return False
    top = max(p.lateral_accel_g for p in held)
    a, b = held[-2], held[-1]
    slope = (b.sideslip_rear_axle_deg - a.sideslip_rear_axle_deg) / (b.lateral_accel_g - a.lateral_accel_g)
    beyond = [p for p in points if p.target_speed_mps > b.target_speed_mps]
    return all(p.lateral_accel_g >= 0.85 * top
               and abs(p.sideslip_rear_axle_deg - (b.sideslip_rear_axle_deg + slope * (p.lateral_accel_g - b.lateral_accel_g))) < 2.0
               for p in beyond)


def limit_lateral_accel(points: list[SteadyPoint]) -> float:
    """The car's steady-state limit: the highest a_y of the steady runs (ISO 4138), whether
    the driver held the radius or the understeering car ran wide at its front tyres' limit."""
    steady = [p.lateral_accel_g for p in points if p.steady]
    return max(steady) if steady else float("nan")


def braking_distance(*, tyres: str = "magic_formula", start_kmh: float = 100.0, **car) -> float:
    """Distance (m) from full brakes at ``start_kmh`` to rest on a straight, flat road (``car``:
    as ``steady_circle``'s), counted from the brake command, as braking tests count from the
    pedal: the brakes' build-up time included."""
    import mujoco

    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.performance import _straight_road
    from biso_cosim.vehicle.sim import VehicleSim

    v0 = start_kmh / 3.6
    sim = VehicleSim(_straight_road(2000.0), tyres=tyres, **car)
    # up to speed at once: the car rolling at v0, its wheels turning with it
    m, d = sim.model, sim.data
    d.qvel[0:2] = (v0 * math.cos(sim.route.start_xy_yaw[2]), v0 * math.sin(sim.route.start_xy_yaw[2]))
    for w in ("fl", "fr", "rl", "rr"):
        d.qvel[m.jnt_dofadr[m.joint(f"{w}_spin").id]] = v0 / sim.index.wheel_radius_m
    mujoco.mj_forward(m, d)
    # one step rolling free: the parked car's brakes released, their build-up with them
    sim.apply(DriverCommand(steer_rad=0.0, drive=0.0, brake=0.0))
    sim.step(1)
    start = d.sensordata[sim.index.rear_axle_pos][:2].copy()
    brake = DriverCommand(steer_rad=0.0, drive=0.0, brake=1.0)
    for _ in range(int(20.0 * sim.control_rate_hz)):
        sim.apply(brake)
        truth = sim.step()
        if abs(truth.speed_mps[-1]) < 0.05:
            break
    return float(np.linalg.norm(d.sensordata[sim.index.rear_axle_pos][:2] - start))


@dataclass(frozen=True)
class StepSteer:
    """ISO 7401 step steer: times from the moment the steering reaches half its step."""

    speed_mps: float
    steer_rad: float
    steady_yaw_rate_rad_s: float
    steady_lateral_accel_g: float
    yaw_rate_response_time_s: float
    """to 90 % of the steady yaw rate"""
    yaw_rate_peak_time_s: float
    yaw_rate_overshoot: float
    """(peak − steady)/steady"""
    lateral_accel_response_time_s: float
    """to 90 % of the steady lateral acceleration"""


def step_steer(*, speed_mps: float = 80.0 / 3.6, lateral_accel_mps2: float = 4.0, steer_rate_rad_s: float = 0.4,
               tyres: str = "magic_formula", understeer_deg_per_g: float | None = None, **car) -> StepSteer:
    """ISO 7401 step steer (``step_steer_series``) and its figures."""
    run = step_steer_series(speed_mps=speed_mps, lateral_accel_mps2=lateral_accel_mps2,
                            steer_rate_rad_s=steer_rate_rad_s, tyres=tyres, understeer_deg_per_g=understeer_deg_per_g,
                            **car)
    # times from the steering command (ISO 7401's steering-wheel angle), not the road wheels'
    # angle, which the compliance steer turns back as the front force builds
    t, delta, r, ay, steer = run["t_s"], run["command_rad"], run["yaw_rate_rad_s"], run["lateral_accel_mps2"], run["step_rad"]
    t50 = float(t[np.flatnonzero(delta >= 0.5 * steer)[0]])
    late = t > t[-1] - 1.5
    r_ss, ay_ss = float(np.mean(r[late])), float(np.mean(ay[late]))
    t90_r = float(t[np.flatnonzero(r >= 0.9 * r_ss)[0]])
    t90_ay = float(t[np.flatnonzero(ay >= 0.9 * ay_ss)[0]])
    i_peak = int(np.argmax(r))
    return StepSteer(speed_mps=speed_mps, steer_rad=steer, steady_yaw_rate_rad_s=r_ss, steady_lateral_accel_g=ay_ss / G,
                     yaw_rate_response_time_s=t90_r - t50, yaw_rate_peak_time_s=float(t[i_peak]) - t50,
                     yaw_rate_overshoot=float(r[i_peak] - r_ss) / r_ss,
                     lateral_accel_response_time_s=t90_ay - t50)


def step_steer_series(*, speed_mps: float = 80.0 / 3.6, lateral_accel_mps2: float = 4.0,
                      steer_rate_rad_s: float = 0.4, tyres: str = "magic_formula",
                      understeer_deg_per_g: float | None = None, **car) -> dict[str, np.ndarray]:
    """The time series of an ISO 7401 step steer from the steering command's start (t_s, the
    road-wheel angle's change steer_rad, the steering command's command_rad, yaw rate, lateral acceleration, speed; step_rad the
    commanded step) at ``speed_mps`` (80 km/h) to a steady ``lateral_accel_mps2`` (4 m/s²),
    the road-wheel angle ramped at ``steer_rate_rad_s`` (0.4 rad/s: about 350 °/s at the
    steering wheel of a 15:1 steering), the drive held at its value before the step. The step
    is sized from the linear bicycle model (L/R plus the understeer gradient, if given).
    ``car``: as ``steady_circle``'s."""
    from biso_cosim.frames import euler_from_quat
    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.performance import _straight_road
    from biso_cosim.vehicle.sim import Truth, VehicleSim

    sim = VehicleSim(_straight_road(3000.0), tyres=tyres, **car)
    wheelbase = sim.index.wheelbase_m
    radius = speed_mps ** 2 / lateral_accel_mps2
    steer = wheelbase / radius + math.radians(understeer_deg_per_g or 0.0) * lateral_accel_mps2 / G
    dt = 1.0 / sim.control_rate_hz
    mass, r_wheel = sim.parameters["total_mass_kg"], sim.index.wheel_radius_m
    peak = sim.parameters["max_drive_torque_nm"]
    integral, target, drive = 0.0, 0.0, 0.0
    approach = speed_mps / _RAMP_MPS2 + 8.0
    for _ in range(int(round(approach / dt))):  # up to speed, straight (the driver steers)
        command = sim.drive()
        target = min(target + _RAMP_MPS2 * dt, speed_mps)
        error = target - float(sim.data.sensordata[sim.index.rear_axle_vel_b.start])
        integral += error * dt
        drive = min(max(mass * (_SPEED_KP * error + _SPEED_KI * integral) * r_wheel / peak, 0.0), 1.0)
        sim.apply(DriverCommand(steer_rad=command.steer_rad, drive=drive, brake=0.0))
        sim.step()
    start_steer = float(sim.data.sensordata[sim.index.steering_angle.start])
    rows, commands, t_start = [], [], sim.steps_done / sim.physics_rate_hz
    for k in range(int(round(6.0 / dt))):
        angle = start_steer + min(k * dt * steer_rate_rad_s, steer)
        sim.apply(DriverCommand(steer_rad=angle, drive=drive, brake=0.0))
        rows.append(sim.step())
        commands.append(np.full(len(rows[-1]), angle - start_steer))
    truth = Truth.concatenate(rows)
    t = truth.t_s - t_start
    roll = euler_from_quat(truth.q_wb)[:, 0]
    ay = truth.specific_force_b[:, 1] - G * np.sin(roll)  # at the IMU site, less gravity's share of the roll
    r = truth.omega_b[:, 2]
    return {"t_s": t, "steer_rad": truth.steer_rad - start_steer, "command_rad": np.concatenate(commands),
            "yaw_rate_rad_s": r, "lateral_accel_mps2": ay, "speed_mps": truth.speed_mps, "step_rad": steer}


def limit_drive(route="figure8", *, duration_s: float = 40.0, speed_mps: float = 14.0,
                lateral_accel_mps2: float = 9.0, look_ahead_s: float = 0.25, seed: int = 0,
                estimators=("biso_plus",)):
    """Drive ``route`` at the limit as a hard (or learning) driver does, not as the scripted
    driver: pure pursuit with a short look-ahead (``look_ahead_s`` × speed, at least 4 m: the
    steering swings, here about 0.5 rad/s RMS, up to 0.43 rad), full throttle below the target
    speed and full brake above it (±0.3 m/s), the target min(``speed_mps``, √(a/κ)) of the
    largest curvature κ in the next max(15 m, v²/12) at a lateral acceleration
    ``lateral_accel_mps2`` beyond the tyres' linear range (figure8, 14 m/s, 9 m/s²: 9-10 m/s² of
    lateral specific force, the rear axle sliding at up to 15-20° in the loops, the front wheels
    braked beyond their peak slip in the ABS). 1 s braked at rest first; the last 20 m braked to
    rest. Returns (the ``CoSimulation``, its ``RunResult``, the commands (steer, drive, brake)
    per control period)."""
    from biso_cosim.cosim import CoSimulation
    from biso_cosim.vehicle.driver import DriverCommand

    sim = CoSimulation(route, duration_s=duration_s, seed=seed, estimators=estimators)
    path = sim.route.path
    wheelbase = sim.vehicle.parameters["wheelbase_m"]
    n = int(math.ceil(duration_s * sim.vehicle.control_rate_hz - 1e-9))
    x, y, yaw = sim.route.start_xy_yaw
    v, idx, commands = 0.0, 0, []
    for k in range(n):
        lo, hi = max(idx - 20, 0), min(idx + 400, len(path) - 1)
        idx = lo + int(np.argmin((path.x_m[lo:hi] - x) ** 2 + (path.y_m[lo:hi] - y) ** 2))
        s = path.s_m[idx]
        ahead = (path.s_m > s) & (path.s_m < s + max(15.0, v * v / 12.0))
        kappa = float(np.abs(path.curvature_per_m[ahead]).max()) if ahead.any() else 0.0
        target = min(speed_mps, math.sqrt(lateral_accel_mps2 / kappa)) if kappa > 1e-6 else speed_mps
        if path.s_m[-1] - s < 20.0:
            target = 0.0
        look = max(4.0, look_ahead_s * v)
        j = min(int(np.searchsorted(path.s_m, s + look)), len(path) - 1)
        alpha = (math.atan2(path.y_m[j] - y, path.x_m[j] - x) - yaw + math.pi) % (2.0 * math.pi) - math.pi
        steer = min(max(math.atan(2.0 * wheelbase * math.sin(alpha) / look), -0.6), 0.6)
        if k < sim.vehicle.control_rate_hz:
            command = DriverCommand(0.0, 0.0, 1.0)
        elif v < target - 0.3:
            command = DriverCommand(steer, 1.0, 0.0)
        elif v > target + 0.3:
            command = DriverCommand(steer, 0.0, 1.0)
        else:
            command = DriverCommand(steer, 0.0, 0.0)
        commands.append((command.steer_rad, command.drive, command.brake))
        _, truth, _ = sim.step(command)
        (x, y), (qw, qx, qy, qz) = truth.pos_w[-1, :2], truth.q_wb[-1]
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        v = float(np.hypot(*truth.vel_w[-1, :2]))
    return sim, sim.result(), np.array(commands)


def step_cost_us(*, steps: int = 5000, repeats: int = 7) -> dict[str, float]:
    """µs per mj_step of the car on flat ground with each tyre model (driving a curve), the
    best of ``repeats`` interleaved timings: the tyre plugin's cost against today's step."""
    import time

    import mujoco

    from biso_cosim.vehicle.model import build_model
    from biso_cosim.vehicle.terrain import Terrain

    runs = {}
    for tyres in ("coulomb", "magic_formula"):
        model, _ = build_model(Terrain(()), tyres=tyres)
        data = mujoco.MjData(model)
        data.ctrl[model.actuator("drive").id] = 300.0
        data.ctrl[model.actuator("steer").id] = 0.1
        mujoco.mj_step(model, data, 2000)
        runs[tyres] = (model, data, [])
    for _ in range(repeats):
        for model, data, times in runs.values():
            t0 = time.perf_counter()
            mujoco.mj_step(model, data, steps)
            times.append((time.perf_counter() - t0) / steps * 1e6)
    cost = {f"{name}_us_per_step": min(times) for name, (_, _, times) in runs.items()}
    cost["ratio"] = cost["magic_formula_us_per_step"] / cost["coulomb_us_per_step"]
    return cost


def handling_report(out_dir: str | Path, *, speeds_mps=(6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 17.0, 18.0, 19.0, 20.0, 21.0),
                    radius_m: float = 40.0, tyres: str = "magic_formula", tyre_params=None,
                    chassis_params=None) -> dict:
    """Run the tests, write handling.md, handling.json and handling_circle.png into ``out_dir``;
    with ``tyre_params`` (``tyres.TyreParams``) and ``chassis_params`` (``tyres.ChassisParams``)
    other than the reference car's, if given."""
    from biso_cosim.vehicle.model import vehicle_parameters

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    car = {"tyre_params": tyre_params, "chassis_params": chassis_params}
    points = [steady_circle(v, radius_m=radius_m, tyres=tyres, **car) for v in speeds_mps]
    wheelbase = vehicle_parameters()["wheelbase_m"]
    fit = understeer_fit(points, wheelbase)
    fit["understeer_gradient_road_wheel_deg_per_g"] = understeer_fit(points, wheelbase, road_wheel=True)[
        "understeer_gradient_deg_per_g"]
    held = [p for p in points if p.steady and abs(p.radius_m - radius_m) < 0.1 * radius_m]
    max_ay = limit_lateral_accel(points)
    progressive = progressive_limit(points, held)
    stop = braking_distance(tyres=tyres, **car)
    step = step_steer(tyres=tyres, understeer_deg_per_g=fit["understeer_gradient_deg_per_g"], **car)
    figures = {**fit, "max_lateral_accel_g": max_ay, "progressive_limit": progressive,
               "stopping_distance_100_m": stop, "yaw_rate_response_time_s": step.yaw_rate_response_time_s,
               "yaw_rate_peak_time_s": step.yaw_rate_peak_time_s, "yaw_rate_overshoot": step.yaw_rate_overshoot,
               "lateral_accel_response_time_s": step.lateral_accel_response_time_s}
    changed = {name: {k: v for k, v in asdict(p).items() if v != getattr(type(p)(), k)}
               for name, p in car.items() if p is not None}
    result = {"tyres": tyres, "radius_m": radius_m, "parameters": changed, "figures": figures,
              "points": [asdict(p) for p in points],
              "step_steer": asdict(step), "step_cost": step_cost_us()}
    (out / "handling.json").write_text(json.dumps(result, indent=2))
    (out / "handling.md").write_text(report_markdown(result))
    _plot(points, wheelbase, out / "handling_circle.png")
    return result


def report_markdown(result: dict) -> str:
    f = result["figures"]
    rows = [f"# Handling ({result['tyres']} tyres), `biso-cosim vehicle handling`", "",
            "| figure | measured | class (published) | within | source |", "|---|---|---|---|---|"]
    changed = [f"{k} = {v!r}" for group in result.get("parameters", {}).values() for k, v in group.items()]
    if changed:
        rows[2:2] = [f"Parameters changed from the reference car's: {', '.join(changed)}.", ""]
    units = {"understeer_gradient_deg_per_g": "°/g", "max_lateral_accel_g": "g", "roll_gradient_deg_per_g": "°/g",
             "stopping_distance_100_m": "m"}
    for key, ((lo, hi), source) in PUBLISHED.items():
        value = f[key]
        ok = "yes" if lo <= value <= hi else "**no**"
        rows.append(f"| {key} | {value:.2f} {units[key]} | {lo:g} to {hi:g} {units[key]} | {ok} | {source} |")
    rows.append(f"| progressive limit (steering grows with a_y; beyond the held radius ≥ 85 % of the a_y kept, "
                f"rear-axle sideslip within 2° of its trend) | {f['progressive_limit']} | true | "
                f"{'yes' if f['progressive_limit'] else '**no**'} | ISO 4138 |")
    rows.append(f"| understeer gradient of the road-wheel angle (the tyres' share, without the compliance steer) | "
                f"{f['understeer_gradient_road_wheel_deg_per_g']:.2f} °/g | - | - | - |")
    rows.append(f"| sideslip_gradient_deg_per_g (at the centre of mass) | {f['sideslip_gradient_deg_per_g']:.2f} °/g "
                "| - | - | no verified class range |")
    for key, unit in (("yaw_rate_response_time_s", "s"), ("yaw_rate_peak_time_s", "s"),
                      ("lateral_accel_response_time_s", "s")):
        rows.append(f"| {key} (ISO 7401, 80 km/h, 4 m/s²) | {f[key]:.3f} {unit} | - | - | no verified class range |")
    rows.append(f"| yaw_rate_overshoot (ISO 7401) | {f['yaw_rate_overshoot']:.1%} | - | - | no verified class range |")
    cost = result["step_cost"]
    rows += ["", f"Physics step: {cost['coulomb_us_per_step']:.1f} µs with the Coulomb tyres, "
             f"{cost['magic_formula_us_per_step']:.1f} µs with the Magic Formula plugin "
             f"({cost['ratio'] - 1.0:+.1%}; best of 7 interleaved timings of 5000 steps, on this machine now).",
             "", f"ISO 4138 constant radius {result['radius_m']:g} m; understeer and sideslip gradients fitted "
             f"over a_y ≤ 0.4 g ({f['points_in_fit']} points); the roll gradient over the same points.", "",
             "| target speed m/s | a_y g | steer (command) rad | road wheels rad | radius m | β at CG ° | "
             "β at rear axle ° | steady |",
             "|---|---|---|---|---|---|---|---|"]
    for p in result["points"]:
        rows.append(f"| {p['target_speed_mps']:.0f} | {p['lateral_accel_g']:.3f} | {p['steer_rad']:.4f} | "
                    f"{p['road_wheel_rad']:.4f} | "
                    f"{p['radius_m']:.1f} | {p['sideslip_cg_deg']:.2f} | {p['sideslip_rear_axle_deg']:.2f} | "
                    f"{p['steady']} |")
    return "\n".join(rows) + "\n"


def _plot(points: list[SteadyPoint], wheelbase_m: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ay = [p.lateral_accel_g for p in points]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    axes[0].plot(ay, [math.degrees(p.steer_rad) for p in points], "o-", label="road-wheel angle δ")
    axes[0].plot(ay, [math.degrees(wheelbase_m / p.radius_m) for p in points], "--", label="Ackermann L/R")
    axes[0].set_xlabel("lateral acceleration, g")
    axes[0].set_ylabel("°")
    axes[0].legend()
    axes[0].set_title("ISO 4138 steady circle: steering")
    axes[1].plot(ay, [p.sideslip_cg_deg for p in points], "o-", label="β at centre of mass")
    axes[1].plot(ay, [p.sideslip_rear_axle_deg for p in points], "s-", label="β at rear axle")
    axes[1].set_xlabel("lateral acceleration, g")
    axes[1].set_ylabel("sideslip, °")
    axes[1].legend()
    axes[1].set_title("sideslip")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
