"""The car's drivetrain and driving resistances: what a drive command becomes at the wheels.

The reference car has the engine and gearbox of an 85 kW compact hatchback (a VW Golf or
Polo 1.0 TSI class car). A drive command ``u`` in [-1, 1] (``DriverCommand.drive``: the
drive torque wanted, as a fraction of the peak wheel torque ``T_peak``) becomes, at every
control period where the controls are written (``vehicle._kernels._apply_controls``, the one
place used by the scripted driver, ``VehicleSim.apply``, ``CoSimulation.step``, the
environments and the FMUs), the torque on the rear differential

    T_wheel = τ_TC(slip) · min(|u|·T_peak, max_g T_g(ω), T_traction),  signed like u,

where, for each forward gear g of overall ratio G_g = i_g·i_final (reverse gear for u < 0),

    n_g = |ω_rear|·G_g·60/(2π)                        engine speed, rpm
    T_g = η·G_g·min(T_e(max(n_g, n_launch)), P_max/ω_e)   0 above the rev limit n_max

* ``T_e``: the engine's full-load torque curve (table, linear in between); the power cap
  ``P_max/ω_e`` makes the power at the crankshaft never exceed ``P_max``;
* below the launch speed ``n_launch`` the clutch slips: the engine holds ``n_launch`` and
  gives its torque there (moving off from rest);
* the gear is the one that gives the most wheel torque at this wheel speed: the ideal
  full-throttle shift points of an automatic gearbox (an upshift where the next gear's
  wheel torque overtakes this one's, or at the rev limit), without a shift time, and
  without a gear state (the gear is a function of the wheel speed, so a saved and restored
  simulation state needs nothing else);
* traction control: the torque is limited to what the rear axle's traction allows at
  μ_TC with the load transfer of the acceleration (``traction_torque_nm``), and ``τ_TC``
  cuts it by the larger drive slip of the two rear wheels, each against the undriven front
  wheel of its side, ``s = max_side (ω_rear,side − ω_front,side)/max(|ω_front,side|, ω_min)``
  (in the direction of drive; in a bend a rear wheel runs on a smaller radius than the front
  wheel of its side, so cornering reads as no slip), leaves the torque alone up to
  ``s_target`` and cuts it linearly to zero at ``s_cut``, as an ESP/ASR system does from the
  wheel-speed sensors: one wheel spinning up through the open differential (the unloaded
  inner wheel in a fast bend) is caught, where the axle's mean slip would let it spin;
* no engine braking: u = 0 leaves the wheels free (as with the clutch open), the brakes
  slow the car; u < 0 engages reverse, whose torque at a forward-rolling car is that of the
  reverse gear at the engine speed |ω_rear|·G_R, none above the rev limit;
* not modelled: the engine's and gearbox's rotating inertia, shift times, turbo lag.

Driving resistances act on the chassis through the ``resistance`` actuator, set with the
drive in the same place: ``F = −(½·ρ·c_w·A·v·|v| + c_rr·m·g·clip(v/v_rr, −1, 1))`` with v
the speed of the undriven front wheels (ω_front·r); the wheels' joint damping in car.xml
adds bearing losses.

One record, :class:`DrivetrainParams` (symbol, unit, value and source of each number), is
the one source of the car's performance figures: :func:`performance` derives the top
speed from it and the car model, and ``routes.limits.car_limits`` takes its figures from
there. ``biso-cosim vehicle performance`` measures them with the MuJoCo car.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators._base import param, param_markdown

__all__ = ["DrivetrainParams", "DRIVETRAIN", "drivetrain_coefficients", "wheel_torque", "resistance_force",
           "top_speed", "RPM_PER_RAD_S"]

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
AIR_DENSITY_KG_M3 = 1.225
"""ISA sea-level air density."""


@dataclass(frozen=True)
class DrivetrainParams:
    """The engine, gearbox and driving resistances of the reference car."""

    torque_curve_rpm: tuple = param(
        (1000.0, 1500.0, 2000.0, 3500.0, 5000.0, 5500.0, 6000.0, 6200.0), symbol="n_i", unit="rpm",
        doc="engine speeds of the full-load torque table",
        source="1.0 TSI 85 kW (EA211 evo, e.g. VW Golf VII/VIII, Polo VI): 200 N·m at 2000-3500 rpm, "
               "85 kW at 5000-5500 rpm (maker's figures)")
    torque_curve_nm: tuple = param(
        (120.0, 165.0, 200.0, 200.0, 162.3, 147.6, 125.0, 115.0), symbol="T_e(n_i)", unit="N·m",
        doc="full-load engine torque at those speeds (linear in between, clamped at the ends)",
        source="the maker's plateau and power band; the ends are a typical turbo three-cylinder's")
    max_power_w: float = param(85_000.0, symbol="P_max", unit="W", doc="rated engine power",
                               source="VW: 85 kW (115 PS)")
    rev_limit_rpm: float = param(6200.0, symbol="n_max", unit="rpm", doc="fuel cut: no torque above it",
                                 source="typical of the engine (red line 6000-6500 rpm)")
    launch_rpm: float = param(2000.0, symbol="n_launch", unit="rpm",
                              doc="engine speed held by the slipping clutch when moving off",
                              source="a full-throttle launch at the start of the torque plateau")
    gear_ratios: tuple = param((3.769, 1.955, 1.281, 0.973, 0.778, 0.642), symbol="i_1..i_6", unit="-",
                               doc="gearbox ratios of the six forward gears",
                               source="6-speed manual of the class (VW MQ200, as listed for the 1.0 TSI)")
    reverse_ratio: float = param(3.182, symbol="i_R", unit="-", doc="reverse gear ratio",
                                 source="same gearbox")
    final_drive: float = param(4.25, symbol="i_final", unit="-", doc="final drive ratio",
                               source="chosen so that about 200 km/h falls at 5500 rpm in 5th gear")
    efficiency: float = param(0.92, symbol="η", unit="-", doc="gearbox and final drive efficiency",
                              source="typical of a manual transaxle")
    traction_friction: float = param(0.9, symbol="μ_TC", unit="-",
                                     doc="traction control: the tyre friction it lets the driven axle use, "
                                         "with the load transfer of the acceleration (a torque limit)",
                                     source="chosen below the tyres' μ = 1 (car.xml): full throttle does not spin "
                                            "the wheels on dry asphalt")
    slip_target: float = param(0.10, symbol="s_target", unit="-",
                               doc="traction control: drive slip up to which the torque is not cut",
                               source="near the peak of a tyre's longitudinal force on dry asphalt")
    slip_cut: float = param(0.40, symbol="s_cut", unit="-", doc="traction control: drive slip at which no torque is left",
                            source="chosen: a linear cut between s_target and s_cut")
    slip_speed_floor_rad_s: float = param(6.0, symbol="ω_min", unit="rad/s",
                                          doc="smallest reference wheel speed of the slip (moving off)",
                                          source="about 2 m/s at the wheel radius")
    drag_area_m2: float = param(0.65, symbol="c_w·A", unit="m²", doc="drag coefficient times frontal area",
                                source="VW Golf VII: c_w = 0.30, A = 2.19 m² (maker's figures)")
    rolling_resistance: float = param(0.010, symbol="c_rr", unit="-", doc="tyre rolling resistance coefficient",
                                      source="passenger-car tyre on asphalt (EU label class C)")
    rolling_speed_mps: float = param(0.5, symbol="v_rr", unit="m/s",
                                     doc="the rolling resistance grows linearly up to this speed (no force at rest)",
                                     source="chosen")

    def check(self) -> None:
        """ValueError naming the field for a record that cannot describe a drivetrain."""
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            if not values or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0 for v in values):
                raise ValueError(f"DrivetrainParams.{f.name} must be positive finite numbers, got {value!r}")
        if len(self.torque_curve_rpm) != len(self.torque_curve_nm):
            raise ValueError("DrivetrainParams.torque_curve_rpm and torque_curve_nm must have the same length")
        if any(b <= a for a, b in zip(self.torque_curve_rpm, self.torque_curve_rpm[1:])):
            raise ValueError(f"DrivetrainParams.torque_curve_rpm must increase, got {self.torque_curve_rpm}")
        if not self.efficiency <= 1.0:
            raise ValueError(f"DrivetrainParams.efficiency must be in (0, 1], got {self.efficiency}")
        if not self.slip_cut > self.slip_target:
            raise ValueError("DrivetrainParams.slip_cut must be > slip_target")

    @property
    def peak_wheel_torque_nm(self) -> float:
        """T_peak: the most torque at the wheels, in first gear at the top of the torque curve."""
        ratio = self.gear_ratios[0] * self.final_drive
        rpm = np.asarray(self.torque_curve_rpm)
        power_cap = self.max_power_w / (rpm / RPM_PER_RAD_S)
        return float(self.efficiency * ratio * np.max(np.minimum(self.torque_curve_nm, power_cap)))

    @staticmethod
    def table() -> str:
        """The parameters as a Markdown table (docs/vehicle.md shows it)."""
        return param_markdown(DrivetrainParams)


DRIVETRAIN = DrivetrainParams()
"""The reference car's drivetrain."""

