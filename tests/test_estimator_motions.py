"""The analytic test motions: consistent truth (rates, specific force, field), seeds, errors."""

import numpy as np
import pytest

from biso_cosim import frames as fr
from biso_cosim import motions as mo


def _as_compared(name):
    """The motion's arguments as `biso-cosim compare` runs it (from rest, BROAD's set-up), the
    rest shortened to 1 s (or to the time the magnet lies beside the resting sensor)."""
    from biso_cosim.compare import MOTION_SETUP

    if name not in MOTION_SETUP:
        return {}
    setup = MOTION_SETUP[name]
    return {**setup, "rest_s": max(1.0, setup.get("magnet_at_rest", (0.0, 0.0))[1])}


@pytest.mark.parametrize("as_compared", [False, True], ids=["default", "as_compared"])
@pytest.mark.parametrize("name", mo.motion_names())
def test_rates_integrate_to_the_attitude(name, as_compared):
    """q(t + h) = q(t) ∘ exp(ω̄ h) to O(h³) with ω̄ the mean of the end rates (the remainder
    of the trapezoid rule, h³ |ω̈|/12, bounded by h³ max |ω̈| for fast vibrations); also
    through a start from rest and with the comparison's arguments."""
    m = mo.make_motion(name, 2.0, 2000.0, **(_as_compared(name) if as_compared else {}))
    h = 1.0 / m.fs_hz
    step = fr.quat_from_rotvec(0.5 * (m.omega_b[:-1] + m.omega_b[1:]) * h)
    err = fr.quat_angle_between(fr.quat_multiply(m.q_wb[:-1], step), m.q_wb[1:])
    scale = max(1.0, float(np.max(np.linalg.norm(m.omega_b, axis=1)))) ** 3
    omega_dd = np.max(np.linalg.norm(np.diff(m.omega_b, 2, axis=0), axis=1)) / h ** 2
    assert np.max(err) < 1e-8 * scale + h ** 3 * omega_dd


@pytest.mark.parametrize("as_compared", [False, True], ids=["default", "as_compared"])
@pytest.mark.parametrize("name", mo.motion_names())
def test_specific_force_and_field_are_the_world_vectors_in_body_axes(name, as_compared):
    m = mo.make_motion(name, 1.0, 200.0, **(_as_compared(name) if as_compared else {}))
    f_w = fr.quat_rotate(m.q_wb, m.specific_force_b)
    np.testing.assert_allclose(f_w, m.accel_w + [0.0, 0.0, 9.80665], atol=1e-9)
    np.testing.assert_allclose(fr.quat_rotate(m.q_wb, m.mag_b), m.mag_w, atol=1e-9)


def test_accelerations_are_second_derivatives_of_position():
    """Shake: the translational acceleration integrates twice to a bounded oscillation."""
    m = mo.make_motion("shake", 10.0, 2000.0, seed=3)
    h = 1.0 / m.fs_hz
    v = np.cumsum(m.accel_w, axis=0) * h
    assert np.max(np.abs(v - v.mean(axis=0))) < 0.5  # m/s: zero-mean sines, no drift
    assert 0.5 * 9.8 < np.max(np.linalg.norm(m.accel_w, axis=1)) < 2.0 * 9.8


def test_tumble_passes_through_all_attitudes_and_circle_is_a_turn():
    m = mo.make_motion("tumble", 30.0, 100.0)
    e = fr.euler_from_quat(m.q_wb)
    assert np.max(np.abs(e[:, 1])) > np.radians(85)
    assert np.ptp(e[:, 0]) > 6.0 and np.ptp(e[:, 2]) > 6.0
    c = mo.make_motion("circle", 5.0, 100.0, speed_mps=10.0, radius_m=25.0)
    np.testing.assert_allclose(c.omega_b[:, 2], 0.4)
    np.testing.assert_allclose(c.specific_force_b[:, 1], 4.0, atol=1e-12)


