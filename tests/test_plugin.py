"""biso_cosim.plugin.ImuPlugin: the FMU's model as a Python class, against the sensor and the
estimators run on whole arrays; lever arm; state; bad input."""

import pickle

import numpy as np
import pytest

from biso_cosim.estimators import flags as est_flags
from biso_cosim.estimators import make_estimator
from biso_cosim.frames import quat_conjugate, quat_rotate
from biso_cosim.metrics import angle_errors_deg
from biso_cosim.motions import make_motion
from biso_cosim.plugin import ImuPlugin, Mounting, PluginOutput, PluginState
from biso_cosim.sensors import MPU9250, Dipole, EarthField, MagneticEnvironment


def _ticks(plugin, motion, t0=0.0, **extra):
    """Feed a motion tick by tick; the concatenated outputs."""
    outs = []
    for i in range(len(motion)):
        row = {k: (v[i] if isinstance(v, np.ndarray) and v.ndim > 0 else v) for k, v in extra.items()}
        outs.append(plugin.step(t0 + motion.t_s[i], motion.q_wb[i], motion.omega_b[i], motion.specific_force_b[i], **row))
    return PluginOutput.concatenate(outs)


def _same(a: PluginOutput, b: PluginOutput) -> None:
    assert np.array_equal(a.t_s, b.t_s)
    for name in ("gyro_b", "accel_b", "mag_b", "temperature_c", "flags", "mag_fresh"):
        assert np.array_equal(getattr(a.samples, name), getattr(b.samples, name), equal_nan=True), name
    assert np.array_equal(a.raw.words, b.raw.words) and np.array_equal(a.raw.status, b.raw.status)
    assert np.array_equal(a.q_true_wb, b.q_true_wb)
    for label, ea in a.estimates.items():
        eb = b.estimates[label]
        assert np.array_equal(ea.estimate.q_wb, eb.estimate.q_wb) and np.array_equal(ea.flags, eb.flags)


def test_readings_and_estimates_equal_the_sensor_and_the_batch_estimator():
    """The FMU's numbers: MPU9250.simulate on the whole truth array, then the estimator's
    batch update; truth rows at 500 Hz (the chip interpolates them to its 1 kHz)."""
    h, t0 = 0.002, 12.5
    motion = make_motion("circle", duration_s=1.0, fs_hz=1.0 / h)
    plugin = ImuPlugin(tick_s=h, profile="mpu9250", seed=11, registers={"smplrt_div": 9}, estimators=["biso_plus"])
    out = _ticks(plugin, motion, t0=t0)
    earth = EarthField()
    imu = MPU9250("mpu9250", seed=11, registers={"smplrt_div": 9}, input_rate_hz=1.0 / h)
    s = imu.simulate(motion.omega_b, motion.specific_force_b,
                     MagneticEnvironment(earth).field_b(motion.q_wb, np.zeros((len(motion), 3))))
    assert len(out) == len(s.t_s) == 100  # 100 Hz ODR: samples at 0, 10, ..., 990 ms
    assert np.array_equal(out.t_s, t0 + s.t_s)
    for name in ("gyro_b", "accel_b", "mag_b", "temperature_c", "flags"):
        assert np.array_equal(getattr(out.samples, name), getattr(s, name)), name
    assert np.array_equal(out.raw.words, s.raw.words) and np.array_equal(out.raw.status, s.raw.status)
    est = make_estimator("biso_plus", imu.output_rate_hz, declination_rad=earth.declination_rad)
    ref = est.update(s.gyro_b, s.accel_b, s.mag_b, imu_flags=s.flags)
    got = out.estimates["biso_plus"]
    assert np.array_equal(got.estimate.q_wb, ref.q_wb) and np.array_equal(got.flags, ref.flags)
    assert np.array_equal(got.estimate.gyro_bias_b, ref.gyro_bias_b)
    # samples fall on truth rows (10 ms apart): the truth at a sample is that row's attitude
    truth = motion.q_wb[np.round(s.t_s / h).astype(int)]
    assert np.max(np.abs(out.q_true_wb - truth)) < 1e-15
    err = angle_errors_deg(ref.q_wb, truth)
    for angle in ("roll", "pitch", "heading", "total"):
        np.testing.assert_allclose(got.errors_deg[angle], err[angle], atol=1e-9)


