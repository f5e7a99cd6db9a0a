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
             swings to ±109°; peak rate about 5 rad/s), optionally with the hand's
             acceleration (``hand_accel_mps2``);
``fast_tumble`` the same 2.6 times faster (BROAD's fast rotation trial: median 330 °/s);
``shake``    hand shaking: ±(5–10)° wobble at 1–3 Hz and translational shaking of about
             1 g peak at 2–6 Hz; its arguments (a spin about body y, the wobble's size, pace and
             base attitude, the translation's pace) make it BROAD's fast combined trial 21;
``magnet``   slow handling while a magnet (dipole 0.5 A·m²) is brought to 4 cm of the sensor
             and taken away (field up to ~1.5 mT), then the Earth field alone again;
``translation`` fast handheld translations (BROAD's "fast translation" trials, Laidig et al.
             2021): ±(10–15)° slow attitude changes while the sensor is moved back and forth
             along all three axes at 1–2.5 Hz, about 1 g RMS of |f| − g (peaks near 3 g),
             for the whole motion;
``near_magnet`` the sensor handled (slow turns, ±0.15 m moves) 0.2–0.45 m from a magnet
             fixed in the room (BROAD's "stationary magnet" trials): the field's direction
             and norm change by a few to tens of µT with the position, partly below the
             norm test's threshold; handled as ``shake`` (``hand``), with the magnet laid beside
             the resting sensor (``magnet_at_rest``) and brief passes (``passes``) it is BROAD's
             trial 29, the magnet met on 1.5 % of the movement;
``vibration`` slow handling with a phone lying on the sensor (BROAD's "phone vibration"
             trials), vibrating during the middle third: a 150 Hz vibration of ±0.0105° and
             ±0.02 mm (accelerations ~2 g, aliased at a 200 Hz sample rate; through the
             MPU-9250's filters 3.6 m/s² and 1.8 °/s RMS, as BROAD trial 27 measured), and the
             phone's own field, fixed in body axes for the whole motion (a hard-iron offset of
             2.4 µT, trial 27's);
             ``vib_span`` and ``hand`` make it trial 27 as a whole (vibrating on 81 % of it,
             the hand's turns and moves);
``tapping``  a finger tapping the sensor (impacts of 5–13 g at 90 Hz along z, every 4 s) while
             the hand turns it (`tumble`): BROAD's tapping trial 24;
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
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from biso_cosim.frames import quat_conjugate, quat_from_rotvec, quat_multiply, quat_rotate
from biso_cosim.units import G0

__all__ = ["Motion", "MOTIONS", "make_motion", "motion_names", "EARTH_FIELD_W", "PHONE_FIELD_B_UT", "dipole_field",
           "recording_statistics"]

EARTH_FIELD_W = (0.0, 18.0, -46.0)
"""Default Earth field in µT, ENU (about |B| = 49 µT, dip 69°: mid-northern latitudes)."""

PHONE_FIELD_B_UT = (-1.47, 0.73, -1.74)
"""The field of a phone lying on the sensor, µT in body axes: BROAD trial 27 (phone vibration),
the mean of m − R_refᵀ B over its movement with B the lab's field (fitted with the offset on
the rotation trials 01, 05, 07), |o| = 2.4 µT, where the undisturbed trials give 0.2–0.9 µT
(their sensor's own offset); after subtracting it the residual is that of an undisturbed trial
(median 1.3 µT), so the field moves with the sensor (``benchmarks/broad_motions.py``)."""

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


def _sines(rng, t, amp, freqs_hz, warp=None):
    """Σ amp_j sin(2π f_j t + φ_j) per axis and its second derivative; φ from rng.

    With ``warp`` = (τ, τ', τ'') of `_rest_warp`, the sum is taken at τ(t) and the second
    derivative is that of p(τ(t)): p''(τ) τ'² + p'(τ) τ''."""
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(len(freqs_hz), 3))
    x = t if warp is None else warp[0]
    pos = np.zeros((x.size, 3))
    vel = np.zeros((x.size, 3))
    acc = np.zeros((x.size, 3))
    for j, f in enumerate(freqs_hz):
        w = 2.0 * np.pi * f
        s = np.sin(w * x[:, None] + phase[j][None, :])
        pos += amp[j] * s
        acc -= amp[j] * w * w * s
        if warp is not None:
            vel += amp[j] * w * np.cos(w * x[:, None] + phase[j][None, :])
    if warp is not None:
        acc = acc * warp[1][:, None] ** 2 + vel * warp[2][:, None]
    return pos, acc


REST_RAMP_S = 1.0
"""Duration of the raised-cosine start after a motion's rest lead-in (``rest_s``)."""


def _rest_warp(t: np.ndarray, rest_s: float):
    """Motion time τ(t) of a motion that starts from rest: τ = 0 until ``rest_s``, then τ'
    rises from 0 to 1 as a raised cosine over REST_RAMP_S, and τ = t − rest_s − REST_RAMP_S/2
    after. Returns (τ, τ', τ''). A motion evaluated at τ holds its t = 0 attitude at rest,
    its body rates are ω(τ)·τ' and its accelerations p''(τ)·τ'² + p'(τ)·τ''."""
    ramp = REST_RAMP_S
    u = np.clip((t - rest_s) / ramp, 0.0, 1.0)
    on = (t > rest_s) & (t < rest_s + ramp)
    tau = np.where(t >= rest_s + ramp, t - rest_s - 0.5 * ramp, 0.5 * ramp * (u - np.sin(np.pi * u) / np.pi))
    dtau = 0.5 * (1.0 - np.cos(np.pi * u))
    ddtau = np.where(on, 0.5 * np.pi / ramp * np.sin(np.pi * u), 0.0)
    return tau, dtau, ddtau


def _time_from_rest(duration_s: float, fs_hz: float, rest_s: float):
    """Sample times of ``rest_s`` at rest followed by ``duration_s`` of motion, and the warp
    (None without a rest: the motion from t = 0, unchanged)."""
    if not (math.isfinite(rest_s) and rest_s >= 0.0):
        raise ValueError(f"rest_s must be >= 0 and finite, got {rest_s!r}")
    t = _time(duration_s + rest_s, fs_hz)
    return t, (None if rest_s == 0.0 else _rest_warp(t, rest_s))


def _warped_chain(t, warp, yaw, pitch, roll):
    """`_euler_chain` at the motion time: the body rate scales with τ' (it is linear in the
    Euler angles' rates)."""
    if warp is None:
        return _euler_chain(t, yaw, pitch, roll)
    q, om = _euler_chain(warp[0], yaw, pitch, roll)
    return q, om * warp[1][:, None]


def _warped_spin_chain(t, warp, yaw, pitch, roll, spin_rad_s: float):
    """`_warped_chain` followed by a steady spin about body y at ``spin_rad_s``: ``q = R_z R_y
    R_x R_y(spin·τ)`` (`rotation_chain`), the body rate scaled with τ' as there."""
    if spin_rad_s == 0.0:
        return _warped_chain(t, warp, yaw, pitch, roll)
    x = t if warp is None else warp[0]
    pairs = (yaw, pitch, roll, (lambda tt: spin_rad_s * tt, lambda tt: np.full_like(tt, spin_rad_s)))
    angles = np.stack([a(x) for a, _ in pairs], axis=1)
    rates = np.stack([r(x) for _, r in pairs], axis=1)
    q, om = rotation_chain([_AXES["z"], _AXES["y"], _AXES["x"], _AXES["y"]], angles, rates)
    return q, (om if warp is None else om * warp[1][:, None])


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


def tumble(duration_s=30.0, fs_hz=200.0, *, seed=0, rate_scale=1.0, rest_s=0.0, hand_accel_mps2=0.0,
           field_w=EARTH_FIELD_W, g=G0):
    """Fast rotations through all attitudes (roll, yaw full turns; pitch to ±109°), after
    ``rest_s`` at rest (`_rest_warp`) if given.

    About the sensor's own point by default (no acceleration). A hand that turns a sensor
    also moves it: ``hand_accel_mps2`` adds a translation at 3.1, 5.7 and 8.3 Hz per axis
    (phases from ``seed``) whose acceleration has that RMS norm. BROAD's rotation trials
    (01, 05, 07) show 0.9–4.6 m/s² RMS (mean 2.25) of kinematic acceleration with its median
    frequency at 5.6–8.2 Hz (``recording_statistics``, ``benchmarks/broad_motions.py``)."""
    t, warp = _time_from_rest(duration_s, fs_hz, rest_s)
    s = float(rate_scale)
    yaw = (lambda tt: 1.3 * s * tt + 0.7 * np.sin(0.9 * s * tt), lambda tt: 1.3 * s + 0.63 * s * np.cos(0.9 * s * tt))
    pitch = (lambda tt: 1.9 * np.sin(0.55 * s * tt), lambda tt: 1.045 * s * np.cos(0.55 * s * tt))
    roll = (lambda tt: 2.1 * s * tt + np.sin(1.7 * s * tt), lambda tt: 2.1 * s + 1.7 * s * np.cos(1.7 * s * tt))
    q, om = _warped_chain(t, warp, yaw, pitch, roll)
    acc = np.zeros((t.size, 3))
    if hand_accel_mps2 > 0.0:
        freqs = [3.1, 5.7, 8.3]
        # nine sines of acceleration amplitude A: RMS norm A·√(9/2)
        amp = float(hand_accel_mps2) / math.sqrt(4.5)
        _, acc = _sines(np.random.default_rng(seed), t, [amp / (2 * np.pi * f) ** 2 for f in freqs], freqs, warp)
    earth = np.asarray(field_w, float)
    return _assemble("tumble", fs_hz, t, q, om, acc, np.tile(earth, (t.size, 1)), earth, g,
                     {"rate_scale": s, "moving": t > rest_s})


def fast_tumble(duration_s=30.0, fs_hz=200.0, *, seed=0, rate_scale=2.6, **kwargs):
    """`tumble` at ``rate_scale`` times its rates: BROAD's fast rotation (trial 07: |ω| median
    333 °/s, 99th percentile 1116 °/s; here 330 and 840 °/s), where a magnetometer that lags
    the gyro by τ is off by |B| |ω| τ in the gyro's frame."""
    return replace(tumble(duration_s, fs_hz, seed=seed, rate_scale=rate_scale, **kwargs), name="fast_tumble")


def tapping(duration_s=60.0, fs_hz=200.0, *, seed=0, rate_scale=1.25, tap_every_s=4.0, tap_peak_mps2=(50.0, 130.0),
            tap_hz=90.0, tap_tau_s=0.015, tap_axis_b=(0.0, 0.0, 1.0), **kwargs):
    """`tumble` (at ``rate_scale``; its other arguments in ``kwargs``) while a finger taps the
    sensor: every ``tap_every_s`` (±25 %, from ``seed``) an impact along ``tap_axis_b`` (body
    axes), a decaying oscillation a e^{−t/τ} sin(2π f t) at ``tap_hz`` with ``tap_tau_s`` and a
    peak a drawn from ``tap_peak_mps2`` (m/s²). BROAD's tapping trial 24: 22 taps in 121 s of
    movement (every 4 s, median), 50–130 m/s² (10th–90th percentile) along the sensor's z,
    each above 5 m/s² for 35–63 ms, the acceleration's power at 87 Hz; the hand turning the
    sensor at 156 °/s median (`tumble` at 1.25×: 155 °/s)."""
    lo, hi = (float(x) for x in tap_peak_mps2)
    axis = np.asarray(tap_axis_b, float)
    if not (tap_every_s > 0.0 and tap_hz > 0.0 and tap_tau_s > 0.0 and 0.0 <= lo <= hi < math.inf
            and axis.shape == (3,) and np.linalg.norm(axis) > 0.0):
        raise ValueError(f"tapping needs tap_every_s, tap_hz, tap_tau_s > 0, 0 <= tap_peak_mps2[0] <= [1] and a "
                         f"non-zero tap_axis_b; got {tap_every_s!r}, {tap_hz!r}, {tap_tau_s!r}, {tap_peak_mps2!r}, "
                         f"{tap_axis_b!r}")
    m = tumble(duration_s, fs_hz, seed=seed, rate_scale=rate_scale, **kwargs)
    rng = np.random.default_rng(seed + 1000)
    t = m.t_s
    moving = m.info["moving"]
    start = t[np.argmax(moving)] if np.any(moving) else t[0]
    axis = axis / np.linalg.norm(axis)
    tap = np.zeros(t.size)
    t0 = start + rng.uniform(0.5, 1.0) * tap_every_s
    while t0 < t[-1]:
        u = t - t0
        on = (u >= 0.0) & (u < 10.0 * tap_tau_s)
        tap[on] += rng.uniform(lo, hi) * np.exp(-u[on] / tap_tau_s) * np.sin(2.0 * np.pi * tap_hz * u[on])
        t0 += tap_every_s * rng.uniform(0.75, 1.25)
    acc = m.accel_w + quat_rotate(m.q_wb, tap[:, None] * axis[None, :])
    return _assemble("tapping", fs_hz, t, m.q_wb, m.omega_b, acc, m.mag_w, m.earth_field_w, kwargs.get("g", G0),
                     {**m.info, "tap_mps2": tap})


def _swing(amp_rad: float, freq_rad_s: float, phase_rad: float, base_rad: float | None = None):
    """An Euler angle ``base + amp·sin(ω t + φ)`` and its rate ``amp·ω·cos(ω t + φ)``, the
    pair ``_euler_chain`` takes for one axis."""
    rate_amp = amp_rad * freq_rad_s
    if base_rad is None:
        return (lambda tt: amp_rad * np.sin(freq_rad_s * tt + phase_rad),
                lambda tt: rate_amp * np.cos(freq_rad_s * tt + phase_rad))
    return (lambda tt: base_rad + amp_rad * np.sin(freq_rad_s * tt + phase_rad),
            lambda tt: rate_amp * np.cos(freq_rad_s * tt + phase_rad))


def shake(duration_s=20.0, fs_hz=200.0, *, seed=0, accel_g=1.0, rest_s=0.0, wobble_deg=(6.0, 8.0, 5.0),
          wobble_hz=(1.3, 2.1, 2.9), accel_hz=(2.0, 3.7, 5.9), spin_dps=0.0, base_deg=None, field_w=EARTH_FIELD_W,
          g=G0):
    """Hand shaking: attitude wobble of ``wobble_deg`` (yaw, pitch, roll; default 5–10°) at
    ``wobble_hz`` (1–3 Hz) and a translation along every axis at the three ``accel_hz``, each
    of ``accel_g``/3 g amplitude (|a| RMS accel_g·g/√2), after ``rest_s`` at rest
    (`_rest_warp`) if given; ``info["position_m"]`` the position about its centre.

    ``base_deg``: the (yaw, pitch, roll) in degrees about which the sensor wobbles (default
    45.8°, 8.6°, −5.7°). ``spin_dps``: the hand also spins the sensor steadily about its y axis
    (`_warped_spin_chain`), so the spin's axis in the world follows the wobble about the base.
    BROAD's fast combined trial 21 (fast rotations and translations together) does: its gyro's
    mean over the movement is −249 °/s about y (−154 °/s on the stationary-magnet trial 29, the
    same kind of motion), the rest of its rate at 0.8–1.2 Hz (median frequency per axis), its
    kinematic acceleration 10.9 m/s² RMS with its power's median at 1.53 Hz; |ω| median
    388 °/s, 99th percentile 670 °/s, RMS 232, 280, 175 °/s about x, y, z
    (``recording_statistics``, ``benchmarks/broad_motions.py``). ``compare.MOTION_SETUP`` runs
    ``shake`` with those figures."""
    t, warp = _time_from_rest(duration_s, fs_hz, rest_s)
    rng = np.random.default_rng(seed)
    q, om, pos, acc = _hand_shaking(t, warp, rng, accel_g, wobble_deg, wobble_hz, accel_hz, spin_dps, g, base_deg)
    earth = np.asarray(field_w, float)
    return _assemble("shake", fs_hz, t, q, om, acc, np.tile(earth, (t.size, 1)), earth, g,
                     {"accel_g": accel_g, "moving": t > rest_s, "position_m": pos})


_SHAKE_BASE_RAD = (0.8, 0.15, -0.1)  # yaw, pitch, roll about which `shake` wobbles by default


def _hand_shaking(t, warp, rng, accel_g, wobble_deg, wobble_hz, accel_hz, spin_dps, g, base_deg=None):
    """Attitude, body rate, position and acceleration of `shake` (its random phases from ``rng``)."""
    wobble_deg, wobble_hz, accel_hz = (np.asarray(x, float) for x in (wobble_deg, wobble_hz, accel_hz))
    if wobble_deg.shape != (3,) or wobble_hz.shape != (3,) or accel_hz.shape != (3,):
        raise ValueError("wobble_deg, wobble_hz and accel_hz take three values each (yaw, pitch, roll; "
                         f"three frequencies), got {wobble_deg.tolist()}, {wobble_hz.tolist()}, {accel_hz.tolist()}")
    if not (np.all(wobble_hz > 0) and np.all(accel_hz > 0) and math.isfinite(spin_dps)):
        raise ValueError(f"wobble_hz and accel_hz must be positive and spin_dps finite, got "
                         f"{wobble_hz.tolist()}, {accel_hz.tolist()}, {spin_dps!r}")
    ph = rng.uniform(0, 2 * np.pi, size=3)
    amp, frq = np.radians(wobble_deg), 2 * np.pi * wobble_hz
    bases = _SHAKE_BASE_RAD if base_deg is None else tuple(math.radians(float(x)) for x in base_deg)
    if len(bases) != 3:
        raise ValueError(f"base_deg takes three angles (yaw, pitch, roll), got {base_deg!r}")
    swings = (_swing(amp[j], frq[j], ph[j], base) for j, base in enumerate(bases))
    q, om = _warped_spin_chain(t, warp, *swings, math.radians(spin_dps))
    # amplitude per frequency so that each contributes about a third of the peak
    amp_pos = [accel_g * g / 3.0 / (2 * np.pi * f) ** 2 for f in accel_hz]
    pos, acc = _sines(rng, t, amp_pos, list(accel_hz), warp)
    return q, om, pos, acc


def magnet(duration_s=30.0, fs_hz=200.0, *, seed=0, moment_am2=0.5, closest_m=0.04, rest_s=0.0, field_w=EARTH_FIELD_W,
           g=G0):
    """Slow handling while a dipole magnet approaches to ``closest_m`` and leaves again, after
    ``rest_s`` at rest (`_rest_warp`) if given.

    The magnet is near during the middle third of the motion: its distance follows a
    smooth bump from 1.5 m down to ``closest_m`` and back.
    """
    t, warp = _time_from_rest(duration_s, fs_hz, rest_s)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=3)
    yaw = _swing(0.6, 0.3, ph[0])
    pitch = _swing(0.25, 0.5, ph[1])
    roll = _swing(0.3, 0.7, ph[2])
    q, om = _warped_chain(t, warp, yaw, pitch, roll)
    tm = t - rest_s  # time since the motion began
    T = tm[-1] if t.size > 1 else 1.0
    # distance: 1.5 m far away, a raised-cosine dip to closest_m over the middle third
    x = np.clip((tm - T / 3.0) / (T / 3.0), 0.0, 1.0)
    dip = 0.5 * (1.0 - np.cos(2.0 * np.pi * x))
    dist = 1.5 - (1.5 - closest_m) * dip
    direction = np.array([0.6, -0.5, 0.62])
    direction /= np.linalg.norm(direction)
    moment = moment_am2 * np.array([0.3, 0.8, -0.52]) / np.linalg.norm([0.3, 0.8, -0.52])
    earth = np.asarray(field_w, float)
    b = earth[None, :] + dipole_field(moment, dist[:, None] * direction[None, :])
    return _assemble("magnet", fs_hz, t, q, om, np.zeros((t.size, 3)), b, earth, g,
                     {"distance_m": dist, "moment_am2": moment_am2, "moving": t > rest_s})


def translation(duration_s=60.0, fs_hz=200.0, *, seed=0, accel_g=2.0, rest_s=0.0, hand_rate_dps=(0.0, 0.0, 0.0),
                field_gradient_ut_per_m=None, accel_hz=(1.1, 1.7, 2.5), swing_deg=(15.0, 10.0, 12.0),
                path_field=None, rest_field=None, field_w=EARTH_FIELD_W, g=G0):
    """Fast handheld translations: slow attitude changes (±(10–15)° at 0.05–0.2 Hz) and a
    back-and-forth translation along every axis at 1.1, 1.7 and 2.5 Hz, each of ``accel_g``/3
    g amplitude (|f| − g about 1 g RMS at the default, peaks near 3 g), for the whole motion
    (the specific force leaves g all the time; its spectrum lies a decade above the cut-off of
    a tilt low-pass of a few seconds); after ``rest_s`` at rest (`_rest_warp`) if given.

    A hand that moves a sensor fast also turns it at the same pace: ``hand_rate_dps`` adds
    rotations of those RMS rates (°/s) in roll, pitch and yaw at 2.5, 1.7 and 1.1 Hz (phases
    from ``seed``). BROAD's fast translation trial 15: 57, 67 and 123 °/s RMS about x, y, z,
    its power's median at 1.26 Hz (the translation's), |ω| median 122 °/s.

    ``field_gradient_ut_per_m`` (3, 3), ENU: the room's field changes with the position,
    B(p) = B + G p (p from the translation's centre; a field without sources nearby has G
    symmetric and traceless). In BROAD's lab the field against the reference, band-passed to
    the translations' 0.3–4 Hz, follows the position with |G| ≈ 4 µT/m (57 % and 65 % of it
    explained on trials 11 and 15: ``benchmarks/broad_motions.py``).

    ``accel_hz``: the translation's three paces (Hz; the hand's rotations take them too, yaw at
    the first: a hand turns the sensor as it moves it); ``swing_deg``: the amplitudes of the slow
    attitude changes (yaw, pitch, roll). BROAD's slow translation trial 11 moves the sensor by
    decimetres with 1.9 m/s² RMS at a median 0.56 Hz, turning it at 23, 18, 25 °/s RMS about
    x, y, z (about z at the translation's 0.56 Hz) and hardly otherwise: the field's direction in
    body axes spreads by 0.5°, 3° and 5.5° (RMS about its mean along the three principal axes),
    so that a uniform-field fit hardly tells the field from an offset, and the lab's gradient
    along the path, felt in step with the hand's turns, passes for 0.7–1 µT of offset
    (`slow_translation`; ``recording_statistics``'s ``field_spread_rad``).

    ``path_field``, ``rest_field``: the field is not the same everywhere in a room. Each is
    (norm ratio, azimuth change in degrees clockwise, dip change in degrees) against
    ``field_w``: the field along the path of the movement (about its centre; the gradient adds
    to it) and at the place where the sensor rests before it (``rest_s``; the field changes
    from one to the other with the start's raised cosine). BROAD's lab, the field turned to
    ENU with the reference against the field fitted on its rotation trials (``python
    benchmarks/broad_motions.py``): trial 15 rests where the field is 5.5 % weaker, turned by
    +1.8° and dipping 2.4° more, and is moved where it is 1.9 % stronger and turned by −1.6°
    (trial 01 rests at that place too); trial 11 rests and moves where it is within 1 % and 2°
    of the fitted field. An estimator that follows the field turns its heading by their
    difference when the movement starts."""
    t, warp = _time_from_rest(duration_s, fs_hz, rest_s)
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, size=3)
    amp, frq = np.radians(np.asarray(swing_deg, float)), 2 * np.pi * np.array([0.05, 0.13, 0.19])
    if amp.shape != (3,) or not np.all(np.isfinite(amp)):
        raise ValueError(f"swing_deg takes three finite angles (yaw, pitch, roll), got {swing_deg!r}")
    freqs = [float(f) for f in np.asarray(accel_hz, float)]
    if len(freqs) != 3 or not all(f > 0.0 and math.isfinite(f) for f in freqs):
        raise ValueError(f"accel_hz takes three positive frequencies, got {accel_hz!r}")
    amp_pos = [accel_g * g / 3.0 / (2 * np.pi * f) ** 2 for f in freqs]
    pos, acc = _sines(rng, t, amp_pos, freqs, warp)
    angles = [_swing(amp[j], frq[j], ph[j], base) for j, base in enumerate((0.5, 0.1, -0.15))]
    rate = np.radians(np.asarray(hand_rate_dps, float))
    if np.any(rate > 0.0):
        ph_hand = rng.uniform(0, 2 * np.pi, size=3)
        for j, (r, f) in enumerate(zip(rate[::-1], freqs)):  # yaw (z) at the first pace … roll (x) at the third
            w = 2 * np.pi * f
            hand = _swing(math.sqrt(2.0) * r / w, w, ph_hand[j])
            slow = angles[j]
            angles[j] = (lambda tt, a=slow, b=hand: a[0](tt) + b[0](tt), lambda tt, a=slow, b=hand: a[1](tt) + b[1](tt))
    q, om = _warped_chain(t, warp, *angles)
    earth = np.asarray(field_w, float)
    path = earth if path_field is None else _field_changed(earth, path_field, "path_field")
    mag_w = np.tile(path, (t.size, 1))
    if rest_field is not None:
        away = np.ones(t.size) if warp is None else warp[1]  # 0 at rest, 1 in the movement
        mag_w = mag_w + (1.0 - away)[:, None] * (_field_changed(earth, rest_field, "rest_field") - path)[None, :]
    if field_gradient_ut_per_m is not None:
        mag_w = mag_w + pos @ np.asarray(field_gradient_ut_per_m, float).T
    return _assemble("translation", fs_hz, t, q, om, acc, mag_w, earth, g,
                     {"accel_g": accel_g, "moving": t > rest_s, "position_m": pos})


def _field_changed(field_w: np.ndarray, change, name: str) -> np.ndarray:
    """``field_w`` (ENU) with its norm scaled, its azimuth turned (clockwise, degrees) and its
    dip changed (degrees): ``change`` = (ratio, azimuth, dip)."""
    ratio, d_az, d_dip = (float(x) for x in change)
    if not (ratio > 0.0 and math.isfinite(ratio) and math.isfinite(d_az) and math.isfinite(d_dip)):
        raise ValueError(f"{name} takes (norm ratio > 0, azimuth change, dip change), got {change!r}")
    e, n, u = (float(x) for x in field_w)
    horiz = math.hypot(e, n)
    norm = math.hypot(horiz, u) * ratio
    az = math.atan2(e, n) + math.radians(d_az)
    dip = math.atan2(-u, horiz) + math.radians(d_dip)
    return np.array([norm * math.cos(dip) * math.sin(az), norm * math.cos(dip) * math.cos(az), -norm * math.sin(dip)])


def slow_translation(duration_s=120.0, fs_hz=200.0, *, seed=0, accel_g=0.28, accel_hz=(0.25, 0.56, 0.85),
                     hand_rate_dps=(23.0, 18.0, 25.0), swing_deg=(3.0, 2.0, 2.0), **kwargs):
    """`translation` at a hand's slow pace and nearly fixed attitude: BROAD's slow translation
    trial 11 (1.9 m/s² RMS at a median 0.56 Hz, decimetres of travel; the hand turning the
    sensor at 23, 18 and 25 °/s RMS about x, y, z in step with the translation, and little
    else: ±3°, ±2°, ±2° of slow swing instead of `translation`'s ±15°, ±10°, ±12°)."""
    return replace(translation(duration_s, fs_hz, seed=seed, accel_g=accel_g, accel_hz=accel_hz,
                               hand_rate_dps=hand_rate_dps, swing_deg=swing_deg, **kwargs),
                   name="slow_translation")


def near_magnet(duration_s=60.0, fs_hz=200.0, *, seed=0, moment_am2=0.5, distance_m=0.3, rest_s=0.0, hand=None,
                magnet_at_rest=None, passes=(), field_w=EARTH_FIELD_W, g=G0):
    """The sensor handled near a magnet fixed in the room: slow turns (yaw ±35°, pitch and
    roll ±15°) and moves of ±0.15 m per axis (0.04–0.11 Hz) about a point ``distance_m``
    from a dipole of ``moment_am2``; the field at the sensor is the Earth's plus the
    dipole's at the sensor's position, so it changes with the position in norm and
    direction (a few µT at 0.45 m, tens at 0.2 m); after ``rest_s`` at rest (`_rest_warp`) if
    given.

    ``hand``: a dict of `shake`'s hand arguments (``accel_g``, ``wobble_deg``, ``wobble_hz``,
    ``accel_hz``, ``spin_dps``): the sensor is handled as `shake` moves it instead of the
    slow turns and moves, about the point ``distance_m`` from the magnet.
    ``magnet_at_rest`` = (closest_m, seconds): the magnet lies ``closest_m`` from the resting
    sensor for the last ``seconds`` of the rest and is gone (at ``distance_m``) 0.8 s
    into the motion (raised-cosine approach and departure of 0.3 s; the magnet moves, not the
    sensor: no acceleration). ``passes``: (fraction, closest_m, seconds) each: at that fraction
    of the motion the hand takes the sensor to ``closest_m`` from the magnet and back, a sin⁴
    bump lasting ``seconds`` (`_bump`; its acceleration added to the hand's; a pass that runs
    past the motion's end is cut there).

    BROAD's stationary-magnet trial 29 is the fast combined motion of trial 21 (``shake``'s
    spin; here −154 °/s about y, |ω| median 331 °/s, 8.9 m/s² RMS at 1.67 Hz) far from the
    magnet, whose field it meets three times: 28 µT on |m| for the last 3 s of the starting rest
    (on until 0.8 s into the movement), and brief passes of 0.05–0.12 s with |m| 20–34 µT off
    about 98–101 s and 133 s; |m| is more than 5 µT off the lab's |B| on 1.5 % of the
    movement, and the field's residual against the reference (3.3 µT) is that of the
    undisturbed fast trial 21 (3.6 µT): the magnet is not felt elsewhere
    (``recording_statistics``, ``benchmarks/broad_motions.py``). ``compare.MOTION_SETUP`` runs
    ``near_magnet`` so."""
    t, warp = _time_from_rest(duration_s, fs_hz, rest_s)
    rng = np.random.default_rng(seed)
    if hand is None:
        ph = rng.uniform(0, 2 * np.pi, size=6)
        yaw = _swing(0.6, 0.35, ph[0])
        pitch = _swing(0.25, 0.55, ph[1])
        roll = _swing(0.25, 0.75, ph[2])
        q, om = _warped_chain(t, warp, yaw, pitch, roll)
        w = 2 * np.pi * np.array([0.04, 0.07, 0.11])
        x = t if warp is None else warp[0]
        pos = 0.15 * np.sin(w[None, :] * x[:, None] + ph[None, 3:])
        acc = -0.15 * w[None, :] ** 2 * np.sin(w[None, :] * x[:, None] + ph[None, 3:])
        if warp is not None:
            vel = 0.15 * w[None, :] * np.cos(w[None, :] * x[:, None] + ph[None, 3:])
            acc = acc * warp[1][:, None] ** 2 + vel * warp[2][:, None]
    else:
        q, om, pos, acc = _hand(t, warp, rng, hand, g)
    direction = np.array([0.6, -0.5, 0.62])
    direction /= np.linalg.norm(direction)
    axis = np.array([0.3, 0.8, -0.52]) / np.linalg.norm([0.3, 0.8, -0.52])
    moment = moment_am2 * axis
    r = distance_m * direction[None, :] + pos  # sensor relative to the magnet
    tm = t - rest_s  # time since the motion began
    if magnet_at_rest is not None:
        # the magnet moved to closest_m from the resting sensor on its own axis (the field adds
        # to the Earth's: |m| up), the sensor not moving
        closest, seconds = (float(x) for x in magnet_at_rest)
        if not (0.0 < closest < distance_m and 0.6 <= seconds <= rest_s):
            raise ValueError(f"magnet_at_rest (closest_m, seconds) needs 0 < closest_m < distance_m and "
                             f"0.6 s <= seconds <= rest_s, got {magnet_at_rest!r}")
        near, _ = _plateau(tm, -seconds, 0.3, seconds + 0.8 - 0.6)
        r = r + near[:, None] * (closest * axis - r[0])[None, :]
    sensor = pos.copy()  # the sensor's position (the passes included; not the magnet's move at rest)
    side = np.cross(axis, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)  # across the magnet's axis: its field against the Earth's, |m| down
    for k, item in enumerate(passes):
        frac, closest, seconds = (float(x) for x in item)
        t0 = frac * duration_s - 0.5 * seconds
        if not (0.0 < closest < distance_m and seconds > 0.0 and 0.0 <= frac <= 1.0):
            raise ValueError(f"passes[{k}] (fraction, closest_m, seconds) needs 0 <= fraction <= 1, "
                             f"0 < closest_m < distance_m and seconds > 0, got {item!r}")
        dip, ddip = _bump(tm, t0, seconds)
        # the hand takes the sensor from its path to closest_m beside the magnet and back
        centre = int(np.clip(np.searchsorted(t, rest_s + t0 + 0.5 * seconds), 0, t.size - 1))
        step = closest * side - r[centre]
        r = r + dip[:, None] * step[None, :]
        sensor += dip[:, None] * step[None, :]
        acc = acc + ddip[:, None] * step[None, :]
    earth = np.asarray(field_w, float)
    b = earth[None, :] + dipole_field(moment, r)
    return _assemble("near_magnet", fs_hz, t, q, om, acc, b, earth, g,
                     {"distance_m": np.linalg.norm(r, axis=1), "moment_am2": moment_am2, "moving": t > rest_s,
                      "position_m": sensor})


def _bump(t, t0, seconds):
    """sin⁴(π (t − t0)/seconds) over [t0, t0 + seconds] (0 elsewhere: its acceleration continuous,
    a hand's move) and its second derivative."""
    u = np.clip((t - t0) / seconds, 0.0, 1.0)
    s, c = np.sin(np.pi * u), np.cos(np.pi * u)
    return s ** 4, (np.pi / seconds) ** 2 * (12.0 * s ** 2 * c ** 2 - 4.0 * s ** 4)


def _hand(t, warp, rng, hand: dict, g):
    """`_hand_shaking` with `shake`'s defaults for the arguments ``hand`` leaves out."""
    known = {"accel_g", "wobble_deg", "wobble_hz", "accel_hz", "spin_dps", "base_deg"}
    if not set(hand) <= known:
        raise ValueError(f"hand takes {', '.join(sorted(known))}; got {', '.join(sorted(set(hand) - known))}")
    args = {"accel_g": 1.0, "wobble_deg": (6.0, 8.0, 5.0), "wobble_hz": (1.3, 2.1, 2.9),
            "accel_hz": (2.0, 3.7, 5.9), "spin_dps": 0.0, "base_deg": None} | dict(hand)
    return _hand_shaking(t, warp, rng, args["accel_g"], args["wobble_deg"], args["wobble_hz"], args["accel_hz"],
                         args["spin_dps"], g, args["base_deg"])


def _plateau(t, t0, ramp, hold):
    """A bump from 0 to 1 and back: a raised-cosine rise over ``ramp`` from ``t0``, 1 for
    ``hold``, a raised-cosine fall over ``ramp``; returns it and its second derivative."""
    u = np.clip((t - t0) / ramp, 0.0, 1.0)
    v = np.clip((t - t0 - ramp - hold) / ramp, 0.0, 1.0)
    up = (t > t0) & (t < t0 + ramp)
    down = (t > t0 + ramp + hold) & (t < t0 + 2 * ramp + hold)
    k = 0.5 * (np.pi / ramp) ** 2
    value = 0.5 * (1.0 - np.cos(np.pi * u)) - 0.5 * (1.0 - np.cos(np.pi * v))
    second = np.where(up, k * np.cos(np.pi * u), 0.0) - np.where(down, k * np.cos(np.pi * v), 0.0)
    return value, second


def vibration(duration_s=60.0, fs_hz=200.0, *, seed=0, vib_hz=150.0, vib_angle_rad=np.radians(0.0105),
              vib_m=0.02e-3, phone_field_b_ut=PHONE_FIELD_B_UT, rest_s=0.0, vib_span=(1.0 / 3.0, 2.0 / 3.0), hand=None,
              field_w=EARTH_FIELD_W, g=G0):
    """Slow handling (yaw ±35°, pitch and roll ±15° at 0.05–0.12 Hz) with a phone lying on the
    sensor; during the middle third it vibrates: an angular vibration of ``vib_angle_rad``
    about a skew body axis and a translation of ``vib_m`` along another, both at ``vib_hz``
    (smoothly switched on and off over 1 s). The phone's field ``phone_field_b_ut`` is fixed
    in body axes for the whole motion (it lies on the sensor before, during and after the
    vibration: a hard-iron offset). With ``rest_s`` the motion starts from rest (`_rest_warp`)
    and the vibration is in the middle third of the rest of it.

    Measured on BROAD trial 27 (phone vibration; ``PHONE_FIELD_B_UT``;
    ``benchmarks/broad_motions.py``): what its IMU recorded while the phone vibrated is a tone
    at 44 Hz (84 % of the power above 20 Hz within ±5 Hz; a phone motor's 150–250 Hz aliased
    by its 285.7 Hz sampling, or its own), 3.5–3.7 m/s² RMS in the accelerometer and
    2.1 °/s RMS in the gyro above 20 Hz. The MPU-9250 of ``compare.motion_dataset`` (41–45 Hz
    filters, 200 Hz) turns ±0.02 mm at 150 Hz into 3.6 m/s² and ±0.0105° into 1.8 °/s RMS
    above 20 Hz, aliased to 50 Hz.

    ``vib_span`` = (on, off): the fractions of the motion between which it vibrates (default the
    middle third). ``hand``: a dict of `shake`'s hand arguments (as in `near_magnet`): the sensor
    is handled as `shake` moves it (turns and translation) instead of the slow turns. Trial 27's
    hand: |ω| median 32 °/s, 99th percentile 96 °/s, its power's median at 2.0 Hz; the
    acceleration below 20 Hz 2.3 m/s² RMS with its median at 0.70 Hz; and it vibrates from 22 s
    into its 117 s of movement to the end (the accelerometer's RMS above 20 Hz 3.6–4.1 m/s² in
    every 5 s from 68 to 163 s, 0.1 before): ``compare.MOTION_SETUP`` runs ``vibration`` so."""
    t, warp = _time_from_rest(duration_s, fs_hz, rest_s)
    rng = np.random.default_rng(seed)
    on, off = (float(x) for x in vib_span)
    if not 0.0 <= on < off <= 1.0:
        raise ValueError(f"vib_span (on, off) needs 0 <= on < off <= 1, got {vib_span!r}")
    if hand is None:
        ph = rng.uniform(0, 2 * np.pi, size=3)
        yaw = _swing(0.6, 0.3, ph[0])
        pitch = _swing(0.25, 0.5, ph[1])
        roll = _swing(0.25, 0.75, ph[2])
        q_slow, om_slow = _warped_chain(t, warp, yaw, pitch, roll)
        acc_hand = 0.0
    else:
        q_slow, om_slow, _, acc_hand = _hand(t, warp, rng, hand, g)
    tm = t - rest_s  # time since the motion began
    T = tm[-1] if t.size > 1 else 1.0
    # on/off envelope: raised-cosine ramps of 1 s at on·T and off·T (its derivatives analytic)
    def env(tt):
        up = np.clip(tt - on * T, 0.0, 1.0)
        down = np.clip(off * T - tt, 0.0, 1.0)
        return 0.5 * (1.0 - np.cos(np.pi * np.minimum(up, down)))

    def denv(tt):
        up, down = tt - on * T, off * T - tt
        d = np.where((up > 0) & (up < 1) & (up <= down), 1.0, 0.0) - np.where((down > 0) & (down < 1) & (down < up),
                                                                              1.0, 0.0)
        return 0.5 * np.pi * np.sin(np.pi * np.clip(np.minimum(up, down), 0.0, 1.0)) * d

    w = 2.0 * np.pi * vib_hz
    a = float(vib_angle_rad)
    axis = np.array([0.5, -0.7, 0.5]) / np.linalg.norm([0.5, -0.7, 0.5])
    th = a * env(tm) * np.sin(w * t)
    dth = a * (denv(tm) * np.sin(w * t) + env(tm) * w * np.cos(w * t))
    q_vib, om_vib = rotation_chain([axis], th[:, None], dth[:, None])
    q = quat_multiply(q_slow, q_vib)
    om = quat_rotate(quat_conjugate(q_vib), om_slow) + om_vib
    # translation along a body direction at the vibration frequency, in the world: its
    # acceleration is that of the amplitude envelope's sine (the slow attitude's change over
    # one period neglected: < 1e-3 of it)
    d_b = np.array([0.2, 0.9, -0.4]) / np.linalg.norm([0.2, 0.9, -0.4])
    d_w = quat_rotate(q_slow, d_b)
    acc = acc_hand + (-vib_m * w * w * env(tm) * np.sin(w * t))[:, None] * d_w
    earth = np.asarray(field_w, float)
    mag_w = earth[None, :] + quat_rotate(q, np.asarray(phone_field_b_ut, float))
    return _assemble("vibration", fs_hz, t, q, om, acc, mag_w, earth, g,
                     {"vib_hz": vib_hz, "vibrating": env(tm) > 0.0, "moving": t > rest_s})


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


def recording_statistics(fs_hz: float, gyro_b, accel_b, mag_b, q_wb, *, moving=None, field_w=None, g: float = G0,
                         high_hz: float = 20.0, disturbed_ut: float = 5.0, vibrating_mps2: float = 1.0) -> dict:
    """What a motion does to an IMU, measured alike on a real recording with a reference
    attitude (BROAD's: ``q_wb`` from optical capture, NaN rows skipped) and on a simulated one
    (the truth), over the ``moving`` samples (all if None):

    ``rate_median_dps``, ``rate_p99_dps``: the gyro's |ω|, ``rate_rms_dps`` its RMS per axis;
    ``accel_rms_mps2``: RMS of the
    kinematic acceleration |f − R_wbᵀ g·up| and ``accel_median_hz`` the median frequency of its
    power (in ENU); ``high_accel_rms_mps2``, ``high_gyro_rms_dps``: RMS of the accelerometer's
    and the gyro's vector above ``high_hz`` (a vibration; the recording's sensor filters
    included) and ``high_accel_peak_hz`` its strongest frequency; ``mag_norm_std_ut``: standard
    deviation of |m|; ``mag_offset_ut``: o of m = R_wbᵀ B + o by least squares, with B =
    ``field_w`` (ENU, µT) if given, else fitted with o (which needs attitudes that turn the
    field through the sensor's axes), ``field_enu_ut`` that B; ``mag_residual_ut``: median
    |m − R_wbᵀ B − o|;
    ``mag_lag_ms``: τ of m ≈ h − τ (h × ω), h = R_wbᵀ B + o, by least squares: how late the
    field is against the reference (with ω from the gyro); ``rate_mean_dps``: the gyro's mean
    per axis (a steady spin), ``rate_mean_enu_dps`` the mean of the rate turned to ENU (the spin's
    axis in the world); ``mag_disturbed_frac``: the fraction of the samples whose |m| is
    more than ``disturbed_ut`` off |B| (a magnet met on the way); ``low_accel_rms_mps2``: RMS of
    the kinematic acceleration below ``high_hz`` (the hand's, without a vibration);
    ``vibrating_frac``: the fraction of the samples where the accelerometer's RMS above
    ``high_hz`` over the surrounding second exceeds ``vibrating_mps2``;
    ``field_spread_rad``: how far the field's direction R_wbᵀ B/|B| moves in body axes, the RMS
    about its mean along its three principal axes (smallest first): an offset is told from the
    field only as far as this spreads;
    ``path_field``, and ``rest_field`` when ``moving`` leaves samples at rest before the
    movement: the mean field turned to ENU with the reference, R_wb m, over the movement and over
    that rest, as (norm ratio, azimuth change clockwise in degrees, dip change in degrees) against
    B (the arguments of `translation`; the sensor's offset is in them too).
    """
    from scipy.signal import butter, sosfiltfilt, welch

    gyro, acc, mag, q = (np.asarray(x, float) for x in (gyro_b, accel_b, mag_b, q_wb))
    n = gyro.shape[0]
    sel = np.ones(n, bool) if moving is None else np.asarray(moving, bool).copy()
    sel &= np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(mag), axis=1)
    rate = np.degrees(np.linalg.norm(gyro[sel], axis=1))
    qs = q[sel] / np.linalg.norm(q[sel], axis=1, keepdims=True)
    kin = acc[sel] - quat_rotate(quat_conjugate(qs), np.tile([0.0, 0.0, g], (qs.shape[0], 1)))
    f_hz, p = welch(quat_rotate(qs, kin), fs=fs_hz, nperseg=min(2048, qs.shape[0]), axis=0)
    cum = np.cumsum(p.sum(axis=1))
    sos = butter(2, high_hz / (0.5 * fs_hz), output="sos")
    high_acc = (acc - sosfiltfilt(sos, acc, axis=0))[sel]
    high_gyro = np.degrees(gyro - sosfiltfilt(sos, gyro, axis=0))[sel]
    win = max(1, int(round(fs_hz)))
    high_all = np.sum((acc - sosfiltfilt(sos, acc, axis=0)) ** 2, axis=1)
    running = np.sqrt(np.convolve(high_all, np.ones(win) / win, mode="same"))[sel]
    low_kin = sosfiltfilt(sos, acc, axis=0)[sel] - quat_rotate(quat_conjugate(qs), np.tile([0.0, 0.0, g], (qs.shape[0], 1)))
    f_h, p_h = welch(high_acc, fs=fs_hz, nperseg=min(1024, high_acc.shape[0]), axis=0)
    p_h = p_h.sum(axis=1) * (f_h > high_hz)
    m = mag[sel]
    if field_w is None:
        # m = R_wbᵀ B + o: linear in (B, o); the rows of R_wbᵀ are the world axes in body axes
        rows = np.stack([quat_rotate(quat_conjugate(qs), np.tile(e, (qs.shape[0], 1))) for e in np.eye(3)], axis=2)
        design = np.concatenate([rows, np.tile(np.eye(3), (qs.shape[0], 1, 1))], axis=2).reshape(-1, 6)
        sol = np.linalg.lstsq(design, m.reshape(-1), rcond=None)[0]
        field, offset = sol[:3], sol[3:]
    else:
        field = np.asarray(field_w, float)
        offset = np.mean(m - quat_rotate(quat_conjugate(qs), np.tile(field, (qs.shape[0], 1))), axis=0)
    field_b = quat_rotate(quat_conjugate(qs), np.tile(field, (qs.shape[0], 1)))
    resid = m - field_b - offset
    # a field τ late: m(t) = h(t − τ) ≈ h − τ ḣ, ḣ = h × ω in body axes (ω from the gyro)
    h_dot = np.cross(field_b, gyro[sel])
    lag = -np.sum(h_dot * resid) / np.sum(h_dot * h_dot)
    spread = np.sqrt(np.clip(np.linalg.eigvalsh(np.cov((field_b / np.linalg.norm(field)).T)), 0.0, None))
    places = {"path_field": _field_against(np.mean(quat_rotate(qs, m), axis=0), field)}
    if moving is not None:
        ok = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(mag), axis=1)
        before = ok & (np.arange(n) < int(np.argmax(np.asarray(moving, bool))))
        if np.any(before):
            qr = q[before] / np.linalg.norm(q[before], axis=1, keepdims=True)
            places["rest_field"] = _field_against(np.mean(quat_rotate(qr, mag[before]), axis=0), field)
    return {
        "rate_median_dps": float(np.median(rate)), "rate_p99_dps": float(np.percentile(rate, 99)),
        "rate_rms_dps": [float(x) for x in np.degrees(np.sqrt(np.mean(gyro[sel] ** 2, axis=0)))],
        "rate_mean_dps": [float(x) for x in np.degrees(np.mean(gyro[sel], axis=0))],
        "rate_mean_enu_dps": [float(x) for x in np.degrees(np.mean(quat_rotate(qs, gyro[sel]), axis=0))],
        "accel_rms_mps2": float(np.sqrt(np.mean(np.sum(kin ** 2, axis=1)))),
        "accel_median_hz": float(f_hz[np.searchsorted(cum, 0.5 * cum[-1])]),
        "high_accel_rms_mps2": float(np.sqrt(np.mean(np.sum(high_acc ** 2, axis=1)))),
        "high_gyro_rms_dps": float(np.sqrt(np.mean(np.sum(high_gyro ** 2, axis=1)))),
        "high_accel_peak_hz": float(f_h[np.argmax(p_h)]),
        "low_accel_rms_mps2": float(np.sqrt(np.mean(np.sum(low_kin ** 2, axis=1)))),
        "vibrating_frac": float(np.mean(running > vibrating_mps2)),
        "mag_norm_std_ut": float(np.std(np.linalg.norm(m, axis=1))),
        "mag_offset_ut": [float(x) for x in offset],
        "mag_residual_ut": float(np.median(np.linalg.norm(resid, axis=1))),
        "mag_lag_ms": float(1e3 * lag),
        "mag_disturbed_frac": float(np.mean(np.abs(np.linalg.norm(m, axis=1) - np.linalg.norm(field)) > disturbed_ut)),
        "field_enu_ut": [float(x) for x in field],
        "field_spread_rad": [float(x) for x in spread],
        **places,
    }


def _field_against(b_w: np.ndarray, field_w: np.ndarray) -> list[float]:
    """(|b|/|B|, azimuth of b − azimuth of B clockwise in degrees, dip of b − dip of B in
    degrees), both ENU: the inverse of `_field_changed`."""
    def polar(v):
        horiz = math.hypot(v[0], v[1])
        return math.hypot(horiz, v[2]), math.atan2(v[0], v[1]), math.atan2(-v[2], horiz)

    (n1, a1, d1), (n0, a0, d0) = polar(b_w), polar(np.asarray(field_w, float))
    d_az = (a1 - a0 + math.pi) % (2.0 * math.pi) - math.pi
    return [float(n1 / n0), float(math.degrees(d_az)), float(math.degrees(d1 - d0))]


MOTIONS: dict[str, Callable[..., Motion]] = {
    "static": static,
    "rotation": rotation,
    "tumble": tumble,
    "fast_tumble": fast_tumble,
    "shake": shake,
    "magnet": magnet,
    "translation": translation,
    "slow_translation": slow_translation,
    "near_magnet": near_magnet,
    "vibration": vibration,
    "tapping": tapping,
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
