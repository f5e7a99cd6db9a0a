"""Route files, paths and speed profiles."""

import math

import _route_reference as ref
import numpy as np
import pytest

from biso_cosim.routes import load_route, parse_route, route_names
from biso_cosim.routes._kernels import _feasible_speeds
from biso_cosim.routes.path import densify


def base(**extra):
    data = {
        "name": "t", "description": "test", "closed": False,
        "waypoint": [{"x_m": 0.0, "y_m": 0.0}, {"x_m": 100.0, "y_m": 0.0, "radius_m": 20.0},
                     {"x_m": 100.0, "y_m": 100.0}],
    }
    data.update(extra)
    return data


def test_library_routes_load_and_close():
    assert {"loop600", "figure8"} <= set(route_names())
    loop = load_route("loop600")
    assert loop.closed and 540.0 < loop.nominal_duration_s < 600.0
    assert math.hypot(loop.path.x_m[-1] - loop.path.x_m[0], loop.path.y_m[-1] - loop.path.y_m[0]) < 1e-9
    turns = np.sign(loop.path.curvature_per_m[loop.path.curvature_per_m != 0])
    assert (turns > 0).any() and (turns < 0).any()  # turns both ways
    assert len(loop.stops) == 3 and len(loop.terrain.features) == 3
    eight = load_route("figure8")
    assert 40.0 < eight.nominal_duration_s < 70.0


def test_fillets_are_exact_arcs_tangent_to_the_legs():
    route = parse_route(base())
    p = route.path
    arc = p.curvature_per_m > 0
    assert np.allclose(p.curvature_per_m[arc], 1 / 20.0)
    # arc length of the 90° fillet and total length: 2·(100 − 20) + 20·π/2
    assert p.length_m == pytest.approx(160.0 + 10.0 * math.pi, abs=1e-3)  # s sums chords
    steps = np.hypot(np.diff(p.x_m), np.diff(p.y_m))
    assert steps.max() <= 0.2501 and steps.min() > 0.1
    heading_rate = np.diff(p.heading_rad) / np.diff(p.s_m)
    assert np.all(np.abs(heading_rate) <= 1.001 / 20.0)  # no kink anywhere (rate over chords)


def test_speed_profile_respects_limits():
    route = parse_route(base(driving={"default_speed_mps": 15.0, "max_lateral_accel_mps2": 2.0,
                                      "accel_mps2": 1.0, "decel_mps2": 2.0}))
    v = route.speed_with_stops_mps
    assert v[0] == 0.0 and v[-1] == 0.0
    arc = route.path.curvature_per_m > 0
    assert np.all(v[arc] <= math.sqrt(2.0 * 20.0) + 1e-9)
    dv2 = np.diff(v**2) / np.diff(route.path.s_m)
    assert dv2.max() <= 2 * 1.0 + 1e-6 and dv2.min() >= -2 * 2.0 - 1e-6
    # nominal duration: the profile's time plus the start wait
    assert route.nominal_duration_s > route.driving.start_wait_s + route.path.length_m / 15.0


def test_stops_become_zero_speed_points():
    data = base()
    data["waypoint"].insert(1, {"x_m": 50.0, "y_m": 0.0, "stop_s": 7.0})
    route = parse_route(data)
    stop = route.stops[0]
    assert stop.dwell_s == 7.0 and stop.s_m == pytest.approx(50.0, abs=0.3)
    assert route.speed_with_stops_mps[stop.index] == 0.0
    assert math.isinf(route.stops[-1].dwell_s)


@pytest.mark.parametrize(("change", "message"), [
    ({"name": None}, "missing required key 'name'"),
    ({"colour": "red"}, r"unknown key\(s\) \['colour'\]"),
    ({"closed": "yes"}, "closed must be true or false"),
    ({"laps": 2}, "laps > 1 needs a closed route"),
    ({"waypoint": [{"x_m": 0.0, "y_m": 0.0}]}, "at least two"),
    ({"driving": {"accel_mps2": -1.0}}, r"driving.accel_mps2 must be > 0"),
    ({"driving": {"top_speed": 3.0}}, r"unknown key\(s\) in \[driving\]"),
    ({"site": {"lat_deg": 95.0}}, r"site.lat_deg must be in \[-90, 90\]"),
    ({"site": {"date": "May"}}, "TOML date"),
])
def test_bad_route_files_name_the_field(change, message):
    data = base()
    for key, value in change.items():
        if value is None:
            data.pop(key)
        else:
            data[key] = value
    with pytest.raises(ValueError, match=message):
        parse_route(data, source="my.toml")