def test_truth_between_ticks_is_the_nlerp_of_the_ticks_around_each_sample():
    h = 0.02  # 50 Hz truth, 200 Hz samples: three of every four fall between ticks
    motion = make_motion("tumble", duration_s=2.0, fs_hz=1.0 / h, seed=3)
    out = _ticks(ImuPlugin(tick_s=h, seed=0), motion)
    j = np.ceil(out.samples.t_s / h - 1e-6).astype(int)
    frac = (out.samples.t_s - j * h) / h + 1.0
    q0, q1 = motion.q_wb[np.maximum(j - 1, 0)], motion.q_wb[j]
    q1 = np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0, -q1, q1)
    q = (1 - frac)[:, None] * q0 + frac[:, None] * q1
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    assert set(np.round(frac, 9)) == {0.25, 0.5, 0.75, 1.0}
    np.testing.assert_allclose(out.q_true_wb, q, atol=1e-15)


def test_any_split_into_calls_gives_the_same_run_bit_for_bit():
    h = 0.001
    motion = make_motion("tumble", duration_s=1.5, fs_hz=1.0 / h, seed=5)
    n = len(motion)
    v_w = np.cumsum(quat_rotate(motion.q_wb, motion.specific_force_b) - [0, 0, 9.80665], axis=0) * h
    accel_w = quat_rotate(motion.q_wb, motion.specific_force_b) - [0.0, 0.0, 9.80665]
    temp = 30.0 + np.linspace(0.0, 5.0, n)
    kwargs = dict(tick_s=h, profile="mpu9250", seed=4, mounting=Mounting((0.3, -0.1, 0.2), (0.5, 0.5, 0.5, 0.5)),
                  estimators={"plus": ("biso_plus", {}), "faithful": "biso", "dcm": "dcm_pi"},
                  speed_from_velocity=True, site=MagneticEnvironment(EarthField(), [Dipole((2.0, 1.0, 0.0), (0, 0, 200))]))
    truth = dict(accel_w=accel_w, v_w=v_w, p_w=np.cumsum(v_w, axis=0) * h, temperature_c=temp)
    whole = ImuPlugin(**kwargs).step(motion.t_s, motion.q_wb, motion.omega_b, **truth)
    rng = np.random.default_rng(0)
    cuts = np.unique(np.concatenate(([0, n], rng.integers(1, n, 60))))
    split = ImuPlugin(**kwargs)
    parts = [split.step(motion.t_s[a:b], motion.q_wb[a:b], motion.omega_b[a:b],
                        **{k: v[a:b] for k, v in truth.items()}) for a, b in zip(cuts[:-1], cuts[1:])]
    ticked = ImuPlugin(**kwargs)
    parts_1 = [ticked.step(motion.t_s[i], motion.q_wb[i], motion.omega_b[i], **{k: v[i] for k, v in truth.items()})
               for i in range(n)]
    _same(whole, PluginOutput.concatenate(parts))
    _same(whole, PluginOutput.concatenate(parts_1))
    assert len(whole) == 300 and ticked.ticks == n
    assert np.all(whole.estimates["plus"].flags[50:] & est_flags.ACCEL_COMPENSATED)


