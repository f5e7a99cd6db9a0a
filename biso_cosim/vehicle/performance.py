"""The car's performance measured with the MuJoCo car: 0-100 km/h, top speed, wheel slip.

A full-throttle run from rest on a straight, flat road (steering held straight, brakes
released), every control period through the same path as every run
(``VehicleSim.apply``: the drivetrain at the current wheel speeds). ``biso-cosim vehicle
performance`` prints it; docs/vehicle.md compares it with the published figures of the
car's class, and tests/test_drivetrain.py checks it within tolerances.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Performance", "measure_performance", "PUBLISHED"]

PUBLISHED = {
    "zero_to_100_s": (9.3, 10.2),
    "top_speed_kmh": (193.0, 204.0),
}
"""Published figures of the class (maker's data): VW Polo VI 1.0 TSI 85 kW, 0-100 km/h 9.3 s
(DSG) to 9.5 s, 193-197 km/h; VW Golf VII/VIII 1.0 TSI 85 kW, 9.7-10.2 s, 202-204 km/h."""


@dataclass(frozen=True)
class Performance:
    """What a full-throttle run from rest shows."""

    zero_to_100_s: float
    """Time from rest to 100 km/h, s (from the moment the brakes release)."""
    top_speed_mps: float
    """Highest speed reached (the speed no longer grows by 0.1 km/h in 10 s), m/s."""
    top_gear: int
    """The gear at the top speed."""
    max_slip_after_1s: float
    """Largest drive slip of the rear axle after the first second, (ω_rear − ω_front)/ω_front."""
    max_rear_wheel_speed_mps: float
    """Largest rear wheel circumferential speed, m/s."""
    duration_s: float
    """Simulated time of the run, s."""

    def table(self) -> str:
        lo, hi = PUBLISHED["zero_to_100_s"]
        tlo, thi = PUBLISHED["top_speed_kmh"]
        rows = ["| figure | measured | class (published) |", "|---|---|---|",
                f"| 0-100 km/h | {self.zero_to_100_s:.1f} s | {lo}-{hi} s |",
                f"| top speed | {self.top_speed_mps * 3.6:.0f} km/h (gear {self.top_gear}) | {tlo:.0f}-{thi:.0f} km/h |",
                f"| rear-wheel drive slip after the first second, largest | {self.max_slip_after_1s:.1%} | "
                "a few %; traction control keeps it below 10-15 % |",
                f"| largest rear wheel speed | {self.max_rear_wheel_speed_mps:.1f} m/s | the car's speed plus the slip |"]
        return "\n".join(rows)


def _straight_road(length_m: float):
    from biso_cosim.routes.route import parse_route

    return parse_route({
        "format": 1, "name": "straight", "description": f"{length_m:g} m straight, flat", "closed": False,
        "driving": {"default_speed_mps": 30.0, "start_wait_s": 0.0},
        "waypoint": [{"x_m": 0.0, "y_m": 0.0}, {"x_m": length_m, "y_m": 0.0}]}, source="<performance>")


def measure_performance(*, duration_s: float = 90.0, control_rate_hz: float = 50.0, drivetrain=None) -> Performance:
    """Drive the car at full throttle from rest for ``duration_s`` on a straight, flat road."""
    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.drivetrain import DRIVETRAIN, _available_torque
    from biso_cosim.vehicle.sim import Truth, VehicleSim

    if not duration_s > 20.0:
        raise ValueError(f"duration_s must be > 20 s, got {duration_s!r}")
    sim = VehicleSim(_straight_road(6000.0), control_rate_hz=control_rate_hz,
                     drivetrain=DRIVETRAIN if drivetrain is None else drivetrain)
    full = DriverCommand(steer_rad=0.0, drive=1.0, brake=0.0)
    last = []
    for _ in range(int(round(duration_s * control_rate_hz))):
        sim.apply(full)
        last.append(sim.step()[-1])  # the last row of each period
    truth = Truth.concatenate(last)
    t, speed, wheels = truth.t_s, truth.speed_mps, truth.wheel_rates
    radius = sim.index.wheel_radius_m
    front, rear = 0.5 * (wheels[:, 0] + wheels[:, 1]), 0.5 * (wheels[:, 2] + wheels[:, 3])
    reach = np.flatnonzero(speed >= 100.0 / 3.6)
    zero_to_100 = float(t[reach[0]]) if reach.size else float("nan")
    late = t >= 1.0
    slip = (rear[late] - front[late]) / np.maximum(front[late], 1e-3)
    top = float(speed.max())
    _, gear = _available_torque(sim.drivetrain_coefficients, False, float(rear[-1]))
    return Performance(zero_to_100_s=zero_to_100, top_speed_mps=top, top_gear=int(gear),
                       max_slip_after_1s=float(slip.max()), max_rear_wheel_speed_mps=float(rear.max() * radius),
                       duration_s=float(t[-1]))
