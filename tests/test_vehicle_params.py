"""The parameters an estimator takes from the car it rides on (``Estimator.vehicle_params``,
``VehicleSim.estimator_defaults``): the rear axle's position, its slip angle per g and the end of
its tyres' linear range."""

from __future__ import annotations

import dataclasses
import math

import pytest

from biso_cosim.cosim import CoSimulation, EstimatorSpec
from biso_cosim.estimators import estimator_vehicle_params
from biso_cosim.routes import load_route
from biso_cosim.vehicle.model import vehicle_parameters
from biso_cosim.vehicle.tyres import (TYRES, TyreParams, linear_accel_mps2, magic_formula, rear_slip_gradient_rad_per_g,
                                      surface_friction)

G0 = 9.80665


def test_the_rear_slip_gradient_is_the_rear_tyres_load_over_their_cornering_stiffness():
    """D_r = W_r/C_αr with C_αr the slope of the plugin's own F_y at a small slip angle, at the
    static load of a rear tyre: the single-track model's rear slip angle per g."""
    p = vehicle_parameters()
    w_r = p["cg_behind_front_axle_m"] / p["wheelbase_m"] * p["total_mass_kg"] * G0 / 2.0
    slip = 1e-4
    c_alpha = -magic_formula(w_r, 0.0, slip)[1] / slip  # the force opposes the slip
    assert rear_slip_gradient_rad_per_g(p) == pytest.approx(w_r / c_alpha, rel=1e-3)
    assert math.degrees(rear_slip_gradient_rad_per_g(p)) == pytest.approx(4.45, abs=0.01)
    # stiffer tyres slip less; the coulomb tyres steer kinematically
    stiffer = dataclasses.replace(TYRES, pky1=2.0 * TYRES.pky1)
    assert rear_slip_gradient_rad_per_g(p, params=stiffer) == pytest.approx(0.5 * rear_slip_gradient_rad_per_g(p))
    assert rear_slip_gradient_rad_per_g(p, "coulomb") == 0.0
    with pytest.raises(ValueError, match="tyres must be one of 'coulomb', 'magic_formula', got 'slick'"):
        rear_slip_gradient_rad_per_g(p, "slick")


def test_the_linear_range_ends_where_the_rear_tyres_secant_stiffness_is_10_percent_below_the_linear():
    """a_l = g₀ F_y/W_r at the slip angle where F_y/α = 0.9 C_αr (the plugin's own F_y, a rear
    tyre's static load); it scales with the road's friction as the peak does (λ_μ scales the
    peak, not the stiffness, so the curve bends sooner), and the coulomb tyres have none."""
    p = vehicle_parameters()
    w_r = p["cg_behind_front_axle_m"] / p["wheelbase_m"] * p["total_mass_kg"] * G0 / 2.0
    a_l = linear_accel_mps2(p)
    assert a_l == pytest.approx(6.13, abs=0.01)
    c_alpha = -magic_formula(w_r, 0.0, 1e-4)[1] / 1e-4
    f_y = a_l / G0 * w_r
    alpha = next(a for a in (x * 1e-5 for x in range(1, 20000)) if -magic_formula(w_r, 0.0, math.tan(a))[1] >= f_y)
    assert f_y / (c_alpha * alpha) == pytest.approx(0.9, abs=2e-3)
    assert linear_accel_mps2(p, friction_scale=surface_friction("wet")) == pytest.approx(4.29, abs=0.01)
    assert linear_accel_mps2(p, "coulomb") == 0.0
    sim = CoSimulation(load_route("figure8"), duration_s=1.0, estimators=["biso_plus"])
    assert sim.estimators["biso_plus"].params.linear_accel_mps2 == a_l
    assert "linear_accel_mps2" in estimator_vehicle_params("biso_plus")


def test_the_cosimulation_gives_biso_plus_the_cars_values_unless_the_user_set_them():
    route = load_route("figure8")
    mine = EstimatorSpec("biso_plus", {"rear_slip_gradient_rad_per_g": 0.01}, label="mine")
    sim = CoSimulation(route, duration_s=1.0, estimators=["biso_plus", "biso", mine])
    defaults = sim.vehicle.estimator_defaults()
    ix = sim.vehicle.index
    assert defaults["speed_point_b_m"] == tuple(float(v) for v in ix.rear_axle_b - ix.imu_pos_b)
    assert defaults["rear_slip_gradient_rad_per_g"] == rear_slip_gradient_rad_per_g(sim.vehicle.parameters)
    params = sim.estimators["biso_plus"].params
    assert params.rear_slip_gradient_rad_per_g == pytest.approx(0.0776, abs=1e-4)
    assert params.speed_point_b_m == defaults["speed_point_b_m"]
    assert sim.estimators["mine"].params.rear_slip_gradient_rad_per_g == 0.01
    assert estimator_vehicle_params("biso") == ()
    coulomb = CoSimulation(dataclasses.replace(route, tyres="coulomb"), duration_s=1.0, estimators=["biso_plus"])
    assert coulomb.estimators["biso_plus"].params.rear_slip_gradient_rad_per_g == 0.0


def test_the_cars_own_tyre_parameters_set_its_rear_slip_gradient():
    from biso_cosim.vehicle.sim import VehicleSim

    softer = TyreParams(pky1=10.0)
    sim = VehicleSim(load_route("figure8"), tyre_params=softer)
    assert sim.estimator_defaults()["rear_slip_gradient_rad_per_g"] == pytest.approx(
        rear_slip_gradient_rad_per_g(sim.parameters, params=softer))
    assert sim.estimator_defaults()["rear_slip_gradient_rad_per_g"] > rear_slip_gradient_rad_per_g(sim.parameters)


def test_the_vehicle_sim_builds_the_car_with_the_chassis_parameters_given():
    """``VehicleSim(chassis_params=...)`` (what ``vehicle handling --chassis`` sets): the brakes'
    front share is the balance asked for, their total torque the one asked for."""
    from biso_cosim.vehicle.sim import VehicleSim
    from biso_cosim.vehicle.tyres import BRAKES, ChassisParams

    chassis = ChassisParams(brake_balance_front=0.6, brake_torque_nm=5000.0)
    sim = VehicleSim(load_route("figure8"), chassis_params=chassis)
    limits = sim.model.actuator_forcerange[[sim.model.actuator(n).id for n in BRAKES], 1]
    assert limits.sum() == pytest.approx(5000.0)
    assert (limits[0] + limits[1]) / limits.sum() == pytest.approx(0.6)
