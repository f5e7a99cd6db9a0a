/* The per-sample pieces every estimator shares, ported operation by operation from
 * biso_cosim/estimators/_kernels.py, reference.py and biso_cosim/frames.py (the same
 * expressions in the same order: the same numbers). Static inline: each update
 * compiles to one function body, as numba's inline="always" does. */
#ifndef BISO_EST_KERNELS_H
#define BISO_EST_KERNELS_H

#include <math.h>
#include <stdint.h>

#include "biso_estimators_gen.h"

typedef struct { double w, x, y, z; } bq;   /* quaternion (w, x, y, z) */
typedef struct { double x, y, z; } bv;      /* 3-vector */
typedef struct { double r[9]; } bm;         /* 3x3 matrix, row-major */

static inline bq bq_make(double w, double x, double y, double z) { bq q; q.w = w; q.x = x; q.y = y; q.z = z; return q; }
static inline bv bv_make(double x, double y, double z) { bv v; v.x = x; v.y = y; v.z = z; return v; }

/* Python's min(a, b) and max(a, b) (numba's builtins): the second argument when it
 * compares smaller (larger), else the first; NaN in the first argument stays. */
static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }

/* ---- frames.py ---------------------------------------------------------------------- */

/* Hamilton product a o b (_qmul) */
static inline bq bq_mul(double aw, double ax, double ay, double az, double bw, double bx, double by, double bz) {
    return bq_make(aw * bw - ax * bx - ay * by - az * bz,
                   aw * bx + ax * bw + ay * bz - az * by,
                   aw * by - ax * bz + ay * bw + az * bx,
                   aw * bz + ax * by - ay * bx + az * bw);
}

/* q o v o q* (_qrot) */
static inline bv bq_rot(double qw, double qx, double qy, double qz, double vx, double vy, double vz) {
    double tx = 2.0 * (qy * vz - qz * vy);
    double ty = 2.0 * (qz * vx - qx * vz);
    double tz = 2.0 * (qx * vy - qy * vx);
    return bv_make(vx + qw * tx + (qy * tz - qz * ty),
                   vy + qw * ty + (qz * tx - qx * tz),
                   vz + qw * tz + (qx * ty - qy * tx));
}

/* q* o v o q (_qrot_inv) */
static inline bv bq_rot_inv(double qw, double qx, double qy, double qz, double vx, double vy, double vz) {
    return bq_rot(qw, -qx, -qy, -qz, vx, vy, vz);
}

/* q/|q| (_qnormalize) */
static inline bq bq_normalize(double w, double x, double y, double z) {
    double n = sqrt(w * w + x * x + y * y + z * z);
    return bq_make(w / n, x / n, y / n, z / n);
}

/* unit quaternion of the rotation vector r (_qexp_rotvec) */
static inline bq bq_exp_rotvec(double rx, double ry, double rz) {
    double angle = sqrt(rx * rx + ry * ry + rz * rz);
    double half = 0.5 * angle;
    double s, c;
    if (angle < 1e-4) {
        double h2 = half * half;
        s = 0.5 * (1.0 - h2 / 6.0 + h2 * h2 / 120.0);
        c = 1.0 - 0.5 * h2 + h2 * h2 / 24.0;
    } else {
        s = sin(half) / angle;
        c = cos(half);
    }
    return bq_make(c, s * rx, s * ry, s * rz);
}

/* rotation matrix of a unit quaternion, row-major (_mat_from_q) */
static inline bm bm_from_q(double w, double x, double y, double z) {
    bm m;
    m.r[0] = 1.0 - 2.0 * (y * y + z * z); m.r[1] = 2.0 * (x * y - w * z); m.r[2] = 2.0 * (x * z + w * y);
    m.r[3] = 2.0 * (x * y + w * z); m.r[4] = 1.0 - 2.0 * (x * x + z * z); m.r[5] = 2.0 * (y * z - w * x);
    m.r[6] = 2.0 * (x * z - w * y); m.r[7] = 2.0 * (y * z + w * x); m.r[8] = 1.0 - 2.0 * (x * x + y * y);
    return m;
}

