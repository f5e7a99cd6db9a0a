"""A small random generator for the sensor kernels: xoshiro256++ with ziggurat normals.

The kernels keep their whole random state in the chip state (four uint64 words), so that a stream cut into chunks of any size continues exactly, and
the state can be copied (get/set state). Seeded from a `numpy.random.SeedSequence`.
Reference: D. Blackman, S. Vigna, "Scrambled linear pseudorandom number generators",
ACM TOMS 47 (2021); xoshiro256++ as published at https://prng.di.unimi.it/.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit

_U23 = np.uint64(23)
_U45 = np.uint64(45)
_U17 = np.uint64(17)
_U11 = np.uint64(11)
_U64 = np.uint64(64)
_INV_2_53 = 1.0 / 9007199254740992.0


@jit
def _rotl(x, k):
    return (x << k) | (x >> (_U64 - k))


@jit
def _next_u64(s):
    """Next 64-bit output of xoshiro256++; advances the state ``s`` (uint64, 4) in place."""
    result = _rotl(s[0] + s[3], _U23) + s[0]
    t = s[1] << _U17
    s[2] ^= s[0]
    s[3] ^= s[1]
    s[1] ^= s[2]
    s[0] ^= s[3]
    s[2] ^= t
    s[3] = _rotl(s[3], _U45)
    return result


@jit
def _uniform(s):
    """Uniform double in the open interval (0, 1) from the top 53 bits."""
    return (float(_next_u64(s) >> _U11) + 0.5) * _INV_2_53


# Ziggurat tables (Doornik 2005, "An improved ziggurat method to generate normal random
# samples", 128 blocks: R = 3.442619855899, V = 9.91256303526217e-3).
_ZIG_C = 128
_ZIG_R = 3.442619855899
_ZIG_V = 9.91256303526217e-3


def _ziggurat_tables() -> tuple[np.ndarray, np.ndarray]:
    x = np.empty(_ZIG_C + 1)
    f = math.exp(-0.5 * _ZIG_R * _ZIG_R)
    x[0] = _ZIG_V / f
    x[1] = _ZIG_R
    x[_ZIG_C] = 0.0
    for i in range(2, _ZIG_C):
        x[i] = math.sqrt(-2.0 * math.log(_ZIG_V / x[i - 1] + f))
        f = math.exp(-0.5 * x[i] * x[i])
    return x, x[1:] / x[:-1]


_ZIG_X, _ZIG_RATIO = _ziggurat_tables()
_U7F = np.uint64(0x7F)


@jit
def _normal(s):
    """Standard normal by the ziggurat method (Doornik 2005), one 64-bit draw per try:
    the low 7 bits pick the block, the top 53 bits give u in (-1, 1)."""
    while True:
        bits = _next_u64(s)
        i = int(bits & _U7F)
        u = 2.0 * ((float(bits >> _U11) + 0.5) * _INV_2_53) - 1.0
        if abs(u) < _ZIG_RATIO[i]:
            return u * _ZIG_X[i]
        if i == 0:
            # the tail beyond R (Marsaglia 1964)
            while True:
                xt = math.log(_uniform(s)) / _ZIG_R
                yt = math.log(_uniform(s))
                if -2.0 * yt >= xt * xt:
                    break
            return xt - _ZIG_R if u < 0.0 else _ZIG_R - xt
        x = u * _ZIG_X[i]
        f0 = math.exp(-0.5 * (_ZIG_X[i] * _ZIG_X[i] - x * x))
        f1 = math.exp(-0.5 * (_ZIG_X[i + 1] * _ZIG_X[i + 1] - x * x))
        if f1 + _uniform(s) * (f0 - f1) < 1.0:
            return x


def seed_state(seed_sequence: np.random.SeedSequence) -> np.ndarray:
    """Four non-zero uint64 words for xoshiro256++ from a SeedSequence."""
    words = seed_sequence.generate_state(4, dtype=np.uint64)
    if not words.any():  # the all-zero state is the one forbidden state
        words[0] = np.uint64(0x9E3779B97F4A7C15)
    return words


def reference_next_u64(state: list[int]) -> int:
    """Plain-Python xoshiro256++ step (the slow twin for the tests); mutates ``state``."""
    mask = (1 << 64) - 1

    def rotl(x: int, k: int) -> int:
        return ((x << k) | (x >> (64 - k))) & mask

    s0, s1, s2, s3 = state
    result = (rotl((s0 + s3) & mask, 23) + s0) & mask
    t = (s1 << 17) & mask
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = rotl(s3, 45)
    state[:] = [s0, s1, s2, s3]
    return result


def reference_normal(state: list[int]) -> float:
    """Plain-Python twin of `_normal` (same draws, same arithmetic); mutates ``state``."""

    def uniform() -> float:
        return ((reference_next_u64(state) >> 11) + 0.5) * _INV_2_53

    while True:
        bits = reference_next_u64(state)
        i = bits & 0x7F
        u = 2.0 * (((bits >> 11) + 0.5) * _INV_2_53) - 1.0
        if abs(u) < _ZIG_RATIO[i]:
            return u * _ZIG_X[i]
        if i == 0:
            while True:
                xt = math.log(uniform()) / _ZIG_R
                yt = math.log(uniform())
                if -2.0 * yt >= xt * xt:
                    break
            return xt - _ZIG_R if u < 0.0 else _ZIG_R - xt
        x = u * _ZIG_X[i]
        f0 = math.exp(-0.5 * (_ZIG_X[i] * _ZIG_X[i] - x * x))
        f1 = math.exp(-0.5 * (_ZIG_X[i + 1] * _ZIG_X[i + 1] - x * x))
        if f1 + uniform() * (f0 - f1) < 1.0:
            return x
