"""Numba kernels of the virtual MPU-9250 (private: arrays in, arrays out, no user errors).

Parameters and state are NumPy record arrays of one element (dtypes below), so that a
kernel call takes few arguments and the whole state can be copied. ``CHANNEL_*`` records
come in an array of two: index 0 is the gyro, index 1 the accelerometer.

Time axis: the kernel works on a "base" grid of rate f_base (the largest of the input
rate and the internal rates, a multiple of all of them). Base tick b is at time b/f_base.
Input sample i is the truth at t_i = i/f_in; between input samples the truth is
interpolated linearly, so every tick in (t_{i-1}, t_i] is produced when input i arrives
(tick 0 from input 0). The chip point-samples the truth at its internal ticks. Per tick,
in this order: bias processes (20 Hz), mount vibration, gyro and accelerometer samples,
AK8963 data becoming ready / continuous measurement, output latch (then the single-mode
trigger). ``CHIP_STATE.phase`` counts ticks modulo each divider.

Random draws come from one xoshiro256++ stream in a fixed order, and terms whose standard
deviation is zero draw nothing, so a stream depends only on the configuration and the
seed, never on how the input is chunked.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.sensors._rng import _normal

N_GM = 16  # Gauss-Markov terms per axis (flicker bias approximation), upper bound
N_BUF = 1024  # internal samples per output interval kept for the increments, upper bound
N_LINE = 8  # longest whole-sample delay line of a DLPF design
N_IN = 10  # input columns: omega_b (3), specific_force_b (3), mag_b (3), temperature (1)
MAX_ORDER = 4  # multiple-integral increments r = 1..4
N_VIB = 8  # mount vibration modes, upper bound

CHANNEL_PARAMS = np.dtype(
    [
        ("sens", "f8", (3, 3)),  # M: I + scale-factor errors + cross-axis
        ("sf_tc", "f8", (3,)),  # scale-factor tempco, 1/°C
        ("bias", "f8", (3,)),  # turn-on bias
        ("bias_tc", "f8", (3,)),  # bias tempco, per °C
        ("nl", "f8", (3,)),  # nonlinearity κ, fraction of FS
        ("gsens", "f8", (3, 3)),  # g-sensitivity (gyro only)
        ("sigma", "f8", (3,)),  # white noise per internal sample
        ("gm_phi", "f8", (N_GM,)),  # Gauss-Markov factor per slow tick
        ("gm_drive", "f8", (N_GM, 3)),  # Gauss-Markov driving std per slow tick
        ("gm_sigma", "f8", (N_GM, 3)),  # stationary std (initial draw)
        ("rw_drive", "f8", (3,)),  # random-walk std per slow tick
        ("full_scale", "f8"),  # nominal full scale (nonlinearity normalisation)
        ("lsb", "f8"),  # counts per SI unit
        ("lp_a", "f8"),
        ("ap_d", "f8"),
        ("n_delay", "i8"),
        ("div", "i8"),  # base ticks per internal sample
        ("per_output", "i8"),  # internal samples per output interval (0: not whole)
    ],
    align=True,
)

CHANNEL_STATE = np.dtype(
    [
        ("lp", "f8", (3,)),
        ("ap_x", "f8", (3,)),
        ("ap_y", "f8", (3,)),
        ("line", "f8", (N_LINE, 3)),
        ("line_pos", "i8"),
        ("gm", "f8", (N_GM, 3)),
        ("rw", "f8", (3,)),
        ("slow", "f8", (3,)),  # sum of the Gauss-Markov terms and the random walk
        ("reg", "f8", (3,)),  # filtered value in the output register (before rounding)
        ("sat", "i8"),  # an internal sample was clipped since the last output
        ("buf", "f8", (N_BUF, 3)),  # internal samples of the current output interval
        ("nbuf", "i8"),
        ("prev", "f8", (3,)),  # last internal sample of the previous output interval
    ],
    align=True,
)

CHIP_PARAMS = np.dtype(
    [
        ("r_cb", "f8", (3, 3)),  # body -> chip
        ("r_bc", "f8", (3, 3)),  # chip -> body
        ("up", "i8"),  # base ticks per input interval
        ("f_base", "f8"),
        ("out_div", "i8"),  # base ticks per output sample
        ("slow_div", "i8"),  # base ticks per bias-process update
        ("n_gm", "i8"),
        ("dlpf", "i8"),
        ("quantize", "i8"),
        ("t_ref", "f8"),
        ("temp_lp_a", "f8"),
        ("temp_lsb", "f8"),
        ("temp_offset", "f8"),
        ("mag_div", "i8"),  # base ticks per AK8963 sample (continuous modes), else 0
        ("mag_trigger_div", "i8"),  # single mode: outputs per trigger (1 + I2C_MST_DLY), else 0
        ("mag_meas_ticks", "i8"),  # single mode: base ticks from trigger to data ready
        ("soft", "f8", (3, 3)),  # vehicle soft iron (body axes)
        ("hard", "f8", (3,)),  # vehicle hard iron, µT (body axes)
        ("r_ak_b", "f8", (3, 3)),  # body -> AK8963 axes
        ("r_b_ak", "f8", (3, 3)),  # AK8963 axes -> body
        ("mag_counts", "f8", (3,)),  # counts per µT of this part (true sensitivity)
        ("mag_adj", "f8", (3,)),  # ASA adjustment a driver applies
        ("mag_offset", "f8", (3,)),
        ("mag_sigma", "f8", (3,)),
        ("mag_res", "f8"),  # µT/LSB
        ("mag_max_code", "f8"),
        ("mag_overflow", "f8"),  # HOFL threshold on |x|+|y|+|z|, µT
        ("mag_bit16", "i8"),
        ("n_vib", "i8"),  # mount vibration modes (advanced at every base tick)
        ("vib_a1", "f8", (N_VIB,)),
        ("vib_a2", "f8", (N_VIB,)),
        ("vib_gain", "f8", (N_VIB, 6)),  # accel xyz, gyro xyz (body axes)
    ],
    align=True,
)

CHIP_STATE = np.dtype(
    [
        ("rng", "u8", (4,)),
        ("tick", "i8"),  # next base tick to process
        ("phase", "i8", (5,)),  # tick mod (slow, gyro, accel, mag, output) dividers
        ("n_in", "i8"),  # input samples consumed
        ("prev_in", "f8", (N_IN,)),  # last input sample
        ("temp_lp", "f8"),
        ("mag_h", "f8", (3,)),  # latest AK8963 measurement, µT, AK axes (unrounded)
        ("mag_code", "f8", (3,)),  # its output codes
        ("mag_new", "i8"),  # AK8963 samples since the last output
        ("mag_hofl", "i8"),
        ("mag_valid", "i8"),
        ("pend", "i8"),  # single mode: a measurement is under way
        ("pend_ready", "i8"),  # base tick at which it becomes readable
        ("pend_h", "f8", (3,)),
        ("pend_code", "f8", (3,)),
        ("pend_hofl", "i8"),
        ("trig_count", "i8"),  # outputs since the last trigger
        ("vib_y1", "f8", (N_VIB, 6)),
        ("vib_y2", "f8", (N_VIB, 6)),
        ("vib", "f8", (6,)),  # current mount vibration: specific force xyz, rate xyz
    ],
    align=True,
)

# Output flag bits (also exported as biso_cosim.sensors.ImuFlag).
FLAG_GYRO_SATURATED = 1
FLAG_ACCEL_SATURATED = 2
FLAG_MAG_OVERFLOW = 4
FLAG_MAG_OVERRUN = 8
FLAG_MAG_INVALID = 16


@jit
def _round_clip(x, lo, hi):
    """Round half away from zero and clip; returns (code, clipped)."""
    r = math.floor(x + 0.5) if x >= 0.0 else -math.floor(-x + 0.5)
    if r > hi:
        return hi, True
    if r < lo:
        return lo, True
    return r, False


@jit
def _slow_tick(cp, ch, chs, cs, first):
    """Advance the bias processes of both channels by one slow step (draw order fixed)."""
    for c in range(2):
        p, s = ch[c], chs[c]
        for m in range(cp.n_gm):
            for a in range(3):
                if p.gm_sigma[m, a] == 0.0:  # absent terms draw nothing
                    continue
                z = _normal(cs.rng)
                if first:
                    s.gm[m, a] = p.gm_sigma[m, a] * z
                else:
                    s.gm[m, a] = p.gm_phi[m] * s.gm[m, a] + p.gm_drive[m, a] * z
        if not first:
            for a in range(3):
                if p.rw_drive[a] != 0.0:
                    s.rw[a] += p.rw_drive[a] * _normal(cs.rng)
        for a in range(3):
            total = s.rw[a]
            for m in range(cp.n_gm):
                total += s.gm[m, a]
            s.slow[a] = total


@jit
def _vibration_tick(cp, cs):
    """Advance the mount-vibration resonators by one base tick (see vibration.py)."""
    for c in range(6):
        total = 0.0
        for m in range(cp.n_vib):
            g = cp.vib_gain[m, c]
            if g == 0.0:
                continue
            y = cp.vib_a1[m] * cs.vib_y1[m, c] + cp.vib_a2[m] * cs.vib_y2[m, c] + g * _normal(cs.rng)
            cs.vib_y2[m, c] = cs.vib_y1[m, c]
            cs.vib_y1[m, c] = y
            total += y
        cs.vib[c] = total


@jit
def _channel_sample(cp, p, s, cs, x_b, f_b, temp, first, y):
    """One internal sample of a channel: errors, noise, clipping, DLPF, register.

    ``x_b`` the true input, ``f_b`` the true specific force (both body axes); ``y`` (3,)
    receives the pre-filter sample (what the increments integrate).
    """
    x0 = cp.r_cb[0, 0] * x_b[0] + cp.r_cb[0, 1] * x_b[1] + cp.r_cb[0, 2] * x_b[2]
    x1 = cp.r_cb[1, 0] * x_b[0] + cp.r_cb[1, 1] * x_b[1] + cp.r_cb[1, 2] * x_b[2]
    x2 = cp.r_cb[2, 0] * x_b[0] + cp.r_cb[2, 1] * x_b[1] + cp.r_cb[2, 2] * x_b[2]
    f0 = cp.r_cb[0, 0] * f_b[0] + cp.r_cb[0, 1] * f_b[1] + cp.r_cb[0, 2] * f_b[2]
    f1 = cp.r_cb[1, 0] * f_b[0] + cp.r_cb[1, 1] * f_b[1] + cp.r_cb[1, 2] * f_b[2]
    f2 = cp.r_cb[2, 0] * f_b[0] + cp.r_cb[2, 1] * f_b[1] + cp.r_cb[2, 2] * f_b[2]
    dt = temp - cp.t_ref
    fs = p.full_scale
    lo = -32768.0 / p.lsb
    hi = 32767.0 / p.lsb
    for a in range(3):
        xa = x0 if a == 0 else (x1 if a == 1 else x2)
        v = p.bias[a] + p.bias_tc[a] * dt + s.slow[a]
        v += p.sens[a, 0] * x0 + p.sens[a, 1] * x1 + p.sens[a, 2] * x2
        v += p.sf_tc[a] * dt * xa
        v += p.gsens[a, 0] * f0 + p.gsens[a, 1] * f1 + p.gsens[a, 2] * f2
        u = xa / fs
        v += 2.5 * p.nl[a] * fs * u * u * u
        if p.sigma[a] != 0.0:
            v += p.sigma[a] * _normal(cs.rng)
        if cp.quantize:
            # the ADC saturates at the register's full scale
            if v > hi:
                v = hi
                s.sat = 1
            elif v < lo:
                v = lo
                s.sat = 1
        y[a] = v
    for a in range(3):
        v = y[a]
        if first:
            s.lp[a] = v
            s.ap_x[a] = v
            s.ap_y[a] = v
            for k in range(N_LINE):
                s.line[k, a] = v
        if cp.dlpf:
            s.lp[a] = p.lp_a * s.lp[a] + (1.0 - p.lp_a) * v
            ap = p.ap_d * s.lp[a] + s.ap_x[a] - p.ap_d * s.ap_y[a]
            s.ap_x[a] = s.lp[a]
            s.ap_y[a] = ap
            if p.n_delay > 0:
                out = s.line[s.line_pos, a]
                s.line[s.line_pos, a] = ap
                ap = out
            s.reg[a] = ap
        else:
            s.reg[a] = v
    if cp.dlpf and p.n_delay > 0:
        s.line_pos = (s.line_pos + 1) % p.n_delay
    # keep the pre-filter samples of this output interval for the increments
    if first:
        for k in range(p.per_output):
            for a in range(3):
                s.buf[k, a] = y[a]
        s.nbuf = p.per_output
        for a in range(3):
            s.prev[a] = y[a]
    elif s.nbuf < N_BUF:
        for a in range(3):
            s.buf[s.nbuf, a] = y[a]
        s.nbuf += 1


@jit
def _increments(p, s, h, order, nsub, out_r, out_sub):
    """Multiple-integral and sub-interval increments of one output interval (chip axes).

    The internal samples are joined by straight lines (the same interpolation as the
    input); ``out_r[r-1]`` is the exact r-fold iterated integral of that polyline over the
    interval (Litmanovich 2002, eq. 1.14), accumulated by repeated summation segment by
    segment; ``out_sub[l]`` its single integral over the l-th of ``nsub`` equal parts.
    """
    n = p.per_output
    h2 = h * h
    h3 = h2 * h
    h4 = h3 * h
    for a in range(3):
        i1 = 0.0
        i2 = 0.0
        i3 = 0.0
        i4 = 0.0
        for k in range(nsub):
            out_sub[k, a] = 0.0
        for seg in range(n):
            va = s.prev[a] if seg == 0 else s.buf[seg - 1, a]
            vb = s.buf[seg, a]
            i4 += i3 * h + i2 * h2 / 2.0 + i1 * h3 / 6.0 + h4 * (va / 30.0 + vb / 120.0)
            i3 += i2 * h + i1 * h2 / 2.0 + h3 * (va / 8.0 + vb / 24.0)
            i2 += i1 * h + h2 * (va / 3.0 + vb / 6.0)
            i1 += h * (va + vb) / 2.0
            if nsub > 0:
                # segment seg spans [seg·nsub, (seg+1)·nsub] in units of 1/nsub segment;
                # part l spans [l·n, (l+1)·n]
                lo = seg * nsub
                hi = lo + nsub
                l = lo // n
                while l * n < hi and l < nsub:
                    u0 = max(lo, l * n)
                    u1 = min(hi, (l + 1) * n)
                    p0 = (u0 - lo) / nsub
                    p1 = (u1 - lo) / nsub
                    out_sub[l, a] += h * (va * (p1 - p0) + (vb - va) * (p1 * p1 - p0 * p0) / 2.0)
                    l += 1
        if order >= 1:
            out_r[0, a] = i1
        if order >= 2:
            out_r[1, a] = i2
        if order >= 3:
            out_r[2, a] = i3
        if order >= 4:
            out_r[3, a] = i4


@jit
def _rotate_rows(r, src, dst):
    """dst[k] = r @ src[k] for rows k of (m, 3) arrays."""
    for k in range(src.shape[0]):
        a, b, c = src[k, 0], src[k, 1], src[k, 2]
        for i in range(3):
            dst[k, i] = r[i, 0] * a + r[i, 1] * b + r[i, 2] * c


@jit
def _first_bad_row(omega, force, mag, temp):
    """Index of the first input row holding a non-finite value, or -1."""
    for i in range(omega.shape[0]):
        for a in range(3):
            if not (math.isfinite(omega[i, a]) and math.isfinite(force[i, a]) and math.isfinite(mag[i, a])):
                return i
        if temp.shape[0] > 0 and not math.isfinite(temp[i]):
            return i
    return -1


@jit
def _n_outputs(cp, cs, n):
    """Number of output ticks that ``n`` more input samples complete."""
    if n == 0:
        return 0
    ticks = 1 + (n - 1) * cp.up if cs.n_in == 0 else n * cp.up
    b0 = cs.tick
    b1 = b0 + ticks - 1
    return b1 // cp.out_div - (b0 + cp.out_div - 1) // cp.out_div + 1


@jit
def _simulate(cp_arr, ch, cs_arr, chs, omega, force, mag, temp, temp_default, order, nsub, floats, words,
              status_bytes, flags_out):
    """Run the chip over input rows; writes the outputs of the ticks they complete.

    ``temp`` holds one value per row, or is empty (then ``temp_default`` is used). The
    caller allocates the outputs for up to K rows (``output_bound``; more than a call
    completes); every entry of the first k rows is written (the arrays may be reused):

    * floats (K·(11 + 6·order + 6·nsub),): float64 blocks of K rows each, ``t (K) |
      gyro (K, 3) | accel (K, 3) | mag (K, 3) | temperature (K) | dtheta (K, order, 3) | dv |
      dtheta_sub (K, nsub, 3) | dv_sub``, of which the first k rows are written;
    * words: int16 (K, 10) registers ``ACCEL_X..Z, TEMP, GYRO_X..Z, HX, HY, HZ``;
    * status_bytes: uint8 (K, 3) ``mag fresh, ST1, ST2``;
    * flags_out: int32 (K,).

    Returns (status, k): status -1 on success, the index of the first non-finite input row,
    or -2 when the outputs hold fewer than the k rows due (in both cases nothing has
    changed). The outputs are the caller's because arrays made here cost about a
    microsecond each to hand back to Python.
    """
    cp = cp_arr[0]
    cs = cs_arr[0]
    gp, ap = ch[0], ch[1]
    gs, as_ = chs[0], chs[1]
    n = omega.shape[0]
    bad = _first_bad_row(omega, force, mag, temp)
    if bad >= 0:
        return bad, 0
    kout = _n_outputs(cp, cs, n)
    K = flags_out.shape[0]
    if kout > K:  # outputs too short (see output_bound): nothing has changed
        return -2, kout
    t_out = floats[:K]
    gyro_out = floats[K : 4 * K].reshape((K, 3))
    accel_out = floats[4 * K : 7 * K].reshape((K, 3))
    mag_out = floats[7 * K : 10 * K].reshape((K, 3))
    temp_out = floats[10 * K : 11 * K]
    o = 11 * K
    dtheta = floats[o : o + 3 * K * order].reshape((K, order, 3))
    o += 3 * K * order
    dv = floats[o : o + 3 * K * order].reshape((K, order, 3))
    o += 3 * K * order
    dtheta_sub = floats[o : o + 3 * K * nsub].reshape((K, nsub, 3))
    o += 3 * K * nsub
    dv_sub = floats[o : o + 3 * K * nsub].reshape((K, nsub, 3))

    cur = np.empty(N_IN)
    x = np.empty(3)
    f = np.empty(3)
    y = np.empty(3)
    tmp_r = np.empty((max(order, 1), 3))
    tmp_s = np.empty((max(nsub, 1), 3))
    k = 0
    for i in range(n):
        for a in range(3):
            cur[a] = omega[i, a]
            cur[3 + a] = force[i, a]
            cur[6 + a] = mag[i, a]
        cur[9] = temp[i] if temp.shape[0] > 0 else temp_default
        if cs.n_in == 0:
            # input 0 makes tick 0; the truth before it is taken as constant (settled chip)
            for c in range(N_IN):
                cs.prev_in[c] = cur[c]
            sub_lo, sub_hi = 0, 0
        else:
            sub_lo, sub_hi = 1, cp.up
        for sub in range(sub_lo, sub_hi + 1):
            # truth at this tick: linear interpolation between the previous and this input
            # (written so that w = 0 and w = 1 give the samples exactly)
            w = sub / cp.up
            b = cs.tick
            first = b == 0
            ph = cs.phase  # counters instead of b % divider: integer division is slow
            if ph[0] == 0:
                _slow_tick(cp, ch, chs, cs, first)
            temp_now = (1.0 - w) * cs.prev_in[9] + w * cur[9]
            if cp.n_vib > 0:
                _vibration_tick(cp, cs)
            is_gyro = ph[1] == 0
            is_accel = ph[2] == 0
            if is_gyro or is_accel:
                for a in range(3):
                    f[a] = (1.0 - w) * cs.prev_in[3 + a] + w * cur[3 + a] + cs.vib[a]
            if is_gyro:
                for a in range(3):
                    x[a] = (1.0 - w) * cs.prev_in[a] + w * cur[a] + cs.vib[3 + a]
                _channel_sample(cp, gp, gs, cs, x, f, temp_now, first, y)
                # on-chip temperature sensor, filtered at the gyro internal rate
                if first or not cp.dlpf:
                    cs.temp_lp = temp_now
                else:
                    cs.temp_lp = cp.temp_lp_a * cs.temp_lp + (1.0 - cp.temp_lp_a) * temp_now
            if is_accel:
                _channel_sample(cp, ap, as_, cs, f, f, temp_now, first, y)
            if cs.pend and b >= cs.pend_ready:
                _mag_commit(cs)
            if cp.mag_div > 0 and ph[3] == 0:
                for a in range(3):
                    x[a] = (1.0 - w) * cs.prev_in[6 + a] + w * cur[6 + a]
                _mag_measure(cp, cs, x)
                _mag_commit(cs)
            if ph[4] == 0:
                _output(cp, gp, gs, ap, as_, cs, k, b, t_out, gyro_out, accel_out, mag_out, temp_out,
                        flags_out, words, status_bytes)
                if cp.mag_trigger_div > 0:
                    # single mode: the driver writes CNTL1 after reading, every 1 + I2C_MST_DLY
                    # samples; a write during a measurement is ignored
                    if cs.trig_count == 0 and not cs.pend:
                        for a in range(3):
                            x[a] = (1.0 - w) * cs.prev_in[6 + a] + w * cur[6 + a]
                        _mag_measure(cp, cs, x)
                        cs.pend_ready = b + cp.mag_meas_ticks
                    cs.trig_count = (cs.trig_count + 1) % cp.mag_trigger_div
                if order > 0 or nsub > 0:
                    _increments(gp, gs, gp.div / cp.f_base, order, nsub, tmp_r, tmp_s)
                    if order > 0:
                        _rotate_rows(cp.r_bc, tmp_r, dtheta[k])
                    if nsub > 0:
                        _rotate_rows(cp.r_bc, tmp_s, dtheta_sub[k])
                    _increments(ap, as_, ap.div / cp.f_base, order, nsub, tmp_r, tmp_s)
                    if order > 0:
                        _rotate_rows(cp.r_bc, tmp_r, dv[k])
                    if nsub > 0:
                        _rotate_rows(cp.r_bc, tmp_s, dv_sub[k])
                _end_interval(gs)
                _end_interval(as_)
                k += 1
            cs.tick = b + 1
            _advance(ph, 0, cp.slow_div)
            _advance(ph, 1, gp.div)
            _advance(ph, 2, ap.div)
            _advance(ph, 3, cp.mag_div)
            _advance(ph, 4, cp.out_div)
        for c in range(N_IN):
            cs.prev_in[c] = cur[c]
        cs.n_in += 1
    return -1, kout


def output_bound(n: int, ticks_per_input: int, out_div: int) -> int:
    """An upper bound of the outputs n input rows complete (``_n_outputs``): they span at
    most n·up base ticks, of which every out_div-th is an output."""
    return n * ticks_per_input // out_div + 1


@jit
def _advance(phase, i, divider):
    """phase[i] = (phase[i] + 1) mod divider."""
    p = phase[i] + 1
    phase[i] = 0 if p >= divider else p


@jit
def _end_interval(s):
    """Start a new output interval: remember its last sample, clear buffer and saturation."""
    if s.nbuf > 0:
        for a in range(3):
            s.prev[a] = s.buf[s.nbuf - 1, a]
    s.nbuf = 0
    s.sat = 0


@jit
def _mag_measure(cp, cs, b_b):
    """An AK8963 measurement of the body-axes field ``b_b`` (µT), into the pending slot."""
    v0 = cp.soft[0, 0] * b_b[0] + cp.soft[0, 1] * b_b[1] + cp.soft[0, 2] * b_b[2] + cp.hard[0]
    v1 = cp.soft[1, 0] * b_b[0] + cp.soft[1, 1] * b_b[1] + cp.soft[1, 2] * b_b[2] + cp.hard[1]
    v2 = cp.soft[2, 0] * b_b[0] + cp.soft[2, 1] * b_b[1] + cp.soft[2, 2] * b_b[2] + cp.hard[2]
    total = 0.0
    for a in range(3):
        h = cp.r_ak_b[a, 0] * v0 + cp.r_ak_b[a, 1] * v1 + cp.r_ak_b[a, 2] * v2
        h += cp.mag_offset[a]
        if cp.mag_sigma[a] != 0.0:
            h += cp.mag_sigma[a] * _normal(cs.rng)
        cs.pend_h[a] = h
        total += abs(h)
        code, _ = _round_clip(h * cp.mag_counts[a], -cp.mag_max_code, cp.mag_max_code)
        cs.pend_code[a] = code
    cs.pend_hofl = 1 if total >= cp.mag_overflow else 0
    cs.pend = 1


@jit
def _mag_commit(cs):
    """The pending AK8963 measurement becomes readable (DRDY)."""
    for a in range(3):
        cs.mag_h[a] = cs.pend_h[a]
        cs.mag_code[a] = cs.pend_code[a]
    cs.mag_hofl = cs.pend_hofl
    cs.mag_new += 1
    cs.mag_valid = 1
    cs.pend = 0


@jit
def _output(cp, gp, gs, ap, as_, cs, k, b, t_out, gyro_out, accel_out, mag_out, temp_out, flags_out,
            words, status_bytes):
    """Latch the registers into output row k (at base tick b)."""
    t_out[k] = b / cp.f_base
    flags = 0
    for c in range(2):
        p = gp if c == 0 else ap
        s = gs if c == 0 else as_
        out = gyro_out if c == 0 else accel_out
        col = 4 if c == 0 else 0
        sat = s.sat != 0
        code0, clip0 = _round_clip(s.reg[0] * p.lsb, -32768.0, 32767.0)
        code1, clip1 = _round_clip(s.reg[1] * p.lsb, -32768.0, 32767.0)
        code2, clip2 = _round_clip(s.reg[2] * p.lsb, -32768.0, 32767.0)
        words[k, col] = np.int16(code0)
        words[k, col + 1] = np.int16(code1)
        words[k, col + 2] = np.int16(code2)
        if cp.quantize:
            v0, v1, v2 = code0 / p.lsb, code1 / p.lsb, code2 / p.lsb
        else:
            v0, v1, v2 = s.reg[0], s.reg[1], s.reg[2]
        for a in range(3):
            out[k, a] = cp.r_bc[a, 0] * v0 + cp.r_bc[a, 1] * v1 + cp.r_bc[a, 2] * v2
        if sat or clip0 or clip1 or clip2:
            flags |= FLAG_GYRO_SATURATED if c == 0 else FLAG_ACCEL_SATURATED
    code, _ = _round_clip((cs.temp_lp - cp.temp_offset) * cp.temp_lsb, -32768.0, 32767.0)
    words[k, 3] = np.int16(code)
    temp_out[k] = code / cp.temp_lsb + cp.temp_offset if cp.quantize else cs.temp_lp
    bitm = 16 if cp.mag_bit16 else 0
    if cs.mag_valid:
        for a in range(3):
            words[k, 7 + a] = np.int16(cs.mag_code[a])
        if cp.quantize:
            v0 = cs.mag_code[0] * cp.mag_res * cp.mag_adj[0]
            v1 = cs.mag_code[1] * cp.mag_res * cp.mag_adj[1]
            v2 = cs.mag_code[2] * cp.mag_res * cp.mag_adj[2]
        else:
            v0, v1, v2 = cs.mag_h[0], cs.mag_h[1], cs.mag_h[2]
        for a in range(3):
            mag_out[k, a] = cp.r_b_ak[a, 0] * v0 + cp.r_b_ak[a, 1] * v1 + cp.r_b_ak[a, 2] * v2
        fresh = cs.mag_new > 0
        overrun = cs.mag_new > 1
        if overrun:
            flags |= FLAG_MAG_OVERRUN
        if cs.mag_hofl:
            flags |= FLAG_MAG_OVERFLOW
        status_bytes[k, 0] = 1 if fresh else 0
        status_bytes[k, 1] = (1 if fresh else 0) | (2 if overrun else 0)
        status_bytes[k, 2] = (8 if cs.mag_hofl else 0) | bitm
    else:
        for a in range(3):
            mag_out[k, a] = np.nan
            words[k, 7 + a] = 0
        flags |= FLAG_MAG_INVALID
        status_bytes[k, 0] = 0
        status_bytes[k, 1] = 0
        status_bytes[k, 2] = bitm
    cs.mag_new = 0
    flags_out[k] = flags
