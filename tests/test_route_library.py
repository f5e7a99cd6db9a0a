"""The shipped routes, driven with the test kit; terrain features; importing real tracks (the
import's own tests, with the bad files it refuses, are in test_route_import.py).

Short routes are driven to their end here; long ones for their first minute (the car, the
driver and the terrain must behave from the start). Whole drives of every route are the job
of ``biso-cosim routes check`` (see the README), which reports the same figures for each.
"""

import math

import numpy as np
import pytest

from biso_cosim.frames import euler_from_quat
from biso_cosim.routes import load_route, route_names
from biso_cosim.routes.importing import import_track, read_track, track_to_route_data
from biso_cosim.testing import drive
from biso_cosim.vehicle.terrain import ISO8608_GD_N0, Rough, Terrain, Washboard, _profile_psd_at_n0

SHORT = {"figure8", "slalom", "parking"}


def test_the_library_has_the_routes_the_issue_names():
    assert {"loop600", "figure8", "slalom", "hill_climb", "banked_oval", "roundabout", "city_stop_go",
            "highway", "parking", "rough_road"} <= set(route_names())
    for name in route_names():
        route = load_route(name)
        assert route.description and route.excites
        assert 30.0 < route.nominal_duration_s < 700.0


@pytest.mark.parametrize("name", sorted(SHORT))
def test_short_routes_are_driven_to_their_end(name):
    run = drive(name, estimator="poisson", seed=0)
    run.assert_completed(max_cross_track_m=1.0)


@pytest.mark.parametrize("name", sorted(set(route_names()) - SHORT))
def test_long_routes_start_well(name):
    run = drive(name, estimator="poisson", seed=0, duration_s=60.0)
    assert np.max(np.abs(run.run.cross_track_m)) < 1.0
    roll, pitch = np.degrees(euler_from_quat(run.run.truth.q_wb)[:, :2]).T
    assert np.max(np.abs(roll)) < 15.0 and np.max(np.abs(pitch)) < 12.0  # no roll-over, no wheelie
    assert run.run.truth.speed_mps.max() > 5.0  # it got going


def test_hill_climb_pitch_follows_the_grade():
    run = drive("hill_climb", estimator="poisson", seed=0, duration_s=40.0)
    truth = run.run.truth
    pitch = euler_from_quat(truth.q_wb)[:, 1]
    route = run.run.route
    # the grade of the road under the car, from the analytic terrain along the direction of travel
    heading = np.arctan2(truth.vel_w[:, 1], truth.vel_w[:, 0])
    gx, gy = route.terrain.gradient(truth.pos_w[:, 0], truth.pos_w[:, 1])
    grade = gx * np.cos(heading) + gy * np.sin(heading)
    moving = truth.speed_mps > 3.0
    # pitch = −atan(grade) (nose up uphill) up to suspension and acceleration pitch (< 1°)
    assert np.max(np.abs(pitch[moving] + np.arctan(grade[moving]))) < math.radians(1.2)
    assert np.max(np.abs(grade)) > 0.14


def test_rough_road_follows_iso8608():
    rough = Rough(0.0, 0.0, 300.0, 0.0, road_class="C", seed=3)
    field, res, _ = rough._grid
    assert _profile_psd_at_n0(field, res) == pytest.approx(ISO8608_GD_N0["C"], rel=1e-9)
    n = field.shape[0]
    psd = 2 * res / n * (np.abs(np.fft.rfft(field - field.mean(axis=0), axis=0)) ** 2).mean(axis=1)
    freq = np.fft.rfftfreq(n, res)
    band = (freq >= 0.1) & (freq <= 2.0)
    slope = np.polyfit(np.log(freq[band]), np.log(psd[band]), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.15)
    assert field.min() == 0.0  # never below the ground plane
    assert np.array_equal(field, Rough(0.0, 0.0, 300.0, 0.0, road_class="C", seed=3)._grid[0])  # seeded


