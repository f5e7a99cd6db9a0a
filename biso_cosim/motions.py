"""Analytic test motions that are not vehicles: truth for estimator tests, ``compare`` and the sensor.

Each motion is an attitude built from elementary rotations whose angles are smooth
functions of time, a position with an analytic second derivative, and a magnetic field in
the world (the Earth's, plus a dipole magnet where the motion has one). Everything is
computed from the analytic derivatives, not by differencing, so the truth is consistent to
rounding: ``q̇_wb = ½ q_wb ∘ ω_b``, ``f_b = q_wb* ∘ (p̈_w + g up) ∘ q_wb``,
``mag_b = q_wb* ∘ B_w ∘ q_wb``.

Body rate of a chain ``q = R_1 R_2 ⋯ R_n``, ``R_j = exp(½ θ_j u_j)`` about fixed unit axes
u_j: ``ω_b = Σ_j θ̇_j (R_{j+1} ⋯ R_n)* u_j (R_{j+1} ⋯ R_n)``. The ZYX Euler chain used for
tumbling has no singularity in this direction, so the motions pass through ±90° pitch.

Motions (``MOTIONS``; ``make_motion(name, duration_s, fs_hz, seed=...)``):

``static``   at rest at a fixed attitude;
``rotation`` constant body rate (default 2 rad/s about a skew axis);
``tumble``   fast rotations through all attitudes (roll and yaw turn full circles, pitch
             swings to ±109°; peak rate about 5 rad/s);
``shake``    hand shaking: ±(5–10)° wobble at 1–3 Hz and translational shaking of about
             1 g peak at 2–6 Hz;
``magnet``   slow handling while a magnet (dipole 0.5 A·m²) is brought to 4 cm of the sensor
             and taken away (field up to ~1.5 mT), then the Earth field alone again;
``translation`` fast handheld translations (BROAD's "fast translation" trials, Laidig et al.
             2021): ±(10–15)° slow attitude changes while the sensor is moved back and forth
             along all three axes at 1–2.5 Hz, about 1 g RMS of |f| − g (peaks near 3 g),
             for the whole motion;
``near_magnet`` the sensor handled (slow turns, ±0.15 m moves) 0.2–0.45 m from a magnet
             fixed in the room (BROAD's "stationary magnet" trials): the field's direction
             and norm change by a few to tens of µT with the position, partly below the
             norm test's threshold;
``vibration`` slow handling with a phone vibrating on the sensor (BROAD's "phone vibration"
             trials) during the middle third: a 150 Hz vibration of ±0.05° and ±0.02 mm
             (rates up to ~1 rad/s, accelerations ~2 g, both aliased at a 200 Hz sample rate)
             and the phone's own field, fixed in body axes (a hard-iron offset that comes and
             goes: 5 µT);
``moving_start`` recording started in motion: a sensor swung in the hand (0.9 Hz sway, 1.9 Hz
             bounce) whose horizontal acceleration is at its peak (``accel_g``, default 0.5 g) at
             t = 0, with slow turns: an estimator that takes its first attitude (and the
             expected field's dip with it) from the first sample starts tilted by atan(0.5) = 27°;
``coning``   classical coning: the body axis z sweeps a cone of half-angle α at Ω;
``circle``   level driving on a circle at constant speed (a vehicle's centripetal acceleration
             with an exact speed, for the acceleration compensation of biso_plus).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from biso_cosim.frames import quat_conjugate, quat_from_rotvec, quat_multiply, quat_rotate
from biso_cosim.units import G0

__all__ = ["Motion", "MOTIONS", "make_motion", "motion_names", "EARTH_FIELD_W", "dipole_field"]

EARTH_FIELD_W = (0.0, 18.0, -46.0)
"""Default Earth field in µT, ENU (about |B| = 49 µT, dip 69°: mid-northern latitudes)."""

_MU0_4PI_UT = 0.1  # µ0/4π in µT·m/A: B[µT] = 0.1 (3(m·r̂)r̂ − m)/r³ with m in A·m², r in m


@dataclass(frozen=True, eq=False)
class Motion:
    """Truth of a test motion, sampled at ``fs_hz`` from t = 0.

    Attributes: ``t_s`` (N,); ``q_wb`` (N, 4) body → ENU; ``omega_b`` (N, 3) rad/s;
    ``specific_force_b`` (N, 3) m/s² (+g up at rest); ``mag_b`` (N, 3) µT; ``accel_w``
    (N, 3) kinematic acceleration in ENU, m/s²; ``mag_w`` (N, 3) field at the sensor in ENU,
    µT (Earth + disturbance); ``earth_field_w`` (3,) the undisturbed field.
    """

    name: str
    fs_hz: float
    t_s: np.ndarray
    q_wb: np.ndarray
    omega_b: np.ndarray
    specific_force_b: np.ndarray
    mag_b: np.ndarray
    accel_w: np.ndarray
    mag_w: np.ndarray
    earth_field_w: np.ndarray
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return self.t_s.shape[0]


_AXES = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}


def rotation_chain(axes: list[np.ndarray], angles: np.ndarray, rates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``q = R_1 ⋯ R_n`` and ``ω_b`` of a chain of rotations about fixed axes.

    ``angles``, ``rates``: (N, n) angle θ_j(t) in rad and its derivative in rad/s.
    """
    n = len(axes)
    factors = [quat_from_rotvec(angles[:, j:j + 1] * axes[j][None, :]) for j in range(n)]
    q = factors[0]
    for j in range(1, n):
        q = quat_multiply(q, factors[j])
    omega = np.zeros((angles.shape[0], 3))
    tail = np.tile([1.0, 0.0, 0.0, 0.0], (angles.shape[0], 1))  # R_{j+1} ⋯ R_n
    for j in range(n - 1, -1, -1):
        omega += rates[:, j:j + 1] * quat_rotate(quat_conjugate(tail), axes[j])
        tail = quat_multiply(factors[j], tail)
    return q, omega


