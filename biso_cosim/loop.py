"""One control period of the co-simulation as one compiled call: MuJoCo's sensor rows → truth
rows → the MPU-9250's samples and the GNSS receiver's fixes → every in-loop estimator →
every attached consumer.

``CoSimulation`` (``biso_cosim.cosim``) gathers the call's arrays once into a ``PeriodPlan``
of named records and calls ``loop_kernel(plan)`` for each period (``step()``, the
environments, BisoVehicle.fmu) or block of periods (``run()``). Nothing here knows an
estimator or a consumer by type: each joins by declaring its own kernel and arrays.

An estimator joins (``biso_cosim.estimators.Estimator``, in the estimator's own module):

* ``loop_kernel``: a jitted ``kernel(arrays, samples)`` that runs the estimator on the
  period's ``PeriodSamples`` (k rows, and the period's fixes) and writes the first k rows
  of its outputs;
* ``loop_arrays(bound)``: a named tuple of the arrays that kernel reads and writes (its
  coefficients and state, advanced in place, and outputs for up to ``bound`` samples with
  at least the fields ``q_wb`` (bound, 4) and ``flags`` (bound,) int64, and ``gyro_bias_b``
  (bound, 3) where it estimates a bias), or None when it cannot run in the loop now;
* ``arrays_version``: a counter it increases whenever it replaces one of those arrays;
* ``gyro_increments``: the gyro increments its kernel reads (``GyroIncrements``: the first m
  rows of ``PeriodSamples.dtheta_b`` or ``dtheta_sub_b``), None (the default) for none. The
  co-simulation has its MPU-9250 form them, once per period, for every estimator that
  declares them (and its navigators); a host that does not form them (the plug-in) runs no
  such estimator in its call.

A receiver (a sensor fed the period's true antenna motion: the GNSS receiver,
``biso_cosim.sensors.GnssReceiver``) joins by the same kind of declaration: ``loop_check(arrays,
pos_w, vel_w) -> bool`` (whether it takes the rows; run before the chip, so that a refusal
changes nothing), ``loop_kernel(arrays, pos_w, vel_w) -> m`` (its m outputs of the period into
``arrays.fixes``, rows of ``FIX_LAYOUT``), ``loop_arrays(n)`` and ``arrays_version``. Its fixes
reach the estimators and consumers in ``PeriodSamples.gnss``.

A consumer (an environment's per-period work) joins by ``CoSimulation.attach(PeriodWork(...))``:
a jitted ``kernel(samples, q, arrays)`` with ``q`` the ``q_wb`` outputs of the estimators it
names and ``arrays`` its own arrays; the same kernel runs on the general path's samples.
"""

from __future__ import annotations

import warnings
from typing import Any, Callable, NamedTuple

import numpy as np
from numba import literal_unroll, typeof, types
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.experimental import structref

from biso_cosim._numba import jit
from biso_cosim.sensors._kernels import _simulate
from biso_cosim.sensors.magnetic import _rotate_into_body
from biso_cosim.vehicle.sim import HistoryArrays
from biso_cosim.vehicle._kernels import HISTORY_READ, TRUTH_LAYOUT, _history_rows, _interpolate_rows, _pack_rows, _wheel_odometry

__all__ = ["PhysicsRows", "SensorArrays", "SampleOutputs", "TruthArrays", "PeriodSamples", "PeriodWork",
           "PeriodPlan", "NO_RECEIVER", "NO_FIXES", "loop_kernel", "prepare", "period_samples", "samples_of",
           "sensor_inputs", "CLOCK_T_START",
           "CLOCK_FIRST_STEP", "CLOCK_HAS_BEFORE", "CLOCK_FIXES", "SENSE_OK", "SENSE_POSITION", "SENSE_OUT_OF_STEP",
           "SENSE_RESTEP", "SENSE_RECEIVER"]


_FIRST_CLASS = "First-class function type feature is experimental"  # numba's label (see ``prepare``)

# the period's clock (``PeriodPlan.clock``, float64): where its steps begin, whether the truth
# row before the period (``TruthArrays.before``) holds one, and how many fixes the receiver
# delivered in the last call
CLOCK_T_START, CLOCK_FIRST_STEP, CLOCK_HAS_BEFORE, CLOCK_FIXES = 0, 1, 2, 3
CLOCK_SIZE = 4

# ``loop_kernel``'s status: success; otherwise the chip's own status (a row index it refused,
# or -2), a position that is not finite, time stamps outside the rows, rows not in the history,
# rows the receiver does not take
SENSE_OK, SENSE_POSITION, SENSE_OUT_OF_STEP, SENSE_RESTEP, SENSE_RECEIVER = -1, -3, -4, -5, -6


