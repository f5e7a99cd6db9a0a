"""Two FMUs exchanging signals every step in an FMPy master, with a plot.

``python -m biso_cosim.fmu.demos.master [--route figure8] [--duration 30] [--out fmu_demo.png]``

``BisoVehicle-fmi2.fmu`` drives the route; after each of its steps its truth outputs (angular rate,
specific force, attitude, position, velocity at its latest sensor sample) are set as the
inputs of the native ``BisoImuPlugin-fmi2.fmu`` (or ``-fmi3``), which runs its own MPU-9250 (another seed) and estimator on
them, as it would on a host's vehicle model. The plot shows the true attitude, the vehicle's
estimate (its sensor sees the 1 kHz physics) and the plug-in's (it sees the truth at the
50 Hz communication steps, interpolated), and one gyro axis of both sensors.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from biso_cosim.fmu.host import FmuInstance
from biso_cosim.fmu.variables import AXES, QUAT

__all__ = ["connect_vehicle_and_plugin", "main"]

# vehicle output → plug-in input
CONNECTIONS = {
    **{f"truth.omega_b.{c}": f"omega_b.{c}" for c in AXES},
    **{f"truth.specific_force_b.{c}": f"specific_force_b.{c}" for c in AXES},
    **{f"truth.q_wb.{c}": f"q_wb.{c}" for c in QUAT},
    **{f"truth.pos_w.{c}": f"pos_w.{c}" for c in AXES},
    **{f"truth.vel_w.{c}": f"vel_w.{c}" for c in AXES},
}
RECORD_VEHICLE = ["sample_time", "truth.q_wb.w", "truth.q_wb.x", "truth.q_wb.y", "truth.q_wb.z",
                  "estimate.roll", "estimate.pitch", "estimate.heading", "gyro_b.z", "truth.speed"]
RECORD_PLUGIN = ["estimate.roll", "estimate.pitch", "estimate.heading", "gyro_b.z", "error.roll",
                 "error.pitch", "error.heading", "new_samples"]


def connect_vehicle_and_plugin(vehicle_fmu: str | Path, plugin_fmu: str | Path, *, route: str = "figure8",
                               duration_s: float = 30.0, step_s: float = 0.02, plugin_seed: int = 1,
                               estimator: str = "biso") -> dict[str, np.ndarray]:
    """Run the two FMUs connected; the recorded outputs of both, one row per step."""
    n = int(round(duration_s / step_s))
    vehicle = FmuInstance(vehicle_fmu, "vehicle", start_values={"route": route, "estimator": estimator},
                          stop_time=duration_s)
    plugin = FmuInstance(plugin_fmu, "plugin", start_values={"sensor.seed": plugin_seed, "estimator": estimator})
    try:
        rec_v, rec_p = [], []
        outputs = list(CONNECTIONS)
        for _ in range(n):
            if not vehicle.step(step_s):
                raise RuntimeError(f"BisoVehicle refused a step: {vehicle.errors()[-1:]}")
            values = vehicle.get(outputs + RECORD_VEHICLE)
            plugin.set(dict(zip(CONNECTIONS.values(), values[:len(outputs)])))
            if not plugin.step(step_s):
                raise RuntimeError(f"BisoImuPlugin refused a step: {plugin.errors()[-1:]}")
            rec_v.append(values[len(outputs):])
            rec_p.append(plugin.get(RECORD_PLUGIN))
    finally:
        vehicle.close()
        plugin.close()
    v, p = np.array(rec_v, dtype=float), np.array(rec_p, dtype=float)
    out = {f"vehicle.{k}": v[:, i] for i, k in enumerate(RECORD_VEHICLE)}
    out.update({f"plugin.{k}": p[:, i] for i, k in enumerate(RECORD_PLUGIN)})
    return out


def _plot(rec: dict[str, np.ndarray], path: Path, title: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from biso_cosim.metrics import attitude_angles_deg

    t = rec["vehicle.sample_time"]
    truth = attitude_angles_deg(np.stack([rec[f"vehicle.truth.q_wb.{c}"] for c in QUAT], axis=1))
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    for ax, angle in zip(axes[:3], ("roll", "pitch", "heading")):
        ax.plot(t, truth[angle], "k", lw=1.5, label="truth (BisoVehicle)")
        ax.plot(t, np.degrees(rec[f"vehicle.estimate.{angle}"]), lw=1, label="estimate, BisoVehicle")
        ax.plot(t, np.degrees(rec[f"plugin.estimate.{angle}"]), lw=1, ls="--", label="estimate, BisoImuPlugin")
        ax.set_ylabel(f"{angle} (°)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[3].plot(t, np.degrees(rec["vehicle.gyro_b.z"]), lw=1, label="gyro z, BisoVehicle's MPU-9250")
    axes[3].plot(t, np.degrees(rec["plugin.gyro_b.z"]), lw=1, ls="--", label="gyro z, BisoImuPlugin's MPU-9250")
    axes[3].set_ylabel("rate (°/s)")
    axes[3].set_xlabel("time (s)")
    axes[3].legend(loc="upper right", fontsize=8)
    axes[3].grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--route", default="figure8", help="library route (default figure8)")
    parser.add_argument("--duration", type=float, default=30.0, metavar="S", help="simulated seconds (default 30)")
    parser.add_argument("--estimator", default="biso", help="estimator of both FMUs (default biso)")
    parser.add_argument("--fmus", default=None, metavar="DIR",
                        help="directory with BisoVehicle-fmi2.fmu and BisoImuPlugin-fmi2.fmu (default: build them now)")
    parser.add_argument("--out", default="fmu_demo.png", metavar="PNG", help="plot file (default fmu_demo.png)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.duration) and args.duration > 0):
        parser.error("--duration must be positive")
    if args.fmus:
        folder = Path(args.fmus)
        paths = {name: folder / f"{name}.fmu" for name in ("BisoVehicle-fmi2", "BisoImuPlugin-fmi2")}
    else:
        from biso_cosim.fmu.build import built_fmus

        paths = built_fmus(("BisoImuPlugin", "BisoVehicle"))
    rec = connect_vehicle_and_plugin(paths["BisoVehicle-fmi2"], paths["BisoImuPlugin-fmi2"], route=args.route,
                                     duration_s=args.duration, estimator=args.estimator)
    rms = {a: math.degrees(float(np.sqrt(np.mean(rec[f"plugin.error.{a}"] ** 2))))
           for a in ("roll", "pitch", "heading")}
    print(f"{len(rec['vehicle.sample_time'])} steps of 20 ms: BisoVehicle -> BisoImuPlugin ({args.route}, "
          f"{args.estimator}); plug-in estimate RMS error roll {rms['roll']:.3f}°, pitch {rms['pitch']:.3f}°, "
          f"heading {rms['heading']:.3f}°")
    print(f"wrote {_plot(rec, Path(args.out), f'{args.route}: BisoVehicle-fmi2.fmu truth -> BisoImuPlugin-fmi2.fmu (FMPy)')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