def dipole_field(moment_w: np.ndarray, r_w: np.ndarray) -> np.ndarray:
    """Field in µT of a dipole ``moment_w`` (A·m²) at the offset ``r_w`` (N, 3) m from it."""
    r = np.linalg.norm(r_w, axis=1, keepdims=True)
    rhat = r_w / r
    mdotr = rhat @ moment_w
    return _MU0_4PI_UT * (3.0 * mdotr[:, None] * rhat - moment_w[None, :]) / r**3


def _assemble(name, fs_hz, t, q, omega, accel_w, mag_w, earth, g, info) -> Motion:
    qc = quat_conjugate(q)
    f_w = accel_w + np.array([0.0, 0.0, g])
    return Motion(name, fs_hz, t, q, omega, quat_rotate(qc, f_w), quat_rotate(qc, mag_w),
                  accel_w, mag_w, earth, info)


def _time(duration_s: float, fs_hz: float) -> np.ndarray:
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be positive and finite, got {duration_s!r}")
    if not (math.isfinite(fs_hz) and fs_hz > 0):
        raise ValueError(f"fs_hz must be positive and finite, got {fs_hz!r}")
    return np.arange(int(round(duration_s * fs_hz))) / fs_hz


def _euler_chain(t, yaw, pitch, roll):
    """ZYX chain from (angle, rate) pairs of callables."""
    angles = np.stack([yaw[0](t), pitch[0](t), roll[0](t)], axis=1)
    rates = np.stack([yaw[1](t), pitch[1](t), roll[1](t)], axis=1)
    return rotation_chain([_AXES["z"], _AXES["y"], _AXES["x"]], angles, rates)


def _sines(rng, t, amp, freqs_hz):
    """Σ amp_j sin(2π f_j t + φ_j) per axis and its second derivative; φ from rng."""
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(len(freqs_hz), 3))
    pos = np.zeros((t.size, 3))
    acc = np.zeros((t.size, 3))
    for j, f in enumerate(freqs_hz):
        w = 2.0 * np.pi * f
        s = np.sin(w * t[:, None] + phase[j][None, :])
        pos += amp[j] * s
        acc -= amp[j] * w * w * s
    return pos, acc


def static(duration_s=10.0, fs_hz=200.0, *, seed=0, rpy=(0.1, -0.2, 0.7), field_w=EARTH_FIELD_W, g=G0):
    """At rest at roll, pitch, yaw ``rpy`` (rad)."""
    t = _time(duration_s, fs_hz)
    c = lambda v: (lambda tt: np.full_like(tt, v), lambda tt: np.zeros_like(tt))  # noqa: E731
    q, om = _euler_chain(t, c(rpy[2]), c(rpy[1]), c(rpy[0]))
    earth = np.asarray(field_w, float)
    return _assemble("static", fs_hz, t, q, om, np.zeros((t.size, 3)), np.tile(earth, (t.size, 1)), earth, g, {})