/* unit quaternion (w >= 0) of a rotation matrix, Shepperd's method (_q_from_mat) */
static inline bq bq_from_mat(double r00, double r01, double r02, double r10, double r11, double r12,
                             double r20, double r21, double r22) {
    double trace = r00 + r11 + r22, s, w, x, y, z;
    if (trace >= r00 && trace >= r11 && trace >= r22) {
        s = 2.0 * sqrt(1.0 + trace);
        w = 0.25 * s; x = (r21 - r12) / s; y = (r02 - r20) / s; z = (r10 - r01) / s;
    } else if (r00 >= r11 && r00 >= r22) {
        s = 2.0 * sqrt(1.0 + r00 - r11 - r22);
        w = (r21 - r12) / s; x = 0.25 * s; y = (r01 + r10) / s; z = (r02 + r20) / s;
    } else if (r11 >= r22) {
        s = 2.0 * sqrt(1.0 + r11 - r00 - r22);
        w = (r02 - r20) / s; x = (r01 + r10) / s; y = 0.25 * s; z = (r12 + r21) / s;
    } else {
        s = 2.0 * sqrt(1.0 + r22 - r00 - r11);
        w = (r10 - r01) / s; x = (r02 + r20) / s; y = (r12 + r21) / s; z = 0.25 * s;
    }
    if (w < 0.0) { w = -w; x = -x; y = -y; z = -z; }
    return bq_normalize(w, x, y, z);
}

/* lambda = Q_NUE_ENU o q_wb o Q_FLU_FUR (_gost_lambda_from_q) */
static inline bq gost_lambda_from_q(double w, double x, double y, double z) {
    bq a = bq_mul(0.5, -0.5, -0.5, -0.5, w, x, y, z);
    double h = sqrt(0.5);
    return bq_mul(a.w, a.x, a.y, a.z, h, h, 0.0, 0.0);
}

/* q_wb = Q_NUE_ENU* o lambda o Q_FLU_FUR* (_q_from_gost_lambda) */
static inline bq q_from_gost_lambda(double l0, double l1, double l2, double l3) {
    bq a = bq_mul(0.5, 0.5, 0.5, 0.5, l0, l1, l2, l3);
    double h = sqrt(0.5);
    return bq_mul(a.w, a.x, a.y, a.z, h, -h, 0.0, 0.0);
}

/* (psi, theta, gamma) from lambda, Aleshkin et al. (2024) eq. (4) with atan2 (_gost_angles_from_lambda) */
static inline bv gost_angles_from_lambda(double l0, double l1, double l2, double l3) {
    double s_theta = 2.0 * (l1 * l2 + l0 * l3);
    double c22 = 2.0 * (l0 * l0 + l2 * l2) - 1.0;
    double c23 = 2.0 * (l2 * l3 - l0 * l1);
    double c11 = 2.0 * (l0 * l0 + l1 * l1) - 1.0;
    double c13 = 2.0 * (l1 * l3 - l0 * l2);
    double cos_theta = sqrt(c11 * c11 + c13 * c13);
    double theta = atan2(s_theta, cos_theta);
    if (cos_theta < BISO_EST_K_GIMBAL_COS) {
        double c31 = 2.0 * (l1 * l3 + l0 * l2);
        double c33 = 2.0 * (l0 * l0 + l3 * l3) - 1.0;
        return bv_make(atan2(c31, c33), theta, 0.0);
    }
    return bv_make(atan2(-c13, c11), theta, atan2(-c23, c22));
}

