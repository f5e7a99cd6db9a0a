"""What the environments compute: rewards against analytic cases, the observation against the
co-simulation's own sample stream (bit for bit), the tuned estimator against a standalone one,
dead reckoning against a plain reference, and the procedural routes."""

import copy
import math

import gymnasium as gym
import numpy as np
import pytest

import biso_cosim.envs  # noqa: F401  (registers the ids)
from biso_cosim.cosim import CoSimulation
from biso_cosim.envs import random_route
from biso_cosim.envs._common import IMU_FIELDS
from biso_cosim.envs.gain_tuning import CROSS_LINK_RATIO
from biso_cosim.estimators import make_estimator
from biso_cosim.estimators.biso import PAPER_K, PAPER_K_P, gains_from_cutoff
from biso_cosim.frames import euler_from_quat, quat_angle_between, quat_from_rotvec, quat_multiply
from biso_cosim.routes import parse_route
from biso_cosim.vehicle.sim import Truth

SHORT = {"episode_duration_s": 1.5}


def capture_periods(core) -> list:
    """The co-simulation's outputs (samples, truth, estimates) of every period from now on:
    an environment keeps no log (and its co-simulation writes every period's samples and
    estimates into the same arrays: copies are kept)."""
    periods = []
    sim_step = core.sim.step

    def step(command=None):
        out = sim_step(command)
        periods.append(copy.deepcopy(out))
        return out

    core.sim.step = step
    return periods


def run_episode(env, policy, seed):
    """The return of an episode of ``policy`` (observation -> action), and its last info."""
    obs, info = env.reset(seed=seed)
    total = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        if terminated or truncated:
            return total, info


def straight_route(length_m=60.0, speed_mps=6.0):
    """An open straight road east, on flat ground."""
    return parse_route({
        "name": "straight", "description": "test straight", "closed": False,
        "driving": {"default_speed_mps": speed_mps, "start_wait_s": 0.5},
        "waypoint": [{"x_m": 0.0, "y_m": 0.0}, {"x_m": length_m, "y_m": 0.0}],
    })


# --------------------------------------------------------------------------------------
# AttitudeEstimation
# --------------------------------------------------------------------------------------


def _newest_q_wb(core):
    """The true attitude at the newest sample (a copy: the environment reuses its arrays)."""
    return core._newest_row[Truth.QUAT_COLUMN:Truth.QUAT_COLUMN + 4].copy()


def test_reward_is_minus_the_rotation_angle_to_the_truth():
    env = gym.make("biso_cosim/AttitudeEstimation-v0", **SHORT)
    env.reset(seed=0)
    core = env.unwrapped
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    for angle in (0.0, 0.1, 1.0, 3.0):
        q_true = _newest_q_wb(core)
        q_action = quat_multiply(q_true, quat_from_rotvec(angle * axis))
        sign = -1.0 if angle == 1.0 else 1.0  # q and -q are the same attitude
        _, reward, _, _, info = env.step(sign * 0.5 * q_action)  # any length: it is normalised
        assert reward == pytest.approx(-angle, abs=1e-9)
        assert reward == info["reward_attitude"] == -info["error_rad"]
        np.testing.assert_array_equal(info["q_wb_true"], q_true)


def test_euler_actions_mean_roll_pitch_yaw():
    env = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="euler", **SHORT)
    env.reset(seed=0)
    for _ in range(5):
        roll, pitch, yaw = euler_from_quat(_newest_q_wb(env.unwrapped))
        _, reward, *_ = env.step(np.array([roll, pitch, yaw]))
        assert reward == pytest.approx(0.0, abs=1e-7)
        _, reward, *_ = env.step(np.array([roll, pitch, yaw + 0.2]))
        assert reward == pytest.approx(-0.2, abs=1e-6)


def test_baseline_as_the_action_scores_the_baseline_error():
    env = gym.make("biso_cosim/AttitudeEstimation-v0", observe_baseline=True, **SHORT)
    obs, info = env.reset(seed=4)
    total, baseline_total = 0.0, 0.0
    while True:
        baseline_q = env.unwrapped.physical_observation()["baseline_q_wb"]
        obs, reward, terminated, truncated, info = env.step(baseline_q)
        # info is about the instant the action was judged: that of the previous observation
        np.testing.assert_array_equal(info["q_wb_baseline"], baseline_q)
        assert reward == -info["baseline_error_rad"]
        total += reward
        baseline_total -= info["baseline_error_rad"]
        if terminated or truncated:
            break
    assert total == baseline_total and total < 0.0


def _accel_mag_attitude(core, imu):
    """The accelerometer+magnetometer attitude of the newest IMU row (physical units)."""
    from biso_cosim.estimators import reference_attitude

    return reference_attitude(imu[-1:, 3:6], imu[-1:, 6:9], declination_rad=core.sim.earth.declination_rad)[0]


def _same_attitude(p, q, atol):
    assert min(np.abs(p - q).max(), np.abs(p + q).max()) < atol


def test_corrections_span_the_gyro_propagation_and_the_accel_mag_attitude():
    """With ``action_type="correction"`` the episode starts at the accelerometer+magnetometer
    attitude; the action's attitude is the prior (the previous estimate propagated with each
    new gyro sample, a plain reference here) turned by max(a, 0) times the innovation (with
    ``correction_time_constant_s=0``: gains of 1 turn all of it): zero (or negative) gains give
    the prior, gains of 1 the accelerometer+magnetometer attitude of the newest sample; the
    reward is minus its angle to the truth."""
    env = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", correction_time_constant_s=0.0,
                   episode_duration_s=3.0)
    env.reset(seed=3)
    core = env.unwrapped
    parts = core.physical_observation()
    _same_attitude(parts["prior_q_wb"], _accel_mag_attitude(core, parts["imu"]), 1e-12)
    assert parts["innovation"].tolist() == [0.0, 0.0, 0.0]
    dt = 1.0 / core.imu_rate_hz
    rng = np.random.default_rng(0)
    for i in range(40):
        parts = core.physical_observation()
        gains = (np.zeros(3), -rng.uniform(0.0, 1.0, 3), np.ones(3), rng.uniform(0.0, 1.0, 3))[i % 4]
        expected = quat_multiply(parts["prior_q_wb"], quat_from_rotvec(np.maximum(gains, 0.0) * parts["innovation"]))
        if i % 4 == 2:  # gains of 1: the accelerometer+magnetometer attitude of the newest sample
            _same_attitude(expected, _accel_mag_attitude(core, parts["imu"]), 1e-9)
        q_true = _newest_q_wb(core)
        _, reward, _, _, info = env.step(gains)
        assert reward == pytest.approx(-quat_angle_between(expected, q_true), abs=1e-9)
        after = core.physical_observation()
        prior = expected
        for omega in after["imu"][:, 0:3]:  # (every row is this step's at the default rates)
            prior = quat_multiply(prior, quat_from_rotvec(omega * dt))
        _same_attitude(after["prior_q_wb"], prior / np.linalg.norm(prior), 1e-12)
        innovation = quat_multiply(after["prior_q_wb"] * [1, -1, -1, -1], _accel_mag_attitude(core, after["imu"]))
        _same_attitude(quat_from_rotvec(after["innovation"]), innovation, 1e-9)


