/* The virtual MPU-9250 and AK8963: set-up (mpu9250.py _timing and _build, profile.py
 * draw_errors) and the per-tick kernel (_kernels.py), statement for statement, so that the
 * arithmetic and the order of random draws are the Python model's. */
#include "biso_sensor.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "rng.h"

/* ---- helpers ------------------------------------------------------------------------------- */

int biso_profile_index(const char *name) {
    int i;
    if (!name) return -1;
    for (i = 0; i < biso_n_profiles; i++)
        if (strcmp(biso_profiles[i].name, name) == 0) return i;
    return -1;
}

int biso_register_check(int field, int value, char *msg, size_t len) {
    const biso_register_field *f;
    int i, n = 0;
    if (field < 0 || field >= BISO_N_REGISTERS) {
        snprintf(msg, len, "no register field %d", field);
        return 1;
    }
    f = &biso_registers[field];
    for (i = 0; i < f->n_allowed; i++)
        if (f->allowed[i] == value) return 0;
    n = snprintf(msg, len, "registers.%s must be one of ", f->name);
    for (i = 0; i < f->n_allowed && n > 0 && (size_t)n < len; i++) {
        /* runs of consecutive values as low..high */
        int j = i;
        while (j + 1 < f->n_allowed && f->allowed[j + 1] == f->allowed[j] + 1) j++;
        if (j > i)
            n += snprintf(msg + n, len - n, "%s%d..%d", i ? ", " : "", f->allowed[i], f->allowed[j]);
        else
            n += snprintf(msg + n, len - n, "%s%d", i ? ", " : "", f->allowed[i]);
        i = j;
    }
    if (n > 0 && (size_t)n < len) snprintf(msg + n, len - n, ", got %d", value);
    return 1;
}

void biso_mounting_matrix(const double q[4], double r[3][3]) {
    double norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    double w = q[0] / norm, x = q[1] / norm, y = q[2] / norm, z = q[3] / norm;
    r[0][0] = 1 - 2 * (y * y + z * z);
    r[0][1] = 2 * (x * y - w * z);
    r[0][2] = 2 * (x * z + w * y);
    r[1][0] = 2 * (x * y + w * z);
    r[1][1] = 1 - 2 * (x * x + z * z);
    r[1][2] = 2 * (y * z - w * x);
    r[2][0] = 2 * (x * z - w * y);
    r[2][1] = 2 * (y * z + w * x);
    r[2][2] = 1 - 2 * (x * x + y * y);
}

/* a / b if it is a positive integer (to 1e-9, as math.isclose), else 0 (mpu9250._ratio) */
static long ratio(double a, double b) {
    double r = a / b;
    double n = nearbyint(r); /* Python's round: half to even */
    double diff = fabs(r - n);
    if (n >= 1.0 && (diff <= fabs(1e-9 * n) || diff <= fabs(1e-9 * r))) return (long)n;
    return 0;
}

/* N(0, (tol/3)²) truncated at ±tol (profile._truncated_normal) */
static double truncated_normal(biso_pcg64 *g, double tol) {
    double z = biso_np_standard_normal(g);
    while (fabs(z) > 3.0) z = biso_np_standard_normal(g);
    return tol * z / 3.0;
}

static void draw_inertial(biso_pcg64 *g, const biso_inertial_profile *ip, int gyro, biso_mpu_channel_params *c) {
    double scale[3], cross[3][3];
    int i, j;
    for (i = 0; i < 3; i++) scale[i] = truncated_normal(g, ip->scale_factor[i]);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) cross[i][j] = truncated_normal(g, ip->cross_axis);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            c->sens[i][j] = ((i == j ? 1.0 : 0.0) + (i == j ? scale[i] : 0.0)) + (i == j ? 0.0 : cross[i][j]);
    for (i = 0; i < 3; i++) c->sf_tc[i] = truncated_normal(g, ip->scale_factor_tempco[i]);
    for (i = 0; i < 3; i++) c->bias[i] = truncated_normal(g, ip->bias_initial[i]);
    for (i = 0; i < 3; i++) c->bias_tc[i] = truncated_normal(g, ip->bias_tempco[i]);
    for (i = 0; i < 3; i++) c->nl[i] = truncated_normal(g, ip->nonlinearity[i]);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) c->gsens[i][j] = gyro ? truncated_normal(g, ip->g_sensitivity) : 0.0;
}

