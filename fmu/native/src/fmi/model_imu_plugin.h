/* BisoImuPlugin: the virtual MPU-9250 and an estimator, driven by another simulator's truth. */
#ifndef BISO_MODEL_IMU_PLUGIN_H
#define BISO_MODEL_IMU_PLUGIN_H

#include "biso_estimators.h"
#include "biso_sensor.h"

typedef struct {
    biso_mpu_config config;     /* the chip as the parameters give it (input rate set by the first step) */
    biso_mpu_params sensor;
    biso_mpu_state sensor_state;
    biso_est est;
    int kind;
    double field_enu_ut[3];     /* the WMM field at the site and date */
    double start_time;
    double step_size;           /* 0 until the first step fixes the truth rate */
    double output_rate_hz;
    int have_prev;
    double prev_q[4], prev_vel[3], prev_omega[3];
    int use_speed, use_temperature, feed_flags;
    int lever;                  /* the chip is away from the point whose motion is given */
    double position_b[3];
} biso_model;

#endif
