"""The co-simulation loop: vehicle → MPU-9250 → estimators, one control period at a time.

docs/design.md §3: the physics runs at ``physics_rate_hz`` (1 kHz) in chunks of one control
period; after each chunk the virtual MPU-9250 and every estimator are called once with the
chunk's arrays (one jitted kernel call each, never a Python call per sample). The truth is
taken at the IMU site (body axes = IMU site axes) and interpolated to the sensor's output
time stamps, so every estimate is compared with the attitude at the instant it refers to.

>>> result = run_route("figure8", seed=0)              # the scripted driver, BISO + Poisson
>>> result.summary()["estimators"]["biso"]["errors"]["roll"]["rms_deg"]
"""

from __future__ import annotations

import copy
import itertools
import math
import signal
import threading
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, NamedTuple

import mujoco
import numpy as np

from biso_cosim._period import (_ARG_AT, _ARG_BEFORE, _ARG_FIRST_STEP, _ARG_FLAGS, _ARG_ODOMETRY, _ARG_OUT, _ARG_PACKED,
                                 _ARG_T_START, _sense_estimate_period, _sensor_inputs)
from biso_cosim.estimators import Estimate, Estimator, make_estimator
from biso_cosim.estimators.biso import BisoEstimator
from biso_cosim.estimators.biso_plus import BisoPlusEstimator
from biso_cosim.frames import quat_angle_between, wrap_angle
from biso_cosim.metrics import ANGLES, angle_errors_deg, attitude_angles_deg, error_stats, start_end_difference
from biso_cosim.routes import Route, load_route
from biso_cosim.sensors import MPU9250, EarthField, ImuSamples, MagneticEnvironment
from biso_cosim.vehicle.driver import DriverCommand
from biso_cosim.vehicle._kernels import _wheel_odometry
from biso_cosim.vehicle.sim import _NO_ROWS, PHYSICS_STATE, Truth, VehicleSim

__all__ = ["EstimatorSpec", "CoSimulation", "CoSimState", "RunResult", "run_route", "DEFAULT_ESTIMATORS", "DEFAULT_SENSOR_PROFILE",
           "NAVIGATOR_PRESETS"]

DEFAULT_SENSOR_PROFILE = "mpu9250_calibrated"
"""A typical MPU-9250 after the usual start-up calibration (see docs/sensors.md)."""

DEFAULT_ESTIMATORS = ("biso", "biso_plus", "poisson")
"""Estimators of a run unless told otherwise: the paper's BISO, its vehicle variant, and the
uncorrected integration they improve on."""

NAVIGATOR_PRESETS = {
    "one_sample": {"coning": "one_sample", "sculling": "traditional1", "position": "rectangle"},
    "two_sample": {"coning": "two_sample", "sculling": "traditional2", "position": "trapezoid"},
    "smoothing": {"coning": "smoothing", "sculling": "smoothing", "position": "exact"},
    "invariant": {"coning": "invariant", "sculling": "invariant_rate1", "position": "exact"},
}
"""Dead-reckoning navigators by family (Litmanovich 2002): coning, sculling and position
algorithms; the update interval is the sensor's output interval."""

# Length of the windows over which the start and end angles of a closed route are averaged
# (the car stands still in both: before driving off, and after the driver has stopped it at
# the finish; the run lasts at least this long after that).
_WINDOW_S = 1.0

# Every log (a run from reset, or a history begun by set_state) gets its own number, so that
# set_state cuts back only the log that a state belongs to.
_LOG_GENERATIONS = itertools.count(1)
# the period kernel's history argument when the rows are given (``_sense_period``)
_NO_HISTORY = np.empty(0)
# The estimators the period kernel can run itself (``CoSimulation._lane``): its slots a, b
# take BISO estimators, c a BISO+; each slot's arguments are (coef, state, *outputs).
_LANE_SLOTS = ((BisoEstimator, 0), (BisoEstimator, 1), (BisoPlusEstimator, 2))
_NO_VELOCITY = np.empty((0, 3))
_NO_SCRATCH = np.empty((0, 0))
_NO_LANE = (np.empty(0), np.empty(0), np.empty((0, 4)), np.empty(0, dtype=np.int64)) * 2 + (
    np.empty(0), np.empty(0), np.empty((0, 4)), np.empty(0, dtype=np.int64), np.empty((0, 3)))
# ``CoSimulation.step``'s command from a caller that has written the period's controls into
# MuJoCo's ctrl itself, after checking them (an environment's action, ``Driving-v0``): the
# period runs as with a DriverCommand of those controls, without making and checking one.
_CONTROLS_APPLIED = object()


def _lane_outputs(bound: int, slots: Iterable[int] = (0, 1, 2)) -> list[tuple[np.ndarray, ...] | None]:
    """The period kernel's estimator outputs for up to ``bound`` samples, by slot (None for
    a slot not in ``slots``): (q_wb, flags) for a and b, (q_wb, flags, gyro bias) for c."""
    out: list[tuple[np.ndarray, ...] | None] = [None, None, None]
    for slot in slots:
        bias = (np.empty((bound, 3)),) if slot == 2 else ()
        out[slot] = (np.empty((bound, 4)), np.empty(bound, dtype=np.int64), *bias)
    return out


def _lane_estimates(outputs: list[tuple[np.ndarray, ...] | None], k: int) -> list[Estimate | None]:
    """The estimates of the first k samples in the period kernel's estimator outputs, by slot."""
    return [None if slot is None else Estimate(*(a[:k] for a in slot)) for slot in outputs]


def _buffer_view(views: dict, k: int, out: tuple, increments: int, subintervals: int,
                 lane_out: list) -> tuple[ImuSamples, list[Estimate | None]]:
    """The samples and the lane's estimates in the first k rows of reused outputs (status
    -1; ``_sensor_buffers``), made once for each k."""
    view = views.get(k)
    if view is None:
        view = views[k] = (MPU9250._samples(-1, k, out, increments, subintervals), _lane_estimates(lane_out, k))
    return view


class PeriodHook(NamedTuple):
    """A caller's own work after each period, run in the period kernel's call when the
    period is planned (``_PeriodPlan``): one call into compiled code and its Python less per
    period, each a few microseconds in the loop (the physics evicts them from the caches).

    ``kernel(period, q, *args)`` runs ``_sense_estimate_period(*period)`` and, on its status
    -1, the work on the period's samples (``_period_samples(period, k)``), and returns the
    (status, k); ``q`` holds the q_wb outputs (one row per possible sample) of the lane's
    ``estimates`` named, in their order. After ``step``, ``CoSimulation._hook_ran`` tells
    whether it ran; when not, the caller does the work itself on what ``step`` returned."""

    kernel: Callable
    estimates: tuple[str, ...]
    args: tuple


