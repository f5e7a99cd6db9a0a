"""The Python side of the C shell that embeds CPython in ``BisoVehicle``
(``native/src/python``): C calls ``instantiate`` once per FMI instance and then the
methods of the `Bridge` it returns, with the FMI call's arguments as numbers (value
references and values by address). A method returns an FMI status (or a handle or size)
and never raises; the slave (``_slave.BisoSlave``) holds the semantics.

Log messages go back through a C function of the shell,
``void log(void *instance, int status, const char *category, const char *message)``, whose
address C passes at instantiation; the shell forwards them to the host's logger.
"""

from __future__ import annotations

import ctypes
import math
import os
from urllib.parse import unquote, urlparse
from pathlib import Path
from typing import Any

from biso_cosim.fmu._slave import ERROR, OK, WARNING, _describe

__all__ = ["Bridge", "instantiate", "SLAVES"]

SLAVES = {"BisoVehicle": ("biso_cosim.fmu.vehicle", "VehicleSlave")}
"""The Python slave class of each Python-based FMU: (module, class)."""

_LOG = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)
_CATEGORY = {OK: b"logEvents", WARNING: b"logStatusWarning"}  # anything else: logStatusError

# kinds of value arrays (biso_python.h BP_*): FMI type, C element type
_KINDS = {0: ("Real", ctypes.c_double), 1: ("Integer", ctypes.c_int32), 2: ("Boolean", ctypes.c_int32),
          3: ("Boolean", ctypes.c_bool), 4: ("String", ctypes.c_char_p)}


def _resources(location: str) -> Path | None:
    """The resources folder from FMI 2.0's URI (``file:///...``) or FMI 3.0's path."""
    if not location:
        return None
    if location.startswith("file:"):
        path = unquote(urlparse(location).path)  # file:///C:/x on Windows: drop the slash before the drive
        return Path(path[1:] if os.name == "nt" and path[2:3] == ":" else path)
    return Path(location)


