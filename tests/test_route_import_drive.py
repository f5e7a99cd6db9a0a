"""Imported tracks drive: each route made from a recording is driven to its end by the scripted
driver with a cross-track RMS of at most 0.5 m (the tracks are short, so that the suite stays
fast; ``biso-cosim routes check my.toml`` drives an imported route of any length)."""

import warnings
from pathlib import Path

import numpy as np

from biso_cosim.routes import RouteWarning, parse_route
from biso_cosim.routes.importing import convert_track
from biso_cosim.routes.synthetic import synthetic_track
from biso_cosim.routes.tracks import read_track
from biso_cosim.testing import drive

COMMA = Path(__file__).resolve().parent / "data" / "comma2k19_i280_60s.gpx"


def imported(track):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RouteWarning)
        return parse_route(convert_track(track).data, source=track.source)


def driven(route):
    run = drive(route, estimator="poisson", seed=0).run
    cross = np.asarray(run.cross_track_m)
    assert run.completed, f"{route.name}: not completed in {run.duration_s:.0f} s"
    rms = float(np.sqrt(np.mean(cross**2)))
    assert rms <= 0.5, f"{route.name}: cross-track RMS {rms:.2f} m"
    return run


def test_an_urban_recording_at_1_hz_with_a_stop_drives():
    syn = synthetic_track("urban", length_m=450.0, rate_hz=1.0, seed=21, stop_at=[(230.0, 8.0)],
                          horizontal_noise_m=3.0, vertical_noise_m=4.0, dropouts=1)
    route = imported(syn.track)
    assert len(route.stops) == 2
    run = driven(route)
    # the 8 s wait is a stop: the car stands there (not a slowdown), then drives on
    still = run.truth.speed_mps < 0.05
    moving = np.flatnonzero(~still)
    between = still[moving[0]:moving[-1]]
    edges = np.diff(np.concatenate([[0], between.astype(np.int8), [0]]))
    longest = np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)) * (run.truth.t_s[1] - run.truth.t_s[0])
    assert 6.5 < longest < 10.0


def test_a_mountain_recording_at_10_hz_drives():
    syn = synthetic_track("mountain", length_m=600.0, rate_hz=10.0, seed=22, horizontal_noise_m=2.0,
                          vertical_noise_m=2.0, dropouts=1)
    route = imported(syn.track)
    assert np.ptp(route.terrain.height(route.path.x_m, route.path.y_m)) > 5.0  # it climbs
    driven(route)


def test_the_real_recording_drives():
    driven(imported(read_track(COMMA)))
