"""``biso_cosim/AttitudeEstimation-v0``: the agent is the attitude estimator."""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle

from biso_cosim.cosim import DEFAULT_SENSOR_PROFILE, EstimatorSpec
from biso_cosim.loop import PeriodWork
from biso_cosim.envs._common import (COMMON_ARGUMENTS, CosimEnv, Scale, _check_number, _check_shaping_gamma,
                                      _shaping_reward)
from biso_cosim.envs._docs import finish_docstring
from biso_cosim.envs._kernels import _angle, _angles_to, _attitude_work, _corrected, _correction_work, _log_gains
from biso_cosim.frames import quat_from_euler
from biso_cosim.routes import Route
from biso_cosim.vehicle.sim import Truth

__all__ = ["AttitudeEstimationEnv"]

_ACTION_TYPES = ("quaternion", "euler", "correction")
_QUATERNION_SCALES = {c: Scale(1.0, -1.0, 1.0, "-") for c in "wxyz"}
_INNOVATION_SCALES = {c: Scale(1.0, -math.pi, math.pi, "rad") for c in "xyz"}
_FULL_CORRECTION = np.ones(3)  # gains of 1 with a gain_max of 1: the whole innovation
_CORRECTION_SCALES = ("linear", "log")
CORRECTION_LOG_RATIO = 1000.0
"""With ``correction_scale="log"``: the ratio of the longest pull time constant (action −1) to
the shortest (action 1, ``correction_time_constant_s``)."""


