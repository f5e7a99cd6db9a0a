"""A small FMPy master for one FMU instance (FMI 2.0 or 3.0 co-simulation), by variable name,
with its log kept.

Used by the tests, the demonstrations and ``benchmarks/fmu_overhead.py``; any co-simulation
FMU works, not only ours.

>>> with FmuInstance("BisoEstimator-fmi3.fmu", start_values={"estimator": "biso_plus"}) as fmu:
...     fmu.set({"gyro_s.x": 0.01, "accel_s.z": 9.81})
...     ok = fmu.step(0.005)                 # False: the FMU refused the step (see fmu.log)
...     fmu.get(["estimate.roll", "estimate.flags"])
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping

__all__ = ["FmuInstance", "FmuCallError", "STATUS_NAMES"]

STATUS_NAMES = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}


class FmuCallError(RuntimeError):
    """An FMI call returned an error status; ``messages`` holds what the FMU logged for it."""

    def __init__(self, call: str, messages: list[str]):
        super().__init__(f"{call} failed: {' | '.join(messages) or 'no message logged'}")
        self.call = call
        self.messages = messages


class FmuInstance:
    """One instance of a co-simulation FMU, instantiated and initialized.

    Args:
        path: the .fmu file, or the directory it was extracted to (shared between instances).
        instance_name: FMI instance name (several instances may load in one process).
        start_values: {variable name: value} set in initialization mode (parameters, inputs).
        start_time, stop_time: of the experiment.

    ``log`` collects (status name, message) of every message the FMU logged. A refused
    setter or initialization raises `FmuCallError` with the FMU's messages.
    """

    def __init__(self, path: str | Path, instance_name: str = "instance",
                 start_values: Mapping[str, Any] | None = None, start_time: float = 0.0,
                 stop_time: float | None = None):
        from fmpy import extract, read_model_description

        path = Path(path)
        self._tmp = None
        if path.is_dir():
            unzipped = path
        else:
            self._tmp = tempfile.mkdtemp(prefix="biso_fmu_run_")
            unzipped = Path(extract(str(path), unzipdir=self._tmp))
        self.model = read_model_description(str(unzipped))
        self.fmi_version = int(self.model.fmiVersion.split(".")[0])
        self.variables = {v.name: v for v in self.model.modelVariables}
        self.log: list[tuple[str, str]] = []
        self.time = float(start_time)
        self.fmu = None
        identifier = self.model.coSimulation.modelIdentifier
        try:
            if self.fmi_version == 3:
                self._instantiate3(unzipped, identifier, instance_name)
                self._call("enterInitializationMode", self.fmu.enterInitializationMode, startTime=start_time,
                           stopTime=stop_time)
            else:
                self._instantiate2(unzipped, identifier, instance_name)
                self._call("setupExperiment", self.fmu.setupExperiment, startTime=start_time, stopTime=stop_time)
                self._call("enterInitializationMode", self.fmu.enterInitializationMode)
            if start_values:
                self.set(start_values)
            self._call("exitInitializationMode", self.fmu.exitInitializationMode)
            if self.fmi_version == 3:
                self._call("enterStepMode", self.fmu.enterStepMode)
        except Exception:
            self.close()
            raise

    def _logger(self, status: int, message: bytes) -> None:
        # FMI 2.0 messages are printf formats (FMPy passes them unformatted): "%%" is "%"
        text = message.decode("utf-8", "replace")
        if self.fmi_version == 2:
            text = text.replace("%%", "%")
        self.log.append((STATUS_NAMES.get(status, str(status)), text))

    def _instantiate2(self, unzipped: Path, identifier: str, name: str) -> None:
        from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

        def logger(env, instance, status, category, message):
            self._logger(status, message)

        libc = ctypes.CDLL(None)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        # the C library's own calloc and free by address (a ctypes function object would return
        # an int and cut the pointer)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(ctypes.cast(libc.calloc, ctypes.c_void_p).value)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(ctypes.cast(libc.free, ctypes.c_void_p).value)
        self._callbacks = callbacks  # keep the ctypes callbacks alive
        fmu = FMU2Slave(guid=self.model.guid, unzipDirectory=str(unzipped), modelIdentifier=identifier,
                        instanceName=name)
        try:
            fmu.instantiate(callbacks=callbacks, loggingOn=True)
        except Exception:  # FMPy raises a bare Exception; the reason is in the log
            fmu.freeLibrary()
            raise FmuCallError("fmi2Instantiate", self.errors()) from None
        self.fmu = fmu

    def _instantiate3(self, unzipped: Path, identifier: str, name: str) -> None:
        from fmpy.fmi3 import FMU3Slave

        def log_message(env, status, category, message):
            self._logger(status, message)

        fmu = FMU3Slave(guid=self.model.guid, unzipDirectory=str(unzipped), modelIdentifier=identifier,
                        instanceName=name)
        try:
            fmu.instantiate(loggingOn=True, logMessage=log_message)
        except Exception:
            fmu.freeLibrary()
            raise FmuCallError("fmi3InstantiateCoSimulation", self.errors()) from None
        self.fmu = fmu

    def _call(self, name: str, function, *args, **kwargs):
        from fmpy.fmi1 import FMICallException

        before = len(self.log)
        try:
            return function(*args, **kwargs)
        except FMICallException:
            raise FmuCallError(name, [m for s, m in self.log[before:] if s in ("error", "fatal")]) from None

    # ---- values ------------------------------------------------------------------------

    def _kind(self, v) -> str:
        return {"Float64": "Real", "Int32": "Integer", "Enumeration": "Integer"}.get(v.type, v.type)

    def set(self, values: Mapping[str, Any]) -> None:
        """Set variables by name (Real, Integer, Boolean, String); `FmuCallError` if refused."""
        groups: dict[str, tuple[list[int], list[Any]]] = {}
        for name, value in values.items():
            v = self.variables.get(name)
            if v is None:
                raise KeyError(f"{self.model.modelName} has no variable {name!r}")
            refs, vals = groups.setdefault(self._kind(v), ([], []))
            refs.append(v.valueReference)
            vals.append(value)
        three = self.fmi_version == 3
        for kind, (refs, vals) in groups.items():
            if kind == "Real":
                self._call("set Real", self.fmu.setFloat64 if three else self.fmu.setReal, refs,
                           [float(x) for x in vals])
            elif kind == "Integer":
                self._call("set Integer", self.fmu.setInt32 if three else self.fmu.setInteger, refs,
                           [int(x) for x in vals])
            elif kind == "Boolean":
                self._call("set Boolean", self.fmu.setBoolean, refs, [bool(x) for x in vals])
            else:
                self._call("set String", self.fmu.setString, refs, [str(x) for x in vals])

    def get(self, names: Iterable[str]) -> list[Any]:
        """Values of variables by name, in the order given."""
        names = list(names)
        three = self.fmi_version == 3
        getters = {"Real": self.fmu.getFloat64 if three else self.fmu.getReal,
                   "Integer": self.fmu.getInt32 if three else self.fmu.getInteger,
                   "Boolean": self.fmu.getBoolean, "String": self.fmu.getString}
        by_type: dict[str, list[int]] = {}
        for name in names:
            try:
                v = self.variables[name]
            except KeyError:
                raise KeyError(f"{self.model.modelName} has no variable {name!r}") from None
            by_type.setdefault(self._kind(v), []).append(v.valueReference)
        out: dict[int, Any] = {}
        for kind, refs in by_type.items():
            for ref, value in zip(refs, getters[kind](refs)):
                out[ref] = value.decode() if isinstance(value, bytes) else value
        return [out[self.variables[n].valueReference] for n in names]

    # ---- stepping ----------------------------------------------------------------------

    def step(self, step_size: float) -> bool:
        """One DoStep from the current time; False when the FMU refused it (the reason is
        in ``log``); the time advances only on success."""
        from fmpy.fmi1 import FMICallException

        try:
            self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=step_size)
        except FMICallException:
            return False
        self.time += step_size
        return True

    def reset(self, start_values: Mapping[str, Any] | None = None) -> None:
        """Reset and initialize again (parameters back to their start values, then ``start_values``)."""
        self._call("reset", self.fmu.reset)
        self.time = 0.0
        if self.fmi_version == 3:
            self._call("enterInitializationMode", self.fmu.enterInitializationMode, startTime=0.0)
        else:
            self._call("setupExperiment", self.fmu.setupExperiment, startTime=0.0)
            self._call("enterInitializationMode", self.fmu.enterInitializationMode)
        if start_values:
            self.set(start_values)
        self._call("exitInitializationMode", self.fmu.exitInitializationMode)
        if self.fmi_version == 3:
            self._call("enterStepMode", self.fmu.enterStepMode)

    # ---- FMU state ---------------------------------------------------------------------

    def get_state(self) -> Any:
        """The FMU's whole state (GetFMUstate), with the host's time."""
        return (self._call("getFMUstate", self.fmu.getFMUState if self.fmi_version == 3 else self.fmu.getFMUstate),
                self.time)

    def set_state(self, state: Any) -> None:
        handle, self.time = state
        self._call("setFMUstate", self.fmu.setFMUState if self.fmi_version == 3 else self.fmu.setFMUstate, handle)

    def free_state(self, state: Any) -> None:
        self._call("freeFMUstate", self.fmu.freeFMUState if self.fmi_version == 3 else self.fmu.freeFMUstate,
                   state[0])

    def serialize(self, state: Any) -> tuple[bytes, float]:
        fn = self.fmu.serializeFMUState if self.fmi_version == 3 else self.fmu.serializeFMUstate
        return bytes(self._call("serializeFMUstate", fn, state[0])), state[1]

    def deserialize(self, data: tuple[bytes, float]) -> Any:
        fn = self.fmu.deserializeFMUState if self.fmi_version == 3 else self.fmu.deSerializeFMUstate
        return self._call("deserializeFMUstate", fn, data[0]), data[1]

    def errors(self) -> list[str]:
        """Messages the FMU logged with status error or fatal."""
        return [m for s, m in self.log if s in ("error", "fatal")]

    def close(self) -> None:
        if self.fmu is not None:
            try:
                self.fmu.terminate()
            except Exception:  # noqa: BLE001 - an instance that never initialized cannot terminate
                pass
            self.fmu.freeInstance()
            self.fmu.freeLibrary()
            self.fmu = None
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __enter__(self) -> "FmuInstance":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
