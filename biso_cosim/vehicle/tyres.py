"""Slip-based tyres: Magic Formula forces computed inside MuJoCo's step by a C engine plugin.

``build_model(..., tyres="magic_formula")`` (``vehicle.model``) gives the four tyre geoms
``condim`` 1 (MuJoCo's contact then carries the normal load only) and adds an instance of
the plugin ``biso.tyres`` (``vehicle/native/tyres.c``, whose header gives the method: Pacejka's
Magic Formula with combined slip and load sensitivity, first-order relaxation of both slips,
low-speed damping, the vertical load from MuJoCo's solved contacts). It is the default
(``DEFAULT_TYRE_MODEL``); ``tyres="coulomb"`` is the car as it was before issue 26: spheres
with MuJoCo's Coulomb friction, which steer kinematically.

The plugin is C, compiled on first use with the system C compiler (the one the native FMUs
use, ``biso_cosim.fmu.native.compiler``) into a cache directory (``$BISO_COSIM_CACHE``, else
``$XDG_CACHE_HOME/biso_cosim``, else ``~/.cache/biso_cosim``), keyed by the source, the
compiler flags and MuJoCo's version, and loaded once per process with
``mujoco.mj_loadPluginLibrary``.

:class:`TyreParams` holds each parameter with its source and its physical range
(``check`` refuses a value outside it, naming the parameter and the range); ``SURFACES``
the friction scale of each road surface. :class:`ChassisParams` holds what the slip-tyre car
has beyond its tyres, with sources and ranges alike: the brakes' torque and front/rear
balance (set on the model's brake actuators), the ABS and the lateral-force compliance
steer (both in the plugin). The plugin also reads the friction of the terrain's surface
patches (``terrain.SurfacePatch``) at each tyre's contact point.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import math
import os
import subprocess
import tempfile
from dataclasses import asdict, dataclass, fields
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from biso_cosim.estimators._base import param
from biso_cosim.units import G0

__all__ = ["TyreParams", "TYRES", "ChassisParams", "CHASSIS", "SURFACES", "TYRE_MODELS", "DEFAULT_TYRE_MODEL",
           "PLUGIN_NAME", "plugin_library", "load_plugin", "magic_formula", "rear_slip_gradient_rad_per_g",
           "tyre_states", "STATE_STRIDE", "surface_friction"]

PLUGIN_NAME = "biso.tyres"
INSTANCE_NAME = "tyres"
"""The plugin instance's name in a car model."""
TYRE_MODELS = ("coulomb", "magic_formula")
"""``coulomb``: MuJoCo's friction on sphere wheels; ``magic_formula``: this module."""
DEFAULT_TYRE_MODEL = "magic_formula"
"""The tyre model of the car wherever none is named (``build_model``, ``VehicleSim``, a route
file without ``tyres``, and through them the CLI, the environments and the FMUs)."""

_BOOK = "Pacejka, Tyre and Vehicle Dynamics (2nd ed. 2006 / 3rd ed. 2012), Appendix 3, Table A3.1"
_TYRE = "205/60 R15 91V car tyre at 2.2 bar, F_z0 = 4000 N (the book's MF parameter set of the class)"

SURFACES = {"dry": 1.0, "wet": 0.7, "gravel": 0.7, "snow": 0.25, "ice": 0.12}
"""Friction scale λ_μ of each road surface against dry asphalt: peak road friction of Wong,
Theory of Ground Vehicles (4th ed. 2008), Table 1.3 (dry asphalt 0.8-0.9, wet asphalt
0.5-0.7, gravel 0.6, hard-packed snow 0.2, ice 0.1), divided by dry asphalt's 0.85."""

