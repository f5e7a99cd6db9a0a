"""Generate the C estimators' constants and parameter tables from the Python definitions.

``python -m biso_cosim.fmu.native.gen`` writes

* ``include/biso_estimators_gen.h``: kinds, flag bits, input validity limits, the
  kernels' numeric constants, the layouts of each estimator's parameters, coefficients
  and state (offsets into the flat arrays the Python estimators use);
* ``src/estimators/biso_est_tables.c``: each kind's parameter table (name, symbol, unit,
  default, allowed range, documentation, tunability, choices) and its fixed parameters;

from the package's own records: ``describe_estimator`` (names, defaults, docs), the
``Params`` type hints (types), ``state_layout`` and the kernel modules' layouts and
constants. ``--check`` exits 1 if the files in the tree are not what the generator
writes now (the test suite runs it). Nothing numeric is typed twice: floats are written
as C99 hexadecimal literals of the Python values.

The allowed ranges are the one part the Python records do not carry (each estimator
checks its values in its ``_coefficients``): they are declared once here, in ``RANGES``,
and ``tests/test_native_estimators.py`` checks them against the Python checks (each
bound accepted, the next double beyond it refused) so that the two cannot drift apart.
"""

from __future__ import annotations

import argparse
import math
import sys
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["NATIVE_KINDS", "RANGES", "CHOICES", "PYTHON_ONLY", "ParamEntry", "kind_entries", "generate", "main"]

HERE = Path(__file__).resolve().parent
HEADER = HERE / "include" / "biso_estimators_gen.h"
TABLES = HERE / "src" / "estimators" / "biso_est_tables.c"

NATIVE_KINDS = ("biso", "positional", "poisson", "dcm_pi", "biso_plus")
"""The estimators with a C implementation (the GNSS-aided ones need a stream of fixes no FMU takes)."""

# Python class → C family (one C implementation per estimator class)
_FAMILIES = {"BisoEstimator": "biso", "DcmPiEstimator": "dcm_pi", "BisoPlusEstimator": "biso_plus"}

_C_INPUTS = ("imu_flags", "speed_mps", "velocity_enu_mps")
"""The optional per-sample inputs (``biso_cosim.estimators._base.INPUTS``) the C update takes."""

PYTHON_ONLY = {"biso": ("gyro_step",)}
"""Parameters without a C counterpart, by family: ``gyro_step`` needs the sensor's
multiple-integral increments (input ``dtheta_b``) and the strapdown coning algorithms,
which the FMUs do not carry; the C code always integrates the held gyro sample ('hold')."""

_INF = math.inf
# family → parameter → (min, max, min_open): the values each estimator's _coefficients accepts
_NONNEG, _POS, _ANY = (0.0, _INF, False), (0.0, _INF, True), (-_INF, _INF, False)
RANGES: dict[str, dict[str, tuple[float, float, bool]]] = {
    "biso": {
        "k": _NONNEG, "k_p": _NONNEG, "cutoff_hz": _POS, "pattern": (12.0, 13.0, False), "norm_gain": _NONNEG,
        "declination_rad": _ANY, "latitude_rad": (-math.radians(89.9), math.radians(89.9), False),
        "altitude_m": (-1.0e4, 1.0e6, False), "stability_rate_rad_s": _NONNEG,
        "gyro_range_rad_s": _POS, "accel_range_mps2": _POS,
    },
    "dcm_pi": {
        "kp_rp": _NONNEG, "ki_rp": _NONNEG, "kp_yaw": _NONNEG, "ki_yaw": _NONNEG,
        "integral_limit_rad_s": _NONNEG, "gravity_mps2": _POS, "declination_rad": _ANY,
        "gyro_range_rad_s": _POS, "accel_range_mps2": _POS,
    },
    "biso_plus": {
        **{name: _NONNEG for name in (
            "tau_acc_s", "tau_acc_speed_s", "k_tilt", "k_heading", "k_p", "bias_limit_rad_s", "rest_time_s",
            "rest_filter_tau_s", "rest_gyro_rad_s", "rest_accel_mps2", "rest_speed_mps", "mag_reject_max_s",
            "tau_field_s", "mag_offset_interval_s", "tau_speed_s", "bias_heading_factor", "mag_disturbance_gain",
            "tau_mag_disturbance_s", "mag_time_skew_s", "bias_heading_factor_free", "speed_slip_hold_s",
            "rear_slip_gradient_rad_per_g", "mag_offset_test_angle_rad", "linear_accel_mps2", "linear_hold_s",
            "mag_offset_shrink_ut")},
        **{name: _POS for name in (
            "accel_gate", "mag_norm_tol", "mag_dip_tol_rad", "gravity_mps2", "mag_noise_ut", "mag_offset_sigma_ut",
            "tau_mag_offset_s", "bias_sigma_init_rad_s", "bias_forgetting_s", "bias_sigma_motion_rad_s",
            "bias_sigma_rest_rad_s", "mag_offset_bias_sigma_rad_s", "field_norm_ut", "gyro_range_rad_s",
            "accel_range_mps2", "accel_gate_free", "mag_heading_noise_ut", "speed_slip_accel_mps2")},
        "tilt_lp_order": (1.0, 2.0, False),
        "dip_rad": (-0.5 * math.pi, 0.5 * math.pi, False), "declination_rad": _ANY, "speed_point_b_m": _ANY,
    },
}
"""Allowed range of every Real and Integer parameter (Booleans and choices have theirs by type)."""


