"""The native FMUs' variables in C and in XML, written from ``fmu/variables.py``.

``variables_c(fmu)`` gives ``biso_variables.h`` (counts, a slot macro per variable, the model
header) and ``biso_variables.c`` (the table the FMI shells read: name, type, causality,
variability, start, bounds, and the variable's role in the model); ``model_description(fmu,
fmi_version, ...)`` the ``modelDescription.xml`` of FMI 2.0 or FMI 3.0 from the same list,
so a variable's value reference, type and start value are one fact in both.

Value references: 1, 2, ... in the order of ``variables_of(fmu)`` for both FMI versions
(FMI 3.0 adds ``time``, the independent variable, as 0).
"""

from __future__ import annotations

import math
import re
import uuid
import xml.etree.ElementTree as ET
from typing import Sequence

from biso_cosim import __version__
from biso_cosim.fmu.variables import UNITS, Var, fingerprint, variables_of

__all__ = ["NATIVE_FMUS", "variables_c", "model_description", "build_description", "instantiation_token",
           "slot_macro", "CAPABILITIES"]

NATIVE_FMUS = {
    "BisoEstimator": ("model_estimator.h", "model_estimator.c"),
    "BisoImuPlugin": ("model_imu_plugin.h", "model_imu_plugin.c"),
}
"""The FMUs with a C model, and their model sources (src/fmi)."""

CAPABILITIES = {
    # the estimator takes any whole number of sample periods per step; the plug-in's truth
    # rate is fixed by its first step; the vehicle takes any whole number of control periods
    "BisoEstimator": {"canHandleVariableCommunicationStepSize": True},
    "BisoImuPlugin": {"canHandleVariableCommunicationStepSize": False},
    "BisoVehicle": {"canHandleVariableCommunicationStepSize": True},
}

SUMMARY = {
    "BisoEstimator": "Attitude estimator of biso_cosim (BISO: Aleshkin et al. 2024, its baselines, biso_plus) in C: "
                     "gyro, accelerometer, magnetometer in, attitude q_wb out. Native: needs no Python.",
    "BisoImuPlugin": "Virtual MPU-9250 + AK8963 (registers, DLPF, rates, errors, quantization) and an attitude "
                     "estimator of biso_cosim in C, for another simulator's vehicle: true motion in; readings, raw "
                     "registers, flags, estimate and its error out. Native: needs no Python.",
    "BisoVehicle": "The biso_cosim co-simulation: MuJoCo car on a scripted route (or driven by the inputs), virtual "
                   "MPU-9250 and attitude estimator in the loop; truth, readings and estimate out. Python-based: its "
                   "C shell runs the model on the Python of the host process, or starts the Python that built it; "
                   "that Python must import biso_cosim and its dependencies.",
}
# (stop time, step size): loop600, the vehicle's default route, and 10 s at rest, as biso-cosim run
DEFAULT_EXPERIMENT = {"BisoEstimator": (10.0, 0.005), "BisoImuPlugin": (10.0, 0.001), "BisoVehicle": (580.0, 0.02)}

_TYPES = {"Real": 0, "Integer": 1, "Boolean": 2, "String": 3}
_CAUSALITY = {"parameter": 0, "input": 1, "output": 2}
_VARIABILITY = {"fixed": 0, "tunable": 1, "discrete": 2, "continuous": 3}
# key heads with a generic meaning in the C core (fmu_core.h BISO_ROLE_*); others are the model's.
# "euler_est" (estimate.roll, pitch, yaw, heading) are derived outputs: the model computes them
# from its other outputs when a host first reads one after a step (model_derive_outputs)
_ROLES = {"param": 1, "given": 2, "register": 3, "estimator": 4, "euler_est": 5}
_PREFIX = {"Real": "R", "Integer": "I", "Boolean": "B", "String": "S"}
STRING_LENGTH = 256


def slot_macro(v: Var) -> str:
    """The C macro of a variable's slot in its type's value array, e.g. ``R_GYRO_S_X``."""
    return f"{_PREFIX[v.type]}_" + re.sub(r"[^A-Za-z0-9]", "_", v.name).upper()


def instantiation_token(fmu: str) -> str:
    """The GUID / instantiation token: fixed by the package version and the variables."""
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"biso_cosim/{fmu}/{__version__}/{fingerprint(fmu)}")) + "}"


def _c_str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_double(x: float) -> str:
    if math.isinf(x):
        return "HUGE_VAL" if x > 0 else "-HUGE_VAL"
    return float(x).hex() if x != 0.0 else "0.0"


def _slots(fmu: str) -> tuple[list[Var], dict[str, int], dict[str, int]]:
    variables = list(variables_of(fmu))
    counters = {t: 0 for t in _TYPES}
    slot = {}
    for v in variables:
        slot[v.name] = counters[v.type]
        counters[v.type] += 1
    return variables, slot, counters


