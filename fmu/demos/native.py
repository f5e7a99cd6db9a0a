"""Run an FMU in a native (non-Python) FMI host: ``fmu_master.c``, compiled here.

``python -m biso_cosim.fmu.demos.native`` builds the native ``BisoEstimator`` FMUs, compiles
the C master against the FMI headers of ``biso_cosim/fmu/native/include``, runs both FMI
versions in it (no Python, no environment variable: the FMUs are C) and compares the output
with ``estimate_attitude``. The Python-based BisoVehicle runs in it too: its C shell starts
the Python named in its resources/python.txt (tests/test_fmu.py).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

__all__ = ["compile_master", "run_native", "NativeRun", "main"]

SOURCE = Path(__file__).with_name("fmu_master.c")


def compile_master(out_dir: str | Path, extra: Sequence[str] = ()) -> Path:
    """Compile ``fmu_master.c`` into ``out_dir`` with the system C compiler; returns the executable."""
    from biso_cosim.fmu.native import INCLUDE_DIR
    from biso_cosim.fmu.native.compiler import compile_program

    exe = Path(out_dir) / "fmu_master"
    return compile_program([SOURCE], exe, [INCLUDE_DIR], libraries=("dl",), extra=("-D_GNU_SOURCE", *extra))


class NativeRun:
    """What one run of the C master gave: ``rows`` (time and outputs per step), ``log``
    (stderr), ``returncode``."""

    def __init__(self, rows: np.ndarray, log: str, returncode: int):
        self.rows, self.log, self.returncode = rows, log, returncode


def run_native(master: str | Path, fmu: str | Path, step: float, n: int, *, start: Mapping[str, object] = {},
               inputs: Mapping[str, float] = {}, outputs: Sequence[str] = (), input_rows: Mapping[str, np.ndarray] = {},
               options: Sequence[str] = (), workdir: str | Path | None = None, env: Mapping[str, str] | None = None,
               prefix: Sequence[str] = (), timeout: float = 600.0) -> NativeRun:
    """Run ``fmu`` in the C master for ``n`` steps: start values by name, held inputs,
    per-step inputs (``input_rows``: name → (n,) values, written to a file), outputs by name;
    ``options`` are the master's (``--check-state``, ``--instances 2``, ``--time`` ...);
    ``prefix`` a command before the master (e.g. valgrind); the environment is ``env`` (default:
    the C library's only: nothing for the FMU's sake)."""
    from fmpy import extract, read_model_description

    workdir = Path(workdir or tempfile.mkdtemp(prefix="biso_native_"))
    workdir.mkdir(parents=True, exist_ok=True)
    unzipped = Path(extract(str(fmu), unzipdir=str(workdir / "fmu")))
    md = read_model_description(str(unzipped))
    var = {v.name: v for v in md.modelVariables}
    version = md.fmiVersion.split(".")[0]
    args = [*prefix, str(master), "--fmi", version, *options]
    if input_rows:
        table = workdir / "inputs.txt"
        names = list(input_rows)
        data = np.column_stack([np.asarray(input_rows[k], dtype=float) for k in names])
        with open(table, "w") as fh:
            fh.write(" ".join(str(var[k].valueReference) for k in names) + "\n")
            np.savetxt(fh, data, fmt="%.17g")
        args += ["--inputs", str(table)]
    args += [str(unzipped), md.coSimulation.modelIdentifier, md.guid, repr(step), str(n)]
    prefix_of = {"Real": "r", "Float64": "r", "Integer": "i", "Int32": "i", "Boolean": "b", "String": "s"}
    for name, value in start.items():
        v = var[name]
        text = str(int(value)) if v.type == "Boolean" else str(value)
        args.append(f"{prefix_of[v.type]}:{v.valueReference}={text}")
    args += [f"in:{var[name].valueReference}={value!r}" for name, value in inputs.items()]
    args += [f"out:{var[name].valueReference}" for name in outputs]
    environment = dict(env) if env is not None else {"PATH": os.environ.get("PATH", "/usr/bin:/bin")}
    done = subprocess.run(args, env=environment, capture_output=True, text=True, timeout=timeout, cwd=workdir)
    lines = [line for line in done.stdout.splitlines() if line]
    rows = np.array([[float(x) for x in line.split(",")] for line in lines]) if lines else np.empty((0, 1 + len(outputs)))
    return NativeRun(rows, done.stderr, done.returncode)


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
    n = args.steps
    ref = estimate_attitude(*(np.tile(x, (n, 1)) for x in (gyro, accel, mag)), 200.0, method="biso_plus")
    worst = 0.0
    paths = built_fmus(("BisoEstimator",))
    with tempfile.TemporaryDirectory(prefix="biso_native_") as tmp:
        master = compile_master(tmp)
        for version in ("fmi2", "fmi3"):
            run = run_native(master, paths[f"BisoEstimator-{version}"], 0.005, n, start={"estimator": "biso_plus"},
                             inputs=inputs, outputs=outputs, workdir=Path(tmp) / version)
            if run.returncode:
                print(run.log)
                return 1
            diff = float(np.max(np.abs(run.rows[:, 1:] - ref)))
            worst = max(worst, diff)
            print(f"{n} steps of BisoEstimator-{version}.fmu in a C master (no Python, no environment): last q_wb "
                  f"{run.rows[-1, 1:]}, largest difference from estimate_attitude {diff:.3g}")
    return 0 if worst == 0.0 else 1


if __name__ == "__main__":
    sys.exit(main())
