"""What the three slaves share: variables from ``variables.py``, FMI-safe error handling,
step-size rules, parameter handling and FMU state.

pythonfmu 0.7 turns any Python exception into ``fmi2Fatal`` and drops the Python object, so
the next call of the host would touch freed memory. Every method the C wrapper calls is
therefore guarded here: an exception is logged with status *error* and the call returns
normally. The only non-fatal failure status pythonfmu can return is ``fmi2Discard`` (from
``do_step`` returning False), so that is how this package refuses:

* an invalid parameter is logged (status error) when the model is configured (in
  ``fmi2ExitInitializationMode``) and every ``fmi2DoStep`` then returns ``fmi2Discard``
  with the reason logged again; an invalid change of a *tunable* parameter is logged, the
  parameter keeps its previous value, and that step is discarded;
* a non-finite input (NaN, inf) makes ``fmi2DoStep`` return ``fmi2Discard`` with the input's
  name logged; nothing is computed and the FMU stays usable (set valid inputs and retry);
* a communication step that is not a whole number of the model's sample periods is
  discarded the same way (nothing is computed).

A refused step changes nothing, so a master may correct the inputs and repeat it.
"""

from __future__ import annotations

import copy
import ctypes
import functools
import io
import json
import math
import pickle
import traceback
from pathlib import Path
from typing import Any, ClassVar
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import (Boolean, DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer,
                       Real, String)
from pythonfmu.enums import Fmi2Status

from biso_cosim import __version__
from biso_cosim.fmu.variables import UNITS, Var, fingerprint, has_flag_name, variables_of

__all__ = ["BisoSlave", "FmuConfigError", "slave_class", "STAMP_FILE"]

STAMP_FILE = "biso_cosim_fmu.json"
"""Resource file written by the build: package version and variable fingerprint."""

_PY_TYPES = {"Real": (Real, float), "Integer": (Integer, int), "Boolean": (Boolean, bool), "String": (String, str)}
_STATE_MAGIC = b"biso_cosim FMU state 1\n"
_MAG_INVALID = 16  # biso_cosim.sensors.ImuFlag.MAG_INVALID


class FmuConfigError(ValueError):
    """A parameter or input the model cannot use; the message names the FMI variable."""


def _guard(fallback: Any = None):
    """Catch every exception of a method the C wrapper calls: log it, return ``fallback``
    (called with the same arguments when callable)."""

    def decorate(method):
        @functools.wraps(method)
        def guarded(self, *args):
            try:
                return method(self, *args)
            except Exception as exc:  # noqa: BLE001 - anything else would be fmi2Fatal
                self._error(f"{method.__name__}: {_describe(exc)}")
                return fallback(self, *args) if callable(fallback) else fallback

        return guarded

    return decorate


def _describe(exc: BaseException) -> str:
    if isinstance(exc, (ValueError, TypeError, KeyError, FileNotFoundError)):
        return str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    tb = traceback.extract_tb(exc.__traceback__)[-1:]
    where = f" at {tb[0].filename}:{tb[0].lineno}" if tb else ""
    return f"{type(exc).__name__}: {exc}{where}"


def _heading(yaw: float) -> float:
    """Compass heading of an ENU yaw, [0, 2π), as ``frames.heading_from_yaw`` for one value."""
    h = (0.5 * math.pi - yaw) % (2.0 * math.pi)
    return 0.0 if h >= 2.0 * math.pi else h


def _nan_list(self, vrs, *_):
    return [math.nan] * len(vrs)