def test_lever_arm_adds_the_centripetal_and_tangential_terms():
    """A chip 0.8 m ahead of the reference point, 0.3 m left and 0.2 m up: the plug-in's
    readings equal the chip run on f + ω̇ × r + ω × (ω × r) formed here with numpy, ω̇ the
    given angular acceleration or else the backward difference of ω between ticks."""
    h = 0.001
    motion = make_motion("tumble", duration_s=1.0, fs_hz=1.0 / h, seed=2)
    r = np.array([0.8, 0.3, 0.2])
    alpha = np.gradient(motion.omega_b, h, axis=0)
    q0 = (np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5))  # chip x along the body y
    field = MagneticEnvironment(EarthField()).field_b(motion.q_wb, np.zeros((len(motion), 3)))
    for given in (True, False):
        plugin = ImuPlugin(tick_s=h, profile="ideal", seed=0, mounting=Mounting(tuple(r), q0))
        out = _ticks(plugin, motion, **({"alpha_b": alpha} if given else {}))
        a = alpha if given else np.vstack([np.zeros(3), np.diff(motion.omega_b, axis=0) / h])
        f_chip = motion.specific_force_b + np.cross(a, r) + np.cross(motion.omega_b, np.cross(motion.omega_b, r))
        s = MPU9250("ideal", seed=0, mounting=np.array(q0), input_rate_hz=1.0 / h).simulate(motion.omega_b, f_chip, field)
        # the ideal part does not quantise: the two sums differ by rounding only
        np.testing.assert_allclose(out.samples.accel_b, s.accel_b, rtol=0.0, atol=1e-12)
        assert np.array_equal(out.samples.gyro_b, s.gyro_b)
    # the analytic circle: the chip d ahead of a rear axle feels −ω²·d along x on top of v²/R
    circle = make_motion("circle", duration_s=1.0, fs_hz=1000.0, speed_mps=10.0, radius_m=20.0)
    ahead = make_motion("circle", duration_s=1.0, fs_hz=1000.0, speed_mps=10.0, radius_m=20.0, imu_ahead_m=1.5)
    out = _ticks(ImuPlugin(tick_s=h, profile="ideal", mounting=Mounting((1.5, 0.0, 0.0))), circle)
    s = MPU9250("ideal", seed=0).simulate(ahead.omega_b, ahead.specific_force_b,
                                          MagneticEnvironment(EarthField()).field_b(ahead.q_wb, np.zeros((1000, 3))))
    np.testing.assert_allclose(out.samples.accel_b, s.accel_b, rtol=0.0, atol=1e-12)
    assert np.mean(out.samples.accel_b[:, 0]) == pytest.approx(-(0.5 ** 2) * 1.5, abs=0.01)


def test_speed_from_velocity_feeds_biso_plus_at_the_reference_point():
    h = 0.001
    motion = make_motion("circle", duration_s=0.6, fs_hz=1.0 / h, speed_mps=8.0)
    v_w = 8.0 * quat_rotate(motion.q_wb, np.array([1.0, 0.0, 0.0]))  # the reference point's velocity
    plugin = ImuPlugin(tick_s=h, speed_from_velocity=True, mounting=Mounting((1.0, 0.0, 0.0)))
    assert plugin.estimators["biso_plus"].params.speed_point_b_m == (-1.0, -0.0, -0.0)
    out = _ticks(plugin, motion, v_w=v_w)
    rows = np.round(out.samples.t_s / h).astype(int)
    speed = quat_rotate(quat_conjugate(motion.q_wb[rows]), v_w[rows])[:, 0]
    np.testing.assert_allclose(speed, 8.0, atol=1e-12)
    est = make_estimator("biso_plus", 200.0, declination_rad=EarthField().declination_rad, speed_point_b_m=(-1.0, 0, 0))
    ref = est.update(out.samples.gyro_b, out.samples.accel_b, out.samples.mag_b, speed_mps=speed,
                     imu_flags=out.samples.flags)
    np.testing.assert_allclose(out.estimates["biso_plus"].estimate.q_wb, ref.q_wb, atol=1e-12)
    assert np.all(out.estimates["biso_plus"].flags[2:] & est_flags.ACCEL_COMPENSATED)
    with pytest.raises(ValueError, match="v_w is required"):
        plugin.step(0.6, motion.q_wb[0], motion.omega_b[0], motion.specific_force_b[0])


