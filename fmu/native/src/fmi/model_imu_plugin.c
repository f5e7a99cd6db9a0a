/* BisoImuPlugin's model, as the Python plug-in (fmu/imu_plugin.py) defines it.
 *
 * The truth given at communication point t_k (angular rate, specific force, attitude;
 * position, velocity, temperature) is the sensor's input sample k, so the truth rate is
 * 1/h for a step size h; the first step fixes h (1/h must be an integer multiple or
 * fraction of the chip's internal rates) and later steps keep it. Between communication
 * points the chip interpolates the truth linearly. The Earth field (WMM at the site and
 * date) is rotated into body axes with the given attitude. The outputs after the step from
 * t_k are those of the samples the chip latched at t <= t_k (new_samples of them; none:
 * outputs held); every sample goes to the estimator, and the error is the estimate's
 * against the truth attitude interpolated (nlerp) to the sample's time stamp. This is the model
 * of biso_cosim.plugin.ImuPlugin (ENU world, FLU body, scalar-first quaternions): the same
 * lever arm (sensor.position_b), the sensor's flags given to the estimator, a unit
 * quaternion required (|q| = 1 ± 1e-5), bit for bit. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "biso_field.h"
#include "fmu_core.h"
#include "fmu_estimate.h"

void model_start(biso_instance *inst) {
    biso_est_output out;
    memset(&out, 0, sizeof out);
    out.q_wb[0] = 1.0;
    out.flags = BISO_EST_FLAG_UNINITIALIZED;
    biso_put_estimate(inst, &out);
}

int model_check_real(biso_instance *inst, const biso_var_info *v, double value, char *msg, size_t len) {
    (void)inst;
    (void)v;
    (void)value;
    (void)msg;
    (void)len;
    return 0; /* the site's bounds are the variables' min/max */
}

int model_check_string(biso_instance *inst, const biso_var_info *v, const char *value, char *msg, size_t len) {
    (void)inst;
    if (strcmp(v->name, "sensor.profile") == 0 && biso_profile_index(value) < 0) {
        int i, n = snprintf(msg, len, "must be a profile built into this FMU: ");
        for (i = 0; i < biso_n_profiles && n > 0 && (size_t)n < len; i++)
            n += snprintf(msg + n, len - n, "%s%s", i ? ", " : "", biso_profiles[i].name);
        if (n > 0 && (size_t)n < len)
            snprintf(msg + n, len - n, ", got '%s' (a profile file is built in with biso-cosim fmu build --profile "
                     "FILE)", value);
        return 1;
    }
    if (strcmp(v->name, "site.date") == 0) {
        double year;
        return biso_decimal_year(value, &year, msg, len);
    }
    return 0;
}

static void read_registers(biso_instance *inst, int *registers) {
    int i;
    for (i = 0; i < BISO_N_VARS; i++) {
        const biso_var_info *v = &biso_vars[i];
        if (v->role != BISO_ROLE_REGISTER) continue;
        registers[v->register_field] = v->type == BISO_BOOLEAN ? inst->core.boolean[v->slot]
                                                               : inst->core.integer[v->slot];
    }
}

