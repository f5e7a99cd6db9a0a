"""``ImuPlugin``: the virtual MPU-9250 and attitude estimators attached to another
simulator's vehicle (see the package docstring for the timing semantics)."""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np
from numba import typeof

from biso_cosim.estimators import Estimate, Estimator, State, describe_estimator, estimator_inputs, make_estimator
from biso_cosim.loop import SampleOutputs, SensorArrays
from biso_cosim.plugin import _kernels as K
from biso_cosim.plugin._tick import TICK_OK, TICK_SENSOR, TickPlan, TickScratch, TruthAtSamples, compiled_call
from biso_cosim.plugin.adapter import HostFrames
from biso_cosim.plugin.output import EstimateOutput, PluginOutput, empty_estimate
from biso_cosim.sensors import MPU9250, EarthField, ImuSamples, MagneticEnvironment, RawSamples

__all__ = ["ImuPlugin", "Mounting", "PluginState"]

_TAKEN_INPUTS = frozenset({"imu_flags", "speed_mps"})  # optional estimator inputs the plug-in can give
_NO_ROWS3 = np.empty((0, 3))
_NO_ROWS = np.empty(0)  # (also an absent vector of one tick)


@dataclass(frozen=True)
class Mounting:
    """Where the chip sits on the host's vehicle, in the host's body axes.

    Args:
        position_m: (3,) the chip's position relative to the point whose motion the host
            gives (its "reference point": often the centre of mass), host body axes, m.
        q_body_chip: rotation chip axes → host body axes, a unit quaternion in the host's
            component order; None: the chip's axes are the host body axes.
    """

    position_m: Sequence[float] = (0.0, 0.0, 0.0)
    q_body_chip: Sequence[float] | None = None

    def __post_init__(self) -> None:
        r = np.asarray(self.position_m, dtype=np.float64)
        if r.shape != (3,) or not np.all(np.isfinite(r)):
            raise ValueError(f"mounting.position_m must be 3 finite numbers (m, host body axes), got {self.position_m!r}")
        object.__setattr__(self, "position_m", tuple(float(x) for x in r))
        if self.q_body_chip is not None:
            q = np.asarray(self.q_body_chip, dtype=np.float64)
            if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(float(np.linalg.norm(q)) - 1.0) > 1e-6:
                raise ValueError(f"mounting.q_body_chip must be a unit quaternion (4 finite numbers, |q| = 1), "
                                 f"got {self.q_body_chip!r}")
            object.__setattr__(self, "q_body_chip", tuple(float(x) for x in q))


@dataclass(frozen=True, eq=False)
class PluginState:
    """The whole dynamic state of an ``ImuPlugin`` (``get_state``/``set_state``; picklable).

    ``sensor``: ``MPU9250.get_state()``; ``estimators``: label → ``State``; ``ticks``: ticks
    taken; ``t0_s``: the host time of the first tick (None before it); ``last_tick``: the
    previous tick in package frames (q_wb (4), ω_b (3), v_w (3)), None before the first.
    """

    sensor: Mapping[str, np.ndarray]
    estimators: Mapping[str, State]
    ticks: int
    t0_s: float | None
    last_tick: np.ndarray | None = field(default=None)


def _estimator_list(estimators: Any) -> list[tuple[str, str, dict[str, Any]]]:
    """(label, name, params) of each entry of ``estimators``."""
    if isinstance(estimators, str):
        estimators = (estimators,)
    if isinstance(estimators, Mapping):
        items = list(estimators.items())
    elif isinstance(estimators, (list, tuple)):
        items = [(None, e) for e in estimators]
    else:
        raise TypeError(f"estimators must be a sequence of names or (name, params) pairs, or a dict label → "
                        f"name / (name, params); got {estimators!r}")
    out = []
    for label, entry in items:
        if isinstance(entry, str):
            name, params = entry, {}
        elif isinstance(entry, tuple) and len(entry) == 2 and isinstance(entry[0], str) and isinstance(entry[1], Mapping):
            name, params = entry[0], dict(entry[1])
        else:
            raise TypeError(f"estimators: each entry must be a name or a (name, params) pair, got {entry!r}")
        label = name if label is None else label
        if not isinstance(label, str) or not label:
            raise ValueError(f"estimators: labels must be non-empty strings, got {label!r}")
        if any(label == o[0] for o in out):
            raise ValueError(f"estimators: label {label!r} given twice (give a dict label → (name, params))")
        out.append((label, name, params))
    return out


