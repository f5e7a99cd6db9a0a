"""Run an FMU in a native (non-Python) FMI host: ``fmu_master.c``, compiled here.

``python -m biso_cosim.fmu.demos.native`` builds ``BisoEstimator.fmu``, compiles the C master
against the FMI 2.0 headers that ship with FMPy, runs it with the environment a Python-based
FMU needs in a native host (``python_environment()``: ``LD_PRELOAD`` of the Python library
and a ``PYTHONPATH`` with the packages), and compares its output with ``estimate_attitude``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path
from typing import Mapping

import numpy as np

__all__ = ["python_environment", "compile_master", "run_native", "main"]

SOURCE = Path(__file__).with_name("fmu_master.c")


def python_environment() -> dict[str, str]:
    """Environment variables a native host needs for a pythonfmu FMU running on this Python.

    The FMU's binary does not link the Python library (it expects the host to provide it), so
    ``LD_PRELOAD`` names this Python's shared library; ``PYTHONPATH`` names the directories
    of the installed packages (biso_cosim, numpy, numba, mujoco ...); ``PYTHONHOME`` the
    standard library of this Python (a venv's base installation).
    """
    libdir = sysconfig.get_config_var("LIBDIR")
    library = sysconfig.get_config_var("LDLIBRARY")
    if not sysconfig.get_config_var("Py_ENABLE_SHARED") or not library.endswith(".so"):
        raise RuntimeError(f"this Python ({sys.executable}) has no shared library; a native host needs one "
                           "(build Python with --enable-shared, or use a distribution's libpython3.X.so)")
    site_dirs = [p for p in sys.path if p.endswith("site-packages")]
    return {
        "LD_PRELOAD": str(Path(libdir) / library),
        "PYTHONHOME": sys.base_prefix,
        "PYTHONPATH": os.pathsep.join(site_dirs),
    }


def compile_master(out_dir: str | Path, compiler: str | None = None) -> Path:
    """Compile ``fmu_master.c`` into ``out_dir``; returns the executable."""
    import fmpy

    cc = compiler or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) found")
    headers = Path(fmpy.__file__).with_name("c-code")
    exe = Path(out_dir) / "fmu_master"
    subprocess.run([cc, "-O2", "-std=c99", "-D_GNU_SOURCE", f"-I{headers}", "-o", str(exe), str(SOURCE), "-ldl"],
                   check=True, capture_output=True, text=True)
    return exe


def run_native(master: str | Path, fmu: str | Path, step: float, n: int, *, start: Mapping[str, object] = {},
               inputs: Mapping[str, float] = {}, outputs: list[str] = (), workdir: str | Path | None = None,
               timeout: float = 300.0) -> tuple[np.ndarray, str]:
    """Run ``fmu`` in the C master for ``n`` steps; (time and outputs per step, stderr)."""
    from fmpy import extract, read_model_description

    workdir = Path(workdir or tempfile.mkdtemp(prefix="biso_native_"))
    unzipped = Path(extract(str(fmu), unzipdir=str(workdir / "fmu")))
    md = read_model_description(str(unzipped))
    var = {v.name: v for v in md.modelVariables}
    args = [str(master), str(unzipped), md.coSimulation.modelIdentifier, md.guid, repr(step), str(n)]
    prefix = {"Real": "r", "Integer": "i", "Boolean": "b", "String": "s"}
    for name, value in start.items():
        v = var[name]
        text = str(int(value)) if v.type == "Boolean" else str(value)
        args.append(f"{prefix[v.type]}:{v.valueReference}={text}")
    args += [f"in:{var[name].valueReference}={value!r}" for name, value in inputs.items()]
    args += [f"out:{var[name].valueReference}" for name in outputs]
    env = {**os.environ, **python_environment()}
    done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=timeout, cwd=workdir)
    if done.returncode != 0:
        raise RuntimeError(f"fmu_master failed ({done.returncode}): {done.stderr[-2000:]}")
    rows = np.array([[float(x) for x in line.split(",")] for line in done.stdout.splitlines()])
    return rows, done.stderr


def main(argv: list[str] | None = None) -> int:
    from biso_cosim.estimators import estimate_attitude
    from biso_cosim.fmu.build import built_fmus

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400, help="number of 5 ms steps (default 400)")
    args = parser.parse_args(argv)
    gyro, accel, mag = [0.02, -0.01, 0.3], [0.5, -0.3, 9.7], [3.0, 18.0, -45.0]
    inputs = {f"{head}.{c}": value for head, row in (("gyro_s", gyro), ("accel_s", accel), ("mag_s", mag))
              for c, value in zip("xyz", row)}
    outputs = [f"estimate.q_wb.{c}" for c in "wxyz"]
    with tempfile.TemporaryDirectory(prefix="biso_native_") as tmp:
        master = compile_master(tmp)
        print("environment for the native host:")
        for key, value in python_environment().items():
            print(f"  {key}={value}")
        rows, log = run_native(master, built_fmus()["BisoEstimator"], 0.005, args.steps,
                               start={"estimator": "biso_plus"}, inputs=inputs, outputs=outputs, workdir=tmp)
    n = args.steps
    ref = estimate_attitude(*(np.tile(x, (n, 1)) for x in (gyro, accel, mag)), 200.0, method="biso_plus")
    diff = float(np.max(np.abs(rows[:, 1:] - ref)))
    print(f"{n} steps of BisoEstimator.fmu in a C master: last q_wb {rows[-1, 1:]}, "
          f"largest difference from estimate_attitude {diff:.3g}")
    return 0 if diff <= 1e-12 else 1


if __name__ == "__main__":
    sys.exit(main())