class PhysicsRows(NamedTuple):
    """Where the period's MuJoCo sensordata rows come from (``biso_cosim.vehicle.HistoryArrays``):
    MuJoCo's sensor ``history`` ring (its ``layout``, ``warnings``, the current ``sensordata``,
    read into ``rows``), or, with an empty history, ``rows`` themselves; ``gather`` the truth's
    sensordata columns; and the physics rate in Hz."""

    source: HistoryArrays
    rate_hz: float


class SensorArrays(NamedTuple):
    """The MPU-9250 the period runs (``MPU9250.loop_arrays``): its parameters and state,
    advanced in place, the default die temperature, the increments it forms (multiple
    integrals up to ``order``, ``nsub`` sub-intervals), and the shift of its clock (s)."""

    params: np.ndarray
    channel_params: np.ndarray
    chip_state: np.ndarray
    channel_state: np.ndarray
    temp_default: float
    order: int
    nsub: int
    t_shift_s: float


class SampleOutputs(NamedTuple):
    """The chip's outputs for up to ``flags.shape[0]`` samples (``MPU9250.sample_views`` reads
    them), and the samples' flags as int64 (``imu_flags``)."""

    floats: np.ndarray
    words: np.ndarray
    status_bytes: np.ndarray
    flags: np.ndarray
    imu_flags: np.ndarray


class TruthArrays(NamedTuple):
    """The truth: the Earth's field (µT, ENU), the row before the period (1, width; valid
    when the clock says so), the period's packed rows, the rows at the samples' time stamps,
    and the wheel odometry there (empty: not wanted) from the wheel radius (m)."""

    field_enu_ut: np.ndarray
    before: np.ndarray
    packed: np.ndarray
    at: np.ndarray
    wheel_radius_m: float
    odometry: np.ndarray


class PeriodSamples(NamedTuple):
    """A period's k samples as its in-loop estimators and consumers receive them: gyro
    (rad/s), accelerometer (m/s²), magnetometer (µT), (k, 3) body axes; ``mag_fresh`` (k,)
    uint8; ``imu_flags`` (k,) int64; ``speed_mps`` (k,) wheel odometry (empty when no
    estimator takes it); ``truth`` (k, width) packed truth at the samples (``TRUTH_LAYOUT``;
    (0, 0) from the plug-in, which has none); ``gnss`` the (m, 9) fixes the receiver
    delivered during the period (``biso_cosim.sensors.gnss.FIX_LAYOUT``: time of validity,
    arrival, ENU position and velocity, valid), (0, 9) without a receiver; and the gyro
    increments over each sample interval the sensor formed for the estimators that declare
    ``gyro_increments`` (rad, body axes; ``ImuSamples.dtheta`` / ``dtheta_sub``):
    ``dtheta_b`` (k, r, 3) the multiple integrals ΔΘ¹..ΔΘ^r, ``dtheta_sub_b`` (k, m, 3) the
    m sub-interval increments, r = 0 and m = 0 (empty) when nothing takes them."""

    gyro_b: np.ndarray
    accel_b: np.ndarray
    mag_b: np.ndarray
    mag_fresh: np.ndarray
    imu_flags: np.ndarray
    speed_mps: np.ndarray
    truth: np.ndarray
    gnss: np.ndarray
    dtheta_b: np.ndarray
    dtheta_sub_b: np.ndarray


class NoReceiver(NamedTuple):
    """The receiver entry's arrays of a period without a receiver: no fixes."""

    fixes: np.ndarray


class PeriodWork(NamedTuple):
    """A consumer's own work after each period (``CoSimulation.attach``): the jitted
    ``kernel(samples, q, arrays)`` on the period's ``PeriodSamples`` (k may be 0), ``q`` the
    tuple of the ``q_wb`` outputs of the estimators ``estimates`` names (their first k rows),
    ``arrays`` the consumer's own (a tuple or named tuple, kept as long as it is attached)."""

    kernel: Callable
    arrays: Any
    estimates: tuple[str, ...] = ()