/* Aleshkin et al. (2024) eq. (7) (_gost_lambda_from_angles) */
static inline bq gost_lambda_from_angles(double psi, double theta, double gamma) {
    double cp = cos(0.5 * psi), sp = sin(0.5 * psi);
    double ct = cos(0.5 * theta), st = sin(0.5 * theta);
    double cg = cos(0.5 * gamma), sg = sin(0.5 * gamma);
    return bq_make(cp * ct * cg - sp * st * sg,
                   cp * ct * sg + sp * st * cg,
                   sp * ct * cg + cp * st * sg,
                   cp * st * cg - sp * ct * sg);
}

/* ---- _kernels.py: input policy ------------------------------------------------------ */

static inline int gyro_ok(double x, double y, double z) {
    double n2 = x * x + y * y + z * z;
    return n2 < BISO_EST_K_MAX_RATE * BISO_EST_K_MAX_RATE;
}

/* any axis of a finite sample at or beyond limit (inf: never) (_beyond) */
static inline int beyond(double x, double y, double z, double limit) {
    return limit < HUGE_VAL && (fabs(x) >= limit || fabs(y) >= limit || fabs(z) >= limit);
}

typedef struct {
    int64_t flags;
    double gx, gy, gz;  /* the gyro sample to use (the held one if this one is invalid) */
    int acc_ok;
    double f2;          /* |f|^2 */
    int mag_ok;
    double ex, ey, ez, e2;  /* E = m x f, |E|^2 */
} sample_checks;

/* the common input policy of every estimator, for one sample (_input_checks) */
static inline sample_checks input_checks(double gx, double gy, double gz, double ax, double ay, double az,
                                         double mx, double my, double mz, double hx, double hy, double hz,
                                         int64_t imu_flags, double gyro_limit, double accel_limit) {
    sample_checks r;
    int64_t flags = 0;
    double m2;
    if (gyro_ok(gx, gy, gz)) {
        if (beyond(gx, gy, gz, gyro_limit) || (imu_flags & BISO_EST_IMU_GYRO_SATURATED))
            flags |= BISO_EST_FLAG_SATURATED;
    } else {
        gx = hx; gy = hy; gz = hz;
        flags |= BISO_EST_FLAG_GYRO_INVALID;
    }
    r.f2 = ax * ax + ay * ay + az * az;
    r.acc_ok = r.f2 > BISO_EST_K_MIN_ACCEL * BISO_EST_K_MIN_ACCEL && r.f2 < BISO_EST_K_MAX_ACCEL * BISO_EST_K_MAX_ACCEL;
    if (r.acc_ok && (beyond(ax, ay, az, accel_limit) || (imu_flags & BISO_EST_IMU_ACCEL_SATURATED))) {
        r.acc_ok = 0;
        flags |= BISO_EST_FLAG_SATURATED;
    }
    if (!r.acc_ok) flags |= BISO_EST_FLAG_ACCEL_INVALID;
    r.ex = my * az - mz * ay;
    r.ey = mz * ax - mx * az;
    r.ez = mx * ay - my * ax;
    r.e2 = r.ex * r.ex + r.ey * r.ey + r.ez * r.ez;
    m2 = mx * mx + my * my + mz * mz;
    r.mag_ok = m2 > BISO_EST_K_MIN_MAG * BISO_EST_K_MIN_MAG && m2 < BISO_EST_K_MAX_MAG * BISO_EST_K_MAX_MAG;
    if (imu_flags & BISO_EST_IMU_MAG_OVERFLOW) {
        flags |= BISO_EST_FLAG_SATURATED;
        r.mag_ok = 0;
    }
    if (imu_flags & BISO_EST_IMU_MAG_INVALID) r.mag_ok = 0;
    r.mag_ok = r.mag_ok && r.acc_ok
               && r.e2 > (BISO_EST_K_MAG_PARALLEL_SIN * BISO_EST_K_MAG_PARALLEL_SIN) * m2 * r.f2;
    if (!r.mag_ok) flags |= BISO_EST_FLAG_MAG_INVALID;
    r.flags = flags;
    r.gx = gx; r.gy = gy; r.gz = gz;
    return r;
}

