"""A call of the plug-in (one tick, or a block of ticks) as one compiled call: the host's
truth checked and mapped to the chip (``_kernels.prepare``), the Earth's field in the
body, the MPU-9250, the truth at its samples, the clock, and every in-loop estimator.

``ImuPlugin`` gathers its arrays once into a ``TickPlan`` of named records and calls
``tick_kernel(plan, given)``, compiled for the plan (``compiled_call``), with each call's
truth (``HostRows``). Nothing here knows an
estimator by type: each joins by its own ``loop_kernel`` and ``loop_arrays``
(``biso_cosim.estimators.Estimator``, ``biso_cosim.loop``), as in the co-simulation's
period call, and receives the call's samples as ``biso_cosim.loop.PeriodSamples`` (no fixes,
no packed truth rows, no gyro increments: an estimator that declares ``gyro_increments``
runs after the call, by ``update``).
"""

from __future__ import annotations

import warnings
from typing import Callable, NamedTuple

import numpy as np
from numba import literal_unroll, typeof, types
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.experimental import structref

from biso_cosim._numba import jit
from biso_cosim.loop import NO_FIXES, samples_of
from biso_cosim.plugin._kernels import CLOCK_T0, ChipRows, HostRows, _count, finish_ticks, prepare
from biso_cosim.sensors._kernels import _simulate
from biso_cosim.sensors.magnetic import _rotate_into_body

__all__ = ["TickPlan", "TickScratch", "TruthAtSamples", "tick_kernel", "compiled_call", "TICK_OK", "TICK_SENSOR"]

_FIRST_CLASS = "First-class function type feature is experimental"  # numba's label (see ``compile_plan``)

# ``tick_kernel``'s status (the first of the pair it returns): success (then the number of
# samples), or the chip's own status (``MPU9250.sample_views`` reads it; nothing changed), or a
# code of ``_kernels.BAD_INPUTS`` (then the row; nothing changed)
TICK_OK, TICK_SENSOR = 0, -1


class TruthAtSamples(NamedTuple):
    """The truth at the call's samples (up to the plan's bound): the host's time of each
    (t₀ plus the chip's time stamp, s), attitude (bound, 4), package frames, and the
    reference point's forward speed (bound,); ``give_speed``: whether the estimators
    receive the speed as ``speed_mps`` (``speed_from_velocity``); ``packed`` (0, 0): the
    ``PeriodSamples.truth`` of the plug-in, which has no packed truth rows of the package's
    car (``TRUTH_LAYOUT``; no estimator reads them, they are for the co-simulation's
    consumers)."""

    t_s: np.ndarray
    q_wb: np.ndarray
    speed_mps: np.ndarray
    give_speed: bool
    packed: np.ndarray


class TickScratch(NamedTuple):
    """The call's working rows, for up to ``rows`` ticks: ``prepare``'s output (``ChipRows``),
    the field in the body (rows, 3), and the truth rows around the samples (rows + 1, 4 and 3)."""

    chip: ChipRows
    mag_b: np.ndarray
    q_rows: np.ndarray
    v_rows: np.ndarray

    @classmethod
    def for_rows(cls, rows: int) -> "TickScratch":
        return cls(ChipRows(np.empty((rows, 4)), np.empty((rows, 3)), np.empty((rows, 3)), np.empty((rows, 3)),
                            np.empty((rows, 3))), np.empty((rows, 3)), np.empty((rows + 1, 4)), np.empty((rows + 1, 3)))


@structref.register
class _TickPlanType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class TickPlan(structref.StructRefProxy):
    """The whole of a plug-in call but its truth: ``host`` (``_kernels.HostMap``), ``clock``
    (``CLOCK_SIZE``,) and ``last`` (``LAST_SIZE``,) (the plug-in's own, advanced in place),
    ``field_enu_ut`` (3,) the Earth's field, ``sensor`` (``SensorArrays``), ``outputs``
    (``SampleOutputs``), ``truth`` (``TruthAtSamples``), ``scratch`` (``TickScratch``),
    ``estimators`` (tuple of (loop_kernel, loop_arrays)). A record numba receives at the
    cost of one argument."""

    def __new__(cls, host, clock, last, field_enu_ut, sensor, outputs, truth, scratch, estimators):
        with warnings.catch_warnings():  # (see ``compile_plan``)
            warnings.filterwarnings("ignore", message=_FIRST_CLASS, category=NumbaExperimentalFeatureWarning)
            return structref.StructRefProxy.__new__(cls, host, clock, last, field_enu_ut, sensor, outputs, truth,
                                                    scratch, tuple(estimators) + ((_no_estimator, ()),))


