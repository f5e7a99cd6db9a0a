"""The C data of the native sensor model, written from the Python package's own definitions.

``sensor_data_c()`` returns the text of ``biso_sensor_data.c`` (declared by the hand-written
``src/sensor/biso_sensor_data.h``): every number the C model needs, taken at build time from
the source the Python model reads, so that the two cannot drift apart:

* chip tables: ``sensors/data/mpu9250.toml`` through ``sensors.registers`` (full scales and
  sensitivities in SI as ``Registers`` computes them), the DLPF design of every table row
  (``sensors.dlpf.design_dlpf``, the same calls ``MPU9250`` makes);
* the built-in profiles (and any extra ones given) in SI, through ``Profile.si``/``axes``,
  with their flicker terms (``profile.flicker_terms``);
* the register fields' allowed values and defaults, probed from ``sensors.Registers``;
* the project's ziggurat tables (``sensors._rng``) and NumPy's (``numpy_tables``);
* the WMM coefficient releases pygeomag reads for each base year ``EarthField`` accepts.

Doubles are written as C99 hexadecimal literals: exact on every compiler.
"""

from __future__ import annotations

import dataclasses
import datetime
from typing import Iterable, Sequence

import numpy as np

__all__ = ["sensor_data_c", "REGISTER_FIELDS", "register_allowed", "wmm_years"]

# the order of the C enum BISO_REG_* (include/biso_sensor.h)
REGISTER_FIELDS = ("smplrt_div", "dlpf_cfg", "gyro_fchoice_b", "gyro_fs_sel", "accel_fs_sel", "a_dlpf_cfg",
                   "accel_fchoice_b", "mag_mode", "mag_bit16", "i2c_mst_dly")
N_GM = 16
N_LINE = 8


def _d(x: float) -> str:
    x = float(x)
    if not np.isfinite(x):
        raise ValueError(f"non-finite constant {x!r}")
    return x.hex() if x != 0.0 else ("-0.0" if np.signbit(x) else "0.0")


def _arr(values: Iterable[float]) -> str:
    return "{" + ", ".join(_d(v) for v in values) + "}"


def _mat(rows) -> str:
    return "{" + ", ".join(_arr(r) for r in rows) + "}"


def _str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", " ") + '"'


def register_allowed() -> dict[str, tuple[list[int], int]]:
    """For each register field: the values ``sensors.Registers`` accepts (probed over
    -1..256, booleans as 0/1) and its default."""
    from biso_cosim.sensors import Registers

    fields = [f.name for f in dataclasses.fields(Registers)]
    if tuple(fields) != REGISTER_FIELDS:
        raise RuntimeError(f"sensors.Registers fields {fields} differ from the C enum order {REGISTER_FIELDS}: "
                           "update include/biso_sensor.h and REGISTER_FIELDS together")
    default = Registers()
    out = {}
    for name in fields:
        if isinstance(getattr(default, name), bool):
            out[name] = ([0, 1], int(getattr(default, name)))
            continue
        allowed = []
        for value in range(-1, 257):
            try:
                Registers(**{name: value})
            except (ValueError, TypeError):
                continue
            allowed.append(value)
        out[name] = (allowed, int(getattr(default, name)))
    return out


