"""What every estimator shares: parameter records, the output and state records, input checks
and the streaming wrapper around a jitted batch kernel.

An estimator is three records (STYLE.md, after VQF): frozen ``Params`` (what the user sets),
derived coefficients (a flat float64 array the kernel reads, computed once in
``_coefficients``), and the state (a flat float64 array the kernel updates in place). The
kernel processes a block of samples with the same per-sample update the Gymnasium
environments and the FMUs call, so batch and streaming agree bit for bit by construction.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Mapping, NamedTuple

import numpy as np

__all__ = ["Estimate", "State", "Estimator", "GyroIncrements", "param", "param_table", "param_markdown", "as_samples",
           "as_series", "as_imu_flags", "layout_offsets", "gyro_range_param", "accel_range_param",
           "saturation_limits", "INPUTS"]


# --------------------------------------------------------------------------------------
# Parameter documentation: one source for docstrings, docs tables, CLI help, FMU variables
# --------------------------------------------------------------------------------------


def param(default: Any, *, symbol: str, unit: str, doc: str, source: str = "") -> Any:
    """A dataclass field that carries its own documentation (symbol, unit, text, source)."""
    meta = {"symbol": symbol, "unit": unit, "doc": doc, "source": source}
    if isinstance(default, (list, dict, set)):
        raise TypeError("mutable defaults are not allowed in parameter records")
    return dataclasses.field(default=default, metadata=meta)


def param_table(params_cls: type) -> list[dict[str, Any]]:
    """Rows ``{name, symbol, unit, default, doc, source}`` of a parameter record."""
    rows = []
    for f in dataclasses.fields(params_cls):
        rows.append({"name": f.name, "default": f.default, **f.metadata})
    return rows


def param_markdown(params_cls: type) -> str:
    """The parameter table of a record as Markdown (for docs/estimators.md)."""
    lines = ["| parameter | symbol | unit | default | meaning | source |", "|---|---|---|---|---|---|"]
    def cell(text: Any) -> str:
        return str(text).replace("|", "\\|")

    for r in param_table(params_cls):
        lines.append(f"| `{r['name']}` | {cell(r['symbol'])} | {cell(r['unit'])} | `{r['default']!r}` | "
                     f"{cell(r['doc'])} | {cell(r['source'])} |")
    return "\n".join(lines)


def check_finite(name: str, value: Any, *, low: float | None = None, high: float | None = None,
                 low_open: bool = False) -> float:
    """``value`` as a float, finite and within [low, high] (or (low, high] with low_open)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if low is not None and (x < low or (low_open and x == low)):
        bound = f"> {low}" if low_open else f">= {low}"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    if high is not None and x > high:
        raise ValueError(f"{name} must be <= {high}, got {value!r}")
    return x


def layout_offsets(parts: tuple[tuple[str, int], ...]) -> dict[str, int]:
    """Offsets of named parts laid end to end in a flat array, plus ``"_size"``: one source
    for a kernel's index constants and the names of ``State`` parts."""
    out, i = {}, 0
    for name, size in parts:
        out[name] = i
        i += size
    out["_size"] = i
    return out


def gyro_range_param() -> Any:
    """The ``gyro_range_rad_s`` field every estimator's parameters carry (one documentation)."""
    return param(None, symbol="FS_g", unit="rad/s",
                 doc="gyro full scale: an axis at ≥ 99.9 % of it is flagged SATURATED (the sample is "
                     "still used); None = no check (the input imu_flags can flag saturation instead)",
                 source="PS-MPU-9250A-01 §3.1 (±250…±2000 °/s)")


def accel_range_param() -> Any:
    """The ``accel_range_mps2`` field every estimator's parameters carry (one documentation)."""
    return param(None, symbol="FS_a", unit="m/s²",
                 doc="accelerometer full scale: an axis at ≥ 99.9 % of it is flagged SATURATED and the "
                     "sample is not used for correction; None = no check",
                 source="PS-MPU-9250A-01 §3.2 (±2…±16 g)")


def saturation_limits(params: Any) -> tuple[float, float]:
    """(gyro, accel) limits the kernels compare each axis with: 99.9 % of the declared full
    scales, inf where none is declared (raises ValueError naming a bad value)."""
    from biso_cosim.estimators._kernels import SATURATION_FRACTION

    out = []
    for name in ("gyro_range_rad_s", "accel_range_mps2"):
        value = getattr(params, name)
        out.append(math.inf if value is None else
                   SATURATION_FRACTION * check_finite(name, value, low=0.0, low_open=True))
    return out[0], out[1]


