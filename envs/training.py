"""What the trained baselines change from the defaults (``benchmarks/rl_baselines.py`` and
``examples/train_sb3.py``): environment arguments and Stable-Baselines3 hyperparameters per
environment. docs/envs.md ("Why PPO did not learn") gives the evidence for each.

This module imports neither torch nor Stable-Baselines3.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ENV_OPTIONS", "ALGO_OPTIONS", "algo_options", "env_options"]

ENV_OPTIONS: dict[str, dict[str, Any]] = {
    "AttitudeEstimation": {"action_type": "correction", "sensor_profile": "mpu9250", "gyro_calibration_s": 2.0,
                           "correction_scale": "log", "shaping_gamma": 0.99},
    "GainTuning": {"control_rate_hz": 10.0, "reference_action": (0.0, 0.0), "observe_attitude": False,
                   "observe_imu": False, "innovation_time_constant_s": 10.0, "shaping_gamma": 0.99},
    "Driving": {"route": "random", "control_rate_hz": 10.0},
}
"""Environment arguments besides the defaults (docs/envs.md, "Why PPO did not learn" and
"AttitudeEstimation and GainTuning, second round", gives the evidence for each):

* AttitudeEstimation: the residual agent (``action_type="correction"``) on a raw MPU-9250 part
  after its start-up gyro calibration (``sensor_profile="mpu9250"``, ``gyro_calibration_s=2``:
  the calibrated default part's gyro drifts so little in an episode that no correction is
  worth more than a few per cent, concentrated in one episode of five; the raw part's scale
  factors and misalignments make the correction worth a third of the error), the pulls' time
  constants on a logarithmic scale (``correction_scale="log"``: 1 s to 1000 s, the zero action
  31.6 s, near the best constant pulls of 33 s in heading and 100 s in tilt, so that the
  policy's mean starts at a good estimator and its noise scales the pull instead of switching it
  off below a = 0), and the potential-based shaping with the learner's γ = 0.99
  (``shaping_gamma``: each step's reward then shows its own correction instead of the error level
  inherited from all earlier steps).
* GainTuning: decisions at 10 Hz (``control_rate_hz``: the gains act over seconds), the
  reference copy at the zero action's gains (``reference_action``: the part of each step's
  error any nearby tuning shares), the attitude out of the observation (``observe_attitude``:
  its heading says nothing about the gains, and the trained policies fitted them to it), the
  IMU samples out of it too (``observe_imu``: they change every step, the best gains are nearly a
  constant per episode, and the trained policy's mean followed them step to step) with 10 s
  statistics of the tuned estimator's innovation instead (``innovation_time_constant_s``:
  features that change over the gains' time scale and show the part's gyro bias; docs/envs.md,
  "GainTuning, third round"), and the shaping with γ = 0.99 (SB3's default: 10 s at 10 Hz).
* Driving: a new procedural route every episode (it is evaluated there and on ``figure8``,
  which it never drove in training), and decisions at 10 Hz (``control_rate_hz``: a rollout
  of 2 048 steps then holds about four episodes instead of one, the same wall time drives
  2.6 times as far, and SB3's default γ = 0.99 looks 10 s ahead, enough to slow for a turn; at
  50 Hz with γ = 0.995 PPO finished no route in 500 000 steps, at 10 Hz its 180 000-step
  checkpoint finished 4 of 5 evaluation seeds of each, docs/envs.md "Driving at 10 Hz").
"""

ALGO_OPTIONS: dict[str, dict[str, Any]] = {
    "AttitudeEstimation": {"policy_kwargs": {"log_std_init": -2.0}},
}
"""Hyperparameters besides SB3's defaults: AttitudeEstimation's residual policy starts with
exploration noise of standard deviation e^-2 = 0.14 instead of 1, as residual policies do
(Silver et al. 2018, Johannink et al. 2019), so that its training episodes stay near the
estimator its zero action is; GainTuning and Driving take SB3's defaults (γ = 0.99 is 10 s
at their 10 Hz decisions: over it the gains' effects play out, and a car slows for a turn).
``VecNormalize`` scales the rewards with the same γ."""


def env_options(name: str) -> dict[str, Any]:
    """The environment arguments of the environment ``name`` ("AttitudeEstimation", ...)."""
    return dict(ENV_OPTIONS.get(name, {}))


def algo_options(name: str) -> dict[str, Any]:
    """The hyperparameters (keyword arguments of the SB3 algorithm) for the environment ``name``."""
    return dict(ALGO_OPTIONS.get(name, {}))