def test_magnet_field_follows_the_dipole_law():
    m = mo.make_motion("magnet", 30.0, 100.0)
    d = m.info["distance_m"]
    extra = np.linalg.norm(m.mag_w - m.earth_field_w, axis=1)
    near, far = np.argmin(d), np.argmax(d)
    # |B| of a dipole falls as 1/r³ along a fixed direction
    assert extra[near] / extra[far] == pytest.approx((d[far] / d[near]) ** 3, rel=1e-9)
    assert extra[near] > 500.0


def test_seeds_and_errors():
    a = mo.make_motion("shake", 2.0, 100.0, seed=1)
    b = mo.make_motion("shake", 2.0, 100.0, seed=1)
    c = mo.make_motion("shake", 2.0, 100.0, seed=2)
    np.testing.assert_array_equal(a.specific_force_b, b.specific_force_b)
    assert not np.array_equal(a.specific_force_b, c.specific_force_b)
    with pytest.raises(ValueError, match="static"):
        mo.make_motion("wobble")
    with pytest.raises(ValueError, match="duration_s"):
        mo.make_motion("static", -1.0)
    with pytest.raises(ValueError, match="fs_hz"):
        mo.make_motion("static", 1.0, 0.0)


def test_translation_keeps_the_specific_force_away_from_g():
    """BROAD's fast translations: |f| − g of about 1 g RMS for the whole motion, its power a
    decade above a 3 s low-pass's cut-off (0.075 Hz), and a bounded position."""
    m = mo.make_motion("translation", 60.0, 200.0, seed=1)
    dev = np.linalg.norm(m.specific_force_b, axis=1) - 9.80665
    assert 0.5 * 9.8 < np.sqrt(np.mean(dev ** 2)) < 1.5 * 9.8
    assert 1.5 * 9.8 < np.max(np.linalg.norm(m.accel_w, axis=1)) < 3.5 * 9.8
    spec = np.abs(np.fft.rfft(m.accel_w, axis=0)) ** 2
    f = np.fft.rfftfreq(len(m), 1.0 / m.fs_hz)
    assert np.sum(spec[f > 0.75]) > 0.99 * np.sum(spec)
    v = np.cumsum(m.accel_w, axis=0) / m.fs_hz
    assert np.max(np.abs(v - v.mean(axis=0))) < 2.5


def test_near_magnet_field_changes_with_the_position():
    """A magnet fixed in the room: the field at the sensor is the Earth's plus the dipole's at
    the sensor's position, its norm off by a few to tens of µT, partly below a 10 % test."""
    m = mo.make_motion("near_magnet", 60.0, 100.0)
    d = m.info["distance_m"]
    assert 0.1 < d.min() and d.max() < 0.6
    extra = np.linalg.norm(m.mag_w - m.earth_field_w, axis=1)
    # a dipole's field at distance r lies between |m|/r³ and 2|m|/r³ (×µ0/4π = 0.1 µT·m/A)
    assert np.all(extra >= 0.1 * 0.5 / d ** 3 * (1 - 1e-9)) and np.all(extra <= 0.2 * 0.5 / d ** 3 * (1 + 1e-9))
    dn = np.abs(np.linalg.norm(m.mag_w, axis=1) - np.linalg.norm(m.earth_field_w))
    assert dn.max() > 10.0 and np.mean(dn < 0.1 * np.linalg.norm(m.earth_field_w)) > 0.2