# --------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Estimate:
    """Output of one ``update`` call (k = number of samples given).

    Attributes
    ----------
    q_wb : (k, 4) unit quaternions (w, x, y, z), body → ENU, one per input sample.
    flags : (k,) int64 bitmask per sample, bits in ``biso_cosim.estimators.flags``.
    gyro_bias_b : (k, 3) estimated gyro bias in rad/s (body axes) for estimators that
        estimate it, else None.
    """

    q_wb: np.ndarray
    flags: np.ndarray
    gyro_bias_b: np.ndarray | None = None


@dataclass(frozen=True, slots=True, eq=False)
class State:
    """The whole state of an estimator: copyable, picklable, restorable with ``set_state``.

    ``values`` is a flat float64 array (what an FMU serialises); ``layout`` names its parts.
    """

    method: str
    values: np.ndarray
    layout: tuple[tuple[str, int], ...]

    def __getitem__(self, name: str) -> np.ndarray:
        start = 0
        for field, size in self.layout:
            if field == name:
                return self.values[start:start + size].copy()
            start += size
        raise KeyError(f"state of {self.method!r} has no part {name!r}; parts: {[f for f, _ in self.layout]}")

    @property
    def q_wb(self) -> np.ndarray:
        """The attitude held in the state, normalised (identity before initialisation)."""
        lam = self["lam"]
        return lam / np.linalg.norm(lam)

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, State) and other.method == self.method
                and np.array_equal(other.values, self.values))

    __hash__ = None


# --------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------


