"""Importing recorded tracks: the smoother, the stops, the checks, and bad files named in one line.

Tracks are made with a seed like real recordings (biso_cosim.routes.synthetic: a known road,
a receiver error of 2-3 m horizontally and 2-5 m vertically that wanders over a minute, white
noise, lost fixes, dropouts), at 1 Hz and 10 Hz, on urban grids and mountain roads, plus one
real recording (tests/data/comma2k19_i280_60s.gpx, MIT, see tests/data/README.md). Driving
the imported routes is in test_route_import_drive.py.
"""

import datetime
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from biso_cosim.routes import RouteWarning, car_limits, load_route, parse_route
from biso_cosim.output import atomic_output
from biso_cosim.routes.importing import TURN_MARGIN, convert_track, import_track, write_route_file
from biso_cosim.routes.smoothing import bin_along, smooth_along, whittaker, whittaker_lambda
from biso_cosim.routes.synthetic import synthetic_track, write_gpx
from biso_cosim.routes.tracks import Track, read_track

DATA = Path(__file__).resolve().parent / "data"
COMMA = DATA / "comma2k19_i280_60s.gpx"
ORIGIN = (51.53, 46.03, 50.0)


def quiet_import(track, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RouteWarning)
        result = convert_track(track, **options)
    return result, parse_route(result.data, source=track.source)


def enu_gpx(path, e, n, up=None, t=None):
    """A GPX track through ENU points (m) around ORIGIN, with heights and times if given."""
    import pymap3d

    lat, lon, _ = pymap3d.enu2geodetic(np.asarray(e), np.asarray(n), np.zeros(len(e)), *ORIGIN)
    alt = None if up is None else ORIGIN[2] + np.asarray(up)
    start = datetime.datetime(2024, 5, 1, 9, 0, tzinfo=datetime.timezone.utc)
    return write_gpx(Track(np.asarray(lat), np.asarray(lon), alt, None, None if t is None else np.asarray(t),
                           start, path.name), path)


def distance_to_road(route, road):
    d, _ = cKDTree(np.column_stack([road.x_m, road.y_m])).query(np.column_stack([route.path.x_m, route.path.y_m]))
    return d


# --------------------------------------------------------------------------------------
# The smoother
# --------------------------------------------------------------------------------------

def test_whittaker_gain_is_the_analytic_one():
    """On a circular grid a sinusoid is an eigenvector: gain 1/(1 + λ(2 sin(πh/Λ))⁴), ½ at the cutoff."""
    h, n, cutoff = 1.0, 1200, 60.0
    s = h * np.arange(n)
    lam = whittaker_lambda(cutoff, h)
    for wavelength in (30.0, 60.0, 120.0, 400.0):
        y = np.sin(2 * np.pi * s / wavelength)
        z = whittaker(y, np.ones(n), lam, closed=True)
        gain = 1.0 / (1.0 + lam * (2 * math.sin(math.pi * h / wavelength)) ** 4)
        np.testing.assert_allclose(z, gain * y, atol=1e-9)
        if wavelength == cutoff:
            assert gain == pytest.approx(0.5)


def test_whittaker_fast_solvers_equal_the_dense_solution():
    import scipy.sparse as sp

    from biso_cosim.routes.smoothing import _second_differences

    rng = np.random.default_rng(3)
    for closed in (False, True):
        n = 300
        w = rng.uniform(0.0, 2.0, n)
        w[100:140] = 0.0  # a dropout
        y = rng.normal(size=(n, 2))
        lam = whittaker_lambda(25.0, 1.0)
        d = _second_differences(n, closed)
        dense = np.linalg.solve((sp.diags(w) + lam * (d.T @ d)).toarray(), w[:, None] * y)
        np.testing.assert_allclose(whittaker(y, w, lam, closed), dense, rtol=1e-9, atol=1e-9)