static const biso_dlpf_row *gyro_row(const int *reg) {
    if (reg[BISO_REG_GYRO_FCHOICE_B] & 1) return &biso_chip.gyro[8];
    if (reg[BISO_REG_GYRO_FCHOICE_B] == 2) return &biso_chip.gyro[9];
    return &biso_chip.gyro[reg[BISO_REG_DLPF_CFG]];
}

static const biso_dlpf_row *accel_row(const int *reg) {
    return reg[BISO_REG_ACCEL_FCHOICE_B] ? &biso_chip.accel[8] : &biso_chip.accel[reg[BISO_REG_A_DLPF_CFG]];
}

/* ---- set-up -------------------------------------------------------------------------------- */

int biso_mpu_setup(biso_mpu_params *p, const biso_mpu_config *cfg, char *msg, size_t len) {
    const int *reg = cfg->registers;
    const biso_dlpf_row *grow, *arow;
    const biso_profile *prof;
    double f_in = cfg->input_rate_hz, f_g, f_a, f_mag, slow_dt, out_rate, mag_rate;
    long gdiv, adiv, per_output;
    int i, j, k, c, single, uses_div;
    uint32_t pool[4];
    biso_pcg64 g;

    memset(p, 0, sizeof *p);
    if (cfg->profile < 0 || cfg->profile >= biso_n_profiles) {
        snprintf(msg, len, "no built-in profile %d", cfg->profile);
        return 1;
    }
    for (i = 0; i < BISO_N_REGISTERS; i++)
        if (biso_register_check(i, reg[i], msg, len)) return 1;
    if (!(isfinite(f_in) && f_in > 0.0)) {
        snprintf(msg, len, "input_rate_hz must be positive and finite, got %g", f_in);
        return 1;
    }
    prof = &biso_profiles[cfg->profile];
    grow = gyro_row(reg);
    arow = accel_row(reg);
    f_g = grow->rate_hz;
    f_a = arow->rate_hz;
    for (c = 0; c < 2; c++) {
        double f = c == 0 ? f_g : f_a;
        if (!(ratio(f, f_in) || ratio(f_in, f))) {
            snprintf(msg, len,
                     "input_rate_hz=%g must be an integer multiple or fraction of the %s internal rate %g Hz of these "
                     "registers", f_in, c == 0 ? "gyro" : "accelerometer", f);
            return 1;
        }
    }
    p->f_base = f_in;
    if (f_g > p->f_base) p->f_base = f_g;
    if (f_a > p->f_base) p->f_base = f_a;
    p->input_rate_hz = f_in;
    p->up = ratio(p->f_base, f_in);
    gdiv = ratio(p->f_base, f_g);
    adiv = ratio(p->f_base, f_a);
    uses_div = reg[BISO_REG_GYRO_FCHOICE_B] == 0 && 0 < reg[BISO_REG_DLPF_CFG] && reg[BISO_REG_DLPF_CFG] < 7;
    per_output = uses_div ? 1 + reg[BISO_REG_SMPLRT_DIV] : 1;
    p->out_div = gdiv * per_output;
    p->slow_div = ratio(p->f_base, biso_chip.slow_rate_hz);
    single = reg[BISO_REG_MAG_MODE] == biso_chip.mode_single;
    out_rate = uses_div ? biso_chip.dlpf_internal_rate_hz / (1 + reg[BISO_REG_SMPLRT_DIV]) : f_g;
    if (single)
        mag_rate = out_rate / (1 + reg[BISO_REG_I2C_MST_DLY]);
    else if (reg[BISO_REG_MAG_MODE] == biso_chip.mode_continuous_1)
        mag_rate = biso_chip.continuous_1_rate_hz;
    else if (reg[BISO_REG_MAG_MODE] == biso_chip.mode_continuous_2)
        mag_rate = biso_chip.continuous_2_rate_hz;
    else
        mag_rate = 0.0;
    f_mag = single ? 0.0 : mag_rate;
    p->mag_div = f_mag > 0 ? ratio(p->f_base, f_mag) : 0;
    p->mag_trigger_div = single ? 1 + reg[BISO_REG_I2C_MST_DLY] : 0;
    p->mag_meas_ticks = (long)ceil(biso_chip.single_measurement_time_ms * 1e-3 * p->f_base - 1e-9);
    if (!(p->up && gdiv && adiv && p->slow_div) || (f_mag > 0 && !p->mag_div)) {
        snprintf(msg, len, "input_rate_hz=%g gives no common time grid with the chip's rates", f_in);
        return 1;
    }

    /* the part: SeedSequence(seed).spawn(2): child 0 draws the errors, child 1 seeds the noise */
    biso_seed_child_pool(cfg->seed, 0, pool);
    biso_pcg64_seed(&g, pool);
    draw_inertial(&g, &prof->gyro, 1, &p->ch[0]);
    draw_inertial(&g, &prof->accel, 0, &p->ch[1]);
    {
        double factor[3], lo = prof->mag_asa_range[0], hi = prof->mag_asa_range[1];
        double factor_lo = (lo - 128.0) / 256.0 + 1.0, factor_hi = (hi - 128.0) / 256.0 + 1.0;
        for (i = 0; i < 3; i++) p->mag_offset[i] = truncated_normal(&g, prof->mag_offset[i]);
        for (i = 0; i < 3; i++) factor[i] = hi > lo ? biso_np_uniform(&g, factor_lo, factor_hi) : factor_lo;
        for (i = 0; i < 3; i++) {
            double a = nearbyint((factor[i] - 1.0) * 256.0 + 128.0); /* np.round: half to even */
            a = a < 0.0 ? 0.0 : (a > 255.0 ? 255.0 : a);
            p->asa[i] = (uint8_t)a;
        }
        biso_seed_child_pool(cfg->seed, 1, pool);
        biso_seed_generate_state64(pool, p->rng_seed_words, 4);
        if (!(p->rng_seed_words[0] | p->rng_seed_words[1] | p->rng_seed_words[2] | p->rng_seed_words[3]))
            p->rng_seed_words[0] = 0x9E3779B97F4A7C15ULL;
        {
            double res = reg[BISO_REG_MAG_BIT16] ? biso_chip.resolution_16bit_ut : biso_chip.resolution_14bit_ut;
            p->mag_res = res;
            p->mag_max_code = reg[BISO_REG_MAG_BIT16] ? biso_chip.max_code_16bit : biso_chip.max_code_14bit;
            for (i = 0; i < 3; i++) {
                p->mag_counts[i] = 1.0 / (res * factor[i]);
                p->mag_adj[i] = ((double)p->asa[i] - 128.0) / 256.0 + 1.0;
                p->mag_sigma[i] = prof->mag_noise[i];
            }
        }
    }
    p->temp_default = prof->temperature_default;
    p->dlpf = prof->dlpf;
    p->quantize = prof->quantization;
    slow_dt = (double)p->slow_div / p->f_base;

    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            p->r_bc[i][j] = cfg->r_bc[i][j];
            p->r_cb[i][j] = cfg->r_bc[j][i];
            p->soft[i][j] = cfg->soft_iron[i][j];
        }
    for (i = 0; i < 3; i++) p->hard[i] = cfg->hard_iron_ut[i];
    p->t_ref = prof->temperature_reference;
    p->temp_lp_a = grow->temp_lowpass_a;
    p->temp_lsb = biso_chip.temp_lsb_per_c;
    p->temp_offset = biso_chip.temp_offset_c;
    /* AK8963 axes: r_ak_b = AK8963_FROM_CHIP · r_cb, r_b_ak = r_bc · AK8963_FROM_CHIPᵀ (the
     * map is a signed permutation: these products are exact in any order) */
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            double a = 0.0, b = 0.0;
            for (k = 0; k < 3; k++) {
                a += biso_chip.ak8963_from_chip[i][k] * p->r_cb[k][j];
                b += p->r_bc[i][k] * biso_chip.ak8963_from_chip[j][k];
            }
            p->r_ak_b[i][j] = a;
            p->r_b_ak[i][j] = b;
        }
    p->mag_overflow = biso_chip.overflow_sum_ut;
    p->mag_bit16 = reg[BISO_REG_MAG_BIT16] != 0;

    for (c = 0; c < 2; c++) {
        biso_mpu_channel_params *ch = &p->ch[c];
        const biso_inertial_profile *ip = c == 0 ? &prof->gyro : &prof->accel;
        const biso_dlpf_row *row = c == 0 ? grow : arow;
        int fs = reg[c == 0 ? BISO_REG_GYRO_FS_SEL : BISO_REG_ACCEL_FS_SEL];
        for (i = 0; i < 3; i++) ch->sigma[i] = ip->noise_density[i] * sqrt(row->rate_hz);
        for (k = 0; k < ip->n_gm; k++) {
            double phi = exp(-slow_dt / ip->gm_tau[k]);
            ch->gm_phi[k] = phi;
            for (i = 0; i < 3; i++) {
                ch->gm_sigma[k][i] = ip->gm_sigma[k][i];
                ch->gm_drive[k][i] = ip->gm_sigma[k][i] * sqrt(1.0 - phi * phi);
            }
        }
        for (i = 0; i < 3; i++) ch->rw_drive[i] = ip->random_walk[i] * sqrt(slow_dt);
        ch->full_scale = c == 0 ? biso_chip.gyro_full_scale[fs] : biso_chip.accel_full_scale[fs];
        ch->lsb = c == 0 ? biso_chip.gyro_lsb_per_unit[fs] : biso_chip.accel_lsb_per_unit[fs];
        ch->lp_a = row->lowpass_a;
        ch->ap_d = row->allpass_d;
        ch->n_delay = row->delay_samples;
        ch->div = c == 0 ? gdiv : adiv;
        if (ip->n_gm > p->n_gm) p->n_gm = ip->n_gm; /* both channels' terms: absent ones have sigma 0 */
    }
    return 0;
}

