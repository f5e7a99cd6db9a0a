"""``biso_cosim/GainTuning-v0``: the agent sets the correction gains of the estimator in the loop."""

from __future__ import annotations

import itertools
import math
from typing import Any, Mapping, Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle

from biso_cosim.cosim import EstimatorSpec
from biso_cosim.loop import PeriodWork
from biso_cosim.envs._common import (COMMON_ARGUMENTS, CosimEnv, Scale, _check_number, _check_shaping_gamma,
                                      _shaping_reward)
from biso_cosim.envs._docs import finish_docstring
from biso_cosim.estimators import describe_estimator, make_estimator
from biso_cosim.estimators.biso import PAPER_K, PAPER_K_P, BisoParams, gains_from_cutoff
from biso_cosim.envs._kernels import (_angle, _angles_to, _innovation_statistics, _mean_error_work, _tune_closed,
                                      _tuning_work)
from biso_cosim.routes import Route
from biso_cosim.vehicle.sim import Truth

__all__ = ["GainTuningEnv", "DEFAULT_TUNING", "CROSS_LINK_RATIO", "DIE_TEMPERATURE_RANGE_C"]

CROSS_LINK_RATIO = "cross_link_ratio"
"""The environment's own BISO parameter r = √3·k_p / k: with ``cutoff_hz`` it sets
k = 2π f_c/√2 and k_p = r·2π f_c/√6 (r = 1: the paper's Butterworth design, damping 0.707;
r = 0: no cross-links). docs/design.md §5, reading D."""

DEFAULT_TUNING: dict[str, dict[str, tuple[float, float, str]]] = {
    "biso": {"cutoff_hz": (0.001, 20.0, "log"), CROSS_LINK_RATIO: (0.0, 2.0, "linear")},
    "biso_plus": {"k_tilt": (0.1, 50.0, "log"), "k_heading": (0.005, 5.0, "log"), "tau_acc_s": (0.1, 10.0, "log")},
}
"""Tuned parameters per estimator: name → (low, high, scale); the action maps [-1, 1] onto
[low, high] linearly or logarithmically (scale ``"linear"`` or ``"log"``)."""

_SCALES = ("linear", "log")

DIE_TEMPERATURE_RANGE_C = (-40.0, 85.0)
"""The MPU-9250's operating range, °C ([PS] §3): the bounds of ``die_temperature_c``."""
# the tag of the die temperature's random stream, drawn from the episode's sensor seed
_TEMPERATURE_STREAM = 0x7E3D


def _check_temperature(value: Any) -> float | tuple[float, float] | None:
    """``die_temperature_c``: None, a number or (low, high) in the operating range (ValueError)."""
    low, high = DIE_TEMPERATURE_RANGE_C
    expected = (f"die_temperature_c must be None, a number or (low, high) with {low:g} <= low < high <= "
                f"{high:g} (°C, the MPU-9250's operating range), got {value!r}")
    if value is None:
        return None
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        if not low <= float(value) <= high:  # (NaN fails too)
            raise ValueError(expected)
        return float(value)
    try:
        a, b = value
        a, b = float(a), float(b)
    except (TypeError, ValueError):
        raise ValueError(expected) from None
    if not low <= a < b <= high:
        raise ValueError(expected)
    return (a, b)


def _check_tuning(estimator: str, tuning: Mapping[str, Any]) -> dict[str, tuple[float, float, str]]:
    if not isinstance(tuning, Mapping) or not tuning:
        raise ValueError(f"tuning must be a non-empty mapping name -> (low, high, scale), got {tuning!r}")
    known = {row["name"] for row in describe_estimator(estimator)["params"]}
    if estimator == "biso":
        known.add(CROSS_LINK_RATIO)
    out = {}
    for name, entry in tuning.items():
        if name not in known:
            raise ValueError(f"tuning: {estimator!r} has no parameter {name!r}; known: {sorted(known)}")
        try:
            low, high, scale = entry
            low, high = float(low), float(high)
        except (TypeError, ValueError):
            raise ValueError(f"tuning[{name!r}] must be (low, high, 'linear' or 'log'), got {entry!r}") from None
        if scale not in _SCALES or not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"tuning[{name!r}] must be (low, high, 'linear' or 'log') with finite low < high, "
                             f"got {entry!r}")
        if scale == "log" and low <= 0.0:
            raise ValueError(f"tuning[{name!r}]: a log scale needs low > 0, got {entry!r}")
        out[name] = (low, high, scale)
    if CROSS_LINK_RATIO in out and "cutoff_hz" not in out:
        raise ValueError(f"tuning: {CROSS_LINK_RATIO!r} needs 'cutoff_hz' tuned too (it sets k and k_p together)")
    return out


