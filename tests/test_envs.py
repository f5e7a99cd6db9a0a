"""The Gymnasium environments against Gymnasium's own conventions: registration, check_env,
determinism under a seed, pickling, vector environments, resets, bad actions, rendering."""

import json
import math
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence

import biso_cosim.envs
from biso_cosim.envs import ENV_IDS
from biso_cosim.envs._common import ResetNeeded, _gl_context, _int_seed

SHORT = {"episode_duration_s": 1.5}  # 75 steps: enough for every check, quick to run

# Several argument sets per environment (check_env runs on each).
ARGUMENT_SETS = {
    "biso_cosim/AttitudeEstimation-v0": [
        {},
        {"action_type": "euler", "observe_baseline": True, "sensor_noise": False, "action_bounds": "raise"},
        {"route": "random", "random_route_options": {"stops": 0}, "sensor_profile": "ideal", "sensor_seed": 3,
         "gnss_rate_hz": 5.0},
        # rates that do not divide: 200 Hz ODR, 80 Hz steps (2 or 3 samples a step, 3 slots)
        {"control_rate_hz": 80.0, "physics_rate_hz": 2000.0},
        # the residual agent: corrections of its gyro-propagated estimate, with the shaping term
        {"action_type": "correction", "shaping_gamma": 0.99, "correction_scale": "log"},
    ],
    "biso_cosim/GainTuning-v0": [
        {},
        {"estimator": "biso_plus", "reference_action": (0.2, -0.3, 0.1), "shaping_gamma": 0.99},
        # (a 100 Hz ODR: 2 samples a step; the reference copy and no attitude in the observation)
        {"tuning": {"cutoff_hz": (0.02, 5.0, "log")}, "registers": {"smplrt_div": 9}, "reference_action": (0.5,),
         "observe_attitude": False},
    ],
    "biso_cosim/Driving-v0": [
        {},
        {"pose_source": "truth", "preview_points": 4, "estimator": "biso_plus", "control_rate_hz": 25.0,
         "gnss_rate_hz": 10.0, "gnss_profile": "ideal"},
        {"route": "random", "random_route_options": {"hills": 1}},
    ],
}
CASES = [(env_id, kwargs) for env_id, sets in ARGUMENT_SETS.items() for kwargs in sets]
CASE_IDS = [f"{env_id.split('/')[1]}-{i}" for env_id, sets in ARGUMENT_SETS.items() for i in range(len(sets))]


def gl_available() -> bool:
    try:
        _gl_context(8, 8).free()
        return True
    except RuntimeError:
        return False


def rollout(env, seed, steps, action_seed=0):
    """Observations, rewards, flags and infos of ``steps`` seeded random actions."""
    env.action_space.seed(action_seed)
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for _ in range(steps):
        step = env.step(env.action_space.sample())
        out.append(step)
        if step[2] or step[3]:
            break
    return out


