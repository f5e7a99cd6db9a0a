"""The car on a route's terrain: placement, control inputs and chunked stepping with truth.

``VehicleSim.step(n)`` advances the physics by n steps and returns the truth of those steps
as a :class:`Truth` record at the physics rate. MuJoCo's sensor values read after
``mj_step`` belong to the state at the start of that step (docs/design.md §3), so the k-th row of
a chunk is the truth at ``t0 + k·dt``, where ``t0`` was the simulation time before the call.
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import mujoco
import numpy as np

from biso_cosim.frames import _q_from_euler
from biso_cosim.vehicle._kernels import (HISTORY_READ, HISTORY_WARNED, TRUTH_LAYOUT, _apply_controls, _drive_period,
                                         _history_rows, _interpolate_rows, _pack_rows, _track_axle, truth_columns)
from biso_cosim.routes import Route
from biso_cosim.vehicle.driver import DriverCommand, DriverParams, RouteDriver
from biso_cosim.vehicle.drivetrain import AIR_DENSITY_KG_M3, DRIVETRAIN, DrivetrainParams, drivetrain_coefficients
from biso_cosim.vehicle.model import CarIndex, build_model, vehicle_parameters

__all__ = ["Truth", "VehicleSim", "ControlArrays", "HistoryArrays", "PhysicsDiverged"]


class PhysicsDiverged(RuntimeError):
    """The physics cannot go on from here: MuJoCo found the state unstable (a non-finite or
    huge position, velocity or acceleration, on which it resets the data to the model's
    initial state and carries on: a run would drive on from there as if nothing happened), or
    a step stopped with ``mujoco.FatalError`` (the tyre plugin on a non-finite force, naming
    the wheel). ``t_s``: the time of the step that failed. Raised by the stepping methods of
    :class:`VehicleSim`; ``CoSimulation.run`` ends the run there (its status ``diverged``)."""

    def __init__(self, reason: str, t_s: float):
        super().__init__(reason)
        self.t_s = t_s


_RESET_WARNINGS = {mujoco.mjtWarning.mjWARN_BADQPOS: "position", mujoco.mjtWarning.mjWARN_BADQVEL: "velocity",
                   mujoco.mjtWarning.mjWARN_BADQACC: "acceleration"}
"""MuJoCo's warnings on which it resets the data (engine_forward.c, mj_checkPos/Vel/Acc)."""


def _mj_step(m: mujoco.MjModel, d: mujoco.MjData, n: int = 1) -> None:
    """``mj_step(m, d, n)``, a step that stops (``mujoco.FatalError``) as PhysicsDiverged."""
    try:
        mujoco.mj_step(m, d, n)
    except mujoco.FatalError as exc:
        raise PhysicsDiverged(f"the physics stopped at t = {d.time:.4f} s: {exc}", float(d.time)) from None


def _mj_step_checked(m: mujoco.MjModel, d: mujoco.MjData) -> None:
    """One ``_mj_step``, and PhysicsDiverged when MuJoCo reset the data in it (a warning of
    ``_RESET_WARNINGS``; after a reset the clock reads 0, so the step's time is taken first)."""
    t_s = d.time
    _mj_step(m, d)
    for warning, quantity in _RESET_WARNINGS.items():
        if d.warning[warning].number:
            raise PhysicsDiverged(f"the physics became unstable at t = {t_s:.4f} s: MuJoCo found a non-finite or huge "
                                  f"{quantity} (dof {d.warning[warning].lastinfo}) and reset the state", t_s)


class ControlArrays(NamedTuple):
    """What a kernel needs to write the controls as ``VehicleSim.apply`` does
    (``_apply_controls``): MuJoCo's ``ctrl``, the actuator indices (steering, drive,
    resistance, four brakes), the wheel spin rates (a view of sensordata, rad/s) and the
    drivetrain's coefficients. The same arrays for the simulator's life."""

    ctrl: np.ndarray
    actuators: np.ndarray
    wheel_rates: np.ndarray
    drivetrain: np.ndarray


class HistoryArrays(NamedTuple):
    """Where a kernel reads a control period's sensordata rows from (``_history_rows``, the
    co-simulation's period call): MuJoCo's sensor history rings (``data.history``), their
    layout (per sensor: history address, samples, sensordata address, width; int64), the
    warning counters (``data.warning.number``), the current ``data.sensordata``, the period's
    rows (steps_per_control, nsensordata) the rows are read into, and ``gather``, the
    sensordata columns of ``Truth``'s columns 1… in order (``_pack_rows``). The same arrays
    for the simulator's life."""

    history: np.ndarray
    layout: np.ndarray
    warnings: np.ndarray
    sensordata: np.ndarray
    rows: np.ndarray
    gather: np.ndarray