def rotation(duration_s=10.0, fs_hz=200.0, *, seed=0, omega_b=(1.0, -1.2, 1.1), field_w=EARTH_FIELD_W, g=G0):
    """Constant body rate ``omega_b`` (rad/s) from a tilted start."""
    t = _time(duration_s, fs_hz)
    w = np.asarray(omega_b, float)
    q0 = quat_from_rotvec(np.array([0.2, -0.1, 0.9]))
    q = quat_multiply(np.tile(q0, (t.size, 1)), quat_from_rotvec(t[:, None] * w[None, :]))
    earth = np.asarray(field_w, float)
    return _assemble("rotation", fs_hz, t, q, np.tile(w, (t.size, 1)), np.zeros((t.size, 3)),
                     np.tile(earth, (t.size, 1)), earth, g, {"omega_b": w})


def tumble(duration_s=30.0, fs_hz=200.0, *, seed=0, rate_scale=1.0, field_w=EARTH_FIELD_W, g=G0):
    """Fast rotations through all attitudes (roll, yaw full turns; pitch to ±109°)."""
    t = _time(duration_s, fs_hz)
    s = float(rate_scale)
    yaw = (lambda tt: 1.3 * s * tt + 0.7 * np.sin(0.9 * s * tt), lambda tt: 1.3 * s + 0.63 * s * np.cos(0.9 * s * tt))
    pitch = (lambda tt: 1.9 * np.sin(0.55 * s * tt), lambda tt: 1.045 * s * np.cos(0.55 * s * tt))
    roll = (lambda tt: 2.1 * s * tt + np.sin(1.7 * s * tt), lambda tt: 2.1 * s + 1.7 * s * np.cos(1.7 * s * tt))
    q, om = _euler_chain(t, yaw, pitch, roll)
    earth = np.asarray(field_w, float)
    return _assemble("tumble", fs_hz, t, q, om, np.zeros((t.size, 3)), np.tile(earth, (t.size, 1)), earth, g,
                     {"rate_scale": s})


def _swing(amp_rad: float, freq_rad_s: float, phase_rad: float, base_rad: float | None = None):
    """An Euler angle ``base + amp·sin(ω t + φ)`` and its rate ``amp·ω·cos(ω t + φ)``, the
    pair ``_euler_chain`` takes for one axis."""
    rate_amp = amp_rad * freq_rad_s
    if base_rad is None:
        return (lambda tt: amp_rad * np.sin(freq_rad_s * tt + phase_rad),
                lambda tt: rate_amp * np.cos(freq_rad_s * tt + phase_rad))
    return (lambda tt: base_rad + amp_rad * np.sin(freq_rad_s * tt + phase_rad),
            lambda tt: rate_amp * np.cos(freq_rad_s * tt + phase_rad))


def shake(duration_s=20.0, fs_hz=200.0, *, seed=0, accel_g=1.0, field_w=EARTH_FIELD_W, g=G0):
    """Hand shaking: attitude wobble of 5–10° at 1–3 Hz and translation of ~``accel_g`` g peak."""
    t = _time(duration_s, fs_hz)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=3)
    amp, frq = np.radians([6.0, 8.0, 5.0]), 2 * np.pi * np.array([1.3, 2.1, 2.9])

    q, om = _euler_chain(t, *(_swing(amp[j], frq[j], ph[j], base) for j, base in enumerate((0.8, 0.15, -0.1))))
    freqs = [2.0, 3.7, 5.9]
    # amplitude per frequency so that each contributes about a third of the peak
    amp_pos = [accel_g * g / 3.0 / (2 * np.pi * f) ** 2 for f in freqs]
    _, acc = _sines(rng, t, amp_pos, freqs)
    earth = np.asarray(field_w, float)
    return _assemble("shake", fs_hz, t, q, om, acc, np.tile(earth, (t.size, 1)), earth, g, {"accel_g": accel_g})