def test_the_zero_correction_beats_the_memoryless_attitude_and_full_correction_is_it():
    """The residual formulation is well posed: the zero action (the gyro propagation from the
    accelerometer+magnetometer attitude at the start) is a far better estimator than the
    memoryless accelerometer+magnetometer attitude, which is the action of gains 1 with
    ``correction_time_constant_s=0`` (and a constant action a complementary filter of that
    time constant, 1 s by default, between the two)."""
    from biso_cosim.envs.baselines import AccelMagAttitude

    absolute = gym.make("biso_cosim/AttitudeEstimation-v0", episode_duration_s=20.0)
    correcting = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", correction_time_constant_s=0.0,
                          episode_duration_s=20.0)
    default = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", episode_duration_s=20.0)
    memoryless = AccelMagAttitude(absolute)
    for seed in (1000, 1001):
        memoryless.reset()
        reference = run_episode(absolute, memoryless, seed)[0]
        full = run_episode(correcting, lambda o: np.ones(3), seed)[0]
        assert full == pytest.approx(reference, rel=1e-6)  # (the baseline sees float32)
        assert run_episode(correcting, lambda o: np.zeros(3), seed)[0] > 2.0 * reference  # (negative returns)
        filtered = run_episode(default, lambda o: np.ones(3), seed)[0]
        assert run_episode(default, lambda o: np.zeros(3), seed)[0] > filtered > reference


@pytest.mark.parametrize("a", [1.0, 0.0, -0.4, -1.0])
def test_log_scale_corrections_pull_with_their_time_constant(a):
    """``correction_scale="log"``: a constant action a pulls as the linear scale's gains of 1
    with the time constant τ · 1000^((1 − a)/2) (a = 1: τ; a = −1: 1000 τ)."""
    tau = 2.0
    log = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", correction_scale="log",
                   correction_time_constant_s=tau, **SHORT)
    linear = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction",
                      correction_time_constant_s=tau * 1000.0 ** (0.5 * (1.0 - a)), **SHORT)
    log.reset(seed=8)
    linear.reset(seed=8)
    for _ in range(40):
        _, reward, *_ = log.step(np.full(3, a))
        _, linear_reward, *_ = linear.step(np.ones(3))
        assert reward == pytest.approx(linear_reward, rel=1e-9)
    with pytest.raises(ValueError, match="correction_scale"):
        gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", correction_scale="square")
    with pytest.raises(ValueError, match="correction_time_constant_s > 0"):
        gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", correction_scale="log",
                 correction_time_constant_s=0.0)


def test_the_shaping_term_is_the_change_of_the_priors_potential():
    """``shaping_gamma``: the reward is ``reward_attitude`` plus γΦ(s') − Φ(s), Φ = −p/(1 − γ), p
    the prior's angle to the true attitude at the newest sample (``prior_error_rad``: checked
    against the observed prior and the next step's truth); the discounted sum of the shaping
    terms is then Φ's change over the episode, (p_0 − γ^T p_T)/(1 − γ), whatever the actions."""
    gamma = 0.9
    env = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", shaping_gamma=gamma, **SHORT)
    plain = gym.make("biso_cosim/AttitudeEstimation-v0", action_type="correction", **SHORT)
    core = env.unwrapped
    rng = np.random.default_rng(2)
    _, info = env.reset(seed=4)
    plain.reset(seed=4)
    first = p = info["prior_error_rad"]
    assert p == quat_angle_between(core.physical_observation()["prior_q_wb"], info["q_wb_true"])
    discounted, t = 0.0, 0
    while True:
        prior = core.physical_observation()["prior_q_wb"]
        assert p == quat_angle_between(prior, _newest_q_wb(core))
        action = rng.uniform(-0.5, 1.0, 3)
        _, reward, _, truncated, info = env.step(action)
        _, plain_reward, _, _, plain_info = plain.step(action)
        assert info["reward_attitude"] == plain_reward == plain_info["reward_attitude"]  # (the same task)
        shaping = info["reward_shaping"]
        assert reward == info["reward_attitude"] + shaping
        assert shaping == pytest.approx((p - gamma * info["prior_error_rad"]) / (1.0 - gamma), rel=1e-12)
        discounted += gamma ** t * shaping
        p, t = info["prior_error_rad"], t + 1
        if truncated:
            break
    assert discounted == pytest.approx((first - gamma ** t * p) / (1.0 - gamma), rel=1e-9)


@pytest.mark.parametrize(("kwargs", "message"), [({"shaping_gamma": 0.99}, "action_type"),
                                                 ({"action_type": "correction", "shaping_gamma": 1.0}, "< 1"),
                                                 ({"action_type": "correction", "shaping_gamma": float("nan")}, "finite"),
                                                 ({"action_type": "correction", "shaping_gamma": -0.5}, ">= 0")])
def test_bad_shaping_is_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("biso_cosim/AttitudeEstimation-v0", **kwargs)


