"""What the car's sideslip does to the estimators: each shipped route with the coulomb and the
magic_formula tyres (issue 26, item 3).

Each route is driven (``run_route``, its samples as ``compare.route_dataset`` keeps them: the co-simulation, the scripted
driver, the virtual MPU-9250 with sensor seed ``--seed``) for ``--duration`` seconds, once
with ``tyres = "coulomb"`` (the car as it is: sphere wheels that steer kinematically, so the
rear axle does not slide sideways) and once with ``tyres = "magic_formula"`` (slip-based
tyres on dry asphalt, ``vehicle.tyres``); the same route otherwise (``Route.tyres``). The
estimators biso_plus (with wheel odometry at the rear axle), VQF and imufusion
(``compare.run_method``) run on the same samples of each drive; biso_plus twice: as
``compare`` runs it, with the rear axle's slip angle per g of the car's tyres, D_r = W_r/C_αr
(``rear_slip_gradient_rad_per_g``, which the car gives it: ``VehicleSim.estimator_defaults``;
the single-track model, Gillespie 1992, ch. 6: the rear tyres' static load over their
cornering stiffness, Pacejka 2012 §4.3; 0 for the coulomb tyres, which steer kinematically),
and with D_r = 0 (the rear axle assumed not to slide sideways).

Printed per route and tyre model: the sideslip angle of the rear axle's centre in bends
(β = atan2(v_y, v_x) of its velocity in body axes, from the truth at the sensor's samples;
bends: forward speed above 3 m/s and |v·ω_z| above 1 m/s²), RMS and largest, and the RMS
roll, pitch and heading errors of each estimator over the whole drive; then, per route, the
error that the slipping tyres add (magic_formula minus coulomb), the error that the
no-sideslip assumption adds with them (biso_plus with D_r = 0 minus with the tyres' D_r), and
where biso_plus (with D_r) is not the best of the three in an angle, by how much.

    nice python benchmarks/sideslip.py                          # every route, 120 s, seed 0
    nice python benchmarks/sideslip.py --routes figure8 slalom --duration 60 --json out.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time

import numpy as np

from biso_cosim.compare import Dataset, run_dataset, run_method
from biso_cosim.cosim import CoSimulation
from biso_cosim.estimators import make_estimator
from biso_cosim.metrics import ANGLES, angle_errors_deg
from biso_cosim.routes import load_route, route_names
from biso_cosim.vehicle.model import car_spec, vehicle_parameters
from biso_cosim.vehicle.tyres import rear_slip_gradient_rad_per_g

METHODS = ("biso_plus", "vqf", "imufusion")
"""The three compared; biso_plus with the rear axle's slip angle of the tyres (D_r)."""
NO_SIDESLIP = "biso_plus_dr0"
"""biso_plus with D_r = 0."""
TYRES = ("coulomb", "magic_formula")
BEND_SPEED_MPS = 3.0
BEND_LATERAL_MPS2 = 1.0


def _rotate_to_body(q_wb: np.ndarray, v_w: np.ndarray) -> np.ndarray:
    """v_b = q* ∘ v_w ∘ q for each row (Hamilton, scalar first; docs/design.md §4)."""
    w, x, y, z = q_wb.T
    r = np.empty((len(q_wb), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - w * z)
    r[:, 0, 2] = 2 * (x * z + w * y)
    r[:, 1, 0] = 2 * (x * y + w * z)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - w * x)
    r[:, 2, 0] = 2 * (x * z - w * y)
    r[:, 2, 1] = 2 * (y * z + w * x)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return np.einsum("nji,nj->ni", r, v_w)  # R_wbᵀ v_w


def rear_axle_sideslip(truth) -> dict[str, float]:
    """RMS and largest sideslip of the rear axle's centre in bends, degrees, and the share of
    the drive spent in bends."""
    model = car_spec().compile()
    lever_b = model.site("rear_axle").pos - model.site("imu").pos  # IMU site to the rear axle, body axes
    v_b = _rotate_to_body(truth.q_wb, truth.vel_w) + np.cross(truth.omega_b, lever_b)
    beta = np.degrees(np.arctan2(v_b[:, 1], v_b[:, 0]))
    bends = (v_b[:, 0] > BEND_SPEED_MPS) & (np.abs(v_b[:, 0] * truth.omega_b[:, 2]) > BEND_LATERAL_MPS2)
    if not bends.any():
        return {"rms_deg": math.nan, "max_deg": math.nan, "bends_share": 0.0}
    return {"rms_deg": float(np.sqrt(np.mean(beta[bends] ** 2))), "max_deg": float(np.max(np.abs(beta[bends]))),
            "bends_share": float(bends.mean())}