/* e^{(0, r)/2}: Taylor series for |r| <= 0.1 rad, sin and cos beyond (_qexp_fast) */
static inline bq qexp_fast(double rx, double ry, double rz) {
    double t2 = rx * rx + ry * ry + rz * rz;
    if (t2 <= 0.01) {
        double x = 0.25 * t2, x2, c, s;
        if (x <= BISO_EST_K_X_FIRST) {
            s = 0.5 * (1.0 - x * BISO_EST_K_S2);
            return bq_make(1.0 - x * BISO_EST_K_C2, s * rx, s * ry, s * rz);
        }
        x2 = x * x;
        c = (1.0 - x * BISO_EST_K_C2) + x2 * ((BISO_EST_K_C4 - x * BISO_EST_K_C6) + x2 * BISO_EST_K_C8);
        s = 0.5 * ((1.0 - x * BISO_EST_K_S2) + x2 * ((BISO_EST_K_S4 - x * BISO_EST_K_S6) + x2 * BISO_EST_K_S8));
        return bq_make(c, s * rx, s * ry, s * rz);
    } else {
        double angle = sqrt(t2);
        double s = sin(0.5 * angle) / angle;
        return bq_make(cos(0.5 * angle), s * rx, s * ry, s * rz);
    }
}

/* q_wb whose Up is along f and East along e (body axes, e _|_ f), Shepperd's method on
 * the unnormalised rows (_q_from_up_east) */
static inline bq q_from_up_east(double fx, double fy, double fz, double f2, double ex, double ey, double ez,
                                double e2) {
    double fn = sqrt(f2), en = sqrt(e2), s = fn * en;
    double r00 = ex * fn, r01 = ey * fn, r02 = ez * fn;
    double r10 = fy * ez - fz * ey, r11 = fz * ex - fx * ez, r12 = fx * ey - fy * ex;
    double r20 = fx * en, r21 = fy * en, r22 = fz * en;
    double t0 = s + (r00 + r11 + r22);
    double t1 = s + (r00 - r11 - r22);
    double t2 = s + (r11 - r00 - r22);
    double t3 = s + (r22 - r00 - r11);
    double d21 = r21 - r12, d02 = r02 - r20, d10 = r10 - r01;
    double s01 = r01 + r10, s02 = r02 + r20, s12 = r12 + r21;
    int c23 = t3 > t2;
    double t23 = c23 ? t3 : t2, w23 = c23 ? d10 : d02, x23 = c23 ? s02 : s01;
    double y23 = c23 ? s12 : t2, z23 = c23 ? t3 : s12;
    int c01 = t1 > t0;
    double t01 = c01 ? t1 : t0, w01 = c01 ? d21 : t0, x01 = c01 ? t1 : d21;
    double y01 = c01 ? s01 : d02, z01 = c01 ? s02 : d10;
    int c = t23 > t01;
    double t = c ? t23 : t01;
    double i = 0.5 / sqrt(s * t);
    return bq_make((c ? w23 : w01) * i, (c ? x23 : x01) * i, (c ? y23 : y01) * i, (c ? z23 : z01) * i);
}

/* (cos D/2, 0, 0, -sin D/2) o q: magnetic north -> true north (_rotate_true_north) */
static inline bq rotate_true_north(double cdh, double sdh, double w, double x, double y, double z) {
    return bq_make(cdh * w + sdh * z, cdh * x + sdh * y, cdh * y - sdh * x, cdh * z - sdh * w);
}

/* ---- reference.py: lambda_k from the accelerometer and the magnetometer ----------------- */

