"""Route files, paths and speed profiles."""

import math

import numpy as np
import pytest

from biso_cosim.routes import load_route, parse_route, route_names
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
