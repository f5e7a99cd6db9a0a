"""Trained baselines: PPO (and SAC) from Stable-Baselines3 on each environment for a fixed
budget, against a random policy, the scripted information baseline and (GainTuning) the oracle.

For each environment and algorithm: the learning curve (mean return of the training
episodes finished in each tenth of the budget, by the task's measure: ``task_reward``), then the final mean
return over the evaluation seeds (deterministic policy) in the training environment (and,
for Driving, trained on procedural routes, on ``figure8`` as well) next to

* random: uniform actions from the action space (seeded);
* info baseline: AttitudeEstimation, the reference BISO in ``info`` (the return a policy
  answering with it would get), the memoryless accelerometer+magnetometer attitude and the
  residual agent's zero action (gyro dead reckoning from the accelerometer+magnetometer
  attitude at the start) and best constant action (a grid of tilt and heading gains);
  GainTuning, the paper's gains as a constant action; Driving, ``PursuitDriver``;
* GainTuning's oracle: the best constant gains of each episode (``gain_oracle``), and the
  best single constant over the evaluation episodes (from the same grid).

Default hyperparameters of SB3 (``MlpPolicy``) except those of ``biso_cosim.envs.training``
(AttitudeEstimation's residual agent, with the environment arguments there, explores less at
the start; Driving decides at 10 Hz), observations and rewards normalised by
``VecNormalize``; training steps/s with 1 and with 2 environments (``SubprocVecEnv``, wall
time) measured over ``--speed-steps`` steps each. Needs the extra ``rl`` (``pip install
torch==2.13.0`` first on this machine: the local CPU build):

    python benchmarks/rl_baselines.py --timesteps 20000             # a quick look
    python benchmarks/rl_baselines.py --envs Driving --timesteps 300000 --curve-rows 10 --speed-steps 0   # the docs' table
    python benchmarks/rl_baselines.py --envs AttitudeEstimation GainTuning --timesteps 150000 --speed-steps 0
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import biso_cosim.envs  # noqa: F401  (registers the ids)
from biso_cosim.envs.baselines import AccelMagAttitude, PursuitDriver, paper_gains
from biso_cosim.envs.training import algo_options, env_options

ENVS = {"AttitudeEstimation": "biso_cosim/AttitudeEstimation-v0", "GainTuning": "biso_cosim/GainTuning-v0",
        "Driving": "biso_cosim/Driving-v0"}
EVALUATION_SEED = 1000  # seeds 1000, 1001, ... (tests/test_envs_tasks.py's)
CORRECTION_GRID = (0.0, 0.1, 0.3, 1.0)  # AttitudeEstimation's constant corrections: tilt and heading gains
# (linear, up to a 10 s pull: pulls of no, 100 s, 33 s and 10 s time constant)


def task_reward(reward, info):
    """The step's reward by the task's measure: AttitudeEstimation's and GainTuning's
    ``reward_attitude`` (minus the attitude error, without the terms that the training options
    of ``biso_cosim.envs.training`` add for the learner: shaping, the reference copy's error),
    Driving's reward."""
    return float(info.get("reward_attitude", reward))


def episode_return(env, policy, seed, reset=None):
    obs, info = env.reset(seed=seed)
    if reset is not None:
        reset()
    total, baseline = 0.0, 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += task_reward(reward, info)
        baseline -= float(info.get("baseline_error_rad", 0.0))
        if terminated or truncated:
            return total, baseline, info


def baselines(name, env, seeds):
    """Mean returns of the scripted policies over the seeds: {label: mean}."""
    out = {}
    rng = np.random.default_rng(0)
    space = env.action_space
    random_policy = lambda obs: rng.uniform(space.low, space.high).astype(np.float32)  # noqa: E731
    runs = [episode_return(env, random_policy, s) for s in seeds]
    out["random"] = np.mean([r[0] for r in runs])
    if name == "AttitudeEstimation":
        out["info baseline: BISO (reference in info)"] = np.mean([r[1] for r in runs])
        if env.unwrapped.action_type == "correction":
            # the same episodes with linear gains up to a 10 s pull (whatever the training's scale)
            linear = gym.make(ENVS[name], **{**env.spec.kwargs, "correction_scale": "linear",
                                             "correction_time_constant_s": 10.0})
            zero = np.zeros(env.action_space.shape, dtype=np.float32)
            out["zero correction (gyro strapdown)"] = np.mean([episode_return(linear, lambda o: zero, s)[0]
                                                               for s in seeds])
            # the best constant correction over the evaluation episodes: gains of the tilt axes
            # (x, y) and of the heading axis (z) on a grid (CORRECTION_GRID each: pulls of time
            # constant 10 s / gain)
            constants = [np.array([t, t, h], dtype=np.float32) for t in CORRECTION_GRID for h in CORRECTION_GRID]
            means = [np.mean([episode_return(linear, lambda o, c=c: c, s)[0] for s in seeds]) for c in constants]
            best = int(np.argmax(means))
            print(f"    best constant correction: {constants[best].tolist()}", flush=True)
            out["best constant correction (grid)"] = means[best]
        # the same episodes (the sensor part of the training options too), quaternion actions
        own = ("action_type", "correction_time_constant_s", "correction_scale", "shaping_gamma")
        absolute = gym.make(ENVS[name], **{k: v for k, v in env.spec.kwargs.items() if k not in own})
        am = AccelMagAttitude(absolute)
        out["accel+mag attitude (memoryless)"] = np.mean([episode_return(absolute, am, s, am.reset)[0]
                                                          for s in seeds])
    elif name == "GainTuning":
        from biso_cosim.envs.gain_oracle import episode_errors

        paper = paper_gains(env)
        out["info baseline: paper gains"] = np.mean([episode_return(env, lambda o: paper, s)[0] for s in seeds])
        oracle, grid_errors = [], []
        axis = np.linspace(-1.0, 1.0, 9)
        grid = [np.array([a, b]) for a in axis for b in axis]
        for s in seeds:  # (the grid of gain_oracle.oracle_action without refinement, one co-simulation per seed)
            grid_errors.append(episode_errors(env, s, grid))
            best = grid[int(np.argmin(grid_errors[-1]))].astype(np.float32)
            oracle.append(episode_return(env, lambda o: best, s)[0])
            print(f"    oracle seed {s}: {env.unwrapped.params_from_action(best)}", flush=True)
        out["oracle: best constant gains per episode"] = np.mean(oracle)
        single = grid[int(np.argmin(np.mean(grid_errors, axis=0)))]
        print(f"    best single constant: {env.unwrapped.params_from_action(single)}", flush=True)
        out["best single constant (grid)"] = np.mean([episode_return(env, lambda o: single, s)[0] for s in seeds])
    else:
        driver = PursuitDriver(env)
        returns = [episode_return(env, driver, s) for s in seeds]
        out["info baseline: pursuit driver"] = np.mean([r[0] for r in returns])
        out["  (finished)"] = f"{sum(r[2]['finished'] for r in returns)}/{len(seeds)}"
    return out


def train(name, algo, timesteps, seed, n_envs=1, rows=10, checkpoint=None):
    """A trained model, its VecNormalize and the learning curve [(steps, mean return, episodes)]:
    ``rows`` rows over the budget; ``checkpoint(model, vec)`` is called at each row."""
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    import torch

    # one thread: on a shared 2-core machine torch's second intra-op thread only spins
    torch.set_num_threads(1)
    curve, returns = [], []
    chunk = max(timesteps // rows, 1)
    running = np.zeros(n_envs)  # each environment's episode return so far, by the task's measure

    class Curve(BaseCallback):
        def _on_step(self) -> bool:
            original = self.model.get_env().get_original_reward()  # (VecNormalize scales the ``rewards`` local)
            for i, info in enumerate(self.locals["infos"]):
                running[i] += task_reward(original[i], info)
                if "episode" in info:
                    returns.append(running[i])
                    running[i] = 0.0
            if self.num_timesteps // chunk > len(curve):
                curve.append((self.num_timesteps, float(np.mean(returns)) if returns else float("nan"), len(returns)))
                returns.clear()
                steps, mean, count = curve[-1]
                print(f"    ({name} {algo}) {steps:>8}: {mean:10.1f}  ({count} episodes)", flush=True)
                if checkpoint is not None:
                    checkpoint(self.model, self.model.get_env())
            return True

    vec = make_vec_env(ENVS[name], n_envs=n_envs, seed=seed, env_kwargs=env_options(name),
                       vec_env_cls=SubprocVecEnv if n_envs > 1 else None)
    options = algo_options(name)
    vec = VecNormalize(vec, gamma=options.get("gamma", 0.99))
    model = (PPO if algo == "ppo" else SAC)("MlpPolicy", vec, seed=seed, verbose=0, device="cpu", **options)
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps, callback=Curve())
    rate = model.num_timesteps / (time.perf_counter() - start)  # (PPO collects whole rollouts of 2048 steps)
    vec.training = False
    return model, vec, curve, rate


def evaluation_options(name):
    """The environments a policy of ``name`` is evaluated in: {table suffix: arguments}. The
    training environment (``biso_cosim.envs.training``); for Driving, trained on procedural
    routes, also ``figure8``, a route it never drove in training."""
    options = env_options(name)
    if name != "Driving":
        return {"": options}
    return {f" ({options.get('route', 'figure8')})": options, " (figure8)": {**options, "route": "figure8"}}


def evaluate(model, vec, env, seeds):
    """Mean return of the deterministic policy over the seeds, and the last info of each episode."""
    policy = lambda obs: model.predict(vec.normalize_obs(obs[None]), deterministic=True)[0][0]  # noqa: E731
    runs = [episode_return(env, policy, s) for s in seeds]
    return float(np.mean([r[0] for r in runs])), [r[2] for r in runs]


def evaluation_rows(name, label, mean, infos):
    """The table's rows of a trained policy: its mean return, and for Driving the episodes
    finished and the distance driven along the route per seed."""
    rows = {label: mean}
    if name == "Driving":
        rows[f"  ({label.split()[0]} finished)"] = f"{sum(i['finished'] for i in infos)}/{len(infos)}"
        rows[f"  ({label.split()[0]} distance m per seed)"] = " ".join(f"{i['distance_m']:.0f}" for i in infos)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=list(ENVS), choices=list(ENVS))
    parser.add_argument("--algos", nargs="+", default=["ppo"], choices=["ppo", "sac"])
    parser.add_argument("--timesteps", type=int, default=500_000, help="training budget per environment and algorithm")
    parser.add_argument("--seeds", type=int, default=5, help="evaluation episodes (seeds 1000, 1001, ...)")
    parser.add_argument("--speed-steps", type=int, default=4096, help="steps of the steps/s measurement (0: none)")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--n-envs", type=int, default=1, help="vector environments of the training (one process "
                                                              "each when > 1): a rollout then holds each one's "
                                                              "n_steps")
    parser.add_argument("--load-dir", default=None, help="evaluate the models saved there by --save-dir "
                                                         "(checkpoints included) instead of training")
    parser.add_argument("--curve-rows", type=int, default=10, help="rows of the learning curve over the budget")
    parser.add_argument("--no-baselines", action="store_true", help="evaluate the trained (or loaded) policies "
                                                                    "only, without the scripted baselines and the "
                                                                    "oracle (they do not depend on the training)")
    parser.add_argument("--save-dir", default=None, help="directory for the trained models (<env>_<algo>.zip and "
                                                         "its VecNormalize <env>_<algo>_vecnormalize.pkl)")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    if args.n_envs < 1:
        parser.error("--n-envs must be >= 1")
    if args.curve_rows < 1:
        parser.error("--curve-rows must be >= 1")
    seeds = list(range(EVALUATION_SEED, EVALUATION_SEED + args.seeds))
    table = []
    for name in args.envs:
        print(f"== {name}: {args.timesteps} steps per algorithm, evaluation seeds {seeds[0]}..{seeds[-1]}", flush=True)
        if args.speed_steps:
            for n in (1, 2):
                _, vec, _, rate = train(name, "ppo", args.speed_steps, args.seed, n_envs=n)
                vec.close()
                print(f"  PPO training steps/s with {n} environment(s): {rate:.0f}", flush=True)
        evaluations = {f"{name}{suffix}": gym.make(ENVS[name], **options)
                       for suffix, options in evaluation_options(name).items()}
        results = {label: {} if args.no_baselines else baselines(name, env, seeds)
                   for label, env in evaluations.items()}
        for algo in args.algos:
            if args.load_dir:  # evaluate a saved model (a checkpoint of an earlier run) instead of training
                import pathlib

                from stable_baselines3 import PPO, SAC
                from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

                import torch

                torch.set_num_threads(1)
                source = pathlib.Path(args.load_dir)
                model = (PPO if algo == "ppo" else SAC).load(source / f"{name}_{algo}.zip", device="cpu")
                vec = VecNormalize.load(str(source / f"{name}_{algo}_vecnormalize.pkl"),
                                        DummyVecEnv([lambda: gym.make(ENVS[name], **env_options(name))]))
                vec.training = False
                label = f"{algo.upper()} ({source / f'{name}_{algo}.zip'}, {model.num_timesteps} steps)"
                for where, env in evaluations.items():
                    results[where].update(evaluation_rows(name, label, *evaluate(model, vec, env, seeds)))
                continue
            save = None
            if args.save_dir:
                import pathlib

                out = pathlib.Path(args.save_dir)
                out.mkdir(parents=True, exist_ok=True)

                def save(model, vec, name=name, algo=algo, out=out):  # (at each row of the curve, and at the end)
                    model.save(out / f"{name}_{algo}.zip")
                    vec.save(str(out / f"{name}_{algo}_vecnormalize.pkl"))

            model, vec, curve, rate = train(name, algo, args.timesteps, args.seed, n_envs=args.n_envs,
                                            rows=args.curve_rows, checkpoint=save)
            if save is not None:
                save(model, vec)
            print(f"  {algo.upper()} learning curve (steps: mean training return over the episodes since the last row):")
            for steps, mean, count in curve:
                print(f"    {steps:>8}: {mean:10.1f}  ({count} episodes)")
            envs = f", {args.n_envs} envs" if args.n_envs > 1 else ""
            label = f"{algo.upper()} ({args.timesteps} steps{envs}, {rate:.0f} steps/s)"
            for where, env in evaluations.items():
                results[where].update(evaluation_rows(name, label, *evaluate(model, vec, env, seeds)))
        for where, rows in results.items():
            for label, value in rows.items():
                shown = value if isinstance(value, str) else f"{value:.1f}"
                print(f"  {where:<24} {label:<48} {shown:>10}", flush=True)
                table.append((where, label, shown))
    print("\n| environment | policy | mean return |\n|---|---|---|")
    for name, label, shown in table:
        print(f"| {name} | {label.strip()} | {shown} |")


if __name__ == "__main__":
    main()