def test_whittaker_keeps_straight_lines_and_bridges_gaps():
    """The penalty leaves straight lines alone: a grade is kept to the ends and across gaps."""
    rng = np.random.default_rng(0)
    grid = np.arange(500.0)
    w = rng.uniform(0.2, 3.0, grid.size)
    w[200:260] = 0.0
    z = whittaker(np.where(w > 0, 3.0 + 0.07 * grid, 99.0), w, whittaker_lambda(100.0, 1.0))
    np.testing.assert_allclose(z, 3.0 + 0.07 * grid, atol=1e-9)
    # samples off the grid: linear binning moves a sample's value by at most a mm here
    s = np.sort(rng.uniform(0.0, 500.0, 80))
    s = s[(s < 200.0) | (s > 260.0)]
    grid, z = smooth_along(s, 3.0 + 0.07 * s, 100.0, grid_m=1.0)
    np.testing.assert_allclose(z, 3.0 + 0.07 * grid, atol=2e-3)


def test_smoothing_keeps_the_ends_of_a_noisy_track():
    """The first sample's noise is averaged away with its neighbours', not kept (the moving
    average with a window shrinking to one sample kept it: a 62 % grade in the first 5 m)."""
    rng = np.random.default_rng(1)
    s = np.arange(0.0, 600.0, 10.0)
    ends, middles, slopes = [], [], []
    for _ in range(300):
        grid, z = smooth_along(s, rng.normal(0.0, 1.0, s.size), 200.0, grid_m=1.0)
        ends.append(z[0])
        middles.append(z[grid.size // 2])
        slopes.append(z[5] - z[0])
    assert np.std(ends) < 0.6 and np.std(middles) < 0.3  # noise σ = 1: the old ends kept all of it
    assert np.std(slopes) < 0.06  # the first 5 m climb by a few cm, not by a metre


def test_ties_make_values_agree():
    n = 400
    y = np.where(np.arange(n) < 200, 0.0, 6.0)
    w = np.ones(n)
    lam = whittaker_lambda(40.0, 1.0)
    free = whittaker(y, w, lam)
    tied = whittaker(y, w, lam, ties=(np.array([50]), np.array([350])))
    assert abs(free[350] - free[50]) > 5.0
    assert abs(tied[350] - tied[50]) < 0.01 * abs(free[350] - free[50])


def test_binning_keeps_the_first_moment():
    s = np.array([0.0, 0.3, 2.5, 7.9, 10.0])
    grid, means, weights = bin_along(s, s * 2.0, grid_m=1.0)
    gaps = np.diff(s)
    share = 0.5 * (np.append(gaps, 0.0) + np.insert(gaps, 0, 0.0))  # each sample's share of the length
    assert weights.sum() == pytest.approx(s[-1] - s[0])
    assert np.sum(weights * grid) == pytest.approx(np.sum(share * s))  # linear binning keeps the centre
    assert np.sum(weights * means) == pytest.approx(np.sum(share * 2.0 * s))


# --------------------------------------------------------------------------------------
# Imported tracks against the road they were recorded on
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize(("rate_hz", "static_hold"), [(1.0, False), (10.0, False), (1.0, True)])
def test_a_stop_in_the_recording_becomes_a_stop_of_the_route(rate_hz, static_hold):
    syn = synthetic_track("urban", length_m=700.0, rate_hz=rate_hz, seed=4, stop_at=[(350.0, 8.0)],
                          static_hold=static_hold, dropouts=0)
    result, route = quiet_import(syn.track)
    assert len(result.stops) == 1 and len(route.stops) == 2  # the stop, and the end
    stop = route.stops[0]
    assert 7.0 <= stop.dwell_s <= 9.0
    k = int(round(350.0 / 0.5))
    assert math.hypot(route.path.x_m[stop.index] - syn.road.x_m[k], route.path.y_m[stop.index] - syn.road.y_m[k]) < 6.0
    assert route.speed_with_stops_mps[stop.index] == 0.0
    # the standing before driving off and after arriving is not a stop
    assert route.stops[-1].index == len(route.path) - 1


@pytest.mark.parametrize(("kind", "rate_hz", "seed"), [("urban", 1.0, 0), ("urban", 10.0, 1), ("mountain", 1.0, 2),
                                                      ("mountain", 10.0, 3)])
def test_imported_route_follows_the_road(kind, rate_hz, seed):
    syn = synthetic_track(kind, length_m=1500.0, rate_hz=rate_hz, seed=seed, horizontal_noise_m=2.5,
                          vertical_noise_m=3.0, dropouts=2)
    result, route = quiet_import(syn.track)
    d = distance_to_road(route, syn.road)
    assert np.sqrt(np.mean(d**2)) < 4.0 and d.max() < 10.0  # the receiver's own error is 2.5 m per axis
    assert route.path.length_m == pytest.approx(syn.road.s_m[-1], rel=0.03)
    # never tighter than the car can turn, with its margin
    assert 1.0 / np.max(np.abs(route.path.curvature_per_m[1:-1]) + 1e-12) > 0.99 * car_limits().turning_radius_m
    from biso_cosim.routes.path import polyline_curvature

    kappa = polyline_curvature(route.path.x_m, route.path.y_m, window_m=4.0, spacing_m=0.25)
    assert np.max(np.abs(kappa[20:-20])) < 1.05 / (TURN_MARGIN * car_limits().turning_radius_m)


def test_grades_of_a_flat_road_under_noisy_heights():
    """1.5 m of height noise on a flat road gave 10-14 % grades; 5 m of noise gives a few %."""
    for sigma, worst in ((1.5, 0.06), (5.0, 0.16)):
        syn = synthetic_track("urban", length_m=2800.0, rate_hz=1.0, seed=5, vertical_noise_m=sigma, top_grade=0.0)
        result, route = quiet_import(syn.track)
        x, y, s = route.path.x_m[::4], route.path.y_m[::4], route.path.s_m[::4]
        z = route.terrain.height(x, y)
        grade = np.diff(z) / np.diff(s)
        assert np.max(np.abs(grade)) < worst
        assert np.sqrt(np.mean(grade**2)) < worst / 3
        first = np.searchsorted(s, 5.0)
        assert abs(z[first] - z[0]) < 0.3  # the first 5 m climbed 3.1 m


def test_heights_follow_the_roads_grades():
    syn = synthetic_track("mountain", length_m=2000.0, rate_hz=10.0, seed=6, vertical_noise_m=3.0)
    _, route = quiet_import(syn.track)
    x, y, s = route.path.x_m[::8], route.path.y_m[::8], route.path.s_m[::8]
    grade = np.diff(route.terrain.height(x, y)) / np.diff(s)
    _, j = cKDTree(np.column_stack([syn.road.x_m, syn.road.y_m])).query(np.column_stack([x, y]))
    true = np.diff(syn.road.z_m[j]) / np.diff(s)
    assert np.std(true) > 0.03  # a real climb and descent
    assert np.sqrt(np.mean((grade - true) ** 2)) < 0.045
    assert np.corrcoef(grade, true)[0, 1] > 0.6


def test_repeated_fixes_are_dropped_and_change_nothing(tmp_path):
    syn = synthetic_track("urban", length_m=600.0, rate_hz=1.0, seed=8)
    t = syn.track
    twice = np.sort(np.concatenate([np.arange(len(t)), np.arange(10, len(t), 25)]))
    doubled = Track(t.lat_deg[twice], t.lon_deg[twice], t.alt_m[twice], None, t.t_s[twice], t.start, t.source)
    plain, _ = quiet_import(t)
    again, _ = quiet_import(doubled)
    assert again.repeated_dropped == twice.size - len(t)
    assert again.data == plain.data


def test_one_length_everywhere(tmp_path):
    syn = synthetic_track("urban", length_m=2800.0, rate_hz=1.0, seed=9, vertical_noise_m=1.5,
                          stop_at=[(1400.0, 8.0)])
    path = write_gpx(syn.track, tmp_path / "drive.gpx")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RouteWarning)
        route = import_track(path)
        result = convert_track(read_track(path))
    km = float(route.description.rsplit(": ", 1)[1].split()[0])
    assert km == pytest.approx(route.summary()["length_m"] / 1000.0, abs=0.005)
    assert result.length_m == pytest.approx(route.path.length_m, abs=1e-6)


def test_the_real_recording_imports_as_it_was_driven():
    track = read_track(COMMA)
    assert len(track) == 579 and track.kind == "track point"
    result, route = quiet_import(track)
    assert not route.closed and result.stops == ()
    assert route.path.length_m == pytest.approx(1009.0, abs=8.0)  # the fixes' own chords: 1009 m
    speeds = np.array([w.speed_mps for w in route.waypoints])
    assert 7.0 < speeds.min() and speeds.max() < 21.0  # 8-20 m/s between the fixes
    z = route.terrain.height(route.path.x_m, route.path.y_m)
    assert 9.0 < np.ptp(z) < 14.0  # 12 m up the on-ramp, then within a few metres
    assert route.site.date == datetime.date(2018, 8, 2)


# --------------------------------------------------------------------------------------
# What the car cannot drive: smoothed further with a warning, or refused naming the point
# --------------------------------------------------------------------------------------

def test_a_corner_too_sharp_is_smoothed_further_with_a_warning(tmp_path):
    # a square corner, sampled every 5 m: smoothed over 15 m it still turns on under 4.8 m
    a = np.arange(0.0, 100.0, 5.0)
    path = enu_gpx(tmp_path / "corner.gpx", np.concatenate([a, np.full(a.size, 100.0)]),
                   np.concatenate([np.zeros(a.size), a]))
    with pytest.warns(RouteWarning, match=r"corner.gpx: the track turns tighter than the car can \(radius under "
                                           r"4.8 m\); smoothed over 30 m instead of 15 m"):
        result = convert_track(read_track(path))
    route = parse_route(result.data)
    assert result.smoothing_m == 30.0
    from biso_cosim.routes.path import polyline_curvature

    kappa = polyline_curvature(route.path.x_m, route.path.y_m, window_m=4.0, spacing_m=0.25)
    assert 1.0 / np.max(np.abs(kappa[20:-20])) > 0.95 * TURN_MARGIN * car_limits().turning_radius_m


def test_a_turn_the_car_cannot_take_is_refused_naming_the_point(tmp_path):
    # out and back 5 m apart: a U-turn on a 2.5 m radius, which no smoothing widens (a car
    # would need a three-point turn)
    phi = np.linspace(-np.pi / 2, np.pi / 2, 12)
    e = np.concatenate([np.linspace(0, 100, 40), 100 + 2.5 * np.cos(phi), np.linspace(100, 0, 40)])
    n = np.concatenate([np.zeros(40), 2.5 + 2.5 * np.sin(phi), np.full(40, 5.0)])
    with pytest.raises(ValueError, match=r"uturn.gpx, line \d+: track point 4\d: the track turns on a radius of "
                                         r"[0-9.]+ m there even smoothed over 60 m; the car needs at least 4.8 m "
                                         r"\(1.25 × its turning radius of 3.86 m\)"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RouteWarning)
            convert_track(read_track(enu_gpx(tmp_path / "uturn.gpx", e, n)))


def test_grades_too_steep_are_smoothed_or_refused(tmp_path):
    e = np.linspace(0.0, 1000.0, 201)
    # 12 m of bad heights over 20 m: smoothed further than the 40 m asked, with a warning
    up = np.where(np.abs(e - 500.0) < 10.0, 12.0, 0.0)
    with pytest.warns(RouteWarning, match=r"spike.gpx: the heights give grades steeper than the car can climb "
                                           r"\(30%\); smoothed over 80 m instead of 40 m"):
        result = convert_track(read_track(enu_gpx(tmp_path / "spike.gpx", e, np.zeros_like(e), up)),
                               height_smoothing_m=40.0)
    assert result.height_smoothing_m == 80.0
    # 1 km at 45 %: no smoothing makes that a road for this car
    with pytest.raises(ValueError, match=r"steep.gpx, line \d+: track point \d+: the road's grade is 4\d% there even "
                                         r"with the heights smoothed over 800 m; the car climbs at most 30%"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RouteWarning)
            convert_track(read_track(enu_gpx(tmp_path / "steep.gpx", e, np.zeros_like(e), 0.45 * e)))


def test_recorded_speeds_beyond_the_car_are_capped_with_a_warning():
    syn = synthetic_track("highway", length_m=3000.0, rate_hz=1.0, seed=2)
    t = syn.track
    fast = Track(t.lat_deg, t.lon_deg, t.alt_m, None, t.t_s * 0.4, t.start, t.source)  # 75 m/s
    top = f"{car_limits().top_speed_mps:.1f}".replace(".", r"\.")  # the drivetrain's top speed, 54.7 m/s
    with pytest.warns(RouteWarning, match=rf"waypoint\(s\) recorded faster than the car's top speed \({top} m/s"):
        result = convert_track(fast)
    speeds = [w["speed_mps"] for w in result.data["waypoint"]]
    assert max(speeds) == pytest.approx(car_limits().top_speed_mps, abs=0.01)
    plain, _ = quiet_import(t)
    cruise = np.median([w["speed_mps"] for w in plain.data["waypoint"]])
    assert cruise == pytest.approx(30.0, abs=1.5)  # the highway's 30 m/s, from the time stamps


def test_gaps_in_the_fixes_are_bridged_with_a_warning():
    syn = synthetic_track("mountain", length_m=1500.0, rate_hz=10.0, seed=11, dropouts=3)
    with pytest.warns(RouteWarning, match=r"gap\(s\) in the fixes, the longest \d+ s"):
        convert_track(syn.track)


def test_a_bridge_over_the_road_is_made_one_crossing_with_a_warning(tmp_path):
    # a figure eight whose crossing is 14 m higher on the second pass: one height per place
    phi = np.linspace(0.0, 2 * np.pi, 400)
    e, n = 150.0 * np.sin(phi), 60.0 * np.sin(2 * phi)
    up = 14.0 * np.exp(-(((phi - np.pi) / 0.3) ** 2))
    e, n, up = e[:-1], n[:-1], up[:-1]
    with pytest.warns(RouteWarning) as record:
        result = convert_track(read_track(enu_gpx(tmp_path / "bridge.gpx", e, n, up)), height_smoothing_m=60.0)
    assert any(re.search(r"passes within 7 m of itself.*heights [0-9.]+ m apart \(a bridge, or GNSS height noise\?\)",
                         str(w.message)) for w in record)
    route = parse_route(result.data)
    assert route.closed
    # at the crossing (the origin) both passes now see the same ground
    feature = route.terrain.features[0]
    xyz = np.asarray(feature.points)
    near = np.hypot(xyz[:, 0], xyz[:, 1]) < 2.0
    assert np.ptp(xyz[near, 2]) < 0.3


# --------------------------------------------------------------------------------------
# Bad files and values: one line naming the file, the line and the point
# --------------------------------------------------------------------------------------

POINT = '<trkpt lat="{lat}" lon="{lon}">{extra}</trkpt>'


def gpx_text(points):
    body = "\n".join(POINT.format(lat=a, lon=b, extra=c) for a, b, c in points)
    return ('<?xml version="1.0"?>\n<gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1">\n'
            f"<trk><trkseg>\n{body}\n</trkseg></trk></gpx>\n")


def line_of(changes=(), lat0=51.5, n=6, step=1e-4):
    """A straight track of n points 11 m apart, 1 s apart; ``changes`` are (point, field, text)
    with field 0 lat, 1 lon, 2 the elements inside <trkpt>."""
    pts = [[f"{lat0 + step * i:.6f}", "46.0", f"<ele>10</ele><time>2024-05-01T09:00:{i:02d}Z</time>"]
           for i in range(n)]
    for index, k, v in changes:
        pts[index][k] = v
    return gpx_text(pts)


# Every bad input tried; the lines of the GPX files are: 1 xml, 2 gpx, 3 trk, 4.. the points.
BAD_TRACKS = [
    ("lat149.gpx", line_of([(3, 0, "149.4")]), r"lat149.gpx, line 7: track point 4 has lat=149.4; expected a "
                                                   r"latitude in \[-90, 90\] degrees"),
    ("lon.gpx", line_of([(2, 1, "-200")]), r"line 6: track point 3 has lon=-200; expected a longitude"),
    ("nolat.gpx", gpx_text([("51.5", "46", ""), ("", "46", "")]).replace('lat=""', ""),
     r"nolat.gpx, line 5: track point 2 \(<trkpt>\) has no lat attribute"),
    ("word.gpx", line_of([(1, 0, "north")]), r"line 5: track point 2 \(<trkpt>\) has lat='north'"),
    ("nan.gpx", line_of([(2, 0, "nan")]), r"line 6: track point 3 has lat=nan"),
    ("ele.gpx", line_of([(2, 2, "<ele>20000</ele><time>2024-05-01T09:00:02Z</time>")]), r"line 6: track point 3 has height=20000; expected a height"),
    ("noele.gpx", line_of([(2, 2, "<time>2024-05-01T09:00:02Z</time>")]),
     r"line 6: track point 3 has no <ele> while others have one"),
    ("badele.gpx", line_of([(2, 2, "<ele>high</ele><time>2024-05-01T09:00:02Z</time>")]),
     r"line 6: track point 3 has <ele> 'high'; expected a height in metres"),
    ("back.gpx", line_of([(4, 2, "<ele>10</ele><time>2024-05-01T08:59:00Z</time>")]),
     r"back.gpx, line 8: track point 5's time is 63 s earlier than the point before's; times must never go back"),
    ("badtime.gpx", line_of([(1, 2, "<ele>10</ele><time>yesterday</time>")]),
     r"line 5: track point 2 has <time> 'yesterday'; expected an ISO 8601 time"),
    ("notime.gpx", line_of([(1, 2, "<ele>10</ele>")]), r"line 5: track point 2 has no <time> while others have one"),
    ("jump.gpx", line_of([(3, 0, "52.5")]), r"jump.gpx, line 7: track point 4 is 111.\d km from the point before, "
                                               r"1 s later \(\d+ m/s; a car's track stays below 100 m/s\)"),
    ("one.gpx", gpx_text([("51.5", "46", "")]), r"at least two track points \(<trkpt>\) or route points"),
    ("still.gpx", gpx_text([("51.5", "46", "")] * 5), r"still.gpx: the track does not move"),
    ("short.gpx", line_of(n=2, step=3e-5), r"short.gpx: the track is only 3.3 m long; a route needs at least 10 m"),
    ("syntax.gpx", '<gpx version="1.1"><trk><trkseg><trkpt lat="51.5" lon="46">\n</trkseg></trk></gpx>',
     r"syntax.gpx, line 2: not valid XML \(a GPX file is XML\): mismatched tag"),
    ("kml.gpx", '<?xml version="1.0"?><kml><Placemark/></kml>', r"kml.gpx: not a GPX file \(its root element is <kml>"),
    ("empty.gpx", "", r"empty.gpx is empty; expected a GPX track"),
    ("binary.gpx", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", r"binary.gpx is a binary file; expected a GPX text file"),
    ("track.kml", "<kml/>", r"expected a \.gpx or \.csv track, got '\.kml'"),
    ("noext", "lat_deg,lon_deg\n", r"expected a \.gpx or \.csv track, got 'no extension'"),
    ("bad.csv", "lat_deg,lon_deg\n51.5,46.0\n51.5,abc\n", r"bad.csv, line 3: expected numbers in columns lat_deg, lon_deg"),
    ("cols.csv", "lat,lon\n51.5,46.0\n", r"cols.csv, line 1: missing column 'lat_deg'"),
    ("range.csv", "lat_deg,lon_deg\n95,46.0\n51.5,46.0\n", r"range.csv, line 2: row 1 has lat=95; expected a latitude"),
    ("inf.csv", "lat_deg,lon_deg,alt_m\n51.5,46.0,inf\n51.5001,46.0,3\n", r"line 2: row 1 has alt_m=inf; values must "
                                                                           r"be finite"),
    ("back.csv", "lat_deg,lon_deg,t_s\n51.5,46.0,5\n51.5001,46.0,4\n", r"back.csv, line 3: row 2's time is 1 s earlier"),
    ("speed.csv", "lat_deg,lon_deg,speed_mps\n51.5,46.0,-3\n51.5001,46.0,4\n", r"line 2: row 1 has speed_mps=-3"),
    ("latin1.csv", "lat_deg,lon_deg\n51.5,46.0 \xb0\n".encode("latin-1"), r"latin1.csv: not UTF-8 text \(byte 26 is 0xb0\); expected a CSV text file"),
    ("head.csv", "\n", r"head.csv, line 1: missing column 'lat_deg'"),
    ("rows.csv", "lat_deg,lon_deg\n51.5,46.0\n", r"rows.csv: a route needs at least two points, found 1"),
]


@pytest.mark.parametrize(("name", "content", "message"), BAD_TRACKS, ids=[b[0] for b in BAD_TRACKS])
def test_bad_tracks_are_one_line_naming_the_point(tmp_path, name, content, message):
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    with pytest.raises((ValueError, FileNotFoundError)) as info:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RouteWarning)
            convert_track(read_track(path))
    text = str(info.value)
    assert "\n" not in text and "np.float64" not in text and "array(" not in text
    assert name in text
    assert re.search(message, text), text


def test_bad_places_and_bounds(tmp_path):
    with pytest.raises(FileNotFoundError, match="track file .*missing.gpx' does not exist"):
        read_track(tmp_path / "missing.gpx")
    (tmp_path / "dir.gpx").mkdir()
    with pytest.raises(ValueError, match=r"dir.gpx is a directory; expected a .gpx or .csv track file"):
        read_track(tmp_path / "dir.gpx")
    syn = synthetic_track("highway", length_m=3000.0, seed=1)
    path = write_gpx(syn.track, tmp_path / "long.gpx")
    with pytest.raises(ValueError, match=r"long.gpx is 0 MB, more than the 0.001 MB a track may have \(max_file_mb\)"):
        read_track(path, max_file_mb=0.001)
    with pytest.raises(ValueError, match=r"long.gpx: the track is 3.\d km long, more than the 2 km a route may be "
                                         r"\(max_length_km\)"):
        convert_track(read_track(path), max_length_km=2.0)
    for option, value in (("smoothing_m", 0.0), ("height_smoothing_m", -1.0), ("spacing_m", 0.5),
                          ("min_stop_s", float("nan")), ("speed_mps", "fast")):
        with pytest.raises(ValueError, match=option):
            convert_track(syn.track, **{option: value})


def test_reading_reports_progress(tmp_path):
    syn = synthetic_track("mountain", length_m=3000.0, rate_hz=10.0, seed=2)
    path = write_gpx(syn.track, tmp_path / "m.gpx")
    seen, stages = [], []
    track = read_track(path, progress=seen.append)
    assert seen[-1] == 1.0 and seen == sorted(seen)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RouteWarning)
        convert_track(track, progress=lambda fraction, stage: stages.append((fraction, stage)))
    fractions = [f for f, _ in stages]
    assert fractions == sorted(fractions) and fractions[-1] >= 0.9
    assert {"finding stops", "smoothing positions", "smoothing heights"} <= {s for _, s in stages}


