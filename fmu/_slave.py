"""A co-simulation slave in Python, addressed by value reference, with FMI's modes, statuses
and refusals: the model half of ``BisoVehicle``, whose C shell
(``native/src/python``) forwards every FMI call to it through ``_embedded.py``.

As the standard reads them (and as the native FMUs do), every refusal is status *error*
with one logged line naming the variable and what is allowed:

* a value outside a variable's allowed range or choices (``allowed_values``), a non-finite
  Real, setting an output, or a fixed parameter after initialization: refused by the setter,
  the value is not stored;
* parameters that only the whole model can judge (a route that does not exist, rates that
  do not divide): refused by ``ExitInitializationMode`` ("invalid parameters: ..."); the
  instance stays in initialization mode, so the host may correct them and exit again;
* an invalid change of a tunable estimator parameter in step mode: refused by the setter,
  every tunable value of that call kept at its previous value;
* a communication step the model cannot take (not a whole number of its periods): refused
  by ``DoStep`` with the allowed steps; nothing is computed, the master may repeat the step.

A method never raises: an unexpected exception is logged (status error) with where it
happened, and the call returns ``ERROR``.
"""

from __future__ import annotations

import copy
import functools
import io
import json
import math
import pickle
import traceback
from pathlib import Path
from typing import Any, Callable, ClassVar, Sequence

import numpy as np

from biso_cosim import __version__
from biso_cosim.fmu.variables import Var, allowed_values, fingerprint, has_flag_name, variables_of

__all__ = ["BisoSlave", "FmuConfigError", "FmuStepError", "STAMP_FILE", "OK", "WARNING", "DISCARD", "ERROR",
           "FATAL"]

STAMP_FILE = "biso_cosim_fmu.json"
"""Resource file written by the build: package version and variable fingerprint."""

OK, WARNING, DISCARD, ERROR, FATAL = range(5)
"""FMI statuses (fmi2Status and fmi3Status have the same values)."""

INSTANTIATED, INITIALIZATION, STEP, TERMINATED = range(4)

_CAST = {"Real": float, "Integer": int, "Boolean": bool, "String": str}
_STATE_MAGIC = b"biso_cosim FMU state 2\n"
_MAG_INVALID = 16  # biso_cosim.sensors.ImuFlag.MAG_INVALID


class FmuConfigError(ValueError):
    """Parameters the model cannot use; the message names the FMI variable."""


class FmuStepError(ValueError):
    """A communication step the model cannot take (nothing was computed); the message says
    what is allowed."""


def _describe(exc: BaseException) -> str:
    if isinstance(exc, (ValueError, TypeError, KeyError, FileNotFoundError)):
        return str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    tb = traceback.extract_tb(exc.__traceback__)[-1:]
    where = f" at {tb[0].filename}:{tb[0].lineno}" if tb else ""
    return f"{type(exc).__name__}: {exc}{where}"


def _guarded(method):
    """Log any exception of an FMI call as status error and return ERROR (the host sees a
    status, never a Python exception)."""

    @functools.wraps(method)
    def call(self, function: str, *args):
        try:
            return method(self, function, *args)
        except Exception as exc:  # noqa: BLE001 - a status is all an FMI host can take
            self.error(f"{function}: {_describe(exc)}")
            return ERROR

    return call


def _heading(yaw: float) -> float:
    """Compass heading of an ENU yaw, [0, 2π), as ``frames.heading_from_yaw`` for one value."""
    h = (0.5 * math.pi - yaw) % (2.0 * math.pi)
    return 0.0 if h >= 2.0 * math.pi else h


