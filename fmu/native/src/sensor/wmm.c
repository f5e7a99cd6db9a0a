/* The World Magnetic Model, statement for statement as pygeomag.GeoMag computes it
 * (_load_coefficients and calculate), and EarthField's use of it (sensors/magnetic.py). */
#include "biso_field.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "biso_sensor_data.h"

#define SIZE (BISO_WMM_N + 1)

/* CPython's math.radians / math.degrees */
static double radians(double x) { return x * (3.14159265358979323846 / 180.0); }
static double degrees(double x) { return x * (180.0 / 3.14159265358979323846); }

static int leap(int y) { return (y % 4 == 0 && y % 100 != 0) || y % 400 == 0; }

int biso_decimal_year(const char *s, double *year, char *msg, size_t len) {
    static const int days_before[12] = {0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334};
    static const int month_days[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    int y, m, d, i, ok = s && strlen(s) == 10 && s[4] == '-' && s[7] == '-';
    for (i = 0; ok && i < 10; i++)
        if (i != 4 && i != 7 && (s[i] < '0' || s[i] > '9')) ok = 0;
    if (ok) {
        y = (s[0] - '0') * 1000 + (s[1] - '0') * 100 + (s[2] - '0') * 10 + (s[3] - '0');
        m = (s[5] - '0') * 10 + (s[6] - '0');
        d = (s[8] - '0') * 10 + (s[9] - '0');
        ok = y >= 1 && m >= 1 && m <= 12 && d >= 1 && d <= month_days[m - 1] + (m == 2 && leap(y));
    }
    if (!ok) {
        snprintf(msg, len, "site.date must be an ISO date YYYY-MM-DD, got '%s'", s ? s : "");
        return 1;
    }
    {
        int doy = days_before[m - 1] + (m > 2 && leap(y)) + d - 1;
        *year = (double)y + (double)doy / (double)(leap(y) ? 366 : 365);
    }
    return 0;
}

int biso_earth_field_at(double glat, double glon, double alt_m, double year, biso_earth_field *out, char *msg,
                        size_t len) {
    const biso_wmm_release *rel;
    double c[SIZE][SIZE], cd[SIZE][SIZE], k[SIZE][SIZE], snorm[SIZE * SIZE], fn[SIZE], fm[SIZE];
    double tc[SIZE][SIZE], dp[SIZE][SIZE], sp[SIZE], cp[SIZE], pp[SIZE];
    double a = 6378.137, b = 6356.7523142, re = 6371.2;
    double a2, b2, c2, a4, b4, c4, dt, rlon, rlat, srlon, srlat, crlon, crlat, srlat2, crlat2;
    double q, q1, q2, ct, st, r2, r, d, ca, sa, aor, ar, br, bt, bp, bpp, bx, by, bz, bh, f, dec, inc;
    double alt = alt_m / 1000.0;
    int i, n, m, base;

    if (!(isfinite(glat) && glat >= -90.0 && glat <= 90.0)) {
        snprintf(msg, len, "site.lat_deg must be in [-90, 90], got %g", glat);
        return 1;
    }
    if (!(isfinite(glon) && glon >= -180.0 && glon <= 180.0)) {
        snprintf(msg, len, "site.lon_deg must be in [-180, 180], got %g", glon);
        return 1;
    }
    if (!(isfinite(alt_m) && alt_m >= -1000.0 && alt_m <= 850000.0)) {
        snprintf(msg, len, "site.alt_m must be in [-1000, 850000], got %g", alt_m);
        return 1;
    }
    base = (int)year;
    if (!(year >= (double)biso_wmm_first_year && year < (double)biso_wmm_last_year + 1.0)) {
        snprintf(msg, len, "site.date must lie within the WMM releases shipped with pygeomag (%d-%d), got %.2f",
                 biso_wmm_first_year, biso_wmm_last_year + 1, year);
        return 1;
    }
    rel = &biso_wmm_releases[biso_wmm_release_of_year[base - biso_wmm_first_year]];

    /* _load_coefficients */
    for (i = 0; i < SIZE; i++)
        for (n = 0; n < SIZE; n++) c[i][n] = cd[i][n] = k[i][n] = 0.0;
    for (i = 0; i < rel->n; i++) {
        int nn = (int)rel->gh[i][0], mm = (int)rel->gh[i][1];
        if (mm > BISO_WMM_N) break;
        c[mm][nn] = rel->gh[i][2];
        cd[mm][nn] = rel->gh[i][4];
        if (mm != 0) {
            c[nn][mm - 1] = rel->gh[i][3];
            cd[nn][mm - 1] = rel->gh[i][5];
        }
    }
    snorm[0] = 1.0;
    fm[0] = 0.0;
    fn[0] = 0.0;
    for (n = 1; n <= BISO_WMM_N; n++) {
        int j = 2;
        snorm[n] = snorm[n - 1] * (double)(2 * n - 1) / (double)n;
        for (m = 0; m <= n; m++) {
            k[m][n] = (double)((n - 1) * (n - 1) - m * m) / (double)((2 * n - 1) * (2 * n - 3));
            if (m > 0) {
                double flnmj = (double)((n - m + 1) * j) / (double)(n + m);
                snorm[n + m * SIZE] = snorm[n + (m - 1) * SIZE] * sqrt(flnmj);
                j = 1;
                c[n][m - 1] = snorm[n + m * SIZE] * c[n][m - 1];
                cd[n][m - 1] = snorm[n + m * SIZE] * cd[n][m - 1];
            }
            c[m][n] = snorm[n + m * SIZE] * c[m][n];
            cd[m][n] = snorm[n + m * SIZE] * cd[m][n];
        }
        fn[n] = (double)(n + 1);
        fm[n] = (double)n;
    }
    k[1][1] = 0.0;

    /* calculate */
    sp[0] = 0.0;
    cp[0] = pp[0] = 1.0;
    for (i = 0; i < SIZE; i++)
        for (n = 0; n < SIZE; n++) dp[i][n] = tc[i][n] = 0.0;
    a2 = a * a;
    b2 = b * b;
    c2 = a2 - b2;
    a4 = a2 * a2;
    b4 = b2 * b2;
    c4 = a4 - b4;
    dt = year - rel->epoch;
    if (dt < 0.0 || dt > 5.0) {
        snprintf(msg, len, "site.date: %.2f lies outside the 5-year life span of %s", year, rel->model);
        return 1;
    }
    rlon = radians(glon);
    rlat = radians(glat);
    srlon = sin(rlon);
    srlat = sin(rlat);
    crlon = cos(rlon);
    crlat = cos(rlat);
    srlat2 = srlat * srlat;
    crlat2 = crlat * crlat;
    sp[1] = srlon;
    cp[1] = crlon;
    q = sqrt(a2 - c2 * srlat2);
    q1 = alt * q;
    q2 = ((q1 + a2) / (q1 + b2)) * ((q1 + a2) / (q1 + b2));
    ct = srlat / sqrt(q2 * crlat2 + srlat2);
    st = sqrt(1.0 - (ct * ct));
    r2 = (alt * alt) + 2.0 * q1 + (a4 - c4 * srlat2) / (q * q);
    r = sqrt(r2);
    d = sqrt(a2 * crlat2 + b2 * srlat2);
    ca = (alt + d) / r;
    sa = c2 * crlat * srlat / (r * d);
    for (m = 2; m <= BISO_WMM_N; m++) {
        sp[m] = sp[1] * cp[m - 1] + cp[1] * sp[m - 1];
        cp[m] = cp[1] * cp[m - 1] - sp[1] * sp[m - 1];
    }
    aor = re / r;
    ar = aor * aor;
    br = bt = bp = bpp = 0.0;
    for (n = 1; n <= BISO_WMM_N; n++) {
        ar = ar * aor;
        for (m = 0; m <= n; m++) {
            double par, temp1, temp2;
            if (n == m) {
                snorm[n + m * SIZE] = st * snorm[n - 1 + (m - 1) * SIZE];
                dp[m][n] = st * dp[m - 1][n - 1] + ct * snorm[n - 1 + (m - 1) * SIZE];
            } else if (n == 1 && m == 0) {
                snorm[n + m * SIZE] = ct * snorm[n - 1 + m * SIZE];
                dp[m][n] = ct * dp[m][n - 1] - st * snorm[n - 1 + m * SIZE];
            } else if (n > 1 && n != m) {
                if (m > n - 2) snorm[n - 2 + m * SIZE] = 0.0;
                if (m > n - 2) dp[m][n - 2] = 0.0;
                snorm[n + m * SIZE] = ct * snorm[n - 1 + m * SIZE] - k[m][n] * snorm[n - 2 + m * SIZE];
                dp[m][n] = ct * dp[m][n - 1] - st * snorm[n - 1 + m * SIZE] - k[m][n] * dp[m][n - 2];
            }
            tc[m][n] = c[m][n] + dt * cd[m][n];
            if (m != 0) tc[n][m - 1] = c[n][m - 1] + dt * cd[n][m - 1];
            par = ar * snorm[n + m * SIZE];
            if (m == 0) {
                temp1 = tc[m][n] * cp[m];
                temp2 = tc[m][n] * sp[m];
            } else {
                temp1 = tc[m][n] * cp[m] + tc[n][m - 1] * sp[m];
                temp2 = tc[m][n] * sp[m] - tc[n][m - 1] * cp[m];
            }
            bt = bt - ar * temp1 * dp[m][n];
            bp += fm[m] * temp2 * par;
            br += fn[n] * temp1 * par;
            if (st == 0.0 && m == 1) { /* north/south geographic poles */
                double parp;
                if (n == 1)
                    pp[n] = pp[n - 1];
                else
                    pp[n] = ct * pp[n - 1] - k[m][n] * pp[n - 2];
                parp = ar * pp[n];
                bpp += fm[m] * temp2 * parp;
            }
        }
    }
    if (st == 0.0)
        bp = bpp;
    else
        bp /= st;
    bx = -bt * ca - br * sa;
    by = bp;
    bz = bt * sa - br * ca;
    bh = sqrt((bx * bx) + (by * by));
    f = sqrt((bh * bh) + (bz * bz));
    dec = degrees(atan2(by, bx));
    inc = degrees(atan2(bz, bh));
    {
        /* GeoMagResult.calculate, then EarthField: ENU = (y, x, -z) / 1000 */
        double x = f * (cos(radians(dec)) * cos(radians(inc)));
        double y = f * (cos(radians(inc)) * sin(radians(dec)));
        double z = f * (sin(radians(inc)));
        double h = f * (cos(radians(inc)));
        out->field_enu_ut[0] = y / 1000.0;
        out->field_enu_ut[1] = x / 1000.0;
        out->field_enu_ut[2] = -z / 1000.0;
        out->declination_rad = radians(dec);
        out->inclination_rad = radians(inc);
        out->horizontal_ut = h / 1000.0;
        out->total_ut = f / 1000.0;
        out->model = rel->model;
    }
    return 0;
}

void biso_rotate_into_body(const double q[4], const double v[3], double o[3]) {
    /* _qrot(qw, -qx, -qy, -qz, v): t = 2 q_vec × v;  v' = v + w t + q_vec × t */
    double qw = q[0], qx = -q[1], qy = -q[2], qz = -q[3];
    double tx = 2.0 * (qy * v[2] - qz * v[1]);
    double ty = 2.0 * (qz * v[0] - qx * v[2]);
    double tz = 2.0 * (qx * v[1] - qy * v[0]);
    o[0] = v[0] + qw * tx + (qy * tz - qz * ty);
    o[1] = v[1] + qw * ty + (qz * tx - qx * tz);
    o[2] = v[2] + qw * tz + (qx * ty - qy * tx);
}