def _reference_methods() -> tuple[str, ...]:
    from biso_cosim.estimators.reference import REFERENCE_METHODS

    return tuple(REFERENCE_METHODS)


CHOICES: dict[str, dict[str, Any]] = {
    "biso": {"reading": lambda: ("D", "L"), "reference": _reference_methods},
}
"""The names a string parameter takes (its C value is the index)."""


@dataclass(frozen=True)
class ParamEntry:
    """One entry of a kind's C parameter vector."""

    name: str            # "k", "speed_point_b_m[1]"
    field: str           # the Python parameter ("speed_point_b_m")
    component: int       # -1, or the index into a 3-vector
    type: str            # REAL | INTEGER | BOOLEAN | CHOICE
    optional: bool
    default: float
    min: float
    max: float
    min_open: bool
    choices: tuple[str, ...]
    symbol: str
    unit: str
    fmi_unit: str
    doc: str
    source: str
    family_index: int    # index into the family's full parameter vector


def _kind_class(kind: str) -> type:
    from biso_cosim.estimators import make_estimator

    return type(make_estimator(kind, 200.0))


def family_of(kind: str) -> str:
    """The C family (implementation) of an estimator kind."""
    name = _kind_class(kind).__name__
    if name not in _FAMILIES:
        raise ValueError(f"estimator {kind!r} ({name}) has no C implementation")
    return _FAMILIES[name]


def _type_of(hint: Any) -> tuple[str, bool, int]:
    """(C type, optional, components) of a Params field's type hint."""
    args = [a for a in typing.get_args(hint) if a is not type(None)] or [hint]
    optional = type(None) in typing.get_args(hint)
    if hint is bool:
        return "BOOLEAN", optional, 1
    if hint is int:
        return "INTEGER", optional, 1
    if hint is str:
        return "CHOICE", optional, 1
    if typing.get_origin(hint) is tuple and len(typing.get_args(hint)) == 3:
        return "REAL", optional, 3
    if float in args:
        return "REAL", optional, 1  # float, float | None, or one gain for all channels
    raise TypeError(f"no C parameter type for {hint!r}")


def _family_entries(family: str) -> list[ParamEntry]:
    """Every C parameter of a family (its Params record, Python-only fields left out)."""
    import dataclasses

    from biso_cosim.estimators import param_table
    from biso_cosim.fmu.variables import fmi_unit

    kind = family  # each family is also the kind of its own name, with nothing fixed
    params_cls = _kind_class(kind).Params
    hints = typing.get_type_hints(params_cls)
    skip = PYTHON_ONLY.get(family, ())
    declared = {f.name for f in dataclasses.fields(params_cls)} - set(skip)
    unknown = (set(RANGES[family]) | set(CHOICES.get(family, {}))) - declared
    if unknown:
        raise ValueError(f"gen.py declares ranges or choices for {sorted(unknown)}, not parameters of {family}")
    out: list[ParamEntry] = []
    for row in param_table(params_cls):
        if row["name"] in skip:
            continue
        ctype, optional, n = _type_of(hints[row["name"]])
        choices: tuple[str, ...] = ()
        if ctype == "CHOICE":
            choices = tuple(CHOICES[family][row["name"]]())
            lo, hi, lo_open = 0.0, float(len(choices) - 1), False
        elif ctype == "BOOLEAN":
            lo, hi, lo_open = 0.0, 1.0, False
        else:
            try:
                lo, hi, lo_open = RANGES[family][row["name"]]
            except KeyError:
                raise ValueError(f"gen.py declares no range for {family}.{row['name']}") from None
        default = row["default"]
        for i in range(n):
            if n == 3:
                value, name = default[i], f"{row['name']}[{i + 1}]"
            else:
                value, name = default, row["name"]
            if value is None:
                value = math.nan
            elif ctype == "CHOICE":
                value = float(choices.index(value))
            out.append(ParamEntry(name, row["name"], i if n == 3 else -1, ctype, optional, float(value), lo, hi,
                                  lo_open, choices, row["symbol"], row["unit"], fmi_unit(row["unit"]), row["doc"],
                                  row["source"], len(out)))
    return out


