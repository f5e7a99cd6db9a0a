"""Building the native FMUs: sources, generated data and model description, the binary for
this platform compiled by the system C compiler, all zipped into one .fmu per FMI version.

An FMU holds ``sources/`` (every C file and header it was built from, flat, with FMI 3.0's
``buildDescription.xml``; FMI 2.0 lists them in ``modelDescription.xml``'s ``SourceFiles``),
so that a host on another platform compiles it itself (e.g. ``fmpy.util.compile_platform_binary``).
"""

from __future__ import annotations

import platform
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Iterable, Sequence

from biso_cosim.fmu.native import NATIVE_DIR, estimator_headers, estimator_sources
from biso_cosim.fmu.native.compiler import compile_objects, link_shared
from biso_cosim.fmu.native.model_description import (NATIVE_FMUS, build_description, model_description,
                                                     variables_c)
from biso_cosim.fmu.native.packaging import write_documentation, zip_fmu
from biso_cosim.fmu.native.sources import INCLUDE, SENSOR_DIR, write_sensor_data

__all__ = ["build_native_fmu", "build_native_fmus", "native_fmu_file_name", "platform_folder", "FMI_VERSIONS", "fmu_sources"]

FMI_VERSIONS = (2, 3)
_FMI_DIR = NATIVE_DIR / "src" / "fmi"


def native_fmu_file_name(name: str, fmi_version: int) -> str:
    """``BisoEstimator-fmi2.fmu``: the FMU's name says which standard it follows."""
    return f"{name}-fmi{fmi_version}.fmu"


def platform_folder(fmi_version: int) -> tuple[str, str]:
    """(binaries/ folder, shared-library suffix) of this platform for an FMI version."""
    machine = platform.machine().lower()
    arch = {"amd64": "x86_64", "x86_64": "x86_64", "arm64": "aarch64", "aarch64": "aarch64"}.get(machine, machine)
    system = {"linux": "linux", "darwin": "darwin", "win32": "windows", "cygwin": "windows"}.get(sys.platform)
    suffix = {"linux": ".so", "darwin": ".dylib", "windows": ".dll"}.get(system or "", ".so")
    if system is None:
        raise RuntimeError(f"no FMI platform name for {sys.platform!r}")
    if fmi_version == 3:
        return f"{arch}-{system}", suffix
    if arch != "x86_64" and not (system == "darwin" and arch == "aarch64"):
        raise RuntimeError(f"FMI 2.0 has no platform folder for {arch}-{system} (it names 32/64-bit only); "
                           "use the FMI 3.0 FMU")
    return {"linux": "linux64", "darwin": "darwin64", "windows": "win64"}[system], suffix


def fmu_sources(name: str, fmi_version: int, folder: Path, extra_profiles: Sequence = ()) -> list[str]:
    """Write every source file of one native FMU into ``folder`` (flat); their names."""
    folder.mkdir(parents=True, exist_ok=True)
    model_h, model_c = NATIVE_FMUS[name]
    fmi = [f"fmi{fmi_version}Functions.h", f"fmi{fmi_version}FunctionTypes.h",
           "fmi2TypesPlatform.h" if fmi_version == 2 else "fmi3PlatformTypes.h", "LICENSE-FMI.txt"]
    copies = [INCLUDE / f for f in ("biso_sensor.h", "biso_sensor_data.h", "biso_field.h", *fmi)]
    copies += [SENSOR_DIR / f for f in ("rng.h", "rng.c", "mpu9250.c", "wmm.c")]
    copies += [*estimator_headers(), *estimator_sources()]
    copies += [_FMI_DIR / f for f in ("fmu_vars.h", "fmu_core.h", "fmu_core.c", "fmu_estimate.h", "fmu_estimate.c",
                                      model_h, model_c, f"fmi{fmi_version}.c",
                                      f"fmi{fmi_version}_unsupported.h")]
    names = []
    for src in copies:
        if src.name in names:
            raise RuntimeError(f"two source files named {src.name}: the FMU's sources/ is flat")
        shutil.copyfile(src, folder / src.name)
        names.append(src.name)
    write_sensor_data(folder, extra_profiles)
    header, table = variables_c(name)
    (folder / "biso_variables.h").write_text(header, "utf-8")
    (folder / "biso_variables.c").write_text(table, "utf-8")
    names += ["biso_sensor_data.c", "biso_variables.h", "biso_variables.c"]
    return sorted(names)


_ABOUT = ("A native FMU: C99, no dependency beyond the C library and libm; its C sources are in "
          "<code>sources/</code>.")


_COMMON = ("rng.c", "mpu9250.c", "wmm.c", "biso_sensor_data.c")  # + the estimators' sources


def _common_objects(folder: Path, extra_profiles: Sequence) -> list[Path]:
    """The objects every native FMU links (sensor, its data, estimators): compiled once per build."""
    src = folder / "src"
    names = fmu_sources("BisoEstimator", 2, src, extra_profiles)
    common = [n for n in names if n in _COMMON or n in {p.name for p in estimator_sources()}]
    return compile_objects([src / n for n in common], folder / "obj", [src])


def _native_fmu(name: str, fmi_version: int, out_dir: Path, extra_profiles: Sequence, common: list[Path]) -> Path:
    folder_name, suffix = platform_folder(fmi_version)
    with tempfile.TemporaryDirectory(prefix="biso_native_fmu_") as tmp:
        root = Path(tmp)
        sources = fmu_sources(name, fmi_version, root / "sources", extra_profiles)
        shared = {o.stem for o in common}
        own = [root / "sources" / s for s in sources if s.endswith(".c") and Path(s).stem not in shared]
        binary = root / "binaries" / folder_name / f"{name}{suffix}"
        binary.parent.mkdir(parents=True)
        objects = compile_objects(own, root / "obj", [root / "sources"])
        link_shared([*common, *objects], binary)
        shutil.rmtree(root / "obj")
        (root / "modelDescription.xml").write_bytes(model_description(name, fmi_version, sources))
        if fmi_version == 3:
            (root / "sources" / "buildDescription.xml").write_bytes(build_description(name, sources))
        write_documentation(root, name, fmi_version, _ABOUT)
        path = zip_fmu(root, out_dir / native_fmu_file_name(name, fmi_version))
    return path


def build_native_fmu(name: str, fmi_version: int, out_dir: str | Path, extra_profiles: Sequence = ()) -> Path:
    """Build one native FMU (``BisoEstimator`` or ``BisoImuPlugin``) for FMI 2.0 or 3.0
    into ``out_dir``; returns its path. Raises `CompilerNotFound` without a C compiler."""
    return build_native_fmus(out_dir, [name], [fmi_version], extra_profiles)[0]


def build_native_fmus(out_dir: str | Path, names: Iterable[str] = tuple(NATIVE_FMUS),
                      versions: Iterable[int] = FMI_VERSIONS, extra_profiles: Sequence = ()) -> list[Path]:
    """Native FMUs (every one in every FMI version by default: four files), their common
    objects compiled once."""
    names, versions = list(names), list(versions)
    for name in names:
        if name not in NATIVE_FMUS:
            raise ValueError(f"no native FMU {name!r}; native: {', '.join(NATIVE_FMUS)}")
    for version in versions:
        if version not in FMI_VERSIONS:
            raise ValueError(f"fmi_version must be one of {FMI_VERSIONS}, got {version!r}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="biso_native_common_") as tmp:
        common = _common_objects(Path(tmp), extra_profiles)
        return [_native_fmu(n, v, out_dir, extra_profiles, common) for n in names for v in versions]
