"""Gymnasium environments: attitude estimation in the loop of a simulated car.

Three environments, each in its own module, registered under the ``biso_cosim`` namespace:

| id | module | the agent |
|---|---|---|
| ``biso_cosim/AttitudeEstimation-v0`` | :mod:`~biso_cosim.envs.attitude_estimation` | estimates the attitude from the IMU samples; reward −angle error |
| ``biso_cosim/GainTuning-v0`` | :mod:`~biso_cosim.envs.gain_tuning` | sets the BISO (or biso_plus) correction gains; reward −the estimator's error |
| ``biso_cosim/Driving-v0`` | :mod:`~biso_cosim.envs.driving` | drives the car from what a car measures; reward progress − cross-track − roll-over |

Make one without importing anything first (Gymnasium imports ``biso_cosim``, which
registers the ids)::

    import gymnasium as gym
    env = gym.make("biso_cosim:biso_cosim/AttitudeEstimation-v0", route="figure8")

or, after ``import biso_cosim.envs``, with the plain id ``"biso_cosim/AttitudeEstimation-v0"``.
Importing this package is light: it imports neither MuJoCo nor numba; the environment
modules are loaded by ``gym.make`` through their entry points.
"""

from __future__ import annotations

import importlib

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "register_envs", "AttitudeEstimationEnv", "GainTuningEnv", "DrivingEnv", "random_route",
           "reference_markdown", "IMU_FIELDS", "GNSS_FIELDS", "ResetNeeded"]

ENV_IDS: dict[str, str] = {
    "biso_cosim/AttitudeEstimation-v0": "biso_cosim.envs.attitude_estimation:AttitudeEstimationEnv",
    "biso_cosim/GainTuning-v0": "biso_cosim.envs.gain_tuning:GainTuningEnv",
    "biso_cosim/Driving-v0": "biso_cosim.envs.driving:DrivingEnv",
}
"""Environment id → entry point (``module:class``)."""

MAX_EPISODE_STEPS: dict[str, int] = {
    "biso_cosim/AttitudeEstimation-v0": 5000,
    "biso_cosim/GainTuning-v0": 5000,
    "biso_cosim/Driving-v0": 10000,
}
"""``max_episode_steps`` of the registrations: 100 s (Driving 200 s) at the default 50 Hz,
more than any default episode of ``figure8`` (3250, 3250 and 4600 steps) and of the
procedural routes, which the environments truncate themselves at ``episode_duration_s``.
Pass ``max_episode_steps=`` to ``gym.make`` for longer routes or other rates."""

_LAZY = {
    "AttitudeEstimationEnv": "biso_cosim.envs.attitude_estimation",
    "GainTuningEnv": "biso_cosim.envs.gain_tuning",
    "DrivingEnv": "biso_cosim.envs.driving",
    "random_route": "biso_cosim.envs.procedural",
    "reference_markdown": "biso_cosim.envs._docs",
    "IMU_FIELDS": "biso_cosim.envs._common",
    "GNSS_FIELDS": "biso_cosim.envs._common",
    "ResetNeeded": "biso_cosim.envs._common",
}


def register_envs() -> None:
    """Register the environments with Gymnasium (idempotent; imports no MuJoCo)."""
    import gymnasium

    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point, max_episode_steps=MAX_EPISODE_STEPS[env_id])


register_envs()


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'biso_cosim.envs' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
