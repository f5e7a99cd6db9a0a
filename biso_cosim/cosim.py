"""The co-simulation loop: vehicle → MPU-9250 → estimators, one control period at a time.

docs/design.md §3: the physics runs at ``physics_rate_hz`` (1 kHz) in chunks of one control
period; after each chunk (in ``run()``, each block of chunks) the virtual MPU-9250, every
estimator that declares a loop kernel and every attached consumer run in one compiled call
(``biso_cosim.loop``; docs/architecture.md), never a Python call per sample. The truth is
taken at the IMU site (body axes = IMU site axes) and interpolated to the sensor's output
time stamps, so every estimate is compared with the attitude at the instant it refers to.

>>> result = run_route("figure8", seed=0)              # the scripted driver, BISO + Poisson
>>> result.summary()["estimators"]["biso"]["errors"]["roll"]["rms_deg"]
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import signal
import threading
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import mujoco
import numpy as np

from biso_cosim.loop import (CLOCK_FIRST_STEP, CLOCK_FIXES, CLOCK_HAS_BEFORE, CLOCK_SIZE, CLOCK_T_START, NO_FIXES,
                             NO_RECEIVER, SENSE_OK, SENSE_POSITION, SENSE_RECEIVER, SENSE_RESTEP, PeriodPlan,
                             PeriodSamples, PeriodWork, PhysicsRows, SampleOutputs, SensorArrays, TruthArrays,
                             loop_kernel, prepare, sensor_inputs)
from biso_cosim.estimators import Estimate, Estimator, make_estimator
from biso_cosim.frames import quat_angle_between, wrap_angle
from biso_cosim.metrics import ANGLES, angle_errors_deg, attitude_angles_deg, error_stats, start_end_difference
from biso_cosim.routes import Route, load_route
from biso_cosim.sensors import MPU9250, EarthField, ImuSamples, MagneticEnvironment
from biso_cosim.vehicle.driver import DriverCommand
from biso_cosim.vehicle._kernels import _wheel_odometry
from biso_cosim.vehicle.sim import PHYSICS_STATE, PhysicsDiverged, Truth, VehicleSim

__all__ = ["EstimatorSpec", "CoSimulation", "CoSimState", "RunResult", "run_route", "DEFAULT_ESTIMATORS", "DEFAULT_SENSOR_PROFILE",
           "NAVIGATOR_PRESETS", "PeriodWork", "CONTROLS_APPLIED"]

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
# the period call's history when the rows are given
_NO_HISTORY = np.empty(0)
# the columns of packed truth rows that ``_pack_rows`` copies when the rows given to the
# period call are packed truth already (``_sense``: a block of ``run()``): all but the time
_TRUTH_GATHER = np.arange(1, Truth.WIDTH)
CONTROLS_APPLIED = object()
"""``CoSimulation.step``'s command from a caller that has written the period's controls into
MuJoCo's ctrl itself, after checking them (an environment's action, ``Driving-v0``): the
period runs as with a DriverCommand of those controls, without making and checking one."""


class _Period:
    """A ``PeriodPlan`` and what Python reads back from it: the records, the in-loop
    estimators (key, estimator, arrays), the consumers' estimates, and the views of its
    outputs made for each number of samples k (for outputs reused from period to period)."""

    __slots__ = ("plan", "physics", "truth", "outputs", "fixes", "in_loop", "per_period", "consumed", "versions",
                 "views", "increments", "subintervals")

    def __init__(self, plan, physics, truth, outputs, fixes, in_loop, consumed, versions, increments, subintervals):
        self.plan, self.physics, self.truth, self.outputs, self.consumed = plan, physics, truth, outputs, consumed
        self.fixes = fixes  # the receiver's output rows and the call's clock (None: no receiver in the call)
        self.in_loop, self.versions, self.increments, self.subintervals = in_loop, versions, increments, subintervals
        # the in-loop estimators whose estimate is made anew each period (``Estimator.loop_views``)
        self.per_period = tuple(entry for entry in in_loop if not entry[1].loop_views)
        self.views: dict[int, tuple] = {}

    def view(self, k: int) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """The samples, the truth at them and the in-loop estimates of the first k rows."""
        view = self.views.get(k)
        if view is None:
            out = self.outputs
            samples = MPU9250.sample_views((out.floats, out.words, out.status_bytes, out.flags), k, self.increments,
                                           self.subintervals)
            estimates = {key: est.loop_estimate(arrays, k) for key, est, arrays in self.in_loop}
            view = self.views[k] = (samples, Truth(self.truth.at[:k]), estimates)
        elif self.per_period:
            for key, est, arrays in self.per_period:
                view[2][key] = est.loop_estimate(arrays, k)
        return view

    def copy(self, k: int) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """``view(k)`` in arrays of their own (for a caller that keeps them: the log)."""
        out = self.outputs
        samples = MPU9250.sample_views((out.floats.copy(), out.words.copy(), out.status_bytes.copy(),
                                        out.flags.copy()), k, self.increments, self.subintervals)
        estimates = {key: _copied(est.loop_estimate(arrays, k)) for key, est, arrays in self.in_loop}
        return samples, Truth(self.truth.at[:k].copy()), estimates

    def fix_rows(self) -> np.ndarray | None:
        """The fixes of the last call (rows of ``FIX_LAYOUT``; views), None without a receiver."""
        return None if self.fixes is None else self.fixes[0][:int(self.fixes[1][CLOCK_FIXES])]


def _copied(estimate: Estimate) -> Estimate:
    """An estimate (any ``Estimate`` record) in arrays of its own."""
    return dataclasses.replace(estimate, **{f.name: getattr(estimate, f.name).copy()
                                            for f in dataclasses.fields(estimate)
                                            if isinstance(getattr(estimate, f.name), np.ndarray)})


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
            name = getattr(item, "name", None) or (item.method if isinstance(item, Estimator) else type(item).__name__)
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
    reuse_outputs : the arrays ``step()`` returns (samples, truth, estimates) are views of
        buffers the next ``step()`` writes again: for callers that are done with each
        period's outputs before the next (the environments, the FMUs); with ``keep_log=False``.

    Attributes
    ----------
    fast_path : True (default): each period (``step()``) or block of periods (``run()``) is
        one call of ``biso_cosim.loop.loop_kernel`` running the sensor, the GNSS receiver,
        every estimator that declares a ``loop_kernel`` and every attached consumer; False:
        the general path, one Python call per stage (the same numbers bit for bit: for tests
        and debugging). Local magnetic disturbances and a start-up gyro calibration take the
        general path.
    """

    def __init__(self, route: str | Route = "figure8", *, duration_s: float | None = None, seed: int = 0,
                 estimators: Iterable[str | EstimatorSpec | tuple] = DEFAULT_ESTIMATORS,
                 sensor_profile: str = DEFAULT_SENSOR_PROFILE, registers: Mapping[str, int] | None = None,
                 mounting: Any = None, gyro_calibration_s: float = 0.0, gnss: Any = "auto",
                 gnss_rate_hz: float = 5.0, navigators: Iterable = (), physics_rate_hz: float = 1000.0,
                 control_rate_hz: float = 50.0, keep_log: bool = True, reuse_outputs: bool = False):
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
        if not isinstance(reuse_outputs, bool) or (reuse_outputs and keep_log):
            raise ValueError(f"reuse_outputs must be True or False, and False with keep_log=True, got {reuse_outputs!r}")
        self.keep_log = keep_log
        self.reuse_outputs = reuse_outputs
        self.fast_path = True
        self._consumers: tuple[PeriodWork, ...] = ()
        self._consumers_version = 0
        # the period call's clock (``loop.CLOCK_*``) and the truth row before the next period
        self._clock = np.zeros(CLOCK_SIZE)
        self._before = np.zeros((1, Truth.WIDTH))
        self._periods: dict[tuple, _Period] = {}  # reused plans (``reuse_outputs``), by rows
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
            if isinstance(spec.instance, Estimator):  # a user's estimator built on ours: it joins as ours do
                if spec.instance.fs_hz != self.imu.output_rate_hz:
                    raise ValueError(f"estimator {spec.key!r}: fs_hz is {spec.instance.fs_hz!r}, the sensor's output "
                                     f"rate {self.imu.output_rate_hz!r} Hz")
                self.estimators[spec.key] = spec.instance
                continue
            if spec.instance is not None:
                self.estimators[spec.key] = _UserEstimator(spec.instance, spec.key)
                continue
            params = dict(spec.params)
            params.setdefault("declination_rad", self.earth.declination_rad)
            est = make_estimator(spec.name, self.imu.output_rate_hz, **(self._vehicle_defaults(spec.name) | params))
            self.estimators[spec.key] = est
        self._wants_odometry = any("speed_mps" in getattr(e, "inputs", ()) for e in self.estimators.values())
        self.n_chunks = int(math.ceil(self.duration_s * self.vehicle.control_rate_hz - 1e-9))
        self.gnss_receiver = self._make_receiver(gnss, gnss_rate_hz, physics_rate_hz)
        # what a state must share with this co-simulation to be restored into it
        self._identity = repr((self.route, self.seed, sensor_profile, _profile_content(sensor_profile),
                               sorted(self.registers.items()), repr(mounting), gyro_calibration_s, repr(gnss),
                               gnss_rate_hz, physics_rate_hz, control_rate_hz,
                               [(s.key, s.name, sorted((k, repr(v)) for k, v in s.params.items())) for s in self.specs],
                               sorted(navigators) if not isinstance(navigators, str) else navigators))
        self._setup_navigators(navigators)
        self._calibrate_gyro()
        self._reset_navigators()
        self._reset_logs()

    def _vehicle_defaults(self, name: str) -> dict[str, Any]:
        """The car's values of the parameters the estimator ``name`` takes from its vehicle
        (``Estimator.vehicle_params``; ``VehicleSim.estimator_defaults``): where the wheel
        odometry's speed is measured, the rear axle's slip angle per g of the car's tyres."""
        from biso_cosim.estimators import estimator_vehicle_params

        known = self.vehicle.estimator_defaults()
        return {p: known[p] for p in estimator_vehicle_params(name) if p in known}

    def odometry_mps(self, truth: Truth) -> np.ndarray:
        """The wheel-odometry speed (m/s) at each row of ``truth``, as the estimators that
        take ``speed_mps`` receive it in the loop. Wheel odometry as an ABS controller forms
        it, from the wheels that are not driven (driven wheels spin under throttle): the mean
        spin rate of the front wheels times the wheel radius, times the cosine of the
        steering angle, is the speed of the rear axle's centre in the bicycle model
        (negative in reverse)."""
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
        # estimators that declare gyro increments (input dtheta_b: BISO's coning-algorithm gyro_step) take them
        # from the same stream
        for est in self.estimators.values():
            wanted = getattr(est, "gyro_increments", None)
            if wanted is None:
                continue
            if wanted.form == "multiple":
                orders = max(orders, wanted.m)
            else:
                subs.add(wanted.m)
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

        The logs are cut back to the state's time (a run whose physics diverged can go on
        from an earlier state). A state later than the logs (from another
        instance, or after a reset) is restored too, but the log then starts afresh at the
        state's time, and the run's summary has no start-to-end figures.
        """
        if not isinstance(state, CoSimState):
            raise TypeError(f"set_state expects a CoSimState from get_state(), got {type(state).__name__}")
        if state.identity != self._identity:
            raise ValueError("set_state: the state is from a co-simulation with another set-up (route, seed, "
                             "sensor, estimators, navigators, GNSS or rates); nothing changed")
        v = self.vehicle
        # the driver reads the sensor data of the last step, which belongs to that step's start
        # (docs/design.md §3): restored as it was rather than recomputed for the current state
        v.restore_physics(state.physics, state.sensordata, state.steps_done)
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
        self.diverged = None  # a whole state again
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
        self.diverged: PhysicsDiverged | None = None  # the physics could not go on (until reset)

    def _check_physics(self) -> None:
        """Refuse to go on from a state the physics could not continue (``diverged``)."""
        if self.diverged is not None:
            raise RuntimeError(f"this co-simulation's physics diverged ({self.diverged}); reset() it to run again")

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
        ``CONTROLS_APPLIED``: as with a command, the controls the caller wrote into MuJoCo's
        ctrl (checked by the caller).
        """
        self._check_physics()
        try:
            if not self._loop_ready():
                return self._sense(self._drive(command))
            self._command(command)
            rows, first, t_start = self.vehicle.step_period()  # rows None: still in MuJoCo's sensor history
            self._period_done(command)
            return self._sense_loop(rows, first, t_start)
        except PhysicsDiverged as exc:
            self.diverged = exc
            raise

    # ------------------------------------------------------------------ consumers
    def attach(self, work: PeriodWork) -> None:
        """Run ``work`` (``biso_cosim.loop.PeriodWork``: a jitted ``kernel(samples, q,
        arrays)``) after every period from now on, on the period's samples and the ``q_wb``
        of the estimators it names: inside the period call on the fast path, after the
        estimators on the general path (the same kernel either way)."""
        if not isinstance(work, PeriodWork):
            raise TypeError(f"attach expects a biso_cosim.loop.PeriodWork, got {type(work).__name__}")
        unknown = [key for key in work.estimates if key not in self.estimators]
        if unknown:
            raise ValueError(f"attach: no estimator {unknown[0]!r} in this co-simulation; have {', '.join(self.estimators)}")
        self._consumers += (work,)
        self._consumers_version += 1

    def detach_all(self) -> None:
        """Remove every attached ``PeriodWork``."""
        self._consumers = ()
        self._consumers_version += 1

    @property
    def consumers(self) -> tuple[PeriodWork, ...]:
        """The attached per-period work, in the order it runs."""
        return self._consumers

    def _consume(self, samples: ImuSamples, at_samples: Truth, outputs: Mapping[str, Estimate],
                 odometry: np.ndarray | None, imu_flags: np.ndarray | None, fix_rows: np.ndarray | None) -> None:
        """The attached work on the general path's period (the fast path runs it in its call)."""
        if not self._consumers:
            return
        k = len(samples.t_s)
        flags = samples.flags.astype(np.int64) if imu_flags is None else imu_flags
        if self._wants_odometry and odometry is None:
            odometry = self.odometry_mps(at_samples)
        speed = odometry if self._wants_odometry else np.empty(0)
        view = PeriodSamples(samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh.view(np.uint8),
                             flags[:k], speed[:k] if speed.shape[0] else speed, at_samples.packed,
                             NO_FIXES if fix_rows is None else np.ascontiguousarray(fix_rows),
                             np.empty((k, 0, 3)) if samples.dtheta is None else samples.dtheta,
                             np.empty((k, 0, 3)) if samples.dtheta_sub is None else samples.dtheta_sub)
        for work in self._consumers:
            work.kernel(view, tuple(outputs[key].q_wb for key in work.estimates), work.arrays)

    @property
    def loop_estimators(self) -> tuple[str, ...]:
        """The estimators the period call runs now (``fast_path``; each declares a
        ``loop_kernel`` and gives ``loop_arrays``, and the sensor forms the increments it
        declares): the others run by ``update`` after it."""
        if not self._loop_ready():
            return ()
        return tuple(key for key, est in self.estimators.items() if self._joins(est) and est.loop_arrays(0) is not None)

    def _joins(self, est: Any) -> bool:
        """Whether ``est`` may join the period call: it has loop arrays, and the gyro
        increments it declares are among those the sensor forms (a ``gyro_step`` set after
        the start is not)."""
        if not callable(getattr(est, "loop_arrays", None)):
            return False
        wanted = getattr(est, "gyro_increments", None)
        return wanted is None or (wanted.m <= self._increment_orders if wanted.form == "multiple"
                                  else wanted.m == self._subintervals)

    @property
    def _last_truth_row(self) -> Truth | None:
        """The newest truth row of the last period (the sample times of the next may reach
        back to it), held in ``_before`` for the period call."""
        return Truth(self._before.copy()) if self._clock[CLOCK_HAS_BEFORE] else None

    @_last_truth_row.setter
    def _last_truth_row(self, row: Truth | None) -> None:
        if row is None:
            self._clock[CLOCK_HAS_BEFORE] = 0.0
        else:
            self._before[:] = row.packed[-1:]
            self._clock[CLOCK_HAS_BEFORE] = 1.0

    def _drive(self, command: DriverCommand | None = None) -> Truth:
        """Driver (or the given command) and physics for one control period."""
        return self.vehicle.truth_of(*self._drive_rows(command))

    def _drive_rows(self, command: DriverCommand | None = None) -> tuple[np.ndarray, int]:
        """``_drive`` with the physics rows unpacked (``VehicleSim.step_rows``)."""
        self._command(command)
        rows = self.vehicle.step_rows()
        self._period_done(command)
        return rows

    def _command(self, command: DriverCommand | None) -> None:
        """The controls of the next period: the scripted driver's, or ``command`` (or those
        in ctrl already: ``CONTROLS_APPLIED``)."""
        vehicle = self.vehicle
        if command is None:
            vehicle.apply_driver()  # the scripted driver (drive() without its command record)
        elif command is not CONTROLS_APPLIED:
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

    def _loop_ready(self) -> bool:
        """Whether periods run as one period call (``fast_path``): not with local magnetic
        disturbances (the call takes the Earth's field alone) or a gyro offset to remove
        before the estimators."""
        return self.fast_path and not self.magnetic.disturbances and not self._has_gyro_offset

    def _versions(self) -> tuple:
        """What a reused plan depends on beyond its own arrays: the sensor's and the
        estimators' array versions, and the attached work."""
        return (self.imu.arrays_version, self._consumers_version,
                None if self.gnss_receiver is None else self.gnss_receiver.arrays_version,
                *(getattr(est, "arrays_version", 0) for est in self.estimators.values()))

    def _period(self, rows: np.ndarray | None, packed_rows: bool) -> _Period:
        """The period call for ``rows`` (None: MuJoCo's sensor history, read into the
        vehicle's rows; else copied into the plan's own rows), gathered once for each kind
        and number of rows and reused while the versions hold."""
        vehicle = self.vehicle
        source = vehicle.history_arrays
        mode = "history" if rows is None else "packed" if packed_rows else "rows"
        key = (mode, source.rows.shape[0] if rows is None else rows.shape[0])
        period = self._periods.get(key)
        if period is not None and period.versions == self._versions():
            if rows is not None:
                np.copyto(period.physics.source.rows, rows)
            return period
        history = source.history if rows is None else _NO_HISTORY
        rows = source.rows if rows is None else rows.copy()
        n = rows.shape[0]
        orders, subs = self._increment_orders, self._subintervals
        floats, words, status_bytes, flags = self.imu.output_arrays(n, orders, subs)
        bound = flags.shape[0]
        physics = PhysicsRows(source._replace(history=history, rows=rows, gather=_TRUTH_GATHER if packed_rows
                                              else source.gather), float(vehicle.physics_rate_hz))
        sensor = SensorArrays(*self.imu.loop_arrays(), orders, subs, float(self._imu_t0_s))
        truth = TruthArrays(self.magnetic.earth.field_enu_ut, self._before, np.empty((n, Truth.WIDTH)),
                            np.empty((bound, Truth.WIDTH)), float(vehicle.index.wheel_radius_m),
                            np.empty(bound if self._wants_odometry else 0))
        outputs = SampleOutputs(floats, words, status_bytes, flags, np.empty(bound, dtype=np.int64))
        in_loop = []
        for label, est in self.estimators.items():
            arrays = est.loop_arrays(bound) if self._joins(est) else None
            if arrays is not None:
                in_loop.append((label, est, arrays))
        index = {label: arrays for label, _, arrays in in_loop}
        consumers = []
        for work in self._consumers:
            if any(label not in index for label in work.estimates):  # an estimate made after the call
                consumers = None
                break
            consumers.append((work.kernel, tuple(index[label].q_wb for label in work.estimates), work.arrays))
        receiver = NO_RECEIVER
        if self.gnss_receiver is not None:
            rx = type(self.gnss_receiver)
            receiver = (rx.loop_check, rx.loop_kernel, self.gnss_receiver.loop_arrays(n))
        estimators = tuple((type(est).loop_kernel, arrays) for _, est, arrays in in_loop)
        plan = prepare(PeriodPlan(physics, sensor, truth, outputs, self._clock, receiver, estimators, consumers or ()))
        fixes = None if receiver is NO_RECEIVER else (receiver[2].fixes, self._clock)
        period = _Period(plan, physics, truth, outputs, fixes, tuple(in_loop), consumers is not None, self._versions(),
                         orders, subs)
        self._periods[key] = period
        return period

    def _sense_loop(self, rows: np.ndarray | None, first_step: int, t_start: float = 0.0, packed_rows: bool = False
                    ) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """``_sense`` of one period's (or block's) rows by one period call
        (``biso_cosim.loop.loop_kernel``): the truth packing, the sensor's inputs, the
        sensor, the truth at its samples, the wheel odometry there, the in-loop estimators
        and the attached work; then what remains in Python (the estimators without a loop
        kernel, GNSS, navigators, the log). The same numbers as the general path, tested.
        ``rows`` None: the rows of ``VehicleSim.step_period``, begun at ``t_start``, read
        from MuJoCo's sensor history in the call; ``packed_rows``: ``rows`` are packed truth."""
        period = self._period(rows, packed_rows)
        clock = self._clock
        clock[CLOCK_T_START], clock[CLOCK_FIRST_STEP] = t_start, first_step
        status, k = loop_kernel(period.plan)
        if status == SENSE_RESTEP:  # the history did not hold the rows (nothing changed): the period stepped again
            return self._sense_loop(self.vehicle.restep(self.vehicle.history_arrays.rows, k), first_step)
        truth = Truth(period.truth.packed)
        if status >= 0 or status in (SENSE_POSITION, SENSE_RECEIVER):  # inputs refused, nothing changed: the
            # general path's errors
            return self._sense_general(truth)
        if status != SENSE_OK:  # (-2: raises) or the sensor and the physics out of step (raises)
            out = period.outputs
            samples = self.imu.sample_views((out.floats, out.words, out.status_bytes, out.flags), k,
                                            self._increment_orders, self._subintervals, status=status)
            self._truth_at(samples.t_s, truth)
        samples, at_samples, estimated = period.view(k) if self.reuse_outputs else period.copy(k)
        if (period.consumed and len(estimated) == len(self.estimators) and not self.keep_log
                and not self.navigators):  # the call was the whole period
            return samples, at_samples, dict(estimated)
        return self._estimate(truth, samples, at_samples, period.truth.odometry[:k], period.outputs.imu_flags[:k],
                              estimated, consumed=period.consumed, fix_rows=period.fix_rows())

    def _sense(self, truth: Truth) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """Sensor and estimators over the physics rows ``truth`` (one or more periods)."""
        if self._loop_ready() and len(truth):
            first_step = int(round(truth.packed[0, 0] * self.vehicle.physics_rate_hz))
            return self._sense_loop(truth.packed, first_step, packed_rows=True)
        return self._sense_general(truth)

    def _sense_general(self, truth: Truth) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """``_sense`` by the general path: one Python call per stage."""
        if self.magnetic.disturbances:
            omega_b, force_b = truth.omega_b, truth.specific_force_b
            mag_b = self.magnetic.field_b(truth.q_wb, truth.pos_w)
        else:  # the Earth's field alone: the sensor's three inputs by one kernel call
            omega_b, force_b, mag_b = np.empty((3, len(truth), 3))
            if not sensor_inputs(truth.packed, self.magnetic.earth.field_enu_ut, omega_b, force_b, mag_b):
                self.magnetic.field_b(truth.q_wb, truth.pos_w)  # raises, naming the positions
        samples = self.imu.simulate(omega_b, force_b, mag_b, increments=self._increment_orders,
                                    subintervals=self._subintervals)
        if self._imu_t0_s:
            samples.t_s -= self._imu_t0_s  # the sensor's clock started before the calibration
        self._remove_gyro_offset(samples)
        return self._estimate(truth, samples, self._truth_at(samples.t_s, truth))

    def _estimate(self, truth: Truth, samples: ImuSamples, at_samples: Truth, odometry: np.ndarray | None = None,
                  imu_flags: np.ndarray | None = None, estimated: Mapping[str, Estimate] | None = None,
                  consumed: bool = False, fix_rows: np.ndarray | None = None
                  ) -> tuple[ImuSamples, Truth, dict[str, Estimate]]:
        """GNSS, navigators and estimators over the sensor's samples (and the log), then the
        attached work unless ``consumed`` (done in the period call); ``odometry``,
        ``imu_flags``: the wheel odometry at the samples and their flags as int64, when
        already at hand; ``estimated``: the outputs of estimators already run on the samples
        (in the period call); ``fix_rows``: the receiver's fixes of the period, when it ran
        in the call. The fixes' geodetic position is computed only for a consumer of the
        record (an estimator after the call; the log's, in ``result``)."""
        fixes = None
        if self.gnss_receiver is not None and fix_rows is None:
            fix_rows = self.gnss_receiver.simulate_rows(truth.pos_w, truth.vel_w)
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
                    odometry = self.odometry_mps(at_samples)
                extra["speed_mps"] = odometry
            if "gnss" in inputs:
                if fixes is None:
                    fixes = self.gnss_receiver.fixes_of(fix_rows)
                extra["gnss"] = fixes
            if "imu_flags" in inputs:  # the sensor's saturation and overflow bits
                if imu_flags is None:
                    imu_flags = samples.flags.astype(np.int64)
                extra["imu_flags"] = imu_flags
            wanted = getattr(est, "gyro_increments", None)
            if wanted is not None:  # (a coning-algorithm gyro step's)
                extra["dtheta_b"] = np.ascontiguousarray(samples.dtheta[:, :wanted.m] if wanted.form == "multiple"
                                                         else samples.dtheta_sub)
            if isinstance(est, Estimator):  # the samples of our own sensor: checked once (see there)
                outputs[key] = est.update_prechecked(samples.gyro_b, samples.accel_b, samples.mag_b, extra)
            else:
                outputs[key] = est.update(samples.gyro_b, samples.accel_b, samples.mag_b, **extra)
        if self.keep_log:
            self._log["truth"].append(at_samples)
            self._log["imu"].append(samples)
            if fix_rows is not None:
                self._log["gnss"].append(fix_rows.copy())
            for key, out in outputs.items():
                self._est_log[key].append(out)
        if not consumed:
            self._consume(samples, at_samples, outputs, odometry, imu_flags, fix_rows)
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

        When the physics cannot go on (``PhysicsDiverged``: MuJoCo found the state unstable,
        or a tyre force was not finite), the run ends after the last whole period; the result
        holds it in ``diverged`` (time, reason; ``judge_run``: status ``diverged``, failed),
        and the co-simulation refuses to step on until ``reset()``. Without a log it raises.
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
        self._check_physics()
        try:
            while not self.done and not stop.raised:
                block.append(self._drive())
                if len(block) == block_periods or self.done:
                    pending, block = block, []
                    self._sense(Truth.concatenate(pending))
                if bar is not None and self._chunks_done % per_second == 0:
                    bar.update(1)
        except PhysicsDiverged as exc:  # the run ends with the periods before (status "diverged")
            self.diverged = exc
        finally:
            if block:  # interrupted mid-block: the sensor and estimators catch up with the physics
                self._sense(Truth.concatenate(block))
            if bar is not None:
                bar.close()
            stop.restore()
        if not self.keep_log:
            if self.diverged is not None:
                raise self.diverged
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
        if self.gnss_receiver is not None:  # (the log holds fix rows: one geodetic conversion for all)
            rows = self._log["gnss"]
            gnss = self.gnss_receiver.fixes_of(np.concatenate(rows) if rows else np.empty((0, 9)))
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
            diverged=None if self.diverged is None else (self.diverged.t_s, str(self.diverged)),
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
    diverged: tuple[float, str] | None = None  # (t_s, reason): the physics could not go on (``PhysicsDiverged``)

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