class _PeriodPlan:
    """The period kernel's arguments, gathered once for the periods that follow while they
    hold: for a co-simulation whose caller consumes each period's outputs within the period
    (``_sensor_buffers``) and whose estimators all run in the kernel (``_lane_only``).

    Every array in them stays the same object while the simulation runs on, except those
    ``after`` checks: the sensor's parameters and state, the estimators' coefficients and
    states (a reset, a restored state or a change of parameters replaces them; BISO's
    change of equal gains writes its coefficients in place), and the caller's
    ``PeriodHook``, run in the same call. Two variants alternate: each
    writes the truth rows into its own array and reads the newest row of the other's as
    the row before the period. Which one is next is told by the identity of
    ``_last_truth_row``; after a reset or a restored state (None, or a new row) none is,
    and the general path plans again."""

    def __init__(self, sim: "CoSimulation", args: list, lane: tuple, lane_out: list, views: dict):
        imu, hook = sim.imu, sim._period_hook
        self._sources = ((imu, "_cp", imu._cp), (imu, "_cs", imu._cs), (imu, "_chs", imu._chs),
                         (sim, "_period_hook", hook),
                         *((est, name, getattr(est, name)) for _, est, _ in lane for name in ("_coef", "_state")))
        first = args[_ARG_PACKED]
        second = np.empty_like(first)
        self.first_row, second_row = Truth._of(first[-1:]), Truth._of(second[-1:])
        reads_second, reads_first = list(args), list(args)
        reads_second[_ARG_BEFORE] = second_row.packed
        reads_first[_ARG_BEFORE], reads_first[_ARG_PACKED] = self.first_row.packed, second
        self._next = {self.first_row: (reads_first, second_row), second_row: (reads_second, self.first_row)}
        self._buffers = (views, tuple(args[_ARG_OUT:_ARG_OUT + 4]), sim._increment_orders, sim._subintervals,
                         args[_ARG_AT], lane_out)
        self._slots = tuple((key, slot) for key, _, slot in lane)
        self._views: dict[int, tuple] = {}
        slots = dict(self._slots)
        self.hook = None  # (kernel, q outputs, args) of the caller's hook, when its estimates are in the lane
        if hook is not None and all(key in slots for key in hook.estimates):
            self.hook = (hook.kernel, tuple(lane_out[slots[key]][0] for key in hook.estimates), hook.args)

    def after(self, last_row: Truth | None) -> tuple[list, Truth] | None:
        """The arguments for the period after the one whose newest truth row is ``last_row``
        and the newest row they leave, or None when the plan no longer holds."""
        variant = self._next.get(last_row)
        if variant is None:
            return None
        for owner, name, value in self._sources:
            if getattr(owner, name) is not value:
                return None
        return variant

    def view(self, k: int) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """What a period of k samples returns: the samples, the truth at them, the estimates
        (views of the reused arrays, made once for each k)."""
        view = self._views.get(k)
        if view is None:
            views, out, increments, subintervals, at, lane_out = self._buffers
            samples, estimates = _buffer_view(views, k, out, increments, subintervals, lane_out)
            view = self._views[k] = (samples, Truth._of(at[:k]), {key: estimates[slot] for key, slot in self._slots})
        return view


def _check_command(command: Any, max_steer_rad: float) -> None:
    """An agent's command: a DriverCommand of finite values within the actuators' ranges."""
    if not isinstance(command, DriverCommand):
        raise TypeError(f"command must be a DriverCommand(steer_rad, drive, brake), got {type(command).__name__}")
    steer, drive, brake = command.steer_rad, command.drive, command.brake
    if (type(steer) is float and type(drive) is float and type(brake) is float
            and -max_steer_rad <= steer <= max_steer_rad and -1.0 <= drive <= 1.0 and 0.0 <= brake <= 1.0):
        return  # the common case in one expression (NaN compares false; inf is out of range)
    for name, low, high in (("steer_rad", -max_steer_rad, max_steer_rad), ("drive", -1.0, 1.0), ("brake", 0.0, 1.0)):
        value = getattr(command, name)
        if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and low <= value <= high):
            raise ValueError(f"command.{name} must be a finite number in [{low:g}, {high:g}], got {value!r}")


def _profile_content(profile: Any) -> str:
    """A sensor profile file's content (a profile given by name or object: its repr)."""
    if isinstance(profile, (str, Path)) and str(profile).endswith(".toml") and Path(profile).is_file():
        return Path(profile).read_text()
    return repr(profile)


@dataclass(frozen=True)
class EstimatorSpec:
    """One estimator of a run: registry name, parameters, and the label it is reported under;
    or a user's own estimator ``instance`` (see :class:`CoSimulation`)."""

    name: str
    params: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""
    instance: Any = None

    @property
    def key(self) -> str:
        return self.label or self.name


def _gyro_step(est: Any):
    """The coning algorithm an estimator's ``gyro_step`` parameter names, or None."""
    params = getattr(est, "params", None)
    if "dtheta_b" not in getattr(est, "inputs", ()) or getattr(params, "gyro_step", "hold") == "hold":
        return None
    from biso_cosim.strapdown.algorithms import get_algorithm

    return get_algorithm("coning", params.gyro_step)


class _UserEstimator:
    """Adapts a user's estimator: ``update(gyro_b, accel_b, mag_b)`` returning (k, 4) ``q_wb``
    or an object with ``q_wb`` (and optionally ``flags``); ``reset()`` if it has one."""

    def __init__(self, instance: Any, label: str):
        if not callable(getattr(instance, "update", None)):
            raise ValueError(f"estimator {label!r}: a user estimator needs an update(gyro_b, accel_b, mag_b) method")
        self.instance = instance
        self.label = label

    def reset(self) -> None:
        reset = getattr(self.instance, "reset", None)
        if callable(reset):
            reset()

    def update(self, gyro_b, accel_b, mag_b) -> Estimate:
        out = self.instance.update(gyro_b, accel_b, mag_b)
        k = gyro_b.shape[0]
        if isinstance(out, np.ndarray):  # (an ndarray's own .flags are memory flags)
            q, flags = out, None
        else:
            q, flags = getattr(out, "q_wb", out), getattr(out, "flags", None)
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (k, 4):
            raise ValueError(f"estimator {self.label!r}: update() returned shape {q.shape}, expected ({k}, 4) q_wb")
        flags = np.zeros(k, dtype=np.int64) if flags is None else np.asarray(flags, dtype=np.int64).reshape(k)
        return Estimate(q_wb=q, flags=flags)


def _estimator_specs(estimators: Iterable[str | EstimatorSpec | tuple]) -> tuple[EstimatorSpec, ...]:
    if isinstance(estimators, (str, EstimatorSpec)):
        estimators = (estimators,)
    specs = []
    for item in estimators:
        if isinstance(item, EstimatorSpec):
            specs.append(item)
        elif isinstance(item, str):
            specs.append(EstimatorSpec(item))
        elif isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str) and isinstance(item[1], Mapping):
            specs.append(EstimatorSpec(item[0], dict(item[1])))
        elif callable(getattr(item, "update", None)):
            name = getattr(item, "name", None) or type(item).__name__
            specs.append(EstimatorSpec(str(name), instance=item))
        else:
            raise ValueError(f"estimators: expected names, (name, params) pairs, EstimatorSpec or objects with "
                             f"an update(gyro_b, accel_b, mag_b) method, got {item!r}")
    if not specs:
        raise ValueError("estimators: give at least one estimator")
    keys = [s.key for s in specs]
    if len(set(keys)) != len(keys):
        raise ValueError(f"estimators: labels must be unique, got {keys} (set EstimatorSpec.label)")
    return tuple(specs)