int model_configure(biso_instance *inst, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    const double *r = inst->core.real;
    const int32_t *b = inst->core.boolean;
    biso_mpu_config *cfg = &m->config;
    biso_earth_field field;
    double year, params[BISO_EST_MAX_PARAMS];
    biso_est_output out;
    int i, j, others;

    memset(m, 0, sizeof *m);
    if (biso_decimal_year(inst->core.string[S_SITE_DATE], &year, msg, len)) return 1;
    if (biso_earth_field_at(r[R_SITE_LAT_DEG], r[R_SITE_LON_DEG], r[R_SITE_ALT_M], year, &field, msg, len)) return 1;
    memcpy(m->field_enu_ut, field.field_enu_ut, sizeof m->field_enu_ut);

    cfg->profile = biso_profile_index(inst->core.string[S_SENSOR_PROFILE]);
    cfg->seed = (uint64_t)inst->core.integer[I_SENSOR_SEED];
    read_registers(inst, cfg->registers);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            cfg->r_bc[i][j] = i == j ? 1.0 : 0.0;
            cfg->soft_iron[i][j] = i == j ? 1.0 : 0.0;
        }
    if (r[R_SENSOR_MOUNTING_ROLL] != 0.0 || r[R_SENSOR_MOUNTING_PITCH] != 0.0 || r[R_SENSOR_MOUNTING_YAW] != 0.0) {
        double q[4], r_bc[3][3];
        biso_q_from_euler(r[R_SENSOR_MOUNTING_ROLL], r[R_SENSOR_MOUNTING_PITCH], r[R_SENSOR_MOUNTING_YAW], q);
        biso_mounting_matrix(q, r_bc);
        memcpy(cfg->r_bc, r_bc, sizeof r_bc);
    }
    /* the chip at 1 kHz checks profile, seed and registers and gives the output rate; the
     * first step sets the truth rate */
    cfg->input_rate_hz = 1000.0;
    if (biso_mpu_setup(&m->sensor, cfg, msg, len)) return 1;
    m->output_rate_hz = biso_mpu_output_rate_hz(&m->sensor);

    m->kind = biso_estimator_kind(inst);
    others = biso_estimator_params(inst, m->kind, params);
    if (b[B_DECLINATION_FROM_SITE]) {
        int index = biso_est_param_find(m->kind, "declination_rad");
        if (index >= 0) params[index] = field.declination_rad;
    }
    if (biso_est_init(&m->est, m->kind, m->output_rate_hz, params, msg, len) != 0) return 1;
    if (others)
        biso_log(inst, BISO_WARNING, "%d parameter(s) of estimators other than %s were set: ignored", others,
                 biso_est_kind_name(m->kind));
    m->use_speed = b[B_USE_VELOCITY];
    if (m->use_speed && !(biso_est_inputs(m->kind) & BISO_EST_INPUT_SPEED_MPS)) {
        snprintf(msg, len, "use_velocity: estimator '%s' takes no speed input (only biso_plus does)",
                 biso_est_kind_name(m->kind));
        return 1;
    }
    m->use_temperature = b[B_USE_TEMPERATURE];
    m->feed_flags = (biso_est_inputs(m->kind) & BISO_EST_INPUT_IMU_FLAGS) != 0;
    m->position_b[0] = r[R_SENSOR_POSITION_B_X];
    m->position_b[1] = r[R_SENSOR_POSITION_B_Y];
    m->position_b[2] = r[R_SENSOR_POSITION_B_Z];
    m->lever = m->position_b[0] != 0.0 || m->position_b[1] != 0.0 || m->position_b[2] != 0.0;
    m->start_time = inst->core.time;
    biso_est_peek(&m->est, &out);
    biso_put_estimate(inst, &out);
    biso_log(inst, BISO_OK, "%s: %s profile, seed %d, ODR %g Hz, field %s (%.3f, %.3f, %.3f) uT, estimator %s",
             BISO_FMU_NAME, inst->core.string[S_SENSOR_PROFILE], (int)cfg->seed, m->output_rate_hz, field.model,
             field.field_enu_ut[0], field.field_enu_ut[1], field.field_enu_ut[2], biso_est_kind_name(m->kind));
    return 0;
}

int model_apply_tunables(biso_instance *inst, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    double params[BISO_EST_MAX_PARAMS], declination[1];
    int index = biso_est_param_find(m->kind, "declination_rad");
    if (biso_estimator_params(inst, m->kind, params))
        biso_log(inst, BISO_WARNING, "parameters of estimators other than %s: ignored", biso_est_kind_name(m->kind));
    if (inst->core.boolean[B_DECLINATION_FROM_SITE] && index >= 0) {
        declination[0] = m->est.params[index]; /* the site's, set at initialization */
        params[index] = declination[0];
    }
    return biso_est_set_params(&m->est, params, msg, len) != 0;
}

/* ---- one step --------------------------------------------------------------------------- */

typedef struct {
    biso_instance *inst;
    double t_in, h, q[4], vel[3];
    int k;
    biso_mpu_sample last;
    double q_true[4];
    biso_est_output out;
} step_ctx;

/* attitude between q0 and q1 on the shorter arc at frac (imu_plugin._nlerp) */
static void nlerp(const double q0[4], const double q1_in[4], double frac, double out[4]) {
    double q1[4], q[4], dot = q0[0] * q1_in[0] + q0[1] * q1_in[1] + q0[2] * q1_in[2] + q0[3] * q1_in[3];
    double n;
    int i;
    for (i = 0; i < 4; i++) q1[i] = dot >= 0.0 ? q1_in[i] : -q1_in[i];
    for (i = 0; i < 4; i++) q[i] = (1.0 - frac) * q0[i] + frac * q1[i];
    n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (i = 0; i < 4; i++) out[i] = q[i] / n;
}