# physical ranges of the parameters (closed intervals): what ``TyreParams.check`` accepts
_RANGES = {
    "fz0_n": (1000.0, 20000.0), "fzmax_n": (2000.0, 50000.0), "pcx1": (1.0, 2.0), "pdx1": (0.1, 2.0), "pdx2": (-1.0, 1.0),
    "pex1": (-10.0, 1.0), "pex2": (-10.0, 10.0), "pex3": (-10.0, 10.0), "pkx1": (1.0, 100.0),
    "pkx2": (-50.0, 50.0), "pkx3": (-5.0, 5.0), "pcy1": (1.0, 2.0), "pdy1": (0.1, 2.0),
    "pdy2": (-1.0, 1.0), "pey1": (-10.0, 1.0), "pey2": (-10.0, 10.0), "pky1": (1.0, 100.0),
    "pky2": (0.2, 10.0), "rbx1": (0.0, 50.0), "rbx2": (-50.0, 50.0), "rcx1": (0.5, 2.0),
    "rby1": (0.0, 50.0), "rby2": (-50.0, 50.0), "rcy1": (0.5, 2.0), "sigma_x_m": (0.05, 2.0),
    "sigma_y_m": (0.05, 2.0), "v_low_mps": (0.1, 10.0), "damping_x_ns_per_m": (0.0, 10000.0),
    "damping_y_ns_per_m": (0.0, 100000.0),
}