class Bridge:
    """One FMI instance: the slave, the logger back into C, the FMU states the host holds
    (by handle) and the strings last handed out (valid until the next call)."""

    def __init__(self, fmu: str, instance_name: str, resources: str, fmi_version: int, log_address: int,
                 context: int, logging_on: int):
        import importlib

        self.fmi = f"fmi{fmi_version}"
        self.fmi_version = fmi_version
        self.logging_on = bool(logging_on)
        self._c_log = _LOG(log_address)
        self._context = context
        module, name = SLAVES[fmu]
        cls = getattr(importlib.import_module(module), name)
        self.slave = cls(instance_name, self._log, _resources(resources))
        self.states: dict[int, Any] = {}
        self._next_handle = 1
        self._strings: list[ctypes.Array] = []

    def _log(self, status: int, message: str) -> None:
        if self._c_log is None or (status == OK and not self.logging_on):
            return
        self._c_log(self._context, status, _CATEGORY.get(status, b"logStatusError"), message.encode("utf-8"))

    # ---- modes ---------------------------------------------------------------------------

    def set_debug_logging(self, on: int) -> int:
        self.logging_on = bool(on)
        return OK

    def setup_experiment(self, start_time: float) -> int:
        return self.slave.setup_experiment(f"{self.fmi}SetupExperiment", start_time)

    def enter_initialization(self, start_time: float) -> int:
        """``start_time``: FMI 3.0's start time; NaN for FMI 2.0 (SetupExperiment gave it)."""
        return self.slave.enter_initialization(f"{self.fmi}EnterInitializationMode",
                                               None if math.isnan(start_time) else start_time)

    def exit_initialization(self) -> int:
        return self.slave.exit_initialization(f"{self.fmi}ExitInitializationMode")

    def do_step(self, t: float, h: float, time_address: int) -> int:
        status = self.slave.do_step(f"{self.fmi}DoStep", t, h)
        ctypes.c_double.from_address(time_address).value = self.slave.time
        return status

    def terminate(self) -> int:
        return self.slave.terminate(f"{self.fmi}Terminate")

    def reset(self) -> int:
        return self.slave.reset(f"{self.fmi}Reset")

    def free(self) -> int:
        """FreeInstance: the model, the states and the logger go (the shell's code may be
        unloaded after this)."""
        try:
            self.slave.free()
        finally:
            self.states.clear()
            self._strings.clear()
            self._c_log = None
        return OK

    # ---- values --------------------------------------------------------------------------

    def _function(self, verb: str, type_name: str) -> str:
        if self.fmi_version == 3:
            type_name = {"Real": "Float64", "Integer": "Int32"}.get(type_name, type_name)
        return f"{self.fmi}{verb}{type_name}"

    def set(self, kind: int, vr_address: int, n: int, value_address: int) -> int:
        type_name, ctype = _KINDS[kind]
        function = self._function("Set", type_name)
        if n == 0:
            return OK
        vrs = list((ctypes.c_uint32 * n).from_address(vr_address))
        raw = list((ctype * n).from_address(value_address))
        if type_name == "String":
            if any(x is None for x in raw):
                self.slave.error(f"{function}: a NULL string")
                return ERROR
            raw = [x.decode("utf-8") for x in raw]
        if self.fmi_version == 3 and 0 in vrs:
            self.slave.error(f"{function}: time (value reference 0) is the independent variable and cannot be set")
            return ERROR
        return self.slave.set(function, type_name, vrs, raw)

    def get(self, kind: int, vr_address: int, n: int, value_address: int) -> int:
        type_name, ctype = _KINDS[kind]
        function = self._function("Get", type_name)
        if n == 0:
            return OK
        vrs = list((ctypes.c_uint32 * n).from_address(vr_address))
        # FMI 3.0's value reference 0 is time, the independent variable (not a slave variable)
        is_time = [self.fmi_version == 3 and type_name == "Real" and vr == 0 for vr in vrs]
        others = [vr for vr, t in zip(vrs, is_time) if not t]
        got: list[Any] = [None] * len(others)
        status = self.slave.get(function, type_name, others, got) if others else OK
        rest = iter(got)
        out = [self.slave.time if t else next(rest) for t in is_time]
        target = (ctype * n).from_address(value_address)
        if type_name == "String":
            self._strings = [ctypes.create_string_buffer(("" if x is None else x).encode("utf-8")) for x in out]
            pointers = (ctypes.c_void_p * n).from_address(value_address)
            for i, buf in enumerate(self._strings):
                pointers[i] = ctypes.addressof(buf)
            return status
        for i, x in enumerate(out):
            if x is not None:
                target[i] = x
        return status

    # ---- FMU state -----------------------------------------------------------------------

    def get_state(self, handle: int) -> int:
        """The instance's state under ``handle`` (0: a new handle); returns the handle, 0 on failure."""
        try:
            state = self.slave.get_state()
        except Exception as exc:  # noqa: BLE001
            self.slave.error(f"{self.fmi}GetFMUstate: {_describe(exc)}")
            return 0
        if handle == 0:
            handle, self._next_handle = self._next_handle, self._next_handle + 1
        self.states[handle] = state
        return handle

    def set_state(self, handle: int) -> int:
        if handle not in self.states:
            self.slave.error(f"{self.fmi}SetFMUstate: no state {handle} (freed, or of another instance)")
            return ERROR
        state = self.states[handle]
        return self.slave.set_state(f"{self.fmi}SetFMUstate", state.state if isinstance(state, _Serialized) else state)

    def free_state(self, handle: int) -> int:
        self.states.pop(handle, None)
        return OK

    def state_size(self, handle: int) -> int:
        """Size of the serialized state, -1 on failure."""
        if handle not in self.states:
            self.slave.error(f"{self.fmi}SerializedFMUstateSize: no state {handle}")
            return -1
        return len(self._serialized(handle))

    def _serialized(self, handle: int) -> bytes:
        item = self.states[handle]
        if isinstance(item, _Serialized):
            return item.data
        data = self.slave.serialize(item)
        self.states[handle] = _Serialized(item, data)
        return data

    def serialize(self, handle: int, address: int, size: int) -> int:
        if handle not in self.states:
            self.slave.error(f"{self.fmi}SerializeFMUstate: no state {handle}")
            return ERROR
        data = self._serialized(handle)
        if size < len(data):
            self.slave.error(f"{self.fmi}SerializeFMUstate: the buffer has {size} bytes, the state needs {len(data)}")
            return ERROR
        ctypes.memmove(address, data, len(data))
        return OK

    def deserialize(self, address: int, size: int) -> int:
        """A new handle holding the state in the bytes at ``address``; 0 on failure."""
        try:
            state = self.slave.deserialize(ctypes.string_at(address, size))
        except Exception as exc:  # noqa: BLE001
            self.slave.error(f"{self.fmi}DeserializeFMUstate: {_describe(exc)}; nothing changed")
            return 0
        handle, self._next_handle = self._next_handle, self._next_handle + 1
        self.states[handle] = state
        return handle


class _Serialized:
    """A state with its serialized bytes (computed once for Size and Serialize)."""

    def __init__(self, state: Any, data: bytes):
        self.state, self.data = state, data


def instantiate(fmu: str, instance_name: str, resources: str, fmi_version: int, log_address: int, context: int,
                logging_on: int) -> Bridge:
    """A `Bridge` for one FMI instance; raises (the C shell logs the message) when the slave
    cannot be made, e.g. an FMU built for other variables."""
    return Bridge(fmu, instance_name, resources, fmi_version, log_address, context, logging_on)