def test_a_gpx_file_read_back_is_the_track(tmp_path):
    syn = synthetic_track("urban", length_m=500.0, rate_hz=10.0, seed=3)
    back = read_track(write_gpx(syn.track, tmp_path / "u.gpx"))
    np.testing.assert_allclose(back.lat_deg, syn.track.lat_deg, atol=1e-8)
    np.testing.assert_allclose(back.alt_m, syn.track.alt_m, atol=1e-3)
    np.testing.assert_allclose(back.t_s, syn.track.t_s, atol=1e-3)
    assert list(back.line[:3]) == [4, 5, 6]


def test_the_same_seed_gives_the_same_track():
    a = synthetic_track("mountain", length_m=800.0, rate_hz=1.0, seed=12, dropouts=1)
    b = synthetic_track("mountain", length_m=800.0, rate_hz=1.0, seed=12, dropouts=1)
    assert np.array_equal(a.track.lat_deg, b.track.lat_deg) and np.array_equal(a.track.t_s, b.track.t_s)
    c = synthetic_track("mountain", length_m=800.0, rate_hz=1.0, seed=13, dropouts=1)
    assert not np.array_equal(a.track.lat_deg[:50], c.track.lat_deg[:50])


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------

def test_route_files_are_written_whole(tmp_path):
    syn = synthetic_track("urban", length_m=500.0, seed=4)
    result, route = quiet_import(syn.track)
    out = write_route_file(result.data, tmp_path / "sub" / "u.toml")
    again = load_route(str(out))
    assert again.path.length_m == pytest.approx(route.path.length_m, abs=1e-3)
    assert list(tmp_path.joinpath("sub").iterdir()) == [out]  # no temporary file left
    out.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_output(out) as temporary:
            temporary.write_text("half a fi")
            raise RuntimeError("interrupted")
    assert out.read_text() == "old" and list(out.parent.iterdir()) == [out]