@pytest.mark.parametrize(("control_rate_hz", "physics_rate_hz"), [(50.0, 1000.0), (80.0, 2000.0), (40.0, 1000.0)])
def test_observation_holds_the_sensor_stream_exactly(control_rate_hz, physics_rate_hz):
    """The IMU rows are the co-simulation's samples, newest last, with `new` marking the
    step's own; a BISO fed from the observation reproduces the baseline bit for bit."""
    kwargs = dict(control_rate_hz=control_rate_hz, physics_rate_hz=physics_rate_hz, episode_duration_s=1.0)
    env = gym.make("biso_cosim/AttitudeEstimation-v0", **kwargs)
    obs, info = env.reset(seed=6)
    core = env.unwrapped
    reference = CoSimulation("figure8", duration_s=2.0, seed=info["sensor_seed"], estimators=("biso",),
                             control_rate_hz=control_rate_hz, physics_rate_hz=physics_rate_hz,
                             sensor_profile=core.sim.imu.profile, gyro_calibration_s=core.sim.gyro_calibration_s)
    stream = []
    policy = make_estimator("biso", core.imu_rate_hz, declination_rad=core.sim.earth.declination_rad)
    slots = core.imu_slots
    assert slots == math.ceil(200.0 / control_rate_hz)
    while True:
        samples, _, _ = reference.step()
        stream.extend(np.column_stack([samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh]))
        imu = core.physical_observation()["imu"]
        new = imu[:, IMU_FIELDS.index("new")] == 1.0
        assert new.sum() == len(samples) and (not len(samples) or new[-1])
        expected = np.array(stream[-slots:])
        np.testing.assert_array_equal(imu[slots - len(expected):, :10], expected)
        q = policy.update(imu[new, 0:3], imu[new, 3:6], imu[new, 6:9]).q_wb[-1]
        obs, _, _, truncated, info = env.step(q)
        assert info["error_rad"] == info["baseline_error_rad"]  # the policy is the baseline
        if truncated:
            break


def test_gnss_part_holds_the_receivers_newest_fix():
    """The observed fix is the one a receiver with the episode's GNSS seed delivers from the
    truth at the IMU samples; an ideal receiver reports the truth at the fix's epoch."""
    from biso_cosim.envs._common import GNSS_FIELDS
    from biso_cosim.sensors.gnss import GnssReceiver

    for profile in ("consumer", "ideal"):
        env = gym.make("biso_cosim/AttitudeEstimation-v0", gnss_rate_hz=5.0, gnss_profile=profile,
                       episode_duration_s=2.0)
        core = env.unwrapped
        periods = capture_periods(core)
        obs, info = env.reset(seed=8)
        receiver = GnssReceiver(profile, seed=info["gnss_seed"], rate_hz=5.0, site=core.route.site,
                                input_rate_hz=core.imu_rate_hz)
        delivered = 0
        while True:
            truth = periods[-1][1]
            fixes = receiver.simulate(truth.pos_w, truth.vel_w)
            gnss = dict(zip(GNSS_FIELDS, core.physical_observation()["gnss"]))
            assert gnss["new"] == float(len(fixes) > 0)
            if len(fixes):
                delivered += 1
                assert gnss["valid"] == 1.0
                np.testing.assert_array_equal([gnss["pos_e"], gnss["pos_n"], gnss["pos_u"]], fixes.pos_w[-1])
                np.testing.assert_array_equal([gnss["vel_e"], gnss["vel_n"], gnss["vel_u"]], fixes.vel_w[-1])
                assert gnss["age_s"] == pytest.approx(truth.t_s[-1] - fixes.t_s[-1], abs=1e-12)
                if profile == "ideal":  # no errors, no latency: the truth at the epoch
                    at = np.flatnonzero(np.isclose(truth.t_s, fixes.t_s[-1], atol=1e-9))
                    np.testing.assert_allclose(fixes.pos_w[-1], truth.pos_w[at[0]], atol=1e-9)
            obs, _, _, truncated, info = env.step(np.array([1.0, 0.0, 0.0, 0.0]))
            if truncated:
                break
        assert delivered == 10  # 5 Hz over 2 s


# --------------------------------------------------------------------------------------
# GainTuning
# --------------------------------------------------------------------------------------


def test_gain_mapping_round_trips_and_hits_the_ends():
    env = gym.make("biso_cosim/GainTuning-v0", **SHORT).unwrapped
    assert env.params_from_action(np.array([-1.0, -1.0])) == {"cutoff_hz": 0.001, CROSS_LINK_RATIO: 0.0}
    top = env.params_from_action(np.array([1.0, 1.0]))
    assert top["cutoff_hz"] == pytest.approx(20.0, rel=1e-12) and top[CROSS_LINK_RATIO] == 2.0
    middle = env.params_from_action(np.zeros(2))
    assert middle["cutoff_hz"] == pytest.approx(math.sqrt(0.001 * 20.0), rel=1e-12)  # log scale
    values = {"cutoff_hz": 0.37, CROSS_LINK_RATIO: 0.6}
    back = env.params_from_action(env.action_from_params(**values))
    assert back == pytest.approx(values, rel=1e-12)
    with pytest.raises(ValueError, match="cutoff_hz"):
        env.action_from_params(cutoff_hz=50.0, cross_link_ratio=1.0)
    # the observed gains at reset are the paper's: f_c = k√2/(2π), r = √3 k_p/k
    obs, info = env.reset(seed=0)
    assert info["params"]["cutoff_hz"] == pytest.approx(PAPER_K * math.sqrt(2.0) / (2.0 * math.pi), rel=1e-12)
    assert info["params"][CROSS_LINK_RATIO] == pytest.approx(math.sqrt(3.0) * PAPER_K_P / PAPER_K, rel=1e-12)
    gains = env.physical_observation()["gains"]
    np.testing.assert_allclose(gains, env.action_from_params(cutoff_hz=info["params"]["cutoff_hz"],
                                                             cross_link_ratio=info["params"][CROSS_LINK_RATIO]))
    assert (info["params"]["k"], info["params"]["k_p"]) == (PAPER_K, PAPER_K_P)
    _, _, _, _, info = env.step(gains)  # the gains in force: nothing to change
    assert (info["params"]["k"], info["params"]["k_p"]) == (PAPER_K, PAPER_K_P)


@pytest.mark.parametrize(("env_id", "name"), [("biso_cosim/AttitudeEstimation-v0", "correction_time_constant_s"),
                                              ("biso_cosim/GainTuning-v0", "gain_time_constant_s")])
@pytest.mark.parametrize("value", [-1.0, float("nan"), "1 s", True])
def test_bad_time_constants_are_refused(env_id, name, value):
    with pytest.raises((ValueError, TypeError), match=name):
        gym.make(env_id, **{name: value})


