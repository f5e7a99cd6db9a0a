"""The C sensor model as a shared library, called through ctypes: the binding the tests and
the benchmark use to put the C MPU-9250 next to the numba one (the FMUs link the same
sources into their binaries).

>>> lib = SensorLibrary.build("/tmp/biso_native")
>>> chip = lib.sensor(profile="mpu9250", seed=3)
>>> out = chip.simulate(omega_b, specific_force_b, mag_b)     # a structured array of samples
"""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from biso_cosim.fmu.native.compiler import compile_shared
from biso_cosim.fmu.native.constants import REGISTER_FIELDS
from biso_cosim.fmu.native.sources import INCLUDE, SENSOR_SOURCES, write_sensor_data

__all__ = ["SensorLibrary", "NativeSensor", "SAMPLE_DTYPE"]

SAMPLE_DTYPE = np.dtype([("t_s", "f8"), ("gyro_b", "f8", 3), ("accel_b", "f8", 3), ("mag_b", "f8", 3),
                         ("temperature_c", "f8"), ("flags", "i4"), ("words", "i2", 10), ("mag_fresh", "u1"),
                         ("st1", "u1"), ("st2", "u1")], align=True)
"""The layout of ``biso_mpu_sample`` (include/biso_sensor.h)."""


class _Config(ctypes.Structure):
    _fields_ = [("profile", ctypes.c_int), ("seed", ctypes.c_uint64), ("registers", ctypes.c_int * 10),
                ("r_bc", ctypes.c_double * 9), ("input_rate_hz", ctypes.c_double),
                ("hard_iron_ut", ctypes.c_double * 3), ("soft_iron", ctypes.c_double * 9)]


class _Field(ctypes.Structure):
    _fields_ = [("field_enu_ut", ctypes.c_double * 3), ("declination_rad", ctypes.c_double),
                ("inclination_rad", ctypes.c_double), ("horizontal_ut", ctypes.c_double),
                ("total_ut", ctypes.c_double), ("model", ctypes.c_char_p)]


class SensorLibrary:
    """A compiled ``libbiso_sensor`` (the sensor sources and their generated data)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        lib = ctypes.CDLL(str(self.path))
        self._lib = lib
        lib.biso_profile_index.argtypes = [ctypes.c_char_p]
        lib.biso_mpu_setup.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Config), ctypes.c_char_p, ctypes.c_size_t]
        lib.biso_mpu_reset.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.biso_mpu_max_outputs.argtypes = [ctypes.c_void_p]
        lib.biso_mpu_output_rate_hz.argtypes = [ctypes.c_void_p]
        lib.biso_mpu_output_rate_hz.restype = ctypes.c_double
        lib.biso_mpu_input.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        lib.biso_mpu_params_size.restype = ctypes.c_size_t
        lib.biso_mpu_state_size.restype = ctypes.c_size_t
        lib.biso_register_check.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t]
        lib.biso_mounting_matrix.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.biso_decimal_year.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_double), ctypes.c_char_p,
                                          ctypes.c_size_t]
        lib.biso_earth_field_at.argtypes = [ctypes.c_double] * 4 + [ctypes.POINTER(_Field), ctypes.c_char_p,
                                                                    ctypes.c_size_t]
        lib.biso_rotate_into_body.argtypes = [ctypes.c_void_p] * 3
        self.params_size = lib.biso_mpu_params_size()
        self.state_size = lib.biso_mpu_state_size()

    @classmethod
    def build(cls, folder: str | Path, extra_profiles=()) -> "SensorLibrary":
        """Generate the data, compile ``libbiso_sensor.so`` into ``folder`` and load it."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        data = write_sensor_data(folder, extra_profiles)
        out = compile_shared([*SENSOR_SOURCES, data], folder / "libbiso_sensor.so", [INCLUDE], hidden=False)
        return cls(out)

    def sensor(self, **kwargs: Any) -> "NativeSensor":
        return NativeSensor(self, **kwargs)

    # ---- the random generators (rng.h), for the tests -----------------------------------

    def seed_pool(self, entropy: int, child: int) -> np.ndarray:
        """The pool of ``SeedSequence(entropy).spawn(n)[child]``."""
        pool = (ctypes.c_uint32 * 4)()
        self._lib.biso_seed_child_pool(ctypes.c_uint64(entropy), ctypes.c_uint32(child), pool)
        return np.array(pool[:], dtype=np.uint32)

    def generate_state64(self, pool, n_words: int) -> np.ndarray:
        out = (ctypes.c_uint64 * n_words)()
        self._lib.biso_seed_generate_state64((ctypes.c_uint32 * 4)(*map(int, pool)), out, n_words)
        return np.array(out[:], dtype=np.uint64)

    def numpy_draws(self, pool, n: int, kind: str, low: float = 0.0, high: float = 1.0) -> np.ndarray:
        """n draws of ``default_rng`` on a SeedSequence ``pool``: ``raw`` (PCG64 words),
        ``normal`` (standard_normal) or ``uniform`` (uniform(low, high))."""
        g = (ctypes.c_uint64 * 4)()
        self._lib.biso_pcg64_seed(g, (ctypes.c_uint32 * 4)(*map(int, pool)))
        lib = self._lib
        if kind == "raw":
            lib.biso_pcg64_next.restype = ctypes.c_uint64
            return np.array([lib.biso_pcg64_next(g) for _ in range(n)], dtype=np.uint64)
        if kind == "normal":
            lib.biso_np_standard_normal.restype = ctypes.c_double
            return np.array([lib.biso_np_standard_normal(g) for _ in range(n)])
        lib.biso_np_uniform.restype = ctypes.c_double
        lib.biso_np_uniform.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]
        return np.array([lib.biso_np_uniform(g, low, high) for _ in range(n)])

    def xoshiro_normals(self, words, n: int) -> np.ndarray:
        """n draws of the noise stream's normal from the state ``words``."""
        s = (ctypes.c_uint64 * 4)(*map(int, words))
        self._lib.biso_xoshiro_normal.restype = ctypes.c_double
        return np.array([self._lib.biso_xoshiro_normal(s) for _ in range(n)])

    def register_check(self, field: int, value: int) -> str | None:
        """The C check of one register field value: None when allowed, else its message."""
        msg = ctypes.create_string_buffer(512)
        return msg.value.decode() if self._lib.biso_register_check(field, value, msg, 512) else None

    def mounting_matrix(self, q_body_chip) -> np.ndarray:
        q = np.ascontiguousarray(q_body_chip, dtype=np.float64)
        out = np.empty((3, 3))
        self._lib.biso_mounting_matrix(q.ctypes.data, out.ctypes.data)
        return out

    def decimal_year(self, iso_date: str) -> float:
        year, msg = ctypes.c_double(), ctypes.create_string_buffer(256)
        if self._lib.biso_decimal_year(iso_date.encode(), ctypes.byref(year), msg, 256):
            raise ValueError(msg.value.decode())
        return year.value

    def earth_field(self, lat_deg: float, lon_deg: float, alt_m: float, year: float) -> dict[str, Any]:
        f, msg = _Field(), ctypes.create_string_buffer(256)
        if self._lib.biso_earth_field_at(lat_deg, lon_deg, alt_m, year, ctypes.byref(f), msg, 256):
            raise ValueError(msg.value.decode())
        return {"field_enu_ut": np.array(f.field_enu_ut[:]), "declination_rad": f.declination_rad,
                "inclination_rad": f.inclination_rad, "horizontal_ut": f.horizontal_ut, "total_ut": f.total_ut,
                "model": f.model.decode()}

    def rotate_into_body(self, q_wb, v_w) -> np.ndarray:
        q = np.ascontiguousarray(q_wb, dtype=np.float64)
        v = np.ascontiguousarray(v_w, dtype=np.float64)
        out = np.empty(3)
        self._lib.biso_rotate_into_body(q.ctypes.data, v.ctypes.data, out.ctypes.data)
        return out


