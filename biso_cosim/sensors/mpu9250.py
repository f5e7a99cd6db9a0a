"""The virtual MPU-9250: true motion in, register values and SI readings out.

Signal path of the gyro and the accelerometer (chip axes, one internal sample):

    x_c = R_cb · x_b                                      mounting (body -> chip)
    y   = (M + diag(k_s)·ΔT)·x_c + 2.5·κ·FS·(x_c/FS)³      scale factor, cross-axis, nonlinearity
          + b + k_b·ΔT + b_flicker(t) + b_rw(t)           turn-on bias, tempco, instability, random walk
          + G·f_c                                         g-sensitivity (gyro)
          + w,  w ~ N(0, N²·f_int)                        white noise (N = noise density)
    y   = clip(y, ±full scale)                            ADC saturation (flagged)
    reg = DLPF(y)                                          table bandwidth and delay (dlpf.py)

At each output instant (ODR) the registers are rounded to int16 (raw) and converted back
to SI (``code / sensitivity``), then rotated chip -> body. ΔT = T − T_0 is the die
temperature's offset from the reference. The white-noise convention: a density N (units
/√Hz) gives σ = N·√f per sample at rate f, so the Allan deviation at τ = 1 s equals N
(IEEE Std 952 angle-random-walk coefficient).

The AK8963 measures the field at its own rate (8 or 100 Hz, or when the driver triggers
it in single mode) in its own axes after the
vehicle's soft and hard iron: ``H = P·R_cb·(S·B_b + h) + o + w``, codes ``H / (R·a)``
with the part's true sensitivity factor a (its fuse-ROM ASA is a rounded to 1/256);
readings ``code·R·((ASA − 128)/256 + 1)`` mapped back to body axes.
"""

from __future__ import annotations

import math
import os
from typing import Any, Mapping

import numpy as np

from biso_cosim.sensors import _kernels as K
from biso_cosim.sensors._rng import seed_state
from biso_cosim.sensors.dlpf import FilterDesign, design_dlpf
from biso_cosim.sensors.profile import DrawnErrors, Profile, draw_errors, flicker_terms
from biso_cosim.sensors.registers import Registers, chip_tables
from biso_cosim.sensors.samples import AK8963_FROM_CHIP, ImuSamples, RawSamples, mounting_matrix
from biso_cosim.sensors.vibration import MountVibration

__all__ = ["MPU9250"]

SLOW_RATE_HZ = 20.0
"""Update rate of the bias-instability and random-walk processes (slowest correlation time
is 1 s by default, so 20 Hz is far above their bandwidth)."""

MAX_SUBINTERVALS = 64


def _ratio(a: float, b: float) -> int:
    """a / b if it is a positive integer (to 1e-9), else 0."""
    r = a / b
    n = round(r)
    return int(n) if n >= 1 and math.isclose(r, n, rel_tol=1e-9) else 0


def _check_seed(seed: Any) -> None:
    if isinstance(seed, bool) or not (seed is None or isinstance(seed, (int, np.integer))):
        raise TypeError(f"seed must be an int or None, got {seed!r}")
    if seed is not None and seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")


def _rows3(name: str, value: Any) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {a.shape}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


