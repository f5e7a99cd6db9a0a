"""Environment steps per second, single and vectorised, against bare MuJoCo stepping.

For each environment: the time (process CPU time by default, steadier than wall time on a
machine shared with other jobs) of ``env.step`` over an episode (the unwrapped
environment, and as ``gym.make`` returns it with Gymnasium's checking wrappers), of the
co-simulation step alone (physics, sensor, estimators: the environment minus its own work),
and of bare ``mj_step`` calls of the same model over the same simulated time, with the same
actuator commands from the same states, all in the same process. Then steps/s
of ``gym.make_vec`` with 2 environments, synchronous and asynchronous (one process each),
by wall time; and, for reference, what the vector machinery itself costs per step with a
trivial environment (CartPole-v1): in asynchronous mode a pipe round trip to each worker,
paid on top of the steps the workers run in parallel.

    python benchmarks/env_steps.py                       # 40 s episodes, every environment
    python benchmarks/env_steps.py --envs Driving --duration 60 --repeat 5
    python benchmarks/env_steps.py --estimators biso biso_plus dcm_pi --no-vector   # each in the loop

``--estimators`` runs each environment with each named estimator in the loop (its
``estimator`` argument; GainTuning only with the estimators it has a default tuning for),
one row each; ``--no-vector`` leaves out the vector-environment columns.

The ratios to bare physics come from ``time_blocks``: the episode's environment steps,
replaying the actions the policy took (the same steps without the policy between them), in
blocks of 25, each block followed by the same periods' physics bare (the same controls from
the same state, ending in the same state, checked; the car's model without the sensor
history the co-simulation reads its rows from): each loop runs with warm caches, as in
a loop of its own, while the two stay milliseconds apart and so meet the same load on a
machine shared with other jobs (separate runs here differ by ±25 %). Each loop is timed as
a whole, by one clock reading before it and one after. The first step of each loop in a
block is a warm-up, not timed: it follows the other loop, whose data and code it finds in
the caches instead of its own. These columns are averaged over the repetitions; the other
columns are each the best of the repetitions.

Columns: µs per step of the unwrapped environment (``env``), the part of it outside the
co-simulation's step measured in the same calls (``own``: the environment's own work), the
environment through ``gym.make``, the co-simulation step alone, bare physics stepped by one
``mj_step`` call per physics step (``bare``) and by one ``mj_step(model, data, nstep)`` call
per control period as Gymnasium's MuJoCo environments do (``nstep``, the stricter baseline);
the ratios env/bare and env/nstep (the issue's budget: overhead over physics < 30 %);
``interleaved``: env/nstep with blocks of one step (the median over the repetitions): each
environment step then starts with caches the bare physics has filled, as when a policy's
forward pass runs between steps; steps/s. The co-simulation steps the physics of a control
period by one ``mj_step(model, data, nstep)`` call too, and reads the sensor rows of its
steps from MuJoCo's sensor history, so it pays no Python per physics step.
"""

from __future__ import annotations

import argparse
import math
import time

import gymnasium as gym
import mujoco
import numpy as np

import biso_cosim.envs  # noqa: F401  (registers the ids)
from biso_cosim.envs import ENV_IDS
from biso_cosim.envs.gain_tuning import DEFAULT_TUNING
from biso_cosim.estimators import estimator_names
from biso_cosim.vehicle.model import build_model
from biso_cosim.vehicle.sim import PHYSICS_STATE

CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}

# Driving follows the route from the true pose here, so that an episode lasts (the dead-
# reckoned pose drifts off the road within tens of metres); the work per step is the same.
KWARGS = {"biso_cosim/Driving-v0": {"pose_source": "truth"}}

# environment steps per block of ``time_blocks`` (0.5 s simulated at 50 Hz)
BLOCK = 25


