"""Braking of the car on the slip-based tyres (vehicle.tyres.ChassisParams, the ABS in
vehicle/native/tyres.c): the brake balance of the model, the ABS holding each wheel's slip
at its target, and the stopping distance from 100 km/h within the class's published range;
the Coulomb car's brakes (the invariants' car) unchanged."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from biso_cosim.vehicle.model import build_model, car_spec, vehicle_parameters
from biso_cosim.vehicle.terrain import Terrain
from biso_cosim.vehicle.tyres import BRAKES, CHASSIS, ChassisParams, tyre_states


def test_the_brakes_split_front_and_rear_by_the_balance_with_the_same_mean():
    coulomb, _ = build_model(Terrain(()), tyres="coulomb")
    slip, _ = build_model(Terrain(()))  # the default: the magic_formula tyres
    ids = [slip.actuator(name).id for name in BRAKES]
    limits = slip.actuator_forcerange[ids, 1]
    assert limits.sum() == pytest.approx(CHASSIS.brake_torque_nm)
    assert (limits[0] + limits[1]) / limits.sum() == pytest.approx(CHASSIS.brake_balance_front)
    kv = -slip.actuator_gainprm[ids, 2]
    assert (kv[0] + kv[1]) / kv.sum() == pytest.approx(CHASSIS.brake_balance_front)
    # the mean gain is car.xml's: a brake command asks the same total torque of both cars
    assert vehicle_parameters(slip)["brake_kv_nms_per_rad"] == vehicle_parameters(coulomb)["brake_kv_nms_per_rad"]
    # the Coulomb car is car.xml's, four equal brakes
    assert vehicle_parameters(coulomb) == vehicle_parameters(car_spec().compile())
    assert len({float(coulomb.actuator_forcerange[coulomb.actuator(n).id, 1]) for n in BRAKES}) == 1


def test_the_balance_is_the_ideal_share_of_the_axle_loads_near_0_8_g():
    """(l_r + z·h)/L, the front axle's share of the loads braking at z g (Wong, §3.5)."""
    p = vehicle_parameters()
    l_r = p["wheelbase_m"] - p["cg_behind_front_axle_m"]
    ideal = (l_r + 0.8 * p["cg_height_m"]) / p["wheelbase_m"]
    assert CHASSIS.brake_balance_front == pytest.approx(ideal, abs=0.02)


@pytest.mark.parametrize("name, value", [("brake_balance_front", 0.3), ("abs_slip_target", 0.0),
                                         ("brake_torque_nm", float("nan")), ("compliance_steer_rad_per_n", -1e-6)])
def test_chassis_parameters_out_of_range_are_refused_naming_them(name, value):
    with pytest.raises(ValueError) as info:
        build_model(Terrain(()), tyres="magic_formula", chassis_params=ChassisParams(**{name: value}))
    text = str(info.value)
    assert text.startswith(f"ChassisParams.{name} must be in [") and "\n" not in text
    with pytest.raises(ValueError, match="apply to tyres='magic_formula' only"):
        build_model(Terrain(()), tyres="coulomb", chassis_params=ChassisParams())


def _full_stop(chassis: ChassisParams, start_mps: float = 100.0 / 3.6):
    """Full brakes from ``start_mps`` on flat ground: (distance m, slips of every wheel at 1 s)."""
    model, _ = build_model(Terrain(()), tyres="magic_formula", chassis_params=chassis)
    data = mujoco.MjData(model)
    brakes = [model.actuator(n).id for n in BRAKES]
    data.ctrl[brakes] = 1.0
    mujoco.mj_step(model, data, 1500)  # settle at rest, braked
    data.qvel[0] = start_mps
    for w in ("fl", "fr", "rl", "rr"):
        data.qvel[model.jnt_dofadr[model.joint(f"{w}_spin").id]] = start_mps / 0.316
    x0 = float(data.qpos[0])
    mujoco.mj_step(model, data, 1000)
    slips = -tyre_states(model, data)["slip_ratio"]
    while data.qvel[0] > 0.02 and data.time < 20.0:
        mujoco.mj_step(model, data, 20)
    return float(data.qpos[0]) - x0, slips


def test_the_abs_holds_every_wheel_at_its_slip_target_and_stops_within_the_class_range():
    from biso_cosim.vehicle.handling import PUBLISHED

    distance, slips = _full_stop(CHASSIS)
    np.testing.assert_allclose(slips, CHASSIS.abs_slip_target, atol=0.01)
    (lo, hi), _ = PUBLISHED["stopping_distance_100_m"]
    assert lo <= distance <= hi
    # the ABS's worth: with a cut-out speed above the start speed it is off, the wheels lock
    locked, slips_locked = _full_stop(ChassisParams(abs_speed_min_mps=10.0), start_mps=9.5)
    unlocked, _ = _full_stop(CHASSIS, start_mps=9.5)
    assert np.all(slips_locked[2:] > 0.9)  # the unloaded rear wheels lock
    assert locked > 1.05 * unlocked


def test_the_brakes_build_up_linearly_over_their_build_up_time():
    """Each brake's torque limit rises as t/t_s from the command (the pressure's build-up), is
    gone when the command is, and costs a stop from 100 km/h at most the v0·t_s/2 that a
    deceleration rising linearly over t_s loses (less: the tyres limit it before the brakes do)."""
    from biso_cosim.vehicle.handling import braking_distance

    model, _ = build_model(Terrain(()))
    data = mujoco.MjData(model)
    brakes = [model.actuator(n).id for n in BRAKES]
    mujoco.mj_step(model, data, 200)
    assert np.all(tyre_states(model, data)["brake_build_up"] == 0.0)
    data.ctrl[brakes] = 0.5
    steps = 37
    mujoco.mj_step(model, data, steps)
    share = steps * model.opt.timestep / CHASSIS.brake_build_up_s
    np.testing.assert_allclose(tyre_states(model, data)["brake_build_up"], share, rtol=1e-12)
    mujoco.mj_step(model, data, 1000)
    assert np.all(tyre_states(model, data)["brake_build_up"] == 1.0)
    data.ctrl[brakes] = 0.0
    mujoco.mj_step(model, data, 1)
    assert np.all(tyre_states(model, data)["brake_build_up"] == 0.0)
    at_once = braking_distance(chassis_params=ChassisParams(brake_build_up_s=0.0))
    built_up = braking_distance()
    assert 0.0 < built_up - at_once <= 100.0 / 3.6 * CHASSIS.brake_build_up_s / 2.0


def test_the_handling_braking_figure_is_the_vehicle_sims():
    """``handling.braking_distance`` (the report's figure: VehicleSim, a brake command of 1)
    within the class range, and the Coulomb car's as it was (the invariants' brakes)."""
    from biso_cosim.vehicle.handling import PUBLISHED, braking_distance

    (lo, hi), _ = PUBLISHED["stopping_distance_100_m"]
    assert lo <= braking_distance(tyres="magic_formula") <= hi
    assert braking_distance(tyres="coulomb") == pytest.approx(51.42, abs=0.01)
    assert math.isfinite(braking_distance(tyres="magic_formula", start_kmh=50.0))


def test_docs_vehicle_shows_the_chassis_parameters_in_force():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "vehicle.md").read_text()
    assert ChassisParams.table() in text, "paste ChassisParams.table() into docs/vehicle.md"