def _as_rows(name: str, value: Any, width: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of real numbers, got {type(value).__name__}") from None
    if a.ndim != 2 or a.shape[1] != width:
        raise ValueError(f"{name} must have shape (k, {width}), got {a.shape}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


def as_samples(*named: tuple[str, Any], width: int = 3) -> list[np.ndarray]:
    """Check that each ``(name, array)`` is (k, width) with one common k; float64, C order.

    NaN and inf are not refused here: each estimator has a per-sample policy for them.
    """
    arrays = [_as_rows(name, value, width) for name, value in named]
    k = arrays[0].shape[0]
    for (name, _), a in zip(named[1:], arrays[1:]):
        if a.shape[0] != k:
            raise ValueError(f"{name} has {a.shape[0]} rows but {named[0][0]} has {k}")
    return arrays


def as_series(name: str, value: Any, k: int) -> np.ndarray:
    """A per-sample scalar input of shape (k,) (float64, C order)."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of real numbers, got {type(value).__name__}") from None
    if a.shape != (k,):
        raise ValueError(f"{name} must have shape ({k},) like the samples, got {a.shape}")
    return np.ascontiguousarray(a)


def as_imu_flags(name: str, value: Any, k: int) -> np.ndarray:
    """Per-sample sensor flag bits of shape (k,), as int64: integers, booleans, or floats that
    are whole numbers (as read from a CSV), all in [0, 2³¹)."""
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of integers, got {type(value).__name__}") from None
    if a.shape != (k,):
        raise ValueError(f"{name} must have shape ({k},) like the samples, got {a.shape}")
    if a.dtype.kind == "f":
        if not np.all(np.isfinite(a)) or not np.all(a == np.round(a)):
            raise ValueError(f"{name} must hold whole numbers (flag bits), got non-integral values")
        if a.size and (a.min() < 0 or a.max() >= 2 ** 31):  # before the cast, which could wrap
            raise ValueError(f"{name} must hold flag bits in [0, 2**31), got values from {a.min()} to {a.max()}")
    elif a.dtype.kind not in "biu":
        raise TypeError(f"{name} must be an array of integers (flag bits), got dtype {a.dtype}")
    elif a.dtype.kind == "u" and a.dtype.itemsize == 8 and a.size and a.max() >= 2 ** 31:
        raise ValueError(f"{name} must hold flag bits in [0, 2**31), got values up to {a.max()}")
    flags = np.ascontiguousarray(a, dtype=np.int64)
    # one reduction (this runs every control period): a value is outside [0, 2**31) exactly
    # when a bit from 31 up is set, the sign bit included
    if flags.size and np.bitwise_or.reduce(flags) >> 31:
        raise ValueError(f"{name} must hold flag bits in [0, 2**31), got values from {a.min()} to {a.max()}")
    return flags


def _as_rows_input(name: str, value: Any, k: int) -> np.ndarray:
    a = _as_rows(name, value, 3)
    if a.shape[0] != k:
        raise ValueError(f"{name} must have shape ({k}, 3) like the samples, got {a.shape}")
    return a


def _as_increments_input(name: str, value: Any, k: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real array of shape ({k}, m, 3), got {type(value).__name__}") from None
    if a.ndim != 3 or a.shape[0] != k or a.shape[2] != 3 or a.shape[1] < 1:
        raise ValueError(f"{name} must have shape ({k}, m, 3) like the samples (m increments per sample), "
                         f"got {a.shape}")
    return np.ascontiguousarray(a)


_NO_BIAS = np.empty((0, 3))  # the bias output of estimators that do not estimate it (never written)

INPUTS: dict[str, tuple[Any, Any]] = {
    "imu_flags": (as_imu_flags, lambda: np.empty(0, dtype=np.int64)),
    "dtheta_b": (_as_increments_input, lambda: np.empty((0, 1, 3))),
    "speed_mps": (as_series, lambda: np.empty(0)),
    "velocity_enu_mps": (_as_rows_input, lambda: np.empty((0, 3))),
}
"""The optional per-sample inputs an estimator may list in ``inputs``: name → (checking
function(name, value, k) → array, the empty array the kernel gets when it is not given).

* ``imu_flags`` (k,) int: the sensor's flag bits per sample (``biso_cosim.sensors.ImuFlag``:
  gyro / accelerometer saturated, AK8963 overflow, magnetometer data invalid), e.g.
  ``ImuSamples.flags`` or the ``imu_flags`` column of a run's log;
* ``speed_mps`` (k,) float: forward speed of the vehicle (wheel odometry or GNSS), NaN = unknown;
* ``velocity_enu_mps`` (k, 3) float: velocity over the ground in ENU (for the transport rate);
* ``dtheta_b`` (k, m, 3) float: the gyro's increments over each sample interval, body axes, in
  the form of a coning algorithm of ``biso_cosim.strapdown`` (sub-interval increments or
  multiple integrals; ``ImuSamples.dtheta_sub`` / ``dtheta``), for ``gyro_step``.
"""


def as_quaternion(name: str, value: Any) -> np.ndarray:
    """A finite non-zero (4,) quaternion, normalised."""
    try:
        q = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a quaternion (w, x, y, z), got {value!r}") from None
    if q.shape != (4,):
        raise ValueError(f"{name} must have shape (4,) (w, x, y, z), got {q.shape}")
    n = float(np.linalg.norm(q))
    if not math.isfinite(n) or n == 0.0:
        raise ValueError(f"{name} must be finite and non-zero, got {q}")
    return q / n


class GyroIncrements(NamedTuple):
    """The gyro increments an estimator's input ``dtheta_b`` takes (``Estimator.gyro_increments``):
    ``form`` "multiple", the multiple integrals ΔΘ¹..ΔΘ^m over each sample interval, or "sub",
    its m sub-interval increments (``ImuSamples.dtheta`` / ``dtheta_sub``; in the period call
    ``biso_cosim.loop.PeriodSamples.dtheta_b`` / ``dtheta_sub_b``, of which an in-loop kernel
    reads the first m rows)."""

    form: str
    m: int


class LoopArrays(NamedTuple):
    """An estimator's arrays in the period call (``Estimator.loop_arrays``): coefficients,
    state, and the outputs q_wb (bound, 4), flags (bound,) int64, gyro_bias_b (bound, 3) or
    (0, 3) when it estimates no bias."""

    coef: np.ndarray
    state: np.ndarray
    q_wb: np.ndarray
    flags: np.ndarray
    gyro_bias_b: np.ndarray


# --------------------------------------------------------------------------------------
# The streaming wrapper
# --------------------------------------------------------------------------------------


class Estimator:
    """Streaming attitude estimator: ``update`` continues where the previous call stopped.

    Subclasses set ``method``, ``Params``, ``state_layout`` and implement
    ``_coefficients(params, fs_hz) -> np.ndarray``, ``_initial_state(q0) -> np.ndarray`` and
    ``_run(coef, state, gyro, accel, mag, extra, q_out, flags_out, bias_out)``, where
    ``extra`` maps each name of ``inputs`` (optional per-sample inputs, ``INPUTS``) to its
    checked array, or to an empty one when it was not given.
    """

    method: ClassVar[str]
    Params: ClassVar[type]
    state_layout: ClassVar[tuple[tuple[str, int], ...]]
    inputs: ClassVar[tuple[str, ...]] = ()
    vehicle_params: ClassVar[tuple[str, ...]] = ()
    """Parameters (names of ``Params``) whose value is a property of the vehicle the estimator
    rides on, e.g. ``speed_point_b_m``: where the speed input is measured. Riding on the
    co-simulation's car (``biso_cosim.cosim``, ``compare``) each of them the user has not set
    takes the car's value (``VehicleSim.estimator_defaults``, which names the ones it knows)."""
    estimates_bias: ClassVar[bool] = False
    loop_kernel: ClassVar[Callable | None] = None
    """The estimator's kernel in the co-simulation's period call (``biso_cosim.loop``): a
    jitted ``kernel(arrays, samples)`` on ``biso_cosim.loop.PeriodSamples`` (k rows: gyro_b,
    accel_b, mag_b, imu_flags, speed_mps, ..., the period's fixes ``gnss`` and the gyro
    increments ``dtheta_b``/``dtheta_sub_b`` it declares in ``gyro_increments``) that advances
    ``arrays`` (``loop_arrays``) and writes the first k rows of its outputs, with the same
    arithmetic as ``update`` on those inputs. None: the estimator runs by ``update`` after
    the period's call."""
    loop_views: ClassVar[bool] = True
    """Whether ``loop_estimate(arrays, k)`` is views of the arrays alone, so that a caller may
    keep it for every later period of k samples (the co-simulation does, with reused
    outputs); False when it makes something of each period (GNSS-aided: the updates)."""

    def __init__(self, fs_hz: float, params: Any = None, *, method: str | None = None):
        self.method = method or type(self).method
        self.fs_hz = check_finite("fs_hz", fs_hz, low=0.0, low_open=True)
        params = self.Params() if params is None else params
        if not isinstance(params, self.Params):
            raise TypeError(f"params must be {self.Params.__name__}, got {type(params).__name__}")
        self._params = params
        self._coef = self._coefficients(params, self.fs_hz)
        self._q0: np.ndarray | None = None
        self._state = self._initial_state(None)
        self._prechecked = None  # (parameter record, input requirements) checked: see update_prechecked
        self._retune_record: tuple[Any, np.ndarray | None] = (None, None)  # (record, its retune_values)
        self.arrays_version = 0
        """Counts the replacements of the coefficient and state arrays (``loop_arrays``)."""

    # -- parameters -------------------------------------------------------------------

    @property
    def params(self) -> Any:
        """The parameter record (frozen); change it with ``set_params``."""
        return self._params

    @property
    def coefficients(self) -> np.ndarray:
        """The derived coefficients the kernel reads (a copy)."""
        return self._coef.copy()

    def set_params(self, **changes: Any) -> None:
        """Change parameters without touching the state (no jump in the attitude).

        Derived coefficients are recomputed; an invalid change raises and leaves the
        estimator as it was.
        """
        params = self._replace_params(**changes)
        coef = self._coefficients(params, self.fs_hz)
        self._params, self._coef = params, coef
        self.arrays_version += 1

    retune_kernel: Any = None
    """Optional, for ``retune``: a jitted ``kernel(values, coef) -> int`` that derives the
    coefficients into ``coef`` in place from ``values`` (``retune_values``' vector of the
    parameter record with the changes written at ``retune_index``), returning -1; or, when
    a value is invalid, writes nothing and returns the index of the first invalid one.
    Declared in the estimator's own module, next to its Python derivation (the reference)."""
    retune_index: Mapping[str, int] = {}
    """With ``retune_kernel``: the real parameters it derives from, and their index in ``values``."""

    def retune_values(self, params: Any) -> np.ndarray:
        """With ``retune_kernel``: the vector of ``params`` (a record ``_coefficients`` accepted) it reads."""
        raise NotImplementedError(f"{type(self).__name__} declares no retune_kernel")

    def retune(self, **changes: Any) -> None:
        """Change parameters while the estimator runs (a tuning loop's change, each step):
        ``set_params``' result, the parameter record, the coefficients and the checks
        consistent, the state untouched. An estimator with a cheaper way for some changes
        takes it here (BISO: equal gains of the closed form, in place), and an estimator
        that offers a jitted derivation (``retune_kernel``) has it derive the coefficients
        in place for changes of the real parameters it names (``retune_index``) given as
        floats (biso_plus: every real parameter; the same numbers as ``set_params``, tested). The new
        coefficients are written into the coefficient array in place when they have its
        shape (a loop that holds the array goes on with it); otherwise the array is
        replaced and ``arrays_version`` counts up."""
        kernel = type(self).retune_kernel  # (a dispatcher binds as a method through an instance)
        if (kernel is not None and changes.keys() <= self.retune_index.keys()
                and all(type(value) is float for value in changes.values())):
            held, values = self._retune_record
            values = (self.retune_values(self._params) if held is not self._params else values).copy()
            index = self.retune_index
            for name, value in changes.items():
                values[index[name]] = value
            if kernel(values, self._coef) < 0:  # derived in place (else nothing written: the checks below raise)
                # the record's checks on these fields are the kernel's: a frozen dataclass copied with the
                # changes set in its __dict__ (dataclasses.replace costs more than the whole derivation)
                params = object.__new__(type(self._params))
                params.__dict__.update(self._params.__dict__, **changes)
                self._params, self._retune_record = params, (params, values)
                return
        params = self._replace_params(**changes)
        coef = self._coefficients(params, self.fs_hz)
        if coef.shape == self._coef.shape and coef.dtype == self._coef.dtype:
            self._coef[...] = coef
            self._params = params
        else:
            self._params, self._coef = params, coef
            self.arrays_version += 1

    def _replace_params(self, **changes: Any) -> Any:
        names = {f.name for f in dataclasses.fields(self.Params)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise TypeError(f"{self.method} has no parameter(s) {unknown}; known: {sorted(names)}")
        return dataclasses.replace(self._params, **changes)

    # -- state ------------------------------------------------------------------------

    def reset(self, q0: Any = None) -> None:
        """Forget everything. With ``q0`` (w, x, y, z), the attitude at the first sample of
        the next ``update`` is ``q0`` exactly; without it the first valid sample initialises
        the attitude from the accelerometer and magnetometer (eq. (7))."""
        q = None if q0 is None else as_quaternion("q0", q0)
        self._state = self._initial_state(q)
        self.arrays_version += 1

    def get_state(self) -> State:
        """A copy of the whole state (restore it with ``set_state``)."""
        return State(self.method, self._state.copy(), self.state_layout)

    def set_state(self, state: State) -> None:
        """Restore a state from ``get_state`` of an estimator of the same method."""
        if not isinstance(state, State):
            raise TypeError(f"state must be a State from get_state(), got {type(state).__name__}")
        if state.method != self.method:
            raise ValueError(f"state is of method {state.method!r}, this estimator is {self.method!r}")
        values = np.asarray(state.values, dtype=np.float64)
        if values.shape != self._state.shape:
            raise ValueError(f"state.values must have shape {self._state.shape}, got {values.shape}")
        self._state = values.copy()
        self.arrays_version += 1

    @property
    def initialized(self) -> bool:
        """Whether an attitude has been set (by ``reset(q0=...)`` or a valid sample)."""
        return bool(self._state[0] != 0.0)

    # -- running ----------------------------------------------------------------------

    def update(self, gyro_b: Any, accel_b: Any, mag_b: Any, **inputs: Any) -> Estimate:
        """Process k samples: gyro (rad/s), accelerometer (m/s²), magnetometer (µT), each
        (k, 3) in body axes at ``fs_hz``, and the optional per-sample inputs this estimator
        lists in ``inputs`` (``INPUTS``: ``imu_flags``, ``speed_mps``, ...). Returns the
        attitude after each sample.

        NaN/inf samples are not errors: see the estimator's policy and the flags. Wrong
        shapes or types, or an input the estimator does not take, raise before anything
        changes.
        """
        gyro, accel, mag = as_samples(("gyro_b", gyro_b), ("accel_b", accel_b), ("mag_b", mag_b))
        k = gyro.shape[0]
        extra = self._extra_inputs(inputs, k)
        q_out = np.empty((k, 4))
        flags = np.empty(k, dtype=np.int64)
        bias = np.empty((k, 3)) if self.estimates_bias else np.empty((0, 3))
        self._run(self._coef, self._state, gyro, accel, mag, extra, q_out, flags, bias)
        return Estimate(q_out, flags, bias if self.estimates_bias else None)

    def update_prechecked(self, gyro_b: np.ndarray, accel_b: np.ndarray, mag_b: np.ndarray,
                          inputs: dict[str, np.ndarray]) -> Estimate:
        """``update`` for a caller that passes arrays already in the kernels' form, and the
        same optional inputs every call: the co-simulation, feeding its own MPU-9250's
        samples (C-contiguous float64 (k, 3), int64 flags, C-contiguous increments and
        series). On a control period's few samples ``update``'s checks cost several times
        the kernel, so here they run on the first call and again whenever
        ``_input_requirements`` changes (a parameter can change what an input must be, e.g.
        BISO's ``gyro_step``); the calls between go straight to the kernel, with the same
        results bit for bit."""
        params, checked = self._params, self._prechecked
        if checked is None or params is not checked[0]:  # (a parameter record is replaced, never changed)
            requirements = self._input_requirements()
            if checked is None or requirements != checked[1] or type(self).update is not Estimator.update:
                out = self.update(gyro_b, accel_b, mag_b, **inputs)
                if type(self).update is Estimator.update:
                    self._prechecked = (params, requirements)
                return out
            self._prechecked = (params, requirements)
        k = gyro_b.shape[0]
        extra = self._absent_inputs | inputs
        q_out = np.empty((k, 4))
        flags = np.empty(k, dtype=np.int64)
        bias = np.empty((k, 3)) if self.estimates_bias else _NO_BIAS
        self._run(self._coef, self._state, gyro_b, accel_b, mag_b, extra, q_out, flags, bias)
        return Estimate(q_out, flags, bias if self.estimates_bias else None)

    # -- in the co-simulation's period call (biso_cosim.loop) ---------------------------

    def loop_arrays(self, bound: int) -> Any:
        """The named tuple of arrays ``loop_kernel`` runs on, with outputs for up to ``bound``
        samples, or None when the estimator cannot run in the period call as it is set now
        (no ``loop_kernel``, or a parameter that needs an input the loop does not give):
        ``LoopArrays(coef, state, q_wb, flags, gyro_bias_b)`` here, the coefficient and
        state arrays themselves (advanced in place; ``arrays_version`` counts their
        replacements)."""
        if type(self).loop_kernel is None:
            return None
        bias = np.empty((bound, 3)) if self.estimates_bias else _NO_BIAS
        return LoopArrays(self._coef, self._state, np.empty((bound, 4)), np.empty(bound, dtype=np.int64), bias)

    def loop_estimate(self, arrays: Any, k: int) -> Estimate:
        """The estimate of the first k samples in ``arrays``' outputs (views)."""
        bias = getattr(arrays, "gyro_bias_b", None)
        return Estimate(arrays.q_wb[:k], arrays.flags[:k], bias[:k] if self.estimates_bias else None)

    @property
    def gyro_increments(self) -> GyroIncrements | None:
        """The gyro increments the input ``dtheta_b`` takes as the parameters are set now
        (``GyroIncrements``: form and rows), None when the estimator takes none (none here):
        the one statement of it, from which the co-simulation asks its MPU-9250 for them,
        feeds them to ``update`` and to the period call, and the log names their columns."""
        return None

    def _input_requirements(self) -> Any:
        """What of the parameters decides which optional inputs ``update`` accepts and in
        what form (none here: the checks of ``INPUTS`` do not depend on parameters)."""
        return ()

    @functools.cached_property
    def _absent_inputs(self) -> dict[str, np.ndarray]:
        """What the kernel gets for each optional input not given (shared between calls:
        kernels only read it)."""
        return {name: INPUTS[name][1]() for name in self.inputs if name in INPUTS}

    def _extra_inputs(self, inputs: dict[str, Any], k: int) -> dict[str, np.ndarray]:
        """Check the optional inputs (raises before anything changes): name → array."""
        unknown = sorted(inputs.keys() - self.inputs)
        if unknown:
            known = list(self.inputs) or "none"
            raise TypeError(f"{self.method} does not take input(s) {unknown}; optional inputs: {known}")
        out = {}
        for name in self.inputs:
            if name in INPUTS:
                value = inputs.get(name)
                out[name] = self._absent_inputs[name] if value is None else INPUTS[name][0](name, value, k)
        return out

    def __repr__(self) -> str:
        return f"{type(self).__name__}(fs_hz={self.fs_hz!r}, params={self._params!r})"