def drive(route, duration_s: float, seed: int) -> tuple[Dataset, object, bool]:
    """The drive's dataset as ``compare.route_dataset`` builds it (``compare.run_dataset``:
    wheel odometry at the rear axle for biso_plus, the car's D_r), and its truth at the samples."""
    sim = CoSimulation(route, duration_s=duration_s, seed=seed, estimators=("poisson",))
    res = sim.run()
    return run_dataset(sim, res), res.truth, bool(res.completed)


def measure(route_name: str, tyres: str, duration_s: float, seed: int) -> dict:
    route = dataclasses.replace(load_route(route_name), tyres=tyres)
    data, truth, completed = drive(route, duration_s, seed)
    row = {"route": route_name, "tyres": tyres, "completed": completed, "sideslip": rear_axle_sideslip(truth),
           "rear_slip_gradient_rad_per_g": data.vehicle_params["rear_slip_gradient_rad_per_g"], "errors": {}}
    est = make_estimator("biso_plus", data.fs_hz, declination_rad=data.declination_rad,
                         **(data.vehicle_params | {"rear_slip_gradient_rad_per_g": 0.0}))
    outputs = {"biso_plus": run_method("biso_plus", data),
               NO_SIDESLIP: est.update(data.gyro_b, data.accel_b, data.mag_b, speed_mps=data.speed_mps).q_wb}
    for m in METHODS[1:]:
        outputs[m] = run_method(m, data)
    for m, q in outputs.items():
        err = angle_errors_deg(q, data.q_true)
        row["errors"][m] = {a: float(np.sqrt(np.mean(err[a] ** 2))) for a in ANGLES}
    return row


def table(rows: list[dict], duration_s: float, seed: int) -> str:
    """Markdown: per route and tyre model the sideslip and the RMS errors; then the added
    error per route and where biso_plus is not the best."""
    shown = (METHODS[0], NO_SIDESLIP, *METHODS[1:])
    label = {"biso_plus": "biso_plus (D_r)", NO_SIDESLIP: "biso_plus D_r = 0"}
    head = "| route | tyres | rear-axle β in bends RMS / max ° | bends % | " + \
        " | ".join(f"{label.get(m, m)} roll / pitch / heading RMS °" for m in shown) + " |"
    d_r = rear_slip_gradient_rad_per_g(vehicle_parameters(), "magic_formula")
    lines = [f"Each route's first {duration_s:g} s, sensor seed {seed}; D_r = {d_r:.4f} rad/g "
             f"({math.degrees(d_r):.2f} °/g) with magic_formula, 0 with coulomb (biso_plus D_r = 0 the same "
             "numbers there).", "", head, "|---|---|---|---|" + "---|" * len(shown)]
    by = {(r["route"], r["tyres"]): r for r in rows}
    for r in rows:
        s = r["sideslip"]
        cells = [" / ".join(f"{r['errors'][m][a]:.2f}" for a in ANGLES) for m in shown]
        lines.append(f"| {r['route']} | {r['tyres']} | {s['rms_deg']:.2f} / {s['max_deg']:.2f} | "
                     f"{100 * s['bends_share']:.0f} | " + " | ".join(cells) + " |")
    lines += ["", "Added by the slipping tyres (magic_formula − coulomb) and, with them, by the no-sideslip "
              "assumption (biso_plus D_r = 0 − biso_plus with D_r), RMS °:", "",
              "| route | " + " | ".join(f"{label.get(m, m)} roll / pitch / heading" for m in METHODS) +
              " | no-sideslip assumption roll / pitch / heading | biso_plus (D_r) not the best |",
              "|---|" + "---|" * (len(METHODS) + 2)]
    for name in dict.fromkeys(r["route"] for r in rows):
        if (name, "coulomb") not in by or (name, "magic_formula") not in by:
            continue
        c, s = by[(name, "coulomb")]["errors"], by[(name, "magic_formula")]["errors"]
        cells = [" / ".join(f"{s[m][a] - c[m][a]:+.2f}" for a in ANGLES) for m in METHODS]
        cells.append(" / ".join(f"{s[NO_SIDESLIP][a] - s['biso_plus'][a]:+.2f}" for a in ANGLES))
        behind = []
        for tyres, e in (("coulomb", c), ("magic_formula", s)):
            for a in ANGLES:
                best = min(METHODS[1:], key=lambda m: e[m][a])
                if e["biso_plus"][a] > e[best][a]:
                    behind.append(f"{tyres} {a}: {best} {e[best][a]:.2f} vs {e['biso_plus'][a]:.2f}")
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {'; '.join(behind) or '-'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--routes", nargs="+", default=route_names())
    ap.add_argument("--duration", type=float, default=120.0, help="seconds of each route (default 120)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the rows to this file")
    args = ap.parse_args(argv)
    rows = []
    for name in args.routes:
        for tyres in TYRES:
            start = time.perf_counter()
            rows.append(measure(name, tyres, args.duration, args.seed))
            print(f"# {name} {tyres}: {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    print(table(rows, args.duration, args.seed))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
