"""The peer wrappers of ``biso_cosim.compare`` (VQF, imufusion): frames, scalar order, units and
magnetic against true north, checked on motions whose attitude is known exactly."""

import math
from dataclasses import replace

import numpy as np
import pytest

from biso_cosim import motions as mo
from biso_cosim.compare import Dataset, _imufusion, _vqf
from biso_cosim.peers import magnetic_to_true
from biso_cosim.frames import quat_from_euler
from biso_cosim.metrics import angle_errors_deg

DECL = math.radians(20.0)
# a field whose horizontal part points 20° east of true north (declination +20°)
FIELD_W = (18.0 * math.sin(DECL), 18.0 * math.cos(DECL), -46.0)
PEERS = {"vqf": _vqf, "imufusion": _imufusion}


def _dataset(name, declination_rad=DECL, **kwargs):
    m = mo.make_motion(name, 40.0, 100.0, field_w=FIELD_W, **kwargs)
    d = Dataset(name, "motion", 0, 100.0, m.t_s, m.omega_b, m.specific_force_b, m.mag_b, m.q_wb, declination_rad)
    return m, d


def _max_errors(q, q_true):
    return {k: float(np.max(np.abs(v))) for k, v in angle_errors_deg(q, q_true).items()}


@pytest.mark.parametrize("peer", PEERS)
def test_peer_converges_to_the_true_attitude(peer):
    """A tilted, turned sensor at rest, and a constant rotation about a skew axis: after the
    peer's start-up its roll, pitch and true heading are the truth (a swapped axis, a
    scalar-last quaternion, degrees for radians or magnetic north would be off by degrees)."""
    pytest.importorskip(peer)
    m, d = _dataset("static", rpy=(0.3, -0.4, 2.0))
    err = _max_errors(PEERS[peer](d)[-1000:], m.q_wb[-1000:])
    assert max(err.values()) < 0.01
    m, d = _dataset("rotation", omega_b=(0.2, -0.3, 0.5))
    err = _max_errors(PEERS[peer](d)[-1000:], m.q_wb[-1000:])
    # imufusion integrates to first order and lags a little under rotation
    assert max(err.values()) < (0.05 if peer == "vqf" else 1.0)


@pytest.mark.parametrize("peer", PEERS)
def test_peer_heading_is_turned_from_magnetic_to_true_north(peer):
    pytest.importorskip(peer)
    m, d = _dataset("static", rpy=(0.1, 0.2, -1.0))
    wrong = replace(d, declination_rad=0.0)
    heading = angle_errors_deg(PEERS[peer](wrong)[-100:], m.q_wb[-100:])["heading"]
    # uncorrected, the peer reports the heading from magnetic north: 20° less than the truth
    np.testing.assert_allclose(heading, -math.degrees(DECL), atol=0.01)


def test_magnetic_to_true_turns_the_world_about_up():
    q_mag = quat_from_euler(0.1, -0.2, 0.3)[None]
    q_true = magnetic_to_true(q_mag, DECL)
    e = angle_errors_deg(q_true, q_mag)
    assert e["roll"][0] == pytest.approx(0.0, abs=1e-9) and e["pitch"][0] == pytest.approx(0.0, abs=1e-9)
    assert e["heading"][0] == pytest.approx(math.degrees(DECL), abs=1e-9)  # compass heading grows by D