void biso_mpu_reset(const biso_mpu_params *p, biso_mpu_state *s) {
    memset(s, 0, sizeof *s);
    memcpy(s->rng, p->rng_seed_words, sizeof s->rng);
}

int biso_mpu_max_outputs(const biso_mpu_params *p) { return (int)(p->up / p->out_div + 1); }

double biso_mpu_output_rate_hz(const biso_mpu_params *p) { return p->f_base / (double)p->out_div; }

double biso_mpu_time_s(const biso_mpu_params *p, const biso_mpu_state *s) {
    return (double)s->n_in / p->input_rate_hz;
}

/* ---- the kernel ---------------------------------------------------------------------------- */

/* round half away from zero and clip; *clipped set when clipped */
static double round_clip(double x, double lo, double hi, int *clipped) {
    double r = x >= 0.0 ? floor(x + 0.5) : -floor(-x + 0.5);
    *clipped = 0;
    if (r > hi) { *clipped = 1; return hi; }
    if (r < lo) { *clipped = 1; return lo; }
    return r;
}

static void slow_tick(const biso_mpu_params *p, biso_mpu_state *s, int first) {
    int c, m, a;
    for (c = 0; c < 2; c++) {
        const biso_mpu_channel_params *cp = &p->ch[c];
        biso_mpu_channel_state *cs = &s->ch[c];
        for (m = 0; m < p->n_gm; m++)
            for (a = 0; a < 3; a++) {
                double z;
                if (cp->gm_sigma[m][a] == 0.0) continue; /* absent terms draw nothing */
                z = biso_xoshiro_normal(s->rng);
                if (first)
                    cs->gm[m][a] = cp->gm_sigma[m][a] * z;
                else
                    cs->gm[m][a] = cp->gm_phi[m] * cs->gm[m][a] + cp->gm_drive[m][a] * z;
            }
        if (!first)
            for (a = 0; a < 3; a++)
                if (cp->rw_drive[a] != 0.0) cs->rw[a] += cp->rw_drive[a] * biso_xoshiro_normal(s->rng);
        for (a = 0; a < 3; a++) {
            double total = cs->rw[a];
            for (m = 0; m < p->n_gm; m++) total += cs->gm[m][a];
            cs->slow[a] = total;
        }
    }
}