def test_bad_waypoints_and_geometry():
    data = base()
    data["waypoint"][1]["speed_mps"] = "fast"
    with pytest.raises(ValueError, match=r"waypoint\[1\].speed_mps must be a finite number"):
        parse_route(data)
    data = base()
    data["waypoint"][1]["radius_m"] = 150.0
    with pytest.raises(ValueError, match=r"waypoint\[0\].*fillets.*reduce radius_m"):
        parse_route(data)
    data = base(closed=True)
    data["waypoint"].append({"x_m": 0.0, "y_m": 0.0})
    with pytest.raises(ValueError, match="repeats the first"):
        parse_route(data)
    with pytest.raises(ValueError, match=r"terrain.feature\[0\].*unknown terrain type 'volcano'"):
        parse_route(base(terrain={"feature": [{"type": "volcano"}]}))
    with pytest.raises(ValueError, match=r"terrain.feature\[0\] \(hill\): missing field\(s\) \['height_m'\]"):
        parse_route(base(terrain={"feature": [{"type": "hill", "x_m": 0, "y_m": 0, "radius_m": 5}]}))
    with pytest.raises(ValueError, match="radius_m must be a positive number"):
        parse_route(base(terrain={"feature": [{"type": "hill", "x_m": 0, "y_m": 0, "radius_m": -5, "height_m": 1}]}))


