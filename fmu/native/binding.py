"""The C estimators from Python: compile the library with the system C compiler and call it
through ctypes, with the interface of the Python estimators (``update``, ``set_params``,
``reset``, ``get_state``/``set_state``).

This is how the tests bind the C code to the numba kernels and how the benchmark times it;
the FMUs link the same sources directly. ``compile_estimators(out_dir)`` builds
``libbiso_estimators.so`` (``.dylib`` on macOS) from ``estimator_sources()`` with
``C_FLAGS``; ``NativeLibrary(path)`` loads it; ``NativeEstimator(lib, name, fs_hz,
**params)`` takes the parameters ``make_estimator`` takes.
"""

from __future__ import annotations

import ctypes
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from biso_cosim.fmu.native import C_FLAGS, INCLUDE_DIR, estimator_sources

__all__ = ["CompilerNotFound", "find_compiler", "compile_estimators", "NativeLibrary", "NativeEstimator", "ParamInfo"]


class CompilerNotFound(RuntimeError):
    """No C compiler on this machine."""


def find_compiler() -> str:
    """The C compiler: $CC, else cc, gcc or clang on the PATH (raises CompilerNotFound)."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        path = shutil.which(name)
        if path:
            return path
    raise CompilerNotFound(f"no C compiler found (looked for {', '.join(candidates)}): install one "
                           "(Debian/Ubuntu: apt-get install gcc; macOS: xcode-select --install) or set CC")


def compile_estimators(out_dir: str | Path, *, cc: str | None = None) -> Path:
    """Build the estimators' shared library into ``out_dir``; returns its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    suffix = ".dylib" if sys.platform == "darwin" else ".so"
    target = out_dir / f"libbiso_estimators{suffix}"
    cmd = [cc or find_compiler(), *C_FLAGS, "-fPIC", "-shared", "-I", str(INCLUDE_DIR),
           *map(str, estimator_sources()), "-o", str(target), "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"compiling the C estimators failed ({' '.join(cmd)}):\n{done.stderr}")
    return target


def _header_sizes() -> dict[str, int]:
    """BISO_EST_MAX_* of the generated header (the layout of ``biso_est``)."""
    text = (INCLUDE_DIR / "biso_estimators_gen.h").read_text(encoding="utf-8")
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"#define BISO_EST_MAX_(\w+) (\d+)", text)}


class _Param(ctypes.Structure):
    _fields_ = [("name", ctypes.c_char_p), ("symbol", ctypes.c_char_p), ("unit", ctypes.c_char_p),
                ("fmi_unit", ctypes.c_char_p), ("doc", ctypes.c_char_p), ("source", ctypes.c_char_p),
                ("type", ctypes.c_int), ("optional", ctypes.c_int), ("tunable", ctypes.c_int),
                ("default_value", ctypes.c_double), ("min", ctypes.c_double), ("max", ctypes.c_double),
                ("min_open", ctypes.c_int), ("choices", ctypes.POINTER(ctypes.c_char_p)), ("n_choices", ctypes.c_int)]


class _Input(ctypes.Structure):
    _fields_ = [("gyro_b", ctypes.c_double * 3), ("accel_b", ctypes.c_double * 3), ("mag_b", ctypes.c_double * 3),
                ("speed_mps", ctypes.c_double), ("velocity_enu_mps", ctypes.c_double * 3),
                ("has_velocity", ctypes.c_int), ("imu_flags", ctypes.c_int64)]


class _Output(ctypes.Structure):
    _fields_ = [("q_wb", ctypes.c_double * 4), ("flags", ctypes.c_int64), ("gyro_bias_b", ctypes.c_double * 3)]


TYPES = ("REAL", "INTEGER", "BOOLEAN", "CHOICE")


class ParamInfo:
    """One entry of a kind's C parameter table (``biso_est_param``), as Python values."""

    def __init__(self, p: _Param):
        self.name = p.name.decode()
        self.symbol, self.unit, self.fmi_unit = p.symbol.decode(), p.unit.decode(), p.fmi_unit.decode()
        self.doc, self.source = p.doc.decode(), p.source.decode()
        self.type = TYPES[p.type]
        self.optional, self.tunable, self.min_open = bool(p.optional), bool(p.tunable), bool(p.min_open)
        self.default, self.min, self.max = p.default_value, p.min, p.max
        self.choices = tuple(p.choices[i].decode() for i in range(p.n_choices))

    @property
    def field(self) -> str:
        """The Python parameter this entry belongs to (``speed_point_b_m[2]`` → ``speed_point_b_m``)."""
        return self.name.split("[", 1)[0]

    def __repr__(self) -> str:
        return f"ParamInfo({self.name!r}, {self.type}, default={self.default!r})"


_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_INT64_P = ctypes.POINTER(ctypes.c_int64)


