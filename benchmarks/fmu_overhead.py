"""Cost of the native FMUs against the numba path, all measured in this one run.

Per step (set the inputs, DoStep, get the main outputs, by value reference: what a master
does each step):

* BisoEstimator (biso_plus, one sample per step, FMI 2.0 and 3.0) in the project's C master
  and in FMPy, next to the numba estimator's cost per sample (its batch update, and one
  Python call per sample); goal ≤ 1 µs per DoStep in the C master;
* BisoImuPlugin (1 ms truth steps, biso_plus) in the C master and in FMPy, next to
  MPU9250.simulate + the estimator on the same truth (numba, batch) per 1 ms; goal ≤ 5 µs;
* a whole route (loop600 by default) fed from a recorded truth: the native plug-in in the C
  master against the numba path on the same truth rows (the Earth field, MPU9250.simulate
  and the estimator, each on the whole array); goal within 1.5× of the numba path;
* BisoVehicle-fmi2.fmu (Python-based: our C shell embedding CPython) over the route in FMPy
  against CoSimulation.run.

    python benchmarks/fmu_overhead.py                       # loop600
    python benchmarks/fmu_overhead.py --route slalom --steps 20000 --no-vehicle

With valgrind installed, the estimator's line also gives the instructions the FMU executes
per step (callgrind), a figure the machine's load does not change.
"""

from __future__ import annotations

import argparse
import re
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from biso_cosim.fmu.demos.native import compile_master, run_native
from biso_cosim.fmu.host import FmuInstance
from biso_cosim.fmu.variables import AXES, QUAT
from biso_cosim.motions import make_motion

EST_OUT = [f"estimate.q_wb.{c}" for c in QUAT]
TRUTH = [f"omega_b.{c}" for c in AXES] + [f"specific_force_b.{c}" for c in AXES] + [f"q_wb.{c}" for c in QUAT]


def _fmpy_loop(fmu: FmuInstance, inputs: list[str], rows: np.ndarray, outputs: list[str], step: float) -> float:
    """Seconds per step of set inputs / DoStep / get outputs through FMPy."""
    var = fmu.variables
    vr_in = [var[n].valueReference for n in inputs]
    vr_out = [var[n].valueReference for n in outputs]
    raw = fmu.fmu
    three = fmu.fmi_version == 3
    set_real, get_real = (raw.setFloat64, raw.getFloat64) if three else (raw.setReal, raw.getReal)
    values = rows.tolist()
    t, start = 0.0, time.perf_counter()
    for row in values:
        set_real(vr_in, row)
        raw.doStep(t, step)
        get_real(vr_out)
        t += step
    return (time.perf_counter() - start) / len(values)


def _master_per_step(master, path, step, rows: dict, start: dict, workdir: Path) -> float:
    """Seconds per step (set inputs / DoStep / get outputs) in the C master, from its --time line."""
    run = run_native(master, path, step, len(next(iter(rows.values()))), start=start, input_rows=rows,
                     outputs=EST_OUT, options=["--time", "--quiet"], workdir=workdir)
    if run.returncode:
        raise RuntimeError(run.log[-2000:])
    return float(re.search(r"time per DoStep: ([0-9.]+) ns", run.log).group(1)) * 1e-9