def test_load_route_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown route 'nowhere'; known routes: .*loop600"):
        load_route("nowhere")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_route(str(tmp_path / "missing.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\nclosed = \n")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_route(str(bad))


def test_densify_of_a_circle_from_four_fillets():
    r = 12.0
    xy = np.array([[r, 0.0], [r, r], [-r, r], [-r, -r], [r, -r]])
    p = densify(xy, np.array([0.0, r, r, r, r]), closed=True)
    np.testing.assert_allclose(np.hypot(p.x_m, p.y_m), r, atol=1e-9)
    assert p.length_m == pytest.approx(2 * math.pi * r, rel=1e-3)


def test_gnss_outage_zones_in_route_files():
    route = parse_route(base(gnss_outage=[{"x0_m": 10.0, "y0_m": 0.0, "x1_m": 40.0, "y1_m": 0.0,
                                           "half_width_m": 8.0, "label": "tunnel"}]))
    assert route.gnss_outages[0].label == "tunnel" and route.summary()["gnss_outages"] == 1
    with pytest.raises(ValueError, match=r"gnss_outage\[0\].*missing \['half_width_m'\]"):
        parse_route(base(gnss_outage=[{"x0_m": 1.0, "y0_m": 0.0, "x1_m": 2.0, "y1_m": 0.0}]))
    with pytest.raises(ValueError, match=r"gnss_outage\[0\].half_width_m must be > 0"):
        parse_route(base(gnss_outage=[{"x0_m": 1.0, "y0_m": 0.0, "x1_m": 2.0, "y1_m": 0.0, "half_width_m": 0}]))


def test_more_bad_route_files():
    data = base()
    data["waypoint"] = [1, 2]
    with pytest.raises(ValueError, match=r"waypoint\[0\] must be a table"):
        parse_route(data)
    data = base()
    data["waypoint"][-1]["stop_s"] = 5.0
    with pytest.raises(ValueError, match=r"waypoint\[2\].stop_s"):
        parse_route(data)
    data = base()
    data["waypoint"][-1]["reverse"] = True
    with pytest.raises(ValueError, match=r"waypoint\[2\].reverse"):
        parse_route(data)
    ring = {"type": "bank", "cx_m": 0, "cy_m": 0, "radius_m": 50, "width_m": 8, "start_deg": 0, "end_deg": 360,
            "bank_deg": 8}
    with pytest.raises(ValueError, match="start_deg and end_deg must differ"):
        parse_route(base(terrain={"feature": [ring]}))
    huge = {"type": "hill", "x_m": 0, "y_m": 0, "radius_m": 1e7, "height_m": 1}
    with pytest.raises(ValueError, match="cells"):
        parse_route(base(terrain={"feature": [huge]})).terrain.patches()


# --------------------------------------------------------------------------------------
# What the car can drive
# --------------------------------------------------------------------------------------

def test_car_limits_come_from_the_model():
    from biso_cosim.routes import car_limits
    from biso_cosim.routes.limits import STANDARD_GRAVITY_MPS2, USABLE_FRICTION
    from biso_cosim.vehicle.drivetrain import DRIVETRAIN, top_speed
    from biso_cosim.vehicle.model import vehicle_parameters

    car, p = car_limits(), vehicle_parameters()
    assert car.turning_radius_m == pytest.approx(p["wheelbase_m"] / math.tan(p["max_steer_rad"]))
    mu = USABLE_FRICTION  # tyre friction 1 in car.xml
    assert car.lateral_accel_mps2 == pytest.approx(mu * STANDARD_GRAVITY_MPS2)
    # rear-axle traction with load transfer: a = μ g (b/L) / (1 − μ h/L); the grade is a/g
    b_l, h_l = p["cg_behind_front_axle_m"] / p["wheelbase_m"], p["cg_height_m"] / p["wheelbase_m"]
    assert car.accel_mps2 == pytest.approx(mu * STANDARD_GRAVITY_MPS2 * b_l / (1 - mu * h_l))
    assert car.grade == pytest.approx(car.accel_mps2 / STANDARD_GRAVITY_MPS2)
    assert car.decel_mps2 <= 4 * p["max_brake_torque_per_wheel_nm"] / p["wheel_radius_m"] / p["total_mass_kg"]
    # the drivetrain's top speed (tests/test_drivetrain.py measures it with the MuJoCo car)
    assert car.top_speed_mps == pytest.approx(top_speed(DRIVETRAIN, mass_kg=p["total_mass_kg"],
                                                        wheel_radius_m=p["wheel_radius_m"],
                                                        wheel_damping_nms=p["wheel_damping_nms_per_rad"])[0])
    assert 175.0 / 3.6 < car.top_speed_mps < 215.0 / 3.6
    table = car.table()
    assert all(name in table for name in ("top_speed_mps", "accel_mps2", "turning_radius_m", "grade"))


def test_library_routes_are_within_the_car_limits():
    import warnings

    from biso_cosim.routes import RouteWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", RouteWarning)
        for name in route_names():
            load_route(name)


@pytest.mark.parametrize(("driving", "field"), [
    ({"accel_mps2": 8.0}, "driving.accel_mps2 = 8 is beyond the car's largest acceleration"),
    ({"decel_mps2": 12.0}, "driving.decel_mps2 = 12 is beyond the car's largest braking deceleration"),
    ({"max_lateral_accel_mps2": 20.0}, "driving.max_lateral_accel_mps2 = 20 is beyond"),
    ({"default_speed_mps": 500.0}, "driving.default_speed_mps = 500 is beyond the car's top speed"),
])
def test_driving_limits_beyond_the_car_are_capped_with_a_warning(driving, field):
    from biso_cosim.routes import RouteWarning, car_limits

    with pytest.warns(RouteWarning, match=field):
        route = parse_route(base(driving=driving), source="my.toml")
    name = next(iter(driving))
    limit = {"accel_mps2": "accel_mps2", "decel_mps2": "decel_mps2", "max_lateral_accel_mps2": "lateral_accel_mps2",
             "default_speed_mps": "top_speed_mps"}[name]
    assert getattr(route.driving, name) == getattr(car_limits(), limit)


def test_waypoint_speed_beyond_the_top_speed_is_capped_naming_the_waypoint():
    from biso_cosim.routes import RouteWarning, car_limits

    data = base()
    data["waypoint"][1]["speed_mps"] = 500.0
    with pytest.warns(RouteWarning, match=r"my.toml: waypoint\[1\].speed_mps = 500 m/s is beyond the car's top speed"):
        route = parse_route(data, source="my.toml")
    assert route.waypoints[1].speed_mps == car_limits().top_speed_mps
    assert route.speed_free_mps.max() <= car_limits().top_speed_mps


def test_a_waypoint_speed_its_curving_leg_never_allows_is_capped_with_a_warning_naming_it():
    """A square of 40 m sides with 20 m fillets is a circle of radius 20 m (started at the
    middle of a side): the legs between two fillets curve all along, so 15 m/s on waypoint
    2's leg is driven at sqrt(2.5 · 20) = 7.07 m/s."""
    from biso_cosim.routes import RouteWarning

    corners = [(20.0, 0.0, 0.0), (40.0, 0.0, 20.0), (40.0, 40.0, 20.0), (0.0, 40.0, 20.0), (0.0, 0.0, 20.0)]
    data = {"name": "ring", "description": "d", "closed": True, "laps": 2,
            "driving": {"max_lateral_accel_mps2": 2.5, "default_speed_mps": 5.0},
            "waypoint": [{"x_m": x, "y_m": y, "radius_m": r} for x, y, r in corners]}
    data["waypoint"][2]["speed_mps"] = 15.0
    with pytest.warns(RouteWarning, match=r"ring.toml: waypoint\[2\].speed_mps = 15 m/s is never reached: its leg "
                                          r"curves all along \(radius 20.0 m at the widest\), which allows at most "
                                          r"7.1 m/s"):
        route = parse_route(data, source="ring.toml")
    on_leg = (route.path.leg % 5) == 2
    assert route.speed_free_mps[on_leg].max() == pytest.approx(math.sqrt(2.5 * 20.0), rel=1e-3)
    # a leg that slows only in the curve at its end is capped silently (the library's rough_road)
    data["waypoint"] = [{"x_m": 0.0, "y_m": 0.0}, {"x_m": 200.0, "y_m": 0.0, "radius_m": 30.0, "speed_mps": 14.0},
                        {"x_m": 200.0, "y_m": 100.0, "radius_m": 30.0}, {"x_m": 0.0, "y_m": 100.0, "radius_m": 30.0}]
    data["laps"] = 1
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RouteWarning)
        parse_route(data, source="ring.toml")