class ImuPlugin:
    """A virtual MPU-9250 (with its AK8963) and attitude estimators on a host's vehicle.

    Args:
        tick_s: the host's truth period in s (its physics step): one call of ``step`` per
            tick, or one call per block of consecutive ticks. It must be an integer multiple
            or fraction of the chip's internal sampling periods (1 ms for the default
            registers: 0.25, 0.5, 1, 2, 5, 20 ms ... are accepted; pybullet's default 1/240 s
            is not).
        frames: the host's conventions (``HostFrames``, a dict or a (world, body, quaternion)
            tuple; default ENU, FLU, scalar first).
        profile: the sensor's error profile (``"mpu9250_calibrated"`` by default, as the FMU;
            ``"mpu9250"``, ``"ideal"``, a profile file or ``Profile``).
        registers: the chip's configuration (``Registers`` or a dict of its fields).
        mounting: ``Mounting`` (position and rotation of the chip in the host's body axes).
        seed: draws the part's turn-on errors and its noise: the same seed gives the same
            readings, bit for bit (the estimators are deterministic).
        site: ``EarthField`` (site and date of the World Magnetic Model) or a
            ``MagneticEnvironment`` (the Earth's field plus local disturbances); default
            Saratov, 2024-05-01.
        estimators: names (``biso_cosim.estimators.estimator_names()``), (name, params)
            pairs, or a dict label → name / (name, params); default ``("biso_plus",)``. An
            unset ``declination_rad`` takes the site's declination.
        speed_from_velocity: give the estimators that take a speed (biso_plus) the forward
            speed of the reference point from the velocity input ``v_w`` (required then at
            every tick); their unset ``speed_point_b_m`` becomes the reference point seen
            from the chip.
        gravity_w: gravity in the host's world axes, m/s², to form the specific force from a
            given acceleration (default standard gravity, down).
        sensor_options: more keywords of ``MPU9250`` (``hard_iron_ut``, ``soft_iron``,
            ``vibration``).
        reuse_outputs: False (default): each ``step`` returns arrays of its own. True: the
            arrays of a ``PluginOutput`` are views of buffers the next ``step`` writes again
            (one output object per number of samples is made once and returned again), for
            hosts that are done with a tick's outputs before the next tick; ``copy()`` what
            you keep. The same numbers either way, bit for bit.
    """

    def __init__(self, *, tick_s: float, frames: Any = None, profile: Any = "mpu9250_calibrated",
                 registers: Any = None, mounting: Mounting | None = None, seed: int | None = 0, site: Any = None,
                 estimators: Any = ("biso_plus",), speed_from_velocity: bool = False, gravity_w: Any = None,
                 sensor_options: Mapping[str, Any] | None = None, reuse_outputs: bool = False) -> None:
        if isinstance(tick_s, bool) or not isinstance(tick_s, (int, float, np.floating, np.integer)):
            raise TypeError(f"tick_s must be a number of seconds, got {tick_s!r}")
        if not (math.isfinite(tick_s) and tick_s > 0.0):
            raise ValueError(f"tick_s must be positive and finite, got {tick_s!r}")
        self.tick_s = float(tick_s)
        self.frames = HostFrames.coerce(frames)
        mounting = Mounting() if mounting is None else mounting
        if not isinstance(mounting, Mounting):
            raise TypeError(f"mounting must be a Mounting, got {type(mounting).__name__}")
        self.mounting = mounting
        self.position_b_m = self.frames.body_to_flu(mounting.position_m)  # FLU, from the reference point
        q_chip = None if mounting.q_body_chip is None else self.frames.mounting_to_package(mounting.q_body_chip)
        if site is None:
            site = EarthField()
        self.environment = site if isinstance(site, MagneticEnvironment) else MagneticEnvironment(site)
        if not isinstance(speed_from_velocity, (bool, np.bool_)):
            raise TypeError(f"speed_from_velocity must be True or False, got {speed_from_velocity!r}")
        self.speed_from_velocity = bool(speed_from_velocity)
        if not isinstance(reuse_outputs, (bool, np.bool_)):
            raise TypeError(f"reuse_outputs must be True or False, got {reuse_outputs!r}")
        self.reuse_outputs = bool(reuse_outputs)
        g = self.frames.standard_gravity_w() if gravity_w is None else np.asarray(gravity_w, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"gravity_w must be 3 finite numbers (m/s², host world axes), got {gravity_w!r}")
        self.gravity_enu = self.frames.world_to_enu(g)
        try:
            self.sensor = MPU9250(profile, seed=seed, registers=registers, mounting=q_chip,
                                  input_rate_hz=1.0 / self.tick_s, **dict(sensor_options or {}))
        except ValueError as exc:
            if "input_rate_hz" in str(exc):
                raise ValueError(f"tick_s = {self.tick_s!r} s (truth at {1.0 / self.tick_s:g} Hz) cannot drive the "
                                 f"chip: {exc}") from None
            raise
        self.estimators: dict[str, Estimator] = {}
        self._feeds: dict[str, tuple[bool, bool]] = {}  # label → (imu_flags, speed_mps)
        for label, name, params in _estimator_list(estimators):
            self.estimators[label] = self._make_estimator(label, name, params)
        ned, frd, scalar_last = (bool(c) for c in self.frames.codes)
        self._host = K.HostMap(ned, frd, scalar_last, bool(np.any(self.position_b_m)), self.position_b_m,
                               self.gravity_enu, self.tick_s, float(self.sensor.input_rate_hz))
        self._clock = np.zeros(K.CLOCK_SIZE)  # t₀, ticks, whether _last_tick holds the previous tick
        self._last_tick = np.zeros(K.LAST_SIZE)  # the previous tick's q_wb, ω_b, v_w (package frames)
        self._gives_speed = any(speed for _, speed in self._feeds.values())
        self._temp_default_c = float(self.sensor.loop_arrays()[4])  # the profile's die temperature
        self._plan: _Plan | None = None
        self._versioned = (self.sensor, *self.estimators.values())  # whose arrays_version the plan depends on
        self.fast_path = True
        """True (default): each call is one compiled call (``_tick.tick_kernel``) with the
        estimators that declare a ``loop_kernel`` inside it; False: one Python call per
        stage (the general path, also taken with local magnetic disturbances). The same
        numbers either way, bit for bit."""
        # what a tick that latches no sample returns (most ticks: the ODR is below the tick
        # rate); its arrays are empty, so one object serves every such call
        none = _empty_samples()
        self._no_samples = PluginOutput(_NO_ROWS, none, _NO_Q, {
            label: EstimateOutput(empty_estimate(e.estimates_bias), _NO_Q, self.frames)
            for label, e in self.estimators.items()}, self.frames)
        self.reset()

    def _make_estimator(self, label: str, name: str, params: dict[str, Any]) -> Estimator:
        try:
            inputs = estimator_inputs(name)
        except ValueError as exc:
            raise ValueError(f"estimators: {exc}") from None
        missing = sorted(set(inputs) - _TAKEN_INPUTS - {"velocity_enu_mps", "dtheta_b"})
        if missing:
            raise ValueError(f"estimators: {name!r} needs input(s) {missing} that the plug-in does not give "
                             "(GNSS-aided estimators need a GNSS receiver: use the co-simulation)")
        known = {row["name"] for row in describe_estimator(name)["params"]}
        if "declination_rad" in known and "declination_rad" not in params:
            params["declination_rad"] = self.environment.earth.declination_rad
        speed = self.speed_from_velocity and "speed_mps" in inputs
        if speed and "speed_point_b_m" in known and "speed_point_b_m" not in params and np.any(self.position_b_m):
            params["speed_point_b_m"] = tuple(float(-x) for x in self.position_b_m)
        try:
            est = make_estimator(name, self.sensor.output_rate_hz, **params)
        except (ValueError, TypeError) as exc:
            raise type(exc)(f"estimators[{label!r}] ({name}): {exc}") from None
        if est.gyro_increments is not None:
            raise ValueError(f"estimators[{label!r}]: gyro_step={est.params.gyro_step!r} needs the chip's increments, "
                             "which the plug-in does not give; use gyro_step='hold'")
        self._feeds[label] = ("imu_flags" in inputs, speed)
        return est

    # ---- properties ----------------------------------------------------------------------

    @property
    def output_rate_hz(self) -> float:
        """The chip's accelerometer/gyro output data rate (Hz): the estimators' sample rate."""
        return self.sensor.output_rate_hz

    @property
    def ticks(self) -> int:
        """Ticks taken since the start (or the last ``reset``)."""
        return int(self._clock[K.CLOCK_TICKS])

    @property
    def next_tick_s(self) -> float | None:
        """The host time the next tick must have (None before the first tick: any time)."""
        t0 = self._t0
        return None if t0 is None else t0 + self.ticks * self.tick_s

    @property
    def _t0(self) -> float | None:
        return float(self._clock[K.CLOCK_T0]) if self._clock[K.CLOCK_HAS_LAST] else None

    @property
    def in_loop_estimators(self) -> tuple[str, ...]:
        """The estimators that run inside the plug-in's compiled call (each declares a
        ``loop_kernel`` and gives ``loop_arrays``; ``biso_cosim.loop``); the others run by
        ``update`` after it. None run inside it with local magnetic disturbances (the call
        takes the Earth's field alone) or with ``fast_path`` off: the whole call then takes
        the general path."""
        if not self.fast_path or self.environment.disturbances:
            return ()
        return tuple(label for label, est in self.estimators.items()
                     if est.gyro_increments is None and est.loop_arrays(0) is not None)

    # ---- state -----------------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> None:
        """Back to before the first tick: the same part and noise stream start again (with an
        int ``seed``, a part drawn anew from it); estimators forget everything."""
        self.sensor.reset(seed)
        for est in self.estimators.values():
            est.reset()
        self._clock[:] = 0.0
        self._last_tick[:] = 0.0

    def get_state(self) -> PluginState:
        """A copy of the whole dynamic state (sensor, estimators, clock, previous tick)."""
        started = bool(self._clock[K.CLOCK_HAS_LAST])
        return PluginState(self.sensor.get_state(), {k: e.get_state() for k, e in self.estimators.items()},
                           self.ticks, self._t0, self._last_tick.copy() if started else None)

    def set_state(self, state: PluginState) -> None:
        """Restore a state from ``get_state`` of this plug-in (or one built with the same
        arguments); a state that does not fit raises ValueError and changes nothing."""
        if not isinstance(state, PluginState):
            raise TypeError(f"state must be a PluginState from get_state(), got {type(state).__name__}")
        if set(state.estimators) != set(self.estimators):
            raise ValueError(f"state holds estimators {sorted(state.estimators)}, this plug-in has "
                             f"{sorted(self.estimators)}")
        last = None if state.last_tick is None else np.array(state.last_tick, dtype=np.float64)
        if (last is None) != (state.t0_s is None) or (last is not None and last.shape != (10,)) or state.ticks < 0:
            raise ValueError("state is not a PluginState of a plug-in (ticks, t0_s and last_tick disagree)")
        saved = self.get_state()
        try:
            self.sensor.set_state(state.sensor)
            for label, est in self.estimators.items():
                est.set_state(state.estimators[label])
        except (ValueError, TypeError):
            self.sensor.set_state(saved.sensor)
            for label, est in self.estimators.items():
                est.set_state(saved.estimators[label])
            raise
        self._clock[K.CLOCK_T0] = 0.0 if last is None else float(state.t0_s)
        self._clock[K.CLOCK_TICKS] = int(state.ticks)
        self._clock[K.CLOCK_HAS_LAST] = last is not None
        self._last_tick[:] = 0.0 if last is None else last

    # ---- stepping --------------------------------------------------------------------------

    def step(self, t_s: Any, q_wb: Any, omega_b: Any, specific_force_b: Any = None, *, accel_w: Any = None,
             alpha_b: Any = None, p_w: Any = None, v_w: Any = None, temperature_c: Any = None) -> PluginOutput:
        """Take the host's truth of one tick (scalar ``t_s``, vectors (3,), ``q_wb`` (4,)) or of
        a block of n consecutive ticks (``t_s`` (n,), vectors (n, 3), ``q_wb`` (n, 4)), in the
        host's conventions, at the host's reference point:

        * ``t_s``: host time; the first tick fixes t₀, tick k must come at t₀ + k·tick_s;
        * ``q_wb``: attitude, world ← body; ``omega_b``: angular rate, rad/s, body axes;
        * ``specific_force_b`` (m/s², body axes; +g up at rest), or instead ``accel_w``: the
          acceleration in m/s², world axes (the plug-in subtracts ``gravity_w``);
        * ``alpha_b``: angular acceleration, rad/s², body axes, for the lever arm (default:
          the slope of ω between ticks);
        * ``p_w`` (m) and ``v_w`` (m/s), world axes: position (for the magnetic field of
          local disturbances) and velocity (for ``speed_from_velocity``); default zero;
        * ``temperature_c``: die temperature (a number, or (n,)); default the profile's.

        Returns the samples the chip latched on these ticks, the estimates after each and the
        truth at their instants (``PluginOutput``). Bad input (NaN, a quaternion that is not
        unit, a tick out of time, wrong shapes) raises ValueError naming the argument, and
        changes nothing.
        """
        # every array handed to the compiled call is float64 of the dimensions of its type:
        # (w,) vectors for one tick (any strides), C-contiguous (n, w) rows for a block
        single = type(t_s) is float or isinstance(t_s, (int, np.floating, np.integer)) or np.ndim(t_s) == 0
        if single:
            t: Any = float(t_s)
            n, absent, rows = 1, _NO_ROWS, _vector
        else:
            t = _series("t_s", t_s)
            n, absent, rows = t.shape[0], _NO_ROWS3, _rows
        q = rows("q_wb", q_wb, n, 4)
        omega = rows("omega_b", omega_b, n, 3)
        if (specific_force_b is None) == (accel_w is None):
            raise ValueError("give either specific_force_b (body axes) or accel_w (world axes), not "
                             + ("both" if accel_w is not None else "neither"))
        force = rows("specific_force_b", specific_force_b, n, 3) if accel_w is None else absent
        accel = absent if accel_w is None else rows("accel_w", accel_w, n, 3)
        alpha = absent if alpha_b is None else rows("alpha_b", alpha_b, n, 3)
        p = absent if p_w is None else rows("p_w", p_w, n, 3)
        if v_w is None and self._gives_speed:
            raise ValueError("v_w is required at every tick: the plug-in was built with speed_from_velocity=True")
        v = absent if v_w is None else rows("v_w", v_w, n, 3)
        if temperature_c is None:
            temp, temp_default = _NO_ROWS, self._temp_default_c
        elif np.ndim(temperature_c) == 0:
            temp, temp_default = _NO_ROWS, float(temperature_c)
            if not math.isfinite(temp_default):
                raise ValueError(f"temperature_c must be finite, got {temperature_c!r}")
        else:
            temp, temp_default = _series("temperature_c", temperature_c, n), 0.0
        given = K.HostRows._make((t, q, omega, force, accel, alpha, p, v, temp, temp_default))
        if not self.fast_path or self.environment.disturbances:
            return self._step_general(given, single, None if temperature_c is None or temp.shape[0] else temp_default)
        plan = self._plan
        if plan is None or n > plan.rows or list(map(_ARRAYS_VERSION, self._versioned)) != plan.versions:
            plan = self._tick_plan(n)
        call = plan.calls[single] or self._compile(plan, single)
        code, value = call(plan.record, given)
        if code != TICK_OK:
            if code == TICK_SENSOR:  # (inputs checked by the call: a fault of the plug-in, not of the host)
                raise RuntimeError(f"the MPU-9250 kernel refused the plug-in's checked rows (status {int(value)}; "
                                   "-2: its outputs' bound is wrong)")
            raise ValueError(self._bad_input(int(code), int(value), given, single))
        if value == 0 and not plan.after:
            return self._no_samples
        return self._output(plan, int(value))

    def _tick_plan(self, n: int) -> "_Plan":
        """The compiled call's arrays for calls of up to n ticks, kept while the sensor's and
        the estimators' ``arrays_version`` hold (a reset or a restored state replaces arrays)."""
        plan = self._plan
        versions = list(map(_ARRAYS_VERSION, self._versioned))
        rows = max(n, 1 if plan is None else plan.rows)
        floats, words, status_bytes, flags = self.sensor.output_arrays(rows)
        bound = flags.shape[0]
        sensor = SensorArrays(*self.sensor.loop_arrays(), 0, 0, 0.0)
        outputs = SampleOutputs(floats, words, status_bytes, flags, np.empty(bound, dtype=np.int64))
        truth = TruthAtSamples(np.empty(bound), np.empty((bound, 4)), np.empty(bound), self._gives_speed,
                               np.empty((0, 0)))
        in_loop, after = [], []
        for label, est in self.estimators.items():
            arrays = est.loop_arrays(bound) if est.gyro_increments is None else None  # (no increments here)
            if arrays is None:
                after.append((label, est))
            else:
                in_loop.append((label, est, arrays))
        record = TickPlan(self._host, self._clock, self._last_tick, self.environment.earth.field_enu_ut, sensor,
                          outputs, truth, TickScratch.for_rows(rows),
                          tuple((type(est).loop_kernel, arrays) for _, est, arrays in in_loop))
        self._plan = _Plan(record, typeof(record), [None, None], rows, versions, (floats, words, status_bytes, flags),
                           truth, tuple(in_loop), tuple(after), {})
        return self._plan

    @staticmethod
    def _compile(plan: "_Plan", single: bool) -> Any:
        """The compiled call of ``plan`` for one tick or for blocks (on the first such call)."""
        call = compiled_call(plan.record_type, _SINGLE_TRUTH if single else _BLOCK_TRUTH)
        plan.calls[single] = call
        return call

    def _output(self, plan: "_Plan", k: int) -> PluginOutput:
        """The compiled call's k samples, truth and in-loop estimates (views of the plan's
        arrays, made once per k, with ``reuse_outputs``; else copies), and the estimators
        that run after it."""
        out = plan.views.get(k)
        if out is None:
            out = self._plan_output(plan, k)
            if self.reuse_outputs:
                plan.views[k] = out
        if not plan.after:
            return out
        estimates = dict(out.estimates)
        estimates.update(self._estimate(plan.after, out.samples, plan.truth.speed_mps[:k], out.q_true_wb))
        return PluginOutput(out.t_s, out.samples, out.q_true_wb, {label: estimates[label] for label in self.estimators},
                            self.frames)

    def _plan_output(self, plan: "_Plan", k: int) -> PluginOutput:
        """The first k rows of the plan's samples, truth and in-loop estimates: views with
        ``reuse_outputs``, else copies (the next call writes the plan's arrays again)."""
        own = _view if self.reuse_outputs else np.copy
        samples = self.sensor.sample_views(tuple(map(own, plan.outputs)), k)
        q_true = own(plan.truth.q_wb[:k])
        estimates = {}
        for label, est, arrays in plan.in_loop:
            e = est.loop_estimate(arrays, k)
            estimates[label] = EstimateOutput(Estimate(own(e.q_wb), own(e.flags),
                                                       None if e.gyro_bias_b is None else own(e.gyro_bias_b)),
                                              q_true, self.frames)
        return PluginOutput(own(plan.truth.t_s[:k]), samples, q_true, estimates, self.frames)

    def _estimate(self, estimators: Any, samples: ImuSamples, speed: np.ndarray, q_true: np.ndarray
                  ) -> dict[str, EstimateOutput]:
        """Estimators ``(label, estimator)`` by ``update`` on the samples."""
        estimates = {}
        for label, est in estimators:
            flags_in, speed_in = self._feeds[label]
            extra: dict[str, Any] = {}
            if flags_in:
                extra["imu_flags"] = samples.flags
            if speed_in:
                extra["speed_mps"] = speed
            estimates[label] = EstimateOutput(est.update(samples.gyro_b, samples.accel_b, samples.mag_b, **extra),
                                              q_true, self.frames)
        return estimates

    def _step_general(self, given: K.HostRows, single: bool, temperature: float | None) -> PluginOutput:
        """``step`` by one Python call per stage: the magnetic field of local disturbances
        (``MagneticEnvironment.field_b``), the chip (``MPU9250.simulate``), every estimator by
        ``update``; the same kernels for the rest, so the same numbers."""
        n = 1 if single else given.t_s.shape[0]
        scratch = TickScratch.for_rows(n)
        chip = scratch.chip
        code, row = K.prepare(self._host, self._clock, self._last_tick, given, chip)
        if code:
            raise ValueError(self._bad_input(int(code), int(row), given, single))
        t = np.array([given.t_s]) if single else given.t_s
        t0 = self._t0 if self._t0 is not None else float(t[0])
        mag_b = self.environment.field_b(chip.q_wb, chip.p_w, t)
        samples = self.sensor.simulate(chip.omega_b, chip.specific_force_b, mag_b,
                                       given.temperature_c if given.temperature_c.shape[0] else temperature)
        k = samples.t_s.shape[0]
        q_true, speed = np.empty((k, 4)), np.empty(k)
        K.finish_ticks(self._host, self._clock, self._last_tick, given, chip, n, samples.t_s, q_true, speed,
                       scratch.q_rows, scratch.v_rows)
        if k == 0:
            return self._no_samples
        return PluginOutput(t0 + samples.t_s, samples, q_true,
                            self._estimate(self.estimators.items(), samples, speed, q_true), self.frames)

    def _bad_input(self, code: int, row: int, given: K.HostRows, single: bool) -> str:
        name = K.BAD_INPUTS[code]
        where = "" if single else f" (row {row})"
        t = np.array([given.t_s]) if single else given.t_s
        q = given.q_wb.reshape(-1, 4)
        due = float((t[0] if self._t0 is None else self._t0) + (self.ticks + row) * self.tick_s)
        t = t.astype(object)  # Python floats in the messages
        if code == 2:
            before, tol = due - self.tick_s, K.TIME_TOL * self.tick_s
            what = ("went backwards" if t[row] < before - tol else
                    "repeats the previous tick" if t[row] <= before + tol else "came early")
            return (f"t_s{where} {what}: got {t[row]!r} s, the next tick is due at {due!r} s "
                    f"(tick_s = {self.tick_s!r} s)")
        if code == 3:
            return (f"t_s{where} = {t[row]!r} s is not the next tick, due at {due!r} s: ticks must come every "
                    f"tick_s = {self.tick_s!r} s, without gaps (the tick period is fixed: the chip's rates "
                    f"must divide it)")
        if code == 5:
            norm = float(np.linalg.norm(q[row]))
            return f"q_wb{where} must be a unit quaternion (|q| = 1 ± {K.QUAT_NORM_TOL:g}), got |q| = {norm!r}"
        if code == 1:
            return f"t_s{where} must be finite, got {t[row]!r}"
        return f"{name}{where} must be finite (no NaN or inf)"

    def __repr__(self) -> str:
        return (f"ImuPlugin(tick_s={self.tick_s!r}, frames={self.frames}, sensor={self.sensor!r}, "
                f"estimators={list(self.estimators)})")