def test_gains_follow_the_actions_with_their_lag():
    """The episode's first action sets the gains; each later one moves the gains in force
    (normalised) by 1 − exp(−dt/τ) of the way towards it; the values in force are theirs."""
    env = gym.make("biso_cosim/GainTuning-v0", episode_duration_s=2.0, gain_time_constant_s=0.5)
    core = env.unwrapped
    alpha = 1.0 - math.exp(-core.dt / 0.5)
    rng = np.random.default_rng(1)
    for seed in (2, 3):
        env.reset(seed=seed)
        gains = rng.uniform(-1.0, 1.0, 2)
        _, _, _, _, info = env.step(gains)  # the first action: the gains at once
        for i in range(30):
            np.testing.assert_allclose(core.physical_observation()["gains"], gains, rtol=0, atol=1e-15)
            values = core.params_from_action(gains)
            assert info["params"]["cutoff_hz"] == pytest.approx(values["cutoff_hz"], rel=1e-14)
            assert info["params"][CROSS_LINK_RATIO] == pytest.approx(values[CROSS_LINK_RATIO], rel=1e-14, abs=1e-15)
            action = rng.uniform(-1.0, 1.0, 2) if i % 10 else gains  # (a repeated action: the gains stay)
            _, _, _, _, info = env.step(action)
            gains = gains + alpha * (action - gains)


def test_tuned_estimator_equals_a_standalone_one_retuned_at_the_same_instants():
    env = gym.make("biso_cosim/GainTuning-v0", episode_duration_s=2.0, gain_time_constant_s=0.0)
    obs, info = env.reset(seed=2)
    core = env.unwrapped
    standalone = make_estimator("biso", core.imu_rate_hz, declination_rad=core.sim.earth.declination_rad)
    rng = np.random.default_rng(0)
    imu = core.physical_observation()["imu"]
    standalone.update(imu[:, 0:3], imu[:, 3:6], imu[:, 6:9])  # the reset period, paper gains
    step = 0
    while True:
        if step % 20 == 0:  # a new gain every 20 steps
            action = rng.uniform(-1.0, 1.0, 2)
            values = core.params_from_action(action)
            k, kp = gains_from_cutoff(values["cutoff_hz"])  # k = ω_n/√2, k_p = r·ω_n/√6
            standalone.set_params(k=k, k_p=values[CROSS_LINK_RATIO] * kp)
        obs, reward, _, truncated, info = env.step(action)
        imu = core.physical_observation()["imu"]
        q = standalone.update(imu[:, 0:3], imu[:, 3:6], imu[:, 6:9]).q_wb
        np.testing.assert_array_equal(info["q_wb_tuned"], q[-1])
        assert info["params"] == {**values, "k": k, "k_p": values[CROSS_LINK_RATIO] * kp}  # what the action set
        assert core.sim.estimators["tuned"].params.k == k
        step += 1
        if truncated:
            break


def test_gain_tuning_reward_is_the_mean_error_over_the_step():
    env = gym.make("biso_cosim/GainTuning-v0", **SHORT)
    env.reset(seed=1)
    periods = capture_periods(env.unwrapped)
    for _ in range(10):
        _, reward, _, _, info = env.step(np.array([0.3, -0.2]))
        _, truth, outputs = periods[-1]
        tuned = outputs["tuned"].q_wb
        total = 0.0
        for angle in quat_angle_between(tuned, truth.q_wb):
            total += angle
        assert reward == -total / len(tuned) == info["reward_attitude"] == -info["error_rad"]


def test_the_reference_copy_is_the_tuned_copy_under_the_reference_action():
    """``reference_action``: a third copy runs the constant gains of that action from the
    episode's first step (before it, as the tuned copy, the baseline's), and its mean error over
    each step joins the reward (``reward_reference``): a policy that plays the reference action
    earns exactly 0 every step and the task's measure of it; any other earns the difference."""
    reference = np.array([0.25, -0.5])
    env = gym.make("biso_cosim/GainTuning-v0", reference_action=reference, **SHORT)
    plain = gym.make("biso_cosim/GainTuning-v0", **SHORT)
    for actions in ([reference] * 30, np.random.default_rng(0).uniform(-1.0, 1.0, (30, 2))):
        env.reset(seed=6)
        plain.reset(seed=6)
        for i, action in enumerate(actions):
            _, reward, _, _, info = env.step(action)
            _, plain_reward, _, _, plain_info = plain.step(action)
            assert info["reward_attitude"] == plain_reward == -info["error_rad"]  # (the same task)
            assert reward == info["reward_attitude"] + info["reward_reference"]
            assert info["reward_reference"] == info["reference_error_rad"] > 0.0
            if actions[0] is reference:
                assert reward == 0.0
            elif i > 0:
                assert reward != 0.0


def test_gain_tuning_shaping_is_the_change_of_the_relative_errors_potential():
    """``shaping_gamma`` in GainTuning: the reward is the task's term, the reference copy's and
    γΦ(s') − Φ(s), Φ = −(the tuned copy's angle to the truth at the newest sample, less the
    reference copy's)/(1 − γ) (``potential_error_rad``: checked against both copies' newest
    estimates); its discounted sum is Φ's change over the episode."""
    gamma = 0.95
    env = gym.make("biso_cosim/GainTuning-v0", reference_action=(0.0, 0.0), shaping_gamma=gamma, **SHORT)
    core = env.unwrapped
    _, info = env.reset(seed=5)
    first = p = info["potential_error_rad"]
    rng = np.random.default_rng(1)
    discounted, t = 0.0, 0
    while True:
        _, reward, _, truncated, info = env.step(rng.uniform(-1.0, 1.0, 2))
        reference_q = core.sim.estimators["reference"].get_state().q_wb
        newest = quat_angle_between(info["q_wb_tuned"], info["q_wb_true"])
        assert info["potential_error_rad"] == pytest.approx(
            newest - quat_angle_between(reference_q, info["q_wb_true"]), abs=1e-12)
        assert reward == info["reward_attitude"] + info["reward_reference"] + info["reward_shaping"]
        assert info["reward_shaping"] == pytest.approx((p - gamma * info["potential_error_rad"]) / (1.0 - gamma),
                                                       rel=1e-12, abs=1e-15)
        discounted += gamma ** t * info["reward_shaping"]
        p, t = info["potential_error_rad"], t + 1
        if truncated:
            break
    assert discounted == pytest.approx((first - gamma ** t * p) / (1.0 - gamma), rel=1e-9, abs=1e-12)
    with pytest.raises(ValueError, match="shaping_gamma"):
        gym.make("biso_cosim/GainTuning-v0", shaping_gamma=1.0)


@pytest.mark.parametrize("value", [(0.0,), (0.0, 1.5), (float("nan"), 0.0), "0 0"])
def test_bad_reference_actions_are_refused(value):
    with pytest.raises(ValueError, match="reference_action"):
        gym.make("biso_cosim/GainTuning-v0", reference_action=value)


