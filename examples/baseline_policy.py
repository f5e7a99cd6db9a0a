"""Evaluate the BISO baseline as a policy in AttitudeEstimation-v0, next to simpler policies.

A policy sees only the observation: the IMU samples of the last step (here in full float64
precision, ``physical_observation()``: the values the float32 observation is scaled from). ``BisoPolicy`` runs
the faithful BISO estimator (Aleshkin et al. 2024) on them and answers with its attitude;
it scores exactly the environment's own reference (``info["baseline_error_rad"]``), which
this script checks. For scale, three more policies: BISO tuned to a 0.05 Hz cutoff without
cross-links, the package's biso_plus (here without the wheel-speed input it can take), and
the attitude from the newest accelerometer and magnetometer sample alone.

    python examples/baseline_policy.py                 # 3 episodes of figure8, about a minute
    python examples/baseline_policy.py --episodes 5 --route random
"""

from __future__ import annotations

import argparse
import math

import gymnasium as gym
import numpy as np

import biso_cosim.envs  # noqa: F401  (registers biso_cosim/AttitudeEstimation-v0)
from biso_cosim.envs import IMU_FIELDS
from biso_cosim.estimators import make_estimator, reference_attitude


class BisoPolicy:
    """An estimator from ``biso_cosim.estimators`` fed with the observed samples."""

    def __init__(self, env, name="biso", **params):
        core = env.unwrapped
        self.core = core
        # the site's magnetic declination is map knowledge a real system has too
        declination = core.sim.earth.declination_rad
        self.estimator = make_estimator(name, core.imu_rate_hz, declination_rad=declination, **params)

    def reset(self):
        self.estimator.reset()

    def __call__(self, obs):
        imu = self.core.physical_observation()["imu"]  # (the observation's samples, exactly)
        new = imu[:, IMU_FIELDS.index("new")] == 1.0  # rows that arrived during the last step
        return self.estimator.update(imu[new, 0:3], imu[new, 3:6], imu[new, 6:9]).q_wb[-1]


class AccelMagPolicy:
    """Attitude from the newest accelerometer and magnetometer sample alone (no gyro)."""

    def __init__(self, env):
        core = env.unwrapped
        self.core = core
        self.declination = core.sim.earth.declination_rad

    def reset(self):
        self.last = np.array([1.0, 0.0, 0.0, 0.0])

    def __call__(self, obs):
        imu = self.core.physical_observation()["imu"]
        q = reference_attitude(imu[-1:, 3:6], imu[-1:, 6:9], declination_rad=self.declination)[0]
        if np.all(np.isfinite(q)):  # (NaN only for a zero specific force)
            self.last = q
        return self.last


def evaluate(env, policy, seeds):
    """Mean return and mean error (deg) over one episode per seed; checks the BISO identity."""
    returns, errors, baseline_errors = [], [], []
    for seed in seeds:
        obs, info = env.reset(seed=seed)
        policy.reset()
        total, steps, baseline = 0.0, 0, 0.0
        while True:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            total += reward
            baseline += info["baseline_error_rad"]
            steps += 1
            if terminated or truncated:
                break
        returns.append(total)
        errors.append(math.degrees(-total / steps))
        baseline_errors.append(math.degrees(baseline / steps))
    return float(np.mean(returns)), float(np.mean(errors)), float(np.mean(baseline_errors))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--route", default="figure8", help="library route or 'random'")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds per episode")
    args = parser.parse_args()

    env = gym.make("biso_cosim/AttitudeEstimation-v0", route=args.route, episode_duration_s=args.duration)
    seeds = list(range(args.episodes))
    policies = {
        "BISO, paper gains (the baseline)": BisoPolicy(env),
        # the positional correction without cross-links (k_p = 0), k for a 0.05 Hz design
        "BISO, 0.05 Hz, no cross-links": BisoPolicy(env, name="positional", k=2 * math.pi * 0.05 / math.sqrt(2.0)),
        "biso_plus (no speed input)": BisoPolicy(env, name="biso_plus"),
        "accelerometer + magnetometer only": AccelMagPolicy(env),
    }
    print(f"{args.episodes} episode(s) of {args.duration:g} s on {args.route!r}, {env.unwrapped.imu_rate_hz:g} Hz IMU")
    print(f"{'policy':<36} {'mean return':>12} {'mean error °':>13} {'baseline °':>11}")
    for name, policy in policies.items():
        mean_return, error_deg, baseline_deg = evaluate(env, policy, seeds)
        print(f"{name:<36} {mean_return:>12.2f} {error_deg:>13.3f} {baseline_deg:>11.3f}")
        if "baseline" in name:
            # the policy is the environment's reference estimator: identical errors
            assert error_deg == baseline_deg, (error_deg, baseline_deg)


if __name__ == "__main__":
    main()
