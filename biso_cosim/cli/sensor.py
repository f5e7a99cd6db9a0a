"""``biso-cosim sensor``: the virtual MPU-9250's validation, tables and configuration.

    biso-cosim sensor allan --hours 1 --out DIR    static run, Allan deviations vs the model
    biso-cosim sensor table [--profile NAME]       the parameter and chip tables (Markdown)
    biso-cosim sensor table --docs docs/sensors.md rewrite the tables embedded in that file
    biso-cosim sensor info [--profile NAME] [--seed N] [--set FIELD=VALUE ...]
                                                  registers, rates, filters, drawn errors
"""

from __future__ import annotations

import argparse
import json
import math


def _register_fields(pairs: list[str]) -> dict[str, object]:
    """``["smplrt_div=0", "mag_bit16=false"]`` -> register fields (ints, 0x.. or booleans)."""
    fields: dict[str, object] = {}
    for pair in pairs or []:
        name, sep, text = pair.partition("=")
        if not sep:
            raise ValueError(f"--set expects FIELD=VALUE, got {pair!r}")
        low = text.strip().lower()
        if low in ("true", "false"):
            fields[name.strip()] = low == "true"
        else:
            try:
                fields[name.strip()] = int(text, 0)
            except ValueError:
                raise ValueError(f"--set {name}: {text!r} is not an integer or true/false") from None
    return fields


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "sensor",
        help="virtual MPU-9250: Allan validation, parameter tables, configuration",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="sensor_command", metavar="ACTION", required=True)

    allan = sub.add_parser("allan", help="simulate a static sensor and compare its Allan deviation with the model")
    allan.add_argument("--hours", type=float, default=1.0, help="simulated duration in hours (default 1)")
    allan.add_argument("--seed", type=int, default=0, help="seed of the part and its noise (default 0)")
    allan.add_argument("--profile", default="mpu9250", help="profile name or TOML file (default mpu9250)")
    allan.add_argument("--smplrt-div", type=int, default=0, help="SMPLRT_DIV (default 0: output at the 1 kHz internal rate)")
    allan.add_argument("--out", required=True, help="output folder for results.json and allan.png")
    allan.set_defaults(func=_allan)

    table = sub.add_parser("table", help="print the parameter and chip tables (Markdown)")
    table.add_argument("--profile", default="mpu9250", help="profile whose values fill the table (default mpu9250)")
    table.add_argument("--docs", metavar="FILE", help="rewrite the generated blocks of this Markdown file instead of printing")
    table.set_defaults(func=_table)

    info = sub.add_parser("info", help="show registers, rates, filter designs and the errors a seed draws")
    info.add_argument("--profile", default="mpu9250")
    info.add_argument("--seed", type=int, default=0)
    info.add_argument("--set", action="append", metavar="FIELD=VALUE", help="register field, e.g. --set smplrt_div=9 (repeatable)")
    info.set_defaults(func=_info)


def _allan(args) -> int:
    from biso_cosim.sensors.allan import validate_static

    if not (math.isfinite(args.hours) and args.hours > 0):
        raise ValueError(f"--hours must be positive, got {args.hours}")
    results = validate_static(args.hours, seed=args.seed, profile=args.profile, registers={"smplrt_div": args.smplrt_div}, out_dir=args.out)
    print(f"static {results['profile']} (seed {args.seed}), {args.hours:g} h at {results['output_rate_hz']:g} Hz, simulated in {results['simulation_wall_s']:.1f} s")
    for sensor in ("gyro", "accel"):
        r = results[sensor]
        unit = r["unit"]
        print(f"{sensor}:")
        print(f"  Allan deviation at 1 s / noise density: {', '.join(f'{x:.3f}' for x in r['ratio_at_1s'])}"
              f"  ({'within' if r['pass_at_1s_within_10pct'] else 'NOT within'} 10 %)")
        print(f"  floor: {', '.join(f'{x:.3g}' for x in r['floor_measured'])} {unit} at τ = {', '.join(f'{x:.0f}' for x in r['floor_tau_s'])} s"
              f" (model there {', '.join(f'{x:.3g}' for x in r['floor_model_at_that_tau'])}; 0.664·B = {r['floor_expected_0.664B'][0]:.3g})")
        print(f"  random walk fitted on the longest τ: {', '.join(f'{x:.3g}' for x in r['random_walk_fitted'])} {r['random_walk_unit']}"
              f" (configured {r['random_walk'][0]:.3g}; few independent samples there)")
        print(f"  share of τ ≥ 0.1 s within 3σ of the model: {r['fraction_of_taus_from_0.1s_within_3sigma_of_model']:.0%}")
    print(f"wrote {args.out}/results.json and {args.out}/allan.png")
    return 0 if results["pass"] else 1


def _table(args) -> int:
    from pathlib import Path

    from biso_cosim.sensors.table import chip_table, fill_docs, parameter_table

    if args.docs:
        path = Path(args.docs)
        if not path.is_file():
            raise FileNotFoundError(f"--docs: {args.docs} not found")
        path.write_text(fill_docs(path.read_text(encoding="utf-8")), encoding="utf-8")
        print(f"updated the tables in {path}")
        return 0
    print("## Error parameters\n")
    print(parameter_table(args.profile))
    print("## Chip behaviour set by registers\n")
    print(chip_table())
    return 0


def _info(args) -> int:
    import numpy as np

    from biso_cosim.sensors import MPU9250
    from biso_cosim.units import DEG, MILLI_G

    imu = MPU9250(args.profile, seed=args.seed, registers=_register_fields(args.set))
    print(repr(imu))
    print(imu.registers.describe())
    for name, d in imu.designs.items():
        print(f"{name} DLPF design: low-pass a = {d.lowpass_a:.6f}, all-pass d = {d.allpass_d:.6f}, "
              f"{d.delay_samples} whole samples, group delay {d.group_delay_s * 1e3:.3f} ms at {d.rate_hz:g} Hz")
    e = imu.errors
    with np.printoptions(precision=4, suppress=True):
        print(f"gyro bias (°/s): {e.gyro.bias / DEG}")
        print(f"gyro sensitivity matrix:\n{e.gyro.sensitivity}")
        print(f"accel bias (mg): {e.accel.bias / MILLI_G}")
        print(f"accel sensitivity matrix:\n{e.accel.sensitivity}")
        print(f"AK8963 offset (µT): {e.mag.offset_ut}, ASA: {imu.asa.tolist()}")
    print(json.dumps({"output_rate_hz": imu.output_rate_hz, "mag_rate_hz": imu.mag_rate_hz}))
    return 0