def test_the_attitude_can_be_left_out_of_the_observation():
    """``observe_attitude=False``: the observation is the default one without the tuned
    estimate's attitude (the same columns otherwise, the same episode)."""
    full = gym.make("biso_cosim/GainTuning-v0", **SHORT)
    without = gym.make("biso_cosim/GainTuning-v0", observe_attitude=False, **SHORT)
    assert "q_wb" not in without.unwrapped.observation_structure
    kept = [i for i, f in enumerate(full.unwrapped.observation_fields) if not f.startswith("q_wb.")]
    assert [full.unwrapped.observation_fields[i] for i in kept] == list(without.unwrapped.observation_fields)
    assert len(kept) == len(full.unwrapped.observation_fields) - 4
    for a, b in zip(rollout_observations(full), rollout_observations(without)):
        assert a[kept].tolist() == b.tolist()
    with pytest.raises(TypeError, match="observe_attitude"):
        gym.make("biso_cosim/GainTuning-v0", observe_attitude="no")


def test_the_imu_samples_can_be_left_out_of_the_observation():
    """``observe_imu=False``: the observation is the default one without the IMU window's
    columns (the same columns otherwise, the same episode)."""
    full = gym.make("biso_cosim/GainTuning-v0", **SHORT)
    without = gym.make("biso_cosim/GainTuning-v0", observe_imu=False, **SHORT)
    assert without.unwrapped.observation_structure["imu"][-1] == 0
    kept = [i for i, f in enumerate(full.unwrapped.observation_fields) if not f.startswith("imu[")]
    assert [full.unwrapped.observation_fields[i] for i in kept] == list(without.unwrapped.observation_fields)
    assert len(kept) == len(full.unwrapped.observation_fields) - 9 * full.unwrapped.imu_slots
    for a, b in zip(rollout_observations(full), rollout_observations(without)):
        assert a[kept].tolist() == b.tolist()
    with pytest.raises(ValueError, match="observe_imu"):
        gym.make("biso_cosim/GainTuning-v0", observe_imu="no")


def test_innovation_statistics_average_the_rotation_from_the_tuned_to_the_baseline_estimate():
    """``innovation_time_constant_s=T``: the observation's ``innovation`` is the moving average,
    weight 1 − exp(−dt/T) a step and 1 at the first, of the rotation vector d from the tuned
    copy's attitude to the baseline copy's at the newest sample (``info``'s q_wb_tuned and
    q_wb_baseline; tuned body axes), and the root of the average of |d|²."""
    from scipy.spatial.transform import Rotation

    def rotvec(info):
        tuned, baseline = (Rotation.from_quat(np.roll(info[k], -1)) for k in ("q_wb_tuned", "q_wb_baseline"))
        return (tuned.inv() * baseline).as_rotvec()

    tau = 0.3
    env = gym.make("biso_cosim/GainTuning-v0", innovation_time_constant_s=tau, **SHORT)
    core = env.unwrapped
    weight = 1.0 - math.exp(-core.dt / tau)
    rng = np.random.default_rng(2)
    obs, info = env.reset(seed=3)
    d = rotvec(info)
    mean, square = d, d @ d
    largest = 0.0
    while True:
        part = core.split_observation(obs)["innovation"]
        np.testing.assert_allclose(part[:3], mean, rtol=1e-5, atol=1e-7)  # (float32)
        assert part[3] == pytest.approx(math.sqrt(square), rel=1e-5, abs=1e-7)
        largest = max(largest, part[3])
        obs, _, _, truncated, info = env.step(rng.uniform(-1.0, 1.0, 2))
        d = rotvec(info)
        mean, square = mean + weight * (d - mean), square + weight * (d @ d - square)
        if truncated:
            break
    assert largest > 1e-3  # (random gains: the copies part)


def test_innovation_statistics_are_zero_when_the_tuned_copy_has_the_baselines_gains():
    """The tuned copy at the baseline's gains (the paper's, as a constant action) is the
    baseline copy: the rotation between them, and so its statistics, are 0."""
    env = gym.make("biso_cosim/GainTuning-v0", innovation_time_constant_s=1.0, **SHORT)
    core = env.unwrapped
    paper = core.baseline_action.astype(np.float32)
    env.reset(seed=4)
    while True:
        obs, _, _, truncated, info = env.step(paper)
        assert quat_angle_between(info["q_wb_tuned"], info["q_wb_baseline"]) < 1e-9
        np.testing.assert_allclose(core.split_observation(obs)["innovation"], 0.0, atol=1e-8)
        if truncated:
            break


def test_the_training_observation_passes_check_env():
    """GainTuning's observation of the trained baselines (``biso_cosim.envs.training``): the
    gains in force and the innovation statistics only."""
    from gymnasium.utils.env_checker import check_env

    from biso_cosim.envs.training import env_options

    env = gym.make("biso_cosim/GainTuning-v0", **{**env_options("GainTuning"), **SHORT})
    assert list(env.unwrapped.observation_structure) == ["imu", "innovation", "gains"]
    assert env.observation_space.shape == (6,)
    check_env(env.unwrapped, skip_render_check=True)


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_innovation_time_constants_are_refused(value):
    with pytest.raises(ValueError, match="innovation_time_constant_s"):
        gym.make("biso_cosim/GainTuning-v0", innovation_time_constant_s=value)


def rollout_observations(env, steps=20):
    env.action_space.seed(0)
    obs, _ = env.reset(seed=7)
    out = [obs]
    for _ in range(steps):
        out.append(env.step(env.action_space.sample())[0])
    return out


def test_die_temperature_moves_the_gyro_bias_by_the_parts_tempco():
    """At rest, the same part at 45 °C and at 25 °C (the reference) differs in its gyro output
    by the drawn bias tempco × 20 °C, rotated from the chip's axes into the body's (the
    kernel's bias + bias_tc·(T − T_ref), biso_cosim/sensors/_kernels.py), to the register's LSB."""
    gyro = {}
    for temperature in (25.0, 45.0):
        env = gym.make("biso_cosim/GainTuning-v0", route="figure8", sensor_noise=False, sensor_seed=7,
                       die_temperature_c=temperature, **SHORT).unwrapped
        _, info = env.reset(seed=0)
        assert info["die_temperature_c"] == temperature
        gyro[temperature] = env.physical_observation()["imu"][:, 0:3].copy()
    imu = env.sim.imu
    expected = imu.r_bc @ (imu.errors.gyro.bias_tempco * 20.0)  # rad/s, body axes
    lsb = 1.0 / imu.registers.gyro_lsb_per_unit  # rad/s
    assert np.max(np.abs(expected)) > 20.0 * lsb  # (a part whose drift the registers resolve)
    np.testing.assert_allclose(gyro[45.0] - gyro[25.0], np.broadcast_to(expected, gyro[45.0].shape), atol=2.0 * lsb)


