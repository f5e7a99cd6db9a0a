"""What the three environments share: episodes and seeds, the IMU observation window,
action checks, rendering, and the arguments every environment takes.

An environment holds one :class:`~biso_cosim.cosim.CoSimulation` (car, virtual MPU-9250,
estimators) and advances it by one control period per ``step``. The co-simulation is built
once for a library route and reset between episodes (only the sensor seed changes); a
procedurally generated route (``route="random"``) needs a new one every episode.

Seeds: ``reset(seed=s)`` makes the episode a function of ``s`` alone:
``SeedSequence(s).spawn(3)`` gives the route's seed, the sensor's seed (turn-on errors and
noise of the MPU-9250) and the GNSS receiver's. ``reset()`` without a seed draws the next
episode seed from the environment's ``np_random``, so a sequence of episodes is
reproducible from the first seed. ``info`` at reset reports ``episode_seed``,
``sensor_seed``, ``route_seed`` (and ``gnss_seed``).
"""

from __future__ import annotations

import importlib
import math
import os
import sys
from typing import Any, ClassVar, Mapping, Sequence

import gymnasium as gym
import mujoco
import numpy as np

from biso_cosim.cosim import CoSimulation, EstimatorSpec
from biso_cosim.loop import PeriodWork
from biso_cosim.envs._kernels import _inside, _push_window, _scale_observation, _window_work
from biso_cosim.envs.procedural import random_route
from biso_cosim.routes import Route, load_route
from biso_cosim.sensors import ImuSamples, Profile
from biso_cosim.vehicle.driver import DriverCommand
from biso_cosim.vehicle.sim import Truth

__all__ = ["CosimEnv", "ImuWindow", "GnssInput", "IMU_FIELDS", "GNSS_FIELDS", "RENDER_MODES", "COMMON_ARGUMENTS",
           "ResetNeeded", "display_available", "Scale", "IMU_SCALES", "GNSS_SCALES"]

MAX_SEED = 2**63 - 1
"""The largest episode seed ``reset`` takes (the range the environments draw seeds from)."""

RANDOM_ROUTE = "random"
"""The ``route`` value that asks for a new procedurally generated route every episode."""

IMU_FIELDS = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z", "mag_x", "mag_y", "mag_z",
              "mag_fresh", "new")
"""Columns of one IMU sample in the observation: gyro (rad/s), accelerometer (specific force,
m/s²), magnetometer (µT), all in body axes (x forward, y left, z up); ``mag_fresh`` 1 when the
AK8963 delivered a new measurement with this sample (it holds its last one in between);
``new`` 1 when the sample arrived during the last step (0: repeated from an earlier step)."""

# Stochastic terms of a sensor profile, zeroed by ``sensor_noise=False``; the per-part
# turn-on errors (bias, scale factor, misalignment...) stay.
_NOISE_KEYS = ("gyro__noise_density", "gyro__bias_instability", "gyro__random_walk", "accel__noise_density",
               "accel__bias_instability", "accel__random_walk", "mag__noise")

_ACTION_BOUNDS = ("clip", "raise")