@dataclass(frozen=True)
class TyreParams:
    """The Magic Formula tyre of the reference car (all four wheels alike). The asymmetric
    terms of the book's set (PEX4, PEY3, the shifts PH*, PV*, RBY3, camber) are left out:
    the forces are odd in each slip."""

    fz0_n: float = param(4000.0, symbol="F_z0", unit="N", doc="nominal load", source=f"{_BOOK}: FNOMIN; {_TYRE}")
    fzmax_n: float = param(10000.0, symbol="F_z,max", unit="N",
                           doc="largest load the formulas see (a larger contact load counts as this much): the "
                               "top of the tyre's range of validity",
                           source="MF-Tyre property files' [VERTICAL_FORCE_RANGE] FZMAX, for which the formulas "
                                  "are fitted; 10000 N = 2.5 F_z0 in the MF-Tyre 6.1 example file of a 205/60 R15 "
                                  "car tyre at 2.2 bar (FNOMIN 4000 N), the class of this set")
    pcx1: float = param(1.685, symbol="p_Cx1", unit="-", doc="shape factor C_x", source=f"{_BOOK}: PCX1")
    pdx1: float = param(1.210, symbol="p_Dx1", unit="-", doc="longitudinal friction μ_x at F_z0", source=f"{_BOOK}: PDX1")
    pdx2: float = param(-0.037, symbol="p_Dx2", unit="-", doc="variation of μ_x with load", source=f"{_BOOK}: PDX2")
    pex1: float = param(0.344, symbol="p_Ex1", unit="-", doc="curvature E_x at F_z0", source=f"{_BOOK}: PEX1")
    pex2: float = param(0.095, symbol="p_Ex2", unit="-", doc="variation of E_x with load", source=f"{_BOOK}: PEX2")
    pex3: float = param(-0.020, symbol="p_Ex3", unit="-", doc="variation of E_x with load squared",
                        source=f"{_BOOK}: PEX3")
    pkx1: float = param(21.51, symbol="p_Kx1", unit="-", doc="slip stiffness K_xκ/F_z at F_z0", source=f"{_BOOK}: PKX1")
    pkx2: float = param(-0.163, symbol="p_Kx2", unit="-", doc="variation of K_xκ/F_z with load",
                        source=f"{_BOOK}: PKX2")
    pkx3: float = param(0.245, symbol="p_Kx3", unit="-", doc="exponent of K_xκ's variation with load",
                        source=f"{_BOOK}: PKX3")
    pcy1: float = param(1.193, symbol="p_Cy1", unit="-", doc="shape factor C_y", source=f"{_BOOK}: PCY1")
    pdy1: float = param(0.990, symbol="p_Dy1", unit="-", doc="lateral friction μ_y at F_z0",
                        source=f"{_BOOK}: PDY1 = -0.990 (ISO sign; here the force opposes the slip)")
    pdy2: float = param(-0.145, symbol="p_Dy2", unit="-", doc="variation of μ_y with load",
                        source=f"{_BOOK}: PDY2 = 0.145 with PDY1's sign turned (μ_y falls with load)")
    pey1: float = param(-1.003, symbol="p_Ey1", unit="-", doc="curvature E_y at F_z0", source=f"{_BOOK}: PEY1")
    pey2: float = param(-0.537, symbol="p_Ey2", unit="-", doc="variation of E_y with load", source=f"{_BOOK}: PEY2")
    pky1: float = param(14.95, symbol="p_Ky1", unit="-", doc="maximum cornering stiffness K_yα/F_z0",
                        source=f"{_BOOK}: PKY1 = -14.95 (ISO sign)")
    pky2: float = param(2.130, symbol="p_Ky2", unit="-", doc="load of the maximum cornering stiffness, /F_z0",
                        source=f"{_BOOK}: PKY2")
    rbx1: float = param(12.35, symbol="r_Bx1", unit="-", doc="combined slip: G_xα's slope factor",
                        source=f"{_BOOK}: RBX1")
    rbx2: float = param(-10.77, symbol="r_Bx2", unit="-", doc="combined slip: G_xα's variation with κ",
                        source=f"{_BOOK}: RBX2")
    rcx1: float = param(1.092, symbol="r_Cx1", unit="-", doc="combined slip: G_xα's shape factor",
                        source=f"{_BOOK}: RCX1")
    rby1: float = param(6.461, symbol="r_By1", unit="-", doc="combined slip: G_yκ's slope factor",
                        source=f"{_BOOK}: RBY1")
    rby2: float = param(4.196, symbol="r_By2", unit="-", doc="combined slip: G_yκ's variation with α",
                        source=f"{_BOOK}: RBY2")
    rcy1: float = param(1.081, symbol="r_Cy1", unit="-", doc="combined slip: G_yκ's shape factor",
                        source=f"{_BOOK}: RCY1")
    sigma_x_m: float = param(0.20, symbol="σ_κ", unit="m", doc="longitudinal relaxation length",
                             source="chosen, shorter than the lateral one; the model: Pacejka 2012, ch. 7")
    sigma_y_m: float = param(0.45, symbol="σ_α", unit="m", doc="lateral relaxation length",
                             source="chosen, of the order of the tyre's radius (σ_α = C_Fα/C_Fy, cornering "
                                    "over lateral carcass stiffness: Pacejka 2012, ch. 7)")
    v_low_mps: float = param(2.0, symbol="v_low", unit="m/s",
                             doc="below it the low-speed damping fades in, as ½(1 + cos(π·V_x/v_low))",
                             source="chosen; the low-speed damping of the transient model: Pacejka 2012, ch. 7-8")
    damping_x_ns_per_m: float = param(3000.0, symbol="k_x,low", unit="N·s/m",
                                      doc="low-speed damping of the longitudinal slip velocity at rest",
                                      source="chosen: about critical for a wheel's spin inertia on the tyre's "
                                             "longitudinal deflection stiffness")
    damping_y_ns_per_m: float = param(8000.0, symbol="k_y,low", unit="N·s/m",
                                      doc="low-speed damping of the lateral slip velocity at rest",
                                      source="chosen: about critical for a corner's share of the car on the "
                                             "tyre's lateral deflection stiffness")

    def check(self) -> None:
        """ValueError naming the parameter and its range for a value out of physical range."""
        _check_ranges(self, _RANGES)
        if not self.fzmax_n > self.fz0_n:
            raise ValueError(f"TyreParams.fzmax_n must be above fz0_n ({self.fz0_n:g} N), got {self.fzmax_n!r}")

    def config(self, chassis: "ChassisParams | None" = None) -> dict[str, str]:
        """The plugin instance's configuration: every parameter by name, exactly (repr), with
        the plugin's parameters of ``chassis`` (default ``CHASSIS``)."""
        self.check()
        values = {**asdict(self), **_plugin_chassis(CHASSIS if chassis is None else chassis)}
        return {name: repr(float(value)) for name, value in values.items()}

    def array(self, chassis: "ChassisParams | None" = None) -> np.ndarray:
        """The parameters in the C plugin's order (``biso_tyres_param_name``), with the
        plugin's parameters of ``chassis`` (default ``CHASSIS``)."""
        self.check()
        lib = _ctypes_library()
        values = {**asdict(self), **_plugin_chassis(CHASSIS if chassis is None else chassis)}
        names = [lib.biso_tyres_param_name(i).decode() for i in range(lib.biso_tyres_param_count())]
        if sorted(names) != sorted(values):
            raise RuntimeError(f"the C plugin's parameters {names} are not TyreParams' and ChassisParams' "
                               f"{sorted(values)}")
        return np.array([values[n] for n in names], dtype=np.float64)

    @staticmethod
    def table() -> str:
        """The parameters as a Markdown table with their ranges (docs/vehicle.md shows it)."""
        return _table(TyreParams, _RANGES)