def random_walk(env, seed: int):
    """A policy: a smooth random walk inside the action space (AttitudeEstimation, GainTuning)."""
    rng = np.random.default_rng(seed)
    space = env.action_space
    state = {"a": (space.low + space.high) / 2.0}

    def policy(obs):
        state["a"] = np.clip(state["a"] + rng.normal(0.0, 0.05, space.shape), space.low, space.high)
        return state["a"]

    return policy


def pursuit(env, seed: int):
    """A policy for Driving: pure pursuit on the observed route ahead at 6 m/s."""
    core = env.unwrapped

    def policy(obs):
        p = core.split_observation(obs)
        x, y = p["route_ahead"][3]
        steer = np.arctan(2.0 * 2.7 * np.sin(np.arctan2(y, x)) / max(np.hypot(x, y), 1e-3)) / 0.6
        return np.clip([0.5 * (6.0 - p["wheel_speed_mps"][:2].mean()), steer], -1.0, 1.0)

    return policy


def time_env(env, make_policy, steps: int, seed: int, clock=time.process_time):
    """Time of ``env.step`` over up to ``steps`` steps of a policy (reset and policy excluded),
    the part of it spent inside the co-simulation's step, the actions and the controls."""
    obs, _ = env.reset(seed=seed)
    core = env.unwrapped
    policy = make_policy(env, seed)
    sim = core.sim
    inner = {"s": 0.0}
    sim_step = sim.step

    def timed_step(command=None):  # shadows the method on this instance while timing
        start = clock()
        out = sim_step(command)
        inner["s"] += clock() - start
        return out

    sim.step = timed_step
    actions, controls = [], []
    elapsed = 0.0
    try:
        for _ in range(steps):
            a = policy(obs)
            start = clock()
            obs, _, terminated, truncated, _ = env.step(a)
            elapsed += clock() - start
            actions.append(a)
            controls.append(sim.vehicle.data.ctrl.copy())
            if terminated or truncated:
                break
    finally:
        del sim.step
    return elapsed, inner["s"], np.array(actions), np.array(controls)


def bare_model(vehicle) -> mujoco.MjModel:
    """The vehicle's model without the sensor history the co-simulation reads its rows from
    (MuJoCo records it in every step: about 2 % of a step here): the bare physics."""
    model, _ = build_model(vehicle.route.terrain, timestep_s=1.0 / vehicle.physics_rate_hz, tyres=vehicle.tyres,
                           tyre_params=vehicle.tyre_params, chassis_params=vehicle.chassis_params,
                           surface=vehicle.surface)
    return model


def time_blocks(env, actions: np.ndarray, controls: np.ndarray, seed: int, block: int,
                clock=time.process_time) -> tuple[float, float, float, int]:
    """An episode of ``env.step`` replaying its recorded ``actions`` (``time_env``: the same
    seed, the same steps) in blocks of ``block`` steps, each block followed by the same
    periods' physics bare on the model without sensor history (``bare_model``) from the
    state at the block's start, each period's recorded ``controls`` and its physics steps,
    by one ``mj_step`` call per physics step and by one ``mj_step(model, data, nstep)`` call
    per period. The replays end in the environment's state, bit for bit (checked): they do
    the same physics work. Each loop is timed by one clock reading before and one after
    it, with nothing else in it: the environment's loop runs no policy and reads no clock
    between its steps, as the physics replays do not between their periods.

    With blocks of more than one step, the first step of each loop is a warm-up, not timed:
    it follows another loop (a switch of data, code or both; the nstep replay alone would
    not pay for it, as it follows the loop replay on the same data), so that every loop is
    timed warm, as in a loop of its own. Blocks of one step time every step (the
    ``interleaved`` column: each step starts cold). Returns the total times of env, loop and
    nstep, and the number of steps timed in each."""
    env.reset(seed=seed)
    vehicle = env.unwrapped.sim.vehicle
    model, data, per, step = vehicle.model, vehicle.data, vehicle.steps_per_control, mujoco.mj_step
    bare = bare_model(vehicle)
    shadow = mujoco.MjData(bare)
    spec = PHYSICS_STATE
    start_state = np.empty(mujoco.mj_stateSize(model, spec))
    env_step = env.step
    warm_up = 1 if block > 1 else 0

    def periods(ctrls, nstep_calls: bool) -> None:
        for ctrl in ctrls:
            shadow.ctrl[:] = ctrl
            if nstep_calls:
                step(bare, shadow, per)
            else:
                for _ in range(per):
                    step(bare, shadow)

    def replay(ctrls, nstep_calls: bool) -> float:
        mujoco.mj_setState(bare, shadow, start_state, spec)
        periods(ctrls[:warm_up], nstep_calls)
        start = clock()
        periods(ctrls[warm_up:], nstep_calls)
        elapsed = clock() - start
        if not (np.array_equal(shadow.qpos, data.qpos) and np.array_equal(shadow.qvel, data.qvel)):
            raise RuntimeError("the bare replay of a block left another state than the environment's steps")
        return elapsed

    t_env = t_loop = t_nstep = 0.0
    timed = 0
    for first in range(0, len(actions), block):
        block_actions, block_controls = actions[first:first + block], controls[first:first + block]
        mujoco.mj_getState(model, data, start_state, spec)
        for a in block_actions[:warm_up]:
            env_step(a)
        start = clock()
        for a in block_actions[warm_up:]:
            env_step(a)
        t_env += clock() - start
        t_loop += replay(block_controls, False)
        t_nstep += replay(block_controls, True)
        timed += max(len(block_actions) - warm_up, 0)
    return t_env, t_loop, t_nstep, timed