COMMON_ARGUMENTS: dict[str, str] = {
    "route": "library route name (`biso_cosim.routes.route_names()`), path of a route file, a "
             "`Route`, or `\"random\"`: a new procedurally generated closed route every episode, "
             "drawn from the episode seed (`biso_cosim.envs.procedural`)",
    "random_route_options": "options of `random_route` for `route=\"random\"` (corners, size, speeds, "
                            "stops, hills, ...; see `RANDOM_ROUTE_DEFAULTS`)",
    "episode_duration_s": "simulated time of an episode in s; None: the route's nominal duration plus 10 s "
                          "(AttitudeEstimation, GainTuning) or 1.5 times it plus 10 s (Driving). The episode "
                          "is truncated then",
    "sensor_profile": "MPU-9250 error profile: `\"mpu9250_calibrated\"` (a part after the usual start-up "
                      "calibration), `\"mpu9250\"` (raw datasheet part), `\"ideal\"`, or a profile file",
    "sensor_noise": "False zeroes the stochastic terms of the profile (white noise, bias instability, "
                    "random walk, magnetometer noise); the part's turn-on errors stay",
    "sensor_seed": "None: a new sensor part and noise stream every episode, from the episode seed; "
                   "an int: the same part and noise every episode",
    "registers": "MPU-9250 register fields (`biso_cosim.sensors.Registers`); they set the output rate "
                 "(default 200 Hz), ranges and filters",
    "gnss_rate_hz": "None: no GNSS; 1 to 10: a virtual GNSS receiver (`biso_cosim.sensors.gnss`) at this rate, "
                    "its newest fix in the observation (antenna at the IMU)",
    "gnss_profile": "GNSS receiver errors: `\"consumer\"` (u-blox M8 class, open sky) or `\"ideal\"`",
    "control_rate_hz": "environment steps per simulated second (a whole fraction of `physics_rate_hz`)",
    "physics_rate_hz": "MuJoCo step rate",
    "gyro_calibration_s": "start-up gyro offset calibration at rest before time zero, s (0: none; use it with "
                          "the raw `\"mpu9250\"` profile)",
    "action_bounds": "out-of-bounds actions: `\"clip\"` to the action space (as Gymnasium's ClipAction "
                     "wrapper does) or `\"raise\"` ValueError. NaN, inf and wrong shapes always raise",
    "render_mode": "`\"rgb_array\"` (chase camera, offscreen: EGL or OSMesa headless) or `\"human\"` "
                   "(MuJoCo viewer; offered only where a display exists)",
    "render_width": "width of rendered frames, pixels (at most 1280)",
    "render_height": "height of rendered frames, pixels (at most 720)",
}
"""Descriptions of the arguments every environment takes (defaults and types come from the
signatures; :mod:`biso_cosim.envs._docs` builds the tables)."""


class ResetNeeded(gym.error.ResetNeeded, ValueError):
    """``step`` before ``reset``, or after the episode ended."""


def display_available() -> bool:
    """Whether an on-screen window can be opened (for ``render_mode="human"``)."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


RENDER_MODES: list[str] = ["rgb_array", *(["human"] if display_available() else [])]
"""Declared render modes: ``"human"`` only where a display exists, since Gymnasium's
``check_env`` opens every declared mode (docs/design.md §10)."""


def _int_seed(sequence: np.random.SeedSequence) -> int:
    """A 63-bit integer seed drawn from a seed sequence (what the sensor and routes take)."""
    return int(sequence.generate_state(1, np.uint64)[0] >> np.uint64(1))


# --------------------------------------------------------------------------------------
# Observation of the IMU samples of one step
# --------------------------------------------------------------------------------------


class ImuWindow:
    """The most recent ``slots`` IMU samples, newest last, as a (slots, 11) array.

    ``slots = ceil(ODR / control rate)``: exactly the samples of one step when the rates
    divide (200 Hz and 50 Hz: 4). When they do not (200 Hz and 80 Hz: 2 or 3 samples a
    step), the oldest rows repeat samples of the previous step with ``new = 0``, so the
    observation keeps its size and every row holds a real sample. Before the first sample
    rows are zero with ``new = 0``. A NaN magnetometer (AK8963 powered down) reads 0 with
    ``mag_fresh = 0``.
    """

    def __init__(self, slots: int):
        self.values = np.zeros((slots, len(IMU_FIELDS)))

    def clear(self) -> None:
        self.values[:] = 0.0

    def push(self, samples: ImuSamples) -> None:
        _push_window(self.values, samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh)


GNSS_FIELDS = ("valid", "new", "age_s", "pos_e", "pos_n", "pos_u", "vel_e", "vel_n", "vel_u")
"""The GNSS part of an observation: the newest fix delivered so far. ``valid`` 1 for a fix
(0 during an outage or before the first fix: the values then read 0), ``new`` 1 when it was
delivered during the last step, ``age_s`` the time from its validity to the newest IMU
sample (latency included), position (m) in the route's local ENU frame, velocity (m/s)."""


class Scale(tuple):
    """How one observed column is normalised: ``(scale, low, high, unit)``; the observation
    holds ``physical / scale`` clipped to ``[low, high]`` (bounds in scaled units)."""

    def __new__(cls, scale: float, low: float, high: float, unit: str):
        return super().__new__(cls, (float(scale), float(low), float(high), unit))


