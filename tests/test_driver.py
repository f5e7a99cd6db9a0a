"""The jitted driver against its plain-Python reference, command by command."""

import numpy as np
import pytest

from biso_cosim.routes import load_route
from biso_cosim.vehicle.sim import VehicleSim

from _driver_reference import ReferenceDriver


@pytest.mark.parametrize(("route", "seconds"), [("figure8", 60.0), ("parking", 80.0), ("city_stop_go", 40.0)])
def test_kernel_driver_equals_the_reference(route, seconds):
    sim = VehicleSim(load_route(route))
    reference = ReferenceDriver(sim.driver)
    for _ in range(int(seconds * sim.control_rate_hz)):
        measured = sim._measure()
        got = sim.driver.command(*measured)
        want = reference.command(*measured)
        np.testing.assert_allclose([got.steer_rad, got.drive, got.brake], [want.steer_rad, want.drive, want.brake],
                                   rtol=0, atol=1e-12)
        for name in ("index", "next_stop", "floor_index", "finished"):
            assert getattr(sim.driver.state, name) == getattr(reference.state, name), name
        assert sim.driver.state.s_m == pytest.approx(reference.state.s_m, abs=1e-12)
        sim.apply(got)
        sim.step()
    if route != "city_stop_go":
        assert sim.driver.finished


def test_driver_state_is_a_copyable_record():
    import copy
    import pickle

    sim = VehicleSim(load_route("figure8"))
    for _ in range(400):  # 8 s: 2 s standing, then away
        sim.drive()
        sim.step()
    state = sim.driver.state
    again = pickle.loads(pickle.dumps(copy.deepcopy(state)))
    assert again.s_m == state.s_m > 10.0 and again.index == state.index
    assert "cross_track_m=" in repr(state)


@pytest.mark.parametrize("route", ["figure8", "parking"])
def test_drive_kernel_equals_measure_command_apply(route):
    """VehicleSim.drive (one kernel from sensordata to ctrl) against its parts called from Python."""
    fused, parts = VehicleSim(load_route(route)), VehicleSim(load_route(route))
    for _ in range(int(40.0 * fused.control_rate_hz)):
        got = fused.drive()
        want = parts.driver.command(*parts._measure())
        parts.apply(want)
        assert got == want
        assert np.array_equal(fused.data.ctrl, parts.data.ctrl)
        assert np.array_equal(fused.driver.state.array, parts.driver.state.array)
        fused.step()
        parts.step()