def test_vibration_is_in_the_middle_third_with_the_phone_field_in_body_axes():
    """BROAD's phone vibration: 150 Hz angular and linear vibration during the middle third only,
    and the phone's field fixed in body axes all along (mag_b − the Earth's field = the phone's:
    it lies on the sensor before, during and after the vibration)."""
    m = mo.make_motion("vibration", 30.0, 1000.0, seed=2)
    on = m.info["vibrating"]
    t = m.t_s
    assert not on[t < 10.0].any() and not on[t > 20.0].any() and on[(t > 11.0) & (t < 19.0)].all()
    earth_b = fr.quat_rotate(fr.quat_conjugate(m.q_wb), m.earth_field_w)
    np.testing.assert_allclose(m.mag_b - earth_b, np.tile(mo.PHONE_FIELD_B_UT, (len(m), 1)), atol=1e-9)
    full = (t > 11.0) & (t < 19.0)
    assert 1.5 * 9.8 < np.max(np.linalg.norm(m.accel_w[full], axis=1)) < 2.5 * 9.8
    # the vibration's own rate: amplitude a·2π f about one axis (the slow handling removed)
    calm = mo.make_motion("vibration", 30.0, 1000.0, seed=2, vib_angle_rad=0.0)
    a, w = np.radians(0.0105), 2 * np.pi * 150.0
    vib = np.linalg.norm(m.omega_b - calm.omega_b, axis=1)
    assert np.max(vib[full]) == pytest.approx(a * w, rel=0.01)
    spec = np.abs(np.fft.rfft((m.omega_b - calm.omega_b)[full], axis=0)) ** 2
    f = np.fft.rfftfreq(int(full.sum()), 1.0 / m.fs_hz)
    assert abs(f[np.argmax(spec.sum(axis=1))] - 150.0) < 0.5


@pytest.mark.parametrize("name", ["tumble", "shake", "magnet", "translation", "near_magnet", "vibration"])
def test_a_motion_started_from_rest_is_the_motion_shifted(name):
    """``rest_s``: at rest (no rate, no acceleration, the motion's first attitude) until rest_s,
    a 1 s raised-cosine start, and then the motion itself REST_RAMP_S/2 late (BROAD's trials
    start at rest)."""
    fs, rest = 1000.0, 3.0
    m = mo.make_motion(name, 12.0, fs, seed=1, rest_s=rest)
    plain = mo.make_motion(name, 12.0, fs, seed=1)
    t = m.t_s
    at_rest = t <= rest
    assert np.all(m.omega_b[at_rest] == 0.0) and np.all(m.accel_w[at_rest] == 0.0)
    assert fr.quat_angle_between(m.q_wb[at_rest], np.tile(plain.q_wb[0], (at_rest.sum(), 1))).max() < 1e-12
    np.testing.assert_array_equal(m.info["moving"], t > rest)
    if name in ("magnet", "vibration"):
        return  # their disturbance runs on the time since the motion began, not on the motion time
    lag = int(round((rest + 0.5 * mo.REST_RAMP_S) * fs))
    after = np.arange(int(round((rest + mo.REST_RAMP_S) * fs)) + 1, len(m))
    assert fr.quat_angle_between(m.q_wb[after], plain.q_wb[after - lag]).max() < 1e-9
    np.testing.assert_allclose(m.omega_b[after], plain.omega_b[after - lag], atol=1e-9)
    np.testing.assert_allclose(m.accel_w[after], plain.accel_w[after - lag], atol=1e-9)


