/* The constants of the virtual MPU-9250, written by the FMU build from the Python package's
 * own data (biso_cosim.fmu.native.constants): chip tables (sensors/data/mpu9250.toml), the
 * DLPF designs of every table row (sensors/dlpf.py), the built-in profiles in SI
 * (the TOML files of sensors/profiles through sensors/profile.py), the register fields' allowed values
 * (sensors/registers.py), both ziggurat tables (sensors/_rng.py, NumPy's) and the WMM
 * coefficients pygeomag uses (sensors/magnetic.py). This header declares them; the build
 * generates biso_sensor_data.c. */
#ifndef BISO_SENSOR_DATA_H
#define BISO_SENSOR_DATA_H

#include <stdint.h>

#define BISO_N_GM 16  /* Gauss-Markov terms per axis, upper bound (sensors/_kernels.py N_GM) */
#define BISO_N_LINE 8 /* longest whole-sample DLPF delay line (N_LINE) */
#define BISO_N_GYRO_ROWS 10  /* DLPF_CFG 0..7, FCHOICE_B x1, FCHOICE_B 10 */
#define BISO_N_ACCEL_ROWS 9  /* A_DLPF_CFG 0..7, ACCEL_FCHOICE_B 1 */
#define BISO_N_REGISTERS 10
#define BISO_WMM_N 12 /* WMM degree and order */

typedef struct {
    double bandwidth_hz, delay_s, rate_hz;
    double lowpass_a, allpass_d;
    int delay_samples;
    double temp_bandwidth_hz, temp_lowpass_a; /* gyro rows: the temperature sensor's filter */
} biso_dlpf_row;

typedef struct {
    biso_dlpf_row gyro[BISO_N_GYRO_ROWS];
    biso_dlpf_row accel[BISO_N_ACCEL_ROWS];
    double gyro_full_scale[4], gyro_lsb_per_unit[4];   /* rad/s, LSB per rad/s (GYRO_FS_SEL) */
    double accel_full_scale[4], accel_lsb_per_unit[4]; /* m/s², LSB per m/s² (ACCEL_FS_SEL) */
    double temp_lsb_per_c, temp_offset_c;
    double dlpf_internal_rate_hz;
    int mode_power_down, mode_single, mode_continuous_1, mode_continuous_2;
    double continuous_1_rate_hz, continuous_2_rate_hz, single_measurement_time_ms;
    double resolution_14bit_ut, resolution_16bit_ut, max_code_14bit, max_code_16bit, overflow_sum_ut;
    double ak8963_from_chip[3][3];
    double slow_rate_hz; /* bias-process update rate (mpu9250.py SLOW_RATE_HZ) */
} biso_chip_tables;

typedef struct {
    double scale_factor[3], cross_axis, scale_factor_tempco[3], bias_initial[3], bias_tempco[3];
    double nonlinearity[3], g_sensitivity, noise_density[3], random_walk[3];
    int n_gm;                                      /* flicker terms (profile.flicker_terms) */
    double gm_tau[BISO_N_GM], gm_sigma[BISO_N_GM][3];
} biso_inertial_profile;

typedef struct {
    const char *name, *description;
    biso_inertial_profile gyro, accel;
    double mag_noise[3], mag_offset[3], mag_asa_range[2];
    double temperature_default, temperature_reference;
    int dlpf, quantization;
} biso_profile;

typedef struct {
    const char *name;
    int n_allowed;
    const int *allowed; /* the values sensors.Registers accepts, ascending */
    int default_value;
} biso_register_field;

typedef struct {
    const char *model, *release_date;
    double epoch;
    int n;                    /* coefficient records */
    const double (*gh)[6];    /* n, m, g, h, dg, dh as pygeomag reads them */
} biso_wmm_release;

extern const biso_chip_tables biso_chip;
extern const biso_profile biso_profiles[];
extern const int biso_n_profiles;
extern const biso_register_field biso_registers[BISO_N_REGISTERS];
extern const double biso_zig_x[129], biso_zig_ratio[128], biso_zig_r;
extern const uint64_t biso_np_ki[256];
extern const double biso_np_wi[256], biso_np_fi[256], biso_np_zig_r, biso_np_zig_inv_r;
extern const biso_wmm_release biso_wmm_releases[];
extern const int biso_n_wmm_releases;
extern const int biso_wmm_first_year, biso_wmm_last_year; /* base years covered, inclusive */
extern const int biso_wmm_release_of_year[];              /* base year - first year -> release */

#endif