class NativeLibrary:
    """The compiled library, with the prototypes of ``biso_estimators.h``."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.lib = lib = ctypes.CDLL(str(self.path))
        sizes = _header_sizes()

        class Est(ctypes.Structure):
            _fields_ = [("kind", ctypes.c_int), ("fs_hz", ctypes.c_double),
                        ("params", ctypes.c_double * sizes["PARAMS"]), ("coef", ctypes.c_double * sizes["COEF"]),
                        ("state", ctypes.c_double * sizes["STATE"])]

        self.Est = Est
        est_p = ctypes.POINTER(Est)
        sig = {
            "biso_est_kind": (ctypes.c_int, [ctypes.c_char_p]),
            "biso_est_kind_name": (ctypes.c_char_p, [ctypes.c_int]),
            "biso_est_kind_summary": (ctypes.c_char_p, [ctypes.c_int]),
            "biso_est_inputs": (ctypes.c_int, [ctypes.c_int]),
            "biso_est_estimates_bias": (ctypes.c_int, [ctypes.c_int]),
            "biso_est_param_count": (ctypes.c_int, [ctypes.c_int]),
            "biso_est_param_at": (ctypes.POINTER(_Param), [ctypes.c_int, ctypes.c_int]),
            "biso_est_param_find": (ctypes.c_int, [ctypes.c_int, ctypes.c_char_p]),
            "biso_est_choice_find": (ctypes.c_int, [ctypes.POINTER(_Param), ctypes.c_char_p]),
            "biso_est_params_default": (None, [ctypes.c_int, _DOUBLE_P]),
            "biso_est_state_size": (ctypes.c_int, [ctypes.c_int]),
            "biso_est_coef_size": (ctypes.c_int, [ctypes.c_int]),
            "biso_est_check_param": (ctypes.c_int, [ctypes.c_int, ctypes.c_int, ctypes.c_double, ctypes.c_char_p,
                                                    ctypes.c_size_t]),
            "biso_est_init": (ctypes.c_int, [est_p, ctypes.c_int, ctypes.c_double, _DOUBLE_P, ctypes.c_char_p,
                                             ctypes.c_size_t]),
            "biso_est_set_params": (ctypes.c_int, [est_p, _DOUBLE_P, ctypes.c_char_p, ctypes.c_size_t]),
            "biso_est_reset": (ctypes.c_int, [est_p, _DOUBLE_P, ctypes.c_char_p, ctypes.c_size_t]),
            "biso_est_get_state": (None, [est_p, _DOUBLE_P]),
            "biso_est_set_state": (None, [est_p, _DOUBLE_P]),
            "biso_est_initialized": (ctypes.c_int, [est_p]),
            "biso_est_peek": (None, [est_p, ctypes.POINTER(_Output)]),
            "biso_est_update": (None, [est_p, ctypes.POINTER(_Input), ctypes.POINTER(_Output)]),
            "biso_est_run": (None, [est_p, ctypes.c_size_t, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P,
                                    _INT64_P, _DOUBLE_P, _INT64_P, _DOUBLE_P]),
        }
        for name, (restype, argtypes) in sig.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = restype, argtypes

    def kind(self, name: str) -> int:
        k = self.lib.biso_est_kind(name.encode())
        if k < 0:
            raise ValueError(f"the C library has no estimator {name!r}")
        return k

    def params(self, kind: int) -> list[ParamInfo]:
        """The kind's parameter table."""
        return [ParamInfo(self.lib.biso_est_param_at(kind, i).contents)
                for i in range(self.lib.biso_est_param_count(kind))]

    def check_param(self, kind: int, index: int, value: float) -> str | None:
        """None if ``value`` is allowed on its own, else the C library's message."""
        buf = ctypes.create_string_buffer(512)
        return None if self.lib.biso_est_check_param(kind, index, value, buf, 512) == 0 else buf.value.decode()


def _ptr(a: np.ndarray | None, ctype=ctypes.c_double):
    return None if a is None else a.ctypes.data_as(ctypes.POINTER(ctype))