static void channel_sample(const biso_mpu_params *p, int c, biso_mpu_state *st, const double x_b[3],
                           const double f_b[3], double temp, int first) {
    const biso_mpu_channel_params *cp = &p->ch[c];
    biso_mpu_channel_state *s = &st->ch[c];
    double y[3];
    double x0 = p->r_cb[0][0] * x_b[0] + p->r_cb[0][1] * x_b[1] + p->r_cb[0][2] * x_b[2];
    double x1 = p->r_cb[1][0] * x_b[0] + p->r_cb[1][1] * x_b[1] + p->r_cb[1][2] * x_b[2];
    double x2 = p->r_cb[2][0] * x_b[0] + p->r_cb[2][1] * x_b[1] + p->r_cb[2][2] * x_b[2];
    double f0 = p->r_cb[0][0] * f_b[0] + p->r_cb[0][1] * f_b[1] + p->r_cb[0][2] * f_b[2];
    double f1 = p->r_cb[1][0] * f_b[0] + p->r_cb[1][1] * f_b[1] + p->r_cb[1][2] * f_b[2];
    double f2 = p->r_cb[2][0] * f_b[0] + p->r_cb[2][1] * f_b[1] + p->r_cb[2][2] * f_b[2];
    double dt = temp - p->t_ref;
    double fs = cp->full_scale;
    double lo = -32768.0 / cp->lsb, hi = 32767.0 / cp->lsb;
    int a, k;
    for (a = 0; a < 3; a++) {
        double xa = a == 0 ? x0 : (a == 1 ? x1 : x2);
        double v = cp->bias[a] + cp->bias_tc[a] * dt + s->slow[a];
        double u;
        v += cp->sens[a][0] * x0 + cp->sens[a][1] * x1 + cp->sens[a][2] * x2;
        v += cp->sf_tc[a] * dt * xa;
        v += cp->gsens[a][0] * f0 + cp->gsens[a][1] * f1 + cp->gsens[a][2] * f2;
        u = xa / fs;
        v += 2.5 * cp->nl[a] * fs * u * u * u;
        if (cp->sigma[a] != 0.0) v += cp->sigma[a] * biso_xoshiro_normal(st->rng);
        if (p->quantize) { /* the ADC saturates at the register's full scale */
            if (v > hi) {
                v = hi;
                s->sat = 1;
            } else if (v < lo) {
                v = lo;
                s->sat = 1;
            }
        }
        y[a] = v;
    }
    for (a = 0; a < 3; a++) {
        double v = y[a];
        if (first) {
            s->lp[a] = v;
            s->ap_x[a] = v;
            s->ap_y[a] = v;
            for (k = 0; k < BISO_N_LINE; k++) s->line[k][a] = v;
        }
        if (p->dlpf) {
            double ap;
            s->lp[a] = cp->lp_a * s->lp[a] + (1.0 - cp->lp_a) * v;
            ap = cp->ap_d * s->lp[a] + s->ap_x[a] - cp->ap_d * s->ap_y[a];
            s->ap_x[a] = s->lp[a];
            s->ap_y[a] = ap;
            if (cp->n_delay > 0) {
                double out = s->line[s->line_pos][a];
                s->line[s->line_pos][a] = ap;
                ap = out;
            }
            s->reg[a] = ap;
        } else {
            s->reg[a] = v;
        }
    }
    if (p->dlpf && cp->n_delay > 0) s->line_pos = (s->line_pos + 1) % cp->n_delay;
}