static void on_sample(void *ctx_, const biso_mpu_sample *s) {
    step_ctx *ctx = (step_ctx *)ctx_;
    biso_model *m = &ctx->inst->core.model;
    biso_est_input in;
    double frac = (s->t_s - ctx->t_in) / ctx->h + 1.0;
    frac = frac < 0.0 ? 0.0 : (frac > 1.0 ? 1.0 : frac);
    nlerp(m->prev_q, ctx->q, frac, ctx->q_true);
    memcpy(in.gyro_b, s->gyro_b, sizeof in.gyro_b);
    memcpy(in.accel_b, s->accel_b, sizeof in.accel_b);
    memcpy(in.mag_b, s->mag_b, sizeof in.mag_b);
    in.speed_mps = NAN;
    in.has_velocity = 0;
    in.velocity_enu_mps[0] = in.velocity_enu_mps[1] = in.velocity_enu_mps[2] = 0.0;
    in.imu_flags = m->feed_flags ? s->flags : 0; /* the sensor's flags, as ImuPlugin gives them */
    if (m->use_speed) {
        double v_w[3], v_b[3];
        int i;
        for (i = 0; i < 3; i++) v_w[i] = (1.0 - frac) * m->prev_vel[i] + frac * ctx->vel[i];
        biso_rotate_into_body(ctx->q_true, v_w, v_b);
        in.speed_mps = v_b[0];
    }
    biso_est_update(&m->est, &in, &ctx->out);
    ctx->last = *s;
    ctx->k++;
}

static int first_step(biso_instance *inst, double h, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    biso_mpu_config cfg = m->config;
    biso_mpu_params chip;
    char why[BISO_MSG];
    cfg.input_rate_hz = 1.0 / h;
    if (biso_mpu_setup(&chip, &cfg, why, sizeof why)) {
        /* the steps this chip can take: truth rates that are whole multiples or fractions of its rates */
        static const double candidates[] = {0.001, 0.002, 0.005, 0.01, 0.02, 0.0005, 0.00025, 0.000125, 0.05, 0.1};
        biso_mpu_params probe;
        char unused[BISO_MSG];
        int n = snprintf(msg, len, "the first step size h = %.17g s sets the truth rate 1/h = %.17g Hz: %s; allowed "
                         "steps: 1/h an integer multiple or fraction of the internal rates, e.g.", h, 1.0 / h, why);
        size_t i;
        for (i = 0; i < sizeof candidates / sizeof candidates[0] && n > 0 && (size_t)n < len; i++) {
            cfg.input_rate_hz = 1.0 / candidates[i];
            if (biso_mpu_setup(&probe, &cfg, unused, sizeof unused) == 0)
                n += snprintf(msg + n, len - n, " %g", candidates[i]);
        }
        if (n > 0 && (size_t)n < len) snprintf(msg + n, len - n, " s");
        return 1;
    }
    if (biso_mpu_output_rate_hz(&chip) != m->output_rate_hz) {
        snprintf(msg, len, "the step size h = %.17g s changes the output rate (%.17g Hz instead of %.17g Hz): use a "
                 "step whose truth rate divides exactly", h, biso_mpu_output_rate_hz(&chip), m->output_rate_hz);
        return 1;
    }
    m->sensor = chip;
    m->config = cfg;
    m->step_size = h;
    biso_mpu_reset(&m->sensor, &m->sensor_state);
    return 0;
}

static const char *truth_names[] = {"omega_b.x", "omega_b.y", "omega_b.z", "specific_force_b.x",
                                    "specific_force_b.y", "specific_force_b.z", "q_wb.w", "q_wb.x", "q_wb.y", "q_wb.z",
                                    "pos_w.x", "pos_w.y", "pos_w.z", "vel_w.x", "vel_w.y", "vel_w.z", "temperature"};

void model_derive_outputs(biso_instance *inst) { biso_derive_estimate(inst); }