class CoSimulation:
    """A route driven by the scripted driver with the virtual MPU-9250 and estimators in the loop.

    Parameters
    ----------
    route : library name, route file path, or :class:`~biso_cosim.routes.Route`.
    duration_s : simulated time; default the route's nominal duration plus 10 s at rest.
    seed : seed of the sensor's random errors (the vehicle and driver are deterministic).
    estimators : names (``biso_cosim.estimators.estimator_names()``), ``(name, params)`` pairs,
        :class:`EstimatorSpec`, or your own estimator objects: anything with
        ``update(gyro_b, accel_b, mag_b)`` that returns the (k, 4) ``q_wb`` of the k samples
        it was given (or an object with ``q_wb`` and optionally ``flags``), called once per
        control period in the loop; ``reset()`` is called on reset if it exists. All see the
        same sensor samples (SI, body axes, at ``output_rate_hz``).
    sensor_profile, registers, mounting : passed to :class:`biso_cosim.sensors.MPU9250`. The
        default profile is the chip after the usual start-up calibration (residual errors);
        ``"mpu9250"`` is the raw chip with the datasheet tolerances.
    gyro_calibration_s : before time zero the sensor is read for this long with the car at
        rest and the mean gyro reading is subtracted from every later reading, as an MPU-9250
        driver does with the gyro offset registers at start-up: use it with the raw
        ``"mpu9250"`` profile, whose ±5 °/s turn-on bias otherwise dominates every gyro-only
        result. 0 (the default) disables it.
    gnss : the virtual GNSS receiver (:class:`biso_cosim.sensors.GnssReceiver`): ``"auto"``
        (default) runs one when an estimator takes GNSS fixes, a profile name (``"consumer"``,
        ``"ideal"``) or a :class:`~biso_cosim.sensors.GnssProfile` always runs one, ``None``
        never. It sits at the IMU (no lever arm), is seeded from ``seed``, and has no fix in
        the route's ``gnss_outage`` zones.
    gnss_rate_hz : its fix rate.
    navigators : dead-reckoning navigators (:class:`biso_cosim.strapdown.StrapdownNavigator`)
        started from the true state at time zero and fed the sensor's increments: names of
        ``NAVIGATOR_PRESETS`` or ``(label, {"coning": ..., "sculling": ..., "position": ...})``.
        They show how fast each algorithm family drifts on the car (no aiding at all).
    physics_rate_hz, control_rate_hz : MuJoCo step rate and driver rate (a whole multiple).
    keep_log : keep every period's truth, sensor samples, estimates and navigation for
        :meth:`result` (the default). Users that take each period's outputs from :meth:`step`
        (the environments, the FMUs) pass False: memory then stays constant however long the
        run, ``run()`` returns None and ``result()`` is refused.
    """

    def __init__(self, route: str | Route = "figure8", *, duration_s: float | None = None, seed: int = 0,
                 estimators: Iterable[str | EstimatorSpec | tuple] = DEFAULT_ESTIMATORS,
                 sensor_profile: str = DEFAULT_SENSOR_PROFILE, registers: Mapping[str, int] | None = None,
                 mounting: Any = None, gyro_calibration_s: float = 0.0, gnss: Any = "auto",
                 gnss_rate_hz: float = 5.0, navigators: Iterable = (), physics_rate_hz: float = 1000.0,
                 control_rate_hz: float = 50.0, keep_log: bool = True):
        self.route = load_route(route)
        if duration_s is None:
            duration_s = math.ceil(self.route.nominal_duration_s + 10.0)
        if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) or not (
                math.isfinite(duration_s) and duration_s > 0.0):
            raise ValueError(f"duration_s must be a positive number of seconds, got {duration_s!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        if not (isinstance(gyro_calibration_s, (int, float)) and 0.0 <= gyro_calibration_s <= 60.0):
            raise ValueError(f"gyro_calibration_s must be in [0, 60] s, got {gyro_calibration_s!r}")
        if not isinstance(keep_log, bool):
            raise TypeError(f"keep_log must be True or False, got {keep_log!r}")
        self.keep_log = keep_log
        # {} from a caller that is done with each step's samples, truth and estimates before the
        # next step (the environments): without a log the sensor and the period kernel's
        # estimators then write every period into the same arrays (n input rows -> (sensor
        # outputs, int64 flags, estimator outputs by slot, {k: (ImuSamples, estimates by slot)
        # of the first k rows})), and the truth at the samples too once a ``_PeriodPlan`` holds.
        self._sensor_buffers: dict[int, tuple] | None = None
        self._plan: _PeriodPlan | None = None  # the period kernel's arguments, gathered once (see there)
        self._period_hook: PeriodHook | None = None  # a caller's work in the planned periods' kernel call
        self._hook_ran = False  # whether it ran in the last step
        self.duration_s = float(duration_s)
        self.seed = int(seed)
        self.gyro_calibration_s = float(gyro_calibration_s)
        self.specs = _estimator_specs(estimators)
        self.vehicle = VehicleSim(self.route, physics_rate_hz=physics_rate_hz, control_rate_hz=control_rate_hz)
        site = self.route.site
        self.earth = EarthField(lat_deg=site.lat_deg, lon_deg=site.lon_deg, alt_m=site.alt_m, date=site.date)
        self.magnetic = MagneticEnvironment(self.earth)
        self.imu = MPU9250(sensor_profile, seed=self.seed, registers=registers, mounting=mounting,
                           input_rate_hz=physics_rate_hz)
        self.sensor_profile = sensor_profile
        self.registers = dict(registers or {})
        self.estimators = {}
        for spec in self.specs:
            if spec.instance is not None:
                self.estimators[spec.key] = _UserEstimator(spec.instance, spec.key)
                continue
            params = dict(spec.params)
            params.setdefault("declination_rad", self.earth.declination_rad)
            est = make_estimator(spec.name, self.imu.output_rate_hz, **(params | self._speed_geometry(spec.name, params)))
            self.estimators[spec.key] = est
        self._wants_odometry = any("speed_mps" in getattr(e, "inputs", ()) for e in self.estimators.values())
        # the estimators the period kernel runs itself when they can (``_lane``): (key, estimator, slot)
        self._lane_estimators: tuple[tuple[str, Estimator, int], ...] = ()
        free = list(_LANE_SLOTS)
        for key, est in self.estimators.items():
            slot = next((entry for entry in free if type(est) is entry[0]), None)
            if slot is not None:
                free.remove(slot)
                self._lane_estimators += ((key, est, slot[1]),)
        self.n_chunks = int(math.ceil(self.duration_s * self.vehicle.control_rate_hz - 1e-9))
        self.gnss_receiver = self._make_receiver(gnss, gnss_rate_hz, physics_rate_hz)
        # what a state must share with this co-simulation to be restored into it
        self._identity = repr((self.route, self.seed, sensor_profile, _profile_content(sensor_profile),
                               sorted(self.registers.items()), repr(mounting), gyro_calibration_s, repr(gnss),
                               gnss_rate_hz, physics_rate_hz, control_rate_hz,
                               [(s.key, s.name, sorted((k, repr(v)) for k, v in s.params.items())) for s in self.specs],
                               sorted(navigators) if not isinstance(navigators, str) else navigators))
        self._setup_navigators(navigators)
        # the period kernel's outputs are all there is to a period (``_estimate``)
        self._lane_only = (len(self._lane_estimators) == len(self.estimators) and self.gnss_receiver is None
                           and not self.navigator_params and not self.keep_log)
        self._calibrate_gyro()
        self._reset_navigators()
        self._reset_logs()

    def _speed_geometry(self, name: str, params: Mapping[str, Any]) -> dict[str, Any]:
        """Where the wheel-odometry speed is measured, for estimators that take a speed."""
        from biso_cosim.estimators import estimator_inputs

        if "speed_mps" not in estimator_inputs(name) or "speed_point_b_m" in params:
            return {}
        ix = self.vehicle.index
        return {"speed_point_b_m": tuple(float(v) for v in ix.rear_axle_b - ix.imu_pos_b)}

    def _odometry_mps(self, truth: Truth) -> np.ndarray:
        """Wheel odometry as an ABS controller forms it, from the wheels that are not driven
        (driven wheels spin under throttle): the mean spin rate of the front wheels times the
        wheel radius, times the cosine of the steering angle, is the speed of the rear axle's
        centre in the bicycle model (negative in reverse)."""
        out = np.empty(len(truth))
        _wheel_odometry(truth.packed, self.vehicle.index.wheel_radius_m, out)
        return out

    # ------------------------------------------------------------------ running
    def reset(self) -> None:
        """Back to time zero with the same seed: a second run repeats the first bit for bit."""
        self.vehicle.reset()
        self.imu.reset(seed=self.seed)
        if self.gnss_receiver is not None:
            self.gnss_receiver.reset(seed=self.seed)
        self._calibrate_gyro()
        self._reset_navigators()
        for est in self.estimators.values():
            est.reset()
        self._reset_logs()

    def _make_receiver(self, gnss: Any, rate_hz: float, input_rate_hz: float):
        from biso_cosim.sensors import GnssReceiver, ZoneOutage

        wanted = any("gnss" in getattr(est, "inputs", ()) for est in self.estimators.values())
        if gnss is None or gnss is False or (gnss == "auto" and not wanted):
            if wanted:
                raise ValueError("gnss=None, but an estimator of this run takes GNSS fixes")
            return None
        outages = tuple(ZoneOutage((z.x0_m, z.y0_m), (z.x1_m, z.y1_m), z.half_width_m, label=z.label)
                        for z in self.route.gnss_outages)
        return GnssReceiver("consumer" if gnss == "auto" else gnss, seed=self.seed, rate_hz=rate_hz,
                            site=self.route.site, input_rate_hz=input_rate_hz, outages=outages)

    def _setup_navigators(self, navigators: Iterable) -> None:
        """Parameters of the navigators, and the increments they and the estimators with a coning-algorithm
        ``gyro_step`` need from the sensor."""
        from biso_cosim.strapdown import NavigatorParams
        from biso_cosim.strapdown.navigator import _setup

        if isinstance(navigators, str):
            navigators = (navigators,)
        self.navigator_params: dict[str, NavigatorParams] = {}
        orders, subs = 0, set()
        for item in navigators:
            if isinstance(item, str):
                if item not in NAVIGATOR_PRESETS:
                    raise ValueError(f"unknown navigator {item!r}; known: {', '.join(NAVIGATOR_PRESETS)} "
                                     "(or a (label, {coning, sculling, position}) pair)")
                label, settings = item, NAVIGATOR_PRESETS[item]
            elif isinstance(item, tuple) and len(item) == 2 and isinstance(item[1], Mapping):
                label, settings = str(item[0]), dict(item[1])
            else:
                raise ValueError(f"navigators: expected preset names or (label, settings) pairs, got {item!r}")
            if label in self.navigator_params:
                raise ValueError(f"navigators: labels must be unique, {label!r} repeats")
            params = NavigatorParams(interval_s=1.0 / self.imu.output_rate_hz, **settings)
            setup = _setup(params)
            if setup.multiple:
                orders = max(orders, setup.rows_dtheta, setup.rows_dv)
            elif setup.rows_dtheta is None:
                orders = max(orders, 1)  # one-sample algorithms take the whole interval's increment
            else:
                subs.add(setup.rows_dtheta)
            self.navigator_params[label] = params
        # estimators whose gyro step is a coning algorithm take the same increments (input dtheta_b)
        self._dtheta_forms: dict[str, tuple[str, int]] = {}
        for key, est in self.estimators.items():
            step = _gyro_step(est)
            if step is None:
                continue
            if step.form == "multiple":
                orders = max(orders, step.m_dtheta)
                self._dtheta_forms[key] = ("multiple", step.m_dtheta)
            elif step.m_dtheta == 1:
                orders = max(orders, 1)
                self._dtheta_forms[key] = ("multiple", 1)  # the whole interval's increment ΔΘ¹
            else:
                subs.add(step.m_dtheta)
                self._dtheta_forms[key] = ("sub", step.m_dtheta)
        if len(subs) > 1:
            raise ValueError(f"navigators and gyro_step: sub-interval algorithms with different numbers of "
                             f"increments ({sorted(subs)}) cannot share one sensor stream; run them separately")
        self._increment_orders = orders
        self._subintervals = subs.pop() if subs else 0

    def _reset_navigators(self) -> None:
        """Navigators start from the true state at time zero (the car at rest, settled)."""
        from biso_cosim.strapdown import StrapdownNavigator

        row = self.vehicle.current_truth()
        interval = 1.0 / self.imu.output_rate_hz
        # the state is at −T: the first update covers the sensor's first interval, ending at 0
        self.navigators = {label: StrapdownNavigator(params, q_wb=row.q_wb[0], v_w=row.vel_w[0], p_w=row.pos_w[0],
                                                     t_s=-interval)
                           for label, params in self.navigator_params.items()}

    def _calibrate_gyro(self) -> None:
        """Start-up gyro offset calibration with the car at rest (see ``gyro_calibration_s``).

        The sensor runs for the calibration time before time zero on the truth of the parked
        car; its clock then reads ``gyro_calibration_s`` at time zero, which ``step`` removes.
        """
        n = int(round(self.gyro_calibration_s * self.vehicle.physics_rate_hz))
        self.gyro_offset_b = np.zeros(3)
        self._has_gyro_offset = False
        self._imu_t0_s = n / self.vehicle.physics_rate_hz
        if n == 0:
            return
        row = self.vehicle.current_truth()
        parked = Truth(np.repeat(row.packed, n, axis=0))
        mag_b = self.magnetic.field_b(parked.q_wb, parked.pos_w)
        samples = self.imu.simulate(parked.omega_b, parked.specific_force_b, mag_b,
                                    increments=self._increment_orders, subintervals=self._subintervals)
        self.gyro_offset_b = samples.gyro_b.mean(axis=0)
        self._has_gyro_offset = bool(self.gyro_offset_b.any())

    # ------------------------------------------------------------------ whole state
    def get_state(self) -> "CoSimState":
        """Everything that determines what happens next (MuJoCo, driver, sensor, estimators,
        navigators, counters), and how long the logs were; picklable. Restore it with
        :meth:`set_state` to go back in time (FMU get/set state, environment checkpoints)."""
        if any(isinstance(e, _UserEstimator) for e in self.estimators.values()):
            raise ValueError("get_state: a user's estimator is in the loop, and its state is unknown to the "
                             "co-simulation")
        v = self.vehicle
        physics = np.empty(mujoco.mj_stateSize(v.model, PHYSICS_STATE))
        mujoco.mj_getState(v.model, v.data, physics, PHYSICS_STATE)
        return CoSimState(
            identity=self._identity, log_origin_chunk=self._log_origin_chunk, log_generation=self._log_generation,
            physics=physics, sensordata=v.data.sensordata.copy(), steps_done=v.steps_done,
            driver=copy.deepcopy(v.driver.state),
            imu=copy.deepcopy(self.imu.get_state()),
            gnss=None if self.gnss_receiver is None else copy.deepcopy(self.gnss_receiver.get_state()),
            estimators={k: copy.deepcopy(e.get_state()) for k, e in self.estimators.items()},
            navigators={k: copy.deepcopy(n.get_state()) for k, n in self.navigators.items()},
            chunks_done=self._chunks_done, finished_chunk=self._finished_chunk,
            last_truth_row=None if self._last_truth_row is None else self._last_truth_row.packed.copy(),
            log_lengths=self._log_lengths())

    def set_state(self, state: "CoSimState") -> None:
        """Restore a state from :meth:`get_state` of this co-simulation's set-up.

        The logs are cut back to the state's time. A state later than the logs (from another
        instance, or after a reset) is restored too, but the log then starts afresh at the
        state's time, and the run's summary has no start-to-end figures.
        """
        if not isinstance(state, CoSimState):
            raise TypeError(f"set_state expects a CoSimState from get_state(), got {type(state).__name__}")
        if state.identity != self._identity:
            raise ValueError("set_state: the state is from a co-simulation with another set-up (route, seed, "
                             "sensor, estimators, navigators, GNSS or rates); nothing changed")
        v = self.vehicle
        mujoco.mj_setState(v.model, v.data, state.physics, PHYSICS_STATE)
        # the driver reads the sensor data of the last step, which belongs to that step's start
        # (docs/design.md §3): restore it as it was rather than recompute it for the current state
        v.data.sensordata[:] = state.sensordata
        v._restart_history()
        v.steps_done = state.steps_done
        v.driver.state = copy.deepcopy(state.driver)
        self.imu.set_state(copy.deepcopy(state.imu))
        if self.gnss_receiver is not None:
            self.gnss_receiver.set_state(copy.deepcopy(state.gnss))
        for key, est in self.estimators.items():
            est.set_state(copy.deepcopy(state.estimators[key]))
        for key, nav in self.navigators.items():
            nav.set_state(copy.deepcopy(state.navigators[key]))
        self._chunks_done = state.chunks_done
        self._finished_chunk = state.finished_chunk
        self._last_truth_row = None if state.last_truth_row is None else Truth(state.last_truth_row.copy())
        lengths = self._log_lengths()
        same_log = (state.log_generation == self._log_generation and state.log_origin_chunk == self._log_origin_chunk
                    and all(lengths[k] >= n for k, n in state.log_lengths.items()))
        if same_log:  # back in time within this log: cut it back
            self._trim_logs(state.log_lengths)
        else:  # another history: a fresh log from the state's time
            self._trim_logs({k: 0 for k in lengths})
            self._log_origin_chunk = state.chunks_done
            self._log_generation = next(_LOG_GENERATIONS)

    def _log_lengths(self) -> dict[str, int]:
        out = {f"log.{k}": len(v) for k, v in self._log.items()}
        out.update({f"est.{k}": len(v) for k, v in self._est_log.items()})
        out.update({f"nav.{k}": len(v) for k, v in self._nav_log.items()})
        return out

    def _trim_logs(self, lengths: Mapping[str, int]) -> None:
        for name, n in lengths.items():
            group, key = name.split(".", 1)
            table = {"log": self._log, "est": self._est_log, "nav": self._nav_log}[group]
            del table[key][n:]

    def _reset_logs(self) -> None:
        self._log_origin_chunk = 0
        self._log_generation = next(_LOG_GENERATIONS)
        self._chunks_done = 0
        self._last_truth_row: Truth | None = None
        self._log: dict[str, list] = {"truth": [], "imu": [], "cross_track_m": [], "progress_m": [], "gnss": []}
        self._finished_chunk: int | None = None
        self._nav_log: dict[str, list] = {k: [] for k in self.navigator_params}
        self._est_log: dict[str, list[Estimate]] = {k: [] for k in self.estimators}

    @property
    def done(self) -> bool:
        return self._chunks_done >= self.n_chunks

    def step(self, command: DriverCommand | None = None) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """One control period: driver, physics, sensor, estimators. Returns the sensor samples
        of the period, the truth at their time stamps, and each estimator's output.

        With ``command`` the car is driven by it for this period instead of by the scripted
        driver (for agents that drive); the driver still tracks progress along the route, at
        the end of the period: ``vehicle.driver.state`` is then where the step left the car
        (scripted periods record it at their start, where the driver's command is made).
        """
        self._hook_ran = False
        if self.magnetic.disturbances:
            return self._sense(self._drive(command))
        self._command(command)
        rows, first, t_start = self.vehicle._step_period()  # rows None: still in MuJoCo's sensor history
        self._period_done(command)
        return self._sense_period(rows, first, t_start)

    def _drive(self, command: DriverCommand | None = None) -> Truth:
        """Driver (or the given command) and physics for one control period."""
        return self.vehicle._truth(*self._drive_rows(command))

    def _drive_rows(self, command: DriverCommand | None = None) -> tuple[np.ndarray, int]:
        """``_drive`` with the physics rows unpacked (``VehicleSim._step_rows``)."""
        self._command(command)
        rows = self.vehicle._step_rows()
        self._period_done(command)
        return rows

    def _command(self, command: DriverCommand | None) -> None:
        """The controls of the next period: the scripted driver's, or ``command`` (or those
        in ctrl already: ``_CONTROLS_APPLIED``)."""
        vehicle = self.vehicle
        if command is None:
            vehicle._drive()  # the scripted driver (drive() without its command record)
        elif command is not _CONTROLS_APPLIED:
            _check_command(command, vehicle.parameters["max_steer_rad"])
            vehicle.apply(command)

    def _period_done(self, command: DriverCommand | None) -> None:
        """After a period's physics: an agent's progress along the route, the log, the count."""
        vehicle = self.vehicle
        if command is not None:
            vehicle.observe_route()
        if self.keep_log:
            self._log["cross_track_m"].append(vehicle.driver.state.cross_track_m)
            self._log["progress_m"].append(vehicle.driver.state.s_m)
        self._chunks_done += 1
        if self._finished_chunk is None and vehicle.driver.finished:
            self._finished_chunk = self._chunks_done

    def _sense_period(self, rows: np.ndarray | None, first_step: int, t_start: float = 0.0
                      ) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """``_sense`` of one period's MuJoCo sensor rows, with the truth packing, the sensor's
        inputs, the sensor, the truth at its samples, the wheel odometry there and the
        estimators of ``_lane`` in one kernel call (``_period``): the same numbers as
        ``_sense(vehicle._truth(rows, first_step))``, tested; the Earth's field alone (no
        local disturbances). ``rows`` None: the rows of ``VehicleSim._step_period``, begun
        at ``t_start``, read from MuJoCo's sensor history by the kernel; for a caller that
        consumes each period's outputs within the period, the call's arguments then serve
        the periods after (``_PeriodPlan``)."""
        if rows is None and self._plan is not None:
            variant = self._plan.after(self._last_truth_row)
            if variant is not None:
                return self._sense_planned(*variant, first_step, t_start)
        vehicle, imu = self.vehicle, self.imu
        orders, subs = self._increment_orders, self._subintervals
        history = (vehicle._history, vehicle._history_layout, t_start, vehicle._warnings, vehicle._sensordata,
                   vehicle._rows)
        if rows is not None:
            history = (_NO_HISTORY, vehicle._history_layout, 0.0, vehicle._warnings, vehicle._sensordata, rows)
        n = history[-1].shape[0]
        packed = np.empty((n, Truth.WIDTH))
        if self._sensor_buffers is None or self.keep_log:
            out = imu._outputs(n, orders, subs)
            bound = out[3].shape[0]
            flags64, lane_out, views = np.empty(bound, dtype=np.int64), None, None
        else:
            if n not in self._sensor_buffers:
                out = imu._outputs(n, orders, subs)
                bound = out[3].shape[0]
                self._sensor_buffers[n] = (out, np.empty(bound, dtype=np.int64), _lane_outputs(bound), {})
            out, flags64, lane_out, views = self._sensor_buffers[n]
            bound = flags64.shape[0]
        at = np.empty((bound, Truth.WIDTH))
        odometry = np.empty(bound if self._wants_odometry else 0)
        before = _NO_ROWS if self._last_truth_row is None else self._last_truth_row.packed
        lane = self._lane()
        if lane and lane_out is None:  # (a log keeps them: new arrays every period)
            lane_out = _lane_outputs(bound, [slot for _, _, slot in lane])
        lane_args = list(_NO_LANE)
        scratch = _NO_SCRATCH
        for _, est, slot in lane:
            lane_args[4 * slot:4 * slot + 2 + len(lane_out[slot])] = est._coef, est._state, *lane_out[slot]
            if slot < 2:
                scratch = est._scratch
        args = [*history, vehicle._gather, first_step, vehicle.physics_rate_hz, self.magnetic.earth.field_enu_ut,  # (_ARG_*)
                before, *imu._kernel_state(), orders, subs, self._imu_t0_s, Truth.QUAT_COLUMN, packed, *out, at,
                vehicle.index.wheel_radius_m, odometry, flags64, _NO_VELOCITY, scratch, *lane_args]
        status, k = _sense_estimate_period(*args)
        result = self._period_outcome(status, k, first_step, packed, out, at, odometry, flags64, lane, lane_out, views)
        if status == -1 and rows is None and views is not None and lane and self._lane_only:
            self._plan = _PeriodPlan(self, args, lane, lane_out, views)
            self._last_truth_row = self._plan.first_row
        return result

    def _sense_planned(self, args: list, last_row: Truth, first_step: int, t_start: float
                       ) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """``_sense_period`` of the rows in MuJoCo's sensor history by the ``_PeriodPlan``'s
        arguments ``args`` (``_PeriodPlan.after``: they hold), which leave ``last_row``."""
        args[_ARG_T_START], args[_ARG_FIRST_STEP] = t_start, first_step
        hook = self._plan.hook
        if hook is None:
            status, k = _sense_estimate_period(*args)
        else:
            kernel, q, hook_args = hook
            status, k = kernel(tuple(args), q, *hook_args)
        if status == -1:
            self._hook_ran = hook is not None
            self._last_truth_row = last_row
            samples, at_samples, estimated = self._plan.view(k)
            return samples, at_samples, dict(estimated)
        # nothing changed, or an error to raise: as the general path goes on (estimators only run on -1)
        self._plan = None
        out = tuple(args[_ARG_OUT:_ARG_OUT + 4])
        return self._period_outcome(status, k, first_step, args[_ARG_PACKED], out, args[_ARG_AT],
                                    args[_ARG_ODOMETRY], args[_ARG_FLAGS], (), None, None)

    def _period_outcome(self, status: int, k: int, first_step: int, packed: np.ndarray, out: tuple,
                        at: np.ndarray, odometry: np.ndarray, flags64: np.ndarray, lane: tuple,
                        lane_out: list | None, views: dict | None) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """What follows the period kernel's call (``status``, ``k``) on these arrays: the
        samples and estimates, the period stepped again, or the general path's errors."""
        if status == -5:  # the history did not hold the rows (nothing changed): the period stepped again
            return self._sense_period(self.vehicle._restep(self.vehicle._rows, k), first_step)
        truth = Truth._of(packed)
        if status >= 0 or status == -3:  # inputs refused, nothing changed: the errors of the general path
            return self._sense(truth)
        orders, subs = self._increment_orders, self._subintervals
        if views is None or status != -1:
            samples = self.imu._samples(status, k, out, orders, subs)  # (raises on status -2)
            estimates = _lane_estimates(lane_out, k) if lane else None
        else:
            samples, estimates = _buffer_view(views, k, out, orders, subs, lane_out)
        if status == -4:
            self._truth_at(samples.t_s, truth)  # raises: the sensor and the physics are out of step
        self._last_truth_row = Truth._of(packed[-1:])
        if self._has_gyro_offset:
            self._remove_gyro_offset(samples)
        estimated = {key: estimates[slot] for key, _, slot in lane} if lane else None
        return self._estimate(truth, samples, Truth._of(at[:k]), odometry[:k], flags64[:k], estimated)

    def _lane(self) -> tuple[tuple[str, Estimator, int], ...]:
        """The estimators the period kernel runs itself this period (``_lane_estimators``:
        the first two BISO and the first BISO+), when each would take
        ``Estimator._update_prechecked``'s short path with the kernel's inputs. That is, they
        have run once through the checks of ``update`` (``_prechecked``), BISO integrates
        the gyro readings (``gyro_step="hold"``: no increments), and the readings need no
        offset removed first. The same arithmetic on the same arrays as their own
        ``update``: the same numbers. Empty when not every one of them can."""
        lane = self._lane_estimators
        if self._has_gyro_offset:
            return ()
        for _, est, slot in lane:
            if est._prechecked is None or (slot < 2 and est._params.gyro_step != "hold"):
                return ()
        return lane

    def _sense(self, truth: Truth) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """Sensor and estimators over the physics rows ``truth`` (one or more periods)."""
        if self.magnetic.disturbances:
            omega_b, force_b = truth.omega_b, truth.specific_force_b
            mag_b = self.magnetic.field_b(truth.q_wb, truth.pos_w)
        else:  # the Earth's field alone: the sensor's three inputs by one kernel call
            omega_b, force_b, mag_b = np.empty((3, len(truth), 3))
            if not _sensor_inputs(truth.packed, self.magnetic.earth.field_enu_ut, omega_b, force_b, mag_b):
                self.magnetic.field_b(truth.q_wb, truth.pos_w)  # raises, naming the positions
        samples = self.imu.simulate(omega_b, force_b, mag_b, increments=self._increment_orders,
                                    subintervals=self._subintervals)
        if self._imu_t0_s:
            samples.t_s -= self._imu_t0_s  # the sensor's clock started before the calibration
        self._remove_gyro_offset(samples)
        return self._estimate(truth, samples, self._truth_at(samples.t_s, truth))

    def _estimate(self, truth: Truth, samples: ImuSamples, at_samples: Truth, odometry: np.ndarray | None = None,
                  imu_flags: np.ndarray | None = None, estimated: Mapping[str, Estimate] | None = None
                  ) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """GNSS, navigators and estimators over the sensor's samples (and the log);
        ``odometry``, ``imu_flags``: the wheel odometry at the samples and their flags as
        int64, when already at hand; ``estimated``: the outputs of estimators already run
        on the samples (the period kernel's, ``_lane``)."""
        if estimated is not None and self._lane_only:  # every estimator has run, and nothing else is due
            return samples, at_samples, estimated
        fixes = None
        if self.gnss_receiver is not None:
            fixes = self.gnss_receiver.simulate(truth.pos_w, truth.vel_w)
        for label, nav in self.navigators.items():
            navigated = self._navigate(nav, samples)
            if self.keep_log:
                self._nav_log[label].append(navigated)
        outputs = {}
        for key, est in self.estimators.items():
            if estimated and key in estimated:
                outputs[key] = estimated[key]
                continue
            inputs = getattr(est, "inputs", ())
            extra = {}
            if "speed_mps" in inputs:
                if odometry is None:
                    odometry = self._odometry_mps(at_samples)
                extra["speed_mps"] = odometry
            if "gnss" in inputs:
                extra["gnss"] = fixes
            if "imu_flags" in inputs:  # the sensor's saturation and overflow bits
                if imu_flags is None:
                    imu_flags = samples.flags.astype(np.int64)
                extra["imu_flags"] = imu_flags
            if key in self._dtheta_forms:  # increments for a coning-algorithm gyro step
                form, m = self._dtheta_forms[key]
                extra["dtheta_b"] = np.ascontiguousarray(samples.dtheta[:, :m] if form == "multiple"
                                                         else samples.dtheta_sub)
            if isinstance(est, Estimator):  # the samples of our own sensor: checked once (see there)
                outputs[key] = est._update_prechecked(samples.gyro_b, samples.accel_b, samples.mag_b, extra)
            else:
                outputs[key] = est.update(samples.gyro_b, samples.accel_b, samples.mag_b, **extra)
        if self.keep_log:
            self._log["truth"].append(at_samples)
            self._log["imu"].append(samples)
            if fixes is not None:
                self._log["gnss"].append(fixes)
            for key, out in outputs.items():
                self._est_log[key].append(out)
        return samples, at_samples, outputs

    def run(self, progress: bool = False, block_periods: int | None = None,
            stop_on_interrupt: bool = False) -> "RunResult | None":
        """Run to ``duration_s`` from wherever the simulation stands; the whole log so far.

        The driver and the physics advance one control period at a time; the sensor and the
        estimators receive ``block_periods`` periods at once. Nothing in a scripted run reads
        the estimates in between, and the sensor and the library's estimators stream exactly,
        so the results are the same bit for bit as with ``step()``, in a tenth of the Python
        calls. Default: 10 periods, or 1 when a user's estimator is in the loop (it is called
        once per control period, as documented, in case it is not chunk-invariant).
        With ``keep_log=False`` it returns None.

        ``stop_on_interrupt``: Ctrl-C (SIGINT, in the main thread) ends the run at the end of
        the control period under way instead of raising KeyboardInterrupt; the result holds
        what was simulated, with ``interrupted`` set (the CLI writes it and exits 130).
        """
        if block_periods is None:
            block_periods = 1 if any(isinstance(e, _UserEstimator) for e in self.estimators.values()) else 10
        if isinstance(block_periods, bool) or not isinstance(block_periods, int) or block_periods < 1:
            raise ValueError(f"block_periods must be a positive integer, got {block_periods!r}")
        start = time.perf_counter()
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=round(self.duration_s), unit="sim s", desc=self.route.name, leave=False)
        per_second = max(int(round(self.vehicle.control_rate_hz)), 1)
        block: list[Truth] = []
        stop = _InterruptFlag(stop_on_interrupt)
        try:
            while not self.done and not stop.raised:
                block.append(self._drive())
                if len(block) == block_periods or self.done:
                    pending, block = block, []
                    self._sense(Truth.concatenate(pending))
                if bar is not None and self._chunks_done % per_second == 0:
                    bar.update(1)
        finally:
            if block:  # interrupted mid-block: the sensor and estimators catch up with the physics
                self._sense(Truth.concatenate(block))
            if bar is not None:
                bar.close()
            stop.restore()
        if not self.keep_log:
            return None
        result = self.result(wall_time_s=time.perf_counter() - start)
        result.interrupted = stop.raised
        return result

    def result(self, wall_time_s: float = float("nan")) -> "RunResult":
        if not self.keep_log:
            raise RuntimeError("result(): this co-simulation keeps no log (keep_log=False); take the outputs "
                               "of each period from step()")
        truth = Truth.concatenate(self._log["truth"]) if self._log["truth"] else None
        if truth is None or len(truth) == 0:
            raise RuntimeError("run() or step() first: nothing has been simulated yet")
        imu = ImuSamples.concatenate(self._log["imu"])
        gnss = None
        if self.gnss_receiver is not None:
            from biso_cosim.sensors import GnssFixes

            gnss = GnssFixes.concatenate(self._log["gnss"])
        estimates = {k: (np.concatenate([o.q_wb for o in outs]), np.concatenate([o.flags for o in outs]))
                     for k, outs in self._est_log.items()}
        navigation = {k: {name: np.concatenate([getattr(o, name) for o in outs]) for name in ("q_wb", "v_w", "p_w")}
                      for k, outs in self._nav_log.items()}
        return RunResult(
            log_start_s=self._log_origin_chunk / self.vehicle.control_rate_hz,
            finished_at_s=None if self._finished_chunk is None else self._finished_chunk / self.vehicle.control_rate_hz,
            progress_m=np.asarray(self._log["progress_m"]),
            route=self.route, truth=truth, imu=imu, estimates=estimates, navigation=navigation, gnss=gnss,
            specs={s.key: s for s in self.specs},
            seed=self.seed, duration_s=self._chunks_done / self.vehicle.control_rate_hz,
            wall_time_s=wall_time_s, completed=self.vehicle.driver.finished,
            cross_track_m=np.asarray(self._log["cross_track_m"]),
            sensor={"profile": self.sensor_profile, "registers": self.registers,
                    "output_rate_hz": self.imu.output_rate_hz, "mag_rate_hz": self.imu.mag_rate_hz,
                    "gyro_calibration_s": self.gyro_calibration_s,
                    "gyro_offset_deg_s": [math.degrees(v) for v in self.gyro_offset_b]},
            site={"lat_deg": self.route.site.lat_deg, "lon_deg": self.route.site.lon_deg,
                  "declination_deg": math.degrees(self.earth.declination_rad),
                  "field_enu_ut": [float(v) for v in self.earth.field_enu_ut]},
        )

    def _remove_gyro_offset(self, samples: ImuSamples) -> None:
        """Subtract the start-up gyro offset from the readings and from the increments: the
        r-fold integral of a constant c over T is c·T^r/r!, each of m sub-intervals c·T/m."""
        if not self._has_gyro_offset:
            return
        samples.gyro_b -= self.gyro_offset_b
        T = 1.0 / self.imu.output_rate_hz
        if samples.dtheta is not None:
            for r in range(samples.dtheta.shape[1]):
                samples.dtheta[:, r] -= self.gyro_offset_b * T ** (r + 1) / math.factorial(r + 1)
        if samples.dtheta_sub is not None:
            samples.dtheta_sub -= self.gyro_offset_b * T / samples.dtheta_sub.shape[1]

    @staticmethod
    def _navigate(nav, samples: ImuSamples):
        if nav.input_form == "multiple":
            return nav.update(samples.dtheta, samples.dv)
        if samples.dtheta_sub is not None and nav.params.coning != "one_sample":
            return nav.update(samples.dtheta_sub, samples.dv_sub)
        return nav.update(samples.dtheta[:, :1], samples.dv[:, :1])

    # ------------------------------------------------------------------ truth at sample times
    def _truth_at(self, t_s: np.ndarray, chunk: Truth) -> Truth:
        """Truth at the sensor's time stamps, which lie between the previous chunk's last row
        and this chunk's last row."""
        before, self._last_truth_row = self._last_truth_row, chunk[-1:]
        first = chunk if before is None else before
        if t_s.shape[0] and (t_s[0] < first.packed[0, 0] - 1e-9 or t_s[-1] > chunk.packed[-1, 0] + 1e-9):
            raise RuntimeError(f"sensor time stamps {t_s[0]:.6f}…{t_s[-1]:.6f} s lie outside the physics rows "
                               f"{first.packed[0, 0]:.6f}…{chunk.packed[-1, 0]:.6f} s: the sensor and the physics "
                               f"are out of step")
        return chunk.at(t_s, self.vehicle.physics_rate_hz, before)