def _curve_allowed(route):
    """The fastest each waypoint's leg may be driven anywhere (the curvature limit of the
    route's own path, by which loading warns of a speed never reached)."""
    from biso_cosim.routes.path import curvature_speed_limit

    n = len(route.waypoints)
    allowed = np.full(n, -np.inf)
    np.maximum.at(allowed, route.path.leg % n, curvature_speed_limit(route.path, route.driving.max_lateral_accel_mps2))
    return np.where(np.isfinite(allowed), allowed, np.inf)  # an open route's last waypoint has no leg


@pytest.mark.parametrize("case", ["comma2k19", "urban", "mountain"])
def test_speeds_beyond_the_curves_lateral_limit_are_capped_at_import(case):
    """The shipped real excerpt with 1 m waypoints and a 1 m/s² limit (its on-ramp then
    curves all along some legs faster than that allows), and recorded-like tracks at the
    default 2.5 m/s²: the import caps those speeds with one warning; loading the route is
    silent; the speed profile the driver follows is the one the recorded speeds gave."""
    if case == "comma2k19":
        track, options = read_track(COMMA), {"spacing_m": 1.0, "max_lateral_accel_mps2": 1.0}
    else:
        track = synthetic_track(case, length_m=450.0 if case == "urban" else 600.0, rate_hz=1.0 if case == "urban"
                                else 10.0, seed=21 if case == "urban" else 22, horizontal_noise_m=3.0,
                                vertical_noise_m=4.0, dropouts=1).track
        options = {}
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        result = convert_track(track, **options)
    capping = [str(w.message) for w in record if "is never reached" in str(w.message)]
    assert result.curve_capped >= 2 and len(capping) == 1
    assert re.search(rf"waypoint\[\d+\]\.speed_mps = [\d.]+ m/s as recorded \(and {result.curve_capped - 1} more "
                     r"waypoint\(s\)\) is never reached: .* capped to that in the route", capping[0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RouteWarning)  # no warning at all when loaded
        route = parse_route(result.data, source=track.source)
    speeds = np.array([w.speed_mps for w in route.waypoints])
    allowed = _curve_allowed(route)
    assert np.all(speeds <= allowed)
    # the recorded speeds: the same import with a lateral limit that caps nothing (the
    # waypoints do not depend on it)
    loose = dict(options, max_lateral_accel_mps2=car_limits().lateral_accel_mps2)
    recorded, recorded_route = quiet_import(track, **loose)
    assert recorded.curve_capped == 0
    assert [(w["x_m"], w["y_m"]) for w in recorded.data["waypoint"]] == [(w.x_m, w.y_m) for w in route.waypoints]
    v_rec = np.array([w["speed_mps"] for w in recorded.data["waypoint"]])
    capped = v_rec > allowed * (1 - 1e-9)
    assert capped.sum() == result.curve_capped
    np.testing.assert_array_equal(speeds[~capped], v_rec[~capped])
    np.testing.assert_allclose(speeds[capped], np.floor(allowed[capped] * 100) / 100)
    # those recorded speeds, loaded at the import's limit, are what the route warned of
    uncapped = dict(result.data, waypoint=[dict(w, speed_mps=float(v)) for w, v in zip(result.data["waypoint"], v_rec)])
    with pytest.warns(RouteWarning, match=r"is never reached: its leg curves all along"):
        before = parse_route(uncapped, source=track.source)
    # ... and the driver's speed profile is the same, to the 0.01 m/s of the rounding
    np.testing.assert_allclose(route.speed_with_stops_mps, before.speed_with_stops_mps, rtol=0, atol=0.01)
    assert route.nominal_duration_s == pytest.approx(before.nominal_duration_s, rel=1e-3)