class GainTuningEnv(CosimEnv, EzPickle):
    r"""
    ## Description
    The car drives a route with the scripted driver and the virtual MPU-9250; the estimator
    in the loop (the faithful BISO of Aleshkin et al. 2024 by default, or `biso_plus`) runs
    on its samples. Each step the agent sets the estimator's correction gains for the next
    control period (a gain schedule; a constant action is a fixed tuning), and is rewarded
    with minus the estimator's attitude error. A second copy of the estimator with fixed
    gains runs on the same samples: for `biso` the paper's gains k = 44.4 s⁻¹, k_p = 25.64 s⁻¹
    (a 10 Hz Butterworth design), for others their defaults. `info` reports its error every
    step as the baseline.

    Gains change without a jump in the estimate (`Estimator.set_params`). They follow the
    actions with a lag (`gain_time_constant_s`, default 1 s): the episode's first action sets
    them, and each later one moves the gains in force (normalised, so f_c on its logarithmic
    scale) by the fraction 1 − exp(−dt/τ) (2 % at 50 Hz) of the way towards it. A constant
    action is a fixed tuning from the first step on (what the oracle searches), while an
    exploring agent's step-to-step noise averages out instead of switching the filter's gains
    by orders of magnitude every 20 ms, which makes the filter as bad as random actions
    whatever the mean of the noise (its effective gains are those of the largest values
    drawn; `docs/envs.md`, "Why PPO did not learn").

    The default episodes make the tuning a real trade-off that depends on the episode: a new
    procedurally generated route each episode (`route="random"`, 80–100 s: long enough for
    the gyro's drift to matter) and a raw MPU-9250 part (`sensor_profile="mpu9250"`: the
    datasheet's turn-on bias, scale-factor and misalignment spreads and noise, uncalibrated,
    a new part every episode) at a die temperature drawn per episode (`die_temperature_c`,
    5–45 °C: the part's drawn bias and scale-factor temperature coefficients, ±0.48 °/s/°C for
    the gyro's bias, move its errors by their coefficient × (T − 25 °C); the temperature is
    constant within an episode, since the co-simulation's loop runs the chip at one die
    temperature). Too little correction lets the gyro bias integrate into tens
    of degrees; too much follows the accelerometer through the car's accelerations and the
    magnetometer's errors. The best constant f_c found by search (`biso_cosim.envs.gain_oracle`)
    lies inside the range and changes from episode to episode (0.04–0.14 Hz on the evaluation
    seeds, against the paper's 10 Hz). The best cross-link ratio is r = 0 (no cross-links) on
    most episodes: at the episode's best f_c the error grows from r = 0 on (a stationary
    minimum, not one the range cuts off), and r < 0 lies outside BISO's domain (the estimator
    refuses k_p < 0: its poles −k ± i√3 k_p only swap), so r = 0 is the edge of the estimator's
    gains, not of a chosen range; at weak correction (f_c ≈ 0.03 Hz) some episodes are best
    with r ≈ 0.7. `docs/envs.md` tabulates the oracle, the paper's gains, the best
    single constant and trained policies (`benchmarks/rl_baselines.py`). The earlier task, the
    calibrated part on `figure8`, is `route="figure8", sensor_profile="mpu9250_calibrated"`
    (its optimum is the weakest correction: the range decides it).

    ## Action Space
    A `Box(-1, 1, (m,), float32)`, one entry per tuned parameter, mapped onto its range
    linearly or logarithmically (`tuning`). Default for `biso`:

    | Num | Parameter | Min | Max | Scale | Unit |
    |---|---|---|---|---|---|
    | 0 | `cutoff_hz`: Butterworth design frequency f_c, k = 2π f_c/√2 | 0.001 | 20 | log | Hz |
    | 1 | `cross_link_ratio` r = √3 k_p/k (1: the paper's design, 0: no cross-links) | 0 | 2 | linear | - |

    Default for `biso_plus`: `k_tilt` (0.1–50 s⁻¹, log), `k_heading` (0.005–5 s⁻¹, log),
    `tau_acc_s` (0.1–10 s, log). `env.unwrapped.params_from_action(a)` and
    `action_from_params(**values)` convert. NaN/inf or a wrong shape raise `ValueError`;
    out-of-bounds values are clipped (or refused with `action_bounds="raise"`).

    ## Observation Space
    A bounded `Box(low, high, (9·n + 4 + m,), float32)` (`9·n + m` with `observe_attitude=False`;
    without the `9·n` with `observe_imu=False`; `+4` with `innovation_time_constant_s`; `+9`
    with GNSS), scaled as in
    `AttitudeEstimation-v0` (`observation_fields`, `observation_scale`, `split_observation`),
    in this order (`env.unwrapped.observation_structure`):

    - *imu (n × 9):* the newest `n = ceil(ODR / control rate)` IMU samples as in
      `AttitudeEstimation-v0` (gyro in rad/s, accelerometer in g, magnetometer in 50 µT; the
      flags `mag_fresh` and `new` where they are not constant);
    - *gnss (9), only with `gnss_rate_hz`:* the newest GNSS fix as in `AttitudeEstimation-v0`;
    - *q_wb (4), unless `observe_attitude=False`:* the tuned estimator's attitude at the
      newest sample;
    - *innovation (4), only with `innovation_time_constant_s=T`:* statistics of the rotation
      vector d (rad, the tuned estimate's body axes) from the tuned copy's attitude to the
      baseline copy's at the newest sample (the baseline, at the paper's 10 Hz gains, follows
      the accelerometer+magnetometer attitude closely: d is nearly the tuned filter's
      innovation), as exponential moving averages over the steps with the weight
      1 − exp(−dt/T), started at the first step's value: the mean of d (`x`, `y`, `z`: a
      sustained offset, the gyro bias over the correction gain) and the root of the mean
      of |d|² (`rms`). They change over T rather than step to step, and tell episodes apart
      by what sets their best gains (the part's gyro bias against the accelerometer's and
      magnetometer's errors);
    - *gains (m):* the gains in force, as the normalised action that sets them.

    `observe_attitude=False` leaves the attitude out: its heading changes with the route and
    says nothing about which gains are right, and a policy trained on few episodes fits its
    gains to it (`docs/envs.md`, "Why PPO did not learn"). `observe_imu=False` leaves the IMU
    samples out for the same reason: they change every step, while the best gains are nearly
    a constant per episode (`docs/envs.md`, "GainTuning, third round").

    ## Rewards
    The total reward is: ***reward*** *=* *reward_attitude* *=* −(mean over the step's IMU
    samples of ∠(q_tuned, q_true)) in rad: the error of the estimate the gains set by the
    action produced during this step.

    With `reference_action` a third copy of the estimator runs on the same samples with the
    constant gains of that normalised action, and its error joins the reward: *reward* =
    *reward_attitude* + *reward_reference*, *reward_reference* = +(its mean error over the
    step's samples). No action changes that copy, so each episode's return moves by the same
    amount for every policy and the best policies stay the task's; what it removes from each
    step's reward is the part of the error that the route's turns and the sensor part cause
    at any nearby gains (`docs/envs.md`). With `shaping_gamma=γ` a potential-based shaping
    term (Ng, Harada and Russell 1999) joins it, *reward_shaping* = γΦ(s') − Φ(s), Φ = −d/(1 − γ),
    d the tuned copy's angle to the truth at the newest sample (less the reference copy's, with
    `reference_action`; `info["potential_error_rad"]`): the error level a step inherits, which
    no action of the step moves, is exchanged for the change of the error the gains in force
    make in the step; with the learner's discount γ no policy's discounted return changes but
    by the first state's potential. The task's measure stays *reward_attitude*.

    `info` carries the reward terms and `error_rad` (= −reward_attitude), `baseline_error_rad`
    (the same mean for the fixed-gain copy; `reference_error_rad` for the reference copy),
    `params` (the tuned values in force, with the cross-link
    ratio also k and k_p), and at the newest sample `t_s`, `q_wb_true`, `q_wb_tuned`,
    `q_wb_baseline`.

    ## Starting State
    As `AttitudeEstimation-v0`: the car at rest at the start of the route; the tuned
    estimator starts with the baseline's gains; `reset` advances one control period.

    ## Episode End
    ### Termination
    Never.

    ### Truncation
    After `episode_duration_s` simulated seconds (default: the route's nominal duration plus
    10 s).

    ## Arguments
    {arguments}

    ## Version History
    * v0: Initial version; the gains' lag (`gain_time_constant_s`) added (2026-12-07);
      `reference_action`, `observe_attitude` and `shaping_gamma` added (2026-12-07);
      `observe_imu` and `innovation_time_constant_s` added (2026-12-07).
    """

    ARGUMENTS = {
        "estimator": '`"biso"` or `"biso_plus"` (or another registered estimator with a `tuning`)',
        "estimator_params": "fixed parameters of both copies; the baseline runs with them and its defaults",
        "tuning": "tuned parameters: name → (low, high, `\"linear\"` or `\"log\"`); "
                  "None: `DEFAULT_TUNING[estimator]`",
        "die_temperature_c": "the MPU-9250's die temperature in the episodes, °C: (low, high) drawn uniformly per "
                             "episode from the sensor seed, a number, or None (the profile's `temperature.default`, "
                             "25 °C for the built-in profiles); constant within an episode",
        "gain_time_constant_s": "time constant τ of the gains' lag, s: after the episode's first action each "
                                "action moves the gains in force (normalised) by 1 − exp(−dt/τ) of the way "
                                "towards it; 0: each action sets them",
        "reference_action": "None, or the normalised action (one entry per tuned parameter, in [-1, 1]) of a third "
                            "copy of the estimator at constant gains whose mean error over each step is added to "
                            "the reward (see Rewards)",
        "observe_attitude": "include the tuned estimator's attitude (`q_wb`) in the observation",
        "observe_imu": "include the IMU samples (`imu`) in the observation (False: the part has no columns)",
        "innovation_time_constant_s": "None, or the time constant T > 0 (s) of the innovation statistics in the "
                                      "observation (`innovation`: moving averages of the rotation from the tuned "
                                      "copy's estimate to the baseline copy's, see Observation Space)",
        "shaping_gamma": "γ of the potential-based shaping term γΦ(s') − Φ(s), Φ = −(the tuned copy's angle to the "
                         "truth at the newest sample, less the reference copy's with `reference_action`)/(1 − γ), "
                         "added to the reward (see Rewards; use the learner's discount); None: no shaping",
    }

    def __init__(self, *, route: str | Route = "random", estimator: str = "biso",
                 estimator_params: Mapping[str, Any] | None = None,
                 tuning: Mapping[str, tuple[float, float, str]] | None = None,
                 die_temperature_c: float | tuple[float, float] | None = (5.0, 45.0),
                 gain_time_constant_s: float = 1.0, reference_action: Sequence[float] | None = None,
                 observe_attitude: bool = True, observe_imu: bool = True,
                 innovation_time_constant_s: float | None = None, shaping_gamma: float | None = None,
                 random_route_options: Mapping[str, Any] | None = None, episode_duration_s: float | None = None,
                 sensor_profile: str = "mpu9250", sensor_noise: bool = True,
                 sensor_seed: int | None = None, registers: Mapping[str, int] | None = None,
                 gnss_rate_hz: float | None = None,
                 gnss_profile: str = "consumer", control_rate_hz: float = 50.0,
                 physics_rate_hz: float = 1000.0, gyro_calibration_s: float = 0.0, action_bounds: str = "clip",
                 render_mode: str | None = None, render_width: int = 480, render_height: int = 270):
        arguments = {k: v for k, v in locals().items() if k not in ("self", "__class__")}
        EzPickle.__init__(self, **arguments)
        if tuning is None:
            if estimator not in DEFAULT_TUNING:
                raise ValueError(f"estimator {estimator!r} has no default tuning ({sorted(DEFAULT_TUNING)}); "
                                 f"give tuning=...")
            tuning = DEFAULT_TUNING[estimator]
        self.tuning = _check_tuning(estimator, tuning)
        self.die_temperature_c = _check_temperature(die_temperature_c)
        """The die temperature of the episodes: None (the profile's default), °C, or (low, high)."""
        self.gain_time_constant_s = _check_number("gain_time_constant_s", gain_time_constant_s, low=0.0, high=3600.0)
        """Time constant of the gains' lag behind the actions, s (0: none)."""
        self.estimator = estimator
        fixed = dict(estimator_params or {})
        self.estimator_params = dict(fixed)
        """The fixed parameters of both copies."""
        clash = sorted(set(fixed) & (set(self.tuning) | ({"k", "k_p"} if CROSS_LINK_RATIO in self.tuning else set())))
        if clash:
            raise ValueError(f"estimator_params {clash} are tuned by the action; remove them")
        if not isinstance(observe_attitude, (bool, np.bool_)):
            raise TypeError(f"observe_attitude must be True or False, got {observe_attitude!r}")
        self.observe_attitude = bool(observe_attitude)
        if not isinstance(observe_imu, (bool, np.bool_)):
            raise ValueError(f"observe_imu must be True or False, got {observe_imu!r}")
        self.observe_imu = bool(observe_imu)
        self.innovation_time_constant_s = (None if innovation_time_constant_s is None else _check_number(
            "innovation_time_constant_s", innovation_time_constant_s, low=0.0, high=3600.0, low_open=True))
        """Time constant of the innovation statistics in the observation, s (None: not observed)."""
        self.reference_action = None if reference_action is None else self._check_reference(reference_action)
        """The normalised action of the reference copy (None: no reference copy)."""
        self.shaping_gamma = _check_shaping_gamma(shaping_gamma)
        """γ of the potential-based shaping term (None: none)."""
        specs = (EstimatorSpec(estimator, fixed, label="tuned"), EstimatorSpec(estimator, fixed, label="baseline"))
        if self.reference_action is not None:  # (its gains are set at reset, as the tuned copy's)
            specs += (EstimatorSpec(estimator, fixed, label="reference"),)
        super().__init__(**{k: arguments[k] for k in COMMON_ARGUMENTS}, estimators=specs)
        tau = self.gain_time_constant_s
        self._lag = -math.expm1(-self.dt / tau) if tau > 0.0 else 1.0
        """The fraction of the way from the gains in force to the action that a step moves them."""
        t_innovation = self.innovation_time_constant_s
        self._innovation_weight = None if t_innovation is None else -math.expm1(-self.dt / t_innovation)
        """The weight of a step's innovation in its moving averages (None: not observed)."""
        self._step_lag = 1.0  # this step's: 1 for the episode's first action
        self.ACTION_NAMES = tuple(self.tuning)
        # the action's map, a column per tuned parameter: low, high / low, high − low, 1 for a
        # logarithmic scale (``_values``; ``_tune_closed``)
        self._scales = np.array([[low, high / low if scale == "log" else math.nan, high - low, scale == "log"]
                                 for low, high, scale in self.tuning.values()], dtype=np.float64).T.copy()
        # BISO tuned by f_c > 0 and r alone: in its closed form, the action goes by ``_tune_closed``
        # with these indices
        names = list(self.tuning)
        self._closed_tuning = set(names) == {"cutoff_hz", CROSS_LINK_RATIO} and self.tuning["cutoff_hz"][0] > 0.0
        self._closed_indices = (names.index("cutoff_hz"), names.index(CROSS_LINK_RATIO)) if self._closed_tuning else ()
        self._closed_names = (*names, "k", "k_p")
        self._closed_values = np.empty(len(names) + 2)  # (the action's values, then k, k_p)
        m = len(self.tuning)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(m,), dtype=np.float32)
        if not self.observe_imu:  # (the window stays, every column dropped from the observation)
            self._dropped["imu"] = {column: range(self.imu_slots) for column in self._raw_scales["imu"]}
        if self.observe_attitude:
            self._raw_structure["q_wb"] = (4,)
            self._raw_scales["q_wb"] = {c: Scale(1.0, -1.0, 1.0, "-") for c in "wxyz"}
        if self._innovation_weight is not None:
            self._raw_structure["innovation"] = (4,)
            self._raw_scales["innovation"] = {**{a: Scale(1.0, -math.pi, math.pi, "rad") for a in "xyz"},
                                              "rms": Scale(1.0, 0.0, math.pi, "rad")}
        self._raw_structure["gains"] = (m,)
        self._raw_scales["gains"] = {name: Scale(1.0, -1.0, 1.0, "-") for name in self.tuning}
        self._set_observation_space()
        baseline = self._sim.estimators["baseline"].params
        self._reading = getattr(baseline, "reading", None)  # BISO's (fixed by estimator_params)
        # what reset restores in the tuned copy: the baseline's own values of what the action sets
        names = ("k", "k_p", "cutoff_hz") if CROSS_LINK_RATIO in self.tuning else tuple(self.tuning)
        self._initial = {name: getattr(baseline, name) for name in names}
        self._initial_gains = self._normalise(self._tuned_values(baseline))
        self._check_corners(fixed)
        self._reference_changes = (None if self.reference_action is None else
                                   self.estimator_changes(self.params_from_action(self.reference_action)))
        self._reference_error = np.zeros(2)  # the reference copy's mean and newest error in the last period
        self._reference_pending = False  # its gains are set with the episode's first action
        self._potential_error = 0.0  # the shaping's potential error (set at reset)
        # the gains in force (normalised) and the tuned copy's newest estimate: in the observation
        self._gains, self._tuned_q = self._observation_parts["gains"], self._observation_parts.get("q_wb", np.empty(4))
        self._gains[:] = self._initial_gains
        self._tuned_q[:] = (1.0, 0.0, 0.0, 0.0)
        self._in_force: tuple[Any, dict[str, float]] = (None, {})  # see _params_in_force
        self._closed_version: int | None = None  # see reset
        self._baseline_q = self._tuned_q.copy()
        # the innovation statistics: their moving averages (d, |d|²), and their part of the observation
        self._innovation_state = np.zeros(4)
        self._innovation = self._observation_parts.get("innovation", np.empty(4))
        self._errors = np.zeros(2)  # the mean errors of the tuned and the baseline copy in the last period
        self._period_samples = np.zeros(1, dtype=np.int64)  # the last period's number of samples

    def _check_reference(self, value: Any) -> np.ndarray:
        """``reference_action``: finite numbers in [-1, 1], one per tuned parameter (ValueError)."""
        m = len(self.tuning)
        try:
            a = np.array(value, dtype=float)
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != (m,) or not np.all(np.abs(a) <= 1.0):  # (NaN fails too)
            raise ValueError(f"reference_action must be None or {m} numbers in [-1, 1] (one per tuned parameter: "
                             f"{list(self.tuning)}), got {value!r}")
        return a

    def _tuned_values(self, params: Any) -> dict[str, float]:
        """The tuned parameters' values in an estimator's parameter record."""
        values = {}
        gains = _biso_gains_of(params) if isinstance(params, BisoParams) else {}
        for name in self.tuning:
            if name in gains:
                value = gains[name]
            else:
                value = getattr(params, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"tuning: {name!r} has no single numeric value in the baseline ({value!r}); "
                                 f"choose other tuned parameters")
            values[name] = float(value)
        return values

    def _check_corners(self, fixed: dict[str, Any]) -> None:
        """Every corner of the tuning box must be a valid estimator (e.g. stable gains)."""
        for corner in itertools.product((-1.0, 1.0), repeat=len(self.tuning)):
            changes = self.estimator_changes(self.params_from_action(np.array(corner)))
            try:
                make_estimator(self.estimator, self.imu_rate_hz, **{**fixed, **changes})
            except (ValueError, TypeError) as exc:
                raise ValueError(f"tuning: the corner {changes} of the tuning box is not a valid "
                                 f"{self.estimator!r}: {exc}") from None

    # ------------------------------------------------------------------ episodes
    @property
    def _rebuilt_each_episode(self) -> bool:
        return isinstance(self.die_temperature_c, tuple)  # (a new die temperature: a new profile)

    def episode_temperature_c(self, sensor_seed: int) -> float | None:
        """The die temperature (°C) of the episode whose part is drawn from ``sensor_seed``
        (None: the profile's default)."""
        t = self.die_temperature_c
        if isinstance(t, tuple):
            rng = np.random.default_rng(np.random.SeedSequence([int(sensor_seed), _TEMPERATURE_STREAM]))
            return float(rng.uniform(*t))
        return t

    def _episode_profile(self, sensor_seed: int):
        """The profile at the episode's die temperature: the part's biases and scale factors
        move by its drawn temperature coefficients × (T − ``temperature.reference``)
        (``biso_cosim.sensors.mpu9250``)."""
        profile = self._sim_options["sensor_profile"]
        t = self.episode_temperature_c(sensor_seed)
        if t is None:
            return profile
        return profile.replace(name=f"{profile.name}@{t:.2f}C", temperature__default=t)

    # ------------------------------------------------------------------ conversions
    @property
    def baseline_action(self) -> np.ndarray:
        """The normalised action of the baseline copy's own values of what the action sets (the
        paper's gains for BISO); outside [-1, 1] where those lie outside the action's range."""
        return self._initial_gains.copy()

    def params_from_action(self, action: Any) -> dict[str, float]:
        """The physical parameter values a normalised action stands for."""
        return self._values(np.asarray(action, dtype=float).tolist())

    def _values(self, action: list[float]) -> dict[str, float]:
        """``params_from_action`` of an action already a list of floats."""
        return {name: low * ratio ** (0.5 * (x + 1.0)) if log else low + 0.5 * (x + 1.0) * span
                for name, (low, ratio, span, log), x in zip(self.tuning, self._scales.T.tolist(), action)}

    def action_from_params(self, **values: float) -> np.ndarray:
        """The normalised action that sets ``values`` (every tuned parameter, within its range)."""
        if set(values) != set(self.tuning):
            raise ValueError(f"give every tuned parameter: {list(self.tuning)}, got {sorted(values)}")
        for name, (low, high, _) in self.tuning.items():
            if not low <= float(values[name]) <= high:
                raise ValueError(f"{name} must be in [{low}, {high}], got {values[name]!r}")
        return self._normalise(values)

    def _normalise(self, values: Mapping[str, float]) -> np.ndarray:
        a = np.empty(len(self.tuning))
        for i, (name, (low, high, scale)) in enumerate(self.tuning.items()):
            v = float(values[name])
            u = math.log(v / low) / math.log(high / low) if scale == "log" else (v - low) / (high - low)
            a[i] = 2.0 * u - 1.0
        return a

    def estimator_changes(self, values: dict[str, float]) -> dict[str, Any]:
        """The estimator's parameter changes for tuned values (``params_from_action``'s; the
        cross-link ratio becomes k, k_p)."""
        changes = dict(values)
        if CROSS_LINK_RATIO in changes:
            ratio = changes.pop(CROSS_LINK_RATIO)
            k, kp = gains_from_cutoff(changes.pop("cutoff_hz"), self._reading)
            changes.update(k=k, k_p=ratio * kp, cutoff_hz=None)
        return changes

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        info = self._begin_episode(seed, options)
        info["die_temperature_c"] = float(self._sim.imu.profile.si("temperature.default"))
        tuned = self._sim.estimators["tuned"]
        tuned.set_params(**self._initial)  # Estimator.reset keeps parameters
        if self._reference_changes is not None:  # (as the tuned copy: the baseline's gains until the first step)
            self._sim.estimators["reference"].set_params(**self._initial)
            self._sim.attach(PeriodWork(_mean_error_work, (self._reference_error,), ("reference",)))
            self._reference_pending = True
        # The coefficients the actions' gains are written into while they stay these: BISO's
        # closed form tuned by f_c > 0 and r alone (valid at the box's corners, so k > 0 and
        # k_p >= 0 inside; any other tuned parameter takes set_params)
        closed = self._closed_tuning and tuned.closed_form
        self._closed_version = tuned.arrays_version if closed else None
        self._gains[:] = self._initial_gains
        self._step_lag = 1.0
        self._first_period()
        if self._innovation_weight is not None:  # (the first step's innovation starts the averages)
            _innovation_statistics(self._tuned_q, self._baseline_q, 1.0, self._innovation_state, self._innovation)
        info.update(self._measure())
        info["params"] = self._params_in_force()
        if self.shaping_gamma is not None:
            self._potential_error = info["potential_error_rad"]
        return self._observation(), info

    @property
    def gains_in_place(self) -> bool:
        """Whether the next action's gains are written in place by one kernel (BISO's closed
        form tuned by f_c and r alone, on the fast path) rather than through ``retune``."""
        tuned = self._sim.estimators["tuned"]
        return self._sim.fast_path and tuned.arrays_version == self._closed_version and tuned.closed_form

    def step(self, action: Any):
        self._require_running()
        tuned = self._sim.estimators["tuned"]
        # (see reset; ``sim.fast_path = False`` takes the general path for the action too)
        if self.gains_in_place:
            self._tune_closed(action, tuned)
        else:
            a = self._check_action(action)
            if self._step_lag != 1.0:
                g = self._gains.tolist()
                a = np.array([x + self._step_lag * (y - x) for x, y in zip(g, a.tolist())])
            if a.tolist() != self._gains.tolist():  # (lists: np.array_equal costs tens of µs in the loop)
                self._set_gains(a)
        self._step_lag = self._lag
        if self._reference_pending:  # the reference copy: the tuned copy under the constant reference action
            self._sim.estimators["reference"].retune(**self._reference_changes)
            self._reference_pending = False
        self._advance()
        if self._innovation_weight is not None:
            _innovation_statistics(self._tuned_q, self._baseline_q, self._innovation_weight, self._innovation_state,
                                   self._innovation)
        info = self._measure()
        info["params"] = self._params_in_force()
        reward = -info["error_rad"]
        info["reward_attitude"] = reward
        if self._reference_changes is not None:
            info["reward_reference"] = info["reference_error_rad"]
            reward = reward + info["reference_error_rad"]
        if self.shaping_gamma is not None:
            info["reward_shaping"] = _shaping_reward(self.shaping_gamma, self._potential_error,
                                                     info["potential_error_rad"])
            reward = reward + info["reward_shaping"]
            self._potential_error = info["potential_error_rad"]
        truncated = self._truncated
        self._end_if(False, truncated)
        return self._observation(), reward, False, truncated, info

    # ------------------------------------------------------------------ parts
    def _set_gains(self, a: np.ndarray) -> None:
        """Set the tuned copy's parameters from normalised gains (``retune``). The values
        in force are then the values the action stands for (with the cross-link ratio also
        the k and k_p derived from them), recorded with the parameter record they made."""
        values = self._values(a.tolist())
        tuned = self._sim.estimators["tuned"]
        changes = self.estimator_changes(values)
        tuned.retune(**changes)
        if "k" in changes:
            values.update(k=changes["k"], k_p=changes["k_p"])
        self._in_force = (tuned.params, values)
        self._gains[:] = a

    def _tune_closed(self, action: Any, tuned: Any) -> None:
        """``_check_action`` and ``_set_gains`` for BISO tuned by f_c and r in its closed
        form (see reset): an action inside the bounds in one kernel call (``_tune_closed``),
        its gains set by ``BisoEstimator.retune`` (in place: the closed form's short path)."""
        a = self._action_array(action)
        space = self.action_space
        tune = (space.low, space.high, self._gains, self._scales, *self._closed_indices, self._reading == "L",
                self._closed_values, self._step_lag)
        changed = _tune_closed(a, *tune)
        if changed < 0:  # not inside the bounds: refused (ValueError), or clipped and set
            changed = _tune_closed(self._bounded_action(a), *tune)
        if changed:
            values = self._closed_values.tolist()
            tuned.retune(k=values[-2], k_p=values[-1], cutoff_hz=None)
            self._in_force = (tuned.params, dict(zip(self._closed_names, values)))

    def _params_in_force(self) -> dict[str, float]:
        """The tuned parameters of the tuned copy now (for BISO's cross-link ratio also k, k_p)."""
        params = self._sim.estimators["tuned"].params
        if params is not self._in_force[0]:  # (after reset; steps record what they set, ``_set_gains``)
            values = self._tuned_values(params)
            if CROSS_LINK_RATIO in self.tuning:
                gains = _biso_gains_of(params)
                values.update(k=float(gains["k"]), k_p=float(gains["k_p"]))
            self._in_force = (params, values)
        return dict(self._in_force[1])

    def _period_work(self) -> PeriodWork:
        """The IMU window, and the mean errors of both copies over the period's samples with
        their newest estimates (``_measure``'s; ``_tuning_period``)."""
        return PeriodWork(_tuning_work, (self._window.values, self._tuned_q, self._baseline_q, self._errors,
                                         self._period_samples), ("tuned", "baseline"))

    def _measure(self) -> dict[str, Any]:
        """Mean errors of both copies over the last period's samples, and the state at the newest."""
        newest = self._newest_row
        q_true = newest[Truth.QUAT_COLUMN:Truth.QUAT_COLUMN + 4]
        if self._period_samples[0]:
            error, baseline_error = self._errors.tolist()
        else:  # no sample this step (ODR below the control rate): the newest estimate stands
            error, baseline_error = _angles_to(self._tuned_q, self._baseline_q, q_true)
        out = {"error_rad": error, "baseline_error_rad": baseline_error, "t_s": float(newest[0]),
               "q_wb_true": q_true.copy(), "q_wb_tuned": self._tuned_q.copy(), "q_wb_baseline": self._baseline_q.copy()}
        if self._reference_changes is not None:
            if not self._period_samples[0]:  # (as above: the reference copy's newest estimate stands)
                self._reference_error[:] = _angle(self._sim.estimators["reference"].get_state().q_wb, q_true)
            out["reference_error_rad"] = float(self._reference_error[0])
        if self.shaping_gamma is not None:  # the potential's error: the newest sample's
            newest_error = _angle(self._tuned_q, q_true)
            out["potential_error_rad"] = (newest_error if self._reference_changes is None
                                          else newest_error - float(self._reference_error[1]))
        return out


def _biso_gains_of(params: Any) -> dict[str, Any]:
    """The gains a BISO parameter record resolves to: k, k_p (the paper's when None), and the
    design frequency f_c and cross-link ratio r they correspond to (per-channel gains: None)."""
    if params.cutoff_hz is not None:
        k, kp = gains_from_cutoff(params.cutoff_hz, params.reading)
        return {"k": k, "k_p": kp, "cutoff_hz": float(params.cutoff_hz), CROSS_LINK_RATIO: 1.0}
    k = PAPER_K if params.k is None else params.k
    kp = PAPER_K_P if params.k_p is None else params.k_p
    if not isinstance(k, (int, float)) or not isinstance(kp, (int, float)):
        return {"k": k, "k_p": kp, "cutoff_hz": None, CROSS_LINK_RATIO: None}
    k1, kp1 = gains_from_cutoff(1.0, params.reading)  # gains are proportional to f_c
    cutoff = k / k1
    return {"k": k, "k_p": kp, "cutoff_hz": cutoff, CROSS_LINK_RATIO: kp / (kp1 * cutoff) if cutoff > 0.0 else None}


finish_docstring(GainTuningEnv)