# drivetrain_coefficients' layout (the kernels' one argument). numba's on-disk cache of a
# kernel that calls these (vehicle/_kernels.py, envs/_kernels.py) is keyed on its own file
# only: after changing the layout or a kernel here, delete the __pycache__/*.nbi of those.
(C_PEAK, C_PMAX, C_REV, C_LAUNCH, C_EFF, C_FINAL, C_REVERSE, C_SLIP_TARGET, C_SLIP_CUT, C_SLIP_FLOOR,
 C_DRAG, C_ROLL, C_ROLL_SPEED, C_RADIUS, C_TRACTION, C_NGEARS, C_NCURVE) = range(17)
C_TABLES = 17
"""The gear ratios follow from here, then the curve's speeds (rpm), then its torques (N·m)."""


def traction_torque_nm(params: DrivetrainParams, *, mass_kg: float, wheel_radius_m: float, rear_load_share: float,
                       cg_height_over_wheelbase: float) -> float:
    """The traction control's torque limit of the rear axle: μ_TC·m·g·(b/L)/(1 − μ_TC·h/L)·r,
    the traction of the rear axle loaded statically (share b/L) plus the load transfer of
    the acceleration itself (h/L), on a flat road."""
    mu = params.traction_friction
    return mu * mass_kg * 9.80665 * rear_load_share / (1.0 - mu * cg_height_over_wheelbase) * wheel_radius_m