class _InterruptFlag:
    """While enabled (and in the main thread), SIGINT sets ``raised`` instead of raising
    KeyboardInterrupt; ``restore`` puts the previous handler back."""

    def __init__(self, enabled: bool):
        self.raised = False
        self._installed = enabled and threading.current_thread() is threading.main_thread()
        if self._installed:
            self._previous = signal.signal(signal.SIGINT, self._handle)

    def _handle(self, signum, frame) -> None:
        self.raised = True

    def restore(self) -> None:
        if self._installed:
            signal.signal(signal.SIGINT, self._previous if self._previous is not None else signal.default_int_handler)
            self._installed = False


@dataclass
class CoSimState:
    """The whole state of a :class:`CoSimulation` (see ``get_state``); picklable."""

    identity: str  # the set-up it belongs to
    log_origin_chunk: int
    log_generation: int
    physics: np.ndarray  # mj_getState(mjSTATE_INTEGRATION)
    sensordata: np.ndarray
    steps_done: int
    driver: Any
    imu: dict
    gnss: Any
    estimators: dict
    navigators: dict
    chunks_done: int
    finished_chunk: int | None
    last_truth_row: np.ndarray | None
    log_lengths: dict


@dataclass
class RunResult:
    """Everything a run produced, at the sensor's output rate, with its metrics."""

    route: Route
    truth: Truth
    imu: ImuSamples
    estimates: dict[str, tuple[np.ndarray, np.ndarray]]
    navigation: dict[str, dict[str, np.ndarray]]
    specs: dict[str, EstimatorSpec]
    seed: int
    duration_s: float
    wall_time_s: float
    completed: bool
    cross_track_m: np.ndarray
    sensor: dict
    site: dict
    gnss: Any = None
    log_start_s: float = 0.0
    finished_at_s: float | None = None
    progress_m: np.ndarray | None = None  # the driver's progress along the route, per control period
    interrupted: bool = False  # ended by Ctrl-C (``run(stop_on_interrupt=True)``)

    @property
    def t_s(self) -> np.ndarray:
        return self.truth.t_s

    def errors(self, key: str) -> dict[str, np.ndarray]:
        """Errors (degrees) of one estimator against the truth: roll, pitch, heading, total."""
        if key not in self.estimates:
            raise ValueError(f"no estimator {key!r} in this run; have {', '.join(self.estimates)}")
        return angle_errors_deg(self.estimates[key][0], self.truth.q_wb)

    def start_end_windows(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """Time windows where the car stands still at the start and at the end of a closed
        route, or None when the route was not driven to its end."""
        if not (self.route.closed and self.completed) or self.log_start_s > 0.0:
            return None
        if self.finished_at_s is None or self.finished_at_s > self.duration_s - _WINDOW_S:
            return None  # not yet standing still at the finish for a whole window
        wait = self.route.driving.start_wait_s
        start = (max(wait - _WINDOW_S, 0.0), wait)
        end = (self.duration_s - _WINDOW_S, self.duration_s)
        return start, end

    def summary(self) -> dict:
        """The figures printed by ``biso-cosim run`` and written to ``summary.json``."""
        windows = self.start_end_windows()
        truth_angles = attitude_angles_deg(self.truth.q_wb)
        out = {
            "route": self.route.summary(),
            "seed": self.seed,
            "duration_s": self.duration_s,
            "completed_route": self.completed,
            "samples": int(self.t_s.shape[0]),
            "sensor": self.sensor,
            "site": self.site,
            "wall_time_s": self.wall_time_s,
            "sim_seconds_per_wall_second": self.duration_s / self.wall_time_s if self.wall_time_s > 0 else None,
            "cross_track_rms_m": float(np.sqrt(np.mean(self.cross_track_m ** 2))),
            "gnss": None if self.gnss is None else {
                "fixes": int(self.gnss.t_s.shape[0]), "valid": int(np.count_nonzero(self.gnss.valid))},
            "start_end_windows_s": windows,
            "truth_start_end_deg": None if windows is None else start_end_difference(self.t_s, truth_angles, *windows),
            "estimators": {},
        }
        for key, (q, flags) in self.estimates.items():
            errors = self.errors(key)
            entry = {
                "method": self.specs[key].name,
                "params": dict(self.specs[key].params),
                "errors": error_stats(errors, self.t_s),
                "flagged_samples": int(np.count_nonzero(flags)),
            }
            if windows is not None:
                est = start_end_difference(self.t_s, attitude_angles_deg(q), *windows)
                entry["start_end_deg"] = est
                entry["start_end_error_deg"] = {
                    a: float(np.degrees(wrap_angle(np.radians(est[a] - out["truth_start_end_deg"][a])))) for a in ANGLES}
            out["estimators"][key] = entry
        if self.navigation:
            out["navigators"] = {key: self.navigation_errors(key) for key in self.navigation}
        return out

    def navigation_errors(self, key: str) -> dict:
        """Dead-reckoning errors of one navigator against the truth (IMU site)."""
        nav = self.navigation[key]
        truth = self.truth
        att = np.degrees(quat_angle_between(nav["q_wb"], truth.q_wb))
        horizontal = np.linalg.norm(nav["p_w"][:, :2] - truth.pos_w[:, :2], axis=1)
        vertical = np.abs(nav["p_w"][:, 2] - truth.pos_w[:, 2])
        velocity = np.linalg.norm(nav["v_w"] - truth.vel_w, axis=1)
        return {
            "attitude_rms_deg": float(np.sqrt(np.mean(att**2))), "attitude_max_deg": float(att.max()),
            "attitude_end_deg": float(att[-1]),
            "horizontal_position_end_m": float(horizontal[-1]), "horizontal_position_max_m": float(horizontal.max()),
            "vertical_position_end_m": float(vertical[-1]),
            "velocity_rms_mps": float(np.sqrt(np.mean(velocity**2))), "velocity_end_mps": float(velocity[-1]),
        }


def run_route(route: str | Route = "figure8", *, duration_s: float | None = None, seed: int = 0,
              estimators: Iterable[str | EstimatorSpec | tuple] = DEFAULT_ESTIMATORS, progress: bool = False,
              **options: Any) -> RunResult:
    """Drive ``route`` with the scripted driver and the estimators in the loop; see CoSimulation."""
    sim = CoSimulation(route, duration_s=duration_s, seed=seed, estimators=estimators, **options)
    return sim.run(progress=progress)
