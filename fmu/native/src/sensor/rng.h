/* Random generators of the virtual MPU-9250 (C twin of biso_cosim/sensors/_rng.py and of the
 * NumPy generator that draws a part's turn-on errors).
 *
 * - xoshiro256++ with the project's 128-block ziggurat normal: the noise stream of the chip
 *   (biso_cosim.sensors._rng._next_u64 and _normal, Blackman & Vigna 2021, Doornik 2005);
 * - NumPy's SeedSequence (its hash mixing, spawn and generate_state), PCG64 (XSL-RR 128/64)
 *   and Generator.standard_normal / uniform: numpy.random.default_rng(child) exactly, so
 *   that a seed draws the same part in C as in Python.
 */
#ifndef BISO_SENSOR_RNG_H
#define BISO_SENSOR_RNG_H

#include <stdint.h>

uint64_t biso_xoshiro_next(uint64_t s[4]);
double biso_xoshiro_uniform(uint64_t s[4]);
double biso_xoshiro_normal(uint64_t s[4]);

/* The pool (4 words) of numpy.random.SeedSequence(entropy).spawn(n)[child]; entropy is a
 * non-negative integer of up to 64 bits. */
void biso_seed_child_pool(uint64_t entropy, uint32_t child, uint32_t pool[4]);
/* SeedSequence.generate_state(n_words, np.uint64) of a pool. */
void biso_seed_generate_state64(const uint32_t pool[4], uint64_t *out, int n_words);

typedef struct {
    uint64_t state_hi, state_lo, inc_hi, inc_lo;
} biso_pcg64;

/* numpy.random.PCG64 seeded from a SeedSequence pool. */
void biso_pcg64_seed(biso_pcg64 *g, const uint32_t pool[4]);
uint64_t biso_pcg64_next(biso_pcg64 *g);
double biso_pcg64_double(biso_pcg64 *g);
/* Generator.standard_normal() and Generator.uniform(low, high) of NumPy. */
double biso_np_standard_normal(biso_pcg64 *g);
double biso_np_uniform(biso_pcg64 *g, double low, double high);

#endif
