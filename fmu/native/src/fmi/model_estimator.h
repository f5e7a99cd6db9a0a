/* BisoEstimator: one attitude estimator of biso_cosim (the estimators' C library). */
#ifndef BISO_MODEL_ESTIMATOR_H
#define BISO_MODEL_ESTIMATOR_H

#include "biso_estimators.h"

typedef struct {
    biso_est est;
    int kind;
    int mounted;         /* a rotation sensor -> body is applied to the inputs */
    double r_bs[3][3];
    int use_speed;
} biso_model;

#endif