TYRES = TyreParams()
"""The reference car's tyres."""

_CHASSIS_RANGES = {
    "brake_torque_nm": (1000.0, 20000.0), "brake_balance_front": (0.5, 0.9), "brake_build_up_s": (0.0, 1.0),
    "abs_slip_target": (0.03, 0.4), "abs_gain_per_s": (1.0, 1000.0), "abs_speed_min_mps": (0.1, 10.0),
    "compliance_steer_rad_per_n": (0.0, 3e-5),
}
_PLUGIN_CHASSIS = ("brake_build_up_s", "abs_slip_target", "abs_gain_per_s", "abs_speed_min_mps", "compliance_steer_rad_per_n")
"""The ChassisParams the C plugin reads (the brakes' torque and balance are the model's actuators)."""


@dataclass(frozen=True)
class ChassisParams:
    """Brakes, ABS and steering compliance of the car on the slip-based tyres (the Coulomb
    car keeps car.xml's equal brakes: its logs are the invariants, and with Coulomb friction a
    locked wheel grips as a rolling one, so there is nothing for an ABS to do)."""

    brake_torque_nm: float = param(6000.0, symbol="T_b,max", unit="N·m",
                                   doc="largest brake torque of the four wheels together",
                                   source="chosen: 1.5 g at the wheel radius for the 1300 kg car, enough to lock "
                                          "every wheel on dry asphalt (μ ≈ 1.2 of the tyres), as a real car's "
                                          "brakes can; car.xml's 4 × 1000 N·m give 0.99 g")
    brake_balance_front: float = param(0.75, symbol="φ_f", unit="-",
                                       doc="front axle's share of the brake torque (each wheel's brake damper "
                                           "gain and torque limit; their mean stays car.xml's, so a brake "
                                           "command asks the same total torque)",
                                       source="the ideal share of the axle loads (l_r + z·h)/L at a deceleration "
                                              "z = 0.8 g is 0.76 for this car (l_r = 1.584 m, h = 0.524 m, "
                                              "L = 2.64 m; Wong, Theory of Ground Vehicles, §3.5): the front "
                                              "wheels lock first up to 0.76 g, the ABS handles beyond")
    brake_build_up_s: float = param(0.2, symbol="t_s", unit="s",
                                    doc="build-up time of the brakes (Schwelldauer: from the pressure's first rise "
                                        "to full pressure): each brake's torque limit rises linearly from 0 over "
                                        "t_s once its command turns positive (in the plugin); 0: at once",
                                    source="about 0.2 s for the hydraulic brakes of passenger cars (0.1-0.3 s; the "
                                           "accident-reconstruction convention, e.g. the Austrian court experts' "
                                           "glossary 'Schwellzeit'); braking tests count it, measuring from the "
                                           "pedal (DIN 70012)")
    abs_slip_target: float = param(0.12, symbol="κ_ABS", unit="-",
                                   doc="ABS: braking slip each wheel's modulator holds on dry asphalt (times "
                                       "the surface's λ_μ elsewhere, as the tyre's peak slip moves)",
                                   source="just below the tyres' peak of F_x (κ = 0.13-0.16 at 5000-2300 N: "
                                          "the Magic Formula of TyreParams), on its stable side")
    abs_gain_per_s: float = param(40.0, symbol="k_ABS", unit="1/s",
                                  doc="ABS: rate of the release of the brake torque per unit of slip beyond "
                                      "the target (integral slip control, at the physics rate)",
                                  source="chosen: releases a locking wheel (slip 1) by a third in 10 ms, as a "
                                         "modulator's valves do, without a limit cycle")
    abs_speed_min_mps: float = param(1.5, symbol="v_ABS", unit="m/s",
                                     doc="ABS: below this wheel speed the modulator is off (full brake torque)",
                                     source="ABS systems switch off at walking pace (about 5 km/h)")
    compliance_steer_rad_per_n: float = param(
        5.5e-6, symbol="c_δ", unit="rad/N",
        doc="lateral-force compliance steer: road-wheel angle lost per newton of the front tyres' lateral force "
            "(0.32 °/kN), a torque on the steering hinge against its servo",
        source="the mechanism: Gillespie, Fundamentals of Vehicle Dynamics (1992), ch. 6 (compliance steer adds "
               "c_δ·W_f to the understeer gradient, W_f the front axle load); the value chosen so that the "
               "understeer gradient falls within the class's 2-4 °/g, not taken from a measured car: no "
               "published measurement of a car of the class was found (docs/vehicle.md); it stands in for the "
               "front axle's compliance and roll effects the model leaves out (Bundorf & Leffert, SAE 760713)")

    def check(self) -> None:
        """ValueError naming the parameter and its range for a value out of physical range."""
        _check_ranges(self, _CHASSIS_RANGES)

    @staticmethod
    def table() -> str:
        """The parameters as a Markdown table with their ranges (docs/vehicle.md shows it)."""
        return _table(ChassisParams, _CHASSIS_RANGES)


