"""Building the FMUs with pythonfmu (FMI 2.0 co-simulation) and validating them with FMPy.

Each FMU holds its slave script (``slaves/*.py``, a unique module name per FMU so that all
three load in one process), a copy of pythonfmu, a stamp with the package version and the
fingerprint of its variables, and ``documentation/index.html`` (the variable table). The
model itself stays in the installed ``biso_cosim`` package: the Python that runs the FMU must
have ``biso_cosim`` and its dependencies importable (docs/fmu.md, "Native hosts").
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
from typing import Iterable

from biso_cosim import __version__
from biso_cosim.fmu.variables import fingerprint, variables_of

__all__ = ["FMU_NAMES", "build_fmu", "build_fmus", "validate_fmu", "built_fmus"]

_SLAVES = Path(__file__).with_name("slaves")
_SCRIPTS = {
    "BisoEstimator": "biso_estimator_fmu.py",
    "BisoImuPlugin": "biso_imu_plugin_fmu.py",
    "BisoVehicle": "biso_vehicle_fmu.py",
}
FMU_NAMES: tuple[str, ...] = tuple(_SCRIPTS)
"""The FMUs this package builds."""


def _documentation(name: str, folder: Path) -> None:
    rows = "\n".join(
        f"<tr><td><code>{html.escape(v.name)}</code></td><td>{v.type}</td><td>{v.causality}</td>"
        f"<td>{v.variability}</td><td>{html.escape(v.unit)}</td><td>{html.escape(str(v.start))}</td>"
        f"<td>{html.escape(v.description)}</td></tr>"
        for v in variables_of(name))
    folder.mkdir()
    (folder / "index.html").write_text(
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{name}</title></head><body>"
        f"<h1>{name}.fmu</h1><p>biso_cosim {__version__}: see docs/fmu.md of the package. The FMU runs on "
        "the Python that loads it, which must import biso_cosim and its dependencies.</p>"
        "<table border='1'><tr><th>variable</th><th>type</th><th>causality</th><th>variability</th>"
        f"<th>unit</th><th>start</th><th>description</th></tr>\n{rows}</table></body></html>\n", "utf-8")


def build_fmu(name: str, out_dir: str | Path) -> Path:
    """Build one FMU (a name of ``FMU_NAMES``) into ``out_dir``; returns its path."""
    from pythonfmu import FmuBuilder

    from biso_cosim.fmu._slave import STAMP_FILE

    if name not in _SCRIPTS:
        raise ValueError(f"unknown FMU {name!r}; known: {', '.join(FMU_NAMES)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
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


def build_fmus(out_dir: str | Path, only: Iterable[str] | None = None) -> list[Path]:
    """Build the FMUs (all, or the names in ``only``) into ``out_dir``."""
    names = list(only) if only else list(FMU_NAMES)
    unknown = [n for n in names if n not in _SCRIPTS]
    if unknown:
        raise ValueError(f"unknown FMU(s) {unknown}; known: {', '.join(FMU_NAMES)}")
    return [build_fmu(n, out_dir) for n in names]


def validate_fmu(path: str | Path) -> list[str]:
    """FMPy's validation of an FMU file: the list of problems (empty when valid)."""
    from fmpy.validation import validate_fmu as fmpy_validate

    return list(fmpy_validate(str(path)))


@functools.cache
def built_fmus() -> dict[str, Path]:
    """All FMUs built once per process into a temporary directory removed at exit (for the
    tests, the demonstrations and the benchmark)."""
    folder = Path(tempfile.mkdtemp(prefix="biso_fmus_"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return {path.stem: path for path in build_fmus(folder)}
