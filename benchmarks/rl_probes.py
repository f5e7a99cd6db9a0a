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

``--signal`` asks instead whether the reward of each step shows the effect of the exploration
noise, which is what a policy gradient estimates: a Gaussian policy around a fixed mean, and
per step the product of the noise ε_t of one action component with the sum of the rewards
that the action can have moved before the next decision could (AttitudeEstimation: the step's
own reward, the correction acts at once; GainTuning: the rewards of the steps within the gains'
lag τ, which carries the action into the gains in force). The probe prints the t statistic
of the mean product over all steps of the episodes (mean / standard error: |t| > 3 is an
effect the noise of these episodes does not explain) for the reward the learner is given
(with the training options of ``biso_cosim.envs.training``) and for the task's measure
(``reward_attitude``), and the standard deviation of both per step:

    python benchmarks/rl_probes.py --signal --seeds 1000 1001 1002 1003 1004
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


def signal_settings(name):
    """(label, environment arguments, noise standard deviation, means, component, lag in steps) of
    the ``--signal`` probe: the training options of ``biso_cosim.envs.training`` and the same
    without the reward terms they add (shaping, the reference copy) or the task changes."""
    from biso_cosim.envs.training import env_options

    options = env_options(name)
    if name == "AttitudeEstimation":
        linear = {**options, "correction_scale": "linear", "correction_time_constant_s": 10.0}
        calibrated = {k: v for k, v in linear.items() if k not in ("sensor_profile", "gyro_calibration_s")}
        calibrated["correction_time_constant_s"] = 100.0  # (the first round's cap)
        return [("raw part, linear up to a 10 s pull", linear, 0.135, (0.0, 0.3), 2, 1),
                ("calibrated part, cap 100 s", calibrated, 0.135, (0.0, 0.3), 2, 1)]
    # the cutoff's component around a cutoff too high (1.7 Hz) and too low (0.012 Hz), r = 0
    means = ((0.5, -1.0), (-0.5, -1.0))
    lag = int(round(options.get("control_rate_hz", 50.0)))  # (τ = 1 s of steps)
    bare = {k: v for k, v in options.items() if k not in ("reference_action", "shaping_gamma")}
    return [("training options", options, 0.57, means, 0, lag),
            ("without shaping", {k: v for k, v in options.items() if k != "shaping_gamma"}, 0.57, means, 0, lag),
            ("without shaping and reference", bare, 0.57, means, 0, lag),
            ("defaults (50 Hz; 2026-12-07)", {}, 0.57, means, 0, 50)]


def signal(name, seeds):
    """Print the ``--signal`` probe of one task (see the module's docstring)."""
    print(f"== {name}: t of (noise of one action component) x (rewards it can move), seeds {seeds}", flush=True)
    for label, kwargs, std, means, component, lag in signal_settings(name):
        env = gym.make(f"biso_cosim/{name}-v0", **kwargs)
        shape = env.action_space.shape
        for mean in means:
            mean = np.broadcast_to(np.asarray(mean, dtype=float), shape)
            rng = np.random.default_rng(0)
            products, given, task = {"given": [], "task": []}, [], []
            for seed in seeds:
                env.reset(seed=seed)
                noise, rewards, measures = [], [], []
                while True:
                    eps = rng.normal(0.0, std, shape)
                    _, reward, terminated, truncated, info = env.step(np.clip(mean + eps, -1.0, 1.0).astype(np.float32))
                    noise.append(eps[component])
                    rewards.append(float(reward))
                    measures.append(float(info["reward_attitude"]))
                    if terminated or truncated:
                        break
                noise = np.array(noise)
                for key, series in (("given", np.array(rewards)), ("task", np.array(measures))):
                    ahead = np.convolve(series, np.ones(lag))[lag - 1:]  # sum of series[t:t + lag]
                    products[key].append(noise * ahead)
                given += rewards
                task += measures
            t = {key: np.concatenate(v) for key, v in products.items()}
            t = {key: v.mean() / v.std() * np.sqrt(v.size) for key, v in t.items()}
            print(f"  {label:<36} noise {std:g} around {np.round(mean, 2).tolist()}: t given {t['given']:6.2f}, "
                  f"task {t['task']:6.2f}; sd per step given {np.std(given):.4g}, task {np.std(task):.4g}",
                  flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["GainTuning", "AttitudeEstimation"],
                        choices=["GainTuning", "AttitudeEstimation"])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1000, 1001], help="episode seeds")
    parser.add_argument("--settings", nargs="+", default=None, help="only the environment settings whose label "
                                                                    "starts with one of these (e.g. 'cap 100')")
    parser.add_argument("--signal", action="store_true", help="the signal probe (see above) instead of the returns")
    args = parser.parse_args()
    if args.signal:
        for name in args.envs:
            signal(name, args.seeds)
        return
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