def _chip() -> str:
    from biso_cosim.sensors import Registers
    from biso_cosim.sensors.dlpf import design_dlpf
    from biso_cosim.sensors.mpu9250 import SLOW_RATE_HZ
    from biso_cosim.sensors.registers import chip_tables
    from biso_cosim.sensors.samples import AK8963_FROM_CHIP

    t = chip_tables()
    # the gyro rows in the order gyro_row() picks them: DLPF_CFG 0..7, FCHOICE_B x1, FCHOICE_B 10
    gyro_regs = [Registers(dlpf_cfg=i) for i in range(8)] + [Registers(gyro_fchoice_b=1), Registers(gyro_fchoice_b=2)]
    accel_regs = [Registers(a_dlpf_cfg=i) for i in range(8)] + [Registers(accel_fchoice_b=1)]
    rows = []
    for reg in gyro_regs:
        g, temp = reg.gyro_dlpf, reg.temperature_dlpf
        d = design_dlpf(g.bandwidth_hz, g.delay_s, g.rate_hz)
        td = design_dlpf(temp.bandwidth_hz, temp.delay_s, g.rate_hz, match_delay=False)
        rows.append((g, d, temp.bandwidth_hz, td.lowpass_a))
    arows = []
    for reg in accel_regs:
        a = reg.accel_dlpf
        arows.append((a, design_dlpf(a.bandwidth_hz, a.delay_s, a.rate_hz), 0.0, 0.0))
    for _, d, _, _ in rows + arows:
        if d.delay_samples > N_LINE:
            raise RuntimeError(f"a DLPF design needs {d.delay_samples} delay samples (C holds {N_LINE})")

    def row(entry, design, temp_bw, temp_a) -> str:
        return (f"{{{_d(entry.bandwidth_hz)}, {_d(entry.delay_s)}, {_d(entry.rate_hz)}, {_d(design.lowpass_a)}, "
                f"{_d(design.allpass_d)}, {design.delay_samples}, {_d(temp_bw)}, {_d(temp_a)}}}")

    fs = [Registers(gyro_fs_sel=i, accel_fs_sel=i) for i in range(4)]
    ak = t["ak8963"]
    parts = [
        "{" + ", ".join(row(*r) for r in rows) + "}",
        "{" + ", ".join(row(*r) for r in arows) + "}",
        _arr(r.gyro_full_scale for r in fs), _arr(r.gyro_lsb_per_unit for r in fs),
        _arr(r.accel_full_scale for r in fs), _arr(r.accel_lsb_per_unit for r in fs),
        _d(t["temperature"]["sensitivity_lsb_per_c"]), _d(t["temperature"]["offset_c"]),
        _d(t["sample_rate"]["dlpf_internal_rate_hz"]),
        str(ak["mode_power_down"]), str(ak["mode_single"]), str(ak["mode_continuous_1"]), str(ak["mode_continuous_2"]),
        _d(ak["continuous_1_rate_hz"]), _d(ak["continuous_2_rate_hz"]), _d(ak["single_measurement_time_ms"]),
        _d(ak["resolution_14bit_ut"]), _d(ak["resolution_16bit_ut"]), _d(ak["max_code_14bit"]),
        _d(ak["max_code_16bit"]), _d(ak["overflow_sum_ut"]),
        _mat(AK8963_FROM_CHIP), _d(SLOW_RATE_HZ),
    ]
    return "const biso_chip_tables biso_chip = {\n    " + ",\n    ".join(parts) + "};\n"


def _inertial(profile, sensor: str) -> str:
    from biso_cosim.sensors.profile import flicker_terms

    taus, sig = flicker_terms(profile.axes(f"{sensor}.bias_instability"), profile.si(f"{sensor}.bias_corner_times"))
    if taus.size > N_GM:
        raise ValueError(f"profile {profile.name!r}: {sensor}.bias_corner_times spans too many decades "
                         f"(at most {(N_GM - 1) / 2:g})")
    tau = np.zeros(N_GM)
    sigma = np.zeros((N_GM, 3))
    tau[:taus.size], sigma[:taus.size] = taus, sig
    g_sens = float(profile.si("gyro.g_sensitivity")) if sensor == "gyro" else 0.0
    parts = [_arr(profile.axes(f"{sensor}.scale_factor")), _d(profile.si(f"{sensor}.cross_axis")),
             _arr(profile.axes(f"{sensor}.scale_factor_tempco")), _arr(profile.axes(f"{sensor}.bias_initial")),
             _arr(profile.axes(f"{sensor}.bias_tempco")), _arr(profile.axes(f"{sensor}.nonlinearity")), _d(g_sens),
             _arr(profile.axes(f"{sensor}.noise_density")), _arr(profile.axes(f"{sensor}.random_walk")),
             str(taus.size), _arr(tau), _mat(sigma)]
    return "{" + ", ".join(parts) + "}"


def _profile(profile) -> str:
    lo, hi = profile.si("mag.asa_range")
    parts = [_str(profile.name), _str(profile.description), _inertial(profile, "gyro"), _inertial(profile, "accel"),
             _arr(profile.axes("mag.noise")), _arr(profile.axes("mag.offset")), _arr((lo, hi)),
             _d(profile.si("temperature.default")), _d(profile.si("temperature.reference")),
             str(int(bool(profile.si("model.dlpf")))), str(int(bool(profile.si("model.quantization"))))]
    return "    {" + ",\n     ".join(parts) + "}"


