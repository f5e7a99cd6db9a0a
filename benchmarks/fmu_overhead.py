"""Cost of running the models as FMUs in FMPy against the same work called directly in Python.

Per-step cost of each FMU (fmi2SetReal of the inputs, fmi2DoStep, fmi2GetReal of the main
outputs, by value reference: what a master does each step) against the Python call that
does the same work; and the wall time of a whole route through ``BisoVehicle.fmu`` against
``CoSimulation(...).run()`` (what ``biso-cosim run`` runs), both measured in this process.

    python benchmarks/fmu_overhead.py                         # loop600, the whole route
    python benchmarks/fmu_overhead.py --duration 60 --steps 2000
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from biso_cosim.fmu.host import FmuInstance
from biso_cosim.fmu.variables import AXES, QUAT
from biso_cosim.motions import make_motion


def _loop(fmu: FmuInstance, inputs: list[str], rows: np.ndarray, outputs: list[str], step: float) -> float:
    """Seconds per step of set inputs / doStep / get outputs through FMPy."""
    var = fmu.variables
    vr_in = [var[n].valueReference for n in inputs]
    vr_out = [var[n].valueReference for n in outputs]
    raw = fmu.fmu
    values = rows.tolist()
    t, start = 0.0, time.perf_counter()
    for row in values:
        raw.setReal(vr_in, row)
        raw.doStep(t, step)
        raw.getReal(vr_out)
        t += step
    return (time.perf_counter() - start) / len(values)


def estimator(path: Path, steps: int) -> tuple[float, float, float]:
    from biso_cosim.estimators import make_estimator

    m = make_motion("tumble", duration_s=steps / 200.0, fs_hz=200.0)
    rows = np.hstack([m.omega_b, m.specific_force_b, m.mag_b])
    inputs = [f"{h}.{c}" for h in ("gyro_s", "accel_s", "mag_s") for c in AXES]
    with FmuInstance(path, "bench") as fmu:
        per_fmu = _loop(fmu, inputs, rows, [f"estimate.q_wb.{c}" for c in QUAT], 0.005)
    est = make_estimator("biso", 200.0)
    g, a, mag = (np.ascontiguousarray(x[:, None, :]) for x in (m.omega_b, m.specific_force_b, m.mag_b))
    start = time.perf_counter()
    for i in range(len(m)):
        est.update(g[i], a[i], mag[i])
    per_python = (time.perf_counter() - start) / len(m)
    est.reset()
    start = time.perf_counter()
    est.update(m.omega_b, m.specific_force_b, m.mag_b)
    per_batch = (time.perf_counter() - start) / len(m)
    return per_fmu, per_python, per_batch


def plugin(path: Path, steps: int) -> tuple[float, float]:
    from biso_cosim.estimators import make_estimator
    from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment

    m = make_motion("circle", duration_s=steps / 1000.0, fs_hz=1000.0)
    rows = np.hstack([m.omega_b, m.specific_force_b, m.q_wb])
    inputs = ([f"omega_b.{c}" for c in AXES] + [f"specific_force_b.{c}" for c in AXES]
              + [f"q_wb.{c}" for c in QUAT])
    outputs = [f"gyro_b.{c}" for c in AXES] + [f"estimate.q_wb.{c}" for c in QUAT] + ["error.total"]
    with FmuInstance(path, "bench") as fmu:
        per_fmu = _loop(fmu, inputs, rows, outputs, 0.001)
    earth = EarthField()
    env = MagneticEnvironment(earth)
    imu = MPU9250("mpu9250_calibrated", seed=0, input_rate_hz=1000.0)
    est = make_estimator("biso", imu.output_rate_hz, declination_rad=earth.declination_rad)
    zero = np.zeros((1, 3))
    start = time.perf_counter()
    for i in range(len(m)):
        q = m.q_wb[i:i + 1]
        s = imu.simulate(m.omega_b[i:i + 1], m.specific_force_b[i:i + 1], env.field_b(q, zero))
        if len(s.t_s):
            est.update(s.gyro_b, s.accel_b, s.mag_b)
    per_python = (time.perf_counter() - start) / len(m)
    return per_fmu, per_python


def vehicle(path: Path, route: str, duration: float | None) -> tuple[float, float, float]:
    from biso_cosim.cosim import CoSimulation

    sim = CoSimulation(route, duration_s=duration, seed=0, estimators=["biso"])
    duration = sim.duration_s
    start = time.perf_counter()
    sim.run()
    python_s = time.perf_counter() - start
    outputs = ([f"truth.q_wb.{c}" for c in QUAT] + [f"gyro_b.{c}" for c in AXES] + [f"accel_b.{c}" for c in AXES]
               + [f"mag_b.{c}" for c in AXES] + [f"estimate.q_wb.{c}" for c in QUAT] + ["error.total", "sample_time"])
    with FmuInstance(path, "bench", start_values={"route": route, "estimator": "biso"}, stop_time=duration) as fmu:
        vr_out = [fmu.variables[n].valueReference for n in outputs]
        raw = fmu.fmu
        n = sim.n_chunks
        t, start = 0.0, time.perf_counter()
        for _ in range(n):
            raw.doStep(t, 0.02)
            raw.getReal(vr_out)
            t += 0.02
        fmu_s = time.perf_counter() - start
    return duration, python_s, fmu_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000, help="steps of the per-step measurements (default 4000)")
    parser.add_argument("--route", default="loop600", help="route of the whole-run comparison (default loop600)")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="simulated seconds of the whole run (default: the route's, as biso-cosim run)")
    parser.add_argument("--fmus", default=None, metavar="DIR", help="directory with built FMUs (default: build now)")
    args = parser.parse_args()
    if args.fmus:
        paths = {n: Path(args.fmus) / f"{n}.fmu" for n in ("BisoEstimator", "BisoImuPlugin", "BisoVehicle")}
    else:
        from biso_cosim.fmu.build import built_fmus

        paths = built_fmus()
    estimator(paths["BisoEstimator"], 200)  # compile and warm up both paths
    plugin(paths["BisoImuPlugin"], 200)

    fmu, python, batch = estimator(paths["BisoEstimator"], args.steps)
    print(f"BisoEstimator: {fmu * 1e6:7.1f} µs per step in FMPy; estimator.update per sample in Python "
          f"{python * 1e6:6.1f} µs ({fmu / python:5.1f}×); batch {batch * 1e6:.2f} µs/sample ({fmu / batch:.0f}×)")
    fmu, python = plugin(paths["BisoImuPlugin"], args.steps)
    print(f"BisoImuPlugin: {fmu * 1e6:7.1f} µs per 1 ms step in FMPy; MPU9250.simulate + estimator per 1 ms "
          f"in Python {python * 1e6:6.1f} µs ({fmu / python:5.1f}×)")
    duration, python_s, fmu_s = vehicle(paths["BisoVehicle"], args.route, args.duration)
    print(f"BisoVehicle:   {args.route}, {duration:g} s simulated: CoSimulation.run (biso-cosim run) "
          f"{python_s:6.1f} s, through BisoVehicle.fmu in FMPy {fmu_s:6.1f} s: {fmu_s / python_s:.3f}× "
          "(aim ≤ 1.5×)")


if __name__ == "__main__":
    main()
