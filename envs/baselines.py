"""Scripted policies for the environments: the information baselines an agent is judged
against (``benchmarks/rl_baselines.py``), each seeing only the observation.

* ``PursuitDriver`` (Driving-v0): pure pursuit (Coulter 1992, the steering law
  δ = atan(2 L sin α / l_d)) on the observed route ahead, with a look-ahead point chosen by
  speed, a correction of the observed offset from the centre line, and a speed that slows for
  the curvature ahead (a_lat ≤ ``lateral_accel_mps2``), from the undriven front wheels; the
  offset terms are none: the route ahead is observed in the car's frame already.
* ``AccelMagAttitude`` (AttitudeEstimation-v0): the memoryless attitude from the newest
  accelerometer and magnetometer sample (TRIAD, ``reference_attitude``), what a policy of
  one step's samples alone is capped at.
* ``FeedbackFilter`` (AttitudeEstimation-v0): a complementary filter that uses the
  observation alone: its own previous estimate (fed back in the observation) propagated
  with the step's gyro samples, pulled towards the accelerometer+magnetometer attitude by
  ``gain`` per step. It shows that the observation holds what an estimator needs.
* ``paper_gains`` (GainTuning-v0): the constant action of the paper's gains.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["PursuitDriver", "AccelMagAttitude", "FeedbackFilter", "paper_gains"]


class PursuitDriver:
    """Pure pursuit on Driving-v0's observation (a callable: observation → action).

    The look-ahead distance is ``lookahead_s`` × speed, at least ``min_lookahead_m``; the
    target speed is ``speed_mps``, lowered so that the curvature of the route ahead
    (from the observed points) keeps the lateral acceleration under ``lateral_accel_mps2``.
    Throttle is proportional to the speed error (``speed_gain`` per m/s), at most
    ``max_throttle``.
    """

    def __init__(self, env: Any, speed_mps: float = 8.5, lookahead_s: float = 0.9, min_lookahead_m: float = 4.0,
                 lateral_accel_mps2: float = 3.0, speed_gain: float = 0.4, max_throttle: float = 0.4):
        self.core = env.unwrapped
        self.wheelbase_m = float(self.core.sim.vehicle.driver.wheelbase_m)
        self.max_steer_rad = float(self.core.sim.vehicle.parameters["max_steer_rad"])
        self.speed_mps, self.lookahead_s, self.min_lookahead_m = speed_mps, lookahead_s, min_lookahead_m
        self.lateral_accel_mps2, self.speed_gain, self.max_throttle = lateral_accel_mps2, speed_gain, max_throttle

    def reset(self) -> None:
        """(No state between steps.)"""

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        p = self.core.split_observation(observation)
        ahead = p["route_ahead"]
        v = float(p["wheel_speed_mps"][:2].mean())
        distances = np.hypot(ahead[:, 0], ahead[:, 1])
        lookahead = max(self.min_lookahead_m, self.lookahead_s * v)
        i = int(min(np.searchsorted(distances, lookahead), len(distances) - 1))
        x, y = ahead[i]
        alpha = math.atan2(y, x)
        steer = math.atan(2.0 * self.wheelbase_m * math.sin(alpha) / max(math.hypot(x, y), 1e-3))
        # curvature ahead: the largest turn between successive chords of the preview
        headings = np.unwrap(np.arctan2(np.diff(ahead[:, 1]), np.diff(ahead[:, 0])))
        chords = np.hypot(np.diff(ahead[:, 0]), np.diff(ahead[:, 1]))
        curvature = float(np.max(np.abs(np.diff(headings)) / np.maximum(chords[1:], 1e-3))) if len(headings) > 1 else 0.0
        target = min(self.speed_mps, math.sqrt(self.lateral_accel_mps2 / max(curvature, 1e-6)))
        # gentle on the throttle: hard acceleration tilts the estimator's attitude, and the
        # heading error it leaves turns into a cross-track error of the dead-reckoned pose
        throttle = min(self.speed_gain * (target - v), self.max_throttle)
        return np.clip([throttle, steer / self.max_steer_rad], -1.0, 1.0).astype(np.float32)


def paper_gains(env: Any) -> np.ndarray:
    """GainTuning-v0's constant action for the gains its baseline copy runs with (the
    paper's, for BISO): the normalised action of the baseline's tuned values, clipped."""
    return np.clip(env.unwrapped.baseline_action, -1.0, 1.0).astype(np.float32)


class AccelMagAttitude:
    """The attitude of the newest accelerometer and magnetometer sample of the observation."""

    def __init__(self, env: Any):
        self.core = env.unwrapped
        self.declination_rad = self.core.sim.earth.declination_rad  # map knowledge a real system has

    def reset(self) -> None:
        self.last = np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32)

    def attitude(self, imu: np.ndarray) -> np.ndarray | None:
        from biso_cosim.estimators import reference_attitude

        q = reference_attitude(imu[-1:, 3:6], imu[-1:, 6:9], declination_rad=self.declination_rad)[0]
        return q if np.all(np.isfinite(q)) else None  # (NaN only for a zero specific force)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        q = self.attitude(self.core.split_observation(observation)["imu"])
        if q is not None:
            self.last = q.astype(np.float32)
        return self.last


class FeedbackFilter(AccelMagAttitude):
    """q ← (q_prev ⊗ exp(½ Σ ω_i Δt)) blended towards the accelerometer+magnetometer
    attitude by ``gain`` (normalised linear interpolation), q_prev from the observation."""

    def __init__(self, env: Any, gain: float = 0.005):
        super().__init__(env)
        self.gain = gain
        self.dt_s = 1.0 / self.core.imu_rate_hz
        self._started = False

    def reset(self) -> None:
        super().reset()
        self._started = False

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        from biso_cosim.frames import quat_from_rotvec, quat_multiply

        parts = self.core.split_observation(observation)
        imu, q = parts["imu"], parts["estimate_q_wb"]
        measured = self.attitude(imu)
        if not self._started:  # the first action: the measured attitude
            self._started = measured is not None
            return (measured if measured is not None else q).astype(np.float32)
        for omega in imu[:, 0:3]:  # (with rates that divide, every row is this step's)
            q = quat_multiply(q, quat_from_rotvec(omega * self.dt_s))
        if measured is not None:
            if np.dot(measured, q) < 0.0:
                measured = -measured
            q = (1.0 - self.gain) * q + self.gain * measured
        q = q / np.linalg.norm(q)
        return (q if q[0] >= 0.0 else -q).astype(np.float32)