CHASSIS = ChassisParams()
"""The reference car's brakes, ABS and steering compliance on the slip-based tyres."""


def _table(record, ranges) -> str:
    rows = ["| parameter | symbol | unit | default | range | meaning | source |", "|---|---|---|---|---|---|---|"]
    for f in fields(record):
        lo, hi = ranges[f.name]
        m = f.metadata
        cells = [str(c).replace("|", "\\|") for c in (m["symbol"], m["unit"], m["doc"], m["source"])]
        rows.append(f"| `{f.name}` | {cells[0]} | {cells[1]} | `{f.default!r}` | {lo:g} to {hi:g} | "
                    f"{cells[2]} | {cells[3]} |")
    return "\n".join(rows)


def surface_friction(surface: str | float) -> float:
    """λ_μ of a named surface (``SURFACES``) or a number in (0, 1.5]."""
    if isinstance(surface, str):
        if surface not in SURFACES:
            raise ValueError(f"surface must be one of {', '.join(SURFACES)} or a friction scale in (0, 1.5], "
                             f"got {surface!r}")
        return SURFACES[surface]
    value = float(surface)
    if not (math.isfinite(value) and 0.0 < value <= 1.5):
        raise ValueError(f"surface friction scale must be in (0, 1.5], got {surface!r}")
    return value


def _plugin_chassis(chassis: "ChassisParams") -> dict[str, float]:
    if not isinstance(chassis, ChassisParams):
        raise TypeError(f"chassis_params must be a ChassisParams, got {type(chassis).__name__}")
    chassis.check()
    return {name: float(getattr(chassis, name)) for name in _PLUGIN_CHASSIS}


# ---- the C plugin: build on first use, load once ------------------------------------------

_SOURCE = resources.files("biso_cosim.vehicle").joinpath("native/tyres.c")
_EXTRA_FLAGS = ("-fPIC", "-shared", "-fexceptions", "-fvisibility=hidden")


def _cache_root() -> Path:
    for var, sub in (("BISO_COSIM_CACHE", ""), ("XDG_CACHE_HOME", "biso_cosim")):
        if os.environ.get(var):
            return Path(os.environ[var]) / sub
    return Path.home() / ".cache" / "biso_cosim"


