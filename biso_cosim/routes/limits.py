"""What the car can drive: the bounds that route files and imported tracks are checked against.

One record, :class:`CarLimits`, holds them with the source of each number. They come from
the compiled car model through :func:`biso_cosim.vehicle.model.vehicle_parameters` (the MJCF
is the one source of the car's geometry, brakes and tyre friction) and from its drivetrain
(:mod:`biso_cosim.vehicle.drivetrain`, the one source of its engine, gears and driving
resistances: the top speed, the drive torque).

Friction limits use the fraction of the tyres' friction coefficient μ = 1 that the scripted
driver may ask for, ``USABLE_FRICTION``. With the default Magic Formula tyres
(``vehicle.tyres``, docs/vehicle.md "Handling") the understeer gradient stays near its linear
3.1 °/g up to about 0.5 g and grows beyond (the steering 0.094 rad at 0.50 g, 0.104 at 0.64 g,
0.123 at 0.78 g on the 40 m circle, where the car holds at most 0.78 g and runs wide at
0.83-0.88 g); with the Coulomb sphere tyres the car steers kinematically up to 0.65 g and
slides suddenly at 0.76 g (docs/design.md §11). 0.65 keeps a route below both limits with
the driver on its path (``biso-cosim routes check``: cross-track RMS 0.09-0.34 m on the
library routes with the magic_formula tyres; docs/routes.md). The same fraction bounds
traction, braking (the Magic Formula tyres brake at 1.19 g with the ABS) and the climbable
grade.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache

import numpy as np

__all__ = ["CarLimits", "car_limits", "USABLE_FRICTION", "STANDARD_GRAVITY_MPS2", "MAX_UNROUNDED_TURN_RAD"]

STANDARD_GRAVITY_MPS2 = 9.80665

USABLE_FRICTION = 0.65
"""Fraction of μ a route may use (Magic Formula tyres: 0.78 g held on a 40 m circle, understeer growing
beyond 0.5 g; sphere tyres: kinematic to 0.65 g, slide at 0.76 g; see the module docstring)."""

MAX_UNROUNDED_TURN_RAD = math.radians(90.0)
"""Largest turn at a waypoint without a fillet (and not a change of direction): the driver cuts
such a corner, by 1.4 m at 90° and 2.2 m at 120° at 8 m/s (measured with the scripted driver)."""


@dataclass(frozen=True)
class CarLimits:
    """The car's limits that a route must respect, SI units; ``sources`` says where each comes from."""

    top_speed_mps: float
    """Highest target speed."""
    accel_mps2: float
    """Largest longitudinal acceleration: drive torque and traction of the driven (rear) axle."""
    decel_mps2: float
    """Largest braking deceleration: brake torque and traction of all four wheels."""
    lateral_accel_mps2: float
    """Largest lateral acceleration in curves."""
    turning_radius_m: float
    """Smallest radius of the rear axle's path at full steering lock (bicycle model)."""
    grade: float
    """Steepest grade (rise over run) the car can climb from rest on the driven axle's traction."""
    sources: dict = field(default_factory=dict, compare=False)
    reverse_top_speed_mps: float = math.inf
    """Highest speed in reverse: the reverse gear at the rev limit."""
    full_throttle_mps_mps2: tuple = field(default=((0.0, math.inf), (math.inf, math.inf)), compare=False)
    """(speeds, m/s; accelerations, m/s²): the car's full-throttle acceleration on a flat road
    at those speeds (drivetrain against the driving resistances; linear in between)."""

    def full_throttle_accel_mps2(self, speed_mps: float) -> float:
        """The car's largest acceleration at ``speed_mps`` on a flat road, forward, m/s²."""
        speeds, accels = self.full_throttle_mps_mps2
        return float(np.interp(speed_mps, speeds, accels))

    def table(self) -> str:
        """The limits as a Markdown table with their sources (docs/routes.md shows it)."""
        rows = ["| limit | value | source |", "|---|---|---|"]
        for name, unit, scale in (("top_speed_mps", "m/s", 1.0), ("accel_mps2", "m/s²", 1.0),
                                  ("decel_mps2", "m/s²", 1.0), ("lateral_accel_mps2", "m/s²", 1.0),
                                  ("turning_radius_m", "m", 1.0), ("grade", "%", 100.0)):
            rows.append(f"| `{name}` | {getattr(self, name) * scale:.2f} {unit} | {self.sources[name]} |")
        return "\n".join(rows)


