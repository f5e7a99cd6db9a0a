"""Drive whole routes with the scripted driver and report how the car and driver did.

This is the full-length companion of the short route tests in the suite: for each route it
reports whether the car reached the end, the driver's cross-track error, the attitude and
specific-force ranges the route produced, and the cost of simulating it.
"""

from __future__ import annotations

import math
import time

import numpy as np

from biso_cosim.frames import euler_from_quat
from biso_cosim.routes import load_route
from biso_cosim.vehicle.sim import Truth, VehicleSim

__all__ = ["drive_route_check"]


def drive_route_check(name: str, extra_s: float = 30.0) -> dict:
    """Drive ``name`` to its end (or its nominal duration + ``extra_s``) and measure it."""
    route = load_route(name)
    sim = VehicleSim(route)
    limit = route.nominal_duration_s + extra_s
    chunks, cross = [], []
    start = time.perf_counter()
    while not sim.driver.finished and len(chunks) / sim.control_rate_hz < limit:
        sim.drive()
        chunks.append(sim.step())
        cross.append(sim.driver.state.cross_track_m)
    wall = time.perf_counter() - start
    truth = Truth.concatenate(chunks)
    angles = np.degrees(euler_from_quat(truth.q_wb))
    cross = np.asarray(cross)
    f = truth.specific_force_b
    return {
        "route": route.name,
        "completed": bool(sim.driver.finished),
        "time_s": round(len(chunks) / sim.control_rate_hz, 2),
        "nominal_s": round(route.nominal_duration_s, 1),
        "cross_track_max_m": round(float(np.max(np.abs(cross))), 3),
        "cross_track_rms_m": round(float(np.sqrt(np.mean(cross**2))), 3),
        "roll_range_deg": [round(float(angles[:, 0].min()), 2), round(float(angles[:, 0].max()), 2)],
        "pitch_range_deg": [round(float(angles[:, 1].min()), 2), round(float(angles[:, 1].max()), 2)],
        "max_yaw_rate_deg_s": round(math.degrees(float(np.max(np.abs(truth.omega_b[:, 2])))), 2),
        "max_horizontal_specific_force_mps2": round(float(np.max(np.hypot(f[:, 0], f[:, 1]))), 2),
        "vertical_specific_force_range_mps2": [round(float(f[:, 2].min()), 2), round(float(f[:, 2].max()), 2)],
        "speed_range_mps": [round(float(truth.speed_mps.min()), 2), round(float(truth.speed_mps.max()), 2)],
        "wall_s": round(wall, 2),
        "sim_seconds_per_wall_second": round(len(chunks) / sim.control_rate_hz / wall, 1),
    }
