"""biso_cosim.testing: drives, cached runs, readable failures, user estimators."""

import numpy as np
import pytest

from biso_cosim.routes import load_route, parse_route
from biso_cosim.testing import AttitudeErrorExceeded, drive


class Frozen:
    """A deliberately useless estimator: always level, facing East."""

    def __init__(self):
        self.calls = 0

    def update(self, gyro_b, accel_b, mag_b):
        self.calls += 1
        return np.tile([1.0, 0.0, 0.0, 0.0], (gyro_b.shape[0], 1))


def test_failure_names_the_angle_when_and_how_far():
    run = drive("figure8", estimator=Frozen(), seed=0, duration_s=20.0)
    with pytest.raises(AttitudeErrorExceeded) as info:
        run.assert_max_error(heading=5.0, roll=30.0)
    message = str(info.value)
    assert "figure8 with Frozen (seed 0)" in message
    assert "heading error over 5°" in message and "first at t = 0.00 s" in message
    assert "largest" in message and "m along the route" in message
    assert "roll" not in message.split("\n", 1)[1]  # roll stayed within 30°
    with pytest.raises(AttitudeErrorExceeded, match=r"heading RMS error [0-9.]+° is over 1°"):
        run.assert_rms_error(heading=1.0)


def test_user_estimators_run_in_the_loop_and_are_never_cached():
    a, b = Frozen(), Frozen()
    run_a = drive("figure8", estimator=a, seed=0, duration_s=4.0)
    drive("figure8", estimator=b, seed=0, duration_s=4.0)
    assert a.calls == b.calls == 200  # one call per control period (50 Hz)
    # the frozen estimate (level, facing East) against the truth (figure8 starts north-east)
    np.testing.assert_allclose(run_a.errors["heading"][:3], 90.0 - 45.0, atol=0.5)


def test_library_runs_are_cached_by_everything_that_makes_them():
    first = drive("figure8", estimator="poisson", seed=0, duration_s=4.0)
    again = drive("figure8", estimator="poisson", seed=0, duration_s=4.0)
    assert again.run is first.run
    assert drive("figure8", estimator="poisson", seed=1, duration_s=4.0).run is not first.run
    labelled = drive("figure8", estimator="poisson", seed=0, duration_s=4.0, label="mine")
    assert labelled.run is not first.run and labelled.key == "mine"
    assert not first.run.truth.packed.flags.writeable  # shared between tests: read-only
    # a changed route is another key: nothing stale comes back
    route = load_route("figure8")
    data = {"name": "figure8", "description": route.description, "closed": True,
            "driving": {"default_speed_mps": 6.0, "start_wait_s": 2.0},
            "waypoint": [{"x_m": w.x_m, "y_m": w.y_m, "radius_m": w.radius_m} for w in route.waypoints]}
    slower = drive(parse_route(data), estimator="poisson", seed=0, duration_s=4.0)
    assert slower.run is not first.run


def test_bounds_and_closure_errors_are_clear():
    run = drive("slalom", estimator="poisson", seed=0, duration_s=5.0)
    with pytest.raises(ValueError, match="positive number of degrees"):
        run.assert_max_error(roll=-1.0)
    with pytest.raises(ValueError, match="at least one bound"):
        run.assert_rms_error()
    with pytest.raises(ValueError, match="leaves no samples"):
        run.assert_rms_error(heading=1e-9, after_s=1000.0)
    with pytest.raises(AssertionError, match="open or was not driven to its end"):
        run.assert_closure(heading=1.0)
    with pytest.raises(AssertionError, match="not completed"):
        run.assert_completed()


def test_drive_route_fixture(drive_route):
    run = drive_route("figure8", estimator="poisson", seed=0, duration_s=4.0)
    run.assert_max_error(roll=5.0, pitch=5.0)