def variables_c(fmu: str) -> tuple[str, str]:
    """(``biso_variables.h``, ``biso_variables.c``) of a native FMU."""
    model_header = NATIVE_FMUS[fmu][0]
    variables, slot, counts = _slots(fmu)
    macros = {}
    for v in variables:
        m = slot_macro(v)
        if m in macros:
            raise RuntimeError(f"{fmu}: variables {macros[m]!r} and {v.name!r} map to the same C name {m}")
        macros[m] = v.name
    header = [
        "/* Generated by biso_cosim.fmu.native.model_description at FMU build time: do not edit. */",
        "#ifndef BISO_VARIABLES_H", "#define BISO_VARIABLES_H", "",
        f'#define BISO_FMU_NAME "{fmu}"',
        f'#define BISO_FMU_TOKEN "{instantiation_token(fmu)}"',
        f'#define BISO_FMU_FINGERPRINT "{fingerprint(fmu)}"',
        f"#define BISO_N_VARS {len(variables)}",
        *(f"#define BISO_N_{t.upper()} {counts[t]}" for t in _TYPES),
        f"#define BISO_STRING_LENGTH {STRING_LENGTH}", "",
        "/* slot of each variable in its type's value array (value reference = table index + 1) */",
        *(f"#define {slot_macro(v)} {slot[v.name]}" for v in variables), "",
        '#include "fmu_vars.h"',
        f'#include "{model_header}"', "", "#endif", ""]
    rows = []
    for v in variables:
        start = v.start
        real = float(start) if v.type == "Real" else 0.0
        integer = int(start) if v.type in ("Integer", "Boolean") else 0
        text = _c_str(str(start)) if v.type == "String" else "NULL"
        if v.type == "String" and len(str(start).encode()) >= STRING_LENGTH:
            raise RuntimeError(f"{fmu}: the start value of {v.name} is longer than {STRING_LENGTH - 1} bytes")
        role = _ROLES.get(v.key[0], 0)
        kind, name = (_c_str(v.key[1]), _c_str(_param_entry(v))) if role in (1, 2) else ("NULL", "NULL")
        given = -1
        if role == 1:
            flag = next((w for w in variables if w.key == ("given", v.key[1], v.key[2])), None)
            given = slot[flag.name] if flag else -1
        register = _register_index(v) if role == 3 else -1
        lo, hi = v.min, v.max
        rows.append(
            f"    {{{_c_str(v.name)}, {_TYPES[v.type]}, {_CAUSALITY[v.causality]}, {_VARIABILITY[v.variability]}, "
            f"{role}, {slot[v.name]}, {_c_double(real)}, {integer}, {text}, {int(lo is not None)}, "
            f"{_c_double(lo if lo is not None else 0.0)}, {int(hi is not None)}, {_c_double(hi if hi is not None else 0.0)}, "
            f"{kind}, {name}, {given}, {register}}}")
    source = "\n".join([
        "/* Generated by biso_cosim.fmu.native.model_description at FMU build time: do not edit. */",
        "#include <math.h>", "#include <stddef.h>", "", '#include "biso_variables.h"', "",
        "const biso_var_info biso_vars[BISO_N_VARS] = {", ",\n".join(rows), "};", ""])
    return "\n".join(header), source


def _param_entry(v: Var) -> str:
    """The C parameter entry name of an estimator parameter variable ("k", "speed_point_b_m[1]")."""
    return v.name.split(".", 1)[1] if v.key[0] == "param" else v.key[2]


def _register_index(v: Var) -> int:
    from biso_cosim.fmu.native.constants import REGISTER_FIELDS

    return REGISTER_FIELDS.index(v.key[1])


# --------------------------------------------------------------------------------------
# modelDescription.xml
# --------------------------------------------------------------------------------------


def _xml_double(x: float) -> str:
    return repr(float(x))


def _units(parent: ET.Element, variables: Sequence[Var]) -> None:
    used = sorted({v.unit for v in variables if v.unit})
    if not used:
        return
    units = ET.SubElement(parent, "UnitDefinitions")
    for name in used:
        exponents, factor, offset, displays = UNITS[name]
        unit = ET.SubElement(units, "Unit", name=name)
        base = ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in exponents.items()})
        if factor != 1.0:
            base.set("factor", _xml_double(factor))
        if offset != 0.0:
            base.set("offset", _xml_double(offset))
        for display, (d_factor, d_offset) in displays.items():
            du = ET.SubElement(unit, "DisplayUnit", name=display, factor=_xml_double(d_factor))
            if d_offset:
                du.set("offset", _xml_double(d_offset))


def _log_categories(parent: ET.Element) -> None:
    cats = ET.SubElement(parent, "LogCategories")
    for name, text in (("logStatusWarning", "warnings (e.g. a parameter of another estimator set)"),
                       ("logStatusError", "errors: the refused call and why (variable, allowed values)"),
                       ("logEvents", "information: parameter changes, configuration")):
        ET.SubElement(cats, "Category", name=name, description=text)