def test_tumble_with_the_hands_acceleration():
    """``hand_accel_mps2``: the RMS norm of the translation's acceleration as asked, its power at
    3–8 Hz (BROAD's rotation trials: 0.9–4.6 m/s², median frequency 5.6–8.2 Hz), the rotation
    unchanged; ``fast_tumble`` is the tumble 2.6 times faster."""
    m = mo.make_motion("tumble", 60.0, 500.0, seed=3, hand_accel_mps2=2.25)
    plain = mo.make_motion("tumble", 60.0, 500.0, seed=3)
    np.testing.assert_array_equal(m.q_wb, plain.q_wb)
    assert np.sqrt(np.mean(np.sum(m.accel_w ** 2, axis=1))) == pytest.approx(2.25, rel=0.02)
    stats = mo.recording_statistics(m.fs_hz, m.omega_b, m.specific_force_b, m.mag_b, m.q_wb)
    assert 3.1 <= stats["accel_median_hz"] <= 8.3
    fast = mo.make_motion("fast_tumble", 10.0, 500.0)
    slow = mo.make_motion("tumble", 26.0, 500.0)
    assert fast.name == "fast_tumble"
    i = np.arange(0, len(fast), 5)  # fast time i/500 s is slow time 2.6 i/500 s, sample 13 i/5
    np.testing.assert_allclose(fast.omega_b[i], 2.6 * slow.omega_b[i * 13 // 5], atol=1e-9)


def test_the_acceleration_is_the_positions_second_derivative_through_the_start():
    """``translation`` from rest (the comparison's arguments): accel_w = p̈ of its position,
    also in the raised-cosine start where p̈(τ(t)) = p''(τ) τ'² + p'(τ) τ'' (central second
    differences, O(h²))."""
    m = mo.make_motion("translation", 3.0, 4000.0, seed=2, **_as_compared("translation"))
    p, h = m.info["position_m"], 1.0 / m.fs_hz
    second = (p[2:] - 2.0 * p[1:-1] + p[:-2]) / h ** 2
    assert np.max(np.abs(second - m.accel_w[1:-1])) < 1e-3 * np.max(np.abs(m.accel_w))


def test_shake_spins_at_the_asked_rate():
    """``spin_dps``: a steady turn about body y on top of the wobble; the wobble's angles
    are periodic, so over whole periods of all of them the body rate's mean is the spin."""
    m = mo.make_motion("shake", 10.0, 1000.0, seed=2, spin_dps=-249.0, wobble_hz=(0.5, 1.0, 2.0))
    plain = mo.make_motion("shake", 10.0, 1000.0, seed=2, wobble_hz=(0.5, 1.0, 2.0))
    np.testing.assert_allclose(np.degrees(m.omega_b.mean(axis=0)), [0.0, -249.0, 0.0], atol=12.0)
    # the spin turns the wobble's attitude about its own y axis: R_y(spin t) appended
    spin = fr.quat_from_rotvec(np.radians(-249.0) * m.t_s[:, None] * np.array([[0.0, 1.0, 0.0]]))
    assert fr.quat_angle_between(m.q_wb, fr.quat_multiply(plain.q_wb, spin)).max() < 1e-9
    np.testing.assert_array_equal(m.accel_w, plain.accel_w)
    with pytest.raises(ValueError, match="three values"):
        mo.make_motion("shake", 1.0, 100.0, wobble_deg=(5.0, 5.0))


def test_near_magnet_passes_and_the_magnet_beside_the_resting_sensor():
    """A pass takes the sensor to ``closest_m`` from the magnet (across its axis: the dipole's
    field against the Earth's, |m| down) and back, its acceleration the second derivative of the
    sensor's position; the magnet laid beside the resting sensor changes the field (on its axis:
    |m| up) with no acceleration; far away the magnet adds about 1 µT (0.5 A·m² at 0.5 m)."""
    hand = {"spin_dps": -154.0, "wobble_deg": (56.0, 12.0, 56.0), "wobble_hz": (0.8, 1.2, 0.9), "accel_g": 1.278,
            "accel_hz": (1.1, 1.7, 2.5)}
    m = mo.make_motion("near_magnet", 20.0, 4000.0, seed=1, rest_s=4.0, distance_m=0.5, hand=hand,
                       magnet_at_rest=(0.15, 3.0), passes=((0.5, 0.105, 0.6),))
    t, d = m.t_s, m.info["distance_m"]
    dn = np.linalg.norm(m.mag_w, axis=1) - np.linalg.norm(m.earth_field_w)
    centre = np.argmin(np.abs(t - 14.0))
    assert d[centre] == pytest.approx(0.105, abs=1e-9) and dn[centre] < -15.0
    resting = (t > 1.3) & (t < 4.0)
    np.testing.assert_allclose(d[resting], 0.15, atol=1e-9)
    assert np.all(dn[resting] > 20.0) and np.all(m.accel_w[t <= 4.0] == 0.0)
    far = (t > 6.0) & ((t < 13.6) | (t > 14.4))
    assert np.all(d[far] > 0.3) and np.max(np.abs(dn[far])) < 5.0
    p, h = m.info["position_m"], 1.0 / m.fs_hz
    second = (p[2:] - 2.0 * p[1:-1] + p[:-2]) / h ** 2
    assert np.max(np.abs(second - m.accel_w[1:-1])) < 1e-3 * np.max(np.abs(m.accel_w))
    with pytest.raises(ValueError, match="passes"):
        mo.make_motion("near_magnet", 10.0, 100.0, passes=((1.5, 0.1, 1.0),))
    with pytest.raises(ValueError, match="magnet_at_rest"):
        mo.make_motion("near_magnet", 10.0, 100.0, rest_s=1.0, magnet_at_rest=(0.15, 3.0))
    with pytest.raises(ValueError, match="hand takes"):
        mo.make_motion("near_magnet", 10.0, 100.0, hand={"spin": 1.0})


def test_vibration_span_and_hand():
    """``vib_span``: it vibrates between those fractions of the motion only; ``hand``: the
    sensor is turned and moved as `shake` moves it, the vibration on top unchanged."""
    hand = {"wobble_deg": (4.3, 2.6, 1.85), "wobble_hz": (1.2, 2.0, 2.8), "accel_g": 0.333, "accel_hz": (0.45, 0.7, 1.1)}
    m = mo.make_motion("vibration", 30.0, 1000.0, seed=2, vib_span=(0.2, 1.0), hand=hand)
    t, on = m.t_s, m.info["vibrating"]
    assert not on[t < 6.0].any() and on[(t > 7.0) & (t < 28.9)].all()
    calm = mo.make_motion("vibration", 30.0, 1000.0, seed=2, vib_span=(0.2, 1.0), hand=hand, vib_angle_rad=0.0,
                          vib_m=0.0)
    np.testing.assert_array_equal(m.accel_w[t < 6.0], calm.accel_w[t < 6.0])
    assert np.sqrt(np.mean(np.sum(calm.accel_w ** 2, axis=1))) == pytest.approx(0.333 * 9.80665 / np.sqrt(2), rel=0.05)
    with pytest.raises(ValueError, match="vib_span"):
        mo.make_motion("vibration", 10.0, 100.0, vib_span=(0.5, 0.4))


def test_translation_rests_and_moves_in_fields_of_their_own():
    """``rest_field`` and ``path_field`` (norm ratio, azimuth and dip changes against ``field_w``)
    are the field at the rest and after the start, measured back as such; the slow translation is
    the translation at its own pace and swing."""
    change_rest, change_path = (0.945, 1.77, 2.43), (1.019, -1.58, -0.26)
    m = mo.make_motion("translation", 10.0, 200.0, rest_s=5.0, rest_field=change_rest, path_field=change_path)
    moving = m.info["moving"]
    st = mo.recording_statistics(m.fs_hz, m.omega_b, m.specific_force_b, m.mag_b, m.q_wb, moving=moving,
                                 field_w=m.earth_field_w)
    np.testing.assert_allclose(st["rest_field"], change_rest, atol=1e-9)
    after = m.t_s > 5.0 + mo.REST_RAMP_S
    np.testing.assert_allclose(mo._field_against(m.mag_w[after].mean(axis=0), m.earth_field_w), change_path, atol=1e-9)
    plain = mo.make_motion("translation", 10.0, 200.0, rest_s=5.0)
    np.testing.assert_array_equal(plain.q_wb, m.q_wb)  # the field changes nothing else
    slow = mo.make_motion("slow_translation", 10.0, 200.0, seed=4)
    same = mo.make_motion("translation", 10.0, 200.0, seed=4, accel_g=0.28, accel_hz=(0.25, 0.56, 0.85),
                          hand_rate_dps=(23.0, 18.0, 25.0), swing_deg=(3.0, 2.0, 2.0))
    assert slow.name == "slow_translation"
    np.testing.assert_array_equal(slow.specific_force_b, same.specific_force_b)
    with pytest.raises(ValueError, match="rest_field"):
        mo.make_motion("translation", 1.0, 100.0, rest_field=(0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="accel_hz"):
        mo.make_motion("translation", 1.0, 100.0, accel_hz=(1.0, -1.0, 2.0))