def wmm_years() -> list[int]:
    """The base years whose dates ``EarthField`` accepts (probed on 1 January of 2000-2049)."""
    from biso_cosim.sensors import EarthField

    years = []
    for year in range(2000, 2050):
        try:
            EarthField(date=datetime.date(year, 1, 1))
        except ValueError:
            continue
        years.append(year)
    if not years or years != list(range(years[0], years[-1] + 1)):
        raise RuntimeError(f"EarthField accepts an unexpected set of years: {years}")
    return years


def _wmm() -> str:
    from pygeomag import GeoMag

    years = wmm_years()
    releases: dict[str, int] = {}
    blocks, names, of_year = [], [], []
    for year in years:
        geomag = GeoMag(base_year=year)
        path = geomag._get_model_filename()  # the file EarthField's GeoMag reads
        if path not in releases:
            (epoch, model, date), records = geomag._read_coefficients_data_from_file()
            name = f"wmm_{len(releases)}"
            rows = ",\n    ".join(_arr(r) for r in records)
            blocks.append(f"static const double {name}[{len(records)}][6] = {{\n    {rows}}};\n")
            names.append(f"{{{_str(model)}, {_str(date)}, {_d(epoch)}, {len(records)}, {name}}}")
            releases[path] = len(releases)
        of_year.append(releases[path])
    return ("".join(blocks) + "const biso_wmm_release biso_wmm_releases[] = {\n    " + ",\n    ".join(names) + "};\n"
            f"const int biso_n_wmm_releases = {len(names)};\n"
            f"const int biso_wmm_first_year = {years[0]}, biso_wmm_last_year = {years[-1]};\n"
            f"const int biso_wmm_release_of_year[] = {{{', '.join(map(str, of_year))}}};\n")


def profiles_for_build(extra: Sequence = ()) -> list:
    """The built-in profiles, then ``extra`` ones (names, paths or `Profile` objects)."""
    from biso_cosim.sensors import Profile
    from biso_cosim.sensors.profile import profile_names

    out = [Profile.load(n) for n in profile_names()]
    for item in extra:
        p = Profile.load(item)
        if any(q.name == p.name for q in out):
            raise ValueError(f"profile name {p.name!r} is taken (built-in or given twice)")
        out.append(p)
    return out


def sensor_data_c(extra_profiles: Sequence = ()) -> str:
    """The text of ``biso_sensor_data.c``."""
    from biso_cosim.fmu.native.numpy_tables import ziggurat_tables
    from biso_cosim.sensors import _rng

    profiles = profiles_for_build(extra_profiles)
    regs = register_allowed()
    reg_arrays = "".join(f"static const int allowed_{n}[] = {{{', '.join(map(str, a))}}};\n"
                         for n, (a, _) in regs.items())
    reg_table = ",\n    ".join(f"{{{_str(n)}, {len(a)}, allowed_{n}, {d}}}" for n, (a, d) in regs.items())
    np_tables = ziggurat_tables()
    np_r = float(np_tables["wi_double"][255]) * 2.0**52  # the ziggurat's R (the last block's edge)
    return "\n".join([
        "/* Generated by biso_cosim.fmu.native.constants at FMU build time: do not edit. */",
        '#include "biso_sensor_data.h"', "",
        _chip(),
        "const biso_profile biso_profiles[] = {\n" + ",\n".join(_profile(p) for p in profiles) + "};",
        f"const int biso_n_profiles = {len(profiles)};", "",
        reg_arrays + f"const biso_register_field biso_registers[BISO_N_REGISTERS] = {{\n    {reg_table}}};", "",
        f"const double biso_zig_x[129] = {_arr(_rng._ZIG_X)};",
        f"const double biso_zig_ratio[128] = {_arr(_rng._ZIG_RATIO)};",
        f"const double biso_zig_r = {_d(_rng._ZIG_R)};", "",
        "const uint64_t biso_np_ki[256] = {" + ", ".join(f"{int(v)}ULL" for v in np_tables["ki_double"]) + "};",
        f"const double biso_np_wi[256] = {_arr(np_tables['wi_double'])};",
        f"const double biso_np_fi[256] = {_arr(np_tables['fi_double'])};",
        f"const double biso_np_zig_r = {_d(np_r)}, biso_np_zig_inv_r = {_d(1.0 / np_r)};", "",
        _wmm(),
    ])