def kind_entries(kind: str) -> tuple[list[ParamEntry], list[tuple[int, float]]]:
    """A kind's parameter entries (those not fixed by its name) and its fixed parameters
    as (family index, value)."""
    from biso_cosim.estimators import describe_estimator

    family = family_of(kind)
    entries = _family_entries(family)
    fixed = describe_estimator(kind)["fixed"]
    kept = [e for e in entries if e.field not in fixed]
    pinned = [(e.family_index, math.nan if fixed[e.field] is None else float(fixed[e.field]))
              for e in entries if e.field in fixed]
    return kept, pinned


# --------------------------------------------------------------------------------------
# C text
# --------------------------------------------------------------------------------------


def _c_double(x: float) -> str:
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "HUGE_VAL" if x > 0 else "-HUGE_VAL"
    return "0.0" if x == 0.0 and math.copysign(1.0, x) > 0 else float(x).hex()


def _c_string(text: str) -> str:
    """A C string literal: ASCII as is, everything else as octal escapes of its UTF-8 bytes."""
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        if ch in "\\\"":
            out.append("\\" + ch)
        elif 32 <= byte < 127:
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def _macro(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).upper().strip("_")


def _layout_lines(prefix: str, layout: tuple[tuple[str, int], ...], size_name: str) -> list[str]:
    lines, offset = [], 0
    for name, size in layout:
        lines.append(f"#define {prefix}_{_macro(name)} {offset}")
        offset += size
    lines.append(f"#define {size_name} {offset}")
    return lines


def _constants() -> list[tuple[str, float]]:
    """The kernels' numeric constants, by the name of their Python definition."""
    import biso_cosim.estimators._kernels as kernels
    import biso_cosim.estimators.biso as biso
    import biso_cosim.estimators.biso_plus as plus
    import biso_cosim.frames as frames
    import biso_cosim.units as units

    named = [
        (kernels, ("MAX_RATE", "MIN_ACCEL", "MAX_ACCEL", "MIN_MAG", "MAX_MAG", "MAG_PARALLEL_SIN",
                   "SATURATION_FRACTION", "_C2", "_C4", "_C6", "_C8", "_S2", "_S4", "_S6", "_S8", "_X_FIRST")),
        (biso, ("PAPER_K", "PAPER_K_P", "EARTH_RATE", "WGS84_A", "WGS84_E2", "_R1", "_R2", "_R3", "_R4", "_R5",
                "_R6", "_R7", "_R8")),
        (plus, ("_A3", "_A5", "_A7", "_A9", "_A11", "_P0_FIELD", "_FIELD_WALK_UT2_PER_S")),
        (frames, ("_GIMBAL_COS",)),
        (units, ("DEG", "G0")),
        (math, ("pi",)),
    ]
    return [(name.strip("_").upper(), float(getattr(module, name))) for module, names in named for name in names]


def _header() -> str:
    import biso_cosim.estimators.biso as biso
    import biso_cosim.estimators.biso_plus as plus
    import biso_cosim.estimators.dcm_pi as dcm
    from biso_cosim.estimators import flags

    lines = [
        "/* Generated by `python -m biso_cosim.fmu.native.gen` from the Python estimators: do not edit. */",
        "#ifndef BISO_ESTIMATORS_GEN_H",
        "#define BISO_ESTIMATORS_GEN_H",
        "",
        "/* estimator kinds (biso_est_kind) */",
    ]
    lines += [f"#define BISO_EST_KIND_{_macro(k)} {i}" for i, k in enumerate(NATIVE_KINDS)]
    lines += [f"#define BISO_EST_N_KINDS {len(NATIVE_KINDS)}", "", "/* output flag bits (biso_cosim.estimators.flags) */"]
    lines += [f"#define BISO_EST_FLAG_{_macro(name)} {bit}" for bit, name in flags.NAMES.items()]
    lines += ["", "/* bits of the input imu_flags (biso_cosim.sensors.ImuFlag) */"]
    lines += [f"#define BISO_EST_{name} {getattr(flags, name)}"
              for name in sorted((n for n in dir(flags) if n.startswith("IMU_")), key=lambda n: getattr(flags, n))]
    lines += ["", "/* numeric constants of the kernels (the Python definitions' values) */"]
    lines += [f"#define BISO_EST_K_{name} {_c_double(value)}" for name, value in _constants()]
    lines += ["", "/* BISO correction modes */"]
    lines += [f"#define BISO_EST_{name} {getattr(biso, name)}" for name in ("MODE_NONE", "MODE_CLOSED", "MODE_GENERAL")]
    lines += ["", "/* BISO: T = L(Q_NUE_ENU) R(Q_FLU_FUR) (our q_wb components -> the paper's lambda), row-major */"]
    lines.append("#define BISO_EST_K_T_GOST {" + ", ".join(_c_double(x) for x in biso._T_GOST.ravel()) + "}")
    for p, m in biso._PATTERNS.items():
        lines.append(f"#define BISO_EST_K_PATTERN_{p} {{" + ", ".join(_c_double(x) for x in m.ravel()) + "}")
    sizes = {"params": [], "coef": [], "state": []}
    for family, module, cls_kind in (("biso", biso, "biso"), ("dcm_pi", dcm, "dcm_pi"), ("biso_plus", plus, "biso_plus")):
        prefix = f"BISO_EST_{_macro(family)}"
        entries = _family_entries(family)
        lines += ["", f"/* {family}: parameters (the family's full vector), coefficients, state */"]
        lines += [f"#define {prefix}_P_{_macro(e.name)} {e.family_index}" for e in entries]
        lines.append(f"#define {prefix}_N_PARAMS {len(entries)}")
        lines += _layout_lines(f"{prefix}_C", module._COEF_LAYOUT, f"{prefix}_COEF_SIZE")
        lines += _layout_lines(f"{prefix}_S", _kind_class(cls_kind).state_layout, f"{prefix}_STATE_SIZE")
        sizes["params"].append(len(entries))
        sizes["coef"].append(sum(n for _, n in module._COEF_LAYOUT))
        sizes["state"].append(sum(n for _, n in _kind_class(cls_kind).state_layout))
    lines += ["", "/* room in biso_est for any kind */"]
    lines += [f"#define BISO_EST_MAX_{k.upper()} {max(v)}" for k, v in sizes.items()]
    lines += ["", "#endif /* BISO_ESTIMATORS_GEN_H */", ""]
    return "\n".join(lines)