def magnet(duration_s=30.0, fs_hz=200.0, *, seed=0, moment_am2=0.5, closest_m=0.04, field_w=EARTH_FIELD_W, g=G0):
    """Slow handling while a dipole magnet approaches to ``closest_m`` and leaves again.

    The magnet is near during the middle third of the motion: its distance follows a
    smooth bump from 1.5 m down to ``closest_m`` and back.
    """
    t = _time(duration_s, fs_hz)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=3)
    yaw = _swing(0.6, 0.3, ph[0])
    pitch = _swing(0.25, 0.5, ph[1])
    roll = _swing(0.3, 0.7, ph[2])
    q, om = _euler_chain(t, yaw, pitch, roll)
    T = t[-1] if t.size > 1 else 1.0
    # distance: 1.5 m far away, a raised-cosine dip to closest_m over the middle third
    x = np.clip((t - T / 3.0) / (T / 3.0), 0.0, 1.0)
    dip = 0.5 * (1.0 - np.cos(2.0 * np.pi * x))
    dist = 1.5 - (1.5 - closest_m) * dip
    direction = np.array([0.6, -0.5, 0.62])
    direction /= np.linalg.norm(direction)
    moment = moment_am2 * np.array([0.3, 0.8, -0.52]) / np.linalg.norm([0.3, 0.8, -0.52])
    earth = np.asarray(field_w, float)
    b = earth[None, :] + dipole_field(moment, dist[:, None] * direction[None, :])
    return _assemble("magnet", fs_hz, t, q, om, np.zeros((t.size, 3)), b, earth, g,
                     {"distance_m": dist, "moment_am2": moment_am2})


def translation(duration_s=60.0, fs_hz=200.0, *, seed=0, accel_g=2.0, field_w=EARTH_FIELD_W, g=G0):
    """Fast handheld translations: slow attitude changes (±(10–15)° at 0.05–0.2 Hz) and a
    back-and-forth translation along every axis at 1.1, 1.7 and 2.5 Hz, each of ``accel_g``/3
    g amplitude (|f| − g about 1 g RMS at the default, peaks near 3 g), for the whole motion (the specific force leaves g all the time; its
    spectrum lies a decade above the cut-off of a tilt low-pass of a few seconds)."""
    t = _time(duration_s, fs_hz)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=3)
    amp, frq = np.radians([15.0, 10.0, 12.0]), 2 * np.pi * np.array([0.05, 0.13, 0.19])

    q, om = _euler_chain(t, *(_swing(amp[j], frq[j], ph[j], base) for j, base in enumerate((0.5, 0.1, -0.15))))
    freqs = [1.1, 1.7, 2.5]
    amp_pos = [accel_g * g / 3.0 / (2 * np.pi * f) ** 2 for f in freqs]
    _, acc = _sines(rng, t, amp_pos, freqs)
    earth = np.asarray(field_w, float)
    return _assemble("translation", fs_hz, t, q, om, acc, np.tile(earth, (t.size, 1)), earth, g,
                     {"accel_g": accel_g})


def near_magnet(duration_s=60.0, fs_hz=200.0, *, seed=0, moment_am2=0.5, distance_m=0.3, field_w=EARTH_FIELD_W,
                g=G0):
    """The sensor handled near a magnet fixed in the room: slow turns (yaw ±35°, pitch and
    roll ±15°) and moves of ±0.15 m per axis (0.04–0.11 Hz) about a point ``distance_m``
    from a dipole of ``moment_am2``; the field at the sensor is the Earth's plus the
    dipole's at the sensor's position, so it changes with the position in norm and
    direction (a few µT at 0.45 m, tens at 0.2 m)."""
    t = _time(duration_s, fs_hz)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=6)
    yaw = _swing(0.6, 0.35, ph[0])
    pitch = _swing(0.25, 0.55, ph[1])
    roll = _swing(0.25, 0.75, ph[2])
    q, om = _euler_chain(t, yaw, pitch, roll)
    w = 2 * np.pi * np.array([0.04, 0.07, 0.11])
    pos = 0.15 * np.sin(w[None, :] * t[:, None] + ph[None, 3:])
    acc = -0.15 * w[None, :] ** 2 * np.sin(w[None, :] * t[:, None] + ph[None, 3:])
    direction = np.array([0.6, -0.5, 0.62])
    direction /= np.linalg.norm(direction)
    r = distance_m * direction[None, :] + pos  # sensor relative to the magnet
    moment = moment_am2 * np.array([0.3, 0.8, -0.52]) / np.linalg.norm([0.3, 0.8, -0.52])
    earth = np.asarray(field_w, float)
    b = earth[None, :] + dipole_field(moment, r)
    return _assemble("near_magnet", fs_hz, t, q, om, acc, b, earth, g,
                     {"distance_m": np.linalg.norm(r, axis=1), "moment_am2": moment_am2})