def time_cosim(core, actions: np.ndarray, seed: int, clock=time.process_time) -> float:
    """The co-simulation steps of the same episode, without the environment around them."""
    core.reset(seed=seed)
    sim = core.sim
    commands = None
    if hasattr(core, "weights"):  # Driving: the same commands the environment turned the actions into
        from biso_cosim.vehicle.driver import DriverCommand

        steer = sim.vehicle.parameters["max_steer_rad"]
        commands = [DriverCommand(float(a[1]) * steer, max(float(a[0]), 0.0), max(-float(a[0]), 0.0)) for a in actions]
    start = clock()
    for i in range(len(actions)):
        sim.step(None if commands is None else commands[i])
    return clock() - start


def time_vector(env_id: str, mode: str, duration: float, actions: np.ndarray, seed: int,
                kwargs: dict | None = None) -> float:
    """Environment steps per second of 2 environments in a vector environment (replaying
    ``actions`` in both; for Driving the copies follow the same commands from the same start)."""
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode=mode, episode_duration_s=duration,
                       **(KWARGS.get(env_id, {}) if kwargs is None else kwargs))
    vec.reset(seed=[seed, seed])
    batch = np.repeat(actions[:, None, :], 2, axis=1)
    start = time.perf_counter()
    for a in batch:
        vec.step(a)
    elapsed = time.perf_counter() - start
    vec.close()
    return 2 * len(actions) / elapsed


def round_trip(mode: str, steps: int = 2000) -> float:
    """µs per step of ``gym.make_vec("CartPole-v1", num_envs=1)``: the vector machinery's own
    cost per step (in ``async`` mode a pipe round trip to the worker process), for reference."""
    vec = gym.make_vec("CartPole-v1", num_envs=1, vectorization_mode=mode)
    vec.reset(seed=0)
    action = np.zeros(1, dtype=np.int64)
    for _ in range(50):
        vec.step(action)
    start = time.perf_counter()
    for _ in range(steps):
        vec.step(action)
    elapsed = time.perf_counter() - start
    vec.close()
    return 1e6 * elapsed / steps


