"""The limit of the car on the slip-based tyres (ISO 4138 on the 40 m circle, vehicle/handling.py):
the highest steady lateral acceleration within the class's published range, reached
progressively (the understeering car runs wide at its front tyres' limit, its rear axle
keeps its grip: the traction control reads the faster rear wheel's slip, so the open
differential's unloaded inner wheel does not spin up)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from biso_cosim.vehicle.handling import PUBLISHED, limit_lateral_accel, progressive_limit, steady_circle

RADIUS_M = 40.0


@pytest.fixture(scope="module")
def points():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the route's lateral-acceleration cap: the runs hold their own speed
        return [steady_circle(v, radius_m=RADIUS_M) for v in (16.0, 18.0, 20.0, 21.0)]


def test_the_limit_lateral_acceleration_is_the_classs_and_is_reached_progressively(points):
    (lo, hi), _ = PUBLISHED["max_lateral_accel_g"]
    assert lo <= limit_lateral_accel(points) <= hi
    held = [p for p in points if p.steady and abs(p.radius_m - RADIUS_M) < 0.1 * RADIUS_M]
    assert [round(p.target_speed_mps) for p in held] == [16, 18]
    assert progressive_limit(points, held)
    # beyond the held radius the car runs wide (understeer) with the steering at the front's
    # limit, and the rear axle's sideslip stays within a few degrees
    beyond = [p for p in points if p not in held]
    assert all(p.radius_m > 1.1 * RADIUS_M and p.steady for p in beyond)
    assert all(p.sideslip_rear_axle_deg > -8.0 for p in beyond)


def test_the_progressive_criterion_refuses_a_breakaway():
    """The criterion itself: a faster run whose rear-axle sideslip leaves the held runs' trend
    by more than 2° (a spin), or whose a_y falls below 85 % of the held limit, is not progressive."""
    from dataclasses import replace

    from biso_cosim.vehicle.handling import SteadyPoint

    def point(v, ay, beta_rear):
        return SteadyPoint(target_speed_mps=v, speed_mps=v, yaw_rate_rad_s=ay * 9.80665 / v, lateral_accel_g=ay,
                           steer_rad=0.07 + 0.05 * ay, road_wheel_rad=0.07, radius_m=40.0, sideslip_cg_deg=0.0,
                           sideslip_rear_axle_deg=beta_rear, roll_deg=4.5 * ay, steady=True)

    held = [point(16.0, 0.64, -3.4), point(18.0, 0.78, -4.6)]
    trend = -4.6 + (-4.6 + 3.4) / (0.78 - 0.64) * (0.88 - 0.78)
    assert progressive_limit([*held, point(20.0, 0.88, trend - 1.5)], held)
    assert not progressive_limit([*held, point(20.0, 0.88, trend - 2.5)], held)
    assert not progressive_limit([*held, point(20.0, 0.60, -4.6)], held)
    assert not progressive_limit([*held, replace(point(20.0, 0.9, trend), steer_rad=0.0)], [*held, replace(
        point(20.0, 0.9, trend), steer_rad=0.0)])
    assert np.isnan(limit_lateral_accel([replace(held[0], steady=False)]))
