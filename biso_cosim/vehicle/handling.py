"""Handling of the car with slip-based tyres, against published figures of its class.

``biso-cosim vehicle handling --out DIR`` runs these with ``tyres="magic_formula"``
(``vehicle.tyres``) and writes ``handling.md`` (each figure next to its published class
range and source), ``handling.json`` and the plots:

* ISO 4138 steady-state circular driving, constant-radius method: the scripted driver holds a
  circle of ``radius_m`` at a series of constant speeds; from the steady part of each run the
  lateral acceleration a_y = v·r (v forward speed, r yaw rate), the road-wheel steering angle
  δ (the bicycle-model angle of the steering column), the radius R = v/r and the sideslip
  angle β at the centre of mass. The understeer gradient is the slope of δ − L/R against
  a_y/g (ISO 4138, the steering angle less the Ackermann angle) over the linear range
  a_y ≤ ``linear_limit_g``; the sideslip gradient the slope of β. The limit is progressive
  when δ grows with a_y up to the highest a_y the car holds, without a jump.
* braking from 100 km/h on a straight, flat road (the brakes of every wheel at full
  command, no ABS): the stopping distance.

Published ranges (see ``PUBLISHED``) are of compact cars; each has its source.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["PUBLISHED", "SteadyPoint", "steady_circle", "understeer_fit", "braking_distance", "handling_report"]

G = 9.80665
# the speed loop of the steady-circle runs: ramp, proportional (1/s) and integral (1/s²) gains
_RAMP_MPS2, _SPEED_KP, _SPEED_KI = 2.0, 1.5, 0.5

PUBLISHED = {
    "understeer_gradient_deg_per_g": ((2.0, 4.0), "road-wheel angle of a compact front-engined car: Gillespie, "
                                      "Fundamentals of Vehicle Dynamics (1992), ch. 6 (passenger cars 1-4 °/g "
                                      "at the road wheels; Milliken & Milliken, Race Car Vehicle Dynamics (1995), "
                                      "ch. 5: production cars 1-5 °/g); the issue's 2-4 °/g"),
    "sideslip_gradient_deg_per_g": ((-4.0, -1.0), "sideslip at the centre of mass at speed of passenger cars, "
                                    "nose inward for a y-left sign (negative): about 1-4 °/g "
                                    "(Heißing & Ersoy, Chassis Handbook (2011), §2.6 steady-state cornering)"),
    "max_lateral_accel_g": ((0.75, 0.95), "steady-state limit of compact cars on dry asphalt, ISO 4138 "
                            "(Heißing & Ersoy, Chassis Handbook (2011), §2.6: 0.8-0.9 g for passenger "
                            "cars on summer tyres)"),
    "stopping_distance_100_m": ((34.0, 40.0), "100-0 km/h of compact hatchbacks of the class on dry "
                                "asphalt (ADAC / auto motor und sport braking tests of VW Golf VII/VIII: "
                                "34-38 m, with ABS)"),
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
    radius_m: float
    sideslip_cg_deg: float
    sideslip_rear_axle_deg: float
    steady: bool
    """True if the speed and the yaw rate held (std below 2 % of their means)."""


def _body_velocity(truth) -> np.ndarray:
    """IMU-site velocity in body axes (n, 3)."""
    from biso_cosim.frames import quat_rotate

    q = truth.q_wb
    conj = np.column_stack([q[:, 0], -q[:, 1], -q[:, 2], -q[:, 3]])
    return np.array([quat_rotate(c, v) for c, v in zip(conj, truth.vel_w)])


def steady_circle(speed_mps: float, *, radius_m: float = 40.0, tyres: str = "magic_formula",
                  settle_s: float = 8.0, window_s: float = 6.0) -> SteadyPoint:
    """One constant-speed run on the circle; the steady state over the last ``window_s``."""
    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.sim import Truth, VehicleSim

    ramp_s = speed_mps / _RAMP_MPS2 + 1.0
    duration = ramp_s + settle_s + window_s
    laps = int(math.ceil(speed_mps * duration / (2 * math.pi * radius_m))) + 1
    sim = VehicleSim(circle_route(radius_m, speed_mps, laps), tyres=tyres)
    rows = []
    # the driver steers; the speed is held by a PI loop of its own (the route's speed profile
    # caps the speed in curves at the car's route limit, below the tyres' limit)
    dt = 1.0 / sim.control_rate_hz
    mass, radius = sim.parameters["total_mass_kg"], sim.index.wheel_radius_m
    peak = sim.parameters["max_drive_torque_nm"]
    integral, target = 0.0, 0.0
    for k in range(int(round(duration * sim.control_rate_hz))):
        command = sim.drive()
        if k * dt > 0.5:
            target = min(target + _RAMP_MPS2 * dt, speed_mps)
            error = target - float(sim.data.sensordata[sim.index.rear_axle_vel_b.start])
            integral += error * dt
            accel = _SPEED_KP * error + _SPEED_KI * integral
            sim.apply(DriverCommand(steer_rad=command.steer_rad, drive=min(max(mass * accel * radius / peak, 0.0), 1.0),
                                    brake=0.0))
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
        steer_rad=float(np.mean(truth.steer_rad[last])), radius_m=speed / r,
        sideslip_cg_deg=math.degrees(float(np.mean(np.arctan2(v_cg[:, 1], v_cg[:, 0])))),
        sideslip_rear_axle_deg=math.degrees(float(np.mean(np.arctan2(v_axle[:, 1], v_axle[:, 0])))),
        steady=steady)


def understeer_fit(points: list[SteadyPoint], wheelbase_m: float, linear_limit_g: float = 0.4) -> dict[str, float]:
    """ISO 4138: slopes of δ − L/R and of β against a_y/g (least squares over the steady
    points with a_y ≤ ``linear_limit_g``), in °/g."""
    use = [p for p in points if p.steady and p.lateral_accel_g <= linear_limit_g]
    if len(use) < 2:
        raise ValueError(f"need two steady points below {linear_limit_g} g, got {len(use)}")
    ay = np.array([p.lateral_accel_g for p in use])
    excess = np.degrees([p.steer_rad - wheelbase_m / p.radius_m for p in use])
    beta = np.array([p.sideslip_cg_deg for p in use])
    return {"understeer_gradient_deg_per_g": float(np.polyfit(ay, excess, 1)[0]),
            "sideslip_gradient_deg_per_g": float(np.polyfit(ay, beta, 1)[0]),
            "points_in_fit": len(use)}


def braking_distance(*, tyres: str = "magic_formula", start_kmh: float = 100.0) -> float:
    """Distance (m) from full brakes at ``start_kmh`` to rest on a straight, flat road."""
    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.performance import _straight_road
    from biso_cosim.vehicle.sim import VehicleSim

    v0 = start_kmh / 3.6
    sim = VehicleSim(_straight_road(2000.0), tyres=tyres)
    # up to speed quickly: set the state (the car rolling at v0, wheels turning with it)
    m, d = sim.model, sim.data
    import mujoco

    d.qvel[0:2] = (v0 * math.cos(sim.route.start_xy_yaw[2]), v0 * math.sin(sim.route.start_xy_yaw[2]))
    for w in ("fl", "fr", "rl", "rr"):
        d.qvel[m.jnt_dofadr[m.joint(f"{w}_spin").id]] = v0 / sim.index.wheel_radius_m
    mujoco.mj_forward(m, d)
    start = d.sensordata[sim.index.rear_axle_pos][:2].copy()
    brake = DriverCommand(steer_rad=0.0, drive=0.0, brake=1.0)
    for _ in range(int(20.0 * sim.control_rate_hz)):
        sim.apply(brake)
        truth = sim.step()
        if abs(truth.speed_mps[-1]) < 0.05:
            break
    return float(np.linalg.norm(d.sensordata[sim.index.rear_axle_pos][:2] - start))


def handling_report(out_dir: str | Path, *, speeds_mps=(6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 17.0, 18.0, 19.0, 20.0),
                    radius_m: float = 40.0, tyres: str = "magic_formula") -> dict:
    """Run the tests, write handling.md, handling.json and handling_circle.png into ``out_dir``."""
    from biso_cosim.vehicle.model import vehicle_parameters

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    points = [steady_circle(v, radius_m=radius_m, tyres=tyres) for v in speeds_mps]
    wheelbase = vehicle_parameters()["wheelbase_m"]
    fit = understeer_fit(points, wheelbase)
    held = [p for p in points if p.steady and abs(p.radius_m - radius_m) < 0.1 * radius_m]
    max_ay = max(p.lateral_accel_g for p in held) if held else float("nan")
    steer = [p.steer_rad for p in held]
    progressive = bool(len(steer) >= 2 and all(b >= a for a, b in zip(steer, steer[1:]))
                       and max(np.diff(steer), default=0.0) < 0.05)
    stop = braking_distance(tyres=tyres)
    figures = {**fit, "max_lateral_accel_g": max_ay, "progressive_limit": progressive,
               "stopping_distance_100_m": stop}
    result = {"tyres": tyres, "radius_m": radius_m, "figures": figures, "points": [asdict(p) for p in points]}
    (out / "handling.json").write_text(json.dumps(result, indent=2))
    (out / "handling.md").write_text(report_markdown(result))
    _plot(points, wheelbase, out / "handling_circle.png")
    return result


def report_markdown(result: dict) -> str:
    f = result["figures"]
    rows = [f"# Handling ({result['tyres']} tyres), `biso-cosim vehicle handling`", "",
            "| figure | measured | class (published) | within | source |", "|---|---|---|---|---|"]
    units = {"understeer_gradient_deg_per_g": "°/g", "sideslip_gradient_deg_per_g": "°/g",
             "max_lateral_accel_g": "g", "stopping_distance_100_m": "m"}
    for key, ((lo, hi), source) in PUBLISHED.items():
        value = f[key]
        ok = "yes" if lo <= value <= hi else "**no**"
        rows.append(f"| {key} | {value:.2f} {units[key]} | {lo:g} to {hi:g} {units[key]} | {ok} | {source} |")
    rows.append(f"| progressive limit (steering grows with a_y, no jump) | {f['progressive_limit']} | true | "
                f"{'yes' if f['progressive_limit'] else '**no**'} | ISO 4138 |")
    rows += ["", f"ISO 4138 constant radius {result['radius_m']:g} m; understeer and sideslip gradients fitted "
             f"over a_y ≤ 0.4 g ({f['points_in_fit']} points).", "",
             "| target speed m/s | a_y g | steer rad | radius m | β at CG ° | β at rear axle ° | steady |",
             "|---|---|---|---|---|---|---|"]
    for p in result["points"]:
        rows.append(f"| {p['target_speed_mps']:.0f} | {p['lateral_accel_g']:.3f} | {p['steer_rad']:.4f} | "
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