@cache
def car_limits() -> CarLimits:
    """The limits of the library's car (biso_cosim/vehicle/car.xml), read from its compiled model."""
    from biso_cosim.vehicle.drivetrain import (DRIVETRAIN, RPM_PER_RAD_S, resistance_force, top_speed,
                                               traction_torque_nm, wheel_torque)
    from biso_cosim.vehicle.model import car_spec, vehicle_parameters

    model = car_spec().compile()
    p = vehicle_parameters(model)
    mu = float(model.geom("fl_tyre").friction[0]) * USABLE_FRICTION
    g = STANDARD_GRAVITY_MPS2
    m, wheelbase, h = p["total_mass_kg"], p["wheelbase_m"], p["cg_height_m"]
    rear_share = p["cg_behind_front_axle_m"] / wheelbase  # static load on the driven rear axle
    # rear-axle traction with the load transfer of the acceleration a itself:
    # μ·m·(g·b/L + a·h/L) = m·a  →  a = μ·g·(b/L) / (1 − μ·h/L)
    traction = mu * g * rear_share / (1.0 - mu * h / wheelbase)
    radius = p["wheel_radius_m"]
    tc = traction_torque_nm(DRIVETRAIN, mass_kg=m, wheel_radius_m=radius, rear_load_share=rear_share,
                            cg_height_over_wheelbase=h / wheelbase)
    torque = min(p["max_drive_torque_nm"], tc) / radius / m
    damping = p["wheel_damping_nms_per_rad"]
    v_top, gear = top_speed(DRIVETRAIN, mass_kg=m, wheel_radius_m=radius, wheel_damping_nms=damping)
    speeds = np.linspace(0.0, v_top, 200)
    accels = np.array([(min(wheel_torque(1.0, v / radius, v / radius, DRIVETRAIN, wheel_radius_m=radius)[0], tc) / radius
                        + resistance_force(v, DRIVETRAIN, mass_kg=m) - 4.0 * damping * v / radius ** 2) / m
                       for v in speeds])
    reverse_top = (DRIVETRAIN.rev_limit_rpm / RPM_PER_RAD_S / (DRIVETRAIN.reverse_ratio * DRIVETRAIN.final_drive)
                   * radius)
    brakes = 4.0 * p["max_brake_torque_per_wheel_nm"] / p["wheel_radius_m"] / m
    # climbing from rest on a grade θ: μ·(cos θ·b/L + sin θ·h/L) = sin θ
    grade = mu * rear_share / (1.0 - mu * h / wheelbase)
    friction = f"tyre friction μ = {mu / USABLE_FRICTION:g} (car.xml) × {USABLE_FRICTION} usable (docs/design.md §11)"
    sources = {
        "top_speed_mps": (f"drivetrain (vehicle/drivetrain.py): {DRIVETRAIN.max_power_w / 1e3:g} kW against drag "
                          f"c_w·A = {DRIVETRAIN.drag_area_m2:g} m², rolling c_rr = {DRIVETRAIN.rolling_resistance:g} "
                          f"and the wheel bearings, in gear {gear} ({v_top * 3.6:.0f} km/h)"),
        "accel_mps2": (f"rear-axle traction, {friction}, {rear_share:.0%} static load, load transfer "
                       f"h/L = {h / wheelbase:.3f}; the drive torque and traction control alone allow "
                       f"{torque:.1f} m/s²"),
        "decel_mps2": f"{friction}, all four wheels braked; the brakes alone allow {brakes:.1f} m/s²",
        "lateral_accel_mps2": friction,
        "turning_radius_m": (f"wheelbase {wheelbase:g} m / tan(max steer {p['max_steer_rad']:g} rad), "
                             "car.xml"),
        "grade": f"rear-axle traction from rest, {friction}",
    }
    return CarLimits(top_speed_mps=v_top, accel_mps2=min(traction, torque),
                     decel_mps2=min(mu * g, brakes), lateral_accel_mps2=mu * g,
                     turning_radius_m=wheelbase / math.tan(p["max_steer_rad"]), grade=grade, sources=sources,
                     reverse_top_speed_mps=reverse_top,
                     full_throttle_mps_mps2=(tuple(speeds.tolist()), tuple(np.maximum(accels, 0.0).tolist())))
