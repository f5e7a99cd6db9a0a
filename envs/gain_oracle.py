"""The oracle of GainTuning-v0: the best constant gains of an episode, found by search.

For an episode (its route, sensor part and noise from the episode seed), one co-simulation
runs many copies of the estimator side by side, one per candidate tuning on a grid (the
same samples for all: the sensor and the car do not depend on the gains), and scores each
by the task's measure, the mean over the samples of the angle to the true attitude. The
best grid point is then refined by a golden-section search along each parameter in turn.
Evaluating the best tuning as a constant action in the environment gives the oracle's return.
"""

from __future__ import annotations

import itertools
import math
from typing import Any, Sequence

import numpy as np

from biso_cosim.cosim import CoSimulation, EstimatorSpec
from biso_cosim.frames import quat_angle_between

__all__ = ["episode_errors", "oracle_action"]


def episode_errors(env: Any, seed: int, actions: Sequence[np.ndarray]) -> np.ndarray:
    """Mean attitude error (rad) over the episode of ``seed`` of each constant normalised
    ``action``, all in one co-simulation of that episode."""
    core = env.unwrapped
    _, info = env.reset(seed=seed)
    fixed = dict(core.estimator_params)
    specs = [EstimatorSpec(core.estimator, {**fixed, **core.estimator_changes(core.params_from_action(a))}, label=f"a{i}")
             for i, a in enumerate(actions)]
    sim = CoSimulation(core.route, duration_s=core.sim.duration_s, seed=info["sensor_seed"], estimators=specs,
                       sensor_profile=core.sim.imu.profile, registers=core.sim.registers,
                       gyro_calibration_s=core.sim.gyro_calibration_s, physics_rate_hz=core.sim.vehicle.physics_rate_hz,
                       control_rate_hz=core.sim.vehicle.control_rate_hz, gnss=None, keep_log=True)
    result = sim.run()
    q_true = result.truth.q_wb
    return np.array([float(np.mean(quat_angle_between(result.estimates[s.label][0], q_true))) for s in specs])


def _golden(f, lo: float, hi: float, iterations: int) -> tuple[float, float]:
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(iterations):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = f(d)
    return (c, fc) if fc < fd else (d, fd)


def oracle_action(env: Any, seed: int, points: int = 9, refine: int = 0) -> tuple[np.ndarray, float]:
    """The best constant normalised action of the episode of ``seed`` and its mean error
    (rad): a grid of ``points`` per tuned parameter over [-1, 1], then ``refine`` rounds of
    golden-section search along each parameter (one co-simulation per evaluation)."""
    m = env.action_space.shape[0]
    axis = np.linspace(-1.0, 1.0, points)
    grid = [np.array(p) for p in itertools.product(axis, repeat=m)]
    errors = episode_errors(env, seed, grid)
    best = grid[int(np.argmin(errors))].copy()
    best_error = float(errors.min())
    step = 2.0 / (points - 1)
    for _ in range(refine):
        for i in range(m):
            def f(x, i=i):
                a = best.copy()
                a[i] = x
                return float(episode_errors(env, seed, [a])[0])
            x, e = _golden(f, max(best[i] - step, -1.0), min(best[i] + step, 1.0), 6)
            if e < best_error:
                best[i], best_error = x, e
    return best.astype(np.float32), best_error