class MPU9250:
    """A virtual MPU-9250 with its AK8963, as configured by its registers.

    Args:
        profile: ``"mpu9250"`` (typical part, errors drawn per seed), ``"ideal"`` (no errors),
            a path to a profile TOML file, or a `Profile`.
        seed: int or None (fresh entropy, see `seed_entropy`); the same seed gives the same
            turn-on errors and noise, bit for bit.
        registers: `Registers`, a dict of its fields, or None for the defaults (±250 °/s,
            ±4 g, DLPF_CFG = 3, A_DLPF_CFG = 3, SMPLRT_DIV = 4 -> 200 Hz, AK8963 100 Hz 16-bit).
        mounting: rotation chip -> body: (4,) ``q_body_chip``, (3, 3) matrix, or None.
        input_rate_hz: rate of the truth arrays given to `simulate`. It must be an integer
            multiple or an integer fraction of the gyro and accelerometer internal rates
            (e.g. 1 kHz for the default registers; 500 Hz, 2 kHz, 8 kHz, ...).
        hard_iron_ut: (3,) vehicle hard iron in µT, body axes (default zero).
        soft_iron: (3, 3) vehicle soft-iron matrix S in body axes, the sensor sees
            ``S·B_b + hard_iron`` (default identity).
        vibration: optional `MountVibration` (resonances of the mount, added to the truth).

    Timing: input sample i of the stream is the truth at t_i = i / input_rate_hz; between
    samples the truth is interpolated linearly. The chip samples it at its internal rate
    and latches outputs at t = k / output_rate_hz, k = 0, 1, ...: a call whose inputs span
    [t_a, t_b] returns the outputs with t_a <= t_s <= t_b (the truth before t = 0 is
    taken as constant: the chip starts settled).
    """

    def __init__(
        self,
        profile: "str | os.PathLike | Profile" = "mpu9250",
        *,
        seed: int | None = 0,
        registers: Registers | Mapping[str, Any] | None = None,
        mounting: Any = None,
        input_rate_hz: float = 1000.0,
        hard_iron_ut: Any = None,
        soft_iron: Any = None,
        vibration: MountVibration | None = None,
    ) -> None:
        self.profile = Profile.load(profile)
        self.registers = Registers.coerce(registers)
        self.r_bc = mounting_matrix(mounting)
        _check_seed(seed)
        if isinstance(input_rate_hz, bool) or not isinstance(input_rate_hz, (int, float, np.floating, np.integer)):
            raise TypeError(f"input_rate_hz must be a number, got {input_rate_hz!r}")
        if not (math.isfinite(input_rate_hz) and input_rate_hz > 0):
            raise ValueError(f"input_rate_hz must be positive and finite, got {input_rate_hz}")
        self.input_rate_hz = float(input_rate_hz)
        self.hard_iron_ut = np.zeros(3) if hard_iron_ut is None else np.asarray(hard_iron_ut, dtype=np.float64)
        if self.hard_iron_ut.shape != (3,) or not np.all(np.isfinite(self.hard_iron_ut)):
            raise ValueError(f"hard_iron_ut must be 3 finite numbers (µT), got {hard_iron_ut!r}")
        self.soft_iron = np.eye(3) if soft_iron is None else np.asarray(soft_iron, dtype=np.float64)
        if self.soft_iron.shape != (3, 3) or not np.all(np.isfinite(self.soft_iron)):
            raise ValueError(f"soft_iron must be a finite (3, 3) matrix, got {soft_iron!r}")
        if abs(np.linalg.det(self.soft_iron)) < 1e-6:
            raise ValueError("soft_iron must be invertible")
        if vibration is not None and not isinstance(vibration, MountVibration):
            raise TypeError(f"vibration must be a MountVibration or None, got {type(vibration).__name__}")
        self.vibration = vibration
        self._timing()
        self._seed = seed
        self._seed_sequence = np.random.SeedSequence(seed)
        self._build()

    # ---- set-up ------------------------------------------------------------------------

    def _timing(self) -> None:
        reg = self.registers
        f_in = self.input_rate_hz
        f_g, f_a = reg.gyro_dlpf.rate_hz, reg.accel_dlpf.rate_hz
        for name, f in (("gyro", f_g), ("accelerometer", f_a)):
            if not (_ratio(f, f_in) or _ratio(f_in, f)):
                raise ValueError(
                    f"input_rate_hz={f_in:g} must be an integer multiple or fraction of the {name} "
                    f"internal rate {f:g} Hz of these registers"
                )
        self._f_base = max(f_in, f_g, f_a)
        self._up = _ratio(self._f_base, f_in)
        self._gdiv = _ratio(self._f_base, f_g)
        self._adiv = _ratio(self._f_base, f_a)
        self._out_div = self._gdiv * reg.gyro_samples_per_output
        self._slow_div = _ratio(self._f_base, SLOW_RATE_HZ)
        ak = chip_tables()["ak8963"]
        single = reg.mag_mode == ak["mode_single"]
        f_mag = 0.0 if single else reg.mag_rate_hz
        self._mag_div = _ratio(self._f_base, f_mag) if f_mag > 0 else 0
        self._mag_trigger_div = 1 + reg.i2c_mst_dly if single else 0
        self._mag_meas_ticks = math.ceil(ak["single_measurement_time_ms"] * 1e-3 * self._f_base - 1e-9)
        if not (self._up and self._gdiv and self._adiv and self._slow_div) or (f_mag > 0 and not self._mag_div):
            raise ValueError(f"input_rate_hz={f_in:g} gives no common time grid with the chip's rates")
        # accelerometer samples per output interval, 0 when an interval holds no whole number
        self._accel_per_output = self._out_div // self._adiv if self._out_div % self._adiv == 0 else 0

    def _build(self) -> None:
        """Draw the part's errors and fill parameter and state records (called by reset too)."""
        children = self._seed_sequence.spawn(2)
        self.errors: DrawnErrors = draw_errors(self.profile, np.random.default_rng(children[0]))
        self._rng_words = seed_state(children[1])
        prof, reg = self.profile, self.registers
        self._temp_default = float(prof.si("temperature.default"))
        use_dlpf = bool(prof.si("model.dlpf"))
        quantize = bool(prof.si("model.quantization"))
        slow_dt = self._slow_div / self._f_base

        cp = np.zeros(1, dtype=K.CHIP_PARAMS)
        c = cp[0]
        c["r_bc"] = self.r_bc
        c["r_cb"] = self.r_bc.T
        c["up"], c["f_base"], c["out_div"], c["slow_div"] = self._up, self._f_base, self._out_div, self._slow_div
        c["dlpf"], c["quantize"] = int(use_dlpf), int(quantize)
        c["t_ref"] = prof.si("temperature.reference")
        temps = chip_tables()["temperature"]
        temp_design = design_dlpf(reg.temperature_dlpf.bandwidth_hz, reg.temperature_dlpf.delay_s, reg.gyro_dlpf.rate_hz, match_delay=False)
        c["temp_lp_a"] = temp_design.lowpass_a
        c["temp_lsb"], c["temp_offset"] = temps["sensitivity_lsb_per_c"], temps["offset_c"]
        c["mag_div"] = self._mag_div
        c["mag_trigger_div"] = self._mag_trigger_div
        c["mag_meas_ticks"] = self._mag_meas_ticks
        c["soft"], c["hard"] = self.soft_iron, self.hard_iron_ut
        c["r_ak_b"] = AK8963_FROM_CHIP @ self.r_bc.T
        c["r_b_ak"] = self.r_bc @ AK8963_FROM_CHIP.T
        mag = self.errors.mag
        c["mag_counts"] = 1.0 / (reg.mag_resolution_ut * mag.sensitivity_factor)
        c["mag_adj"] = (mag.asa.astype(np.float64) - 128.0) / 256.0 + 1.0
        c["mag_offset"] = mag.offset_ut
        c["mag_sigma"] = prof.axes("mag.noise")
        c["mag_res"] = reg.mag_resolution_ut
        c["mag_max_code"] = reg.mag_max_code
        c["mag_overflow"] = chip_tables()["ak8963"]["overflow_sum_ut"]
        c["mag_bit16"] = int(reg.mag_bit16)
        modes = self.vibration.modes if self.vibration is not None else ()
        c["n_vib"] = len(modes)
        for i, mode in enumerate(modes):
            c["vib_a1"][i], c["vib_a2"][i], c["vib_gain"][i] = mode.coefficients(self._f_base)

        ch = np.zeros(2, dtype=K.CHANNEL_PARAMS)
        n_gm = 0
        self.designs: dict[str, FilterDesign] = {}
        for idx, sensor in enumerate(("gyro", "accel")):
            p = ch[idx]
            err = getattr(self.errors, sensor)
            entry = reg.gyro_dlpf if sensor == "gyro" else reg.accel_dlpf
            design = design_dlpf(entry.bandwidth_hz, entry.delay_s, entry.rate_hz)
            if design.delay_samples > K.N_LINE:
                raise RuntimeError(f"{sensor} DLPF design needs {design.delay_samples} delay samples")
            self.designs[sensor] = design
            p["sens"], p["sf_tc"], p["bias"], p["bias_tc"] = err.sensitivity, err.scale_factor_tempco, err.bias, err.bias_tempco
            p["nl"], p["gsens"] = err.nonlinearity, err.g_sensitivity
            p["sigma"] = prof.axes(f"{sensor}.noise_density") * math.sqrt(entry.rate_hz)
            taus, sig = flicker_terms(prof.axes(f"{sensor}.bias_instability"), prof.si(f"{sensor}.bias_corner_times"))
            if taus.size > K.N_GM:
                raise ValueError(f"profile {sensor}.bias_corner_times spans too many decades (at most {(K.N_GM - 1) / 2:g})")
            n = taus.size
            n_gm = max(n_gm, n)  # one count for both channels: absent terms have sigma 0
            phi = np.exp(-slow_dt / taus)
            p["gm_phi"][:n] = phi
            p["gm_sigma"][:n] = sig
            p["gm_drive"][:n] = sig * np.sqrt(1.0 - phi**2)[:, None]
            p["rw_drive"] = prof.axes(f"{sensor}.random_walk") * math.sqrt(slow_dt)
            p["full_scale"] = reg.gyro_full_scale if sensor == "gyro" else reg.accel_full_scale
            p["lsb"] = reg.gyro_lsb_per_unit if sensor == "gyro" else reg.accel_lsb_per_unit
            p["lp_a"], p["ap_d"], p["n_delay"] = design.lowpass_a, design.allpass_d, design.delay_samples
            p["div"] = self._gdiv if sensor == "gyro" else self._adiv
            p["per_output"] = reg.gyro_samples_per_output if sensor == "gyro" else self._accel_per_output
        c["n_gm"] = n_gm
        self._cp, self._ch = cp, ch
        self._ticks_per_input, self._out_div = int(cp[0]["up"]), int(cp[0]["out_div"])  # for the output bound
        self._new_state()

    def _new_state(self) -> None:
        self._cs = np.zeros(1, dtype=K.CHIP_STATE)
        self._cs[0]["rng"] = self._rng_words
        self._chs = np.zeros(2, dtype=K.CHANNEL_STATE)
        self._arrays_changed()

    def _arrays_changed(self) -> None:
        self.arrays_version = getattr(self, "arrays_version", 0) + 1

    def loop_arrays(self) -> tuple:
        """The arrays the co-simulation's period kernel (``biso_cosim.loop``) runs the chip
        on: parameters, channel parameters, chip state, channel state (the chip's own arrays,
        advanced in place), and the default die temperature. They are replaced, and
        ``arrays_version`` counts up, when the registers, the seed or a restored state
        change them."""
        return self._cp, self._ch, self._cs, self._chs, self._temp_default

    # ---- public ------------------------------------------------------------------------

    @property
    def output_rate_hz(self) -> float:
        """Accel/gyro/temperature output data rate (ODR) in Hz, from the registers."""
        return self._f_base / self._out_div

    @property
    def mag_rate_hz(self) -> float:
        """AK8963 measurement rate in Hz (0 when powered down)."""
        return self.registers.mag_rate_hz

    @property
    def asa(self) -> np.ndarray:
        """The part's AK8963 fuse-ROM sensitivity adjustment bytes (ASAX, ASAY, ASAZ)."""
        return self.errors.mag.asa.copy()

    @property
    def seed(self) -> int | None:
        """The seed the part and its noise stream were drawn from (None: fresh entropy)."""
        return self._seed

    def internal_samples_per_output(self, sensor: str) -> int:
        """Internal (post-DLPF) samples the chip decimates to one output sample: the gyro's
        ``registers.gyro_samples_per_output``, the accelerometer's over the same output
        interval (0 when the interval holds no whole number of them)."""
        if sensor == "gyro":
            return int(self.registers.gyro_samples_per_output)
        if sensor == "accel":
            return int(self._accel_per_output)
        raise ValueError(f"sensor must be 'gyro' or 'accel', got {sensor!r}")

    @property
    def seed_entropy(self) -> int | list[int]:
        """The entropy of the seed sequence (equal to ``seed`` when one was given)."""
        return self._seed_sequence.entropy

    @property
    def time_s(self) -> float:
        """Time of the next input sample the stream expects."""
        return int(self._cs[0]["n_in"]) / self.input_rate_hz

    def reset(self, seed: int | None = None) -> None:
        """Back to time 0: the same part (turn-on errors) and noise stream start again.

        With an int ``seed`` the part is drawn anew from that seed.
        """
        if seed is not None:
            _check_seed(seed)
            self._seed = seed
            self._seed_sequence = np.random.SeedSequence(seed)
            self._build()
        else:
            self._new_state()

    def get_state(self) -> dict[str, np.ndarray]:
        """A copy of the whole dynamic state (filters, clocks, random stream)."""
        return {"chip": self._cs.copy(), "channels": self._chs.copy()}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore a state from `get_state` of this object (or one with the same settings)."""
        try:
            chip, channels = state["chip"], state["channels"]
        except (KeyError, TypeError):
            raise ValueError("state must be a dict from get_state() with keys 'chip' and 'channels'") from None
        if getattr(chip, "dtype", None) != K.CHIP_STATE or getattr(channels, "dtype", None) != K.CHANNEL_STATE:
            raise ValueError("state does not come from MPU9250.get_state()")
        self._cs = chip.copy()
        self._chs = channels.copy()
        self._arrays_changed()

    def simulate(
        self,
        omega_b: Any,
        specific_force_b: Any,
        mag_b: Any,
        temperature_c: Any = None,
        *,
        increments: int = 0,
        subintervals: int = 0,
    ) -> ImuSamples:
        """Run the chip over the next input samples and return the outputs they complete.

        Args:
            omega_b: (n, 3) true angular rate in rad/s, vehicle body axes.
            specific_force_b: (n, 3) true specific force in m/s² (+9.8 up at rest), body axes,
                at the sensor's location.
            mag_b: (n, 3) true magnetic field in µT, body axes (e.g. `MagneticEnvironment.field_b`).
            temperature_c: die temperature in °C: (n,) per sample, a number, or None (the
                profile's default).
            increments: 0..4: also return ``dtheta``/``dv`` with the r-fold integrals, r = 1..increments.
            subintervals: 0..64: also return ``dtheta_sub``/``dv_sub`` over this many equal parts.

        Streaming: consecutive calls continue one stream; outputs of any chunking
        concatenate to the output of one call, bit for bit. A refused call (ValueError or
        TypeError: wrong shape, NaN or infinite values) changes nothing.
        """
        w = _rows3("omega_b", omega_b)
        f = _rows3("specific_force_b", specific_force_b)
        m = _rows3("mag_b", mag_b)
        n = w.shape[0]
        if f.shape[0] != n or m.shape[0] != n:
            raise ValueError(f"omega_b, specific_force_b and mag_b must have the same number of rows, got {n}, {f.shape[0]}, {m.shape[0]}")
        if temperature_c is None:
            temp, temp_default = _EMPTY, self._temp_default
        elif np.ndim(temperature_c) == 0:
            temp, temp_default = _EMPTY, float(temperature_c)
            if not math.isfinite(temp_default):
                raise ValueError(f"temperature_c must be finite, got {temperature_c}")
        else:
            temp = np.ascontiguousarray(temperature_c, dtype=np.float64)
            if temp.shape != (n,):
                raise ValueError(f"temperature_c must be a number or have shape ({n},), got {temp.shape}")
            temp_default = 0.0
        if increments or subintervals:
            increments, subintervals = self._check_increments(increments, subintervals)
        else:
            increments = subintervals = 0
        out = self.output_arrays(n, increments, subintervals)
        bad, k = _kernel(self._cp, self._ch, self._cs, self._chs, w, f, m, temp, temp_default, increments,
                         subintervals, *out)
        if bad >= 0:
            row = int(bad)
            names = [name for name, a in (("omega_b", w), ("specific_force_b", f), ("mag_b", m))
                     if not np.all(np.isfinite(a[row]))]
            if temp.size and not math.isfinite(temp[row]):
                names.append("temperature_c")
            raise ValueError(f"{' and '.join(names)} must be finite: row {row} is not (nothing was simulated)")
        return self.sample_views(out, k, increments, subintervals, status=bad)

    # -- the kernel's arrays (also for callers that run the kernel inside their own) ----

    def _kernel_state(self) -> tuple:
        """The kernel's first four arguments (parameters and state: the chip's own arrays)
        and the default die temperature."""
        return self._cp, self._ch, self._cs, self._chs, self._temp_default

    def output_arrays(self, n: int, increments: int = 0, subintervals: int = 0) -> tuple[np.ndarray, ...]:
        """Output arrays of the chip's kernel for up to n input rows (``K.output_bound`` rows
        each): (floats, words, status_bytes, flags), for callers that run the kernel
        (``loop_arrays``) inside their own compiled call; ``sample_views`` reads them."""
        bound = K.output_bound(n, self._ticks_per_input, self._out_div)
        return (np.empty(bound * (11 + 6 * (increments + subintervals))), np.empty((bound, 10), dtype=np.int16),
                np.empty((bound, 3), dtype=np.uint8), np.empty(bound, dtype=np.int32))

    @staticmethod
    def sample_views(out: tuple[np.ndarray, ...], k: int, increments: int = 0, subintervals: int = 0, *,
                     status: int = -1) -> ImuSamples:
        """The first k samples the kernel wrote into ``out`` (``output_arrays``), as
        ``ImuSamples`` of views of those arrays (copy them to keep them past the next run).
        ``status``: the kernel's (-1: k rows written; -2: k outputs were due but ``out`` had
        room for fewer, a wrong ``output_bound``: RuntimeError)."""
        floats, words, status_bytes, flags = out
        if status == -2:
            raise RuntimeError(f"MPU9250: {k} outputs due but room for {flags.shape[0]} (output_bound is wrong)")
        B = flags.shape[0]
        inc = None
        if increments or subintervals:
            o, r, m3 = 11 * B, 3 * B * increments, 3 * B * subintervals
            inc = (
                floats[o : o + 3 * k * increments].reshape(k, increments, 3) if increments else None,
                floats[o + r : o + r + 3 * k * increments].reshape(k, increments, 3) if increments else None,
                floats[o + 2 * r : o + 2 * r + 3 * k * subintervals].reshape(k, subintervals, 3) if subintervals else None,
                floats[o + 2 * r + m3 : o + 2 * r + m3 + 3 * k * subintervals].reshape(k, subintervals, 3)
                if subintervals else None,
            )
        status_bytes = status_bytes[:k]
        return ImuSamples(
            floats[:k],
            floats[B : B + 3 * k].reshape(k, 3),
            floats[4 * B : 4 * B + 3 * k].reshape(k, 3),
            floats[7 * B : 7 * B + 3 * k].reshape(k, 3),
            status_bytes[:, 0].view(np.bool_),
            floats[10 * B : 10 * B + k],
            flags[:k],
            RawSamples(words[:k], status_bytes[:, 1:]),
            *(inc or ()),
        )

    def _check_increments(self, increments: Any, subintervals: Any) -> tuple[int, int]:
        if isinstance(increments, bool) or not isinstance(increments, (int, np.integer)) or not 0 <= increments <= K.MAX_ORDER:
            raise ValueError(f"increments must be an int in [0, {K.MAX_ORDER}], got {increments!r}")
        if isinstance(subintervals, bool) or not isinstance(subintervals, (int, np.integer)) or not 0 <= subintervals <= MAX_SUBINTERVALS:
            raise ValueError(f"subintervals must be an int in [0, {MAX_SUBINTERVALS}], got {subintervals!r}")
        if not self._accel_per_output:
            raise ValueError(
                f"increments need whole accelerometer samples in each output interval; the ODR "
                f"{self.output_rate_hz:g} Hz exceeds the accelerometer internal rate {self.registers.accel_dlpf.rate_hz:g} Hz"
            )
        return int(increments), int(subintervals)

    def __repr__(self) -> str:
        return (
            f"MPU9250(profile={self.profile.name!r}, seed={self._seed!r}, "
            f"odr={self.output_rate_hz:g} Hz, mag={self.mag_rate_hz:g} Hz, input={self.input_rate_hz:g} Hz)"
        )


_EMPTY = np.empty(0)
_kernel = K._simulate