def _tables() -> str:
    from biso_cosim.estimators import describe_estimator, estimator_inputs, make_estimator

    lines = [
        "/* Generated by `python -m biso_cosim.fmu.native.gen` from the Python estimators: do not edit. */",
        "#include <math.h>",
        "",
        '#include "biso_est_internal.h"',
        "",
    ]
    kinds = []
    for kind in NATIVE_KINDS:
        entries, pinned = kind_entries(kind)
        sym = _macro(kind).lower()
        for e in entries:
            if e.choices and e.component <= 0:
                lines.append(f"static const char *const choices_{sym}_{_macro(e.name).lower()}[] = {{"
                             + ", ".join(_c_string(c) for c in e.choices) + "};")
        lines.append(f"static const biso_est_param params_{sym}[] = {{")
        for e in entries:
            choices = f"choices_{sym}_{_macro(e.name).lower()}" if e.choices else "NULL"
            lines.append(
                f"    {{{_c_string(e.name)}, {_c_string(e.symbol)}, {_c_string(e.unit)}, {_c_string(e.fmi_unit)},\n"
                f"     {_c_string(e.doc)},\n"
                f"     {_c_string(e.source)},\n"
                f"     BISO_EST_{e.type}, {int(e.optional)}, 1, {_c_double(e.default)}, {_c_double(e.min)}, "
                f"{_c_double(e.max)}, {int(e.min_open)}, {choices}, {len(e.choices)}}},")
        lines.append("};")
        lines.append(f"static const int family_index_{sym}[] = {{" + ", ".join(str(e.family_index) for e in entries) + "};")
        if pinned:
            lines.append(f"static const biso_est_fixed fixed_{sym}[] = {{"
                         + ", ".join(f"{{{i}, {_c_double(v)}}}" for i, v in pinned) + "};")
        est = make_estimator(kind, 200.0)
        inputs = " | ".join(f"BISO_EST_INPUT_{_macro(n)}" for n in estimator_inputs(kind)
                            if n in _C_INPUTS) or "0"
        kinds.append(
            f"    {{{_c_string(kind)}, {_c_string(describe_estimator(kind)['summary'])},\n"
            f"     BISO_EST_FAMILY_{_macro(family_of(kind))}, {inputs}, {int(est.estimates_bias)},\n"
            f"     params_{sym}, family_index_{sym}, {len(entries)}, "
            f"{f'fixed_{sym}' if pinned else 'NULL'}, {len(pinned)}}},")
        lines.append("")
    lines.append("const biso_est_kind_info biso_est_kinds[BISO_EST_N_KINDS] = {")
    lines += kinds
    lines += ["};", ""]
    return "\n".join(lines)


def generate() -> dict[Path, str]:
    """The generated files: path → text."""
    return {HEADER: _header(), TABLES: _tables()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m biso_cosim.fmu.native.gen", description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a generated file in the tree is out of date")
    args = parser.parse_args(argv)
    stale = []
    for path, text in generate().items():
        current = path.read_text(encoding="utf-8") if path.exists() else None
        if current == text:
            continue
        if args.check:
            stale.append(path)
        else:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
    if stale:
        print("out of date (run python -m biso_cosim.fmu.native.gen): " + ", ".join(map(str, stale)), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