def vibration(duration_s=60.0, fs_hz=200.0, *, seed=0, vib_hz=150.0, vib_angle_rad=np.radians(0.05),
              vib_m=0.02e-3, phone_field_b_ut=(3.0, -2.5, 3.0), field_w=EARTH_FIELD_W, g=G0):
    """Slow handling (yaw ±35°, pitch and roll ±15° at 0.05–0.12 Hz); during the middle third
    a phone vibrates on the sensor: an angular vibration of ``vib_angle_rad`` about a skew
    body axis and a translation of ``vib_m`` along another, both at ``vib_hz`` (smoothly
    switched on and off over 1 s), and the phone's field ``phone_field_b_ut`` fixed in body
    axes (it moves with the sensor: a hard-iron offset that appears and leaves)."""
    t = _time(duration_s, fs_hz)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=3)
    yaw = _swing(0.6, 0.3, ph[0])
    pitch = _swing(0.25, 0.5, ph[1])
    roll = _swing(0.25, 0.75, ph[2])
    T = t[-1] if t.size > 1 else 1.0
    # on/off envelope: raised-cosine ramps of 1 s at T/3 and 2T/3 (its derivatives analytic)
    def env(tt):
        up = np.clip(tt - T / 3.0, 0.0, 1.0)
        down = np.clip(2.0 * T / 3.0 - tt, 0.0, 1.0)
        return 0.5 * (1.0 - np.cos(np.pi * np.minimum(up, down)))

    def denv(tt):
        up, down = tt - T / 3.0, 2.0 * T / 3.0 - tt
        d = np.where((up > 0) & (up < 1) & (up <= down), 1.0, 0.0) - np.where((down > 0) & (down < 1) & (down < up),
                                                                              1.0, 0.0)
        return 0.5 * np.pi * np.sin(np.pi * np.clip(np.minimum(up, down), 0.0, 1.0)) * d

    w = 2.0 * np.pi * vib_hz
    a = float(vib_angle_rad)
    q_slow, om_slow = _euler_chain(t, yaw, pitch, roll)
    axis = np.array([0.5, -0.7, 0.5]) / np.linalg.norm([0.5, -0.7, 0.5])
    th = a * env(t) * np.sin(w * t)
    dth = a * (denv(t) * np.sin(w * t) + env(t) * w * np.cos(w * t))
    q_vib, om_vib = rotation_chain([axis], th[:, None], dth[:, None])
    q = quat_multiply(q_slow, q_vib)
    om = quat_rotate(quat_conjugate(q_vib), om_slow) + om_vib
    # translation along a body direction at the vibration frequency, in the world: its
    # acceleration is that of the amplitude envelope's sine (the slow attitude's change over
    # one period neglected: < 1e-3 of it)
    d_b = np.array([0.2, 0.9, -0.4]) / np.linalg.norm([0.2, 0.9, -0.4])
    d_w = quat_rotate(q_slow, d_b)
    acc = (-vib_m * w * w * env(t) * np.sin(w * t))[:, None] * d_w
    earth = np.asarray(field_w, float)
    on = (env(t) > 0.0)[:, None]
    mag_w = earth[None, :] + on * quat_rotate(q, np.asarray(phone_field_b_ut, float))
    return _assemble("vibration", fs_hz, t, q, om, acc, mag_w, earth, g,
                     {"vib_hz": vib_hz, "vibrating": env(t) > 0.0})


def moving_start(duration_s=60.0, fs_hz=200.0, *, seed=0, accel_g=0.5, field_w=EARTH_FIELD_W, g=G0):
    """Started in motion: slow turns (yaw ±35°, pitch and roll ±15° at 0.05–0.12 Hz) while the
    hand sways the sensor horizontally at 0.9 Hz (a direction from ``seed``) and bounces it at
    1.9 Hz, cosines of time so that both accelerations are at their peak at t = 0: the
    horizontal one ``accel_g`` g (position amplitude accel_g·g/(2π·0.9 Hz)² = 0.15 m at 0.5 g),
    the vertical one a fifth of it. The first sample's specific force is tilted from the
    vertical by atan(accel_g/(1 + accel_g/5)) (25° at the default)."""
    t = _time(duration_s, fs_hz)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=4)
    yaw = _swing(0.6, 0.3, ph[0])
    pitch = _swing(0.25, 0.5, ph[1])
    roll = _swing(0.25, 0.75, ph[2])
    q, om = _euler_chain(t, yaw, pitch, roll)
    a0 = accel_g * g
    sway = np.array([math.cos(ph[3]), math.sin(ph[3]), 0.0])
    # p = −A/ω² cos(ωt): p̈ = A cos(ωt), at its peak at t = 0
    acc = (a0 * np.cos(2 * np.pi * 0.9 * t))[:, None] * sway[None, :]
    acc[:, 2] += 0.2 * a0 * np.cos(2 * np.pi * 1.9 * t)
    earth = np.asarray(field_w, float)
    return _assemble("moving_start", fs_hz, t, q, om, acc, np.tile(earth, (t.size, 1)), earth, g,
                     {"accel_g": accel_g})