def test_die_temperature_is_drawn_per_episode_from_the_sensor_seed():
    env = gym.make("biso_cosim/GainTuning-v0", route="figure8", die_temperature_c=(5.0, 45.0), **SHORT).unwrapped
    temperatures = [env.reset(seed=seed)[1]["die_temperature_c"] for seed in (0, 1, 2, 0)]
    assert all(5.0 <= t <= 45.0 for t in temperatures) and len(set(temperatures[:3])) == 3
    assert temperatures[3] == temperatures[0]  # reproducible under the seed
    _, info = env.reset(seed=1)
    assert info["die_temperature_c"] == env.episode_temperature_c(info["sensor_seed"])
    assert env.sim.imu.profile.si("temperature.default") == info["die_temperature_c"]
    fixed = gym.make("biso_cosim/GainTuning-v0", die_temperature_c=None, **SHORT)
    assert fixed.reset(seed=0)[1]["die_temperature_c"] == 25.0  # the profile's default


@pytest.mark.parametrize("value", [(45.0, 5.0), (-50.0, 20.0), 90.0, float("nan"), "warm", (1.0, 2.0, 3.0), True])
def test_bad_die_temperature_is_refused(value):
    with pytest.raises(ValueError, match="die_temperature_c must be"):
        gym.make("biso_cosim/GainTuning-v0", die_temperature_c=value)


@pytest.mark.parametrize(("tuning", "message"), [
    ({"k_magic": (0.1, 1.0, "log")}, "no parameter"),
    ({"cutoff_hz": (0.0, 1.0, "log")}, "low > 0"),
    ({"cutoff_hz": (2.0, 1.0, "linear")}, "low < high"),
    ({CROSS_LINK_RATIO: (0.0, 1.0, "linear")}, "needs 'cutoff_hz'"),
    ({"k_tilt": (0.1, 1.0, "log")}, "no parameter"),  # a biso_plus parameter
])
def test_bad_tuning_is_refused(tuning, message):
    with pytest.raises(ValueError, match=message):
        gym.make("biso_cosim/GainTuning-v0", tuning=tuning)


def test_a_tuning_box_with_unstable_corners_is_refused():
    # k = 0 with k_p > 0 has poles ±i√3k_p: not asymptotically stable, refused by the estimator
    with pytest.raises(ValueError, match="not a valid"):
        gym.make("biso_cosim/GainTuning-v0", tuning={"k": (0.0, 10.0, "linear")})
    env = gym.make("biso_cosim/GainTuning-v0", tuning={"k": (1.0, 100.0, "log"), "k_p": (0.0, 50.0, "linear")})
    assert env.reset(seed=0)[1]["params"] == {"k": PAPER_K, "k_p": PAPER_K_P}


# --------------------------------------------------------------------------------------
# Driving
# --------------------------------------------------------------------------------------


def pursue(env, obs, point=3, speed_mps=6.0):
    """Pure pursuit on the observed route ahead, speed from the undriven front wheels."""
    p = env.unwrapped.split_observation(obs)
    x, y = p["route_ahead"][point]
    steer = math.atan(2.0 * 2.7 * math.sin(math.atan2(y, x)) / max(math.hypot(x, y), 1e-3)) / 0.6
    v = p["wheel_speed_mps"][:2].mean()
    return np.clip([0.5 * (speed_mps - v), steer], -1.0, 1.0)


def test_route_ahead_at_the_start_lies_along_the_road():
    env = gym.make("biso_cosim/Driving-v0", route=straight_route(), pose_source="truth", preview_spacing_m=3.0)
    obs, info = env.reset(seed=0)
    ahead = env.unwrapped.split_observation(obs)["route_ahead"]
    np.testing.assert_allclose(ahead[:, 0], 3.0 * np.arange(1, 11), atol=0.3)  # the sampling step is 0.25 m
    np.testing.assert_allclose(ahead[:, 1], 0.0, atol=0.02)


def test_driving_the_route_earns_its_length():
    route = straight_route(60.0)
    env = gym.make("biso_cosim/Driving-v0", route=route, pose_source="truth")
    obs, info = env.reset(seed=0)
    terms = dict.fromkeys(env.unwrapped.REWARD_TERMS, 0.0)
    while True:
        obs, reward, terminated, truncated, info = env.step(pursue(env, obs))
        parts = [info[t] for t in env.unwrapped.REWARD_TERMS]
        assert reward == sum(parts)  # exactly: the same sum in the same order
        for t in terms:
            terms[t] += info[t]
        if terminated or truncated:
            break
    assert terminated and info["finished"] and not info["off_route"]
    assert terms["reward_progress"] == pytest.approx(route.path.length_m, abs=1.5)
    # on the centre line within centimetres: a few hundredths of the progress lost
    assert -0.02 * route.path.length_m < terms["reward_cross_track"] <= 0.0
    assert terms["reward_rollover"] == terms["reward_off_route"] == 0.0


def test_the_cross_track_term_is_the_fraction_of_the_progress_lost_off_centre():
    """reward_cross_track = -max(Δs', 0) × min(|e| / max_cross_track_m, 1) for the default
    weights (Δs' the credited progress): never larger than the step's progress, zero when the
    car does not progress."""
    env = gym.make("biso_cosim/Driving-v0", route=straight_route(200.0), max_cross_track_m=3.0)
    _, info = env.reset(seed=0)
    before, seen = info["distance_m"], 0
    while True:  # drift off to the left until the road ends
        _, reward, terminated, truncated, info = env.step(np.array([0.3, 0.08]))
        gained = info["distance_m"] - before
        before = info["distance_m"]
        allowed = info["speed_limit_mps"] * env.unwrapped.dt
        credited = min(gained, allowed) - max(gained - allowed, 0.0)
        assert info["reward_progress"] == credited
        expected = -max(credited, 0.0) * min(abs(info["cross_track_m"]) / 3.0, 1.0)
        assert info["reward_cross_track"] == pytest.approx(expected, rel=1e-12, abs=1e-15)
        assert abs(info["reward_cross_track"]) <= max(info["reward_progress"], 0.0)
        seen += abs(info["cross_track_m"]) > 1.5 and gained > 0.0
        if terminated or truncated:
            break
    assert terminated and info["off_route"] and seen > 10  # (far off centre for a while before the edge)


