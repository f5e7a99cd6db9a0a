"""pybullet's racecar with biso_cosim's virtual MPU-9250 and biso_plus on board.

The car (pybullet_data's racecar.urdf, headless) stands, turns left on a steady circle, then
right; the plug-in is fed from its base state every 1 ms physics tick (the chip mounted 10 cm
ahead of and 5 cm above the base, rotated 90° about z). Prints what the chip read against the
host's own truth, and the estimator's errors; ``--plot out.png`` draws them.

    pip install 'biso_cosim[pybullet]'
    python examples/plugin_pybullet_racecar.py --seed 0 --plot racecar.png
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from biso_cosim.plugin import Mounting, PluginOutput
from biso_cosim.plugin.pybullet_racecar import RacecarBridge

G = 9.80665


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0, help="the chip's seed (part and noise)")
    parser.add_argument("--speed", type=float, default=1.5, help="wheel speed, m/s")
    parser.add_argument("--steer", type=float, default=0.3, help="steering angle of the turns, rad")
    parser.add_argument("--turn-s", type=float, default=6.0, help="duration of each turn, s")
    parser.add_argument("--block-ticks", type=int, default=20, help="physics ticks per plug-in call")
    parser.add_argument("--plot", help="write a figure of readings and errors to this PNG file")
    args = parser.parse_args(argv)

    mounting = Mounting(position_m=(0.10, 0.0, 0.05), q_body_chip=(math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)))
    phases = [("rest", 0.0, 0.0, 1.5), ("left", args.speed, args.steer, args.turn_s),
              ("right", args.speed, -args.steer, args.turn_s)]
    runs = []
    with RacecarBridge(seed=args.seed, registers={"accel_fs_sel": 2}, mounting=mounting, speed_from_velocity=True,
                       block_ticks=args.block_ticks) as bridge:
        for name, speed, steer, duration in phases:
            bridge.command(speed, steer)
            runs.append((name, bridge.drive(duration)))

    print(f"pybullet racecar, 1 ms ticks, chip seed {args.seed}; means over the last half of each phase")
    print(f"{'phase':6} {'yaw rate host':>14} {'gyro z':>9} {'v·ω host':>10} {'accel y':>9} {'accel z':>9}"
          f" {'roll':>6} {'pitch':>6} {'heading':>8}  (errors RMS, deg)")
    for name, run in runs:
        out = run.output
        t_mid = 0.5 * (run.t_s[0] + run.t_s[-1])
        ticks, window = run.t_s >= t_mid, out.t_s >= t_mid
        yaw_rate = float(np.mean(run.omega_b[ticks, 2]))
        speed = float(np.mean(np.linalg.norm(run.v_w[ticks, :2], axis=1)))
        # the chip's centripetal acceleration: ω²·(its distance from the centre); v²/R at the base
        centripetal = math.copysign(speed * abs(yaw_rate), yaw_rate) if speed > 0.05 else 0.0
        errors = out.estimates["biso_plus"].errors_deg
        rms = {a: float(np.sqrt(np.mean(errors[a][window] ** 2))) for a in ("roll", "pitch", "heading")}
        gyro, accel = out.gyro_b[window].mean(axis=0), out.accel_b[window].mean(axis=0)
        print(f"{name:6} {yaw_rate:14.4f} {gyro[2]:9.4f} {centripetal:10.4f} {accel[1]:9.4f} {accel[2]:9.4f}"
              f" {rms['roll']:6.2f} {rms['pitch']:6.2f} {rms['heading']:8.2f}")
    if args.plot:
        _plot(runs, args.plot)
        print(f"wrote {args.plot}")
    return 0


def _plot(runs, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = PluginOutput.concatenate([run.output for _, run in runs])
    t = np.concatenate([run.t_s for _, run in runs])
    omega_z = np.concatenate([run.omega_b[:, 2] for _, run in runs])
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    axes[0].plot(t, omega_z, lw=0.6, label="host yaw rate (pybullet)")
    axes[0].plot(out.t_s, out.gyro_b[:, 2], lw=0.8, label="gyro z (plug-in)")
    axes[0].set_ylabel("rad/s")
    axes[1].plot(out.t_s, out.accel_b[:, 1], lw=0.6, label="accel y")
    axes[1].plot(out.t_s, out.accel_b[:, 2] - G, lw=0.6, label="accel z − g")
    axes[1].set_ylabel("m/s²")
    for angle in ("roll", "pitch", "heading"):
        axes[2].plot(out.t_s, out.estimates["biso_plus"].errors_deg[angle], lw=0.8, label=f"{angle} error")
    axes[2].set_ylabel("deg")
    axes[2].set_xlabel("t (s)")
    for ax in axes:
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle("pybullet racecar with biso_cosim.plugin.ImuPlugin (biso_plus)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