class BisoSlave:
    """Base of a Python co-simulation slave. Subclasses set ``fmu`` and implement
    ``_configure()`` (build the model from ``values``; raise ValueError / TypeError naming
    the variable), ``_advance(step_size)`` (one communication step; `FmuStepError` before
    computing anything when the step cannot be taken), ``release_model()``, ``model_state()``
    and ``restore_model_state(state)``.

    Args:
        instance_name: the host's name of the instance (for messages).
        log: ``log(status, message)``: hands a message to the host's logger.
        resources: the FMU's resources/ folder (its stamp is checked), or None.
    """

    fmu: ClassVar[str]

    def __init__(self, instance_name: str, log: Callable[[int, str], None], resources: Path | None = None):
        self.instance_name = instance_name
        self._log = log
        self._check_stamp(resources)
        self.specs: tuple[Var, ...] = variables_of(self.fmu)
        self.by_vr: dict[int, Var] = {vr: v for vr, v in enumerate(self.specs, start=1)}
        self.spec = {v.name: v for v in self.specs}
        # names of the variables of each key head, in component order (e.g. "gyro" → 3 names)
        self.keyed: dict[str, list[str]] = {}
        for v in self.specs:
            self.keyed.setdefault(v.key[0], []).append(v.name)
        self._start()

    def _start(self) -> None:
        self.values: dict[str, Any] = {v.name: v.start for v in self.specs}
        self.set_by_host: set[str] = set()
        self.phase = INSTANTIATED
        self.start_time = self.time = 0.0

    # ---- logging -----------------------------------------------------------------------

    def error(self, message: str) -> None:
        self._log(ERROR, message)

    def warning(self, message: str) -> None:
        self._log(WARNING, message)

    def info(self, message: str) -> None:
        self._log(OK, message)

    # ---- modes ---------------------------------------------------------------------------

    @_guarded
    def setup_experiment(self, function: str, start_time: float) -> int:
        if self.phase != INSTANTIATED:
            self.error(f"{function}: only allowed after instantiation or reset")
            return ERROR
        self.start_time = self.time = float(start_time)
        return OK

    @_guarded
    def enter_initialization(self, function: str, start_time: float | None = None) -> int:
        if self.phase != INSTANTIATED:
            self.error(f"{function}: only allowed after instantiation or reset")
            return ERROR
        if start_time is not None:
            self.start_time = self.time = float(start_time)
        self.phase = INITIALIZATION
        return OK

    @_guarded
    def exit_initialization(self, function: str) -> int:
        if self.phase != INITIALIZATION:
            self.error(f"{function}: only allowed in initialization mode")
            return ERROR
        try:
            self._configure()
        except (ValueError, TypeError, KeyError, FileNotFoundError) as exc:
            self.error(f"{function}: invalid parameters: {_describe(exc)} (correct them and exit initialization "
                       "mode again)")
            return ERROR
        self.phase = STEP
        return OK

    @_guarded
    def do_step(self, function: str, t: float, step_size: float) -> int:
        if self.phase != STEP:
            self.error(f"{function}: only allowed in step mode (after ExitInitializationMode)")
            return ERROR
        if not (math.isfinite(step_size) and step_size > 0.0):
            self.error(f"{function} at t = {t!r} s refused: the step size must be positive, got {step_size!r}")
            return ERROR
        try:
            self._advance(step_size)
        except FmuStepError as exc:
            self.error(f"{function} at t = {t!r} s refused (nothing computed): {exc}")
            return ERROR
        self.time = t + step_size
        return OK

    @_guarded
    def terminate(self, function: str) -> int:
        if self.phase not in (INITIALIZATION, STEP):
            self.error(f"{function}: only allowed in initialization or step mode")
            return ERROR
        # after Terminate only Reset or FreeInstance may follow: the model's resources go now
        self.release_model()
        self.phase = TERMINATED
        return OK

    @_guarded
    def reset(self, function: str) -> int:
        self.release_model()
        self._start()
        return OK

    def free(self) -> None:
        self.release_model()

    # ---- values --------------------------------------------------------------------------

    @_guarded
    def set(self, function: str, type_name: str, vrs: Sequence[int], values: Sequence[Any]) -> int:
        """Set variables of one FMI type (``Real``, ``Integer``, ``Boolean``, ``String``) by
        value reference; refused ones are logged and not stored."""
        status = OK
        old: dict[str, Any] = {}  # tunable parameters changed in step mode: their previous values
        for vr, value in zip(vrs, values):
            v = self.by_vr.get(int(vr))
            if v is None or v.type != type_name:
                self.error(f"{function}: {self.fmu} has no {type_name} variable with value reference {vr}")
                status = ERROR
                continue
            value = _CAST[v.type](value)
            problem = self._refusal(v, value)
            if problem:
                self.error(f"{function}: {v.name} not set: {problem}")
                status = ERROR
                continue
            if v.causality == "parameter":
                if self.phase == STEP:
                    old.setdefault(v.name, self.values[v.name])
                self.set_by_host.add(v.name)
            self.values[v.name] = value
        if old and not self._apply_tunables(function, sorted(old)):
            self.values.update(old)
            status = ERROR
        return status

    def _refusal(self, v: Var, value: Any) -> str | None:
        """Why ``value`` cannot be stored in ``v`` now (None: it can)."""
        if v.causality == "output":
            return "it is an output (the FMU computes it)"
        if self.phase == TERMINATED:
            return "the instance is terminated (Reset it first)"
        if v.causality == "parameter" and v.variability == "fixed" and self.phase == STEP:
            return f"a fixed parameter cannot change after initialization (kept {self.values[v.name]!r})"
        if v.type == "Boolean" or (v.type == "String" and not allowed_values(v).choices):
            return None
        allowed = allowed_values(v)
        if allowed.admits(value):
            return None
        bounded = math.isfinite(allowed.lo) or math.isfinite(allowed.hi)
        unit = f" {v.unit}" if v.unit and bounded and not allowed.choices else ""
        return f"allowed {allowed}{unit}, got {value!r}"

    @_guarded
    def get(self, function: str, type_name: str, vrs: Sequence[int], out: list[Any]) -> int:
        """Write the values of variables of one FMI type into ``out`` (same order as ``vrs``)."""
        status = OK
        values = self.values
        for i, vr in enumerate(vrs):
            v = self.by_vr.get(int(vr))
            if v is None or v.type != type_name:
                self.error(f"{function}: {self.fmu} has no {type_name} variable with value reference {vr}")
                status = ERROR
                continue
            out[i] = values[v.name]
        return status

    def vector(self, head: str) -> list[Any]:
        """The current values of the variables of one key head, in component order."""
        values = self.values
        return [values[n] for n in self.keyed[head]]

    def put(self, head: str, seq: Any) -> None:
        """Write the outputs of one key head from a sequence (list, tuple, array) or a scalar."""
        names = self.keyed[head]
        values, cast = self.values, _CAST[self.spec[names[0]].type]
        if isinstance(seq, np.ndarray):
            seq = seq.tolist()
        if not isinstance(seq, (list, tuple)):
            values[names[0]] = cast(seq)
            return
        for name, x in zip(names, seq):
            values[name] = cast(x)

    # ---- the model (subclasses) ----------------------------------------------------------

    def _configure(self) -> None:
        raise NotImplementedError

    def _advance(self, step_size: float) -> None:
        raise NotImplementedError

    def release_model(self) -> None:
        """Drop the model's resources (subclasses with a heavy model override)."""

    def model_state(self) -> Any:
        raise NotImplementedError

    def restore_model_state(self, state: Any) -> None:
        raise NotImplementedError

    def apply_estimator_params(self, changes: dict[str, Any]) -> None:
        """Change the configured estimator's parameters (ValueError / TypeError when invalid)."""
        raise NotImplementedError

    # ---- tunable parameters and estimators ----------------------------------------------

    def _apply_tunables(self, function: str, names: list[str]) -> bool:
        """Apply tunable estimator parameters changed in step mode; False (logged) when invalid."""
        changes: dict[str, Any] = {}
        chosen = self.values["estimator"]
        for name in names:
            v = self.spec[name]
            if v.key[0] == "given":  # a has_ flag: the parameter it belongs to changes
                v = self.spec[f"{v.key[1]}.{v.key[2]}"]
            if v.key[1] == chosen:
                changes[v.key[2]] = self._param_value(v)
            else:
                self.warning(f"{function}: {name} belongs to another estimator than {chosen!r}: ignored")
        if not changes:
            return True
        try:
            self.apply_estimator_params(changes)
        except (ValueError, TypeError) as exc:
            self.error(f"{function}: invalid parameter change of {chosen}: {exc} (every value of this call kept)")
            return False
        self.info(f"{function}: {chosen} parameters changed: {changes}")
        return True

    def estimator_choice(self) -> tuple[str, dict[str, Any]]:
        """The chosen estimator's name and its parameters from the variables (an optional
        one is None unless its ``has_`` flag is true). With ``declination_from_site`` true
        ``declination_rad`` is left out: the model uses its site's."""
        name = self.values["estimator"]
        params: dict[str, Any] = {}
        for v in self.specs:
            if v.key[0] == "param" and v.key[1] == name:
                params[v.key[2]] = self._param_value(v)
        if self.values.get("declination_from_site", False):
            params.pop("declination_rad", None)
        return name, params

    def _param_value(self, v: Var) -> Any:
        from biso_cosim.fmu.variables import estimator_param_groups

        row = next(r for r in estimator_param_groups()[v.key[1]] if r["name"] == v.key[2])
        if row["kind"] == "Real3":
            prefix = v.name.rsplit("[", 1)[0]
            return tuple(self.values[f"{prefix}[{i}]"] for i in (1, 2, 3))
        if row["optional"] and not self.values[has_flag_name(v.key[1], v.key[2])]:
            return None
        return self.values[v.name]

    def samples_in(self, step_size: float, rate_hz: float, what: str) -> int:
        """How many periods of ``rate_hz`` one step holds; `FmuStepError` unless whole."""
        n_float = step_size * rate_hz
        n = round(n_float)
        if n < 1 or abs(n_float - n) > 1e-6:
            raise FmuStepError(f"the communication step {step_size!r} s is not a whole number of {what} periods; "
                               f"allowed steps: n * {1.0 / rate_hz!r} s (n = 1, 2, ...)")
        return n

    def mounting_quaternion(self, head: str = "mounting") -> np.ndarray | None:
        """q_body_sensor from the mounting angles, or None for no rotation."""
        from biso_cosim.frames import quat_from_euler

        angles = self.vector(head)
        return None if not any(angles) else quat_from_euler(*angles)

    # ---- shared outputs ------------------------------------------------------------------

    def put_estimate(self, q_wb: np.ndarray, flags: int, gyro_bias_b: np.ndarray | None) -> None:
        """``estimate.*`` from the attitude after the latest sample."""
        from biso_cosim.frames import _euler_from_q

        w, x, y, z = (float(c) for c in q_wb)
        roll, pitch, yaw = _euler_from_q(w, x, y, z)
        self.put("q_est", (w, x, y, z))
        self.put("euler_est", (roll, pitch, yaw, _heading(yaw)))
        self.put("flags_est", int(flags))
        self.put("bias_est", (0.0, 0.0, 0.0) if gyro_bias_b is None else gyro_bias_b)

    def put_errors(self, q_est: np.ndarray, q_true: np.ndarray) -> None:
        """``error.*``: estimate minus truth as ``biso_cosim.metrics.angle_errors_deg`` defines
        them (roll, pitch, compass heading wrapped to (−π, π]; total rotation angle), in rad,
        with the scalar kernels (one sample: the array functions cost more than the step)."""
        from biso_cosim.frames import _euler_from_q, _qmul, _qnormalize

        e = _qnormalize(*(float(c) for c in q_est))
        t = _qnormalize(*(float(c) for c in q_true))
        ae, at = _euler_from_q(*e), _euler_from_q(*t)
        diff = (ae[0] - at[0], ae[1] - at[1], _heading(ae[2]) - _heading(at[2]))
        d = _qmul(e[0], -e[1], -e[2], -e[3], *t)
        total = 2.0 * math.atan2(math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3]), abs(d[0]))
        self.put("error", [math.pi - (math.pi - a) % (2.0 * math.pi) for a in diff] + [total])

    def put_readings(self, samples: Any, start_time: float, count: int | None = None) -> None:
        """The latest of the MPU-9250 output samples of a step (held when there are none);
        ``count``: the samples of the whole step when they came in several calls."""
        k = len(samples.t_s)
        self.put("new_samples", k if count is None else count)
        if k == 0:
            return
        self.put("sample_time", start_time + float(samples.t_s[-1]))
        for head, column in (("gyro", samples.gyro_b), ("accel", samples.accel_b), ("mag", samples.mag_b),
                             ("temperature", samples.temperature_c), ("mag_fresh", samples.mag_fresh),
                             ("imu_flags", samples.flags), ("raw", samples.raw.words), ("status", samples.raw.status)):
            self.put(head, column[-1])
        if samples.flags[-1] & _MAG_INVALID:
            self.put("mag", (0.0, 0.0, 0.0))  # the documented sentinel, never NaN out

    # ---- FMU state -----------------------------------------------------------------------

    def get_state(self) -> dict[str, Any]:
        """A deep copy of the whole instance: variables, mode, time and the model's state."""
        return copy.deepcopy({
            "fmu": self.fmu, "values": self.values, "set_by_host": self.set_by_host, "phase": self.phase,
            "time": self.time, "start_time": self.start_time,
            "model": self.model_state() if self.phase == STEP else None,
        })

    @_guarded
    def set_state(self, function: str, state: Any) -> int:
        if not isinstance(state, dict) or state.get("fmu") != self.fmu:
            self.error(f"{function}: not a state of {self.fmu}; nothing changed")
            return ERROR
        state = copy.deepcopy(state)
        fixed = self._fixed_values()
        was_step = self.phase == STEP
        self.values.clear()
        self.values.update(state["values"])
        self.set_by_host = state["set_by_host"]
        self.time, self.start_time = state["time"], state["start_time"]
        if state["model"] is not None:
            if not was_step or self._fixed_values() != fixed:
                self._configure()  # e.g. after Reset: the model from the state's parameters
            self.restore_model_state(state["model"])
        elif was_step:
            self.release_model()
        self.phase = state["phase"]
        return OK

    def _fixed_values(self) -> list[Any]:
        return [self.values[v.name] for v in self.specs if v.causality == "parameter" and v.variability == "fixed"]

    @staticmethod
    def serialize(state: dict[str, Any]) -> bytes:
        return _STATE_MAGIC + pickle.dumps(state, protocol=5)

    @staticmethod
    def deserialize(data: bytes) -> Any:
        """The state in ``data``; ValueError when it is not one of ours."""
        if not data.startswith(_STATE_MAGIC):
            raise ValueError("not a serialized biso_cosim FMU state (or one of another version)")
        return _StateUnpickler(io.BytesIO(data[len(_STATE_MAGIC):])).load()

    # ---- build stamp ---------------------------------------------------------------------

    def _check_stamp(self, resources: Path | None) -> None:
        """Refuse to run under a package whose variables differ from those the FMU was built with."""
        stamp = Path(resources) / STAMP_FILE if resources else None
        if stamp is None or not stamp.is_file():
            return
        built = json.loads(stamp.read_text("utf-8"))
        if built.get("fingerprint") != fingerprint(self.fmu):
            raise RuntimeError(
                f"{self.fmu} was built with biso_cosim {built.get('version')} whose variables differ from "
                f"those of the installed biso_cosim {__version__}: rebuild it with `biso-cosim fmu build`")


class _StateUnpickler(pickle.Unpickler):
    """Loads only what our states hold: builtins containers, numpy arrays, our records."""

    def find_class(self, module: str, name: str):
        if module.split(".")[0] == "numpy" or module.startswith("biso_cosim."):
            return super().find_class(module, name)
        if module == "builtins" and name in {"set", "frozenset", "complex", "slice", "range"}:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"FMU state refers to {module}.{name}, which a state never holds")