@structref.register
class _PeriodPlanType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class PeriodPlan(structref.StructRefProxy):
    """The whole of a period's call: ``physics`` (PhysicsRows), ``sensor`` (SensorArrays),
    ``truth`` (TruthArrays), ``outputs`` (SampleOutputs), ``clock`` (float64, ``CLOCK_*``),
    ``receiver`` ((check, kernel, arrays) of the receiver, or ``NO_RECEIVER``), ``estimators``
    (tuple of (kernel, arrays)), ``consumers`` (tuple of (kernel, q, arrays)). A record numba
    receives at the cost of one argument, whatever it holds."""

    def __new__(cls, physics, sensor, truth, outputs, clock, receiver, estimators, consumers):
        with warnings.catch_warnings():  # (see ``prepare``)
            warnings.filterwarnings("ignore", message=_FIRST_CLASS, category=NumbaExperimentalFeatureWarning)
            return structref.StructRefProxy.__new__(cls, physics, sensor, truth, outputs, clock, receiver,
                                                    tuple(estimators) + ((_no_estimator, ()),),
                                                    tuple(consumers) + ((_no_consumer, (), ()),))


structref.define_proxy(PeriodPlan, _PeriodPlanType,
                       ["physics", "sensor", "truth", "outputs", "clock", "receiver", "estimators", "consumers"])


@jit
def _no_estimator(arrays, samples):
    """The entry that ends every plan's estimators (a tuple numba can unroll, never empty)."""


@jit
def _no_consumer(samples, q, arrays):
    """The entry that ends every plan's consumers."""


@jit
def _no_receiver_check(arrays, pos_w, vel_w):
    """A period without a receiver takes any rows."""
    return True


@jit
def _no_receiver(arrays, pos_w, vel_w):
    """A period without a receiver delivers no fixes."""
    return 0


NO_FIXES = np.empty((0, 9))
"""``PeriodSamples.gnss`` without a receiver."""

NO_RECEIVER = (_no_receiver_check, _no_receiver, NoReceiver(NO_FIXES))
"""``PeriodPlan.receiver`` of a period without a receiver."""


@jit
def sensor_inputs(packed, field_enu_ut, omega_b, force_b, mag_b):
    """From packed truth rows (``TRUTH_LAYOUT``): the body rate and the specific force as
    contiguous (n, 3) rows, and the Earth's field ``field_enu_ut`` (µT, ENU, the same
    everywhere) rotated into each row's attitude (``MagneticEnvironment.field_b``'s kernel).
    Returns whether every position is finite (``field_b`` refuses positions that are not)."""
    w, f, q, p = TRUTH_LAYOUT.omega_b, TRUTH_LAYOUT.specific_force_b, TRUTH_LAYOUT.q_wb, TRUTH_LAYOUT.pos_w
    for k in range(packed.shape[0]):
        for a in range(3):
            omega_b[k, a] = packed[k, w + a]
            force_b[k, a] = packed[k, f + a]
    return _rotate_into_body(packed[:, q:q + 4], packed[:, p:p + 3], field_enu_ut, mag_b)


@jit
def _sense(physics, sensor, truth, outputs, clock, receiver):
    """A period's sensing: the rows (read from the history when it is not empty), the truth
    packed from them, the chip's inputs and the chip, its time stamps shifted, the truth
    (and the odometry) at them, the flags as int64, the receiver's fixes. Returns (status,
    k): ``SENSE_OK`` and the number of samples; the chip's status when it refused the rows
    (a row index, or -2), ``SENSE_POSITION`` or ``SENSE_RECEIVER`` (nothing changed but the
    packed truth), ``SENSE_OUT_OF_STEP``, or ``SENSE_RESTEP`` and ``_history_rows``' outcome
    (nothing changed)."""
    source = physics.source
    rows = source.rows
    if source.history.shape[0]:
        outcome = _history_rows(source.history, source.layout, rows.shape[0], clock[CLOCK_T_START], source.warnings,
                                source.sensordata, rows)
        if outcome != HISTORY_READ:
            return SENSE_RESTEP, outcome
    packed = truth.packed
    _pack_rows(rows, source.gather, int(clock[CLOCK_FIRST_STEP]), physics.rate_hz, packed)
    n = packed.shape[0]
    inputs = np.empty((3, n, 3))
    if not sensor_inputs(packed, truth.field_enu_ut, inputs[0], inputs[1], inputs[2]):
        return SENSE_POSITION, 0
    p, v = TRUTH_LAYOUT.pos_w, TRUTH_LAYOUT.vel_w
    if not receiver[0](receiver[2], packed[:, p:p + 3], packed[:, v:v + 3]):
        return SENSE_RECEIVER, 0
    status, k = _simulate(sensor.params, sensor.channel_params, sensor.chip_state, sensor.channel_state, inputs[0],
                          inputs[1], inputs[2], np.empty(0), sensor.temp_default, sensor.order, sensor.nsub,
                          outputs.floats, outputs.words, outputs.status_bytes, outputs.flags)
    if status != -1:
        return status, k
    t_s = outputs.floats[:k]
    if sensor.t_shift_s != 0.0:
        for i in range(k):
            t_s[i] -= sensor.t_shift_s
    before = truth.before[:1 if clock[CLOCK_HAS_BEFORE] != 0.0 else 0]
    t0_s = before[0, 0] if before.shape[0] else packed[0, 0]
    if k and (t_s[0] < t0_s - 1e-9 or t_s[k - 1] > packed[n - 1, 0] + 1e-9):
        return SENSE_OUT_OF_STEP, k
    if k:
        _interpolate_rows(before, packed, t0_s, physics.rate_hz, t_s, TRUTH_LAYOUT.q_wb, truth.at[:k])
        if truth.odometry.shape[0]:
            _wheel_odometry(truth.at[:k], truth.wheel_radius_m, truth.odometry[:k])
    for i in range(k):
        outputs.imu_flags[i] = outputs.flags[i]
    for c in range(packed.shape[1]):  # the row before the next period
        truth.before[0, c] = packed[n - 1, c]
    clock[CLOCK_HAS_BEFORE] = 1.0
    clock[CLOCK_FIXES] = receiver[1](receiver[2], packed[:, p:p + 3], packed[:, v:v + 3])
    return SENSE_OK, k


