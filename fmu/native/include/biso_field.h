/* The Earth's magnetic field at a site and date: the World Magnetic Model as pygeomag
 * evaluates it (a port of NOAA's legacy C code), with the coefficient releases pygeomag
 * ships, embedded by the build. The C twin of biso_cosim.sensors.EarthField. */
#ifndef BISO_FIELD_H
#define BISO_FIELD_H

#include <stddef.h>

typedef struct {
    double field_enu_ut[3]; /* µT, x East, y North, z Up */
    double declination_rad; /* east of true north positive */
    double inclination_rad; /* downward positive */
    double horizontal_ut, total_ut;
    const char *model;      /* WMM release used */
} biso_earth_field;

/* Decimal year of an ISO date "YYYY-MM-DD" (as EarthField: year + day of year / days in
 * the year); 0 on success, else a message naming site.date. */
int biso_decimal_year(const char *iso_date, double *year, char *msg, size_t len);
/* The field at geodetic latitude/longitude (deg), altitude (m) and decimal year; 0 on
 * success, else a message naming the variable and its allowed range. */
int biso_earth_field_at(double lat_deg, double lon_deg, double alt_m, double year, biso_earth_field *out, char *msg,
                        size_t len);
/* q* ∘ v ∘ q of a unit quaternion q = q_wb: a world vector in body axes (frames._qrot_inv). */
void biso_rotate_into_body(const double q_wb[4], const double v_w[3], double v_b[3]);

#endif