/* east (unnormalised, _|_ f) of the estimate l (_east_from_estimate) */
static inline bv east_from_estimate(double fx, double fy, double fz, double f2, double lw, double lx, double ly,
                                    double lz) {
    bv n = bq_rot_inv(lw, lx, ly, lz, 0.0, 1.0, 0.0);
    double ex = n.y * fz - n.z * fy;
    double ey = n.z * fx - n.x * fz;
    double ez = n.x * fy - n.y * fx;
    double l2 = lw * lw + lx * lx + ly * ly + lz * lz;
    if (ex * ex + ey * ey + ez * ez < 0.01 * f2 * l2 * l2) {
        bv e = bq_rot_inv(lw, lx, ly, lz, 1.0, 0.0, 0.0);
        double d = (e.x * fx + e.y * fy + e.z * fz) / f2;
        ex = e.x - d * fx; ey = e.y - d * fy; ez = e.z - d * fz;
    }
    return bv_make(ex, ey, ez);
}

/* lambda_k by TRIAD (_ref_triad) */
static inline bq ref_triad(double fx, double fy, double fz, double f2, double ex, double ey, double ez, double e2,
                           int mag_ok, double lw, double lx, double ly, double lz, double cdh, double sdh) {
    bv e;
    if (mag_ok) {
        bq q = q_from_up_east(fx, fy, fz, f2, ex, ey, ez, e2);
        return rotate_true_north(cdh, sdh, q.w, q.x, q.y, q.z);
    }
    e = east_from_estimate(fx, fy, fz, f2, lw, lx, ly, lz);
    return q_from_up_east(fx, fy, fz, f2, e.x, e.y, e.z, e.x * e.x + e.y * e.y + e.z * e.z);
}

/* lambda_k by TRIAD from the up direction u and the field m (_ref_vector) */
static inline bq ref_vector(double ux, double uy, double uz, double mx, double my, double mz, int mag_ok,
                            double lw, double lx, double ly, double lz, double cdh, double sdh) {
    double ex = my * uz - mz * uy;
    double ey = mz * ux - mx * uz;
    double ez = mx * uy - my * ux;
    return ref_triad(ux, uy, uz, ux * ux + uy * uy + uz * uz, ex, ey, ez, ex * ex + ey * ey + ez * ez, mag_ok,
                     lw, lx, ly, lz, cdh, sdh);
}

/* lambda_k by the corrected eqs. (5)-(7) of Aleshkin et al. (2024) (_ref_euler) */
static inline bq ref_euler(double fx, double fy, double fz, double mx, double my, double mz, int mag_ok,
                           double lw, double lx, double ly, double lz, double decl) {
    double fpx = fx, fpy = fz, fpz = -fy, psi;
    double theta = atan2(fpx, sqrt(fpy * fpy + fpz * fpz));
    double gamma = atan2(-fpz, fpy);
    bq l;
    if (mag_ok) {
        double hx = mx, hy = mz, hz = -my;
        double sg = sin(gamma), cg = cos(gamma);
        double st = sin(theta), ct = cos(theta);
        psi = atan2(hy * sg + hz * cg, hx * ct - (hy * cg - hz * sg) * st) - decl;
    } else {
        double n = sqrt(lw * lw + lx * lx + ly * ly + lz * lz);
        bq g = gost_lambda_from_q(lw / n, lx / n, ly / n, lz / n);
        psi = gost_angles_from_lambda(g.w, g.x, g.y, g.z).x;
    }
    l = gost_lambda_from_angles(psi, theta, gamma);
    return q_from_gost_lambda(l.w, l.x, l.y, l.z);
}

/* lambda_k by method (0 vector, 1 euler) (_reference) */
static inline bq reference(int method, double fx, double fy, double fz, double f2, double ex, double ey, double ez,
                           double e2, double mx, double my, double mz, int mag_ok, double lw, double lx, double ly,
                           double lz, double decl, double cdh, double sdh) {
    if (method == 0) return ref_triad(fx, fy, fz, f2, ex, ey, ez, e2, mag_ok, lw, lx, ly, lz, cdh, sdh);
    return ref_euler(fx, fy, fz, mx, my, mz, mag_ok, lw, lx, ly, lz, decl);
}

#endif /* BISO_EST_KERNELS_H */