class BisoSlave(Fmi2Slave):
    """Base of the biso_cosim slaves. Subclasses set ``fmu``, ``summary``, ``fmi_options`` and
    implement ``_configure()`` (build the model from the parameters; raise ValueError /
    TypeError naming the variable) and ``_advance(step_size)`` (one communication step)."""

    fmu: ClassVar[str]
    summary: ClassVar[str]
    author = "biso_cosim"
    license = "MIT"
    # CoSimulation capabilities; each FMU adds canHandleVariableCommunicationStepSize and
    # canGetAndSetFMUstate / canSerializeFMUstate
    fmi_options: ClassVar[dict[str, bool]] = {"canInterpolateInputs": False,
                                              "canBeInstantiatedOnlyOncePerProcess": False}
    default_step_s: ClassVar[float]     # DefaultExperiment stepSize (FMPy's simulate_fmu uses it)
    default_stop_s: ClassVar[float]     # DefaultExperiment stopTime

    def __init__(self, **kwargs: Any):
        super().__init__(**kwargs)
        self.modelName = self.fmu
        self.description = self.summary
        self.version = __version__
        self.default_experiment = DefaultExperiment(0.0, self.default_stop_s, self.default_step_s)
        self._check_stamp()
        self.specs: tuple[Var, ...] = variables_of(self.fmu)
        self.spec = {v.name: v for v in self.specs}
        self.values: dict[str, Any] = {v.name: v.start for v in self.specs}
        # names of the variables of each key head, in component order (e.g. "gyro" → 3 names)
        self.keyed: dict[str, list[str]] = {}
        for v in self.specs:
            self.keyed.setdefault(v.key[0], []).append(v.name)
        for v in self.specs:
            self._register(v)
        self._real_inputs = [v.name for v in self.specs if v.causality == "input" and v.type == "Real"]
        self._cast = {v.name: _PY_TYPES[v.type][1] for v in self.specs}
        self.set_by_host: set[str] = set()
        self.pending: set[str] = set()     # tunable parameters changed since the last step
        self.start_time = 0.0
        self.time = 0.0
        self.configured = False
        self.problem: str | None = None    # why every step is refused, if anything

    # ---- variables ---------------------------------------------------------------------

    def _register(self, v: Var) -> None:
        cls, _ = _PY_TYPES[v.type]
        kwargs: dict[str, Any] = {"causality": getattr(Fmi2Causality, v.causality),
                                  "variability": getattr(Fmi2Variability, v.variability),
                                  "description": v.description}
        if v.causality == "output":
            kwargs["initial"] = Fmi2Initial.exact  # fmpy validate wants start values of outputs
        values = self.values
        self.register_variable(cls(v.name, getter=lambda n=v.name: values[n],
                                   setter=lambda x, var=v: self._set(var, x), **kwargs), nested=False)

    def _set(self, v: Var, value: Any) -> None:
        if v.causality == "output":
            self._error(f"{v.name} is an output and cannot be set")
            return
        value = _PY_TYPES[v.type][1](value)
        if v.causality == "parameter" and self.configured:
            if v.variability != "tunable":
                self._error(f"{v.name} is a fixed parameter: it cannot change after initialization "
                            f"(kept {self.values[v.name]!r})")
                return
            self.pending.add(v.name)
        self.values[v.name] = value
        if v.causality == "parameter":
            self.set_by_host.add(v.name)

    def vector(self, head: str) -> list[Any]:
        """The current values of the variables of one key head, in component order."""
        values = self.values
        return [values[n] for n in self.keyed[head]]

    def put(self, head: str, seq: Any) -> None:
        """Write the outputs of one key head from a sequence (list, tuple, array) or a scalar."""
        names = self.keyed[head]
        values, cast = self.values, self._cast[names[0]]
        if isinstance(seq, np.ndarray):
            seq = seq.tolist()
        if not isinstance(seq, (list, tuple)):
            values[names[0]] = cast(seq)
            return
        for name, x in zip(names, seq):
            values[name] = cast(x)

    # ---- logging -----------------------------------------------------------------------

    def _message(self, message: str, status: Fmi2Status) -> None:
        # an FMI log message is a printf format: "%" must be written "%%"
        self.log(f"{self.fmu} {self.instance_name}: {message}".replace("%", "%%"), status)

    def _error(self, message: str) -> None:
        self._message(message, Fmi2Status.error)

    def _warning(self, message: str) -> None:
        self._message(message, Fmi2Status.warning)

    def _info(self, message: str) -> None:
        self._message(message, Fmi2Status.ok)

    # ---- FMI calls (all guarded) ---------------------------------------------------------

    get_real = _guard(_nan_list)(Fmi2Slave.get_real)
    get_integer = _guard(lambda self, vrs: [0] * len(vrs))(Fmi2Slave.get_integer)
    get_boolean = _guard(lambda self, vrs: [False] * len(vrs))(Fmi2Slave.get_boolean)
    get_string = _guard(lambda self, vrs: [""] * len(vrs))(Fmi2Slave.get_string)

    @_guard()
    def set_real(self, vrs, values):
        self._set_each(vrs, values, "Real")

    @_guard()
    def set_integer(self, vrs, values):
        self._set_each(vrs, values, "Integer")

    @_guard()
    def set_boolean(self, vrs, values):
        self._set_each(vrs, values, "Boolean")

    @_guard()
    def set_string(self, vrs, values):
        self._set_each(vrs, values, "String")

    def _set_each(self, vrs, values, type_name: str) -> None:
        for vr, value in zip(vrs, values):
            var = self.vars.get(vr)
            if var is None or self.spec[var.name].type != type_name:
                self._error(f"no {type_name} variable with value reference {vr}")
                continue
            try:
                var.setter(value)
            except Exception as exc:  # noqa: BLE001
                self._error(f"setting {var.name}: {_describe(exc)}")

    @_guard()
    def setup_experiment(self, start_time: float, stop_time: float | None = None, tolerance: float | None = None):
        # pythonfmu 0.7's wrapper passes the start time only; the models need nothing else
        self.start_time = self.time = float(start_time)

    @_guard()
    def enter_initialization_mode(self):
        pass

    @_guard()
    def exit_initialization_mode(self):
        self._try_configure()

    @_guard()
    def terminate(self):
        # after fmi2Terminate only fmi2Reset (which configures the model again) or
        # fmi2FreeInstance may follow: the model's resources (MuJoCo) go now, while everything
        # they need is alive, rather than with the slave when the cycle collector finds it
        self.release_model()
        self.configured = False

    def release_model(self) -> None:
        """Drop the model's resources (subclasses with a heavy model override)."""

    @_guard(False)
    def do_step(self, current_time: float, step_size: float) -> bool:
        if not self.configured and self.problem is None:
            self._try_configure()  # a master that skipped initialization mode
        if self.problem is not None:
            self._error(f"step at t = {current_time:g} s refused: {self.problem}")
            return False
        if not (math.isfinite(step_size) and step_size > 0.0):
            self._error(f"step at t = {current_time:g} s refused: step size must be positive, got {step_size!r}")
            return False
        values = self.values
        bad = [n for n in self._real_inputs if not math.isfinite(values[n])]
        if bad:
            self._error(f"step at t = {current_time:g} s refused: input(s) {', '.join(bad)} not finite "
                        f"({', '.join(repr(values[n]) for n in bad)}); nothing was computed")
            return False
        if self.pending and not self._apply_pending():
            return False
        try:
            self._advance(step_size)
        except FmuConfigError as exc:
            self._error(f"step at t = {current_time:g} s refused: {exc}")
            return False
        self.time = current_time + step_size
        return True

    # ---- configuration -------------------------------------------------------------------

    def _try_configure(self) -> None:
        try:
            self._configure()
        except (ValueError, TypeError, KeyError, FileNotFoundError) as exc:
            self.problem = f"invalid parameters: {_describe(exc)}"
            self._error(self.problem)
            return
        self.configured = True
        self.pending.clear()

    def _configure(self) -> None:
        raise NotImplementedError

    def _advance(self, step_size: float) -> None:
        raise NotImplementedError

    def _apply_pending(self) -> bool:
        """Apply the tunable estimator parameters changed since the last step (``self.est``,
        ``self.name``: the configured estimator); False (step refused) when invalid."""
        changes: dict[str, Any] = {}
        for name in sorted(self.pending):
            v = self.spec[name]
            if v.key[0] == "given":  # a has_ flag: the parameter it belongs to changes
                v = self.spec[f"{v.key[1]}.{v.key[2]}"]
            if v.key[1] == self.name:
                changes[v.key[2]] = self._param_value(v)
            else:
                self._warning(f"{name} belongs to another estimator than {self.name!r}: ignored")
        self.pending.clear()
        if not changes:
            return True
        try:
            self.est.set_params(**changes)
        except (ValueError, TypeError) as exc:
            self.params_as_values(self.name, self.est.params)
            self._error(f"step refused: invalid parameter change of {self.name}: {exc} (parameters kept)")
            return False
        self._info(f"{self.name} parameters changed: {changes}")
        return True

    def samples_in(self, step_size: float, rate_hz: float, what: str) -> int:
        """How many periods of ``rate_hz`` one step holds; FmuConfigError unless whole."""
        n_float = step_size * rate_hz
        n = round(n_float)
        if n < 1 or abs(n_float - n) > 1e-6:
            raise FmuConfigError(f"the communication step {step_size!r} s is not a whole number of {what} "
                                 f"periods (1/{rate_hz:g} s); use a multiple of {1.0 / rate_hz!r} s")
        return n

    def mounting_quaternion(self, head: str = "mounting") -> np.ndarray | None:
        """q_body_sensor from the mounting angles, or None for no rotation."""
        from biso_cosim.frames import quat_from_euler

        angles = self.vector(head)
        if not all(math.isfinite(a) for a in angles):
            raise ValueError(f"{'/'.join(self.keyed[head])} must be finite, got {angles}")
        return None if not any(angles) else quat_from_euler(*angles)

    # ---- estimators ----------------------------------------------------------------------

    def estimator_choice(self, site_declination: float | None = None) -> tuple[str, dict[str, Any]]:
        """The chosen estimator's name and its parameters from the variables (an optional
        one is None unless its ``has_`` flag is true).

        With ``declination_from_site`` true, ``declination_rad`` is ``site_declination``
        (left out when that is None: the model then uses its own site's).
        """
        from biso_cosim.fmu.variables import fmu_estimator_names

        name = self.values["estimator"]
        if name not in fmu_estimator_names():
            raise ValueError(f"estimator must be one of {', '.join(fmu_estimator_names())}, got {name!r}"
                             " (the GNSS-aided estimators are not offered in the FMUs)")
        params: dict[str, Any] = {}
        for v in self.specs:
            if v.key[0] == "param" and v.key[1] == name:
                params[v.key[2]] = self._param_value(v)
        if self.values.get("declination_from_site", False):
            params.pop("declination_rad", None)
            if site_declination is not None:
                params["declination_rad"] = site_declination
        return name, params

    def make_estimator(self, fs_hz: float, params: dict[str, Any]):
        """``make_estimator`` for the chosen estimator; errors name its FMI variables."""
        from biso_cosim.estimators import make_estimator

        try:
            return make_estimator(self.name, fs_hz, **params)
        except (ValueError, TypeError) as exc:
            raise ValueError(f"estimator {self.name!r} (variables {self.name}.*): {exc}") from None

    def _param_value(self, v: Var) -> Any:
        from biso_cosim.fmu.variables import estimator_param_groups

        row = next(r for r in estimator_param_groups()[v.key[1]] if r["name"] == v.key[2])
        if row["kind"] == "Real3":
            prefix = v.name.rsplit("[", 1)[0]
            return tuple(self.values[f"{prefix}[{i}]"] for i in (1, 2, 3))
        if row["optional"] and not self.values[has_flag_name(v.key[1], v.key[2])]:
            return None
        return self.values[v.name]

    def params_as_values(self, name: str, params: Any) -> None:
        """Write an estimator's parameter record back into the variables (after a refused change)."""
        for v in self.specs:
            if v.key[0] == "param" and v.key[1] == name:
                value = getattr(params, v.key[2])
                if len(v.key) == 4:
                    value = value[v.key[3]]
                elif value is None:
                    continue  # the value stays; its has_ flag (a parameter of its own) says None
                elif isinstance(value, tuple):
                    value = value[0]
                self.values[v.name] = _PY_TYPES[v.type][1](value)

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

    def model_state(self) -> Any:
        """A copy of the model's own state (subclasses that support FMU state override)."""
        raise NotImplementedError

    def restore_model_state(self, state: Any) -> None:
        raise NotImplementedError

    @_guard()
    def _get_fmu_state(self):
        if not self.fmi_options.get("canGetAndSetFMUstate"):
            self._error("fmi2GetFMUstate is not supported by this FMU (canGetAndSetFMUstate=false)")
            return None
        return copy.deepcopy({
            "fmu": self.fmu, "values": self.values, "set_by_host": self.set_by_host, "pending": self.pending,
            "time": self.time, "start_time": self.start_time,
            "configured": self.configured, "problem": self.problem,
            "model": self.model_state() if self.configured else None,
        })

    @_guard()
    def _set_fmu_state(self, state):
        if not self.fmi_options.get("canGetAndSetFMUstate"):
            self._error("fmi2SetFMUstate is not supported by this FMU (canGetAndSetFMUstate=false)")
            return
        if not isinstance(state, dict) or state.get("fmu") != self.fmu:
            self._error(f"fmi2SetFMUstate: not a state of {self.fmu}; nothing changed")
            return
        state = copy.deepcopy(state)
        fixed = self._fixed_values()
        self.values.clear()
        self.values.update(state["values"])
        for name in ("set_by_host", "pending", "time", "start_time", "problem"):
            setattr(self, name, state[name])
        if state["configured"] and (not self.configured or self._fixed_values() != fixed):
            self._try_configure()  # e.g. after fmi2Reset: the model from the state's parameters
        if state["model"] is not None:
            self.restore_model_state(state["model"])
        self.configured = state["configured"]

    def _fixed_values(self) -> list[Any]:
        return [self.values[v.name] for v in self.specs if v.causality == "parameter" and v.variability == "fixed"]

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        return _STATE_MAGIC + pickle.dumps(state, protocol=5)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        if not data.startswith(_STATE_MAGIC):
            return None  # _set_fmu_state then logs that this is not a state of this FMU
        return _StateUnpickler(io.BytesIO(data[len(_STATE_MAGIC):])).load()

    # ---- model description ---------------------------------------------------------------

    def _check_stamp(self) -> None:
        """Refuse to run under a package whose variables differ from those the FMU was built with."""
        stamp = Path(self.resources or "") / STAMP_FILE
        if not self.resources or not stamp.is_file():
            return
        built = json.loads(stamp.read_text("utf-8"))
        if built.get("fingerprint") != fingerprint(self.fmu):
            raise RuntimeError(
                f"{self.fmu}.fmu was built with biso_cosim {built.get('version')} whose variables differ from "
                f"those of the installed biso_cosim {__version__}: rebuild it with `biso-cosim fmu build`")

    def to_xml(self, model_options: dict[str, str] | None = None) -> Element:
        root = super().to_xml(model_options or {})
        cs = root.find("CoSimulation")
        for option, value in self.fmi_options.items():
            cs.set(option, str(bool(value)).lower())
        # UnitDefinitions go right after the CoSimulation element (FMI 2.0 schema order)
        units = Element("UnitDefinitions")
        used = {v.unit for v in self.specs if v.unit}
        for name in sorted(used):
            exponents, factor, offset, displays = UNITS[name]
            unit = SubElement(units, "Unit", name=name)
            base = SubElement(unit, "BaseUnit", {k: str(e) for k, e in exponents.items()})
            if factor != 1.0:
                base.set("factor", repr(factor))
            if offset != 0.0:
                base.set("offset", repr(offset))
            for display, (d_factor, d_offset) in displays.items():
                du = SubElement(unit, "DisplayUnit", name=display, factor=repr(d_factor))
                if d_offset:
                    du.set("offset", repr(d_offset))
        root.insert(list(root).index(cs) + 1, units)
        for node in root.find("ModelVariables"):
            v = self.spec[node.get("name")]
            typed = node[0]
            if v.type == "Real":
                if typed.get("start") is not None:
                    typed.set("start", _xml_double(v.start))  # all 17 digits, NaN for None
                if v.unit:
                    typed.set("unit", v.unit)
                if v.display_unit:
                    typed.set("displayUnit", v.display_unit)
            if v.min is not None:
                typed.set("min", _xml_double(v.min) if v.type == "Real" else str(int(v.min)))
            if v.max is not None:
                typed.set("max", _xml_double(v.max) if v.type == "Real" else str(int(v.max)))
        return root