def apply_command(controls: ControlArrays, command: DriverCommand) -> None:
    """Write ``command`` into ``controls.ctrl`` (its drive through the drivetrain at the wheel
    rates in ``controls``): what ``VehicleSim.apply`` does with its own arrays."""
    _apply_controls(controls.ctrl, controls.actuators, command.steer_rad, command.drive, command.brake,
                    controls.wheel_rates, controls.drivetrain)


# Before time zero the car settles on its suspension with the brakes on for this long, so
# that the first samples show a car at rest rather than contacts finding their depth.
_SETTLE_S = 3.0
# Everything a step depends on (time, physics, warm start, controls, ...) except the sensor
# history, which only carries each period's rows out (see ``step_rows``); an int, which the
# bindings take without an enum conversion per call.
PHYSICS_STATE = int(mujoco.mjtState.mjSTATE_INTEGRATION) & ~int(mujoco.mjtState.mjSTATE_HISTORY)
# The most steps one ``mj_step(m, d, nstep)`` call of ``step_rows`` covers (the length of
# each sensor's history ring).
_MAX_HISTORY_STEPS = 100


def _columns(index: int | slice, doc: str) -> property:
    return property(lambda self: self.packed[:, index], doc=doc)


class Truth:
    """True motion at the IMU site, one row per instant, packed in one (n, 23) array.

    Columns: ``t_s``; ``omega_b`` (rad/s, body axes); ``specific_force_b`` (m/s², +g up at
    rest); ``q_wb`` (attitude of the body, i.e. of the IMU site, in ENU); ``pos_w`` (m);
    ``vel_w`` (m/s); ``speed_mps`` (forward speed of the rear axle); ``wheel_rates`` (rad/s,
    wheels fl, fr, rl, rr); ``steer_rad`` (bicycle steering angle). The attributes are views
    of ``packed``.
    """

    __slots__ = ("packed",)
    LAYOUT = TRUTH_LAYOUT  # where each quantity sits in a row
    WIDTH = TRUTH_LAYOUT.width
    QUAT_COLUMN = TRUTH_LAYOUT.q_wb

    t_s = _columns(truth_columns("t_s"), "time, s")
    omega_b = _columns(truth_columns("omega_b"), "angular rate in body axes, rad/s")
    specific_force_b = _columns(truth_columns("specific_force_b"), "specific force in body axes, m/s²")
    q_wb = _columns(truth_columns("q_wb"), "attitude, body to ENU")
    pos_w = _columns(truth_columns("pos_w"), "IMU site position, ENU, m")
    vel_w = _columns(truth_columns("vel_w"), "IMU site velocity, ENU, m/s")
    speed_mps = _columns(truth_columns("speed_mps"), "forward speed of the rear axle, m/s")
    wheel_rates = _columns(truth_columns("wheel_rates"), "wheel spin rates fl, fr, rl, rr, rad/s")
    steer_rad = _columns(truth_columns("steer_rad"), "bicycle steering angle (the steering column), rad, left positive")

    def __init__(self, packed: np.ndarray):
        if packed.ndim != 2 or packed.shape[1] != self.WIDTH:
            raise ValueError(f"packed truth must have shape (n, {self.WIDTH}), got {packed.shape}")
        self.packed = packed

    def __len__(self) -> int:
        return self.packed.shape[0]

    def __getitem__(self, index) -> "Truth":
        return Truth(self.packed[index] if isinstance(index, slice) else self.packed[np.atleast_1d(index)])

    @staticmethod
    def concatenate(parts: list["Truth"]) -> "Truth":
        if not parts:
            return Truth(np.empty((0, Truth.WIDTH)))
        return Truth(np.concatenate([p.packed for p in parts]))

    def at(self, t_s: np.ndarray, rate_hz: float, before: "Truth | None" = None) -> "Truth":
        """The truth at times ``t_s`` within these rows (uniform at ``rate_hz``): vectors
        interpolated linearly, the attitude on the shorter arc (nlerp). With ``before`` (the
        row one step before these), the times may reach back to it."""
        out = np.empty((t_s.shape[0], self.WIDTH))
        if t_s.shape[0]:
            first = self.packed if before is None else before.packed
            _interpolate_rows(_NO_ROWS if before is None else before.packed, self.packed, float(first[0, 0]),
                              float(rate_hz), np.ascontiguousarray(t_s, dtype=np.float64), self.QUAT_COLUMN, out)
        return Truth(out)