static void mag_measure(const biso_mpu_params *p, biso_mpu_state *s, const double b_b[3]) {
    double v0 = p->soft[0][0] * b_b[0] + p->soft[0][1] * b_b[1] + p->soft[0][2] * b_b[2] + p->hard[0];
    double v1 = p->soft[1][0] * b_b[0] + p->soft[1][1] * b_b[1] + p->soft[1][2] * b_b[2] + p->hard[1];
    double v2 = p->soft[2][0] * b_b[0] + p->soft[2][1] * b_b[1] + p->soft[2][2] * b_b[2] + p->hard[2];
    double total = 0.0;
    int a, clipped;
    for (a = 0; a < 3; a++) {
        double h = p->r_ak_b[a][0] * v0 + p->r_ak_b[a][1] * v1 + p->r_ak_b[a][2] * v2;
        h += p->mag_offset[a];
        if (p->mag_sigma[a] != 0.0) h += p->mag_sigma[a] * biso_xoshiro_normal(s->rng);
        s->pend_h[a] = h;
        total += fabs(h);
        s->pend_code[a] = round_clip(h * p->mag_counts[a], -p->mag_max_code, p->mag_max_code, &clipped);
    }
    s->pend_hofl = total >= p->mag_overflow ? 1 : 0;
    s->pend = 1;
}