def _xml_double(x: float) -> str:
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "INF" if x > 0 else "-INF"
    return repr(float(x))


class _StateUnpickler(pickle.Unpickler):
    """Loads only what our states hold: builtins containers, numpy arrays, our records."""

    def find_class(self, module: str, name: str):
        if module.split(".")[0] == "numpy" or module.startswith("biso_cosim."):
            return super().find_class(module, name)
        if module == "builtins" and name in {"set", "frozenset", "complex", "slice", "range"}:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"FMU state refers to {module}.{name}, which a state never holds")


def hold(namespace: dict) -> None:
    """Add one reference to a slave script's module namespace; the script calls
    ``hold(globals())`` at its top level.

    pythonfmu 0.7's loader (``findClass`` in its fmi2.cpp) re-executes the slave script in
    the module's namespace at every ``fmi2Instantiate`` and then releases that namespace
    once more than it acquired it. A script whose namespace nothing else references (ours
    define no functions) would lose its module dictionary at the first instantiation and the
    second one would fail or crash. The re-execution also runs this call, so each
    instantiation adds the reference it takes away.
    """
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(namespace))


def slave_class(base: type[BisoSlave]):
    """Decorator for the slave scripts: ``@slave_class(EstimatorSlave)`` above ``class
    BisoEstimator(Fmi2Slave):`` makes that name the package's slave class.

    The script keeps the literal ``class Name(Fmi2Slave):`` that pythonfmu's loaders look for
    (a regular expression on the text in older releases; in 0.7 the class whose MRO holds
    ``Fmi2Slave`` deepest among the names the script defines), while the class itself lives
    in the package: a slave script stays free of numba caches and of module names shared
    between FMUs (docs/design.md §10).
    """

    def decorate(stub: type) -> type:
        return type(stub.__name__, (base,), {"__module__": stub.__module__, "__doc__": stub.__doc__ or base.__doc__})

    return decorate
