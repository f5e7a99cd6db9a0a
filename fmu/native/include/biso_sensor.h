/* The virtual MPU-9250 with its AK8963, in C99: the twin of biso_cosim.sensors.MPU9250
 * (mpu9250.py, _kernels.py), for the native FMUs.
 *
 * Same model, same numbers: the same register set-up, internal rates and decimation, error
 * terms, DLPF, quantization and saturation flags, AK8963 modes, rate, axes and ASA, and the
 * same random draws for a seed (the turn-on errors through NumPy's default_rng, the noise
 * through xoshiro256++), in the same order and with the same arithmetic. Not here: the
 * multiple-integral increments and the mount vibration (Python-only outputs and options).
 *
 * Parameters (biso_mpu_params) are set once by biso_mpu_setup; the dynamic state
 * (biso_mpu_state) is plain data: copying it is a whole-state save, restoring it a restore.
 */
#ifndef BISO_SENSOR_H
#define BISO_SENSOR_H

#include <stddef.h>
#include <stdint.h>

#include "biso_sensor_data.h"

/* register fields, in the order of sensors.Registers */
enum {
    BISO_REG_SMPLRT_DIV, BISO_REG_DLPF_CFG, BISO_REG_GYRO_FCHOICE_B, BISO_REG_GYRO_FS_SEL, BISO_REG_ACCEL_FS_SEL,
    BISO_REG_A_DLPF_CFG, BISO_REG_ACCEL_FCHOICE_B, BISO_REG_MAG_MODE, BISO_REG_MAG_BIT16, BISO_REG_I2C_MST_DLY
};

/* output flag bits (biso_cosim.sensors.ImuFlag) */
#define BISO_FLAG_GYRO_SATURATED 1
#define BISO_FLAG_ACCEL_SATURATED 2
#define BISO_FLAG_MAG_OVERFLOW 4
#define BISO_FLAG_MAG_OVERRUN 8
#define BISO_FLAG_MAG_INVALID 16

#define BISO_N_IN 10 /* input row: omega_b (3), specific_force_b (3), mag_b (3), temperature */

typedef struct {
    int profile;                /* index into biso_profiles */
    uint64_t seed;              /* the Python model's seed (>= 0) */
    int registers[BISO_N_REGISTERS];
    double r_bc[3][3];          /* mounting, chip -> body */
    double input_rate_hz;
    double hard_iron_ut[3];     /* body axes */
    double soft_iron[3][3];     /* body axes */
} biso_mpu_config;

typedef struct {
    double sens[3][3], sf_tc[3], bias[3], bias_tc[3], nl[3], gsens[3][3], sigma[3];
    double gm_phi[BISO_N_GM], gm_drive[BISO_N_GM][3], gm_sigma[BISO_N_GM][3], rw_drive[3];
    double full_scale, lsb, lp_a, ap_d;
    long n_delay, div;
} biso_mpu_channel_params;

typedef struct {
    biso_mpu_channel_params ch[2]; /* 0 gyro, 1 accelerometer */
    double r_cb[3][3], r_bc[3][3];
    long up, out_div, slow_div, n_gm, dlpf, quantize;
    double f_base, input_rate_hz, t_ref, temp_lp_a, temp_lsb, temp_offset, temp_default;
    long mag_div, mag_trigger_div, mag_meas_ticks, mag_bit16;
    double soft[3][3], hard[3], r_ak_b[3][3], r_b_ak[3][3];
    double mag_counts[3], mag_adj[3], mag_offset[3], mag_sigma[3], mag_res, mag_max_code, mag_overflow;
    uint8_t asa[3];                /* the part's fuse-ROM ASA bytes */
    uint64_t rng_seed_words[4];    /* the noise stream's state at time 0 */
} biso_mpu_params;

typedef struct {
    double lp[3], ap_x[3], ap_y[3], line[BISO_N_LINE][3];
    long line_pos;
    double gm[BISO_N_GM][3], rw[3], slow[3], reg[3];
    long sat;
} biso_mpu_channel_state;

typedef struct {
    biso_mpu_channel_state ch[2];
    uint64_t rng[4];
    long tick, phase[5], n_in;
    double prev_in[BISO_N_IN], temp_lp;
    double mag_h[3], mag_code[3];
    long mag_new, mag_hofl, mag_valid, pend, pend_ready;
    double pend_h[3], pend_code[3];
    long pend_hofl, trig_count;
    double vib[6]; /* mount vibration (none in C: zeros, kept so that the arithmetic is the Python's) */
} biso_mpu_state;

typedef struct {
    double t_s;          /* latch time on the input time axis */
    double gyro_b[3], accel_b[3], mag_b[3]; /* SI, body axes; mag_b NaN while powered down */
    double temperature_c;
    int32_t flags;       /* BISO_FLAG_* */
    int16_t words[10];   /* ACCEL_X..Z, TEMP, GYRO_X..Z, HX, HY, HZ */
    uint8_t mag_fresh, st1, st2;
} biso_mpu_sample;

/* Index of a built-in profile by name, or -1. */
int biso_profile_index(const char *name);
/* Checks a register field value; 0 when allowed, else writes a message naming the field
 * and the allowed values. */
int biso_register_check(int field, int value, char *msg, size_t len);
/* Rotation matrix chip -> body of a quaternion q_body_chip (normalised as mounting_matrix does). */
void biso_mounting_matrix(const double q[4], double r_bc[3][3]);

/* Sets up the parameters (draws the part's errors); 0 on success, else a message. */
int biso_mpu_setup(biso_mpu_params *p, const biso_mpu_config *cfg, char *msg, size_t len);
/* The state at time 0 (the same part and noise stream start again). */
void biso_mpu_reset(const biso_mpu_params *p, biso_mpu_state *s);
/* Most output samples one input row can complete. */
int biso_mpu_max_outputs(const biso_mpu_params *p);
double biso_mpu_output_rate_hz(const biso_mpu_params *p);
/* Time of the next input sample the stream expects. */
double biso_mpu_time_s(const biso_mpu_params *p, const biso_mpu_state *s);
/* One input row (finite values: the caller checks); writes the outputs it completes into
 * out (room for biso_mpu_max_outputs) and returns their number. */
int biso_mpu_input(const biso_mpu_params *p, biso_mpu_state *s, const double row[BISO_N_IN], biso_mpu_sample *out);
/* The same, handing each completed sample to on_sample(ctx, sample) in time order. */
typedef void (*biso_mpu_sample_function)(void *ctx, const biso_mpu_sample *sample);
int biso_mpu_input_each(const biso_mpu_params *p, biso_mpu_state *s, const double row[BISO_N_IN],
                        biso_mpu_sample_function on_sample, void *ctx);
/* sizeof the records, for hosts that allocate them (ctypes, the tests) */
size_t biso_mpu_params_size(void);
size_t biso_mpu_state_size(void);

#endif