def _mujoco_paths() -> tuple[Path, Path]:
    """(MuJoCo's include directory, its shared library) inside the installed mujoco package."""
    import mujoco

    root = Path(mujoco.__file__).parent
    libs = sorted(root.glob("libmujoco.so*")) or sorted(root.glob("libmujoco*.dylib")) or sorted(root.glob("mujoco*.dll"))
    if not (root / "include" / "mujoco" / "mjplugin.h").is_file() or not libs:
        raise RuntimeError(f"the mujoco package at {root} has no include/mujoco/mjplugin.h or libmujoco: "
                           "the tyre plugin cannot be built")
    return root / "include", libs[0]


@functools.cache
def plugin_library() -> Path:
    """The compiled plugin (built into the cache directory on first use)."""
    import mujoco

    from biso_cosim.fmu.native.compiler import CFLAGS, CompilerNotFound, find_compiler

    include, libmujoco = _mujoco_paths()
    source = _SOURCE.read_bytes()
    key = hashlib.sha256(source + repr((CFLAGS, _EXTRA_FLAGS, mujoco.__version__, str(libmujoco))).encode()).hexdigest()
    folder = _cache_root() / f"tyres-{key[:16]}"
    target = folder / "libbiso_tyres.so"
    if target.is_file():
        return target
    try:
        cc = find_compiler()
    except CompilerNotFound as exc:
        raise CompilerNotFound("the magic_formula tyres are a C plugin compiled on first use: "
                               f"{str(exc).split('; ', 1)[-1]}") from None
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        src = Path(tmp) / "tyres.c"
        src.write_bytes(source)
        out = Path(tmp) / target.name
        args = [*cc.split(), *CFLAGS, *_EXTRA_FLAGS, f"-I{include}", str(src), str(libmujoco),
                f"-Wl,-rpath,{libmujoco.parent}", "-lm", "-o", str(out)]
        done = subprocess.run(args, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"compiling the tyre plugin failed ({' '.join(args)}):\n{done.stderr[-4000:]}")
        os.replace(out, target)  # atomic: another process may build the same at the same time
    return target


@functools.cache
def load_plugin() -> Path:
    """Register the plugin ``biso.tyres`` with MuJoCo (once per process)."""
    import mujoco

    path = plugin_library()
    mujoco.mj_loadPluginLibrary(str(path))
    return path


@functools.cache
def _ctypes_library() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(load_plugin()))
    lib.biso_tyres_param_name.restype = ctypes.c_char_p
    lib.biso_tyres_param_name.argtypes = [ctypes.c_int]
    lib.biso_tyres_param_count.restype = ctypes.c_int
    lib.biso_tyres_state_stride.restype = ctypes.c_int
    dp = ctypes.POINTER(ctypes.c_double)
    lib.biso_tyres_magic_formula.restype = None
    lib.biso_tyres_magic_formula.argtypes = [dp, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                                             dp, dp]
    return lib


def magic_formula(fz_n: float, slip_ratio: float, lateral_slip: float, *, params: TyreParams = TYRES,
                  friction_scale: float = 1.0) -> tuple[float, float]:
    """(F_x, F_y) in N of the plugin's C function at load ``fz_n``, slip ratio κ and lateral
    slip tan α (F_x along the heading, F_y to the left, opposing the lateral slip)."""
    lib = _ctypes_library()
    p = params.array()
    fx, fy = ctypes.c_double(), ctypes.c_double()
    dp = ctypes.POINTER(ctypes.c_double)
    lib.biso_tyres_magic_formula(p.ctypes.data_as(dp), float(fz_n), float(slip_ratio), float(lateral_slip),
                                 float(friction_scale), ctypes.byref(fx), ctypes.byref(fy))
    return fx.value, fy.value


