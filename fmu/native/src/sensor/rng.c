/* Random generators of the virtual MPU-9250: see rng.h. */
#include "rng.h"

#include <math.h>

#include "biso_sensor_data.h"

/* ---- xoshiro256++ and the project's ziggurat (biso_cosim/sensors/_rng.py) ---------------- */

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

uint64_t biso_xoshiro_next(uint64_t s[4]) {
    uint64_t result = rotl(s[0] + s[3], 23) + s[0];
    uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

#define INV_2_53 (1.0 / 9007199254740992.0)

double biso_xoshiro_uniform(uint64_t s[4]) { return ((double)(biso_xoshiro_next(s) >> 11) + 0.5) * INV_2_53; }

double biso_xoshiro_normal(uint64_t s[4]) {
    for (;;) {
        uint64_t bits = biso_xoshiro_next(s);
        int i = (int)(bits & 0x7F);
        double u = 2.0 * (((double)(bits >> 11) + 0.5) * INV_2_53) - 1.0;
        double x, f0, f1;
        if (fabs(u) < biso_zig_ratio[i]) return u * biso_zig_x[i];
        if (i == 0) {
            double xt, yt;
            for (;;) { /* the tail beyond R (Marsaglia 1964) */
                xt = log(biso_xoshiro_uniform(s)) / biso_zig_r;
                yt = log(biso_xoshiro_uniform(s));
                if (-2.0 * yt >= xt * xt) break;
            }
            return u < 0.0 ? xt - biso_zig_r : biso_zig_r - xt;
        }
        x = u * biso_zig_x[i];
        f0 = exp(-0.5 * (biso_zig_x[i] * biso_zig_x[i] - x * x));
        f1 = exp(-0.5 * (biso_zig_x[i + 1] * biso_zig_x[i + 1] - x * x));
        if (f1 + biso_xoshiro_uniform(s) * (f0 - f1) < 1.0) return x;
    }
}

/* ---- NumPy's SeedSequence ---------------------------------------------------------------- */

#define INIT_A 0x43b0d7e5u
#define MULT_A 0x931e8875u
#define INIT_B 0x8b51f9ddu
#define MULT_B 0x58f38dedu
#define MIX_MULT_L 0xca01f9ddu
#define MIX_MULT_R 0x4973f715u
#define XSHIFT 16

static uint32_t hashmix(uint32_t value, uint32_t *hash_const) {
    value ^= *hash_const;
    *hash_const *= MULT_A;
    value *= *hash_const;
    value ^= value >> XSHIFT;
    return value;
}

static uint32_t mix(uint32_t x, uint32_t y) {
    uint32_t result = MIX_MULT_L * x - MIX_MULT_R * y;
    result ^= result >> XSHIFT;
    return result;
}

void biso_seed_child_pool(uint64_t entropy, uint32_t child, uint32_t pool[4]) {
    /* assembled entropy: the entropy's 32-bit words (little end first, [0] for 0), padded
     * with zeros to the pool size because a spawn key follows, then the spawn key (child) */
    uint32_t words[5];
    int n = 0, i, j;
    uint32_t hash_const = INIT_A;
    words[n++] = (uint32_t)(entropy & 0xFFFFFFFFu);
    if (entropy >> 32) words[n++] = (uint32_t)(entropy >> 32);
    while (n < 4) words[n++] = 0;
    words[n++] = child;
    for (i = 0; i < 4; i++) pool[i] = hashmix(words[i], &hash_const);
    for (i = 0; i < 4; i++)
        for (j = 0; j < 4; j++)
            if (i != j) pool[j] = mix(pool[j], hashmix(pool[i], &hash_const));
    for (i = 4; i < n; i++)
        for (j = 0; j < 4; j++) pool[j] = mix(pool[j], hashmix(words[i], &hash_const));
}

void biso_seed_generate_state64(const uint32_t pool[4], uint64_t *out, int n_words) {
    uint32_t hash_const = INIT_B;
    int i;
    for (i = 0; i < 2 * n_words; i++) {
        uint32_t v = pool[i % 4];
        v ^= hash_const;
        hash_const *= MULT_B;
        v *= hash_const;
        v ^= v >> XSHIFT;
        if (i % 2 == 0)
            out[i / 2] = v;
        else
            out[i / 2] |= (uint64_t)v << 32; /* little-endian pairs of 32-bit words */
    }
}

/* ---- PCG64 (XSL-RR 128/64), 128-bit arithmetic in two 64-bit halves ------------------------ */

#define PCG_MULT_HI 2549297995355413924ULL
#define PCG_MULT_LO 4865540595714422341ULL

static void mul_64_128(uint64_t a, uint64_t b, uint64_t *hi, uint64_t *lo) {
    uint64_t a0 = a & 0xFFFFFFFFu, a1 = a >> 32, b0 = b & 0xFFFFFFFFu, b1 = b >> 32;
    uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    uint64_t mid = (p00 >> 32) + (p01 & 0xFFFFFFFFu) + (p10 & 0xFFFFFFFFu);
    *lo = (mid << 32) | (p00 & 0xFFFFFFFFu);
    *hi = p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
}

static void pcg_step(biso_pcg64 *g) {
    uint64_t hi, lo;
    mul_64_128(g->state_lo, PCG_MULT_LO, &hi, &lo);
    hi += g->state_hi * PCG_MULT_LO + g->state_lo * PCG_MULT_HI;
    lo += g->inc_lo;
    hi += g->inc_hi + (lo < g->inc_lo);
    g->state_hi = hi;
    g->state_lo = lo;
}

void biso_pcg64_seed(biso_pcg64 *g, const uint32_t pool[4]) {
    uint64_t v[4];
    biso_seed_generate_state64(pool, v, 4);
    /* pcg64_set_seed: state = v[0]·2^64 + v[1], sequence = v[2]·2^64 + v[3] */
    g->state_hi = 0;
    g->state_lo = 0;
    g->inc_hi = (v[2] << 1) | (v[3] >> 63);
    g->inc_lo = (v[3] << 1) | 1u;
    pcg_step(g);
    g->state_lo += v[1];
    g->state_hi += v[0] + (g->state_lo < v[1]);
    pcg_step(g);
}

uint64_t biso_pcg64_next(biso_pcg64 *g) {
    uint64_t x;
    unsigned rot;
    pcg_step(g);
    x = g->state_hi ^ g->state_lo;
    rot = (unsigned)(g->state_hi >> 58);
    return (x >> rot) | (x << ((64u - rot) & 63u));
}

double biso_pcg64_double(biso_pcg64 *g) { return (double)(biso_pcg64_next(g) >> 11) * (1.0 / 9007199254740992.0); }

double biso_np_standard_normal(biso_pcg64 *g) {
    for (;;) {
        uint64_t r = biso_pcg64_next(g);
        int idx = (int)(r & 0xff);
        uint64_t rabs;
        int sign;
        double x;
        r >>= 8;
        sign = (int)(r & 0x1);
        rabs = (r >> 1) & 0x000fffffffffffffULL;
        x = (double)rabs * biso_np_wi[idx];
        if (sign) x = -x;
        if (rabs < biso_np_ki[idx]) return x;
        if (idx == 0) {
            for (;;) {
                double xx = -biso_np_zig_inv_r * log1p(-biso_pcg64_double(g));
                double yy = -log1p(-biso_pcg64_double(g));
                if (yy + yy > xx * xx) return ((rabs >> 8) & 0x1) ? -(biso_np_zig_r + xx) : biso_np_zig_r + xx;
            }
        } else if (((biso_np_fi[idx - 1] - biso_np_fi[idx]) * biso_pcg64_double(g) + biso_np_fi[idx]) <
                   exp(-0.5 * x * x)) {
            return x;
        }
    }
}

double biso_np_uniform(biso_pcg64 *g, double low, double high) {
    double range = high - low;
    return low + range * biso_pcg64_double(g);
}