def test_state_get_set_reset_and_seed():
    h = 0.001
    motion = make_motion("tumble", duration_s=0.6, fs_hz=1.0 / h, seed=1)
    first, second = motion.t_s < 0.3, motion.t_s >= 0.3
    plugin = ImuPlugin(tick_s=h, profile="mpu9250", seed=7, estimators=["biso_plus", "biso"])
    plugin.step(motion.t_s[first], motion.q_wb[first], motion.omega_b[first], motion.specific_force_b[first])
    state = plugin.get_state()
    rest = (motion.t_s[second], motion.q_wb[second], motion.omega_b[second], motion.specific_force_b[second])
    a = plugin.step(*rest)
    plugin.set_state(pickle.loads(pickle.dumps(state)))
    _same(a, plugin.step(*rest))
    assert plugin.ticks == 600
    plugin.reset()
    fresh = ImuPlugin(tick_s=h, profile="mpu9250", seed=7, estimators=["biso_plus", "biso"])
    whole = (motion.t_s + 100.0, motion.q_wb, motion.omega_b, motion.specific_force_b)  # another t₀ after reset
    fresh_out = fresh.step(*whole)
    _same(plugin.step(*whole), fresh_out)
    plugin.reset(seed=8)
    other = ImuPlugin(tick_s=h, profile="mpu9250", seed=8, estimators=["biso_plus", "biso"]).step(*whole)
    _same(plugin.step(*whole), other)
    assert not np.array_equal(other.samples.gyro_b, fresh_out.samples.gyro_b)  # another part, other noise
    with pytest.raises(ValueError, match="estimators"):
        ImuPlugin(tick_s=h, estimators=["biso"]).set_state(state)
    with pytest.raises(TypeError, match="PluginState"):
        plugin.set_state({"sensor": None})
    assert isinstance(state, PluginState) and state.ticks == 300 and state.t0_s == 0.0


def _assert_refused(plugin, call, match):
    before = plugin.get_state()
    with pytest.raises(ValueError, match=match):
        call()
    after = plugin.get_state()
    assert after.ticks == before.ticks and after.t0_s == before.t0_s
    assert np.array_equal(after.last_tick, before.last_tick)
    assert all(np.array_equal(after.sensor[k], before.sensor[k]) for k in before.sensor)
    assert all(np.array_equal(after.estimators[k].values, before.estimators[k].values, equal_nan=True)
               for k in before.estimators)