_PER_STEP_CALLS = {"fmi2": ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal"),
                   "fmi3": ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64")}


def _instructions_per_step(master, path, version: str, step: float, rows: dict, start: dict,
                           workdir: Path) -> float | None:
    """Instructions the FMU executes per step (its SetReal, DoStep and GetReal, the calls a
    master makes each step), counted by valgrind's callgrind: the difference of two runs of
    1000 and 2000 steps over 1000 steps, so that instantiation and initialization drop out.
    A figure independent of the machine's load; None without valgrind."""
    if shutil.which("valgrind") is None:
        return None
    totals = []
    for n in (1000, 2000):
        out = workdir / f"callgrind.{version}.{n}"
        toggles = [f"--toggle-collect={f}" for f in _PER_STEP_CALLS[version]]
        run = run_native(master, path, step, n, start=start, input_rows={k: v[:n] for k, v in rows.items()},
                         outputs=EST_OUT, options=["--quiet"], workdir=workdir / f"cg{n}", timeout=1800,
                         prefix=["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", *toggles])
        if run.returncode:
            raise RuntimeError(run.log[-2000:])
        totals.append(int(re.search(r"^summary: (\d+)", out.read_text(), re.M).group(1)))
    return (totals[1] - totals[0]) / 1000.0


def estimator(paths, master, steps: int, tmp: Path) -> None:
    from biso_cosim.estimators import make_estimator

    m = make_motion("tumble", duration_s=steps / 200.0, fs_hz=200.0)
    data = np.hstack([m.omega_b, m.specific_force_b, m.mag_b])
    inputs = [f"{h}.{c}" for h in ("gyro_s", "accel_s", "mag_s") for c in AXES]
    rows = {name: data[:, k] for k, name in enumerate(inputs)}
    start = {"estimator": "biso_plus"}
    est = make_estimator("biso_plus", 200.0)
    est.update(m.omega_b[:10], m.specific_force_b[:10], m.mag_b[:10])  # compiled
    est.reset()
    t0 = time.perf_counter()
    est.update(m.omega_b, m.specific_force_b, m.mag_b)
    batch = (time.perf_counter() - t0) / len(m)
    est.reset()
    g, a, mag = (np.ascontiguousarray(x[:, None, :]) for x in (m.omega_b, m.specific_force_b, m.mag_b))
    t0 = time.perf_counter()
    for i in range(len(m)):
        est.update(g[i], a[i], mag[i])
    per_call = (time.perf_counter() - t0) / len(m)
    print(f"BisoEstimator (biso_plus, one sample per step), {steps} steps; numba: batch {batch * 1e6:.3f} µs/sample, "
          f"one Python call per sample {per_call * 1e6:.2f} µs")
    for version in ("fmi2", "fmi3"):
        c = _master_per_step(master, paths[f"BisoEstimator-{version}"], 0.005, rows, start, tmp / f"e{version}")
        with FmuInstance(paths[f"BisoEstimator-{version}"], "bench", start_values=start) as fmu:
            f = _fmpy_loop(fmu, inputs, data, EST_OUT, 0.005)
        instructions = _instructions_per_step(master, paths[f"BisoEstimator-{version}"], version, 0.005, rows, start,
                                              tmp / f"i{version}")
        counted = ("" if instructions is None else
                   f"; callgrind: {instructions:.0f} instructions per step (SetReal + DoStep + GetReal)")
        print(f"  {version}: C master {c * 1e6:6.3f} µs per DoStep ({c / batch:5.1f}× numba batch; goal ≤ 1 µs: "
              f"{'met' if c <= 1e-6 else 'NOT met'}), FMPy {f * 1e6:6.1f} µs per step{counted}")


def plugin(paths, master, steps: int, tmp: Path) -> None:
    m = make_motion("circle", duration_s=steps / 1000.0, fs_hz=1000.0)
    data = np.hstack([m.omega_b, m.specific_force_b, m.q_wb])
    rows = {name: data[:, k] for k, name in enumerate(TRUTH)}
    start = {"estimator": "biso_plus"}
    numba = _numba_path(0.001, m.omega_b, m.specific_force_b, m.q_wb, np.zeros((len(m.t_s), 3)))
    print(f"BisoImuPlugin (1 ms truth steps, biso_plus), {steps} steps; numba (field + MPU9250.simulate + "
          f"estimator, batch) {numba * 1e6:.2f} µs per 1 ms")
    outputs = [f"gyro_b.{c}" for c in AXES] + EST_OUT + ["error.total"]
    for version in ("fmi2", "fmi3"):
        c = _master_per_step(master, paths[f"BisoImuPlugin-{version}"], 0.001, rows, start, tmp / f"p{version}")
        with FmuInstance(paths[f"BisoImuPlugin-{version}"], "bench", start_values=start) as fmu:
            f = _fmpy_loop(fmu, TRUTH, data, outputs, 0.001)
        print(f"  {version}: C master {c * 1e6:6.3f} µs per 1 ms step ({c / numba:5.2f}× numba; goal ≤ 5 µs: "
              f"{'met' if c <= 5e-6 else 'NOT met'}), FMPy {f * 1e6:6.1f} µs per step")


def _numba_path(h, omega, force, q_wb, pos) -> float:
    """Seconds per truth row of the plug-in's work on the numba path (batch calls)."""
    from biso_cosim.estimators import make_estimator
    from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment

    env = MagneticEnvironment(EarthField())
    for warm in (True, False):
        n = 50 if warm else len(omega)
        imu = MPU9250("mpu9250_calibrated", seed=0, input_rate_hz=1.0 / h)
        est = make_estimator("biso_plus", imu.output_rate_hz, declination_rad=env.earth.declination_rad)
        t0 = time.perf_counter()
        s = imu.simulate(omega[:n], force[:n], env.field_b(q_wb[:n], pos[:n]))
        est.update(s.gyro_b, s.accel_b, s.mag_b)
        elapsed = time.perf_counter() - t0
    return elapsed / len(omega)


def route(paths, master, name: str, tmp: Path, with_vehicle: bool) -> None:
    from biso_cosim.cosim import CoSimulation

    sim = CoSimulation(name, seed=0, estimators=["biso"])
    t0 = time.perf_counter()
    result = sim.run()
    run_s = time.perf_counter() - t0
    t = result.truth
    h = float(np.median(np.diff(t.t_s)))
    rows = {f"omega_b.{c}": t.omega_b[:, k] for k, c in enumerate(AXES)}
    rows.update({f"specific_force_b.{c}": t.specific_force_b[:, k] for k, c in enumerate(AXES)})
    rows.update({f"q_wb.{c}": t.q_wb[:, k] for k, c in enumerate(QUAT)})
    rows.update({f"pos_w.{c}": t.pos_w[:, k] for k, c in enumerate(AXES)})
    n = len(t.t_s)
    numba = _numba_path(h, t.omega_b, t.specific_force_b, t.q_wb, t.pos_w) * n
    native = _master_per_step(master, paths["BisoImuPlugin-fmi2"], h, rows, {"estimator": "biso_plus"},
                              tmp / "route") * n
    print(f"{name} ({sim.duration_s:g} s) fed from its recorded truth ({n} rows, {h * 1e3:g} ms): native plug-in in "
          f"the C master {native * 1e3:.1f} ms, numba path {numba * 1e3:.1f} ms: {native / numba:.2f}× "
          f"(goal ≤ 1.5×: {'met' if native <= 1.5 * numba else 'NOT met'})")
    if with_vehicle:
        outputs = ([f"truth.q_wb.{c}" for c in QUAT] + [f"gyro_b.{c}" for c in AXES] + EST_OUT + ["error.total"])
        with FmuInstance(paths["BisoVehicle-fmi2"], "bench", start_values={"route": name, "estimator": "biso"},
                         stop_time=sim.duration_s) as fmu:
            vr_out = [fmu.variables[k].valueReference for k in outputs]
            raw = fmu.fmu
            tt, t0 = 0.0, time.perf_counter()
            for _ in range(sim.n_chunks):
                raw.doStep(tt, 0.02)
                raw.getReal(vr_out)
                tt += 0.02
            fmu_s = time.perf_counter() - t0
        print(f"BisoVehicle-fmi2.fmu (Python-based) over {name} in FMPy {fmu_s:.1f} s, CoSimulation.run {run_s:.1f} s: "
              f"{fmu_s / run_s:.2f}×")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="steps of the per-step measurements (default 20000)")
    parser.add_argument("--route", default="loop600", help="route of the whole-run comparison (default loop600)")
    parser.add_argument("--no-vehicle", action="store_true", help="leave out BisoVehicle (Python-based)")
    args = parser.parse_args()
    from biso_cosim.fmu.build import built_fmus

    names = ("BisoEstimator", "BisoImuPlugin") + (() if args.no_vehicle else ("BisoVehicle",))
    paths = built_fmus(names)
    with tempfile.TemporaryDirectory(prefix="biso_bench_") as tmp:
        tmp = Path(tmp)
        master = compile_master(tmp)
        estimator(paths, master, args.steps, tmp)
        plugin(paths, master, args.steps, tmp)
        route(paths, master, args.route, tmp, not args.no_vehicle)


if __name__ == "__main__":
    main()
