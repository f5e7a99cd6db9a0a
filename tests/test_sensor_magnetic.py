"""Earth field (WMM via pygeomag) in ENU and local disturbances."""

import datetime
import math

import numpy as np
import pytest
from pygeomag import GeoMag

from biso_cosim.frames import quat_from_euler, quat_rotate
from biso_cosim.sensors import Dipole, EarthField, MagneticEnvironment, SteelBeam


def test_saratov_field_in_enu_agrees_with_pygeomag_ned():
    e = EarthField()  # Saratov, 2024-05-01
    r = GeoMag(base_year=2024).calculate(glat=51.53, glon=46.03, alt=0.05, time=2024 + 121 / 366)
    np.testing.assert_allclose(e.field_enu_ut, np.array([r.y, r.x, -r.z]) / 1000.0, rtol=1e-12)
    # plausibility for the site: ~53 µT, dip ~69° down, declination ~11° east
    assert 50 < e.total_ut < 56 and 65 < math.degrees(e.inclination_rad) < 73
    assert 8 < math.degrees(e.declination_rad) < 14
    # consistency of the derived quantities with the vector
    east, north, up = e.field_enu_ut
    assert math.atan2(east, north) == pytest.approx(e.declination_rad, abs=1e-9)
    assert math.atan2(-up, math.hypot(east, north)) == pytest.approx(e.inclination_rad, abs=1e-9)
    assert np.linalg.norm(e.field_enu_ut) == pytest.approx(e.total_ut, rel=1e-9)


def test_southern_hemisphere_points_up_and_dates_are_checked():
    e = EarthField(-34.6, -58.4, 0.0, datetime.date(2022, 1, 1))  # Buenos Aires
    assert e.field_enu_ut[2] > 0 and e.inclination_rad < 0
    with pytest.raises(ValueError, match="lat_deg"):
        EarthField(91.0, 0.0)
    with pytest.raises(ValueError, match="2010-2030"):
        EarthField(date=datetime.date(2005, 1, 1))
    with pytest.raises(TypeError, match="date"):
        EarthField(date="2024-05-01")


def test_field_b_rotates_the_world_field_into_the_body():
    env = MagneticEnvironment(EarthField.from_enu([0.0, 20.0, -40.0]))
    # nose to the north (yaw +90°): body x = north, body y = west
    q = quat_from_euler(0.0, 0.0, math.pi / 2)
    np.testing.assert_allclose(env.field_b(q, np.zeros(3)), [20.0, 0.0, -40.0], atol=1e-12)
    rng = np.random.default_rng(0)
    qs = quat_from_euler(*rng.uniform(-1, 1, size=(3, 50)))
    b_b = env.field_b(qs, np.zeros((50, 3)))
    np.testing.assert_allclose(quat_rotate(qs, b_b), np.tile([0.0, 20.0, -40.0], (50, 1)), atol=1e-12)


def test_dipole_matches_the_textbook_field_and_moves():
    env = MagneticEnvironment(EarthField.from_enu([0.0, 0.0, 0.0]), [Dipole((0, 0, 0), (0, 0, 1000.0), velocity_mps=(10.0, 0, 0))])
    # on the axis: 2·(μ0/4π)·m/r³ ; in the equatorial plane: −(μ0/4π)·m/r³  (0.1 µT·m³/A·m²)
    np.testing.assert_allclose(env.field_w([0, 0, 5.0]), [0, 0, 2 * 0.1 * 1000 / 125], atol=1e-12)
    np.testing.assert_allclose(env.field_w([0, 5.0, 0]), [0, 0, -0.1 * 1000 / 125], atol=1e-12)
    # after 1 s it has moved 10 m east
    np.testing.assert_allclose(env.field_w([10.0, 0, 5.0], t_s=1.0), [0, 0, 1.6], atol=1e-12)
    assert np.linalg.norm(env.field_w([0, 0, 5.0], t_s=1.0)) < 1.0


def test_steel_beam_is_induced_along_the_earth_field_and_decays():
    earth = EarthField.from_enu([0.0, 18.0, -48.0])
    beam = SteelBeam((-20.0, 0.0, 0.0), (20.0, 0.0, 0.0), susceptibility_am2_per_ut=2.0)
    env = MagneticEnvironment(earth, [beam])
    near = env.field_w([0.0, 0.0, 2.0]) - earth.field_enu_ut
    far = env.field_w([0.0, 0.0, 200.0]) - earth.field_enu_ut
    assert 1.0 < np.linalg.norm(near) < 200.0
    assert np.linalg.norm(far) < 1e-2 * np.linalg.norm(near)


def test_bad_positions_and_disturbances():
    env = MagneticEnvironment(EarthField.from_enu([0.0, 20.0, -40.0]))
    with pytest.raises(ValueError, match="p_w"):
        env.field_w(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="p_w must be finite"):
        env.field_w([0.0, np.nan, 0.0])
    with pytest.raises(TypeError, match="disturbances"):
        MagneticEnvironment(disturbances=[object()])