static void mag_commit(biso_mpu_state *s) {
    int a;
    for (a = 0; a < 3; a++) {
        s->mag_h[a] = s->pend_h[a];
        s->mag_code[a] = s->pend_code[a];
    }
    s->mag_hofl = s->pend_hofl;
    s->mag_new += 1;
    s->mag_valid = 1;
    s->pend = 0;
}

static void output(const biso_mpu_params *p, biso_mpu_state *s, long b, biso_mpu_sample *o) {
    int32_t flags = 0;
    int c, a, clipped;
    o->t_s = (double)b / p->f_base;
    for (c = 0; c < 2; c++) {
        const biso_mpu_channel_params *cp = &p->ch[c];
        const biso_mpu_channel_state *cs = &s->ch[c];
        double *out = c == 0 ? o->gyro_b : o->accel_b;
        int col = c == 0 ? 4 : 0, any = cs->sat != 0;
        double code[3], v[3];
        for (a = 0; a < 3; a++) {
            code[a] = round_clip(cs->reg[a] * cp->lsb, -32768.0, 32767.0, &clipped);
            any |= clipped;
            o->words[col + a] = (int16_t)code[a];
        }
        for (a = 0; a < 3; a++) v[a] = p->quantize ? code[a] / cp->lsb : cs->reg[a];
        for (a = 0; a < 3; a++) out[a] = p->r_bc[a][0] * v[0] + p->r_bc[a][1] * v[1] + p->r_bc[a][2] * v[2];
        if (any) flags |= c == 0 ? BISO_FLAG_GYRO_SATURATED : BISO_FLAG_ACCEL_SATURATED;
    }
    {
        double code = round_clip((s->temp_lp - p->temp_offset) * p->temp_lsb, -32768.0, 32767.0, &clipped);
        o->words[3] = (int16_t)code;
        o->temperature_c = p->quantize ? code / p->temp_lsb + p->temp_offset : s->temp_lp;
    }
    {
        int bitm = p->mag_bit16 ? 16 : 0;
        if (s->mag_valid) {
            double v[3];
            int fresh = s->mag_new > 0, overrun = s->mag_new > 1;
            for (a = 0; a < 3; a++) o->words[7 + a] = (int16_t)s->mag_code[a];
            for (a = 0; a < 3; a++) v[a] = p->quantize ? s->mag_code[a] * p->mag_res * p->mag_adj[a] : s->mag_h[a];
            for (a = 0; a < 3; a++)
                o->mag_b[a] = p->r_b_ak[a][0] * v[0] + p->r_b_ak[a][1] * v[1] + p->r_b_ak[a][2] * v[2];
            if (overrun) flags |= BISO_FLAG_MAG_OVERRUN;
            if (s->mag_hofl) flags |= BISO_FLAG_MAG_OVERFLOW;
            o->mag_fresh = (uint8_t)fresh;
            o->st1 = (uint8_t)((fresh ? 1 : 0) | (overrun ? 2 : 0));
            o->st2 = (uint8_t)((s->mag_hofl ? 8 : 0) | bitm);
        } else {
            for (a = 0; a < 3; a++) {
                o->mag_b[a] = NAN;
                o->words[7 + a] = 0;
            }
            flags |= BISO_FLAG_MAG_INVALID;
            o->mag_fresh = 0;
            o->st1 = 0;
            o->st2 = (uint8_t)bitm;
        }
    }
    s->mag_new = 0;
    o->flags = flags;
}

static void advance(long *phase, long divider) {
    long q = *phase + 1;
    *phase = q >= divider ? 0 : q;
}

typedef struct {
    biso_mpu_sample *out;
    int k;
} collect_ctx;

