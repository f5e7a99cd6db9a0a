"""Why a Gaussian policy learns GainTuning and AttitudeEstimation only with the designs of
2026-12-07: the return of scripted policies that explore as PPO does, with and without them.

PPO's policy is a Gaussian around its mean action (standard deviation 1 at the start,
clipped to the action space). In both tasks the action sets how strongly a feedback
estimator corrects itself, and the estimator remembers: a few steps of large gains undo
many steps of small ones. The probes show whether the return still depends on the mean
action when noise is added to it (if it does not, a policy gradient has nothing to follow):

* GainTuning: the best single constant of the evaluation episodes (f_c = 0.14 Hz, r = 0),
  that constant with Gaussian noise (standard deviation 0.57, the trained policy's of the
  2026-12-04 run), and uniform random actions, each with the gains' lag
  (``gain_time_constant_s``, default 1 s) and without it (0).
* AttitudeEstimation, ``action_type="correction"``: constant actions (0: gyro dead reckoning;
  c > 0: a complementary filter pulling the fraction c · (1 − exp(−dt/τ)) of the innovation
  each step) and Gaussian actions of standard deviation 1 around the means 0, -1 and -2 (and
  of 0.14, the trained baselines' initial noise, around 0 and 0.5), with gains of 1 pulling
  all the way to the accelerometer+magnetometer attitude (``correction_time_constant_s=0``),
  with the default cap (τ = 1 s: 2 % a step) and with the trained baselines' (τ = 100 s).

    python benchmarks/rl_probes.py              # seeds 1000 and 1001, about 6 minutes
    python benchmarks/rl_probes.py --envs AttitudeEstimation --settings "cap 100" --seeds 1000 1001 1002 1003 1004
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import biso_cosim.envs  # noqa: F401  (registers the ids)


def episode_return(env, policy, seed):
    obs, _ = env.reset(seed=seed)
    total = 0.0
    while True:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        total += float(reward)
        if terminated or truncated:
            return total


def gaussian(mean, std, rng):
    """A clipped Gaussian policy around a fixed mean action."""
    mean = np.asarray(mean, dtype=float)
    return lambda obs: np.clip(mean + rng.normal(0.0, std, mean.shape), -1.0, 1.0).astype(np.float32)


def probes(name):
    """(environment argument sets, policies) of one task: label -> kwargs, label -> policy maker."""
    if name == "GainTuning":
        best = [0.0, -1.0]  # f_c = sqrt(0.001 * 20) = 0.141 Hz, r = 0
        return ({"lag 0": {"gain_time_constant_s": 0.0}, "lag 1 s": {}},
                {"constant f_c 0.14 Hz, r 0": lambda rng: (lambda obs: np.array(best, dtype=np.float32)),
                 "same + noise 0.57": lambda rng: gaussian(best, 0.57, rng),
                 "uniform random": lambda rng: (lambda obs: rng.uniform(-1.0, 1.0, 2).astype(np.float32))})
    return ({"cap 0 (gain 1 = memoryless)": {"action_type": "correction", "correction_time_constant_s": 0.0},
             "cap 1 s": {"action_type": "correction"},
             "cap 100 s (training.py)": {"action_type": "correction", "correction_time_constant_s": 100.0}},
            {**{f"constant {c:g}": (lambda rng, c=c: (lambda obs: np.full(3, c, dtype=np.float32)))
                for c in (0.0, 0.005, 0.05, 0.25, 0.5, 1.0)},
             **{f"noise 1 around {m:g}": (lambda rng, m=m: gaussian([m] * 3, 1.0, rng)) for m in (0.0, -1.0, -2.0)},
             **{f"noise 0.14 around {m:g}": (lambda rng, m=m: gaussian([m] * 3, 0.135, rng)) for m in (0.0, 0.5)}})


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["GainTuning", "AttitudeEstimation"],
                        choices=["GainTuning", "AttitudeEstimation"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1000, 1001], help="episode seeds")
    parser.add_argument("--settings", nargs="+", default=None, help="only the environment settings whose label "
                                                                    "starts with one of these (e.g. 'cap 100')")
    args = parser.parse_args()
    for name in args.envs:
        settings, policies = probes(name)
        print(f"== {name}: return per seed {args.seeds}", flush=True)
        for setting, kwargs in settings.items():
            if args.settings and not any(setting.startswith(prefix) for prefix in args.settings):
                continue
            env = gym.make(f"biso_cosim/{name}-v0", **kwargs)
            for label, make in policies.items():
                rng = np.random.default_rng(0)
                returns = [episode_return(env, make(rng), seed) for seed in args.seeds]
                print(f"  {setting:<28} {label:<28} " + " ".join(f"{r:9.1f}" for r in returns), flush=True)


if __name__ == "__main__":
    main()