structref.define_proxy(TickPlan, _TickPlanType,
                       ["host", "clock", "last", "field_enu_ut", "sensor", "outputs", "truth", "scratch", "estimators"])


@jit
def _no_estimator(arrays, samples):
    """The entry that ends every plan's estimators (a tuple numba can unroll, never empty)."""


@jit
def _samples_of(sensor, outputs, truth, k):
    """The first k samples of a call as ``PeriodSamples`` (views of the outputs; no fixes)."""
    speed = truth.speed_mps[:k] if truth.give_speed else truth.speed_mps[:0]
    return samples_of(outputs, sensor, k, speed, truth.packed, NO_FIXES)


@jit(cache=False)  # (a plan's type names its estimators' kernels: compiled once per process for each set)
def tick_kernel(plan, given):
    """One call of the plug-in on the host's truth ``given`` (``HostRows``): returns
    (``TICK_OK``, k samples), (code of ``BAD_INPUTS``, row) or (``TICK_SENSOR``, the chip's
    status); only a success changes anything (the chip, the clock, the estimators)."""
    n = _count(given.t_s)
    scratch = plan.scratch
    chip = scratch.chip
    code, row = prepare(plan.host, plan.clock, plan.last, given, chip)
    if code:
        return code, row
    q_wb, omega_b, force_b, mag_b = chip.q_wb[:n], chip.omega_b[:n], chip.specific_force_b[:n], scratch.mag_b[:n]
    _rotate_into_body(q_wb, chip.p_w[:n], plan.field_enu_ut, mag_b)  # (positions checked by ``prepare``)
    sensor, outputs = plan.sensor, plan.outputs
    status, k = _simulate(sensor.params, sensor.channel_params, sensor.chip_state, sensor.channel_state, omega_b,
                          force_b, mag_b, given.temperature_c, given.temperature_default_c, sensor.order, sensor.nsub,
                          outputs.floats, outputs.words, outputs.status_bytes, outputs.flags)
    if status != -1:
        return TICK_SENSOR, status
    truth = plan.truth
    finish_ticks(plan.host, plan.clock, plan.last, given, chip, n, outputs.floats[:k], truth.q_wb[:k],
                 truth.speed_mps[:k], scratch.q_rows, scratch.v_rows)
    if k == 0:
        return TICK_OK, 0
    t0_s = plan.clock[CLOCK_T0]
    for i in range(k):
        truth.t_s[i] = t0_s + outputs.floats[i]
        outputs.imu_flags[i] = outputs.flags[i]
    samples = _samples_of(sensor, outputs, truth, k)
    for entry in literal_unroll(plan.estimators):
        entry[0](entry[1], samples)
    return TICK_OK, k


def compiled_call(plan_type: types.Type, given: HostRows) -> Callable:
    """``tick_kernel`` compiled for a plan of type ``plan_type`` (``numba.typeof``) and truth
    of ``given``'s type (one tick or a block), as the compiled function
    (``Dispatcher.compile``; compiled once per set of estimators and kind of truth in a
    process). The caller gives it a plan of that type and truth of exactly that type
    (``ImuPlugin.step`` makes every array float64 of its type's dimensions, C-contiguous
    where the type says so): a call then skips the dispatcher's resolution of the argument
    types, which costs more than the tick itself. numba calls the estimators' kernels held
    in the record through its first-class function type, which it labels experimental: the
    label is silenced here, where it is known why it appears."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_FIRST_CLASS, category=NumbaExperimentalFeatureWarning)
        return tick_kernel.compile((plan_type, typeof(given)))