def rear_slip_gradient_rad_per_g(vehicle: dict[str, float], tyres: str = DEFAULT_TYRE_MODEL,
                                 params: TyreParams | None = None) -> float:
    """D_r, the rear axle's steady-state slip angle per g of lateral acceleration, rad: the
    static load of a rear tyre over its cornering stiffness, W_r/C_αr (steady-state
    single-track model, Gillespie, Fundamentals of Vehicle Dynamics, 1992, ch. 6), with
    C_αr = K_yα = p_Ky1·F_z0·sin(2·atan(F_z/(p_Ky2·F_z0))) of ``params`` (default ``TYRES``;
    Pacejka 2012 §4.3). ``vehicle`` holds ``model.vehicle_parameters``' total mass, wheelbase
    and centre-of-mass position. 0 for the coulomb tyres, which steer kinematically (their
    rear axle does not slide sideways below the sudden slide). 0.0776 rad/g (4.45 °/g) for the
    reference car on ``TYRES``; the 40 m ISO 4138 circle measures 4.6-4.9 °/g
    (docs/vehicle.md)."""
    rear = _rear_tyre_at_rest(vehicle, tyres, params)
    if rear is None:
        return 0.0
    w_r, k, _ = rear
    return w_r / k


def _rear_tyre_at_rest(vehicle: dict[str, float], tyres: str,
                       params: TyreParams | None) -> tuple[float, float, TyreParams] | None:
    """(W_r, the static load of a rear tyre, N; its cornering stiffness K_yα there, N/rad; the
    parameters) of ``tyres`` with ``params`` (default ``TYRES``), K_yα = p_Ky1·F_z0·
    sin(2·atan(W_r/(p_Ky2·F_z0))) (Pacejka 2012 §4.3); None for the coulomb tyres."""
    if tyres not in TYRE_MODELS:
        raise ValueError(f"tyres must be one of {', '.join(repr(t) for t in TYRE_MODELS)}, got {tyres!r}")
    if tyres == "coulomb":
        return None
    t = TYRES if params is None else params
    w_r = vehicle["cg_behind_front_axle_m"] / vehicle["wheelbase_m"] * vehicle["total_mass_kg"] * G0 / 2.0
    return w_r, t.pky1 * t.fz0_n * math.sin(2.0 * math.atan(w_r / (t.pky2 * t.fz0_n))), t


def linear_accel_mps2(vehicle: dict[str, float], tyres: str = DEFAULT_TYRE_MODEL,
                      params: TyreParams | None = None, friction_scale: float = 1.0) -> float:
    """a_l, the end of the rear tyres' linear range as a horizontal specific force, m/s²: the
    lateral force per load, times g₀, at which a rear tyre's secant cornering stiffness F_y/α
    (the single-track model's stiffness) has fallen 10 % below K_yα, at its static load W_r on a
    road of friction scale ``friction_scale`` (λ_μ scales the peak, not the stiffness, so the
    range shrinks with it). Pure lateral slip of the Magic Formula (Pacejka 2012 §4.3); beyond
    it the slip angle grows faster than D_r f_y and, at the peak (about 1.04 g here), without
    bound. 6.1 m/s² (0.63 g) for the reference car on ``TYRES`` on a dry road (4.3 wet); 0 for the coulomb
    tyres (no limit: they steer kinematically up to their sudden slide, and their car is the
    one before issue 26, kept as it was)."""
    from scipy.optimize import brentq

    rear = _rear_tyre_at_rest(vehicle, tyres, params)
    if rear is None:
        return 0.0
    w_r, k, t = rear

    def lateral_force_n(alpha: float) -> float:
        return abs(magic_formula(w_r, 0.0, math.tan(alpha), params=t, friction_scale=friction_scale)[1])

    # the secant F_y/α falls monotonically over (0, 0.5 rad): its one crossing of 0.9·K_yα
    alpha = brentq(lambda a: lateral_force_n(a) / (k * a) - 0.9, 1e-4, 0.5, xtol=1e-15)
    return G0 * lateral_force_n(alpha) / w_r


STATE_STRIDE = 18
"""Numbers of the plugin state per wheel (tyres.c: slip ratio, lateral slip, load, F_x, F_y,
in contact, the ABS's release of the brake torque, the friction scale under the tyre, the
brake's built-up share of its torque limit, heading (3), left (3), contact point (3))."""
STATE_COLUMNS = ("slip_ratio", "lateral_slip", "load_n", "fx_n", "fy_n", "in_contact", "abs_release",
                 "friction_scale", "brake_build_up")


