/* What both native FMUs do with their estimator: its parameters from the variables, the
 * estimate.* outputs, and the quaternion and angle helpers of biso_cosim.frames and
 * fmu/_slave.py (the same arithmetic, for the same numbers). */
#ifndef BISO_FMU_ESTIMATE_H
#define BISO_FMU_ESTIMATE_H

#include "biso_estimators.h"
#include "fmu_core.h"

/* the estimator the String variable "estimator" names (checked by its setter) */
int biso_estimator_kind(biso_instance *inst);
/* the kind's parameter vector from the variables (an optional one NaN unless its has_
 * flag is true); returns how many variables of other estimators differ from their start */
int biso_estimator_params(biso_instance *inst, int kind, double *params);
/* estimate.* from an estimator output; the Euler angles and heading (derived outputs) are
 * marked stale and computed by biso_derive_estimate when a host reads one */
void biso_put_estimate(biso_instance *inst, const biso_est_output *out);
/* estimate.roll, pitch, yaw, heading from estimate.q_wb.* */
void biso_derive_estimate(biso_instance *inst);

/* frames._q_from_euler (intrinsic z-y-x), _qnormalize, _euler_from_q, _qmul */
void biso_q_from_euler(double roll, double pitch, double yaw, double q[4]);
void biso_q_normalize(const double q[4], double out[4]);
void biso_euler_from_q(const double q[4], double *roll, double *pitch, double *yaw);
/* compass heading of an ENU yaw, [0, 2π) (_slave._heading) */
double biso_heading(double yaw);
/* Python's float a % b (the sign of b) */
double biso_py_mod(double a, double b);

#endif