def test_corners_the_car_cannot_take_are_refused_naming_the_waypoint():
    # a closed route of two waypoints turns back on itself at both (it parked the car forever)
    two = {"name": "two", "description": "d", "closed": True,
           "waypoint": [{"x_m": 0.0, "y_m": 0.0}, {"x_m": 50.0, "y_m": 0.0}]}
    with pytest.raises(ValueError, match=r"two.toml: waypoint\[1\] turns by 180° without a fillet"):
        parse_route(two, source="two.toml")
    sharp = base()
    sharp["waypoint"] = [{"x_m": 0.0, "y_m": 0.0}, {"x_m": 100.0, "y_m": 0.0},
                         {"x_m": 100.0 + 50.0 * math.cos(math.radians(120)), "y_m": 50.0 * math.sin(math.radians(120))}]
    with pytest.raises(ValueError, match=r"waypoint\[1\] turns by 120° without a fillet.*at most 90°"):
        parse_route(sharp)
    sharp["waypoint"][1]["radius_m"] = 2.0
    with pytest.raises(ValueError, match=r"waypoint\[1\].radius_m = 2 m is tighter than the car's turning radius"):
        parse_route(sharp)
    sharp["waypoint"][1]["radius_m"] = 5.0
    parse_route(sharp)  # a fillet the car can take
    square = base()  # 90° without a fillet: the driver cuts it by about a metre, allowed
    square["waypoint"][1].pop("radius_m")
    parse_route(square)


def test_a_closed_routes_start_corner_counts_only_when_driven_through():
    triangle = [{"x_m": 0.0, "y_m": 0.0}, {"x_m": 100.0, "y_m": 0.0, "radius_m": 10.0},
                {"x_m": 10.0, "y_m": 30.0, "radius_m": 10.0}]
    parse_route({"name": "t", "description": "d", "closed": True, "waypoint": triangle})  # starts, ends at rest
    with pytest.raises(ValueError, match=r"waypoint\[0\] turns by 1[0-9][0-9]° without a fillet"):
        parse_route({"name": "t", "description": "d", "closed": True, "laps": 2, "waypoint": triangle})


# --------------------------------------------------------------------------------------
# Fast code against its slow reference
# --------------------------------------------------------------------------------------

def _path_arrays(p):
    return (p.x_m, p.y_m, p.s_m, p.heading_rad, p.curvature_per_m, p.leg)


@pytest.mark.parametrize("name", route_names())
def test_densify_and_speed_passes_equal_their_references_to_the_bit(name):
    route = load_route(name)
    xy = np.array([[w.x_m, w.y_m] for w in route.waypoints])
    radius = np.array([w.radius_m for w in route.waypoints])
    fast, slow = densify(xy, radius, route.closed), ref.densify(xy, radius, route.closed)
    for a, b in zip(_path_arrays(fast), _path_arrays(slow)):
        assert np.array_equal(a, b)
    rng = np.random.default_rng(len(name))
    v = rng.uniform(0.0, 30.0, len(route.path))
    v[rng.integers(0, v.size, 5)] = 0.0
    ds = np.diff(route.path.s_m)
    mine = v.copy()
    _feasible_speeds(mine, ds, 1.3, 2.1, 2.0)
    assert np.array_equal(mine, ref.feasible_speeds(v, ds, 1.3, 2.1))


def test_densify_of_random_polylines_equals_the_reference():
    rng = np.random.default_rng(7)
    for closed in (False, True):
        for _ in range(5):
            angles = np.cumsum(rng.uniform(-1.2, 1.2, 12))
            steps = rng.uniform(20.0, 60.0, 12)
            xy = np.column_stack([np.cumsum(steps * np.cos(angles)), np.cumsum(steps * np.sin(angles))])
            radius = np.where(rng.random(12) < 0.5, rng.uniform(4.0, 8.0, 12), 0.0)
            radius[0] = radius[-1] = 0.0
            fast, slow = densify(xy, radius, closed), ref.densify(xy, radius, closed)
            for a, b in zip(_path_arrays(fast), _path_arrays(slow)):
                assert np.array_equal(a, b)