def test_washboard_and_patch_resolution():
    board = Washboard(0.0, 0.0, 40.0, 0.0, amplitude_m=0.02, wavelength_m=0.8)
    assert board.height(20.4, 0.0) == pytest.approx(0.02)
    assert board.height(20.0, 0.0) == pytest.approx(0.0, abs=1e-12)
    assert board.height(20.4, 10.0) == 0.0
    patches = Terrain((board,)).patches()
    assert patches[0].resolution_m == 0.1


def test_rough_road_shakes_the_sensor():
    run = drive("rough_road", estimator="poisson", seed=0, duration_s=60.0).run  # as the test above
    truth = run.truth
    standing = truth.t_s < 4.5
    humps = np.zeros(truth.t_s.shape, bool)
    for x in (60.0, 110.0, 160.0):  # the three speed humps, taken at 5 m/s
        humps |= (np.abs(truth.pos_w[:, 0] - x) < 4.0) & (np.abs(truth.pos_w[:, 1]) < 5.0)
    assert humps.any()
    assert np.std(truth.specific_force_b[humps, 2]) > 20 * np.std(truth.specific_force_b[standing, 2])
    assert np.max(truth.specific_force_b[humps, 2]) > 11.0  # a jolt of over 0.1 g up


def _write_gpx(path, lat, lon, ele=None, extra=""):
    points = []
    for i, (a, b) in enumerate(zip(lat, lon)):
        e = f"<ele>{ele[i]:.2f}</ele>" if ele is not None else ""
        points.append(f'<trkpt lat="{a:.7f}" lon="{b:.7f}">{e}</trkpt>')
    path.write_text('<?xml version="1.0"?>\n<gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1">\n'
                    f"<trk><trkseg>\n" + "\n".join(points) + f"\n{extra}</trkseg></trk></gpx>\n")


def test_import_a_closed_gpx_track_with_heights(tmp_path):
    import pymap3d

    theta = np.linspace(0.0, 2 * np.pi, 200)
    e, n = 150 * np.cos(theta) - 150, 100 * np.sin(theta)
    up = 3.0 * np.sin(theta)
    lat, lon, alt = pymap3d.enu2geodetic(e, n, up + 40.0, 51.53, 46.03, 40.0)
    _write_gpx(tmp_path / "loop.gpx", lat, lon, alt)
    route = import_track(tmp_path / "loop.gpx", speed_mps=8.0)
    assert route.closed and route.site.lat_deg == pytest.approx(51.53, abs=1e-6)
    assert route.path.length_m == pytest.approx(2 * np.pi * math.sqrt((150**2 + 100**2) / 2), rel=0.02)
    z = route.terrain.height(route.path.x_m, route.path.y_m)
    assert np.ptp(z) == pytest.approx(6.0, rel=0.1)  # the track's ±3 m, smoothed a little
    run = drive(route, estimator="poisson", seed=0, duration_s=25.0)
    assert np.max(np.abs(run.run.cross_track_m)) < 1.0


def test_import_a_csv_with_speeds(tmp_path):
    rows = ["lat_deg,lon_deg,speed_mps"] + [f"{51.5 + 1e-5 * i:.7f},46.0,{5 + i % 3}" for i in range(100)]
    (tmp_path / "line.csv").write_text("\n".join(rows) + "\n")
    data = track_to_route_data(read_track(tmp_path / "line.csv"))
    assert not data["closed"] and "terrain" not in data
    speeds = [w["speed_mps"] for w in data["waypoint"]]
    assert 5.0 <= min(speeds) and max(speeds) <= 7.0


def test_imported_heights_are_not_the_earths_curvature(tmp_path):
    """A long, level track (constant ellipsoidal height) stays level: ENU "up" would fall."""
    import pymap3d

    e = np.linspace(0.0, 10_000.0, 400)
    lat, lon, _ = pymap3d.enu2geodetic(e, np.zeros_like(e), np.zeros_like(e), 51.53, 46.03, 100.0)
    _write_gpx(tmp_path / "level.gpx", lat, lon, np.full_like(e, 100.0))
    data = track_to_route_data(read_track(tmp_path / "level.gpx"))
    assert "terrain" not in data  # no height change, no road feature