def main() -> None:
    names = [env_id.split("/")[1].split("-")[0] for env_id in ENV_IDS]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=names, choices=names)
    parser.add_argument("--duration", type=float, default=40.0, help="simulated seconds per episode")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions; the best of each is kept")
    parser.add_argument("--clock", default="cpu", choices=sorted(CLOCKS),
                        help="process CPU time (steady on a shared machine) or wall time")
    parser.add_argument("--estimators", nargs="+", default=None, choices=estimator_names(),
                        help="run each environment with each of these estimators in the loop (one row each)")
    parser.add_argument("--no-vector", action="store_true", help="leave out the vector environments (sync/s, async/s)")
    args = parser.parse_args()
    clock = CLOCKS[args.clock]
    print(f"single-process figures: {args.clock} time; vector environments: wall time")
    print(f"{'environment':<19} {'steps':>6} {'env µs':>7} {'own µs':>7} {'make µs':>8} {'cosim µs':>9} "
          f"{'bare µs':>8} {'nstep µs':>9} {'env/bare':>9} {'env/nstep':>10} {'interleaved':>12} {'steps/s':>8} "
          f"{'sync/s':>7} {'async/s':>8}")
    runs = []
    for env_id in ENV_IDS:
        name = env_id.split("/")[1].split("-")[0]
        if name not in args.envs:
            continue
        for estimator in args.estimators or (None,):
            if estimator is not None and name == "GainTuning" and estimator not in DEFAULT_TUNING:
                print(f"{name + ' ' + estimator:<19} (no default tuning for {estimator}: not run)")
                continue
            runs.append((env_id, name, estimator))
    for env_id, name, estimator in runs:
        kwargs = dict(KWARGS.get(env_id, {}), **({} if estimator is None else {"estimator": estimator}))
        label = name if estimator is None else f"{name[:10]} {estimator}"
        wrapped = gym.make(env_id, episode_duration_s=args.duration, **kwargs)
        core = wrapped.unwrapped
        steps = int(round(args.duration * core.metadata["render_fps"])) - 1
        make_policy = pursuit if name == "Driving" else random_walk
        time_env(core, make_policy, 50, seed=1)  # warm-up: numba caches, first allocations
        best = dict.fromkeys(("own", "make", "cosim"), np.inf)
        per_step = dict.fromkeys(("env", "bare", "nstep"), 0.0)  # (mean over the repetitions)
        interleaved = []
        for _ in range(args.repeat):
            t_env, t_inner, actions, controls = time_env(core, make_policy, steps, 1, clock)
            best["own"] = min(best["own"], t_env - t_inner)
            best["make"] = min(best["make"], time_env(wrapped, make_policy, steps, 1, clock)[0])
            best["cosim"] = min(best["cosim"], time_cosim(core, actions, 1, clock))
            *times, timed = time_blocks(core, actions, controls, 1, BLOCK, clock)
            for key, value in zip(("env", "bare", "nstep"), times):
                per_step[key] += value / timed / args.repeat
            t_env, _, t_nstep, _ = time_blocks(core, actions, controls, 1, 1, clock)
            interleaved.append(t_env / t_nstep)
        done = len(actions)
        sync = asynchronous = math.nan
        if not args.no_vector:
            sync = time_vector(env_id, "sync", args.duration, actions, seed=1, kwargs=kwargs)
            asynchronous = time_vector(env_id, "async", args.duration, actions, seed=1, kwargs=kwargs)
        us = {**{k: 1e6 * v / done for k, v in best.items()}, **{k: 1e6 * v for k, v in per_step.items()}}
        print(f"{label:<19} {done:>6} {us['env']:>7.1f} {us['own']:>7.1f} {us['make']:>8.1f} {us['cosim']:>9.1f} "
              f"{us['bare']:>8.1f} {us['nstep']:>9.1f} {us['env'] / us['bare']:>9.3f} "
              f"{us['env'] / us['nstep']:>10.3f} {np.median(interleaved):>12.3f} "
              f"{1e6 / us['env']:>8.0f} {sync:>7.0f} {asynchronous:>8.0f}")
    if not args.no_vector:
        print(f"vector machinery per step, CartPole-v1 (1 copy) for reference: sync {round_trip('sync'):.0f} µs, "
              f"async {round_trip('async'):.0f} µs")

if __name__ == "__main__":
    main()