_NO_Q = np.empty((0, 4))
_ARRAYS_VERSION = operator.attrgetter("arrays_version")
_ANY_STRIDES = np.zeros(4)[::2]  # a strided (2,): its numba type is a 1-d float64 array of any layout
assert typeof(_ANY_STRIDES).layout == "A"  # (numpy calls arrays of one element contiguous, whatever their strides)
_SINGLE_TRUTH = K.HostRows(0.0, _ANY_STRIDES, _ANY_STRIDES, _ANY_STRIDES, _ANY_STRIDES, _ANY_STRIDES, _ANY_STRIDES,
                           _ANY_STRIDES, _NO_ROWS, 0.0)
_BLOCK_TRUTH = K.HostRows(_NO_ROWS, np.zeros((1, 4)), _NO_ROWS3, _NO_ROWS3, _NO_ROWS3, _NO_ROWS3, _NO_ROWS3, _NO_ROWS3,
                          _NO_ROWS, 0.0)
"""The two kinds of truth ``step`` gives the compiled call (one tick; a block of ticks): its types."""


class _Plan(NamedTuple):
    """The compiled call's record, its numba type and its compiled functions for blocks and
    for one tick (``calls[False]``, ``calls[True]``: ``_tick.compiled_call``, made on first
    use), and what ``step`` reads of it: calls of up to ``rows`` ticks, built at these
    array ``versions``; the chip's output arrays; the truth at the samples; the in-loop
    estimators (label, estimator, loop arrays) and those after it; the outputs made of its
    arrays for each number of samples k (``reuse_outputs``)."""

    record: TickPlan
    record_type: Any
    calls: list
    rows: int
    versions: list
    outputs: tuple
    truth: TruthAtSamples
    in_loop: tuple
    after: tuple
    views: dict