@pytest.mark.parametrize("overspeed", [0.0, 1.0])
def test_progress_is_credited_up_to_the_speed_limit(overspeed):
    """reward_progress = min(Δs, L) − w_o·max(Δs − L, 0), L = v_lim·dt: a car faster than the
    limit earns the limit's progress less w_o times its excess (w_o = overspeed_weight); without
    a limit every metre counts."""
    for limit in (4.0, None):
        env = gym.make("biso_cosim/Driving-v0", route=straight_route(200.0), pose_source="truth",
                       speed_limit_mps=limit, overspeed_weight=overspeed)
        obs, info = env.reset(seed=0)
        dt = env.unwrapped.dt
        before, capped, doubled = info["distance_m"], 0, 0
        while True:
            obs, reward, terminated, truncated, info = env.step(pursue(env, obs, speed_mps=9.0))
            gained = info["distance_m"] - before
            before = info["distance_m"]
            if limit is None:
                assert info["speed_limit_mps"] == math.inf and info["reward_progress"] == gained
            else:
                assert info["speed_limit_mps"] <= limit
                allowed = info["speed_limit_mps"] * dt
                assert info["reward_progress"] == min(gained, allowed) - overspeed * max(gained - allowed, 0.0)
                capped += gained > limit * dt
                if gained > 2.0 * allowed:  # (beyond twice the limit's progress a step loses)
                    assert (info["reward_progress"] < 0.0) == (overspeed == 1.0)
                    doubled += 1
            assert reward == sum(info[t] for t in env.unwrapped.REWARD_TERMS)
            if terminated or truncated:
                break
        assert info["finished"]
        if limit is not None:
            assert capped > 2.0 / dt and doubled > 1.0 / dt  # (driven at 9 m/s for most of 200 m: over twice the limit for seconds)


def test_speed_limits_slow_for_turns_and_brake_before_them():
    """v_lim(s_i) = min over the samples j ≥ i of √(v_j² + 2·a·(s_j − s_i)), v_j the smaller of
    speed_limit_mps and √(a/|κ_j|): the backward pass against the definition, and the slowest
    turn of figure8 (25 m radius) at √(a·25 m)."""
    from biso_cosim.routes.path import curvature_speed_limit

    a = 2.0
    env = gym.make("biso_cosim/Driving-v0", route="figure8", speed_limit_mps=12.0, speed_limit_accel_mps2=a)
    env.reset(seed=0)
    core = env.unwrapped
    path = core.route.path
    limits = core.speed_limits_mps()
    base = np.minimum(curvature_speed_limit(path, a), 12.0)
    s = path.s_m
    reference = np.array([np.min(np.sqrt(base[i:] ** 2 + 2.0 * a * (s[i:] - s[i]))) for i in range(len(s))])
    np.testing.assert_allclose(limits, reference, rtol=1e-12)
    assert limits.min() == pytest.approx(math.sqrt(a * 25.0), rel=0.02) and limits.max() == 12.0
    assert np.all(limits[:-1] ** 2 <= limits[1:] ** 2 + 2.0 * a * np.diff(s) + 1e-9)


def test_standing_still_earns_nothing_and_the_stalled_episode_is_truncated():
    env = gym.make("biso_cosim/Driving-v0", route=straight_route(200.0), stall_s=2.0)
    env.reset(seed=0)
    steps, moved = 0, 0.0
    while True:
        _, reward, terminated, truncated, info = env.step(np.array([-1.0, 0.3]))  # braked, wheel turned
        steps += 1
        moved += abs(info["reward_progress"])
        assert abs(info["reward_cross_track"]) <= max(info["reward_progress"], 0.0)
        if terminated or truncated:
            break
    assert truncated and not terminated and info["stalled"] and steps == round(2.0 / env.unwrapped.dt)
    # the braked car settles on its tyres' deflection by micrometres: all the stand's reward within
    # the 0.1 mm a parked car on the slip-based tyres may creep in 10 s (tests/test_tyres.py)
    assert moved < 1e-4


def test_a_car_that_drives_is_never_stalled():
    env = gym.make("biso_cosim/Driving-v0", route=straight_route(60.0), pose_source="truth", stall_s=1.0)
    obs, _ = env.reset(seed=0)
    while True:
        obs, reward, terminated, truncated, info = env.step(pursue(env, obs))
        if terminated or truncated:
            break
    assert terminated and info["finished"] and not info["stalled"]


@pytest.mark.parametrize(("arguments", "message"), [
    ({"cross_track_weight": 1.5}, "cross_track_weight"), ({"cross_track_weight": -0.1}, "cross_track_weight"),
    ({"stall_s": 0.0}, "stall_s"), ({"stall_s": -1.0}, "stall_s"), ({"speed_limit_mps": 0.0}, "speed_limit_mps"),
    ({"speed_limit_mps": float("inf")}, "speed_limit_mps"), ({"speed_limit_accel_mps2": -1.0}, "speed_limit_accel_mps2"),
    ({"overspeed_weight": 1.5}, "overspeed_weight")])
def test_bad_reward_settings_are_refused(arguments, message):
    with pytest.raises(ValueError, match=message):
        gym.make("biso_cosim/Driving-v0", **arguments)


def test_leaving_the_road_ends_the_episode_with_its_penalty():
    env = gym.make("biso_cosim/Driving-v0", route=straight_route(200.0), max_cross_track_m=3.0,
                   off_route_penalty=42.0)
    env.reset(seed=0)
    while True:
        _, reward, terminated, truncated, info = env.step(np.array([0.6, 1.0]))  # full left lock
        if terminated or truncated:
            break
    assert terminated and info["off_route"] and abs(info["cross_track_m"]) > 3.0
    assert info["reward_off_route"] == -42.0 and info["reward_rollover"] == 0.0
    assert reward == sum(info[t] for t in env.unwrapped.REWARD_TERMS)


def test_dead_reckoning_matches_a_plain_reference():
    """Straight ahead (steering 0): the navigation pose is the sum over the samples of
    speed(front wheels) × horizontal forward axis of the estimate / ODR."""
    env = gym.make("biso_cosim/Driving-v0", route=straight_route(), episode_duration_s=4.0)
    obs, info = env.reset(seed=3)
    core = env.unwrapped
    start = info["true_pose"][:2].copy()
    periods = capture_periods(core)
    while True:
        obs, _, terminated, truncated, info = env.step(np.array([0.4, 0.0]))
        if terminated or truncated:
            break
    q = np.concatenate([outputs["estimator"].q_wb for _, _, outputs in periods])
    wheel_rates = np.concatenate([truth.wheel_rates for _, truth, _ in periods])
    radius = core.sim.vehicle.index.wheel_radius_m
    x, y = start
    for i in range(len(q)):
        w, qx, qy, qz = q[i]
        v = 0.5 * (wheel_rates[i, 0] + wheel_rates[i, 1]) * radius
        x += v * (1.0 - 2.0 * (qy * qy + qz * qz)) / core.imu_rate_hz
        y += v * 2.0 * (qx * qy + w * qz) / core.imu_rate_hz
    np.testing.assert_allclose(info["nav_pose"][:2], [x, y], rtol=0, atol=1e-6)  # summation order, cos(steering ≈ 0)
    assert info["true_pose"][0] > 5.0  # it did drive