def coning(duration_s=10.0, fs_hz=200.0, *, seed=0, half_angle_rad=0.1, rate_rad_s=2 * np.pi, field_w=EARTH_FIELD_W, g=G0):
    """Coning: q = R_z(Ωt) R_x(α) R_z(−Ωt); body rate magnitude 2Ω sin(α/2)."""
    t = _time(duration_s, fs_hz)
    a, w = float(half_angle_rad), float(rate_rad_s)
    angles = np.stack([w * t, np.full_like(t, a), -w * t], axis=1)
    rates = np.stack([np.full_like(t, w), np.zeros_like(t), np.full_like(t, -w)], axis=1)
    q, om = rotation_chain([_AXES["z"], _AXES["x"], _AXES["z"]], angles, rates)
    earth = np.asarray(field_w, float)
    return _assemble("coning", fs_hz, t, q, om, np.zeros((t.size, 3)), np.tile(earth, (t.size, 1)), earth, g,
                     {"half_angle_rad": a, "rate_rad_s": w})


def circle(duration_s=20.0, fs_hz=200.0, *, seed=0, speed_mps=10.0, radius_m=30.0, imu_ahead_m=0.0,
           field_w=EARTH_FIELD_W, g=G0):
    """Level driving on a circle (left turn) at constant speed: yaw rate v/R, centripetal v²/R.

    A reference point (a rear axle: no sideslip) moves on the circle with its velocity along
    body x at ``speed_mps`` (``info["speed_mps"]``); the IMU sits ``imu_ahead_m`` ahead of it
    on the body x axis (``info["speed_point_b_m"]`` is the reference point seen from the IMU).
    """
    t = _time(duration_s, fs_hz)
    w = speed_mps / radius_m
    c = (lambda tt: np.zeros_like(tt), lambda tt: np.zeros_like(tt))
    q, om = _euler_chain(t, (lambda tt: w * tt, lambda tt: np.full_like(tt, w)), c, c)
    # reference point: toward the centre v²/R along body +y; the IMU adds −ω² d along body x
    body_x = np.stack([np.cos(w * t), np.sin(w * t), np.zeros_like(t)], axis=1)
    body_y = np.stack([-np.sin(w * t), np.cos(w * t), np.zeros_like(t)], axis=1)
    acc = speed_mps * w * body_y - w * w * imu_ahead_m * body_x
    earth = np.asarray(field_w, float)
    return _assemble("circle", fs_hz, t, q, om, acc, np.tile(earth, (t.size, 1)), earth, g,
                     {"speed_mps": np.full_like(t, speed_mps), "radius_m": radius_m,
                      "speed_point_b_m": (-float(imu_ahead_m), 0.0, 0.0)})


MOTIONS: dict[str, Callable[..., Motion]] = {
    "static": static,
    "rotation": rotation,
    "tumble": tumble,
    "shake": shake,
    "magnet": magnet,
    "translation": translation,
    "near_magnet": near_magnet,
    "vibration": vibration,
    "moving_start": moving_start,
    "coning": coning,
    "circle": circle,
}
"""Name → motion function ``f(duration_s, fs_hz, *, seed, ...) -> Motion``."""


def motion_names() -> tuple[str, ...]:
    return tuple(MOTIONS)


def make_motion(name: str, duration_s: float | None = None, fs_hz: float = 200.0, *, seed: int = 0, **kwargs) -> Motion:
    """A test motion by name (``motion_names()``); unknown names raise ValueError listing them."""
    if name not in MOTIONS:
        raise ValueError(f"unknown motion {name!r}; known: {', '.join(MOTIONS)}")
    fn = MOTIONS[name]
    if duration_s is None:
        return fn(fs_hz=fs_hz, seed=seed, **kwargs)
    return fn(duration_s, fs_hz, seed=seed, **kwargs)