int model_step(biso_instance *inst, double t, double h, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    double *r = inst->core.real;
    double truth[17], row[BISO_N_IN], norm;
    step_ctx ctx;
    int i, n;
    (void)t;
    truth[0] = r[R_OMEGA_B_X], truth[1] = r[R_OMEGA_B_Y], truth[2] = r[R_OMEGA_B_Z];
    truth[3] = r[R_SPECIFIC_FORCE_B_X], truth[4] = r[R_SPECIFIC_FORCE_B_Y], truth[5] = r[R_SPECIFIC_FORCE_B_Z];
    truth[6] = r[R_Q_WB_W], truth[7] = r[R_Q_WB_X], truth[8] = r[R_Q_WB_Y], truth[9] = r[R_Q_WB_Z];
    truth[10] = r[R_POS_W_X], truth[11] = r[R_POS_W_Y], truth[12] = r[R_POS_W_Z];
    truth[13] = r[R_VEL_W_X], truth[14] = r[R_VEL_W_Y], truth[15] = r[R_VEL_W_Z];
    truth[16] = r[R_TEMPERATURE];
    for (i = 0, n = 0; i < 17; i++)
        if (!isfinite(truth[i])) {
            if (!n) n = snprintf(msg, len, "input(s) not finite:");
            if (n > 0 && (size_t)n < len) n += snprintf(msg + n, len - n, " %s = %g", truth_names[i], truth[i]);
        }
    if (n) return BISO_ERROR;
    if (m->step_size == 0.0) {
        if (first_step(inst, h, msg, len)) return BISO_ERROR;
    } else if (fabs(h - m->step_size) > 1e-9 * m->step_size) {
        snprintf(msg, len, "the step size must stay %.17g s (the first step set the truth rate of the sensor), got "
                 "%.17g s", m->step_size, h);
        return BISO_ERROR;
    }
    norm = sqrt(truth[6] * truth[6] + truth[7] * truth[7] + truth[8] * truth[8] + truth[9] * truth[9]);
    if (fabs(norm - 1.0) > 1e-5) {
        snprintf(msg, len, "q_wb must be a unit quaternion (|q| = 1 +- 1e-05), got (%g, %g, %g, %g), |q| = %.17g",
                 truth[6], truth[7], truth[8], truth[9], norm);
        return BISO_ERROR;
    }
    memset(&ctx, 0, sizeof ctx);
    ctx.inst = inst;
    ctx.h = h;
    for (i = 0; i < 4; i++) ctx.q[i] = truth[6 + i] / norm;
    for (i = 0; i < 3; i++) ctx.vel[i] = truth[13 + i];
    for (i = 0; i < 6; i++) row[i] = truth[i];
    if (m->lever) {
        /* rigid body: the chip at r feels f + ω̇ × r + ω × (ω × r) (plugin/_kernels.prepare); ω̇
         * is the slope of the rate the chip interpolates between steps (0 at the first) */
        const double *w = truth, *rb = m->position_b;
        double al[3], c[3], cc[3], t3[3];
        for (i = 0; i < 3; i++) al[i] = m->have_prev ? (w[i] - m->prev_omega[i]) / h : 0.0;
        c[0] = w[1] * rb[2] - w[2] * rb[1], c[1] = w[2] * rb[0] - w[0] * rb[2], c[2] = w[0] * rb[1] - w[1] * rb[0];
        cc[0] = w[1] * c[2] - w[2] * c[1], cc[1] = w[2] * c[0] - w[0] * c[2], cc[2] = w[0] * c[1] - w[1] * c[0];
        t3[0] = al[1] * rb[2] - al[2] * rb[1], t3[1] = al[2] * rb[0] - al[0] * rb[2];
        t3[2] = al[0] * rb[1] - al[1] * rb[0];
        for (i = 0; i < 3; i++) row[3 + i] = truth[3 + i] + cc[i] + t3[i];
        /* the chip's position p + q ∘ r ∘ q* matters only for local disturbances, which the FMU
         * does not carry: the Earth field is the same everywhere */
    }
    biso_rotate_into_body(ctx.q, m->field_enu_ut, row + 6);
    row[9] = m->use_temperature ? truth[16] : m->sensor.temp_default;
    ctx.t_in = biso_mpu_time_s(&m->sensor, &m->sensor_state);
    if (!m->have_prev) { /* the chip starts settled: the truth before the first row is this row */
        memcpy(m->prev_q, ctx.q, sizeof m->prev_q);
        memcpy(m->prev_vel, ctx.vel, sizeof m->prev_vel);
        m->have_prev = 1;
    }
    biso_mpu_input_each(&m->sensor, &m->sensor_state, row, on_sample, &ctx);
    memcpy(m->prev_q, ctx.q, sizeof m->prev_q);
    memcpy(m->prev_vel, ctx.vel, sizeof m->prev_vel);
    memcpy(m->prev_omega, truth, sizeof m->prev_omega);

    inst->core.integer[I_NEW_SAMPLES] = ctx.k;
    if (ctx.k == 0) return BISO_OK;
    {
        const biso_mpu_sample *s = &ctx.last;
        int32_t *iv = inst->core.integer;
        int invalid = (s->flags & BISO_FLAG_MAG_INVALID) != 0;
        r[R_SAMPLE_TIME] = m->start_time + s->t_s;
        r[R_GYRO_B_X] = s->gyro_b[0], r[R_GYRO_B_Y] = s->gyro_b[1], r[R_GYRO_B_Z] = s->gyro_b[2];
        r[R_ACCEL_B_X] = s->accel_b[0], r[R_ACCEL_B_Y] = s->accel_b[1], r[R_ACCEL_B_Z] = s->accel_b[2];
        /* no AK8963 sample (powered down): the documented sentinel 0, never NaN out */
        r[R_MAG_B_X] = invalid ? 0.0 : s->mag_b[0];
        r[R_MAG_B_Y] = invalid ? 0.0 : s->mag_b[1];
        r[R_MAG_B_Z] = invalid ? 0.0 : s->mag_b[2];
        r[R_TEMPERATURE_C] = s->temperature_c;
        inst->core.boolean[B_MAG_FRESH] = s->mag_fresh != 0;
        iv[I_IMU_FLAGS] = s->flags;
        iv[I_RAW_ACCEL_X] = s->words[0], iv[I_RAW_ACCEL_Y] = s->words[1], iv[I_RAW_ACCEL_Z] = s->words[2];
        iv[I_RAW_TEMP] = s->words[3];
        iv[I_RAW_GYRO_X] = s->words[4], iv[I_RAW_GYRO_Y] = s->words[5], iv[I_RAW_GYRO_Z] = s->words[6];
        iv[I_RAW_MAG_X] = s->words[7], iv[I_RAW_MAG_Y] = s->words[8], iv[I_RAW_MAG_Z] = s->words[9];
        iv[I_RAW_ST1] = s->st1;
        iv[I_RAW_ST2] = s->st2;
    }
    biso_put_estimate(inst, &ctx.out);
    {
        /* error.*: estimate minus truth (metrics.angle_errors_deg, in rad; _slave.put_errors) */
        double e[4], tq[4], ae[3], at[3], d[4], diff[3];
        const double pi = 3.141592653589793;
        biso_q_normalize(ctx.out.q_wb, e);
        biso_q_normalize(ctx.q_true, tq);
        biso_euler_from_q(e, &ae[0], &ae[1], &ae[2]);
        biso_euler_from_q(tq, &at[0], &at[1], &at[2]);
        diff[0] = ae[0] - at[0];
        diff[1] = ae[1] - at[1];
        diff[2] = biso_heading(ae[2]) - biso_heading(at[2]);
        /* d = e* ∘ t */
        d[0] = e[0] * tq[0] - (-e[1]) * tq[1] - (-e[2]) * tq[2] - (-e[3]) * tq[3];
        d[1] = e[0] * tq[1] + (-e[1]) * tq[0] + (-e[2]) * tq[3] - (-e[3]) * tq[2];
        d[2] = e[0] * tq[2] - (-e[1]) * tq[3] + (-e[2]) * tq[0] + (-e[3]) * tq[1];
        d[3] = e[0] * tq[3] + (-e[1]) * tq[2] - (-e[2]) * tq[1] + (-e[3]) * tq[0];
        r[R_ERROR_ROLL] = pi - biso_py_mod(pi - diff[0], 2.0 * pi);
        r[R_ERROR_PITCH] = pi - biso_py_mod(pi - diff[1], 2.0 * pi);
        r[R_ERROR_HEADING] = pi - biso_py_mod(pi - diff[2], 2.0 * pi);
        r[R_ERROR_TOTAL] = 2.0 * atan2(sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3]), fabs(d[0]));
    }
    return BISO_OK;
}