_NO_ROWS = np.empty((0, Truth.WIDTH))


class VehicleSim:
    """The reference car on ``route``'s terrain, driven by the scripted driver.

    ``tyres`` and ``surface`` (see ``model.build_model``) default to the route's
    (``Route.tyres``, ``Route.surface``: a route file may name them; "magic_formula"
    (``tyres.DEFAULT_TYRE_MODEL``) and "dry" otherwise); an explicit ``tyres`` with the route's
    surface only if it is "magic_formula".
    """

    def __init__(self, route: Route, *, physics_rate_hz: float = 1000.0, control_rate_hz: float = 50.0,
                 driver_params: DriverParams | None = None, drivetrain: DrivetrainParams = DRIVETRAIN,
                 tyres: str | None = None, tyre_params=None, chassis_params=None,
                 surface: str | float | None = None):
        if not physics_rate_hz > 0.0:
            raise ValueError(f"physics_rate_hz must be > 0, got {physics_rate_hz}")
        if not control_rate_hz > 0.0:
            raise ValueError(f"control_rate_hz must be > 0, got {control_rate_hz}")
        ratio = physics_rate_hz / control_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"physics_rate_hz ({physics_rate_hz}) must be a whole multiple of "
                             f"control_rate_hz ({control_rate_hz})")
        self.route = route
        self.physics_rate_hz = float(physics_rate_hz)
        self.control_rate_hz = float(control_rate_hz)
        self.steps_per_control = int(round(ratio))
        self._history_steps = min(self.steps_per_control, _MAX_HISTORY_STEPS)
        # tyres: "coulomb" or "magic_formula" (vehicle.tyres), see build_model; not given, the
        # route's (``Route.tyres``, "magic_formula" unless its file names one), and the route's
        # surface with the magic_formula tyres
        if tyres is None:
            tyres = route.tyres
        if surface is None:
            surface = route.surface if tyres == "magic_formula" else "dry"
        self.tyres = tyres
        self.surface = surface
        self.tyre_params = tyre_params
        self.chassis_params = chassis_params
        self.model, self.patches = build_model(route.terrain, timestep_s=1.0 / physics_rate_hz,
                                               history_steps=self._history_steps, tyres=tyres,
                                               tyre_params=tyre_params, chassis_params=chassis_params,
                                               surface=surface)
        self.data = mujoco.MjData(self.model)
        self.index = CarIndex.of(self.model)
        params = vehicle_parameters(self.model, drivetrain)
        self.parameters = params
        self.drivetrain = drivetrain
        self._drivetrain = drivetrain_coefficients(
            drivetrain, mass_kg=params["total_mass_kg"], wheel_radius_m=self.index.wheel_radius_m,
            rear_load_share=params["cg_behind_front_axle_m"] / params["wheelbase_m"],
            cg_height_over_wheelbase=params["cg_height_m"] / params["wheelbase_m"])
        self.driver = RouteDriver(
            route, wheelbase_m=self.index.wheelbase_m, wheel_radius_m=self.index.wheel_radius_m,
            mass_kg=params["total_mass_kg"], max_drive_torque_nm=params["max_drive_torque_nm"],
            brake_kv=params["brake_kv_nms_per_rad"],
            max_brake_torque_nm=params["max_brake_torque_per_wheel_nm"],
            max_steer_rad=params["max_steer_rad"], dt_s=1.0 / control_rate_hz, params=driver_params,
            power_w_per_kg=drivetrain.efficiency * drivetrain.max_power_w / params["total_mass_kg"],
            drag_per_m=0.5 * AIR_DENSITY_KG_M3 * drivetrain.drag_area_m2 / params["total_mass_kg"],
            rolling_mps2=drivetrain.rolling_resistance * 9.80665)
        # a control period is one mj_step(m, d, nstep) call; the sensors' history rings hold
        # its sensordata rows (no Python per physics step). Arrays and views made once:
        m = self.model
        self._rows = np.empty((self.steps_per_control, m.nsensordata))
        self._start_state = np.empty(mujoco.mj_stateSize(m, PHYSICS_STATE))
        self._history_layout = np.column_stack([m.sensor_historyadr, m.sensor_history[:, 0], m.sensor_adr,
                                                m.sensor_dim]).astype(np.int64)
        self._history, self._warnings = self.data.history, self.data.warning.number
        self._ctrl, self._sensordata = self.data.ctrl, self.data.sensordata
        ix = self.index
        self._actuators = np.array([ix.steer, ix.drive, ix.resistance, *ix.brakes], dtype=np.int64)
        self._wheel_rates = self.data.sensordata[ix.wheel_rates]  # a view: the current spin rates
        self._sensor_layout = np.array([ix.quat.start, ix.rear_axle_pos.start, ix.rear_axle_vel_b.start,
                                        ix.wheel_rates.start, ix.wheel_rates.stop - ix.wheel_rates.start], dtype=np.int64)
        self._axle_x = int(ix.rear_axle_pos.start)
        self._controls = ControlArrays(self._ctrl, self._actuators, self._wheel_rates, self._drivetrain)
        # sensordata columns of Truth's columns 1..22, in order
        self._settled: tuple[np.ndarray, np.ndarray] | None = None
        self._gather = np.r_[np.arange(ix.gyro.start, ix.gyro.stop), np.arange(ix.accel.start, ix.accel.stop),
                             np.arange(ix.quat.start, ix.quat.stop), np.arange(ix.pos.start, ix.pos.stop),
                             np.arange(ix.vel_w.start, ix.vel_w.stop), [ix.rear_axle_vel_b.start],
                             np.arange(ix.wheel_rates.start, ix.wheel_rates.stop),
                             [ix.steering_angle.start]].astype(np.int64)
        self._history_arrays = HistoryArrays(self._history, self._history_layout, self._warnings, self._sensordata,
                                             self._rows, self._gather)
        self.row_fault: Callable[[np.ndarray, int], None] | None = None
        """Fault injection (tests, robustness studies): None (default), or a callable
        ``fault(rows, first_step)`` given each period's sensordata rows (n, nsensordata; the
        columns ``index`` names) and the index of its first step, after the physics and
        before anything reads them, which may change them in place (a NaN rate, a bad
        position) as a faulty sensor bus would. While it is set, every period is stepped
        with its rows read out of MuJoCo's history at once (``step``'s way), so that the
        fault sees them; MuJoCo's own state is not changed by it."""
        self.reset()

    def estimator_defaults(self) -> dict[str, Any]:
        """What this car tells an estimator that rides on it, by the estimators' parameter
        names (``Estimator.vehicle_params``: an estimator lists those it takes; the
        co-simulation and ``compare`` give each of them as the default of a parameter the
        user has not set): ``speed_point_b_m``, where the wheel odometry's speed is measured
        (the rear axle's centre) seen from the IMU site, body axes, m; and
        ``rear_slip_gradient_rad_per_g``, the rear axle's slip angle per g of lateral
        acceleration of its tyres (``tyres.rear_slip_gradient_rad_per_g``: W_r/C_αr, 0 for
        the coulomb tyres); ``linear_accel_mps2``, the end of the rear tyres' linear range on
        the route's road (``tyres.linear_accel_mps2``, 0 for the coulomb tyres)."""
        from biso_cosim.vehicle.tyres import linear_accel_mps2, rear_slip_gradient_rad_per_g, surface_friction

        ix = self.index
        return {"speed_point_b_m": tuple(float(v) for v in ix.rear_axle_b - ix.imu_pos_b),
                "rear_slip_gradient_rad_per_g": rear_slip_gradient_rad_per_g(self.parameters, self.tyres,
                                                                             self.tyre_params),
                "linear_accel_mps2": linear_accel_mps2(self.parameters, self.tyres, self.tyre_params,
                                                       surface_friction(self.surface))}

    # ------------------------------------------------------------------ placement
    def reset(self) -> None:
        """Put the car at the start of the route, at rest and settled; time zero."""
        m, d, ix = self.model, self.data, self.index
        mujoco.mj_resetData(m, d)
        x0, y0, yaw = self.route.start_xy_yaw
        # the route starts at the rear axle; the free joint sits at the centre of mass
        c, s = math.cos(yaw), math.sin(yaw)
        back = -ix.rear_axle_b[0]
        cx, cy = x0 + c * back, y0 + s * back
        ground = float(self.route.terrain.height(cx, cy))
        d.qpos[0:3] = (cx, cy, ground + float(m.body("chassis").pos[2]))
        d.qpos[3:7] = _q_from_euler(0.0, 0.0, yaw)
        d.ctrl[:] = 0.0
        d.ctrl[ix.brakes] = 1.0
        if self._settled is None:
            mujoco.mj_forward(m, d)
            for _ in range(int(round(_SETTLE_S * self.physics_rate_hz))):
                _mj_step_checked(m, d)
            d.time = 0.0
            self._settled = (np.empty(mujoco.mj_stateSize(m, PHYSICS_STATE)), d.sensordata.copy())
            mujoco.mj_getState(m, d, self._settled[0], PHYSICS_STATE)
        else:  # the same settled start as the first time, without settling again
            mujoco.mj_setState(m, d, self._settled[0], PHYSICS_STATE)
            d.sensordata[:] = self._settled[1]
        self._restart_history()
        self.steps_done = 0
        self.periods_with_warnings = 0  # control periods in which MuJoCo warned (see ``restep``)
        self.driver.reset()

    # ------------------------------------------------------------------ stepping
    def apply(self, command: DriverCommand) -> None:
        """Write ``command`` into the controls (its drive through the drivetrain at the
        current wheel speeds)."""
        apply_command(self._controls, command)

    def _measure(self) -> tuple[list[float], float, float, float]:
        """What the driver measures, as plain floats: rear-axle position, yaw, forward speed,
        mean wheel spin rate (this runs once per control period)."""
        ix = self.index
        sd = self.data.sensordata.tolist()
        w, x, y, z = sd[ix.quat.start:ix.quat.stop]
        yaw = math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))
        axle = sd[ix.rear_axle_pos.start:ix.rear_axle_pos.stop]
        wheels = sd[ix.wheel_rates.start:ix.wheel_rates.stop]
        return axle, yaw, sd[ix.rear_axle_vel_b.start], sum(wheels) / len(wheels)

    @property
    def control_arrays(self) -> ControlArrays:
        """The arrays a kernel writes the controls with, as ``apply`` does (``ControlArrays``)."""
        return self._controls

    @property
    def drivetrain_coefficients(self) -> np.ndarray:
        """The coefficients the drivetrain's kernels read (``drivetrain.drivetrain_coefficients``
        of ``drivetrain``, this car's mass and geometry), as a read-only view."""
        view = self._drivetrain.view()
        view.flags.writeable = False
        return view

    @property
    def history_arrays(self) -> HistoryArrays:
        """The arrays a kernel reads a period's sensordata rows from (``HistoryArrays``)."""
        return self._history_arrays

    @property
    def sensordata(self) -> np.ndarray:
        """MuJoCo's sensordata now (``data.sensordata``, one array viewing the model's
        buffer for the simulator's life, so a kernel may hold it): the columns ``index``
        names (quaternion, rear axle, wheel rates, steering angle, ...)."""
        return self._sensordata

    def drive(self) -> DriverCommand:
        """Ask the driver for the next control period's command from the current state, and
        apply it: one kernel from the sensors to the controls (``_measure``, the driver's
        ``command`` and ``apply`` in one call; the same numbers, tested)."""
        out = self.apply_driver()
        return DriverCommand(steer_rad=float(out[0]), drive=float(out[1]), brake=float(out[2]))

    def apply_driver(self) -> np.ndarray:
        """``drive`` for callers that need no command record (the co-simulation, each
        period): the driver's output array (steer_rad, drive, brake), which the next call
        overwrites."""
        driver = self.driver
        out = driver._out
        _drive_period(*driver._arrays, driver._params, driver.state.array, self._sensordata, self._sensor_layout,
                      self._ctrl, self._actuators, self._drivetrain, out)
        return out

    def observe_route(self) -> None:
        """Update the driver's progress and cross-track error without driving (an agent drives)."""
        driver = self.driver  # (driver.track at the axle, in one kernel call)
        _track_axle(*driver._arrays[:3], driver.state.array, self._sensordata, self._axle_x)

    def step(self, n: int | None = None) -> Truth:
        """Advance ``n`` physics steps (default: one control period) with the controls held;
        truth of those steps. The same steps as ``n`` calls of ``mj_step``, bit for bit."""
        return self.truth_of(*self.step_rows(n))

    def step_rows(self, n: int | None = None) -> tuple[np.ndarray, int]:
        """``step`` without packing the truth: MuJoCo's sensordata after each of the ``n``
        steps (a buffer that the next call overwrites) and the index of the first step
        (``truth_of`` packs them)."""
        m, d = self.model, self.data
        n = self.steps_per_control if n is None else n
        rows = self._rows if n == self._rows.shape[0] else np.empty((n, m.nsensordata))
        mujoco.mj_getState(m, d, self._start_state, PHYSICS_STATE)
        done = 0
        while done < n:
            k = min(n - done, self._history_steps)
            t_start = d.time
            _mj_step(m, d, k)
            outcome = _history_rows(self._history, self._history_layout, k, t_start, self._warnings,
                                    self._sensordata, rows[done:done + k])
            if outcome != HISTORY_READ:
                self.restep(rows, outcome)
                break
            done += k
        first = self.steps_done
        self.steps_done += n
        if self.row_fault is not None:
            self.row_fault(rows, first)
        return rows, first

    def step_period(self) -> tuple[np.ndarray | None, int, float]:
        """A control period as one ``mj_step(m, d, n)`` call whose sensordata rows stay in
        the sensors' history for the caller to read (``_history_rows`` into
        ``history_arrays.rows``; the co-simulation's period kernel does, saving a kernel
        call), or ``restep`` when that fails. Returns (None, index of the first step, time at
        the period's start); a period longer than the history, or any period while
        ``row_fault`` is set, is stepped by ``step_rows`` instead: (its rows, first, 0)."""
        n = self.steps_per_control
        if n > self._history_steps or self.row_fault is not None:
            return (*self.step_rows(), 0.0)
        m, d = self.model, self.data
        mujoco.mj_getState(m, d, self._start_state, PHYSICS_STATE)
        t_start = d.time
        _mj_step(m, d, n)
        first = self.steps_done
        self.steps_done += n
        return None, first, t_start

    def restep(self, rows: np.ndarray, outcome: int) -> np.ndarray:
        """The rows of the steps since the last period's start, into ``rows`` (and returned),
        after ``_history_rows`` could not read them (``outcome``, its code): MuJoCo warned (e.g. a bad velocity, on which it resets
        the data and goes on, history and all), or the clock was set back by hand. The period
        is stepped again from its start one mj_step at a time (the same steps), and the
        history rings start afresh. PhysicsDiverged at the step on which MuJoCo reset the
        data (a warning of ``_RESET_WARNINGS``); other warnings are counted
        (``periods_with_warnings``) and the run goes on."""
        m, d = self.model, self.data
        self.periods_with_warnings += outcome == HISTORY_WARNED
        mujoco.mj_setState(m, d, self._start_state, PHYSICS_STATE)
        self._warnings[:] = 0
        for i in range(rows.shape[0]):
            _mj_step_checked(m, d)
            rows[i] = d.sensordata
        self._warnings[:] = 0
        self._restart_history()
        return rows

    def restore_physics(self, physics: np.ndarray, sensordata: np.ndarray, steps_done: int) -> None:
        """Restore MuJoCo's state ``physics`` (``mj_getState(PHYSICS_STATE)``), the sensor data
        as it was then (it belongs to the last step's start, and the driver reads it: restored,
        not recomputed) and the count of steps, with the sensors' history started afresh (a
        restored state, e.g. ``CoSimulation.set_state``)."""
        mujoco.mj_setState(self.model, self.data, physics, PHYSICS_STATE)
        self.data.sensordata[:] = sensordata
        self._restart_history()
        self.steps_done = steps_done

    def _restart_history(self) -> None:
        """Start every sensor's history ring afresh just before the current time, holding the
        current sensordata: needed whenever the clock is set back (a reset, a restored
        state), since MuJoCo advances a ring only past its newest stamp."""
        m, d = self.model, self.data
        dt = m.opt.timestep
        for s in range(m.nsensor):
            nsample = int(m.sensor_history[s, 0])
            if nsample:
                adr, dim = m.sensor_adr[s], m.sensor_dim[s]
                times = d.time - dt * np.arange(nsample, 0, -1)
                values = np.ascontiguousarray(np.broadcast_to(d.sensordata[adr:adr + dim], (nsample, dim)))
                mujoco.mj_initSensorHistory(m, d, s, times, values, d.time - dt)

    def current_truth(self) -> Truth:
        """The truth of the current state as one row (at the time of the last step's start)."""
        return self.truth_of(self.data.sensordata[None, :].copy(), max(self.steps_done - 1, 0))

    def truth_of(self, buf: np.ndarray, first_step: int) -> Truth:
        """The truth of sensordata rows ``buf`` (n, nsensordata; ``step_rows``') whose first
        row is the step of index ``first_step``, packed (``TRUTH_LAYOUT``)."""
        packed = np.empty((buf.shape[0], Truth.WIDTH))
        _pack_rows(buf, self._gather, first_step, self.physics_rate_hz, packed)
        return Truth(packed)
