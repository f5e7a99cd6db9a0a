"""Cost of the co-simulation against bare MuJoCo stepping of the same model.

For each route: the wall time of the full co-simulation (driver, physics, virtual MPU-9250,
the estimators, logging) and of bare ``mj_step`` calls over the same number of steps with
the same car (its model without the sensor history the co-simulation reads its rows from),
from the same settled start, replaying the same actuator commands (so the physics does the
same work), in the same process; and their ratio (``ratio``; ``r nstep`` against one
``mj_step(model, data, nstep)`` call per control period, the stricter baseline). The three
run one after the other in each repetition, seconds apart: the ratios are the medians of
each repetition's ratios (on a machine shared with other jobs the speed drifts by tens of
per cent over minutes). Also the share of each layer, timed separately over one run.

    python benchmarks/cosim_overhead.py                 # every shipped route, 60 s each
    python benchmarks/cosim_overhead.py --routes loop600 --duration 600
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from biso_cosim.cosim import CoSimulation
from biso_cosim.routes import route_names
from biso_cosim.vehicle.sim import PHYSICS_STATE
from env_steps import bare_model


def record_controls(sim: CoSimulation) -> np.ndarray:
    """The actuator commands of each control period of a run."""
    sim.reset()
    controls = []
    while not sim.done:
        sim.step()
        controls.append(sim.vehicle.data.ctrl.copy())
    return np.array(controls)


def bare_steps(sim: CoSimulation, controls: np.ndarray, nstep: bool = False) -> float:
    """Step the same car from the same start with the same commands, nothing else: one
    ``mj_step`` call per physics step, or with ``nstep`` one ``mj_step(model, data, nstep)``
    call per control period (as Gymnasium's MuJoCo environments step); the model without the
    sensor history the co-simulation reads its rows from."""
    vehicle = sim.vehicle
    vehicle.reset()
    model = bare_model(vehicle)
    data = mujoco.MjData(model)
    state = np.empty(mujoco.mj_stateSize(model, PHYSICS_STATE))
    mujoco.mj_getState(vehicle.model, vehicle.data, state, PHYSICS_STATE)
    mujoco.mj_setState(model, data, state, PHYSICS_STATE)
    per = vehicle.steps_per_control
    step = mujoco.mj_step
    start = time.perf_counter()
    if nstep:
        for ctrl in controls:
            data.ctrl[:] = ctrl
            step(model, data, per)
    else:
        for ctrl in controls:
            data.ctrl[:] = ctrl
            for _ in range(per):
                step(model, data)
    return time.perf_counter() - start


def layers(sim: CoSimulation) -> dict[str, float]:
    """Wall time of each layer over one run, by timing each call of the loop."""
    sim.reset()
    clock = time.perf_counter
    spent = {"driver": 0.0, "physics": 0.0, "magnetic field": 0.0, "sensor": 0.0, "estimators": 0.0, "rest": 0.0}
    total_start = clock()
    vehicle = sim.vehicle
    for _ in range(sim.n_chunks):
        t0 = clock()
        vehicle.drive()
        t1 = clock()
        truth = vehicle.step()
        t2 = clock()
        mag = sim.magnetic.field_b(truth.q_wb, truth.pos_w)
        t3 = clock()
        samples = sim.imu.simulate(truth.omega_b, truth.specific_force_b, mag)
        t4 = clock()
        for est in sim.estimators.values():
            est.update(samples.gyro_b, samples.accel_b, samples.mag_b)
        t5 = clock()
        spent["driver"] += t1 - t0
        spent["physics"] += t2 - t1
        spent["magnetic field"] += t3 - t2
        spent["sensor"] += t4 - t3
        spent["estimators"] += t5 - t4
    spent["rest"] = clock() - total_start - sum(spent.values())
    return spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--routes", nargs="+", default=route_names(), choices=route_names())
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds per route")
    parser.add_argument("--repeat", type=int, default=5, help="repetitions; medians of the times and of the "
                        "ratios within each repetition")
    args = parser.parse_args()
    print(f"{'route':<10} {'steps':>8} {'cosim s':>9} {'bare s':>9} {'nstep s':>9} {'ratio':>7} {'r nstep':>8} "
          f"{'µs/step':>8} {'bare µs':>8}")
    for name in args.routes:
        sim = CoSimulation(name, duration_s=args.duration, seed=0)
        controls = record_controls(sim)  # also compiles the kernels and warms the caches
        n_steps = sim.n_chunks * sim.vehicle.steps_per_control
        times = []  # (cosim, bare, nstep) of each repetition, seconds apart
        for _ in range(args.repeat):
            sim.reset()
            start = time.perf_counter()
            sim.run()
            times.append((time.perf_counter() - start, bare_steps(sim, controls), bare_steps(sim, controls, nstep=True)))
        t = np.array(times)
        cosim, bare, nstep = np.median(t, axis=0)
        print(f"{name:<10} {n_steps:>8} {cosim:>9.3f} {bare:>9.3f} {nstep:>9.3f} "
              f"{np.median(t[:, 0] / t[:, 1]):>7.3f} {np.median(t[:, 0] / t[:, 2]):>8.3f} "
              f"{cosim / n_steps * 1e6:>8.2f} {bare / n_steps * 1e6:>8.2f}")
        spent = layers(sim)
        total = sum(spent.values())
        print("    share of the loop: " + ", ".join(f"{k} {100 * v / total:.1f} %" for k, v in spent.items()))


if __name__ == "__main__":
    main()
