"""Building the FMUs and validating them with FMPy.

* ``BisoEstimator`` and ``BisoImuPlugin`` are native: C99 sources and a binary for this
  platform compiled by the system C compiler, in FMI 2.0 and FMI 3.0 co-simulation
  (``BisoEstimator-fmi2.fmu``, ``BisoEstimator-fmi3.fmu``, ``BisoImuPlugin-fmi2.fmu``,
  ``BisoImuPlugin-fmi3.fmu``; ``native/build.py``). They need no Python.
* ``BisoVehicle.fmu`` stays Python-based (FMI 2.0, pythonfmu): it runs MuJoCo and the
  driver, so the Python that loads it must import ``biso_cosim`` and its dependencies
  (docs/fmu.md, "Native hosts"). It holds its slave script, a copy of pythonfmu, a stamp
  with the package version and the fingerprint of its variables, and
  ``documentation/index.html``.
"""

from __future__ import annotations

import atexit
import functools
import html
import json
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Iterable, Sequence

from biso_cosim import __version__
from biso_cosim.fmu.native.build import FMI_VERSIONS, build_native_fmu, build_native_fmus, native_fmu_file_name
from biso_cosim.fmu.native.model_description import NATIVE_FMUS
from biso_cosim.fmu.variables import fingerprint, variables_of

__all__ = ["FMU_NAMES", "NATIVE_FMU_NAMES", "PYTHON_FMU_NAMES", "build_fmu", "build_fmus", "validate_fmu",
           "built_fmus", "fmu_files"]

_SLAVES = Path(__file__).with_name("slaves")
_SCRIPTS = {"BisoVehicle": "biso_vehicle_fmu.py"}
NATIVE_FMU_NAMES: tuple[str, ...] = tuple(NATIVE_FMUS)
PYTHON_FMU_NAMES: tuple[str, ...] = tuple(_SCRIPTS)
FMU_NAMES: tuple[str, ...] = NATIVE_FMU_NAMES + PYTHON_FMU_NAMES
"""The FMUs this package builds: two native ones (each in FMI 2.0 and 3.0), one Python-based."""


def fmu_files(name: str) -> list[str]:
    """The file names one FMU name builds (``BisoEstimator`` → its FMI 2.0 and 3.0 files)."""
    if name in NATIVE_FMUS:
        return [native_fmu_file_name(name, v) for v in FMI_VERSIONS]
    if name in _SCRIPTS:
        return [f"{name}.fmu"]
    raise ValueError(f"unknown FMU {name!r}; known: {', '.join(FMU_NAMES)}")


def _documentation(name: str, folder: Path) -> None:
    rows = "\n".join(
        f"<tr><td><code>{html.escape(v.name)}</code></td><td>{v.type}</td><td>{v.causality}</td>"
        f"<td>{v.variability}</td><td>{html.escape(v.unit)}</td><td>{html.escape(str(v.start))}</td>"
        f"<td>{html.escape(v.description)}</td></tr>"
        for v in variables_of(name))
    folder.mkdir()
    (folder / "index.html").write_text(
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{name}</title></head><body>"
        f"<h1>{name}.fmu</h1><p>biso_cosim {__version__}: see docs/fmu.md of the package. This FMU is "
        "Python-based (it runs MuJoCo and the driver): it runs on the Python that loads it, which must import "
        "biso_cosim and its dependencies. The sensor and estimator FMUs are native (no Python).</p>"
        "<table border='1'><tr><th>variable</th><th>type</th><th>causality</th><th>variability</th>"
        f"<th>unit</th><th>start</th><th>description</th></tr>\n{rows}</table></body></html>\n", "utf-8")


def _build_python_fmu(name: str, out_dir: Path) -> Path:
    from pythonfmu import FmuBuilder

    from biso_cosim.fmu._slave import STAMP_FILE

    script = _SLAVES / _SCRIPTS[name]
    saved_path = list(sys.path)
    try:
        with tempfile.TemporaryDirectory(prefix="biso_fmu_") as tmp:
            stamp = Path(tmp) / STAMP_FILE
            stamp.write_text(json.dumps({"fmu": name, "version": __version__, "fingerprint": fingerprint(name)}))
            _documentation(name, Path(tmp) / "documentation")
            return Path(FmuBuilder.build_FMU(script, dest=out_dir, project_files=[stamp],
                                             documentation_folder=Path(tmp) / "documentation"))
    finally:
        # the builder imports the script from slaves/: forget it, so that a loaded FMU
        # imports its own copy from its resources
        sys.path[:] = saved_path
        sys.modules.pop(script.stem, None)
        shutil.rmtree(_SLAVES / "__pycache__", ignore_errors=True)


def build_fmu(name: str, out_dir: str | Path, extra_profiles: Sequence = ()) -> list[Path]:
    """Build one FMU (a name of ``FMU_NAMES``) into ``out_dir``; returns its file(s): a
    native FMU in FMI 2.0 and FMI 3.0, the Python one once. ``extra_profiles``: sensor
    profile files built into the native plug-in beside the built-in ones."""
    if name not in FMU_NAMES:
        raise ValueError(f"unknown FMU {name!r}; known: {', '.join(FMU_NAMES)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if name in NATIVE_FMUS:
        return [build_native_fmu(name, v, out_dir, extra_profiles) for v in FMI_VERSIONS]
    return [_build_python_fmu(name, out_dir)]


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
    ``BisoEstimator-fmi3``, ``BisoImuPlugin-fmi2``, ``BisoImuPlugin-fmi3``, ``BisoVehicle``."""
    folder = Path(tempfile.mkdtemp(prefix="biso_fmus_"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return {path.stem: path for path in build_fmus(folder, only)}