@jit
def samples_of(outputs, sensor, k, speed_mps, truth, fixes):
    """The first k samples in the chip's ``outputs`` (``SampleOutputs``, written by the
    kernel of ``sensor``, ``SensorArrays``) as ``PeriodSamples`` of views of them, with the
    host's ``speed_mps``, ``truth`` and ``fixes`` (the layout ``MPU9250.sample_views`` reads)."""
    floats, bound = outputs.floats, outputs.flags.shape[0]
    r, m = sensor.order, sensor.nsub
    o = 11 * bound  # the increments: ΔΘ^1..r, ΔV^1..r, then the sub-interval ΔΘ, ΔV
    s = o + 6 * bound * r
    return PeriodSamples(floats[bound:bound + 3 * k].reshape((k, 3)),
                         floats[4 * bound:4 * bound + 3 * k].reshape((k, 3)),
                         floats[7 * bound:7 * bound + 3 * k].reshape((k, 3)), outputs.status_bytes[:k, 0],
                         outputs.imu_flags[:k], speed_mps, truth, fixes,
                         floats[o:o + 3 * k * r].reshape((k, r, 3)), floats[s:s + 3 * k * m].reshape((k, m, 3)))


@jit
def _samples_of(outputs, sensor, truth, k, fixes):
    """The first k samples of a period and its fixes (the plan's records, not the plan: a
    cached kernel's type must not name the estimators' kernels)."""
    speed = truth.odometry[:k] if truth.odometry.shape[0] else truth.odometry
    return samples_of(outputs, sensor, k, speed, truth.at[:k], fixes)


@jit(cache=False)  # (a plan's type names its kernels: compiled once per process for each set)
def loop_kernel(plan):
    """A period (or block of periods) of ``plan``: ``_sense``, then on success every
    estimator's kernel and every consumer's (also on a period of no samples). Returns (status, k)."""
    status, k = _sense(plan.physics, plan.sensor, plan.truth, plan.outputs, plan.clock, plan.receiver)
    if status != SENSE_OK:
        return status, k
    samples = _samples_of(plan.outputs, plan.sensor, plan.truth, k,
                          plan.receiver[2].fixes[:int(plan.clock[CLOCK_FIXES])])
    for entry in literal_unroll(plan.estimators):
        entry[0](entry[1], samples)
    for entry in literal_unroll(plan.consumers):
        entry[0](samples, entry[1], entry[2])
    return status, k


@jit(cache=False)  # (as ``loop_kernel``: the plan's type names its kernels)
def period_samples(plan, k):
    """The first k samples of ``plan``'s last successful call and its fixes (``PeriodSamples``)."""
    return _samples_of(plan.outputs, plan.sensor, plan.truth, k, plan.receiver[2].fixes[:int(plan.clock[CLOCK_FIXES])])


_COMPILED: set = set()


def prepare(plan: PeriodPlan) -> PeriodPlan:
    """``plan`` with ``loop_kernel`` compiled for its type (once per set of kernels and
    array types in a process). numba calls the estimators' and consumers' kernels held in
    the record through its first-class function type, which it labels experimental: the
    label is silenced here, where it is known why it appears."""
    plan_type = typeof(plan)
    if plan_type not in _COMPILED:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=_FIRST_CLASS, category=NumbaExperimentalFeatureWarning)
            loop_kernel.compile((plan_type,))
        _COMPILED.add(plan_type)
    return plan
