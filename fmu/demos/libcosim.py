"""The FMUs in another FMI host from PyPI: libcosim (Open Simulation Platform, C++), via libcosimpy.

``python -m biso_cosim.fmu.demos.libcosim [--duration 10]`` (needs ``pip install libcosimpy``)

libcosim is a native co-simulation engine: it loads the FMUs itself (FMI Library), connects
``BisoVehicle``'s truth outputs to the native ``BisoImuPlugin-fmi2``'s inputs (libcosim
loads FMI 1.0 and 2.0 FMUs only) and steps both on its own
threads; Python here only builds the system and reads the results. The run is compared with
the same connection made by the FMPy master (``demos/master.py``): libcosim passes an
output to the connected input before the next step (a Jacobi scheme), the FMPy master right
after the vehicle's step (Gauss–Seidel), so the plug-in's inputs lag one step more here.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from biso_cosim.fmu.demos.master import CONNECTIONS

__all__ = ["run_connected", "main"]

_NS = 1_000_000_000


def _references(execution, index: int) -> dict[str, int]:
    return {v.name.decode(): v.reference for v in execution.slave_variables(index)}


def run_connected(vehicle_fmu: str | Path, plugin_fmu: str | Path, *, route: str = "figure8",
                  duration_s: float = 10.0, step_s: float = 0.02,
                  record: tuple[str, ...] = ("estimate.q_wb.w", "estimate.q_wb.z", "gyro_b.z", "new_samples"),
                  ) -> dict[str, np.ndarray]:
    """Run BisoVehicle → BisoImuPlugin in libcosim; per step: the vehicle's connected outputs
    (``vehicle.<name>``) and the plug-in's ``record`` outputs (``plugin.<name>``)."""
    from libcosimpy.CosimEnums import CosimExecutionState
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_step_size(step_size=int(round(step_s * _NS)))
    vehicle = execution.add_local_slave(CosimLocalSlave(fmu_path=str(vehicle_fmu), instance_name="vehicle"))
    plugin = execution.add_local_slave(CosimLocalSlave(fmu_path=str(plugin_fmu), instance_name="plugin"))
    ref_v, ref_p = _references(execution, vehicle), _references(execution, plugin)
    execution.string_initial_value(vehicle, ref_v["route"], route)
    for out, inp in CONNECTIONS.items():
        execution.connect_real_variables(vehicle, ref_v[out], plugin, ref_p[inp])
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    outs_v = [ref_v[n] for n in CONNECTIONS]
    real_p = [n for n in record if n != "new_samples"]
    rows_v, rows_p, counts = [], [], []
    for _ in range(int(round(duration_s / step_s))):
        if not execution.step():
            raise RuntimeError("libcosim refused a step (see its log)")
        rows_v.append(observer.last_real_values(vehicle, outs_v))
        rows_p.append(observer.last_real_values(plugin, [ref_p[n] for n in real_p]))
        if "new_samples" in record:
            counts.append(observer.last_integer_values(plugin, [ref_p["new_samples"]])[0])
    status = execution.status()
    if status.state == CosimExecutionState.ERROR.value:
        raise RuntimeError(f"libcosim execution error: {status.error_code}")
    out = {f"vehicle.{n}": np.array(rows_v)[:, i] for i, n in enumerate(CONNECTIONS)}
    out.update({f"plugin.{n}": np.array(rows_p)[:, i] for i, n in enumerate(real_p)})
    if counts:
        out["plugin.new_samples"] = np.array(counts)
    return out


def main(argv: list[str] | None = None) -> int:
    from biso_cosim.fmu.build import built_fmus
    from biso_cosim.fmu.host import FmuInstance

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--route", default="figure8")
    parser.add_argument("--duration", type=float, default=10.0, metavar="S")
    args = parser.parse_args(argv)
    paths = built_fmus(("BisoImuPlugin", "BisoVehicle"))
    rec = run_connected(paths["BisoVehicle-fmi2"], paths["BisoImuPlugin-fmi2"], route=args.route, duration_s=args.duration)
    # the vehicle alone in FMPy gives the same truth, step by step
    n = len(rec["vehicle.truth.q_wb.w"])
    with FmuInstance(paths["BisoVehicle-fmi2"], "fmpy", start_values={"route": args.route}) as fmu:
        ref = []
        for _ in range(n):
            assert fmu.step(0.02)
            ref.append(fmu.get(list(CONNECTIONS)))
    diff = float(np.max(np.abs(np.array(ref) - np.stack([rec[f"vehicle.{k}"] for k in CONNECTIONS], 1))))
    print(f"libcosim ran BisoVehicle -> BisoImuPlugin for {n} steps; vehicle outputs equal FMPy's to {diff:.3g}; "
          f"plug-in estimate at the end q_wb.w = {rec['plugin.estimate.q_wb.w'][-1]:.6f}, "
          f"{int(rec['plugin.new_samples'].sum())} sensor samples")
    return 0 if diff == 0.0 else 1


if __name__ == "__main__":
    sys.exit(main())