def tyre_states(model, data) -> dict[str, np.ndarray]:
    """The plugin's per-wheel quantities now (wheels fl, fr, rl, rr): ``STATE_COLUMNS``."""
    import mujoco

    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_PLUGIN, INSTANCE_NAME)
    if i < 0:
        raise ValueError("the model has no tyre plugin (build it with tyres='magic_formula')")
    adr = int(model.plugin_stateadr[i])
    state = np.asarray(data.plugin_state[adr:adr + 4 * STATE_STRIDE]).reshape(4, STATE_STRIDE)
    return {name: state[:, k].copy() for k, name in enumerate(STATE_COLUMNS)}


WHEEL_GEOMS = ("fl_tyre", "fr_tyre", "rl_tyre", "rr_tyre")


BRAKES = ("brake_fl", "brake_fr", "brake_rl", "brake_rr")
STEER = "steer"


def add_tyre_plugin(spec, params: TyreParams | None = None, chassis: ChassisParams | None = None, *,
                    surfaces: tuple = ()) -> None:
    """Turn the car of ``spec`` (``model.car_spec()``) to the Magic Formula tyres: its tyre
    geoms without MuJoCo's friction (condim 1: the contact carries the normal load only), its
    brakes to the torque and balance of ``chassis`` (default ``CHASSIS``), and an instance of
    the plugin with ``params`` (default ``TYRES``) acting on them (with the ABS and the
    compliance steer of ``chassis``, and the friction of the surface patches ``surfaces``,
    ``terrain.SurfacePatch`` records)."""
    params = TYRES if params is None else params
    chassis = CHASSIS if chassis is None else chassis
    if not isinstance(params, TyreParams):
        raise TypeError(f"tyre_params must be a TyreParams, got {type(params).__name__}")
    config = params.config(chassis)
    load_plugin()
    for name in WHEEL_GEOMS:
        spec.geom(name).condim = 1
    _set_brakes(spec, chassis)
    spec.activate_plugin(PLUGIN_NAME)  # what <extension><plugin plugin=...> does in MJCF
    instance = spec.add_plugin(name=INSTANCE_NAME, plugin_name=PLUGIN_NAME)
    numbers = [number for patch in surfaces for number in patch.plugin_numbers()]
    instance.config = {**config, "wheels": " ".join(WHEEL_GEOMS), "brakes": " ".join(BRAKES), "steer": STEER,
                       "surfaces": " ".join(repr(float(v)) for v in numbers)}


def _set_brakes(spec, chassis: ChassisParams) -> None:
    """Each wheel's brake damper: gain kv_w = 4·φ_w·kv̄ and torque limit φ_w·T_b,max, with φ_w
    the wheel's share (φ_f/2 front, (1 − φ_f)/2 rear) and kv̄ car.xml's gain (the mean of
    the four stays kv̄: a brake command asks the same total torque kv̄·u·Σω)."""
    kv = [-spec.actuator(name).gainprm[2] for name in BRAKES]
    if not (len(set(kv)) == 1 and kv[0] > 0.0):
        raise ValueError(f"the car's brakes {BRAKES} must be damper actuators of one gain, got {kv}")
    for name in BRAKES:
        share = chassis.brake_balance_front / 2 if name in ("brake_fl", "brake_fr") else (1.0 - chassis.brake_balance_front) / 2
        actuator = spec.actuator(name)
        gain = list(actuator.gainprm)
        gain[2] = -4.0 * share * kv[0]
        actuator.gainprm = gain
        actuator.forcerange = [-share * chassis.brake_torque_nm, share * chassis.brake_torque_nm]


def _check_ranges(record: Any, ranges: dict[str, tuple[float, float]]) -> None:
    """ValueError naming the first field of the parameter record outside its (low, high)."""
    for f in fields(record):
        value = getattr(record, f.name)
        lo, hi = ranges[f.name]
        if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"{type(record).__name__}.{f.name} must be in [{lo:g}, {hi:g}] {f.metadata['unit']}, "
                             f"got {value!r}")
