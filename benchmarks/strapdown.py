"""Speed of the strapdown algorithms (Litmanovich 2002): numba batch kernels against plain
NumPy implementations of the same printed formulas, measured in the same run.

    python benchmarks/strapdown.py [--n 200000] [--repeat 5]

Prints intervals per second for every coning, sculling and displacement algorithm (batch
call over N intervals) and for the navigator (one ``navigate`` call against a per-interval
Python/NumPy loop, on fewer intervals), with the ratio numba / NumPy. Also checks that the
two agree, so the comparison is between equal results.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from biso_cosim import strapdown as sd

X = np.cross


def _c(a, b):
    return X(a, b)


# Plain NumPy, vectorised over intervals: th[:, r] is ΔΘ^{r+1} or the (r+1)-th sub-increment.
NUMPY_CONING = {
    "one_sample": lambda th, T: np.zeros((th.shape[0], 3)),
    "two_sample": lambda th, T: 2 / 3 * _c(th[:, 0], th[:, 1]),
    "traditional3": lambda th, T: 33 / 80 * _c(th[:, 0], th[:, 2]) + 57 / 80 * _c(th[:, 1], th[:, 2] - th[:, 0]),
    "traditional3_miller": lambda th, T: 9 / 20 * _c(th[:, 0], th[:, 2]) + 27 / 40 * _c(th[:, 1], th[:, 2] - th[:, 0]),
    "smoothing": lambda th, T: 6 / T**2 * _c(th[:, 0], th[:, 2]) - 3 / T * _c(th[:, 1], 4 / T**2 * th[:, 2] - th[:, 0]),
    "invariant": lambda th, T: (18 / T**2 * _c(th[:, 0], th[:, 2])
                                - 1.5 / T * _c(th[:, 1], 44 / T**2 * th[:, 2] - 3 * th[:, 0])
                                - 30 / T**3 * _c(th[:, 0] - 6 / T * th[:, 1] + 12 / T**2 * th[:, 2], th[:, 3])),
}
NUMPY_SCULLING = {
    "traditional1": lambda th, v, T: 0.5 * _c(th[:, 0], v[:, 0]),
    "traditional2": lambda th, v, T: (0.5 * _c(th[:, 0] + th[:, 1], v[:, 0] + v[:, 1])
                                      + 2 / 3 * (_c(th[:, 0], v[:, 1]) - _c(th[:, 1], v[:, 0]))),
    "smoothing": lambda th, v, T: 0.5 * _c(th[:, 0], v[:, 0]) - (_c(th[:, 0], v[:, 1]) - _c(th[:, 1], v[:, 0])) / T,
    "invariant_accel1": lambda th, v, T: (_c(th[:, 0], v[:, 0]) + 6 / T**2 * _c(th[:, 1] - 2 * T / 3 * th[:, 0], v[:, 1])
                                          - 12 / T**3 * _c(th[:, 1] - T / 2 * th[:, 0], v[:, 2])),
    "invariant_accel0": lambda th, v, T: _c(th[:, 0], v[:, 0] - v[:, 1] / T),
    "invariant_rate1": lambda th, v, T: (-6 / T**2 * _c(th[:, 1], v[:, 1] - 2 * T / 3 * v[:, 0])
                                         + 12 / T**3 * _c(th[:, 2], v[:, 1] - T / 2 * v[:, 0])),
    "invariant_rate0": lambda th, v, T: _c(th[:, 1], v[:, 0]) / T,
}
NUMPY_DISPLACEMENT = {
    "traditional1": lambda th, v, T: T / 6 * _c(th[:, 0], v[:, 0]),
    "smoothing": lambda th, v, T: (T / 15 * _c(th[:, 0], v[:, 0]) - 0.3 * _c(th[:, 0], v[:, 1])
                                   + 0.2 * _c(th[:, 1], v[:, 0]) + 0.6 / T * _c(th[:, 1], v[:, 1])),
    "invariant_accel1": lambda th, v, T: (_c(th[:, 0], v[:, 1]) - 2 * _c(4 / T * th[:, 0] - 6 / T**2 * th[:, 1], v[:, 2])
                                          + 3 * _c(6 / T**2 * th[:, 0] - 12 / T**3 * th[:, 1], v[:, 3])),
    "invariant_accel0": lambda th, v, T: _c(th[:, 0], v[:, 1] - 2 / T * v[:, 2]),
    "invariant_rate1": lambda th, v, T: (_c(th[:, 2], 4 / T * v[:, 0] - 6 / T**2 * v[:, 1])
                                         - 2 * _c(th[:, 3], 6 / T**2 * v[:, 0] - 12 / T**3 * v[:, 1])),
    "invariant_rate0": lambda th, v, T: _c(th[:, 2], v[:, 0]) / T,
}


def best_time(fn, repeat: int) -> float:
    fn()  # warm-up (JIT compilation, caches)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def numpy_navigate(params, th, dv):
    """Per-interval loop with NumPy: the navigator equations of navigator.py, plainly."""
    T, g = params.interval_s, np.array(params.gravity_w)
    q, v, p = np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3)
    con, scu, dis = NUMPY_CONING[params.coning], NUMPY_SCULLING[params.sculling], NUMPY_DISPLACEMENT[params.sculling]

    def rot(q, x):
        t = 2 * np.cross(q[1:], x)
        return x + q[0] * t + np.cross(q[1:], t)

    out = np.empty((th.shape[0], 3))
    for k in range(th.shape[0]):
        a, b = th[k:k + 1], dv[k:k + 1]
        v_new = v + rot(q, b[0, 0] + scu(a, b, T)[0]) + g * T
        p = p + v * T + rot(q, b[0, 1] + dis(a, b, T)[0]) + 0.5 * g * T * T
        v = v_new
        phi = a[0, 0] + con(a, T)[0]
        angle = np.linalg.norm(phi)
        half = 0.5 * angle
        s = np.sinc(half / np.pi) * 0.5
        d = np.array([np.cos(half), *(s * phi)])
        q = np.array([q[0] * d[0] - q[1:] @ d[1:], *(q[0] * d[1:] + d[0] * q[1:] + np.cross(q[1:], d[1:]))])
        q /= np.linalg.norm(q)
        out[k] = p
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200_000, help="intervals per batch call")
    parser.add_argument("--repeat", type=int, default=5, help="timed repetitions (best is kept)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    T = 0.005
    scale = (T ** np.arange(1, 5))[:, None]
    th = rng.normal(size=(args.n, 4, 3)) * scale
    dv = rng.normal(size=(args.n, 4, 3)) * scale * 10
    print(f"{'algorithm':<34} {'numba /s':>12} {'numpy /s':>12} {'ratio':>7}")
    rows = []
    for quantity, table in (("coning", NUMPY_CONING), ("sculling", NUMPY_SCULLING), ("displacement", NUMPY_DISPLACEMENT)):
        for name, ref in table.items():
            info = sd.get_algorithm(quantity, name)
            a = np.ascontiguousarray(th[:, :info.m_dtheta])
            if quantity == "coning":
                fast = lambda: sd.coning_correction(name, a, T)
                slow = lambda: ref(a, T)
            else:
                b = np.ascontiguousarray(dv[:, :info.m_dv])
                fast = {"sculling": sd.sculling_correction, "displacement": sd.position_correction}[quantity]
                fast = (lambda f=fast, b=b: f(name, a, b, T))
                slow = (lambda b=b: ref(a, b, T))
            np.testing.assert_allclose(fast(), slow(), rtol=1e-9, atol=1e-9 * np.abs(slow()).max())
            t_fast, t_slow = best_time(fast, args.repeat), best_time(slow, args.repeat)
            rows.append((f"{quantity} {name}", args.n / t_fast, args.n / t_slow))
    n_nav = min(args.n, 20_000)
    params = sd.NavigatorParams(T, coning="invariant", sculling="invariant_rate1", position="exact")
    a, b = th[:n_nav], dv[:n_nav]
    fast = lambda: sd.navigate(params, a, b).p_w
    slow = lambda: numpy_navigate(params, a, b)
    np.testing.assert_allclose(fast(), slow(), rtol=1e-9, atol=1e-12)
    rows.append(("navigator invariant/rate1/exact", n_nav / best_time(fast, args.repeat),
                 n_nav / best_time(slow, 1)))
    for label, fast_rate, slow_rate in rows:
        print(f"{label:<34} {fast_rate:>12.3g} {slow_rate:>12.3g} {fast_rate / slow_rate:>7.1f}")


if __name__ == "__main__":
    main()
