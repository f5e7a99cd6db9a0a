"""Building the FMUs and validating them with FMPy.

Every FMU is built in FMI 2.0 and FMI 3.0 co-simulation (``<name>-fmi2.fmu``,
``<name>-fmi3.fmu``), its binary compiled for this platform by the system C compiler:

* ``BisoEstimator`` and ``BisoImuPlugin`` are native: C99 models, with their sources
  inside (``native/build.py``). They need no Python.
* ``BisoVehicle`` is Python-based (it runs MuJoCo and the driver): its binary is our C
  shell that embeds CPython and calls ``biso_cosim.fmu.vehicle`` (``native/python_shell.py``),
  so the process that loads it needs a Python that imports biso_cosim (docs/fmu.md,
  "BisoVehicle and Python").
"""

from __future__ import annotations

import atexit
import functools
import shutil
import tempfile
from pathlib import Path
from typing import Iterable, Sequence

from biso_cosim.fmu.native.build import FMI_VERSIONS, build_native_fmu, build_native_fmus, native_fmu_file_name
from biso_cosim.fmu.native.model_description import NATIVE_FMUS
from biso_cosim.fmu.native.python_shell import PYTHON_FMUS, build_python_fmu

__all__ = ["FMU_NAMES", "NATIVE_FMU_NAMES", "PYTHON_FMU_NAMES", "build_fmu", "build_fmus", "validate_fmu",
           "built_fmus", "fmu_files"]

NATIVE_FMU_NAMES: tuple[str, ...] = tuple(NATIVE_FMUS)
PYTHON_FMU_NAMES: tuple[str, ...] = PYTHON_FMUS
FMU_NAMES: tuple[str, ...] = NATIVE_FMU_NAMES + PYTHON_FMU_NAMES
"""The FMUs this package builds, each in FMI 2.0 and 3.0: two native ones, one Python-based."""


def fmu_files(name: str) -> list[str]:
    """The file names one FMU name builds (``BisoEstimator`` → its FMI 2.0 and 3.0 files)."""
    if name not in FMU_NAMES:
        raise ValueError(f"unknown FMU {name!r}; known: {', '.join(FMU_NAMES)}")
    return [native_fmu_file_name(name, v) for v in FMI_VERSIONS]


def build_fmu(name: str, out_dir: str | Path, extra_profiles: Sequence = ()) -> list[Path]:
    """Build one FMU (a name of ``FMU_NAMES``) into ``out_dir`` in FMI 2.0 and FMI 3.0;
    returns the two files. ``extra_profiles``: sensor profile files built into the native
    plug-in beside the built-in ones."""
    if name not in FMU_NAMES:
        raise ValueError(f"unknown FMU {name!r}; known: {', '.join(FMU_NAMES)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if name in NATIVE_FMUS:
        return [build_native_fmu(name, v, out_dir, extra_profiles) for v in FMI_VERSIONS]
    return [build_python_fmu(name, v, out_dir) for v in FMI_VERSIONS]


def build_fmus(out_dir: str | Path, only: Iterable[str] | None = None, extra_profiles: Sequence = ()) -> list[Path]:
    """Build the FMUs (all, or the names in ``only``) into ``out_dir``."""
    names = list(only) if only else list(FMU_NAMES)
    unknown = [n for n in names if n not in FMU_NAMES]
    if unknown:
        raise ValueError(f"unknown FMU(s) {unknown}; known: {', '.join(FMU_NAMES)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    native = [n for n in names if n in NATIVE_FMUS]
    built = build_native_fmus(out_dir, native, FMI_VERSIONS, extra_profiles) if native else []
    by_name = {n: built[2 * i:2 * i + 2] for i, n in enumerate(native)}
    return [path for n in names for path in (by_name[n] if n in by_name else build_fmu(n, out_dir))]


def validate_fmu(path: str | Path) -> list[str]:
    """FMPy's validation of an FMU file: the list of problems (empty when valid)."""
    from fmpy.validation import validate_fmu as fmpy_validate

    return list(fmpy_validate(str(path)))


@functools.cache
def built_fmus(only: tuple[str, ...] | None = None) -> dict[str, Path]:
    """FMUs built once per process into a temporary directory removed at exit (for the
    tests, the demonstrations and the benchmark), by file stem: ``BisoEstimator-fmi2``,
    ``BisoEstimator-fmi3``, ``BisoImuPlugin-fmi2``, ``BisoImuPlugin-fmi3``, ``BisoVehicle-fmi2``,
    ``BisoVehicle-fmi3``."""
    folder = Path(tempfile.mkdtemp(prefix="biso_fmus_"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return {path.stem: path for path in build_fmus(folder, only)}