class AttitudeEstimationEnv(CosimEnv, EzPickle):
    r"""
    ## Description
    A car drives a route with the scripted driver (pure pursuit and a speed profile); a
    virtual MPU-9250 on it delivers gyro, accelerometer and AK8963 magnetometer samples.
    Each step the agent receives the IMU samples of the last control period and answers
    with its estimate of the car's attitude at the newest of them. The reward is minus the
    angle between its estimate and the true attitude. A reference estimator (the faithful
    BISO of Aleshkin et al. 2024 by default) runs on the same samples, and `info` carries
    its estimate and error every step, so any agent is compared with it all the way.

    Frames (the package's): world ENU; body x forward, y left, z up; quaternions
    `(w, x, y, z)`, Hamilton, `q_wb` maps body vectors to world vectors.

    ## Action Space
    With `action_type="quaternion"` (default) a `Box(-1, 1, (4,), float32)`: the estimate
    `q_wb = (w, x, y, z)`, normalised by the environment (any non-zero length; `q` and `-q`
    are the same attitude). With `action_type="euler"` a `Box([-π, -π/2, -π], [π, π/2, π],
    (3,), float32)`: roll, pitch, yaw in rad (intrinsic z-y-x, yaw counter-clockwise from
    East). NaN/inf or a wrong shape raise `ValueError`, and so does an all-zero quaternion;
    out-of-bounds values are clipped to the box (or refused with `action_bounds="raise"`).

    | Num | Action (quaternion) | Min | Max | Unit |
    |---|---|---|---|---|
    | 0 | w | -1 | 1 | - |
    | 1 | x | -1 | 1 | - |
    | 2 | y | -1 | 1 | - |
    | 3 | z | -1 | 1 | - |

    With `action_type="correction"` (the residual formulation, for learning agents) a
    `Box(-1, 1, (3,), float32)`: gains g_i = max(a_i, 0) · (1 − exp(−dt/τ)) on the components
    of the observed `innovation` δ (body axes x, y, z; τ = `correction_time_constant_s`), and
    the estimate is `prior ∘ exp(g ⊙ δ)`: the agent's previous estimate propagated with the
    step's gyro samples (`prior_q_wb`), turned by a fraction of the rotation to the
    accelerometer+magnetometer attitude of the newest sample. Zero (or negative) actions are
    gyro dead reckoning from the accelerometer+magnetometer attitude at the start (a far
    better estimator than the memoryless attitude on the default calibrated part: tested);
    a constant action of 1 is a complementary filter of time constant τ (1 s by default; with
    τ = 0 the memoryless attitude itself, the `AccelMagAttitude` baseline: tested); a policy
    chooses the gains from the samples each step (e.g. trusting the accelerometer only while
    the car drives straight at constant speed). The range stops at τ rather than at the
    memoryless attitude so that an exploring policy's noise does not pull the estimate to
    the accelerometer+magnetometer attitude whatever its mean (`docs/envs.md`, "Why PPO did
    not learn"). With `correction_scale="log"` each component sets the time constant of its
    pull on a logarithmic scale instead, τ_i = τ · 1000^((1 − a_i)/2) (a_i = 1: τ, 0: 31.6 τ,
    −1: 1000 τ), gain 1 − exp(−dt/τ_i): every action pulls, the zero action at the middle of
    three decades (as GainTuning's cutoff), and an exploring policy's noise scales the pull by
    a factor rather than switching it on and off at a = 0.

    ## Observation Space
    A bounded `Box(low, high, (9·n + 4,), float32)` (`9·n + 7` with `action_type="correction"`;
    `+9` with GNSS, `+4` with `observe_baseline=True`): physical values divided by documented
    scales and clipped to the bounds (`env.unwrapped.observation_fields` names each column,
    `env.unwrapped.observation_scale` gives its unit's size, `split_observation(obs)` returns
    the parts in SI units, `physical_observation()` the exact float64 values), in this order
    (`env.unwrapped.observation_structure`):

    - *imu (n × 9):* the newest `n = ceil(ODR / control rate)` IMU samples, oldest first
      (4 at the default 200 Hz and 50 Hz), each row `gyro_x, gyro_y, gyro_z` (in rad/s,
      bounds the gyro's full scale, ±4.36 rad/s by default), `accel_x, accel_y, accel_z`
      (specific force in g = 9.80665 m/s², +1 up at rest; bounds the full scale, ±4 g),
      `mag_x, mag_y, mag_z` (in units of 50 µT, about the Earth's field; bounds the AK8963's
      ±4912 µT). Two flags join each row when they are not constant: `mag_fresh` (1: a new
      AK8963 measurement with this sample; at 200 Hz / 100 Hz / 50 Hz the fresh rows are always
      the 2nd and 4th, so it is left out) and `new` (1: the sample arrived during the last
      step; left out when the rates divide). When they do not, rows not renewed this step
      repeat older samples with `new = 0`.
    - *gnss (9), only with `gnss_rate_hz`:* the newest GNSS fix delivered so far: `valid`,
      `new` (delivered during the last step), `age_s` (s, from its time of validity to the
      newest IMU sample, latency included; bounds 0–60 s), position `pos_e, pos_n, pos_u`
      (units of 100 m in the route's local ENU frame) and velocity `vel_e, vel_n, vel_u`
      (units of 10 m/s); zeros with `valid = 0` before the first fix and during outages.
    - *estimate_q_wb (4):* the agent's own previous estimate fed back: the attitude of its
      last action as a unit quaternion with w ≥ 0 (identity at reset). With it a policy can
      propagate its estimate with the gyro samples, as a filter does, rather than re-deriving
      the attitude from one step's accelerometer and magnetometer samples.
    - *baseline_q_wb (4), only with `observe_baseline=True`:* the reference estimator's
      attitude at the newest sample (for residual agents that correct it).

    With `action_type="correction"` the parts after the IMU (and GNSS) are instead:

    - *prior_q_wb (4):* the agent's previous estimate propagated with each of the step's gyro
      samples ω_i in turn, `q ← q ∘ exp(ω_i Δt)` (Δt = 1/ODR), unit, w ≥ 0; at reset the
      accelerometer+magnetometer attitude of the first observation's newest sample;
    - *innovation (3):* the rotation vector δ (body axes, rad, |δ| ≤ π) with
      `prior ∘ exp(δ)` = the accelerometer+magnetometer attitude of the newest sample (TRIAD
      as `biso_cosim.estimators.reference_attitude`, the site's declination; without a usable
      field the heading is the prior's; zero without a usable specific force; zero at reset);
    - *baseline_q_wb (4), only with `observe_baseline=True`:* as above.

    The readings are what the chip delivers in SI: the part's errors (by default the
    residuals after the usual start-up calibration), noise, DLPF and quantisation included.

    ## Rewards
    The total reward is: ***reward*** *=* *reward_attitude* *=* −∠(q_action, q_true) in rad,
    the rotation angle between the agent's estimate and the true attitude at the newest
    sample of the observation the agent acted on (in [−π, 0]).

    With `shaping_gamma=γ` (only with `action_type="correction"`) a potential-based shaping
    term (Ng, Harada and Russell 1999) joins it: *reward* = *reward_attitude* +
    *reward_shaping*, *reward_shaping* = γΦ(s') − Φ(s) with the potential Φ = −p/(1 − γ),
    p the angle between the prior (`prior_q_wb`, the agent's previous estimate propagated
    with the gyro) and the true attitude at the newest sample of the observation. With the
    same γ as the learner's discount it changes no policy's discounted return but by the
    first state's potential, which no action moves, so the best policies stay the task's;
    what changes is the reward each step carries: the error this step's correction removed,
    (p − e)/(1 − γ), less the error the gyro adds before the next prior, where without it
    each step carries the error level inherited from all earlier steps (`docs/envs.md`,
    "Why PPO did not learn"). The task's measure stays *reward_attitude* (its sum is the
    return the docs tabulate).

    `info` carries the reward terms and, for the same instant: `t_s` (s), `q_wb_true`,
    `q_wb_baseline`, `error_rad` (= −reward), `baseline_error_rad`, and `distance_m` (the
    car's progress along the route, m); with corrections also `prior_error_rad` (the next
    prior's angle to the truth, p of the next step). `info` at reset has the same state keys
    for the first observation plus `episode_seed`, `sensor_seed`, `route_seed`, `route` (and
    `gnss_seed`; with corrections `prior_error_rad`).

    ## Starting State
    The car stands at the start of the route, settled on its suspension, brakes on; the
    scripted driver waits for the route's `start_wait_s`, then drives. `reset` advances one
    control period (or more, until the first IMU sample) so that the first observation
    holds samples. Every episode draws a new sensor part and noise stream from the episode
    seed (unless `sensor_seed` fixes them); with `route="random"` a new route as well.

    ## Episode End
    ### Termination
    The episode never terminates: estimation has no failure state.

    ### Truncation
    After `episode_duration_s` simulated seconds (default: the route's nominal duration plus
    10 s at rest, about 65 s = 3250 steps for `figure8`).

    ## Arguments
    Pass them to `gymnasium.make`, e.g.
    `gym.make("biso_cosim:biso_cosim/AttitudeEstimation-v0", route="loop600", action_type="euler")`.

    {arguments}

    ## Version History
    * v0: Initial version: scripted driver on library or procedural routes, MPU-9250 at its
      register-defined rate, optional GNSS receiver, BISO reference in `info`;
      `action_type="correction"` added (2026-12-07); `shaping_gamma`, `correction_scale` added (2026-12-07).
    """

    ARGUMENTS = {
        "action_type": '`"quaternion"` (q_wb, 4 numbers), `"euler"` (roll, pitch, yaw in rad) or `"correction"` '
                       "(gains on the innovation of the gyro-propagated estimate: see Action Space)",
        "estimator": "reference estimator whose estimate and error `info` reports "
                     "(`biso_cosim.estimators.estimator_names()`)",
        "estimator_params": "its parameters (`describe_estimator(name)`); the declination of the route's site is "
                            "set unless given",
        "observe_baseline": "append the reference estimate to the observation",
        "correction_time_constant_s": 'with `action_type="correction"`: the time constant τ of the pull towards the '
                                      "accelerometer+magnetometer attitude at gains of 1, s (a gain of 1 turns the "
                                      "fraction 1 − exp(−dt/τ) of the innovation each step; 0: all of it)",
        "correction_scale": 'with `action_type="correction"`: `"linear"` (gains max(a, 0), 0 or less: no pull) or '
                            '`"log"` (pull time constants from `correction_time_constant_s` at a = 1 to 1000 times it '
                            "at a = −1, logarithmically; see Action Space)",
        "shaping_gamma": 'with `action_type="correction"`: γ of the potential-based shaping term γΦ(s\') − Φ(s), '
                         "Φ = −(the prior's angle to the truth)/(1 − γ), added to the reward (see Rewards; use the "
                         "learner's discount); None: no shaping",
    }
    ACTION_NAMES = ("w", "x", "y", "z")

    def __init__(self, *, route: str | Route = "figure8", action_type: str = "quaternion", estimator: str = "biso",
                 estimator_params: Mapping[str, Any] | None = None, observe_baseline: bool = False,
                 correction_time_constant_s: float = 1.0, correction_scale: str = "linear",
                 shaping_gamma: float | None = None,
                 random_route_options: Mapping[str, Any] | None = None, episode_duration_s: float | None = None,
                 sensor_profile: str = DEFAULT_SENSOR_PROFILE, sensor_noise: bool = True,
                 sensor_seed: int | None = None, registers: Mapping[str, int] | None = None,
                 gnss_rate_hz: float | None = None,
                 gnss_profile: str = "consumer", control_rate_hz: float = 50.0,
                 physics_rate_hz: float = 1000.0, gyro_calibration_s: float = 0.0, action_bounds: str = "clip",
                 render_mode: str | None = None, render_width: int = 480, render_height: int = 270):
        arguments = {k: v for k, v in locals().items() if k not in ("self", "__class__")}
        EzPickle.__init__(self, **arguments)
        if action_type not in _ACTION_TYPES:
            raise ValueError(f"action_type must be one of {_ACTION_TYPES}, got {action_type!r}")
        if not isinstance(observe_baseline, (bool, np.bool_)):
            raise TypeError(f"observe_baseline must be True or False, got {observe_baseline!r}")
        self.correction_time_constant_s = _check_number("correction_time_constant_s", correction_time_constant_s,
                                                        low=0.0, high=3600.0)
        """The time constant of the pull of gains of 1 towards the accelerometer+magnetometer attitude, s."""
        if correction_scale not in _CORRECTION_SCALES:
            raise ValueError(f"correction_scale must be one of {_CORRECTION_SCALES}, got {correction_scale!r}")
        if correction_scale == "log" and self.correction_time_constant_s == 0.0:
            raise ValueError('correction_scale="log" needs correction_time_constant_s > 0 (its shortest pull)')
        self.correction_scale = correction_scale
        """How a correction action maps onto its gains: "linear" or "log" (see Action Space)."""
        if shaping_gamma is not None:
            if action_type != "correction":
                raise ValueError(f'shaping_gamma needs action_type="correction" (its potential is the prior\'s '
                                 f"error), got action_type={action_type!r}")
        self.shaping_gamma = _check_shaping_gamma(shaping_gamma)
        """γ of the potential-based shaping term (None: none)."""
        spec = EstimatorSpec(estimator, dict(estimator_params or {}), label="baseline")
        super().__init__(**{k: arguments[k] for k in COMMON_ARGUMENTS}, estimators=(spec,))
        self.action_type = action_type
        self.observe_baseline = bool(observe_baseline)
        if action_type == "quaternion":
            self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        elif action_type == "euler":
            self.ACTION_NAMES = ("roll", "pitch", "yaw")
            high = np.array([math.pi, 0.5 * math.pi, math.pi], dtype=np.float32)
            self.action_space = spaces.Box(-high, high, dtype=np.float32)
        else:
            self.ACTION_NAMES = ("gain_x", "gain_y", "gain_z")
            self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        if action_type == "correction":  # the prior the correction turns, and its innovation
            self._raw_structure.update(prior_q_wb=(4,), innovation=(3,))
            self._raw_scales.update(prior_q_wb=_QUATERNION_SCALES, innovation=_INNOVATION_SCALES)
        else:
            self._raw_structure["estimate_q_wb"] = (4,)
            self._raw_scales["estimate_q_wb"] = _QUATERNION_SCALES
        if self.observe_baseline:
            self._raw_structure["baseline_q_wb"] = (4,)
            self._raw_scales["baseline_q_wb"] = _QUATERNION_SCALES
        self._set_observation_space()
        # the agent's previous estimate (unit, w >= 0; identity at reset): fed back in the
        # observation, or with corrections the start of the next prior
        self._estimate_q = self._observation_parts.get("estimate_q_wb", np.empty(4))
        self._prior_q = self._observation_parts.get("prior_q_wb", np.empty(4))
        self._innovation = self._observation_parts.get("innovation", np.empty(3))
        # Δt of the gyro propagation, cos(D/2), sin(D/2) of the site's declination (set at reset)
        self._correction_constants = np.array([1.0 / self.imu_rate_hz, 1.0, 0.0])
        self._q = np.empty(4)  # a correction action's attitude
        tau = self.correction_time_constant_s
        self._gain_max = -math.expm1(-self.dt / tau) if tau > 0.0 else 1.0  # (the fraction a gain of 1 turns)
        self._gains = np.empty(3)  # a log-scale action's gains
        # the newest reference estimate (in the observation when observed)
        self._baseline_q = self._observation_parts.get("baseline_q_wb", np.empty(4))
        self._baseline_q[:] = (1.0, 0.0, 0.0, 0.0)
        self._prior_error = 0.0  # the prior's angle to the truth (the shaping's potential, set at reset)

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        info = self._begin_episode(seed, options)
        self._estimate_q[:] = (1.0, 0.0, 0.0, 0.0)
        declination = self._sim.earth.declination_rad  # (a random route's site may differ)
        self._correction_constants[1:] = (math.cos(0.5 * declination), math.sin(0.5 * declination))
        self._first_period()
        if self.action_type == "correction":  # the first prior: the accelerometer+magnetometer attitude
            _corrected(self._prior_q, _FULL_CORRECTION, self._innovation, 1.0, self._prior_q)
            self._innovation[:] = 0.0
        info.update(self._state_info())
        if self.action_type == "correction":
            self._prior_error = info["prior_error_rad"] = _angle(self._prior_q, info["q_wb_true"])
        info["baseline_error_rad"] = _angle(info["q_wb_baseline"], info["q_wb_true"])
        return self._observation(), info

    def step(self, action: Any):
        self._require_running()
        q = self._action_attitude(self._check_action(action))
        info = self._state_info()
        error, info["baseline_error_rad"] = _angles_to(q, info["q_wb_baseline"], info["q_wb_true"])
        info["error_rad"] = error
        reward = -error
        info["reward_attitude"] = reward
        w, x, y, z = q.tolist()
        norm = math.copysign(math.sqrt(w * w + x * x + y * y + z * z), w if w != 0.0 else 1.0)
        self._estimate_q[:] = (w / norm, x / norm, y / norm, z / norm)
        self._advance()
        if self.action_type == "correction":  # the next prior's error: the next state's potential
            prior_error = _angle(self._prior_q, self._newest_row[Truth.QUAT_COLUMN:Truth.QUAT_COLUMN + 4])
            info["prior_error_rad"] = prior_error
            if self.shaping_gamma is not None:
                shaping = _shaping_reward(self.shaping_gamma, self._prior_error, prior_error)
                info["reward_shaping"] = shaping
                reward = reward + shaping
            self._prior_error = prior_error
        truncated = self._truncated
        self._end_if(False, truncated)
        return self._observation(), reward, False, truncated, info

    def action_quaternion(self, action: Any) -> np.ndarray:
        """The unit quaternion ``q_wb`` an action stands for (after the bounds policy)."""
        q = self._action_attitude(self._check_action(action))
        return q / np.linalg.norm(q)

    def _action_attitude(self, a: np.ndarray) -> np.ndarray:
        """The attitude of a checked action as a quaternion of any non-zero length (the angle
        kernel normalises, so an action equal to an estimate scores exactly its error)."""
        if self.action_type == "correction":
            if self.correction_scale == "log":
                _log_gains(a, self.dt, self.correction_time_constant_s, math.log(CORRECTION_LOG_RATIO), self._gains)
                _corrected(self._prior_q, self._gains, self._innovation, 1.0, self._q)
            else:
                _corrected(self._prior_q, a, self._innovation, self._gain_max, self._q)
            return self._q
        if self.action_type == "euler":
            return quat_from_euler(a[0], a[1], a[2])
        if not any(a.tolist()):
            raise ValueError("action quaternion must not be all zeros")
        return a

    # ------------------------------------------------------------------ parts
    def _period_work(self) -> PeriodWork:
        """The IMU window and the reference estimator's newest estimate (``_attitude_period``);
        with corrections also the prior and its innovation (``_correction_period``)."""
        if self.action_type == "correction":
            return PeriodWork(_correction_work, (self._window.values, self._baseline_q, self._estimate_q,
                                                 self._correction_constants, self._prior_q, self._innovation),
                              ("baseline",))
        return PeriodWork(_attitude_work, (self._window.values, self._baseline_q), ("baseline",))

    def _state_info(self) -> dict[str, Any]:
        row = self._newest_row
        return {"t_s": float(row[0]), "q_wb_true": row[Truth.QUAT_COLUMN:Truth.QUAT_COLUMN + 4].copy(),
                "q_wb_baseline": self._baseline_q.copy(), "distance_m": self._sim.vehicle.driver.state.s_m}


finish_docstring(AttitudeEstimationEnv)