def drivetrain_coefficients(params: DrivetrainParams, *, mass_kg: float, wheel_radius_m: float,
                            rear_load_share: float = 0.4, cg_height_over_wheelbase: float = 0.2) -> np.ndarray:
    """The coefficient array of the kernels for ``params`` on a car of ``mass_kg`` with wheels
    of ``wheel_radius_m``, a static load share ``rear_load_share`` on the driven rear axle and
    a centre of mass ``cg_height_over_wheelbase`` high (as a fraction of the wheelbase)."""
    params.check()
    for name, value in (("mass_kg", mass_kg), ("wheel_radius_m", wheel_radius_m),
                        ("rear_load_share", rear_load_share), ("cg_height_over_wheelbase", cg_height_over_wheelbase)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    head = np.zeros(C_TABLES)
    head[C_PEAK], head[C_PMAX], head[C_REV] = params.peak_wheel_torque_nm, params.max_power_w, params.rev_limit_rpm
    head[C_LAUNCH], head[C_EFF], head[C_FINAL] = params.launch_rpm, params.efficiency, params.final_drive
    head[C_REVERSE], head[C_SLIP_TARGET], head[C_SLIP_CUT] = params.reverse_ratio, params.slip_target, params.slip_cut
    head[C_SLIP_FLOOR] = params.slip_speed_floor_rad_s
    head[C_DRAG] = 0.5 * AIR_DENSITY_KG_M3 * params.drag_area_m2
    head[C_ROLL] = params.rolling_resistance * mass_kg * 9.80665
    head[C_ROLL_SPEED], head[C_RADIUS] = params.rolling_speed_mps, wheel_radius_m
    head[C_TRACTION] = traction_torque_nm(params, mass_kg=mass_kg, wheel_radius_m=wheel_radius_m,
                                          rear_load_share=rear_load_share,
                                          cg_height_over_wheelbase=cg_height_over_wheelbase)
    head[C_NGEARS], head[C_NCURVE] = len(params.gear_ratios), len(params.torque_curve_rpm)
    return np.concatenate([head, params.gear_ratios, params.torque_curve_rpm, params.torque_curve_nm])


# ---- kernels -----------------------------------------------------------------------------

@jit
def _engine_torque_nm(c, rpm):
    """Full-load engine torque at ``rpm`` (N·m): the table, clamped at its ends, capped by
    the power; 0 above the rev limit."""
    if rpm > c[C_REV]:
        return 0.0
    n = int(c[C_NCURVE])
    base = C_TABLES + int(c[C_NGEARS])
    if rpm <= c[base]:
        torque = c[base + n]
    elif rpm >= c[base + n - 1]:
        torque = c[base + 2 * n - 1]
    else:
        k = 0
        while c[base + k + 1] < rpm:
            k += 1
        n0, n1 = c[base + k], c[base + k + 1]
        t0, t1 = c[base + n + k], c[base + n + k + 1]
        torque = t0 + (t1 - t0) * (rpm - n0) / (n1 - n0)
    omega_e = rpm / (60.0 / (2.0 * math.pi))
    if torque * omega_e > c[C_PMAX]:
        torque = c[C_PMAX] / omega_e
    return torque


@jit
def _gear_wheel_torque_nm(c, ratio, omega_wheel):
    """Wheel torque (N·m) at full load through the overall ratio ``ratio`` at the wheel speed
    ``omega_wheel`` (rad/s, positive in the gear's direction; magnitude used)."""
    rpm = abs(omega_wheel) * ratio * (60.0 / (2.0 * math.pi))
    if rpm > c[C_REV]:
        return 0.0
    return c[C_EFF] * ratio * _engine_torque_nm(c, max(rpm, c[C_LAUNCH]))


@jit
def _available_torque(c, reverse, omega_wheel):
    """(most wheel torque at full load, N·m; its gear: 1.. forward, -1 reverse, 0 none)."""
    if reverse:
        torque = _gear_wheel_torque_nm(c, c[C_REVERSE] * c[C_FINAL], omega_wheel)
        return torque, -1 if torque > 0.0 else 0
    best, gear = 0.0, 0
    for g in range(int(c[C_NGEARS])):
        torque = _gear_wheel_torque_nm(c, c[C_TABLES + g] * c[C_FINAL], omega_wheel)
        if torque > best:
            best, gear = torque, g + 1
    return best, gear


@jit
def _traction_factor(c, slip):
    """τ_TC: 1 up to s_target, linear down to 0 at s_cut."""
    if slip <= c[C_SLIP_TARGET]:
        return 1.0
    if slip >= c[C_SLIP_CUT]:
        return 0.0
    return (c[C_SLIP_CUT] - slip) / (c[C_SLIP_CUT] - c[C_SLIP_TARGET])


@jit
def _wheel_torque(c, drive, omega_rl, omega_rr, omega_fl, omega_fr):
    """(torque on the rear differential, N·m, signed like ``drive``; gear) for the drive
    command ``drive`` in [-1, 1] at the four wheels' speeds (rad/s): the engine turns with
    the rear wheels' mean (the differential's crown wheel); the traction control cuts by the
    larger drive slip of the two rear wheels, each against the undriven front wheel of its
    side (in the direction of drive; in a bend each rear wheel runs on a smaller radius than
    the front wheel ahead of it, so cornering alone never reads as slip), so that one wheel
    spinning up (the unloaded inner wheel in a bend, through the open differential) is
    caught, not averaged away."""
    if drive == 0.0:
        return 0.0, 0
    sign = 1.0 if drive > 0.0 else -1.0
    rl, rr, fl, fr = sign * omega_rl, sign * omega_rr, sign * omega_fl, sign * omega_fr  # positive in the direction of drive
    available, gear = _available_torque(c, drive < 0.0, 0.5 * (rl + rr))
    torque = min(abs(drive) * c[C_PEAK], available, c[C_TRACTION])
    floor = c[C_SLIP_FLOOR]
    slip = max((rl - fl) / max(abs(fl), floor), (rr - fr) / max(abs(fr), floor))
    return sign * torque * _traction_factor(c, slip), gear


@jit
def _resistance_n(c, omega_front):
    """Driving resistance on the chassis (N, along its x axis) at the front wheels' speed."""
    v = omega_front * c[C_RADIUS]
    roll = min(max(v / c[C_ROLL_SPEED], -1.0), 1.0)
    return -(c[C_DRAG] * v * abs(v) + c[C_ROLL] * roll)


@jit
def _drivetrain_controls(c, drive, wheel_rates):
    """(drive torque, N·m; resistance, N) for the drive command from the wheel spin rates
    ``wheel_rates`` (fl, fr, rl, rr, rad/s)."""
    front = 0.5 * (wheel_rates[0] + wheel_rates[1])
    torque, _ = _wheel_torque(c, drive, wheel_rates[2], wheel_rates[3], wheel_rates[0], wheel_rates[1])
    return torque, _resistance_n(c, front)


# ---- the same in Python, for analysis (the kernels above are what runs) -----------------

def wheel_torque(drive: float, omega_rear_rad_s: float, omega_front_rad_s: float,
                 params: DrivetrainParams = DRIVETRAIN, *, wheel_radius_m: float = 0.316) -> tuple[float, int]:
    """(torque on the rear differential, N·m; gear: 1.. forward, -1 reverse, 0 none) for a
    drive command in [-1, 1] at the mean rear and front wheel speeds: the engine and gearbox
    with the slip cut of the traction control, without its traction limit (which depends on
    the car: ``traction_torque_nm``)."""
    if not -1.0 <= drive <= 1.0:
        raise ValueError(f"drive must be in [-1, 1], got {drive!r}")
    c = drivetrain_coefficients(params, mass_kg=1.0, wheel_radius_m=wheel_radius_m)
    c[C_TRACTION] = math.inf
    rear, front = float(omega_rear_rad_s), float(omega_front_rad_s)
    torque, gear = _wheel_torque(c, float(drive), rear, rear, front, front)
    return float(torque), int(gear)


def resistance_force(speed_mps: float, params: DrivetrainParams = DRIVETRAIN, *, mass_kg: float) -> float:
    """Driving resistance (N, negative against forward motion) at ``speed_mps``."""
    c = drivetrain_coefficients(params, mass_kg=mass_kg, wheel_radius_m=1.0)
    return float(_resistance_n(c, float(speed_mps)))


def top_speed(params: DrivetrainParams = DRIVETRAIN, *, mass_kg: float, wheel_radius_m: float,
              wheel_damping_nms: float = 0.0) -> tuple[float, int]:
    """(top speed on a flat road, m/s; its gear): the highest speed where the most wheel
    force of any gear still meets the resistances (drag, rolling, and the four wheels'
    joint damping ``wheel_damping_nms`` each, N·m·s/rad), without wheel slip."""
    c = drivetrain_coefficients(params, mass_kg=mass_kg, wheel_radius_m=wheel_radius_m)

    def surplus(v):
        omega = v / wheel_radius_m
        torque, gear = _available_torque(c, False, omega)
        return torque / wheel_radius_m + float(_resistance_n(c, omega)) - 4.0 * wheel_damping_nms * omega / wheel_radius_m, gear

    v_high = params.rev_limit_rpm / RPM_PER_RAD_S / (params.gear_ratios[-1] * params.final_drive) * wheel_radius_m
    grid = np.linspace(1.0, v_high, 4000)
    ok = [v for v in grid if surplus(v)[0] > 0.0]
    lo = ok[-1]
    hi = min(lo + (grid[1] - grid[0]), v_high)
    for _ in range(60):  # bisection on the last sign change
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if surplus(mid)[0] > 0.0 else (lo, mid)
    return lo, surplus(lo)[1]