class NativeSensor:
    """One C MPU-9250 with the arguments of `biso_cosim.sensors.MPU9250` (built-in profiles
    by name; registers as a dict; mounting as a rotation matrix chip -> body)."""

    def __init__(self, lib: SensorLibrary, profile: str = "mpu9250", seed: int = 0,
                 registers: Mapping[str, Any] | None = None, r_bc: Any = None, input_rate_hz: float = 1000.0,
                 hard_iron_ut: Any = None, soft_iron: Any = None):
        from biso_cosim.sensors import Registers

        self.lib = lib
        index = lib._lib.biso_profile_index(profile.encode())
        if index < 0:
            raise ValueError(f"no built-in profile {profile!r} in {lib.path}")
        reg = Registers.coerce(registers)
        cfg = _Config()
        cfg.profile, cfg.seed, cfg.input_rate_hz = index, seed, input_rate_hz
        cfg.registers[:] = [int(getattr(reg, n)) for n in REGISTER_FIELDS]
        cfg.r_bc[:] = np.asarray(np.eye(3) if r_bc is None else r_bc, dtype=np.float64).ravel().tolist()
        cfg.hard_iron_ut[:] = np.zeros(3) if hard_iron_ut is None else list(map(float, hard_iron_ut))
        cfg.soft_iron[:] = np.asarray(np.eye(3) if soft_iron is None else soft_iron, dtype=np.float64).ravel().tolist()
        self.params = ctypes.create_string_buffer(lib.params_size)
        self.state = ctypes.create_string_buffer(lib.state_size)
        msg = ctypes.create_string_buffer(512)
        if lib._lib.biso_mpu_setup(self.params, ctypes.byref(cfg), msg, 512):
            raise ValueError(msg.value.decode())
        lib._lib.biso_mpu_reset(self.params, self.state)
        self.max_outputs = lib._lib.biso_mpu_max_outputs(self.params)
        self.output_rate_hz = lib._lib.biso_mpu_output_rate_hz(self.params)

    def reset(self) -> None:
        self.lib._lib.biso_mpu_reset(self.params, self.state)

    def get_state(self) -> bytes:
        return self.state.raw

    def set_state(self, raw: bytes) -> None:
        ctypes.memmove(self.state, raw, len(raw))

    def simulate(self, omega_b, specific_force_b, mag_b, temperature_c=None, temp_default: float = 25.0) -> np.ndarray:
        """The samples the rows complete, as a `SAMPLE_DTYPE` array (one C call per row)."""
        n = len(omega_b)
        rows = np.empty((n, 10))
        rows[:, 0:3], rows[:, 3:6], rows[:, 6:9] = omega_b, specific_force_b, mag_b
        rows[:, 9] = temp_default if temperature_c is None else temperature_c
        out = np.zeros(n * self.max_outputs + 1, dtype=SAMPLE_DTYPE)
        k = 0
        fn = self.lib._lib.biso_mpu_input
        base = out.ctypes.data
        for i in range(n):
            k += fn(self.params, self.state, rows[i].ctypes.data, base + k * SAMPLE_DTYPE.itemsize)
        return out[:k]