G0 = 9.80665
IMU_SCALES: dict[str, Scale] = {
    **{f"gyro_{a}": Scale(1.0, -1.0, 1.0, "rad/s") for a in "xyz"},  # bounds: the gyro's full scale (set per env)
    **{f"accel_{a}": Scale(G0, -1.0, 1.0, "m/s²") for a in "xyz"},  # bounds: the accelerometer's full scale
    **{f"mag_{a}": Scale(50.0, -4912.0 / 50.0, 4912.0 / 50.0, "µT") for a in "xyz"},  # AK8963 range ±4912 µT
    "mag_fresh": Scale(1.0, 0.0, 1.0, "-"),
    "new": Scale(1.0, 0.0, 1.0, "-"),
}
"""Normalisation of the IMU columns: gyro in rad/s, accelerometer in g (9.80665 m/s²),
magnetometer in units of 50 µT (about the Earth's field); bounds at the chip's full-scale
ranges (set by the registers: ±4.36 rad/s and ±4 g by default)."""

GNSS_SCALES: dict[str, Scale] = {
    "valid": Scale(1.0, 0.0, 1.0, "-"), "new": Scale(1.0, 0.0, 1.0, "-"), "age_s": Scale(1.0, 0.0, 60.0, "s"),
    **{f"pos_{a}": Scale(100.0, -100.0, 100.0, "m") for a in "enu"},
    **{f"vel_{a}": Scale(10.0, -10.0, 10.0, "m/s") for a in "enu"},
}
"""Normalisation of the GNSS columns: position in units of 100 m (±10 km of the route's
origin), velocity in units of 10 m/s, age in s (clipped at 60 s)."""

class GnssInput:
    """A virtual GNSS receiver fed with the truth at the IMU's sample times, holding its newest fix.

    The receiver's clock starts at the episode's first IMU sample; its antenna is the IMU
    (the receiver models no lever arm).
    """

    def __init__(self, profile: str, rate_hz: float, imu_rate_hz: float):
        from biso_cosim.sensors.gnss import GNSS_PROFILES, RATE_RANGE_HZ, GnssReceiver  # only where GNSS is asked for

        low, high = RATE_RANGE_HZ
        _check_number("gnss_rate_hz", rate_hz, low=low, high=high)
        _check_choice("gnss_profile", profile, tuple(GNSS_PROFILES))
        self._receiver_type = GnssReceiver
        self._options = {"profile": profile, "rate_hz": rate_hz, "input_rate_hz": imu_rate_hz}
        self.receiver = GnssReceiver(**self._options, seed=0)  # checks the options now
        self.values = np.zeros(len(GNSS_FIELDS))
        self._t0 = math.nan
        self._t_fix = math.nan

    def reset(self, site: Any, seed: int) -> None:
        self.receiver = self._receiver_type(**self._options, site=site, seed=seed)
        self.values[:] = 0.0
        self._t0 = self._t_fix = math.nan

    def push(self, truth: Truth) -> None:
        v = self.values
        v[1] = 0.0
        if not len(truth):
            return
        if math.isnan(self._t0):
            self._t0 = float(truth.t_s[0])
        fixes = self.receiver.simulate(truth.pos_w, truth.vel_w)
        if len(fixes):
            valid = bool(fixes.valid[-1])
            self._t_fix = float(fixes.t_s[-1]) + self._t0
            v[0], v[1] = float(valid), 1.0
            v[3:6] = fixes.pos_w[-1] if valid else 0.0
            v[6:9] = fixes.vel_w[-1] if valid else 0.0
        v[2] = float(truth.t_s[-1]) - self._t_fix if not math.isnan(self._t_fix) else 0.0


# --------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------


def _gl_context(width: int, height: int):
    """An OpenGL context for offscreen rendering, from MUJOCO_GL or the first backend that works.

    MuJoCo chooses its own backend once, when it is imported; a headless machine whose
    process imported MuJoCo without ``MUJOCO_GL=egl`` would get GLFW, which needs a display.
    Trying the backends here makes ``rgb_array`` work wherever one of them does.
    """
    chosen = os.environ.get("MUJOCO_GL", "").strip().lower()
    if chosen in ("egl", "osmesa", "glfw", "cgl"):
        names = [chosen]
    elif sys.platform == "darwin":
        names = ["cgl", "glfw"]
    elif sys.platform.startswith("linux"):
        names = (["glfw"] if display_available() else []) + ["egl", "osmesa"]
    else:
        names = ["glfw"]
    errors = []
    for name in names:
        try:
            context = importlib.import_module(f"mujoco.{name}").GLContext(width, height)
            context.make_current()
            return context
        except Exception as exc:  # noqa: BLE001 -- any failure means: try the next backend
            errors.append(f"{name}: {type(exc).__name__}: {exc}")
    raise RuntimeError("no OpenGL backend could render offscreen (" + "; ".join(errors) + "); "
                       "install EGL (libegl1) or OSMesa (libosmesa6), or set MUJOCO_GL")


