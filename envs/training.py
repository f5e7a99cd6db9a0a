"""What the trained baselines change from the defaults (``benchmarks/rl_baselines.py`` and
``examples/train_sb3.py``): environment arguments and Stable-Baselines3 hyperparameters per
environment. docs/envs.md ("Why PPO did not learn") gives the evidence for each.

This module imports neither torch nor Stable-Baselines3.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ENV_OPTIONS", "ALGO_OPTIONS", "algo_options", "env_options"]

ENV_OPTIONS: dict[str, dict[str, Any]] = {
    "AttitudeEstimation": {"action_type": "correction", "correction_time_constant_s": 100.0},
    "Driving": {"route": "random"},
}
"""Environment arguments besides the defaults: AttitudeEstimation's agent corrects its
gyro-propagated estimate (the residual formulation) with gains up to the pull of a 100 s time
constant: on the default calibrated part the best constant pull is about 1/200 s
(`benchmarks/rl_probes.py`), half this range, where with the default 1 s it would be 0.5 % of
the range and the exploration noise alone would pull harder; the driving agent trains on a new
procedural route every episode (it is evaluated there and on ``figure8``, which it never
drove in training)."""

ALGO_OPTIONS: dict[str, dict[str, Any]] = {
    "AttitudeEstimation": {"policy_kwargs": {"log_std_init": -2.0}},
    "GainTuning": {"gamma": 0.999},
    "Driving": {"gamma": 0.995},
}
"""Hyperparameters besides SB3's defaults: AttitudeEstimation's residual policy starts with
exploration noise of standard deviation e^-2 = 0.14 instead of 1, as residual policies do
(Silver et al. 2018, Johannink et al. 2019), so that its training episodes stay near the
estimator its zero action is; GainTuning discounts with γ = 0.999 (a horizon of 1000 steps,
20 s) instead of 0.99 (2 s): the gains' effects (the gyro's drift under too little correction,
the cross-link's bias estimate) play out over seconds to tens of seconds; Driving with
γ = 0.995 (4 s, about 30 m of road at the pursuit driver's speed) instead of 0.99 (2 s,
less than the distance a fast car needs to slow for a turn). ``VecNormalize``
scales the rewards with the same γ."""


def env_options(name: str) -> dict[str, Any]:
    """The environment arguments of the environment ``name`` ("AttitudeEstimation", ...)."""
    return dict(ENV_OPTIONS.get(name, {}))


def algo_options(name: str) -> dict[str, Any]:
    """The hyperparameters (keyword arguments of the SB3 algorithm) for the environment ``name``."""
    return dict(ALGO_OPTIONS.get(name, {}))