def _empty_samples() -> ImuSamples:
    """ImuSamples of no sample (read-only arrays: one object is shared by every such call)."""
    arrays = [np.empty(0), np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)), np.empty(0, dtype=bool), np.empty(0),
              np.empty(0, dtype=np.int32), np.empty((0, 10), dtype=np.int16), np.empty((0, 2), dtype=np.uint8)]
    for a in arrays:
        a.flags.writeable = False
    return ImuSamples(*arrays[:7], RawSamples(arrays[7], arrays[8]))


def _view(a: np.ndarray) -> np.ndarray:
    return a


def _series(name: str, value: Any, n: int | None = None) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be real numbers, got {type(value).__name__}") from None
    if a.ndim != 1 or a.shape[0] == 0 or (n is not None and a.shape[0] != n):
        want = "a non-empty (n,) array" if n is None else f"shape ({n},) like t_s"
        raise ValueError(f"{name} must have {want}, got shape {a.shape}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


def _vector(name: str, value: Any, n: int, width: int) -> np.ndarray:
    """One tick's vector of ``width`` numbers as float64 (width,) (any strides)."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be real numbers, got {type(value).__name__}") from None
    if a.shape != _VECTOR_SHAPES[width]:
        raise ValueError(f"{name} must have shape ({width},) for one tick, got {a.shape}")
    return a


_VECTOR_SHAPES = {3: (3,), 4: (4,)}


def _rows(name: str, value: Any, n: int, width: int) -> np.ndarray:
    """A block's rows of ``width`` numbers as C-contiguous float64 (n, width)."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be real numbers, got {type(value).__name__}") from None
    if a.shape != (n, width):
        raise ValueError(f"{name} must have shape ({n}, {width}) like t_s, got {a.shape}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)
