"""A small FMPy master for one FMU instance, by variable name, with its log kept.

Used by the tests, the demonstrations and ``benchmarks/fmu_overhead.py``; any FMI 2.0
co-simulation FMU works, not only ours.

>>> with FmuInstance("BisoEstimator.fmu", start_values={"estimator": "biso_plus"}) as fmu:
...     fmu.set({"gyro_s.x": 0.01, "accel_s.z": 9.81})
...     ok = fmu.step(0.005)                 # False: the FMU discarded the step (see fmu.log)
...     fmu.get(["estimate.roll", "estimate.flags"])
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping

__all__ = ["FmuInstance", "STATUS_NAMES"]

STATUS_NAMES = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}


class FmuInstance:
    """One instance of an FMI 2.0 co-simulation FMU, instantiated and initialized.

    Args:
        path: the .fmu file, or the directory it was extracted to (shared between instances).
        instance_name: FMI instance name (several instances may load in one process).
        start_values: {variable name: value} set before initialization (parameters, inputs).
        start_time, stop_time: passed to fmi2SetupExperiment.

    ``log`` collects (status name, message) of every message the FMU logged.
    """

    def __init__(self, path: str | Path, instance_name: str = "instance",
                 start_values: Mapping[str, Any] | None = None, start_time: float = 0.0,
                 stop_time: float | None = None):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE

        path = Path(path)
        self._tmp = None
        if path.is_dir():
            unzipped = path
        else:
            self._tmp = tempfile.mkdtemp(prefix="biso_fmu_run_")
            unzipped = Path(extract(str(path), unzipdir=self._tmp))
        self.model = read_model_description(str(unzipped))
        self.variables = {v.name: v for v in self.model.modelVariables}
        self.log: list[tuple[str, str]] = []

        def logger(env, instance, status, category, message):
            # FMI messages are printf formats; ours carry no arguments, only "%%" for "%". FMPy's
            # native formatting proxy keeps one logger per process, so it is not used here.
            text = message.decode("utf-8", "replace").replace("%%", "%")
            self.log.append((STATUS_NAMES.get(status, str(status)), text))

        libc = ctypes.CDLL(None)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(libc.calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(libc.free)
        self._callbacks = callbacks  # keep the ctypes callbacks alive
        self.fmu = FMU2Slave(guid=self.model.guid, unzipDirectory=str(unzipped),
                             modelIdentifier=self.model.coSimulation.modelIdentifier, instanceName=instance_name)
        try:
            self.fmu.instantiate(callbacks=callbacks, loggingOn=True)
        except Exception as exc:  # FMPy raises a bare Exception; the reason is in the log
            self.fmu = None
            self.close()
            raise RuntimeError(f"fmi2Instantiate of {path} failed: {self.log or exc}") from None
        self.time = float(start_time)
        self.fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        self.fmu.enterInitializationMode()
        if start_values:
            self.set(start_values)
        self.fmu.exitInitializationMode()

    # ---- values ------------------------------------------------------------------------

    def _refs(self, names: Iterable[str]) -> dict[str, list[int]]:
        by_type: dict[str, list[int]] = {}
        for name in names:
            try:
                v = self.variables[name]
            except KeyError:
                raise KeyError(f"{self.model.modelName} has no variable {name!r}") from None
            by_type.setdefault(v.type, []).append(v.valueReference)
        return by_type

    def set(self, values: Mapping[str, Any]) -> None:
        """Set variables by name (Real, Integer, Boolean, String)."""
        groups: dict[str, tuple[list[int], list[Any]]] = {}
        for name, value in values.items():
            v = self.variables.get(name)
            if v is None:
                raise KeyError(f"{self.model.modelName} has no variable {name!r}")
            refs, vals = groups.setdefault(v.type, ([], []))
            refs.append(v.valueReference)
            vals.append(value)
        for kind, (refs, vals) in groups.items():
            if kind == "Real":
                self.fmu.setReal(refs, [float(x) for x in vals])
            elif kind in ("Integer", "Enumeration"):
                self.fmu.setInteger(refs, [int(x) for x in vals])
            elif kind == "Boolean":
                self.fmu.setBoolean(refs, [bool(x) for x in vals])
            else:
                self.fmu.setString(refs, [str(x) for x in vals])

    def get(self, names: Iterable[str]) -> list[Any]:
        """Values of variables by name, in the order given."""
        names = list(names)
        out: dict[str, Any] = {}
        getters = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "Boolean": self.fmu.getBoolean,
                   "String": self.fmu.getString}
        for kind, refs in self._refs(names).items():
            for ref, value in zip(refs, getters[kind](refs)):
                out[ref] = value
        return [out[self.variables[n].valueReference] for n in names]

    # ---- stepping ----------------------------------------------------------------------

    def step(self, step_size: float) -> bool:
        """One fmi2DoStep from the current time; False when the FMU discarded or failed it
        (the reason is in ``log``); the time advances only on success."""
        from fmpy.fmi1 import FMICallException

        try:
            self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=step_size)
        except FMICallException:
            return False
        self.time += step_size
        return True

    def reset(self) -> None:
        """fmi2Reset and initialize again (parameters back to their start values)."""
        self.fmu.reset()
        self.time = 0.0
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def errors(self) -> list[str]:
        """Messages the FMU logged with status error or fatal."""
        return [m for s, m in self.log if s in ("error", "fatal")]

    def close(self) -> None:
        if self.fmu is not None:
            self.fmu.terminate()
            self.fmu.freeInstance()
            self.fmu = None
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __enter__(self) -> "FmuInstance":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