def model_description(fmu: str, fmi_version: int, source_files: Sequence[str] = ()) -> bytes:
    """``modelDescription.xml`` of one of our FMUs (native or Python-based) for FMI 2.0 (2)
    or FMI 3.0 (3)."""
    variables = list(variables_of(fmu))
    stop, step = DEFAULT_EXPERIMENT[fmu]
    caps = {"needsExecutionTool": False, "canBeInstantiatedOnlyOncePerProcess": False,
            **CAPABILITIES[fmu]}
    common = {"modelName": fmu, "description": SUMMARY[fmu], "author": "biso_cosim", "version": __version__,
              "license": "MIT (the FMI headers: BSD-2-Clause)", "generationTool": f"biso_cosim {__version__}",
              "variableNamingConvention": "flat"}
    if fmi_version == 2:
        root = ET.Element("fmiModelDescription", fmiVersion="2.0", guid=instantiation_token(fmu),
                          numberOfEventIndicators="0", **common)
        cs = ET.SubElement(root, "CoSimulation", modelIdentifier=fmu)
        for k, v in {**caps, "canGetAndSetFMUstate": True, "canSerializeFMUstate": True,
                     "canInterpolateInputs": False, "canRunAsynchronuously": False,
                     "providesDirectionalDerivative": False}.items():
            cs.set(k, str(v).lower())
        if source_files:
            files = ET.SubElement(cs, "SourceFiles")
            for name in source_files:
                if name.endswith(".c"):
                    ET.SubElement(files, "File", name=name)
    elif fmi_version == 3:
        root = ET.Element("fmiModelDescription", fmiVersion="3.0", instantiationToken=instantiation_token(fmu),
                          **common)
        cs = ET.SubElement(root, "CoSimulation", modelIdentifier=fmu)
        for k, v in {**caps, "canGetAndSetFMUState": True, "canSerializeFMUState": True,
                     "providesIntermediateUpdate": False, "canReturnEarlyAfterIntermediateUpdate": False,
                     "hasEventMode": False, "providesEvaluateDiscreteStates": False}.items():
            cs.set(k, str(v).lower())
    else:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    _units(root, variables)
    _log_categories(root)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stopTime=_xml_double(stop), stepSize=_xml_double(step))
    mv = ET.SubElement(root, "ModelVariables")
    if fmi_version == 3:
        ET.SubElement(mv, "Float64", name="time", valueReference="0", causality="independent",
                      variability="continuous", description="simulation time")
    outputs = []
    for vr, v in enumerate(variables, start=1):
        attrs = {"name": v.name, "valueReference": str(vr), "causality": v.causality, "variability": v.variability,
                 "description": v.description}
        if v.causality == "output":
            attrs["initial"] = "exact"
            outputs.append(vr)
        if fmi_version == 2:
            node = ET.SubElement(mv, "ScalarVariable", attrs)
            typed = ET.SubElement(node, v.type)
        else:
            tag = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}[v.type]
            typed = ET.SubElement(mv, tag, attrs)
        if v.type == "String":
            if fmi_version == 2:
                typed.set("start", str(v.start))
            else:
                ET.SubElement(typed, "Start", value=str(v.start))
        elif v.type == "Boolean":
            typed.set("start", "true" if v.start else "false")
        elif v.type == "Integer":
            typed.set("start", str(int(v.start)))
        else:
            typed.set("start", _xml_double(v.start))
        if v.type == "Real":
            if v.unit:
                typed.set("unit", v.unit)
            if v.display_unit:
                typed.set("displayUnit", v.display_unit)
        if v.min is not None and v.type in ("Real", "Integer"):
            typed.set("min", _xml_double(v.min) if v.type == "Real" else str(int(v.min)))
        if v.max is not None and v.type in ("Real", "Integer"):
            typed.set("max", _xml_double(v.max) if v.type == "Real" else str(int(v.max)))
    ms = ET.SubElement(root, "ModelStructure")
    if fmi_version == 2:
        out = ET.SubElement(ms, "Outputs")
        for vr in outputs:
            ET.SubElement(out, "Unknown", index=str(vr))  # 1-based position = value reference
    else:
        for vr in outputs:
            ET.SubElement(ms, "Output", valueReference=str(vr))
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def build_description(fmu: str, source_files: Sequence[str]) -> bytes:
    """FMI 3.0's ``sources/buildDescription.xml``: one C99 source file set, include directory
    ``sources/``, libm."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=fmu)
    files = ET.SubElement(config, "SourceFileSet", language="C99")
    for name in source_files:
        if name.endswith(".c"):
            ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(files, "IncludeDirectory", name=".")
    ET.SubElement(config, "Library", name="m")
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")