def test_bad_input_is_refused_by_name_and_changes_nothing():
    h = 0.001
    motion = make_motion("tumble", duration_s=0.05, fs_hz=1.0 / h, seed=1)
    q, w, f = motion.q_wb, motion.omega_b, motion.specific_force_b
    plugin = ImuPlugin(tick_s=h, seed=0)
    reference = ImuPlugin(tick_s=h, seed=0)
    for i in range(10):
        _same(plugin.step(i * h, q[i], w[i], f[i]), reference.step(i * h, q[i], w[i], f[i]))
    nan3 = np.array([0.0, np.nan, 0.0])
    t = 10 * h
    cases = [
        (lambda: plugin.step(t, q[10], nan3, f[10]), "omega_b must be finite"),
        (lambda: plugin.step(t, q[10], w[10], [np.inf, 0, 0]), "specific_force_b must be finite"),
        (lambda: plugin.step(t, [np.nan, 0, 0, 1.0], w[10], f[10]), "q_wb must be finite"),
        (lambda: plugin.step(t, [1.0, 0.1, 0, 0], w[10], f[10]), r"q_wb must be a unit quaternion .*\|q\| = 1.00498"),
        (lambda: plugin.step(t, [0.0, 0, 0, 0], w[10], f[10]), "q_wb must be a unit quaternion"),
        (lambda: plugin.step(np.nan, q[10], w[10], f[10]), "t_s must be finite"),
        (lambda: plugin.step(5 * h, q[10], w[10], f[10]), "t_s went backwards"),
        (lambda: plugin.step(9 * h, q[10], w[10], f[10]), "t_s repeats the previous tick"),
        (lambda: plugin.step(12 * h, q[10], w[10], f[10]), "t_s = 0.012 s is not the next tick, due at 0.01"),
        (lambda: plugin.step(t, q[10], w[10], accel_w=[0, 0, np.nan]), "accel_w must be finite"),
        (lambda: plugin.step(t, q[10], w[10], f[10], p_w=nan3), "p_w must be finite"),
        (lambda: plugin.step(t, q[10], w[10], f[10], v_w=nan3), "v_w must be finite"),
        (lambda: plugin.step(t, q[10], w[10], f[10], alpha_b=nan3), "alpha_b must be finite"),
        (lambda: plugin.step(t, q[10], w[10], f[10], temperature_c=np.nan), "temperature_c must be finite"),
        (lambda: plugin.step(t, q[10], w[10]), "give either specific_force_b"),
        (lambda: plugin.step(t, q[10], w[10], f[10], accel_w=f[10]), "not both"),
        (lambda: plugin.step(t, q[10, :3], w[10], f[10]), r"q_wb must have shape \(4,\)"),
        (lambda: plugin.step([t, t + h], q[10:12], w[10:12], f[10:11]), r"specific_force_b must have shape \(2, 3\)"),
        # a block whose second row is bad: nothing of the block is taken
        (lambda: plugin.step([t, t + h], q[10:12], np.vstack([w[10], nan3]), f[10:12]), r"omega_b \(row 1\)"),
        (lambda: plugin.step([t, t + 3 * h], q[10:12], w[10:12], f[10:12]), r"t_s \(row 1\) = 0.013"),
    ]
    for call, match in cases:
        _assert_refused(plugin, call, match)
    for i in range(10, 50):  # nothing was lost: the run goes on as if the bad calls never happened
        _same(plugin.step(i * h, q[i], w[i], f[i]), reference.step(i * h, q[i], w[i], f[i]))


def test_bad_construction_names_the_argument():
    with pytest.raises(ValueError, match=r"tick_s = 0.004166.* cannot drive the chip"):
        ImuPlugin(tick_s=1.0 / 240.0)  # pybullet's default step
    with pytest.raises(ValueError, match="tick_s must be positive"):
        ImuPlugin(tick_s=-0.001)
    with pytest.raises(ValueError, match="world must be one of ENU, NED"):
        ImuPlugin(tick_s=0.001, frames=("NWU", "FLU", "wxyz"))
    with pytest.raises(ValueError, match="body must be one of FLU, FRD"):
        ImuPlugin(tick_s=0.001, frames={"body": "RFU"})
    with pytest.raises(ValueError, match="quaternion must be one of wxyz, xyzw"):
        ImuPlugin(tick_s=0.001, frames={"quaternion": "zyxw"})
    with pytest.raises(ValueError, match="unknown estimator 'vqf'"):
        ImuPlugin(tick_s=0.001, estimators=["vqf"])
    with pytest.raises(ValueError, match="GNSS"):
        ImuPlugin(tick_s=0.001, estimators=["gnss_kalman"])
    with pytest.raises(ValueError, match="gyro_step"):
        ImuPlugin(tick_s=0.001, estimators=[("biso", {"gyro_step": "bortz"})])
    with pytest.raises(TypeError, match=r"estimators\['biso'\] \(biso\).*no parameter"):
        ImuPlugin(tick_s=0.001, estimators=[("biso", {"gain": 1.0})])
    with pytest.raises(ValueError, match="label 'biso' given twice"):
        ImuPlugin(tick_s=0.001, estimators=["biso", "biso"])
    with pytest.raises(ValueError, match="mounting.q_body_chip must be a unit quaternion"):
        Mounting((0, 0, 0), (1.0, 1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="gravity_w"):
        ImuPlugin(tick_s=0.001, gravity_w=(0.0, 9.8))
    assert ImuPlugin(tick_s=0.02).output_rate_hz == 200.0  # 50 Hz truth drives the chip too