static void collect(void *ctx, const biso_mpu_sample *sample) {
    collect_ctx *c = (collect_ctx *)ctx;
    c->out[c->k++] = *sample;
}

int biso_mpu_input(const biso_mpu_params *p, biso_mpu_state *s, const double row[BISO_N_IN], biso_mpu_sample *out) {
    collect_ctx ctx;
    ctx.out = out;
    ctx.k = 0;
    return biso_mpu_input_each(p, s, row, collect, &ctx);
}

int biso_mpu_input_each(const biso_mpu_params *p, biso_mpu_state *s, const double cur[BISO_N_IN],
                        biso_mpu_sample_function on_sample, void *ctx) {
    biso_mpu_sample sample;
    double x[3], f[3];
    long sub, sub_lo, sub_hi;
    int k = 0, a, c;
    if (s->n_in == 0) {
        /* input 0 makes tick 0; the truth before it is taken as constant (settled chip) */
        for (c = 0; c < BISO_N_IN; c++) s->prev_in[c] = cur[c];
        sub_lo = 0;
        sub_hi = 0;
    } else {
        sub_lo = 1;
        sub_hi = p->up;
    }
    for (sub = sub_lo; sub <= sub_hi; sub++) {
        /* truth at this tick: linear interpolation between the previous and this input */
        double w = (double)sub / (double)p->up;
        long b = s->tick;
        int first = b == 0;
        long *ph = s->phase;
        double temp_now;
        int is_gyro, is_accel;
        if (ph[0] == 0) slow_tick(p, s, first);
        temp_now = (1.0 - w) * s->prev_in[9] + w * cur[9];
        is_gyro = ph[1] == 0;
        is_accel = ph[2] == 0;
        if (is_gyro || is_accel)
            for (a = 0; a < 3; a++) f[a] = (1.0 - w) * s->prev_in[3 + a] + w * cur[3 + a] + s->vib[a];
        if (is_gyro) {
            for (a = 0; a < 3; a++) x[a] = (1.0 - w) * s->prev_in[a] + w * cur[a] + s->vib[3 + a];
            channel_sample(p, 0, s, x, f, temp_now, first);
            /* on-chip temperature sensor, filtered at the gyro internal rate */
            if (first || !p->dlpf)
                s->temp_lp = temp_now;
            else
                s->temp_lp = p->temp_lp_a * s->temp_lp + (1.0 - p->temp_lp_a) * temp_now;
        }
        if (is_accel) channel_sample(p, 1, s, f, f, temp_now, first);
        if (s->pend && b >= s->pend_ready) mag_commit(s);
        if (p->mag_div > 0 && ph[3] == 0) {
            for (a = 0; a < 3; a++) x[a] = (1.0 - w) * s->prev_in[6 + a] + w * cur[6 + a];
            mag_measure(p, s, x);
            mag_commit(s);
        }
        if (ph[4] == 0) {
            output(p, s, b, &sample);
            if (p->mag_trigger_div > 0) {
                /* single mode: the driver writes CNTL1 after reading, every 1 + I2C_MST_DLY
                 * samples; a write during a measurement is ignored */
                if (s->trig_count == 0 && !s->pend) {
                    for (a = 0; a < 3; a++) x[a] = (1.0 - w) * s->prev_in[6 + a] + w * cur[6 + a];
                    mag_measure(p, s, x);
                    s->pend_ready = b + p->mag_meas_ticks;
                }
                s->trig_count = (s->trig_count + 1) % p->mag_trigger_div;
            }
            s->ch[0].sat = 0;
            s->ch[1].sat = 0;
            on_sample(ctx, &sample); /* after the trigger: the sample is complete */
            k++;
        }
        s->tick = b + 1;
        advance(&ph[0], p->slow_div);
        advance(&ph[1], p->ch[0].div);
        advance(&ph[2], p->ch[1].div);
        advance(&ph[3], p->mag_div);
        advance(&ph[4], p->out_div);
    }
    for (c = 0; c < BISO_N_IN; c++) s->prev_in[c] = cur[c];
    s->n_in += 1;
    return k;
}

size_t biso_mpu_params_size(void) { return sizeof(biso_mpu_params); }
size_t biso_mpu_state_size(void) { return sizeof(biso_mpu_state); }