class NativeEstimator:
    """One C estimator instance with the Python estimators' interface.

    ``params`` are those of ``make_estimator(name, fs_hz, **params)`` (strings, booleans,
    None, 3-tuples), converted to the C parameter vector by the C library's own table.
    Errors of the C library raise ``ValueError`` with its message.
    """

    def __init__(self, lib: NativeLibrary, name: str, fs_hz: float, **params: Any):
        self.lib, self.method = lib, name
        self.kind = lib.kind(name)
        self.table = lib.params(self.kind)
        self._index = {p.name: i for i, p in enumerate(self.table)}
        self._est = lib.Est()
        self.values = np.array([p.default for p in self.table], dtype=np.float64)
        self._apply(params)
        buf = ctypes.create_string_buffer(512)
        if lib.lib.biso_est_init(ctypes.byref(self._est), self.kind, float(fs_hz), _ptr(self.values), buf, 512):
            raise ValueError(buf.value.decode())
        self.fs_hz = float(fs_hz)

    @property
    def estimates_bias(self) -> bool:
        return bool(self.lib.lib.biso_est_estimates_bias(self.kind))

    def _apply(self, params: dict[str, Any]) -> None:
        """Write Python parameter values into ``self.values``."""
        for name, value in params.items():
            if name in self._index:
                entries = [(self._index[name], value)]
            elif f"{name}[1]" in self._index:
                entries = [(self._index[f"{name}[{i + 1}]"], value[i]) for i in range(3)]
            else:
                raise TypeError(f"the C {self.method} has no parameter {name!r}")
            for i, v in entries:
                info = self.table[i]
                if v is None:
                    v = math.nan
                elif info.type == "CHOICE":
                    v = info.choices.index(v) if v in info.choices else -1.0
                elif isinstance(v, (tuple, list, np.ndarray)):
                    raise TypeError(f"{name}: the C estimators take one value (no per-channel form)")
                self.values[i] = float(v)

    @property
    def coefficients(self) -> np.ndarray:
        return np.array(self._est.coef[:self.lib.lib.biso_est_coef_size(self.kind)])

    def set_params(self, **changes: Any) -> None:
        """Retune (``biso_est_set_params``); an invalid change raises and changes nothing."""
        values = self.values.copy()
        try:
            self._apply(changes)
            buf = ctypes.create_string_buffer(512)
            if self.lib.lib.biso_est_set_params(ctypes.byref(self._est), _ptr(self.values), buf, 512):
                raise ValueError(buf.value.decode())
        except Exception:
            self.values = values
            raise

    def reset(self, q0: Any = None) -> None:
        q = None if q0 is None else np.ascontiguousarray(q0, dtype=np.float64)
        buf = ctypes.create_string_buffer(512)
        if self.lib.lib.biso_est_reset(ctypes.byref(self._est), _ptr(q), buf, 512):
            raise ValueError(buf.value.decode())

    def get_state(self) -> np.ndarray:
        """The whole state: the values of the Python estimator's ``get_state()``."""
        out = np.empty(self.lib.lib.biso_est_state_size(self.kind))
        self.lib.lib.biso_est_get_state(ctypes.byref(self._est), _ptr(out))
        return out

    def set_state(self, values: Any) -> None:
        v = np.ascontiguousarray(values, dtype=np.float64)
        if v.shape != (self.lib.lib.biso_est_state_size(self.kind),):
            raise ValueError(f"state must have shape ({self.lib.lib.biso_est_state_size(self.kind)},), got {v.shape}")
        self.lib.lib.biso_est_set_state(ctypes.byref(self._est), _ptr(v))

    def peek(self) -> tuple[np.ndarray, int, np.ndarray]:
        out = _Output()
        self.lib.lib.biso_est_peek(ctypes.byref(self._est), ctypes.byref(out))
        return np.array(out.q_wb), int(out.flags), np.array(out.gyro_bias_b)

    def update(self, gyro_b, accel_b, mag_b, *, speed_mps=None, velocity_enu_mps=None, imu_flags=None):
        """k samples through ``biso_est_run``: returns ``Estimate(q_wb, flags, gyro_bias_b)``."""
        from biso_cosim.estimators import Estimate

        g, a, m = (np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3) for x in (gyro_b, accel_b, mag_b))
        k = g.shape[0]
        speed = None if speed_mps is None else np.ascontiguousarray(speed_mps, dtype=np.float64).reshape(k)
        vel = None if velocity_enu_mps is None else np.ascontiguousarray(velocity_enu_mps, dtype=np.float64).reshape(k, 3)
        flags_in = None if imu_flags is None else np.ascontiguousarray(imu_flags, dtype=np.int64).reshape(k)
        q = np.empty((k, 4))
        flags = np.empty(k, dtype=np.int64)
        bias = np.empty((k, 3))
        self.lib.lib.biso_est_run(ctypes.byref(self._est), k, _ptr(g), _ptr(a), _ptr(m), _ptr(speed), _ptr(vel),
                                  _ptr(flags_in, ctypes.c_int64), _ptr(q), _ptr(flags, ctypes.c_int64), _ptr(bias))
        return Estimate(q, flags, bias if self.estimates_bias else None)

    def update_one(self, gyro_b, accel_b, mag_b, *, speed_mps=math.nan, imu_flags=0):
        """One sample through ``biso_est_update`` (the FMU's call): (q_wb, flags, gyro_bias_b)."""
        inp, out = _Input(), _Output()
        inp.gyro_b[:], inp.accel_b[:], inp.mag_b[:] = gyro_b, accel_b, mag_b
        inp.speed_mps, inp.imu_flags, inp.has_velocity = speed_mps, imu_flags, 0
        self.lib.lib.biso_est_update(ctypes.byref(self._est), ctypes.byref(inp), ctypes.byref(out))
        return np.array(out.q_wb), int(out.flags), np.array(out.gyro_bias_b)