def test_every_id_is_registered_and_lazy():
    assert set(ENV_IDS) <= set(gym.registry)
    # importing the package registers the ids but loads neither MuJoCo nor the env modules
    code = ("import sys, biso_cosim.envs, gymnasium as gym; "
            "print(int('mujoco' in sys.modules), int('biso_cosim.envs.driving' in sys.modules), "
            "int('biso_cosim/Driving-v0' in gym.registry))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["0", "0", "1"]


def test_make_with_module_prefix_in_a_fresh_process():
    """gym.make("biso_cosim:biso_cosim/<Name>-v0") without importing anything first."""
    code = ("import json, gymnasium as gym\n"
            "shapes = {}\n"
            f"for env_id in {list(ENV_IDS)!r}:\n"
            "    env = gym.make('biso_cosim:' + env_id, episode_duration_s=0.5)\n"
            "    obs, info = env.reset(seed=1)\n"
            "    obs, *_ = env.step(env.action_space.sample())\n"
            "    shapes[env_id] = list(obs.shape)\n"
            "print(json.dumps(shapes))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    # (importing biso_cosim must register the ids: biso_cosim/__init__.py imports biso_cosim.envs)
    assert run.returncode == 0, run.stderr[-2000:]
    shapes = json.loads(run.stdout.splitlines()[-1])
    # 4 IMU rows of 9 columns (`mag_fresh` and `new` are constant per row at 200 Hz / 50 Hz:
    # left out), then each task's parts
    assert shapes == {"biso_cosim/AttitudeEstimation-v0": [40], "biso_cosim/GainTuning-v0": [42],
                      "biso_cosim/Driving-v0": [67]}


@pytest.mark.parametrize(("env_id", "kwargs"), CASES, ids=CASE_IDS)
def test_check_env(env_id, kwargs):
    env = gym.make(env_id, **SHORT, **kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    # the only advice check_env may give: unbounded observations (as Gymnasium's MuJoCo envs),
    # and for Euler-angle actions a box in radians rather than [-1, 1]
    allowed = ("infinity",) + (("symmetric and normalized",) if kwargs.get("action_type") == "euler" else ())
    messages = [str(w.message) for w in caught]
    assert all(any(a in m for a in allowed) for m in messages), messages
    env.close()


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_check_env_with_rendering(env_id):
    if not gl_available():
        pytest.skip("no OpenGL backend (EGL, OSMesa or a display) on this machine")
    env = gym.make(env_id, render_mode="rgb_array", **SHORT)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env.unwrapped)
    env.close()


def test_rendered_frames_follow_the_car():
    if not gl_available():
        pytest.skip("no OpenGL backend (EGL, OSMesa or a display) on this machine")
    env = gym.make("biso_cosim/Driving-v0", render_mode="rgb_array", render_width=160, render_height=90, **SHORT)
    env.reset(seed=0)
    first = env.render()
    for _ in range(20):
        env.step(np.array([1.0, 0.5]))
    later = env.render()
    assert first.shape == later.shape == (90, 160, 3) and first.dtype == np.uint8
    assert first.std() > 5.0  # an image, not a blank buffer
    # the chase camera follows the car: the car stays in view while the ground moves past
    assert np.mean(np.abs(first.astype(int) - later.astype(int))) > 0.5
    env.close()
    env.close()  # closing twice is allowed


def test_rendered_frames_show_the_road_and_a_sky():
    """The asphalt (dark grey, the road's colour) under the car, a blue sky above the horizon."""
    if not gl_available():
        pytest.skip("no OpenGL backend (EGL, OSMesa or a display) on this machine")
    from biso_cosim.envs._render import ROAD_WIDTH_M, road_geoms

    env = gym.make("biso_cosim/Driving-v0", render_mode="rgb_array", render_width=160, render_height=90, **SHORT)
    env.reset(seed=0)
    frame = env.render().astype(int)
    top, bottom = frame[:5], frame[-10:]
    assert (top[..., 2] > top[..., 0] + 40).mean() > 0.9  # sky: blue over red
    asphalt = (np.abs(bottom - 46).max(axis=-1) < 12).mean()  # 0.18 grey, lit
    assert asphalt > 0.3, asphalt
    # the road follows the route: its boxes' centres lie on the centre line, at the terrain's height
    route = env.unwrapped.route
    geoms = road_geoms(route)
    centres = np.array([pos[:2] for _, pos, _, rgba in geoms if rgba[0] < 0.5])
    hint = int(np.argmin(np.hypot(route.path.x_m - centres[10][0], route.path.y_m - centres[10][1])))
    _, _, offset = route.path.locate(*centres[10], hint)
    assert abs(offset) < 0.1 and geoms[0][0][1] == pytest.approx(0.5 * ROAD_WIDTH_M)
    env.close()


def test_human_viewer_scene_has_the_road_and_a_sky():
    """The interactive viewer's extra scene (its ``user_scn``, filled by ``decorate_scene``):
    the rgb_array frames' road, and a sky of boxes that encloses the route inside the far
    plane. Rendered offscreen from the chase camera (no window), the frame has no background
    left: the sky covers it, in the sky's colours (blue over red)."""
    import mujoco

    from biso_cosim.envs._render import SKY_EMISSION, decorate_scene, road_geoms, sky_geoms

    env = gym.make("biso_cosim/Driving-v0", route="random", **SHORT)
    env.reset(seed=0)
    core = env.unwrapped
    model, route = core.sim.vehicle.model, core.route
    scene = mujoco.MjvScene(model, maxgeom=10000)  # (the viewer's: mujoco.viewer.launch_passive)
    decorate_scene(scene, route, model)
    far_m = float(model.vis.map.zfar * model.stat.extent)
    road, sky = road_geoms(route), sky_geoms(route, far_m)
    assert scene.ngeom == len(road) + len(sky)
    for i, (size, pos, _, rgba) in enumerate(road + sky):
        geom = scene.geoms[i]
        np.testing.assert_allclose(geom.pos, pos, rtol=1e-6)
        np.testing.assert_allclose(geom.rgba, rgba, rtol=1e-6)
        assert geom.emission == (0.0 if i < len(road) else SKY_EMISSION)
    path = route.path
    wall = np.array([pos for _, pos, _, _ in sky[:-1]])
    # every panel stands beyond every point of the route and within the far plane of all of them
    distances = np.hypot(wall[:, None, 0] - path.x_m[None, :], wall[:, None, 1] - path.y_m[None, :])
    assert distances.min() > 10.0 and distances.max() < far_m
    # the wall closes around the route: panels at every bearing from its centre, no gap of more than 10°
    centre = sky[-1][1][:2]
    bearings = np.sort(np.arctan2(wall[:, 1] - centre[1], wall[:, 0] - centre[0]))
    assert np.max(np.diff(np.concatenate([bearings, bearings[:1] + 2.0 * np.pi]))) < np.radians(10.0)
    assert sky[-1][1][2] > wall[:, 2].max()  # the lid over the wall
    if not gl_available():
        return
    width, height = 160, 90
    context = _gl_context(width, height)
    try:
        full = mujoco.MjvScene(model, maxgeom=20000)
        camera = mujoco.MjvCamera()
        camera.type, camera.fixedcamid = mujoco.mjtCamera.mjCAMERA_FIXED, model.camera("chase").id
        mujoco.mjv_updateScene(model, core.sim.vehicle.data, mujoco.MjvOption(), None, camera,
                               mujoco.mjtCatBit.mjCAT_ALL, full)
        decorate_scene(full, route, model)  # (the viewer appends its user_scn so)
        gl = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, gl)
        rect = mujoco.MjrRect(0, 0, width, height)
        pixels, depth = np.empty((height, width, 3), np.uint8), np.empty((height, width), np.float32)
        mujoco.mjr_render(rect, full, gl)
        mujoco.mjr_readPixels(pixels, depth, rect, gl)
        gl.free()
    finally:
        context.free()
    frame, depth = np.flipud(pixels).astype(int), np.flipud(depth)
    assert (depth >= 1.0).mean() == 0.0  # no black background anywhere
    top = frame[:5]
    assert (top[..., 2] > top[..., 0] + 20).mean() > 0.9  # sky: blue over red


def test_human_mode_only_with_a_display():
    from biso_cosim.envs import AttitudeEstimationEnv
    from biso_cosim.envs._common import display_available

    modes = AttitudeEstimationEnv.metadata["render_modes"]
    assert "rgb_array" in modes and ("human" in modes) == display_available()
    if "human" not in modes:
        # (gym.make would fall back to its HumanRendering wrapper around "rgb_array")
        with pytest.raises(ValueError, match="needs a display"):
            AttitudeEstimationEnv(render_mode="human", **SHORT)


@pytest.mark.parametrize(("env_id", "kwargs"), [CASES[0], CASES[2], CASES[4], CASES[5], CASES[8], CASES[10]],
                         ids=[CASE_IDS[i] for i in (0, 2, 4, 5, 8, 10)])
def test_same_seed_same_rollout_bit_for_bit(env_id, kwargs):
    a = rollout(gym.make(env_id, **SHORT, **kwargs), seed=11, steps=40)
    b = rollout(gym.make(env_id, **SHORT, **kwargs), seed=11, steps=40)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert data_equivalence(x, y, exact=True)
    c = rollout(gym.make(env_id, **SHORT, **kwargs), seed=12, steps=40)
    assert not np.array_equal(a[5][0], c[5][0])


# GainTuning with a parameter tuned besides BISO's f_c and r (the gains' short path must not take it)
THREE_TUNED = ("biso_cosim/GainTuning-v0", {"tuning": {"cutoff_hz": (0.05, 2.0, "log"),
                                                       "cross_link_ratio": (0.0, 2.0, "linear"),
                                                       "declination_rad": (-0.3, 0.3, "linear")}})


@pytest.mark.parametrize(("env_id", "kwargs"), [CASES[0], CASES[2], CASES[4], CASES[5], CASES[6], CASES[7],
                                                THREE_TUNED, CASES[8]],
                         ids=[*(CASE_IDS[i] for i in (0, 2, 4, 5, 6, 7)), "GainTuning-three-tuned", CASE_IDS[8]])
def test_fast_paths_step_as_the_plain_ones_bit_for_bit(env_id, kwargs):
    """Each environment's own work inside the period call (``PeriodWork``, attached) and
    GainTuning's short gain change give the steps of the plain paths (the co-simulation's
    general path, ``fast_path = False``; ``set_params``), through a restored state and a
    parameter change that make the co-simulation gather its periods' arrays again and the
    gain change take the long path; what the action tunes besides the gains reaches the
    estimator."""
    fast, plain = (gym.make(env_id, **SHORT, **kwargs) for _ in range(2))
    for env in (fast, plain):
        env.action_space.seed(4)
        env.reset(seed=9)
    plain.unwrapped.sim.fast_path = False  # (from the first step: the reset's period is the same either way;
    # GainTuning's action then goes by the plain check and set_params too)
    assert fast.unwrapped.sim.loop_estimators == tuple(fast.unwrapped.sim.estimators)  # every one in the call
    tuned = fast.unwrapped.sim.estimators.get("tuned")  # GainTuning's
    if tuned is not None:
        short = tuned.method == "biso" and set(fast.unwrapped.tuning) == {"cutoff_hz", "cross_link_ratio"}
        assert fast.unwrapped.gains_in_place == short
    for i in range(60):
        if i == 20:
            for env in (fast, plain):
                env.unwrapped.sim.set_state(env.unwrapped.sim.get_state())
        if i == 40 and tuned is not None:
            for env in (fast, plain):  # a change of anything but the gains makes new coefficients
                estimator = env.unwrapped.sim.estimators["tuned"]
                estimator.set_params(declination_rad=estimator.params.declination_rad)
            assert fast.unwrapped._closed_version != tuned.arrays_version
        steps = [env.step(env.action_space.sample()) for env in (fast, plain)]
        assert data_equivalence(steps[0], steps[1], exact=True), i
        if steps[0][2] or steps[0][3]:
            break
    if tuned is not None:
        assert tuned.params == plain.unwrapped.sim.estimators["tuned"].params
        params = steps[0][4]["params"]
        for name in set(params) - {"cutoff_hz", "cross_link_ratio", "k", "k_p"}:
            assert getattr(tuned.params, name) == params[name]


def test_episode_seeds_derive_from_the_reset_seed():
    env = gym.make("biso_cosim/AttitudeEstimation-v0", route="random", **SHORT)
    _, info = env.reset(seed=5)
    route_seq, sensor_seq, gnss_seq = np.random.SeedSequence(5).spawn(3)
    assert info["episode_seed"] == 5
    assert info["sensor_seed"] == _int_seed(sensor_seq)
    assert info["route_seed"] == _int_seed(route_seq)
    assert "gnss_seed" not in info
    assert gym.make("biso_cosim/AttitudeEstimation-v0", gnss_rate_hz=2.0, **SHORT).reset(seed=5)[1]["gnss_seed"] == \
        _int_seed(gnss_seq)
    assert info["route"] == f"random-{info['route_seed']}"
    # unseeded resets continue the stream of the first seed: a reproducible sequence
    seeds = [env.reset()[1]["episode_seed"] for _ in range(3)]
    env.reset(seed=5)
    assert [env.reset()[1]["episode_seed"] for _ in range(3)] == seeds
    assert len(set(seeds)) == 3
    # a fixed sensor seed keeps the part and its noise
    fixed = gym.make("biso_cosim/AttitudeEstimation-v0", sensor_seed=9, **SHORT)
    assert fixed.reset(seed=1)[1]["sensor_seed"] == fixed.reset(seed=2)[1]["sensor_seed"] == 9
    assert np.array_equal(fixed.reset(seed=1)[0], fixed.reset(seed=2)[0])


def test_random_routes_change_with_the_seed_only():
    env = gym.make("biso_cosim/Driving-v0", route="random", pose_source="truth", **SHORT)
    obs_a, info_a = env.reset(seed=3)
    obs_b, info_b = env.reset(seed=4)
    obs_c, info_c = env.reset(seed=3)
    assert info_a["route"] != info_b["route"] and info_a["route"] == info_c["route"]
    assert np.array_equal(obs_a, obs_c)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_pickle_round_trip(env_id):
    env = gym.make(env_id, **SHORT)
    env.reset(seed=2)
    env.step(env.action_space.sample())
    copy = pickle.loads(pickle.dumps(env))
    # EzPickle: the copy is built from the same arguments; after a seeded reset both agree
    assert data_equivalence(rollout(env, seed=4, steps=10), rollout(copy, seed=4, steps=10), exact=True)


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_env_matches_single_envs(mode):
    env_id = "biso_cosim/AttitudeEstimation-v0"
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode=mode, **SHORT)
    singles = [gym.make(env_id, **SHORT) for _ in range(2)]
    obs, infos = vec.reset(seed=20)
    single_obs = [env.reset(seed=20 + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(single_obs))
    vec.action_space.seed(1)
    for _ in range(30):
        actions = vec.action_space.sample()
        obs, rewards, terminated, truncated, infos = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, info = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rewards[i] == r and terminated[i] == te and truncated[i] == tr
            assert infos["baseline_error_rad"][i] == info["baseline_error_rad"]
    vec.close()


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_reset_returns_to_a_valid_start(env_id):
    env = gym.make(env_id, **SHORT)
    first, info = env.reset(seed=7)
    assert env.observation_space.contains(first)
    for _ in range(30):
        env.step(env.action_space.sample())
    again, info_again = env.reset(seed=7)  # mid-episode reset
    assert data_equivalence((first, info), (again, info_again), exact=True)
    sim = env.unwrapped.sim
    # at rest at the start, only the reset's own time (one period; Driving's alignment) elapsed
    assert abs(sim.vehicle.driver.state.s_m) < 0.01
    assert sim.vehicle.data.time == pytest.approx(env.unwrapped._reset_time_s(), abs=2e-3)
    # run to the end, then reset again
    while True:
        *_, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            break
    with pytest.raises(ResetNeeded):
        env.unwrapped.step(env.action_space.sample())
    assert data_equivalence(env.reset(seed=7), (first, info), exact=True)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_step_before_reset_is_refused(env_id):
    env = gym.make(env_id, **SHORT).unwrapped
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(env.action_space.sample())
    assert isinstance(ResetNeeded("x"), ValueError)


def bad_actions(n):
    """Actions every environment with n action values refuses, and the message that says why."""
    return [(np.r_[np.nan, np.zeros(n - 1)], "finite"), (np.r_[1.0, np.inf, np.zeros(n - 2)], "finite"),
            (np.zeros(n - 1), "shape"), (np.zeros((n, 1)), "shape"), ("w", "shape|real numbers"),
            (None, "shape|real numbers")]


BAD_ACTIONS = [("biso_cosim/AttitudeEstimation-v0", action, message) for action, message in bad_actions(4)] + [
    ("biso_cosim/AttitudeEstimation-v0", np.zeros(4), "zeros"),
    *(("biso_cosim/GainTuning-v0", action, message) for action, message in bad_actions(2)),
    *(("biso_cosim/Driving-v0", action, message) for action, message in bad_actions(2))]


@pytest.mark.parametrize(("env_id", "action", "message"), BAD_ACTIONS)
def test_bad_actions_raise_before_anything_changes(env_id, action, message):
    env, reference = gym.make(env_id, **SHORT), gym.make(env_id, **SHORT)
    env.reset(seed=3)
    reference.reset(seed=3)
    good = np.array([1.0, 0.0, 0.0, 0.0]) if "Attitude" in env_id else np.array([0.5, -0.25])
    env.step(good)
    reference.step(good)
    with pytest.raises(ValueError, match=message):
        env.step(action)
    # the refused call changed nothing: the env goes on exactly like one that never saw it
    assert data_equivalence(env.step(-good), reference.step(-good), exact=True)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_out_of_bounds_actions_clip_or_raise(env_id):
    clip = gym.make(env_id, **SHORT)
    strict = gym.make(env_id, action_bounds="raise", **SHORT)
    reference = gym.make(env_id, **SHORT)
    for env in (clip, strict, reference):
        env.reset(seed=1)
    space = clip.action_space
    wild = np.where(np.arange(space.shape[0]) % 2 == 0, 5.0 * space.high, 5.0 * space.low)
    with pytest.raises(ValueError, match="out of bounds"):
        strict.step(wild)
    # clipping: the same as the clipped action (what Gymnasium's ClipAction does)
    assert data_equivalence(clip.step(wild), reference.step(np.clip(wild, space.low, space.high)), exact=True)
    with pytest.raises(ValueError, match="action_bounds"):
        gym.make(env_id, action_bounds="wrap", **SHORT)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"route": "nowhere"}, "^route: unknown route"),
    ({"control_rate_hz": 30.0}, "whole multiple"),
    ({"episode_duration_s": -1.0}, "episode_duration_s"),
    ({"sensor_seed": -2}, "sensor_seed"),
    ({"random_route_options": {"hills": 1}}, "random"),
    ({"route": "random", "random_route_options": {"lakes": 1}}, "unknown option"),
    ({"action_type": "matrix"}, "action_type"),
    ({"render_width": 5000}, "render_width"),
    ({"render_mode": "ascii"}, "render_mode"),
    ({"sensor_profile": "mpu6050"}, "^sensor_profile: profile"),
    ({"estimator": "kalman"}, "unknown estimator"),
    ({"gnss_rate_hz": 50.0}, "gnss_rate_hz"),
    ({"gnss_rate_hz": 5.0, "gnss_profile": "survey"}, "gnss_profile"),
])
@pytest.mark.filterwarnings("ignore:.*render_mode")
def test_bad_arguments_name_themselves(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("biso_cosim/AttitudeEstimation-v0", **kwargs)


@pytest.mark.parametrize("seed", [-1, 2**63, 1.5, "7", True])
def test_bad_seeds_name_themselves(seed):
    env = gym.make("biso_cosim/AttitudeEstimation-v0", **SHORT)
    with pytest.raises(ValueError, match=r"^seed must be None or an int in \[0, 2\*\*63 - 1\]"):
        env.reset(seed=seed)
    env.reset(seed=2**63 - 1)  # the top of the range is fine


@pytest.mark.parametrize(("env_id", "kwargs"), CASES, ids=CASE_IDS)
def test_spaces_are_bounded_float32_without_constant_columns(env_id, kwargs):
    """Bounded float32 Boxes; the observation is the physical state over its documented scales
    (clipped to the bounds); no column stays constant over an episode of random actions."""
    env = gym.make(env_id, episode_duration_s=4.0, **kwargs)
    core = env.unwrapped
    for space in (env.observation_space, env.action_space):
        assert space.dtype == np.float32 and space.is_bounded()
    assert len(core.observation_fields) == env.observation_space.shape[0] == core.observation_scale.shape[0]
    assert env.spec.max_episode_steps == biso_cosim.envs.MAX_EPISODE_STEPS[env_id.replace("biso_cosim:", "")]
    observations = [obs for obs, *_ in rollout(env, seed=5, steps=200)]
    obs = observations[-1]
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    # the observation is the physical parts over their scales (the parts the observation keeps)
    physical = core.physical_observation()
    split = core.split_observation(obs)
    for name, part in split.items():
        raw = physical[name]
        if name == "imu" and part.shape[-1] < raw.shape[-1]:
            raw = raw[:, :part.shape[-1]]  # (`mag_fresh` and `new`, the last columns, left out)
        np.testing.assert_allclose(part, raw, rtol=1e-6, atol=1e-6 * np.abs(raw).max(initial=1.0))
    stacked = np.stack(observations[1:])
    constant = [f for f, column in zip(core.observation_fields, stacked.T) if np.all(column == column[0])]
    if core.imu_slots != core.imu_rate_hz * core.dt:  # rates that do not divide: `new` is 1 on the newest
        always = math.floor(core.imu_rate_hz * core.dt)  # floor(ODR / control rate) rows (kept for the others)
        constant = [f for f in constant if f not in [f"imu[{r}].new" for r in range(core.imu_slots - always,
                                                                                        core.imu_slots)]]
    constant = [f for f in constant if f != "gnss.valid"]  # (0 only in outages, before the first fix)
    # (a sensor without noise reads the same quantised field while the car waits at the start)
    assert not constant or kwargs.get("sensor_profile") == "ideal" or kwargs.get("sensor_noise") is False, constant


def test_make_vec_with_the_plain_id_after_the_import():
    vec = gym.make_vec("biso_cosim/Driving-v0", num_envs=2, vectorization_mode="sync", **SHORT)
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (2, 67) and obs.dtype == np.float32
    vec.close()


def test_common_arguments_agree_across_environments():
    """Each environment spells out the common keywords (typed, v5 style); they must not drift."""
    import inspect

    from biso_cosim.envs import AttitudeEstimationEnv, DrivingEnv, GainTuningEnv
    from biso_cosim.envs._common import COMMON_ARGUMENTS

    signatures = [inspect.signature(cls.__init__).parameters for cls in (AttitudeEstimationEnv, GainTuningEnv,
                                                                         DrivingEnv)]
    # GainTuning's episodes differ on purpose: random routes and a raw part (a real trade-off)
    own_defaults = {"route", "sensor_profile"}
    for name in COMMON_ARGUMENTS:
        first = signatures[0][name]
        if name in own_defaults:
            assert signatures[0][name].default == signatures[2][name].default, name
            continue
        for params in signatures[1:]:
            assert (params[name].default, params[name].annotation, params[name].kind) == \
                (first.default, first.annotation, first.kind), name


def test_docs_reference_is_in_sync():
    from pathlib import Path

    from biso_cosim.envs import reference_markdown

    docs = Path(__file__).resolve().parents[1] / "docs" / "envs.md"
    generated = reference_markdown()
    assert generated in docs.read_text(encoding="utf-8"), (
        "docs/envs.md is out of date: replace its reference part with biso_cosim.envs.reference_markdown()")
    for env_id in ENV_IDS:
        cls = gym.spec(env_id).entry_point
        assert "{arguments}" not in biso_cosim.envs.__getattr__(cls.split(":")[1]).__doc__