class _Offscreen:
    """Frames of one camera of a model into RGB arrays (the core of ``mujoco.Renderer``)."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, camera: str, road: list | None = None):
        self.model = model
        self._road = road or []  # boxes drawn into each frame's scene (``_render.road_geoms``)
        self._context = _gl_context(width, height)
        self._scene = mujoco.MjvScene(model, maxgeom=10000)
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = model.camera(camera).id
        self._mjr = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._mjr)
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._pixels = np.empty((height, width, 3), dtype=np.uint8)
        self._depth = np.empty((height, width), dtype=np.float32)

    def render(self, data: mujoco.MjData) -> np.ndarray:
        from biso_cosim.envs._render import add_geoms, paint_sky

        self._context.make_current()
        mujoco.mjv_updateScene(self.model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL,
                               self._scene)
        add_geoms(self._scene, self._road)
        mujoco.mjr_render(self._rect, self._scene, self._mjr)
        mujoco.mjr_readPixels(self._pixels, self._depth, self._rect, self._mjr)
        frame = np.flipud(self._pixels).copy()
        paint_sky(frame, np.flipud(self._depth))
        return frame

    def close(self) -> None:
        if self._context is not None:
            self._context.make_current()
            self._mjr.free()
            self._context.free()
            self._context = None


class _Window:
    """The interactive MuJoCo viewer following the chase camera (needs a display), with the
    road and the sky in its scene (``_render.decorate_scene``)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, camera: str, route: Route):
        import mujoco.viewer

        from biso_cosim.envs._render import decorate_scene

        self.model = model
        self._handle = mujoco.viewer.launch_passive(model, data, show_left_ui=False, show_right_ui=False)
        self._handle.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._handle.cam.fixedcamid = model.camera(camera).id
        with self._handle.lock():  # the road and the sky of the rgb_array frames (``_render``)
            decorate_scene(self._handle.user_scn, route, model)

    def render(self, data: mujoco.MjData) -> None:
        if self._handle.is_running():
            self._handle.sync()

    def close(self) -> None:
        self._handle.close()


# --------------------------------------------------------------------------------------
# The base environment
# --------------------------------------------------------------------------------------


def _check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(repr(c) for c in choices)}, got {value!r}")
    return value


def _check_shaping_gamma(value: Any) -> float | None:
    """None, or the discount γ of a potential-based shaping term (``_shaping_reward``): 0 ≤ γ < 1."""
    if value is None:
        return None
    gamma = _check_number("shaping_gamma", value, low=0.0, high=1.0)
    if gamma >= 1.0:
        raise ValueError(f"shaping_gamma must be < 1 (the potential is −error/(1 − γ)), got {value!r}")
    return gamma


def _shaping_reward(gamma: float, error_before: float, error_after: float) -> float:
    """The potential-based shaping term γΦ(s') − Φ(s) with Φ = −error/(1 − γ) (Ng, Harada and
    Russell 1999): with the learner's discount γ it changes every policy's discounted return by
    the first state's potential only."""
    return (error_before - gamma * error_after) / (1.0 - gamma)