# --------------------------------------------------------------------------------------
# Procedural routes
# --------------------------------------------------------------------------------------


def test_random_routes_are_reproducible_closed_and_varied():
    a, b = random_route(21), random_route(21)
    assert a.waypoints == b.waypoints and a.name == "random-21"
    assert random_route(22).waypoints != a.waypoints
    headings = []
    for seed in range(12):
        route = random_route(seed, stops=2, hills=1)
        assert route.closed and route.start_xy_yaw[:2] == (0.0, 0.0)
        assert len(route.stops) == 3 and len(route.terrain.features) == 1
        assert 5 + 1 <= len(route.waypoints) <= 8 + 1
        turns = np.diff(np.unwrap(route.path.heading_rad))
        assert abs(turns.sum()) == pytest.approx(2.0 * math.pi, abs=0.05)  # one loop, no crossing
        headings.append(route.start_xy_yaw[2])
    # start headings spread over the circle
    assert np.ptp(np.mod(headings, 2.0 * math.pi)) > math.pi


@pytest.mark.parametrize(("options", "message"), [
    ({"corners": (3, 5)}, "corners"),
    ({"size_m": (100.0, 50.0)}, "low <= high"),
    ({"hills": -1}, "hills"),
    ({"stops": 9}, "stops"),
    ({"bridges": 1}, "unknown option"),
])
def test_random_route_options_are_checked(options, message):
    with pytest.raises(ValueError, match=message):
        random_route(0, **options)


@pytest.mark.slow
def test_scripted_driver_completes_random_routes():
    from biso_cosim.cosim import run_route

    for seed in range(3):
        result = run_route(random_route(seed, hills=1), seed=0, estimators=("biso",))
        assert result.completed and result.summary()["cross_track_rms_m"] < 0.5


# --------------------------------------------------------------------------------------
# Scripted baselines
# --------------------------------------------------------------------------------------

EVALUATION_SEEDS = range(1000, 1005)  # benchmarks/rl_baselines.py's


@pytest.mark.parametrize("control_rate_hz", [50.0, 10.0])  # the default, and the trained baselines'
def test_pursuit_baseline_completes_every_evaluation_seed_of_figure8(control_rate_hz):
    """With the default dead-reckoned pose (the estimator's errors steer the car)."""
    from biso_cosim.envs.baselines import PursuitDriver

    env = gym.make("biso_cosim/Driving-v0", control_rate_hz=control_rate_hz)
    policy = PursuitDriver(env)
    for seed in EVALUATION_SEEDS:
        total, info = run_episode(env, policy, seed)
        assert info["finished"] and not info["off_route"] and not info["rolled_over"], seed
        assert total > 0.8 * env.unwrapped.route.path.length_m  # progress dominates: 387 m of road


@pytest.mark.slow
def test_pursuit_baseline_completes_every_evaluation_seed_of_random_routes():
    from biso_cosim.envs.baselines import PursuitDriver

    env = gym.make("biso_cosim/Driving-v0", route="random")
    policy = PursuitDriver(env)
    for seed in EVALUATION_SEEDS:
        total, info = run_episode(env, policy, seed)
        assert info["finished"] and not info["off_route"] and not info["rolled_over"], seed


def test_the_fed_back_estimate_lets_a_policy_beat_the_memoryless_attitude():
    """A complementary filter that sees only the observation (its previous estimate, fed
    back, and the step's samples) halves the error of the accelerometer+magnetometer attitude."""
    from biso_cosim.envs.baselines import AccelMagAttitude, FeedbackFilter

    env = gym.make("biso_cosim/AttitudeEstimation-v0", episode_duration_s=20.0)
    returns = {}
    for name, policy in (("memoryless", AccelMagAttitude(env)), ("feedback", FeedbackFilter(env))):
        total = 0.0
        for seed in (1000, 1001):
            obs, info = env.reset(seed=seed)
            policy.reset()
            np.testing.assert_array_equal(env.unwrapped.split_observation(obs)["estimate_q_wb"], [1.0, 0, 0, 0])
            while True:
                action = policy(obs)
                obs, reward, terminated, truncated, info = env.step(action)
                total += reward
                fed_back = env.unwrapped.physical_observation()["estimate_q_wb"]
                q = np.asarray(action, dtype=np.float64)
                np.testing.assert_allclose(fed_back, q / np.linalg.norm(q) * np.sign(q[0]), atol=1e-12)
                if terminated or truncated:
                    break
        returns[name] = total
    assert returns["feedback"] > 0.6 * returns["memoryless"]  # (returns are negative: errors)


def test_gain_oracle_scores_constant_gains_as_the_environment_does():
    """The oracle's side-by-side copies score a constant action as the environment's
    tuned copy does (the mean over the samples; the environment leaves out the reset's period)."""
    from biso_cosim.envs.gain_oracle import episode_errors

    env = gym.make("biso_cosim/GainTuning-v0", episode_duration_s=20.0)
    actions = [np.array([-0.3, 0.0]), np.array([0.5, -0.5])]
    errors = episode_errors(env, 1000, actions)
    for action, error in zip(actions, errors):
        env.reset(seed=1000)
        step_errors = []
        while True:
            _, reward, _, truncated, info = env.step(action)
            step_errors.append(-reward)
            if truncated:
                break
        assert np.mean(step_errors) == pytest.approx(error, rel=0.02)


@pytest.mark.slow
def test_gain_oracle_lies_inside_the_range_and_beats_the_paper():
    from biso_cosim.envs.gain_oracle import episode_errors, oracle_action

    env = gym.make("biso_cosim/GainTuning-v0")
    for seed in (1000, 1001, 1002):
        best, error = oracle_action(env, seed)
        assert -1.0 < best[0] < 1.0, seed  # f_c inside its range
        assert error < episode_errors(env, seed, [env.unwrapped.baseline_action])[0]
