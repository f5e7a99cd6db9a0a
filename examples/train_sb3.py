"""Train a Stable-Baselines3 agent on one of the environments, evaluate it, save it.

Default hyperparameters, observations and rewards normalised by VecNormalize, as for
Gymnasium's MuJoCo tasks. Needs the extra ``rl``; on this machine install torch first with
``pip install torch==2.13.0`` (the local CPU build), then ``pip install -e ".[rl]"``.

    python examples/train_sb3.py --env Driving --timesteps 20000          # a quick look
    python examples/train_sb3.py --env GainTuning --algo sac --timesteps 200000 --save gains.zip
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import biso_cosim.envs  # noqa: F401  (registers the ids: make_vec_env takes the plain id)
from biso_cosim.envs.training import algo_options, env_options

ENVS = {"AttitudeEstimation": "biso_cosim/AttitudeEstimation-v0", "GainTuning": "biso_cosim/GainTuning-v0",
        "Driving": "biso_cosim/Driving-v0"}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Driving", choices=list(ENVS))
    parser.add_argument("--algo", default="ppo", choices=["ppo", "sac"])
    parser.add_argument("--timesteps", type=int, default=20_000)
    parser.add_argument("--n-envs", type=int, default=1, help="vector environments (one process each when > 1)")
    parser.add_argument("--episodes", type=int, default=3, help="evaluation episodes (seeds 1000, 1001, ...)")
    parser.add_argument("--save", default=None, help="path of the saved model (.zip; its VecNormalize next to it)")
    args = parser.parse_args()

    import torch
    from stable_baselines3.common.vec_env import SubprocVecEnv

    torch.set_num_threads(1)  # (a second intra-op thread only spins for SB3's small networks on 2 cores)

    options = env_options(args.env)  # (and the hyperparameters: what benchmarks/rl_baselines.py trains with)
    vec = make_vec_env(ENVS[args.env], n_envs=args.n_envs, seed=0, env_kwargs=options,
                       vec_env_cls=SubprocVecEnv if args.n_envs > 1 else None)
    hyperparameters = algo_options(args.env)
    vec = VecNormalize(vec, gamma=hyperparameters.get("gamma", 0.99))
    model = (PPO if args.algo == "ppo" else SAC)("MlpPolicy", vec, seed=0, verbose=1, device="cpu", **hyperparameters)
    model.learn(total_timesteps=args.timesteps)
    vec.training = False
    if args.save:
        model.save(args.save)
        vec.save(args.save.removesuffix(".zip") + "_vecnormalize.pkl")

    env = gym.make(ENVS[args.env], **options)
    returns = []
    for seed in range(1000, 1000 + args.episodes):
        obs, info = env.reset(seed=seed)
        total = 0.0
        while True:
            action, _ = model.predict(vec.normalize_obs(obs[None]), deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action[0])
            # the task's measure: without the terms the training options add for the learner
            # (AttitudeEstimation's and GainTuning's shaping, GainTuning's reference copy)
            total += float(info.get("reward_attitude", reward))
            if terminated or truncated:
                break
        returns.append(total)
        print(f"seed {seed}: return {total:.1f}")
    print(f"mean return over {args.episodes} episodes: {np.mean(returns):.1f}")


if __name__ == "__main__":
    main()