def _check_number(name: str, value: Any, *, low: float | None = None, high: float | None = None,
                  low_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if low is not None and (x < low or (low_open and x == low)):
        raise ValueError(f"{name} must be {'>' if low_open else '>='} {low}, got {value!r}")
    if high is not None and x > high:
        raise ValueError(f"{name} must be <= {high}, got {value!r}")
    return x


def _sensor_profile(sensor_profile: Any, sensor_noise: bool) -> Profile:
    if not isinstance(sensor_noise, (bool, np.bool_)):
        raise TypeError(f"sensor_noise must be True or False, got {sensor_noise!r}")
    try:
        profile = Profile.load(sensor_profile)
    except (ValueError, FileNotFoundError, TypeError) as exc:
        raise ValueError(f"sensor_profile: {exc}") from None
    if not sensor_noise:
        profile = profile.replace(name=f"{profile.name}-noiseless", **{key: 0.0 for key in _NOISE_KEYS})
    return profile


class CosimEnv(gym.Env):
    """Base of the environments: one co-simulation, advanced one control period per step.

    Subclasses define the spaces, build the estimator specs, and implement ``reset`` and
    ``step`` around ``_begin_episode`` and ``_advance``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": RENDER_MODES, "render_fps": 50}
    ARGUMENTS: ClassVar[dict[str, str]] = {}
    """Descriptions of the subclass's own arguments (see COMMON_ARGUMENTS)."""
    CAMERA: ClassVar[str] = "chase"

    def __init__(self, *, route: str | Route, random_route_options: Mapping[str, Any] | None,
                 episode_duration_s: float | None, sensor_profile: str, sensor_noise: bool, sensor_seed: int | None,
                 registers: Mapping[str, int] | None, gnss_rate_hz: float | None, gnss_profile: str,
                 control_rate_hz: float, physics_rate_hz: float,
                 gyro_calibration_s: float, action_bounds: str, render_mode: str | None, render_width: int,
                 render_height: int, estimators: tuple[EstimatorSpec, ...]):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got "
                             f"{render_mode!r}" + ("" if display_available() else " ('human' needs a display)"))
        self.render_mode = render_mode
        for name, value, limit in (("render_width", render_width, 1280), ("render_height", render_height, 720)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= limit:
                raise ValueError(f"{name} must be an int in [1, {limit}] (the model's offscreen buffer), got {value!r}")
        self._render_size = (int(render_width), int(render_height))
        self._action_bounds = _check_choice("action_bounds", action_bounds, _ACTION_BOUNDS)
        if episode_duration_s is not None:
            episode_duration_s = _check_number("episode_duration_s", episode_duration_s, low=0.0, low_open=True)
        self._episode_duration_s = episode_duration_s
        if sensor_seed is not None and (isinstance(sensor_seed, bool) or not isinstance(sensor_seed, (int, np.integer))
                                        or sensor_seed < 0):
            raise ValueError(f"sensor_seed must be None or an int >= 0, got {sensor_seed!r}")
        self._sensor_seed = None if sensor_seed is None else int(sensor_seed)
        self._sim_options = {
            "sensor_profile": _sensor_profile(sensor_profile, sensor_noise),
            "registers": None if registers is None else dict(registers),
            "gyro_calibration_s": _check_number("gyro_calibration_s", gyro_calibration_s, low=0.0, high=60.0),
            "physics_rate_hz": _check_number("physics_rate_hz", physics_rate_hz, low=0.0, low_open=True),
            "control_rate_hz": _check_number("control_rate_hz", control_rate_hz, low=0.0, low_open=True),
            "estimators": estimators,
            "keep_log": False,  # each step's outputs are all an environment needs: constant memory
        }
        if route == RANDOM_ROUTE:
            self._route_options = dict(random_route_options or {})
            first = random_route(0, **self._route_options)  # checks the options now
        else:
            if random_route_options is not None:
                raise ValueError('random_route_options needs route="random"')
            self._route_options = None
            try:
                first = load_route(route)
            except (ValueError, FileNotFoundError, TypeError) as exc:
                raise ValueError(f"route: {exc}") from None
        # Built now for a fixed route (its errors surface here), and rebuilt per episode for random ones.
        self._sim = self._build(first, seed=0)
        self.dt = 1.0 / self._sim.vehicle.control_rate_hz
        """Simulated time of one step, s."""
        self.metadata = {**type(self).metadata, "render_fps": int(round(self._sim.vehicle.control_rate_hz))}
        self.imu_rate_hz = self._sim.imu.output_rate_hz
        """Output data rate of the MPU-9250 (its registers), Hz."""
        self.imu_slots = max(int(math.ceil(self.imu_rate_hz * self.dt - 1e-9)), 1)
        """IMU samples in each observation (see ImuWindow)."""
        self._window = ImuWindow(self.imu_slots)
        self._gnss = None if gnss_rate_hz is None else GnssInput(gnss_profile, gnss_rate_hz, self.imu_rate_hz)
        # the physical (raw, float64) parts the environment keeps; the observation is their
        # normalised float32 image (``_set_observation_space``)
        self._raw_structure = {"imu": (self.imu_slots, len(IMU_FIELDS))}
        imu = self._sim.imu.registers
        gyro_fs, accel_fs = imu.gyro_full_scale, imu.accel_full_scale / G0
        self._raw_scales: dict[str, dict[str, Scale]] = {"imu": {
            **IMU_SCALES, **{f"gyro_{a}": Scale(1.0, -gyro_fs, gyro_fs, "rad/s") for a in "xyz"},
            **{f"accel_{a}": Scale(G0, -accel_fs, accel_fs, "m/s²") for a in "xyz"}}}
        # Constant columns are left out (part → column → the rows where it is constant; a column
        # goes when it is constant on every row): ``new`` is 1 on the newest floor(ODR / control
        # rate) rows every step, all of them when the rates divide; ``mag_fresh`` is the same
        # every step when the magnetometer's samples fall on the same rows (100 Hz AK8963 at
        # 200 Hz ODR, 4 samples a step: rows 1 and 3), and 0 with the AK8963 off (its
        # field columns read 0 then too).
        whole = abs(self.imu_rate_hz * self.dt - self.imu_slots) < 1e-9
        mag_rate_hz = self._sim.imu.mag_rate_hz
        if mag_rate_hz > 0.0:
            mag_every = self.imu_rate_hz / mag_rate_hz
            mag_fixed = (whole and abs(mag_every - round(mag_every)) < 1e-9
                         and self.imu_slots % max(round(mag_every), 1) == 0)
        else:
            mag_fixed = True
        always_new = int(math.floor(self.imu_rate_hz * self.dt + 1e-9))
        self._dropped: dict[str, dict[str, range]] = {"imu": {
            "new": range(self.imu_slots - min(always_new, self.imu_slots), self.imu_slots),
            **({"mag_fresh": range(self.imu_slots)} if mag_fixed else {}),
            **({f"mag_{a}": range(self.imu_slots) for a in "xyz"} if mag_rate_hz <= 0.0 else {})}}
        if self._gnss is not None:
            self._raw_structure["gnss"] = (len(GNSS_FIELDS),)
            self._raw_scales["gnss"] = dict(GNSS_SCALES)
        self._viewer: _Offscreen | _Window | None = None
        self._running = False
        # the truth at the newest sample (a packed ``Truth`` row): a view of the co-simulation's
        # reused arrays, read within the step (or the next, before its period is stepped)
        self._newest_row: np.ndarray | None = None

    # ------------------------------------------------------------------ episodes
    @property
    def sim(self) -> CoSimulation:
        """The co-simulation of the current episode (car, sensor, estimators)."""
        return self._sim

    @property
    def route(self) -> Route:
        """The route of the current episode."""
        return self._sim.route

    def _default_duration_s(self, route: Route) -> float:
        return math.ceil(route.nominal_duration_s + 10.0)

    def _check_route(self, route: Route) -> None:
        """Refuse routes the environment cannot use (ValueError); any route by default."""

    def _reset_time_s(self) -> float:
        """Simulated time ``reset`` spends before the first observation (one control period)."""
        return 1.0 / self._sim_options["control_rate_hz"]

    @property
    def _rebuilt_each_episode(self) -> bool:
        """Whether a fixed route's co-simulation is built anew each episode (a subclass whose
        ``_episode_profile`` varies; random routes are rebuilt anyway)."""
        return False

    def _episode_profile(self, sensor_seed: int) -> Profile:
        """The sensor profile of the episode whose part is drawn from ``sensor_seed``: the
        environment's own (a subclass may vary it per episode, with ``_rebuilt_each_episode``)."""
        return self._sim_options["sensor_profile"]

    def _build(self, route: Route, seed: int) -> CoSimulation:
        self._check_route(route)
        duration = self._episode_duration_s or self._default_duration_s(route)
        # each step's outputs are consumed within the step: the co-simulation reuses their arrays
        options = {**self._sim_options, "sensor_profile": self._episode_profile(seed)}
        return CoSimulation(route, duration_s=duration + self._reset_time_s(), seed=seed, reuse_outputs=True,
                            **options)

    def _begin_episode(self, seed: int | None, options: dict[str, Any] | None) -> dict[str, Any]:
        """Seed the episode, set up its route and sensor, and rewind the co-simulation."""
        if options:
            raise ValueError(f"reset options are not used by this environment, got {sorted(options)}")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                                 or not 0 <= seed <= MAX_SEED):
            raise ValueError(f"seed must be None or an int in [0, 2**63 - 1], got {seed!r}")
        super().reset(seed=None if seed is None else int(seed))
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(0, 2**63 - 1))
        route_sequence, sensor_sequence, gnss_sequence = np.random.SeedSequence(episode_seed).spawn(3)
        sensor_seed = self._sensor_seed if self._sensor_seed is not None else _int_seed(sensor_sequence)
        route_seed = None
        if self._route_options is not None:
            route_seed = _int_seed(route_sequence)
            self._sim = self._build(random_route(route_seed, **self._route_options), seed=sensor_seed)
        elif self._rebuilt_each_episode:
            self._sim = self._build(self._sim.route, seed=sensor_seed)
        else:
            self._sim.seed = sensor_seed
            self._sim.reset()
        self._window.clear()
        self._sim.detach_all()
        self._sim.attach(self._period_work())
        info = {"episode_seed": episode_seed, "sensor_seed": sensor_seed, "route_seed": route_seed,
                "route": self._sim.route.name}
        if self._gnss is not None:
            info["gnss_seed"] = _int_seed(gnss_sequence)
            self._gnss.reset(self._sim.route.site, info["gnss_seed"])
        self._running = True
        return info

    def _advance(self, command: DriverCommand | None = None):
        """One control period: returns (samples, truth at the samples, estimator outputs)."""
        samples, truth, outputs = self._sim.step(command)
        if self._gnss is not None:
            self._gnss.push(truth)
        if truth.packed.shape[0]:
            self._newest_row = truth.packed[-1]
        if self.render_mode == "human":
            self.render()
        return samples, truth, outputs

    def _period_work(self) -> PeriodWork:
        """What is updated after every control period, attached to the co-simulation: the
        IMU window (a subclass adds its own updates, in one kernel with the window's)."""
        return PeriodWork(_window_work, (self._window.values,))

    def _first_period(self, command: DriverCommand | None = None):
        """Advance from the reset until the observation holds a sample: one period at the
        default rates, more when the sensor's output rate is below the control rate."""
        while True:
            samples, truth, outputs = self._advance(command)
            if len(samples):
                return samples, truth, outputs

    def _require_running(self) -> None:
        if not self._running:
            raise ResetNeeded("call reset() first: the episode has not started or has ended")

    def _end_if(self, terminated: bool, truncated: bool) -> None:
        if terminated or truncated:
            self._running = False

    @property
    def _truncated(self) -> bool:
        return self._sim.done

    # ------------------------------------------------------------------ actions
    def _check_action(self, action: Any) -> np.ndarray:
        """The action as a float64 array of the action space's shape, finite, within bounds
        (clipped or refused per ``action_bounds``). Raises ValueError before anything changes."""
        a = self._action_array(action)
        if _inside(a, self.action_space.low, self.action_space.high):  # the common case in one call
            return a
        return self._bounded_action(a)

    def _action_array(self, action: Any) -> np.ndarray:
        """The action as a new float64 array of the action space's shape (else ValueError)."""
        space = self.action_space
        try:
            a = np.array(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action must be an array of {space.shape[0]} real numbers, got {action!r}") from None
        if a.shape != space.shape:
            raise ValueError(f"action must have shape {space.shape} ({', '.join(self.ACTION_NAMES)}), got {a.shape}")
        return a

    def _bounded_action(self, a: np.ndarray) -> np.ndarray:
        """``_check_action`` of an ``_action_array`` not inside the bounds (NaN compares
        false): ValueError for a value that is not finite, else clipped or refused."""
        low, high = self.action_space.low, self.action_space.high
        bad = ~np.isfinite(a)
        if bad.any():
            names = [self.ACTION_NAMES[i] for i in np.flatnonzero(bad)]
            raise ValueError(f"action must be finite; {', '.join(names)} is {a[bad].tolist()}")
        outside = (a < low) | (a > high)
        if outside.any():
            if self._action_bounds == "raise":
                parts = [f"{self.ACTION_NAMES[i]}={a[i]!r} not in [{low[i]:g}, {high[i]:g}]"
                         for i in np.flatnonzero(outside)]
                raise ValueError("action out of bounds: " + "; ".join(parts) + ' (action_bounds="raise")')
            a = np.clip(a, low, high)
        return a

    # ------------------------------------------------------------------ rendering
    def render(self) -> np.ndarray | None:
        """An RGB frame (height, width, 3) of the chase camera, or None in ``"human"`` mode."""
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode: pass render_mode='rgb_array' to make()")
            return None
        model, data = self._sim.vehicle.model, self._sim.vehicle.data
        if self._viewer is not None and self._viewer.model is not model:  # a new route: a new model
            self._viewer.close()
            self._viewer = None
        if self._viewer is None:
            if self.render_mode == "rgb_array":
                from biso_cosim.envs._render import road_geoms

                self._viewer = _Offscreen(model, *self._render_size, camera=self.CAMERA,
                                          road=road_geoms(self._sim.route))
            else:
                self._viewer = _Window(model, data, camera=self.CAMERA, route=self._sim.route)
        return self._viewer.render(data)

    def close(self) -> None:
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    # ------------------------------------------------------------------ observations
    def split_observation(self, observation: np.ndarray) -> dict[str, np.ndarray]:
        """The parts of an observation by name in physical units (float64: the observation
        times its scales), shaped as in ``observation_structure``."""
        obs = np.asarray(observation)
        if obs.shape != self.observation_space.shape:
            raise ValueError(f"observation must have shape {self.observation_space.shape}, got {obs.shape}")
        physical = obs.astype(np.float64) * self.observation_scale
        out, start = {}, 0
        for name, shape in self.observation_structure.items():
            size = int(np.prod(shape))
            out[name] = physical[start:start + size].reshape(shape)
            start += size
        return out

    def physical_observation(self) -> dict[str, np.ndarray]:
        """The current observation's parts exactly as the environment keeps them (float64,
        SI units, every column, e.g. the IMU rows with all of ``IMU_FIELDS``): copies."""
        return {name: part.copy() for name, part in self._raw_parts(self._observation_buffer).items()}

    def _raw_parts(self, raw: np.ndarray) -> dict[str, np.ndarray]:
        out, start = {}, 0
        for name, shape in self._raw_structure.items():
            size = int(np.prod(shape))
            out[name] = raw[start:start + size].reshape(shape)
            start += size
        return out

    def _set_observation_space(self) -> None:
        """The observation space, and the array the physical parts are kept in:
        ``_observation_parts`` are views of it by name (the IMU window and the GNSS part are
        kept in it; a subclass keeps its own parts there too).

        The observation is the float32 image of that array: each column divided by its scale
        (``_raw_scales``: name → column → ``Scale``) and clipped to its bounds, without the
        columns in ``_dropped`` (constant ones). ``observation_structure`` names its parts,
        ``observation_fields`` its columns, ``observation_scale`` the scale of each."""
        size = sum(int(np.prod(shape)) for shape in self._raw_structure.values())
        index, scale, low, high, fields = [], [], [], [], []
        self.observation_structure = {}
        start = 0
        for name, shape in self._raw_structure.items():
            columns = self._raw_scales[name]
            if len(columns) != shape[-1]:
                raise RuntimeError(f"{type(self).__name__}: part {name!r} has {shape[-1]} columns, "
                                   f"{len(columns)} scales")  # (a programming error)
            dropped = self._dropped.get(name, {})
            rows = int(np.prod(shape[:-1]))
            # a column is kept when some row keeps it (rows where it is constant then read it too)
            kept = [j for j, column in enumerate(columns) if len(dropped.get(column, ())) < rows]
            for r in range(rows):
                for j in kept:
                    column = list(columns)[j]
                    sc = columns[column]
                    index.append(start + r * shape[-1] + j)
                    scale.append(sc[0])
                    low.append(sc[1])
                    high.append(sc[2])
                    fields.append(f"{name}[{r}].{column}" if len(shape) > 1 else f"{name}.{column}")
            self.observation_structure[name] = (*shape[:-1], len(kept))
            start += int(np.prod(shape))
        self._obs_index = np.array(index, dtype=np.int64)
        self.observation_scale = np.array(scale)
        """Physical value of one unit of each observed column (SI units of ``observation_fields``)."""
        self.observation_fields = tuple(fields)
        """Name of each observed column: ``part[row].column``."""
        self._obs_inverse_scale = 1.0 / self.observation_scale
        self._obs_low = np.array(low, dtype=np.float32)
        self._obs_high = np.array(high, dtype=np.float32)
        self.observation_space = gym.spaces.Box(self._obs_low.copy(), self._obs_high.copy(), dtype=np.float32)
        self._obs_bounds = (self._obs_index, self._obs_inverse_scale, self._obs_low.astype(np.float64),
                            self._obs_high.astype(np.float64))
        self._observation_buffer = np.zeros(size)
        self._observation_parts = self._raw_parts(self._observation_buffer)
        for holder, name in ((self._window, "imu"), (self._gnss, "gnss")):
            if holder is not None:
                self._observation_parts[name][:] = holder.values
                holder.values = self._observation_parts[name]

    def _public(self, raw: np.ndarray) -> np.ndarray:
        """The observation of a raw (physical) array: scaled, clipped, float32."""
        return _scale_observation(raw, *self._obs_bounds)

    def _observation(self) -> np.ndarray:
        """The observation now."""
        return _scale_observation(self._observation_buffer, *self._obs_bounds)
