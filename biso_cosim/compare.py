"""Accuracy comparison of the estimators and their open peers on the same simulated MPU-9250 data.

A *dataset* is one run of the virtual MPU-9250: a vehicle route driven by the co-simulation,
or an analytic test motion (``biso_cosim.motions``) fed through the same sensor model. Every
estimator sees exactly the same samples; the estimators do not act on the vehicle, so
running them after the drive gives the same numbers as running them in the loop.

Peers (optional dependencies, extra ``compare``):

``vqf``        VQF of Laidig & Seel (2023), the real-time (causal) ``vqf.VQF.updateBatch`` with
               its default parameters (``offlineVQF`` looks ahead and is not comparable);
``imufusion``  x-io Fusion AHRS with its documented example settings (gain 0.5, acceleration
               and magnetic rejection 10°, recovery 5 s) and its gyro offset corrector.

Both report heading to magnetic north; their output is turned to true north with the site's
declination, which our estimators receive as a parameter. ``biso_plus`` gets the speed of
the rear axle from wheel odometry (mean rear wheel rate × wheel radius, so with wheel slip)
and, with it, the car's parameters it takes from its vehicle (``Estimator.vehicle_params``,
``VehicleSim.estimator_defaults``): the position of the rear axle relative to the IMU and
the rear axle's slip angle per g of the route's tyres, D_r = W_r/C_αr (0 for the coulomb
tyres); ``biso_plus_nospeed`` is the same without the speed input (and without them). Test
motions have no speed.

Errors are estimate minus truth in roll, pitch and compass heading (``biso_cosim.metrics``),
RMS and largest magnitude per dataset, over all samples.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

from biso_cosim import peers
from biso_cosim.estimators import estimator_vehicle_params, make_estimator
from biso_cosim.metrics import ANGLES, angle_errors_deg
from biso_cosim.output import write_text_atomic

if TYPE_CHECKING:
    from biso_cosim.routes import Route

__all__ = ["Dataset", "route_dataset", "run_dataset", "motion_dataset", "run_method", "compare", "METHODS", "DEFAULT_METHODS",
           "DEFAULT_MOTIONS", "format_table"]

DEFAULT_MOTIONS = ("tumble", "fast_tumble", "shake", "magnet", "translation", "slow_translation", "near_magnet",
                   "vibration", "tapping", "moving_start")
"""Non-vehicle motions of the comparison (issue 4's targets; issue 23's BROAD-like ones)."""

# Sensor configuration for the non-vehicle motions: tumbling reaches 5.7 rad/s, beyond the
# vehicle default of ±250 °/s, and shaking about 2.3 g: ±2000 °/s and ±8 g, as a user would set.
MOTION_REGISTERS = {"gyro_fs_sel": 3, "accel_fs_sel": 2}

MOTION_PROFILE = ("mpu9250_calibrated", {"gyro__bias_initial": 0.7, "mag__noise": 0.7})
"""Sensor errors for the non-vehicle motions: a calibrated MPU-9250 (the co-simulation's
default profile) with two residuals as large as BROAD's calibrated IMU shows them (measured on
the ten trials of the shared BROAD subset, docs/estimators.md "Simulated against real"): the
gyro bias at the trials' starting rest, 0.23 °/s RMS per axis over the ten trials (up to
0.48 °/s; tolerance 3σ = 0.7 °/s), and the magnetometer's noise at rest, 0.7 µT per axis.
BROAD's other residuals lie within the calibrated profile's: magnetometer offset 0.2–0.9 µT
(fit against the optical reference on the undisturbed trials), gyro scale factor within 0.6 %
and cross-axis within 0.5 % (the gyro against the reference's rate, on the trials that turn
the sensor every way: 01, 05, 07, 21, 24, 29). The raw profile ``mpu9250`` (a 10 µT offset
tolerance, ±3 % scale factors, a 5 °/s bias) made the motions' heading a test of offset
learning: its unknown offset cost every method 10–25° of heading, which BROAD does not show.
Figures: ``python benchmarks/broad_motions.py``."""


MOTION_SETUP = {name: {"rest_s": 10.0} for name in ("shake", "magnet", "translation", "near_magnet", "vibration")}
MOTION_SETUP["tumble"] = {"rest_s": 10.0, "hand_accel_mps2": 2.25}
MOTION_SETUP["fast_tumble"] = {"rest_s": 10.0, "hand_accel_mps2": 4.63}
_LAB_GRADIENT_UT_PER_M = ((0.7, 0.8, -1.3), (0.8, 1.8, -0.7), (-1.3, -0.7, -2.5))
MOTION_SETUP["translation"] = {"rest_s": 40.0, "hand_rate_dps": (57.0, 67.0, 123.0),
                               "field_gradient_ut_per_m": _LAB_GRADIENT_UT_PER_M,
                               "path_field": (1.019, -1.58, -0.26), "rest_field": (0.945, 1.77, 2.43)}
MOTION_SETUP["slow_translation"] = {"rest_s": 33.0, "field_gradient_ut_per_m": _LAB_GRADIENT_UT_PER_M,
                                    "path_field": (1.003, 0.88, 0.14), "rest_field": (0.990, 1.96, -0.39)}
MOTION_SETUP["shake"] = {"rest_s": 10.0, "spin_dps": -249.0, "wobble_deg": (56.0, 20.0, 56.0),
                         "wobble_hz": (0.8, 1.2, 0.9), "accel_g": 1.566, "accel_hz": (1.0, 1.5, 2.3),
                         "base_deg": (189.0, 8.6, 0.0)}
MOTION_SETUP["tapping"] = {"rest_s": 10.0, "hand_accel_mps2": 2.23}
MOTION_SETUP["vibration"] = {"rest_s": 10.0, "vib_span": (0.19, 1.0),
                             "hand": {"wobble_deg": (4.3, 2.6, 1.85), "wobble_hz": (1.2, 2.0, 2.8), "accel_g": 0.333,
                                      "accel_hz": (0.45, 0.7, 1.1)}}
MOTION_SETUP["near_magnet"] = {"rest_s": 10.0, "distance_m": 0.5,
                               "hand": {"spin_dps": -154.0, "wobble_deg": (56.0, 12.0, 56.0),
                                        "wobble_hz": (0.8, 1.2, 0.9), "accel_g": 1.278, "accel_hz": (1.1, 1.7, 2.5),
                                        "base_deg": (193.0, 8.6, 20.0)},
                               "magnet_at_rest": (0.15, 3.0),
                               "passes": ((0.55, 0.105, 0.8), (0.58, 0.105, 0.8), (0.85, 0.105, 0.8))}
"""Keyword arguments of the motions as the comparison runs them, as BROAD's trials were
recorded (docs/estimators.md "Simulated against real"). ``rest_s``: seconds at rest before
the motion (added to its duration): BROAD's trials start at rest (26–46 s in the ten of the
shared subset) and are scored over the movement, so an estimator meets their motions
converged and with its gyro bias learned at rest (which biso_plus needs before it learns a
magnetometer offset); started in motion, the first attitude of ``translation`` was tilted by
up to atan(2 g / g) and its convergence counted in the RMS error. ``moving_start`` is the
motion that tests a start in motion. ``hand_accel_mps2``: the hand's acceleration while it turns the sensor, BROAD's
rotation trials' mean for ``tumble`` (1.20, 0.91 and 4.63 m/s² RMS on 01, 05, 07), the fast
trial 07's for ``fast_tumble``. ``hand_rate_dps``: the hand's rotation while it moves the
sensor fast, BROAD's fast translation trial 15 (RMS about x, y, z). ``field_gradient_ut_per_m``:
the field of BROAD's lab changes with the position by about 4 µT/m (fitted on the translated
trials 11, 15 and 27, where it explains 45–65 % of the field's residual; the mean made
symmetric and traceless); only a motion that moves the sensor by decimetres feels it.
``path_field``, ``rest_field``: the field where the sensor is moved and where it rests before,
against the Earth's (norm ratio, azimuth and dip changes in degrees), as BROAD's translation
trials met them (the field turned to ENU with the reference, against the lab's field fitted on
the rotation trials): trial 15 rests 40 s where the field is 5.5 % weaker, turned by +1.8° and
dipping 2.4° more, and is moved where it is 1.9 % stronger and turned by −1.6°; trial 11 rests
33 s and moves where the field is within 1 % and 2° of the lab's. An estimator that follows the
field, as VQF does with its 9 s, turns with it by about 3° when trial 15's movement starts
(VQF's heading error −2.7° over its first 40 s); biso_plus, which weighs the heading down while
|m| differs from the field it has learned (κ D), follows it slowly, and leads VQF there (0.76×).
Simulated with the rest of 10 s of the other motions, VQF had not yet settled on the rest's field
when the movement began. ``slow_translation`` is trial 11: decimetres of travel at 0.56 Hz with
the hand's turns in step and hardly any other change of attitude, so the gradient passes for an
offset; biso_plus's online offset estimate takes it for one (1.6× VQF on the trial, 0.93° of
total RMSE without the estimate against 1.43° with it; ``motions.slow_translation``).
``tapping`` is BROAD's tapping trial 24: the hand turns the sensor as on the rotation trials
(156 °/s median; its acceleration below 20 Hz 2.23 m/s² RMS, the trial's) while a finger taps it
every 4 s with 50–130 m/s² at 90 Hz along z (``motions.tapping``).
``shake`` is BROAD's fast combined trial 21 (rotation and translation together): the sensor
spun about its y axis at −249 °/s (the trial's mean rate) while the hand turns it ±56° in yaw
and roll, ±20° in pitch at 0.8–1.2 Hz (|ω| median 388 °/s, RMS 232, 280, 175 °/s about x, y, z
on the trial) and translates it with 10.9 m/s² RMS at 1.0–2.3 Hz (trial: 10.86 at a median
1.53 Hz), about a base attitude (``base_deg``) that keeps the spin axis near the world's north
(the mean rate in ENU: trial 21 (−14, 138, 1) °/s, here (−27…−15, 144…148, −7…3) on seeds 0–2).
That axis matters: the field reaches the estimator τ ≈ 10.7 ms after the gyro's rate
(``MOTION_MAG_DELAY_S``), so under a steady spin ω about north it is off by τ ω × B, an eastward
error τ ω B_up, a heading error of τ ω B_up/B_north (2.65 times the spin's angle τ ω in BROAD's
lab; about east, none). With the spin axis 45° from north (the default base) VQF's heading RMS
was 1.3–1.4° (seeds 0, 1), with it along north 2.4–3.6°, and 1.0–1.6° with it along north but
no lag (``MOTION_MAG_DELAY_S`` = 0); trial 21: 3.7°. The hand shaking of before (±5–10°,
100 °/s, 6.8 m/s² at 3.7 Hz) had none of it.
``near_magnet`` is BROAD's stationary-magnet trial 29: the same kind of motion (spin −154 °/s,
8.9 m/s² RMS at 1.1–2.5 Hz; the mean rate in ENU (−11, 66, −38) °/s on the trial, here about
(−14, 86, −40)) 0.5 m from the magnet (about 1 µT of it), which lies beside the
resting sensor for the last 3 s of the rest (|m| 25 µT up; trial 29: 28 µT) and which the
sensor passes three times at 0.105 m (|m| 20 µT down, 0.8 s each; trial 29: brief passes
with 20–34 µT), |m| more than 5 µT off on 1.5–1.7 % of the movement (trial 29: 1.5 %); the slow
handling of before (12 °/s) 0.2–0.45 m from it felt tens of µT all the time.
``vibration`` is BROAD's phone-vibration trial 27 as a whole: the phone vibrates from 19 % of
the movement to its end (trial 27: from 22 s into its 117 s; the middle third before), while
the hand turns the sensor at 23 °/s RMS per axis around 2 Hz and moves it with 2.3 m/s² RMS
at 0.45–1.1 Hz below 20 Hz (trial 27: 23, 23, 24 °/s, median frequency 2.0 Hz; 2.3 m/s² at a
median 0.70 Hz; before: slow turns of 11 °/s median and no translation)
(``motions.shake``, ``motions.near_magnet``, ``motions.vibration``; figures: ``python
benchmarks/broad_motions.py``)."""


MOTION_MAG_DELAY_S = 0.014
"""How much older the field the magnetometer reports is than the motion the gyro reports, on
top of the MPU-9250 model's own timing (its AK8963 at 100 Hz lags the truth by 2.5 ms, the
gyro's 41 Hz filter by 5.9 ms: the field led the gyro by 3.4 ms). BROAD's IMU, fitted on the
fast trials 07, 21, 29 against the optical reference (m ≈ R_refᵀB + o − τ (R_refᵀB × ω)):
τ = 14.0–15.4 ms, its gyro 3.8–4.2 ms behind the reference, so its field lags its gyro by
about 10.7 ms; under fast rotation the field in the gyro's frame is off by |B| |ω| τ (about
3 µT at BROAD 07's median 333 °/s), which on BROAD's fast trials doubles the residual of the
field against the reference (1.3–1.5 µT on the slow ones, 3–4 µT on the fast ones)."""


def motion_profile():
    """The `Profile` of ``MOTION_PROFILE``."""
    from biso_cosim.sensors.profile import Profile

    base, changes = MOTION_PROFILE
    return Profile.load(base).replace(name=f"{base}_broad", **changes)


@dataclass(frozen=True, eq=False)
class Dataset:
    """Sensor samples and the truth at their time stamps."""

    name: str
    kind: str  # "route" or "motion"
    seed: int
    fs_hz: float
    t_s: np.ndarray
    gyro_b: np.ndarray
    accel_b: np.ndarray
    mag_b: np.ndarray
    q_true: np.ndarray
    declination_rad: float
    speed_mps: np.ndarray | None = None
    vehicle_params: dict = field(default_factory=dict)
    """The vehicle's values of the estimators' ``vehicle_params`` (``VehicleSim.estimator_defaults``:
    where the speed is measured, the rear axle's slip angle per g); empty for test motions."""
    gyro_range_rad_s: float | None = None
    info: dict = field(default_factory=dict)


def route_dataset(route: str | Route, seed: int = 0, duration_s: float | None = None) -> Dataset:
    """Drive ``route`` in the co-simulation (sensor seed ``seed``) and keep its samples, with
    the car's parameters that estimators take from their vehicle."""
    from biso_cosim.cosim import CoSimulation

    sim = CoSimulation(route, duration_s=duration_s, seed=seed, estimators=("poisson",))
    return run_dataset(sim, sim.run())


def run_dataset(sim, result) -> Dataset:
    """The samples of a finished run (``result`` of the co-simulation ``sim``) as a route
    ``Dataset``: wheel odometry at the rear axle (mean rear wheel rate × wheel radius) and the
    car's ``VehicleSim.estimator_defaults``."""
    radius = sim.vehicle.index.wheel_radius_m
    odometry = 0.5 * (result.truth.wheel_rates[:, 2] + result.truth.wheel_rates[:, 3]) * radius
    gyro_fs = {0: 250.0, 1: 500.0, 2: 1000.0, 3: 2000.0}[int(result.sensor["registers"].get("gyro_fs_sel", 0))]
    return Dataset(
        name=sim.route.name, kind="route", seed=sim.seed, fs_hz=float(result.sensor["output_rate_hz"]),
        t_s=result.t_s, gyro_b=result.imu.gyro_b, accel_b=result.imu.accel_b, mag_b=result.imu.mag_b,
        q_true=result.truth.q_wb, declination_rad=math.radians(result.site["declination_deg"]), speed_mps=odometry,
        vehicle_params=sim.vehicle.estimator_defaults(), gyro_range_rad_s=math.radians(gyro_fs),
        info={"completed": result.completed, "field_enu_ut": result.site["field_enu_ut"]})


def motion_dataset(name: str, seed: int = 0, duration_s: float | None = None) -> Dataset:
    """A test motion (``biso_cosim.motions``) at 1 kHz through the virtual MPU-9250 (``MOTION_REGISTERS``,
    ``MOTION_PROFILE``) with the arguments of ``MOTION_SETUP``; ``info`` holds the field and the
    motion's masks at the samples (``moving``: not in the rest before it; all samples if it has none)."""
    from biso_cosim.motions import make_motion
    from biso_cosim.sensors import MPU9250, EarthField, Registers

    earth = EarthField()  # the default site (Saratov)
    motion = make_motion(name, duration_s, 1000.0, seed=seed, field_w=tuple(earth.field_enu_ut),
                         **MOTION_SETUP.get(name, {}))
    imu = MPU9250(motion_profile(), seed=seed, registers=Registers(**MOTION_REGISTERS), input_rate_hz=1000.0)
    lag = int(round(MOTION_MAG_DELAY_S * 1000.0))
    mag_b = np.concatenate([np.repeat(motion.mag_b[:1], lag, axis=0), motion.mag_b[:len(motion) - lag]])
    s = imu.simulate(motion.omega_b, motion.specific_force_b, mag_b)
    idx = np.clip(np.rint(s.t_s * 1000.0).astype(np.int64), 0, len(motion) - 1)
    masks = {k: v[idx] for k, v in motion.info.items()  # "moving", "vibrating": at the samples
             if isinstance(v, np.ndarray) and v.dtype == bool and v.shape == (len(motion),)}
    return Dataset(
        name=name, kind="motion", seed=seed, fs_hz=imu.output_rate_hz, t_s=s.t_s, gyro_b=s.gyro_b,
        accel_b=s.accel_b, mag_b=s.mag_b, q_true=motion.q_wb[idx], declination_rad=earth.declination_rad,
        gyro_range_rad_s=math.radians(2000.0), info={"field_enu_ut": [float(x) for x in earth.field_enu_ut],
                                                     "moving": np.ones(len(idx), bool), **masks})


# --------------------------------------------------------------------------------------
# methods
# --------------------------------------------------------------------------------------


def _ours(name: str, use_speed: bool = False, **fixed: Any) -> Callable[[Dataset], np.ndarray]:
    def run(d: Dataset) -> np.ndarray:
        params = dict(fixed, declination_rad=d.declination_rad)
        inputs = {}
        if use_speed and d.speed_mps is not None:  # the vehicle's parameters go with its speed
            params |= {p: d.vehicle_params[p] for p in estimator_vehicle_params(name) if p in d.vehicle_params}
            inputs["speed_mps"] = d.speed_mps
        est = make_estimator(name, d.fs_hz, **params)
        return est.update(d.gyro_b, d.accel_b, d.mag_b, **inputs).q_wb
    return run


def _vqf(d: Dataset) -> np.ndarray:
    return peers.vqf(d.gyro_b, d.accel_b, d.mag_b, d.fs_hz, d.declination_rad)


def _imufusion(d: Dataset) -> np.ndarray:
    return peers.imufusion(d.gyro_b, d.accel_b, d.mag_b, d.fs_hz, d.declination_rad,
                           gyroscope_range=math.degrees(d.gyro_range_rad_s or math.radians(2000.0)))


METHODS: dict[str, Callable[[Dataset], np.ndarray]] = {
    "biso": _ours("biso"),
    "positional": _ours("positional"),
    "poisson": _ours("poisson"),
    "dcm_pi": _ours("dcm_pi"),
    "biso_plus": _ours("biso_plus", use_speed=True),
    "biso_plus_nospeed": _ours("biso_plus"),
    "vqf": _vqf,
    "imufusion": _imufusion,
}
"""Name → function(dataset) → q_wb (N, 4)."""

DEFAULT_METHODS = tuple(METHODS)


def run_method(name: str, d: Dataset) -> np.ndarray:
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; known: {', '.join(METHODS)}")
    return METHODS[name](d)


def _stats(q: np.ndarray, d: Dataset) -> dict[str, dict[str, float]]:
    """RMS and largest absolute error of each angle and of the total attitude error over the
    samples of ``d.info["moving"]`` (a motion's rest before it is not scored, as BROAD scores
    only the movement of its trials); over every sample where the dataset has no such mask
    (routes)."""
    err = angle_errors_deg(q, d.q_true)
    moving = d.info.get("moving")
    keep = np.ones(len(q), bool) if moving is None else np.asarray(moving, bool)
    return {a: {"rms_deg": float(np.sqrt(np.mean(err[a][keep] ** 2))),
                "max_abs_deg": float(np.max(np.abs(err[a][keep])))}
            for a in (*ANGLES, "total")}


def compare(routes: Iterable[str] = ("figure8",), motions: Iterable[str] = DEFAULT_MOTIONS,
            seeds: Iterable[int] = (0,), methods: Iterable[str] = DEFAULT_METHODS, *,
            route_duration_s: float | None = None, motion_duration_s: float | None = None,
            progress: Callable[[str], None] | None = None,
            on_dataset: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """Run every method on every (dataset, seed); returns ``{"rows": [...], "config": {...}}``.

    Each row: dataset, kind, seed, method, errors {roll, pitch, heading, total: {rms_deg,
    max_abs_deg}}, seconds (wall time of the method on that dataset). A method whose optional
    dependency is missing is reported once in ``config["skipped"]`` and left out.
    ``progress(message)`` is called before each (dataset, seed); ``on_dataset(result)`` after
    each, with the rows so far (the CLI writes them, so that an interrupted comparison keeps
    the datasets that finished).
    """
    methods = list(methods)
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"unknown method {m!r}; known: {', '.join(METHODS)}")
    rows, skipped = [], {}
    routes, motions, seeds = list(routes), list(motions), list(seeds)

    def result() -> dict[str, Any]:
        return {"rows": list(rows), "config": {"routes": routes, "motions": motions, "seeds": [int(s) for s in seeds],
                                               "methods": methods, "skipped": dict(skipped),
                                               "motion_registers": MOTION_REGISTERS}}

    jobs = [("route", r) for r in routes] + [("motion", m) for m in motions]
    for seed in seeds:
        for kind, name in jobs:
            if progress:
                progress(f"{kind} {name} seed {seed}")
            d = route_dataset(name, seed, route_duration_s) if kind == "route" else \
                motion_dataset(name, seed, motion_duration_s)
            for m in methods:
                if m in skipped:
                    continue
                start = time.perf_counter()
                try:
                    q = run_method(m, d)
                except ImportError as exc:
                    skipped[m] = f"not installed: {exc.name or exc}"
                    continue
                rows.append({"dataset": name, "kind": kind, "seed": int(seed), "method": m,
                             "errors": _stats(q, d), "seconds": time.perf_counter() - start,
                             "samples": int(len(d.t_s))})
            if on_dataset:
                on_dataset(result())
    return result()


def summarize(result: dict[str, Any]) -> dict[tuple[str, str], dict[str, float]]:
    """Mean over seeds of the RMS errors: {(dataset, method): {roll, pitch, heading, total}}."""
    acc: dict[tuple[str, str], list] = {}
    for r in result["rows"]:
        acc.setdefault((r["dataset"], r["method"]), []).append(r["errors"])
    return {key: {a: float(np.mean([e[a]["rms_deg"] for e in errs])) for a in (*ANGLES, "total")}
            for key, errs in acc.items()}


def format_table(result: dict[str, Any]) -> str:
    """Markdown table: one line per dataset and method, RMS (max) of roll, pitch, heading in degrees,
    averaged over seeds for RMS and the largest over seeds for max."""
    acc: dict[tuple[str, str], list] = {}
    for r in result["rows"]:
        acc.setdefault((r["dataset"], r["method"]), []).append(r["errors"])
    lines = ["| dataset | method | roll RMS (max) ° | pitch RMS (max) ° | heading RMS (max) ° |",
             "|---|---|---|---|---|"]
    for (ds, m), errs in acc.items():
        cells = []
        for a in ANGLES:
            rms = np.mean([e[a]["rms_deg"] for e in errs])
            mx = np.max([e[a]["max_abs_deg"] for e in errs])
            cells.append(f"{rms:.2f} ({mx:.1f})")
        lines.append(f"| {ds} | {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write(result: dict[str, Any], out_dir: str | Path) -> dict[str, Path]:
    """``results.json`` and ``table.md`` in ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "results.json", "table": out / "table.md"}
    write_text_atomic(paths["json"], json.dumps(result, indent=2))
    write_text_atomic(paths["table"], format_table(result) + "\n")
    return paths
