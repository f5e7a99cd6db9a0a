"""Coning, sculling and displacement algorithms (Litmanovich 2002) against exact derivations.

Every algorithm is re-derived here from first principles in exact rational arithmetic
(``fractions``): a polynomial model of the signal, fitted to the algorithm's inputs
(sub-interval increments or multiple integrals), then either integrated exactly
(traditional and smoothing) or put into the invariant quadratures (4.1)-(4.3). The result is
a bilinear form δ = Σ K_ij x_i × y_j with rational K, which is compared with the printed
(corrected) coefficients and with the kernel's, probed on unit vectors. The same engine
gives each algorithm's error on the coning and sculling test motions as an exact power
series in ω·T and its general-motion local error, which checks the paper's error formulas.
"""

import math
from fractions import Fraction as F

import numpy as np
import pytest

from biso_cosim import strapdown as sd
from biso_cosim.strapdown import _kernels
from biso_cosim.strapdown.motions import ConingMotion, ScullingMotion

P = 12  # Taylor terms of the signal model used for error series
D = 10  # degree of the error series in x = ω·T

# --------------------------------------------------------------------------------------
# Exact derivation engine (T = 1; powers of T follow from dimensions)
# --------------------------------------------------------------------------------------
# A signal is ω(τ) = Σ_p c_p τ^p / p!, c_p its p-th derivative at t_k (A, B, C, D = c_0..c_3).
# An input is a linear functional of it: row i of L gives the input as Σ_p L[i][p] c_p.


def sub_functional(m, n=P):
    """Sub-interval increment j over [(j−1)/m, j/m]."""
    return [[(F(j + 1, m) ** (p + 1) - F(j, m) ** (p + 1)) / math.factorial(p + 1) for p in range(n)]
            for j in range(m)]


def multiple_functional(m, n=P):
    """r-fold integral over [0, 1] (Cauchy): 1 / (p + r)!."""
    return [[F(1, math.factorial(p + r)) for p in range(n)] for r in range(1, m + 1)]


def solve(A):
    """Inverse of a square rational matrix (Gauss-Jordan)."""
    n = len(A)
    M = [list(row) + [F(int(i == j)) for j in range(n)] for i, row in enumerate(A)]
    for i in range(n):
        piv = next(k for k in range(i, n) if M[k][i] != 0)
        M[i], M[piv] = M[piv], M[i]
        M[i] = [x / M[i][i] for x in M[i]]
        for k in range(n):
            if k != i and M[k][i] != 0:
                M[k] = [x - M[k][i] * y for x, y in zip(M[k], M[i])]
    return [row[n:] for row in M]


def fit(L, degree):
    """Rows p = 0..degree: the model coefficients c_p as combinations of the inputs."""
    return solve([row[:degree + 1] for row in L])


def integral_weight(p, q):
    """∫₀¹ α_p(τ) ω_q(τ) dτ with α_p = τ^{p+1}/(p+1)!, ω_q = τ^q/q!: weight of c_p × c_q in
    ∫ ΔΘ(t_k, τ) × a(τ) dτ, eq. (2.2), (2.9)."""
    return F(1, math.factorial(p + 1) * math.factorial(q) * (p + q + 2))


def displacement_weight(p, q):
    """The same against (1 − τ): weight in δS_s = ∫∫ ΔΘ × a, eq. (5.4)."""
    return integral_weight(p, q) / (p + q + 3)


def polynomial_algorithm(L_w, L_a, deg_w, deg_a, weight=integral_weight):
    """Traditional / smoothing: fit both signals, integrate the models exactly."""
    Fw, Fa = fit(L_w, deg_w), fit(L_a, deg_a)
    return [[sum(Fw[p][i] * weight(p, q) * Fa[q][j] for p in range(deg_w + 1) for q in range(deg_a + 1))
             for j in range(len(L_a))] for i in range(len(L_w))]


def end_derivatives(degree):
    """Rows n: the n-th derivative at the interval end from the smoothing fit (3.4)/(3.5)."""
    Fm = fit(multiple_functional(degree + 1), degree)
    return [[sum(Fm[p][i] / math.factorial(p - n) for p in range(n, degree + 1)) for i in range(degree + 1)]
            for n in range(degree + 1)]


def zeros(n, m):
    return [[F(0)] * m for _ in range(n)]


def accel_invariant(degree, terms, displacement=False):
    """(4.1) δV_s = Θ¹×V¹ − Σ_n (−1)^n ω^(n)_end × V^{n+2}, and its δS_s twin
    Θ¹×V² + Σ_n (−1)^{n+1} (n+2) ω^(n)_end × V^{n+3}."""
    Dm = end_derivatives(degree)
    K = zeros(degree + 1, terms + 1 + displacement)
    K[0][int(displacement)] += 1
    for n in range(terms):
        for i in range(degree + 1):
            if displacement:
                K[i][n + 2] += (-1) ** (n + 1) * (n + 2) * Dm[n][i]
            else:
                K[i][n + 1] -= (-1) ** n * Dm[n][i]
    return K


def rate_invariant(degree, terms, rows, displacement=False):
    """(4.2) δV_s = Σ_n (−1)^n Θ^{n+2} × a^(n)_end, twin Σ_n (−1)^n (n+1) Θ^{n+3} × a^(n)_end."""
    Dm = end_derivatives(degree)
    K = zeros(rows, degree + 1)
    for n in range(terms):
        for j in range(degree + 1):
            K[n + 1 + displacement][j] += (-1) ** n * (n + 1 if displacement else 1) * Dm[n][j]
    return K


def scaled(K, s):
    return [[x * s for x in row] for row in K]


def padded(K, n, m):
    return [[K[i][j] if i < len(K) and j < len(K[i]) else F(0) for j in range(m)] for i in range(n)]


# Derived bilinear forms: name -> (form, K); coning K acts on (ΔΘ, ΔΘ)
CONING = {
    "one_sample": ("sub", [[F(0)]]),
    "two_sample": ("sub", scaled(polynomial_algorithm(sub_functional(2), sub_functional(2), 1, 1), F(1, 2))),
    "traditional3": ("sub", scaled(polynomial_algorithm(sub_functional(3), sub_functional(3), 2, 2), F(1, 2))),
    "smoothing": ("multiple", scaled(polynomial_algorithm(multiple_functional(3), multiple_functional(3), 2, 2), F(1, 2))),
    # (4.3) with the missing ½: δΘ_c = ½ Σ (−1)^n ΔΘ^{n+2} × ω^(n)_end
    "invariant": ("multiple", padded(scaled(rate_invariant(2, 3, 4), F(1, 2)), 4, 4)),
}
SCULLING = {
    "traditional1": ("sub", polynomial_algorithm(sub_functional(1), sub_functional(1), 0, 0)),
    "traditional2": ("sub", polynomial_algorithm(sub_functional(2), sub_functional(2), 1, 1)),
    "smoothing": ("multiple", polynomial_algorithm(multiple_functional(2), multiple_functional(2), 1, 1)),
    "invariant_accel1": ("multiple", accel_invariant(1, 2)),
    "invariant_accel0": ("multiple", accel_invariant(0, 1)),
    "invariant_rate1": ("multiple", rate_invariant(1, 2, 3)),
    "invariant_rate0": ("multiple", rate_invariant(0, 1, 2)),
}
DISPLACEMENT = {
    "traditional1": polynomial_algorithm(multiple_functional(1), multiple_functional(1), 0, 0, displacement_weight),
    "smoothing": polynomial_algorithm(multiple_functional(2), multiple_functional(2), 1, 1, displacement_weight),
    "invariant_accel1": accel_invariant(1, 2, displacement=True),
    "invariant_accel0": accel_invariant(0, 1, displacement=True),
    "invariant_rate1": rate_invariant(1, 2, 4, displacement=True),
    "invariant_rate0": rate_invariant(0, 1, 3, displacement=True),
}


def anti(K):
    """Coefficients of ΔΘ_i × ΔΘ_j, i < j, of a coning form."""
    n = len(K)
    return {(i, j): K[i][j] - K[j][i] for i in range(n) for j in range(i + 1, n)}


# --------------------------------------------------------------------------------------
# The printed coefficients (with docs/design.md §7 corrections) are what the derivation gives
# --------------------------------------------------------------------------------------


def test_polynomial_fits_are_the_printed_ones():
    # (2.1): A = (3ΔΘ1 − ΔΘ2)/T, B = 4(ΔΘ2 − ΔΘ1)/T²
    assert fit(sub_functional(2), 1) == [[3, -1], [-4, 4]]
    # (2.8): A = (11ΔΘ1 − 7ΔΘ2 + 2ΔΘ3)/(2T), B = 9(−2ΔΘ1 + 3ΔΘ2 − ΔΘ3)/T², C = 27(ΔΘ1 − 2ΔΘ2 + ΔΘ3)/T³
    assert fit(sub_functional(3), 2) == [[F(11, 2), F(-7, 2), 1], [-18, 27, -9], [27, -54, 27]]
    # (3.4) and (3.5), the smoothing fits to ΔΘ¹, ΔΘ², ΔΘ³
    assert fit(multiple_functional(3), 2) == [[3, -24, 60], [-24, 168, -360], [60, -360, 720]]
    assert fit(multiple_functional(2), 1) == [[-2, 6], [6, -12]]
    # the smoothing recentring of §3: A = Â + C T²/12 + D T³/30, B = B̂ − C T/2 − 3 D T²/20
    Lc = [row[:4] for row in multiple_functional(2, 4)]
    Fl = fit(multiple_functional(2), 1)
    est = [[sum(Fl[p][i] * Lc[i][q] for i in range(2)) for q in range(4)] for p in range(2)]
    assert est[0][2:] == [-F(1, 12), -F(1, 30)] and est[1][2:] == [F(1, 2), F(3, 20)]


def test_coning_coefficients():
    # (2.10): X (ΔΘ1 × ΔΘ3) + Y ΔΘ2 × (ΔΘ3 − ΔΘ1), X = 33/80, Y = 57/80
    assert anti(CONING["traditional3"][1]) == {(0, 1): F(57, 80), (0, 2): F(33, 80), (1, 2): F(57, 80)}
    assert anti(CONING["two_sample"][1]) == {(0, 1): F(2, 3)}
    # (3.7): (6/T²) ΔΘ¹×ΔΘ³ − (3/T) ΔΘ² × ((4/T²) ΔΘ³ − ΔΘ¹)
    assert anti(CONING["smoothing"][1]) == {(0, 1): -3, (0, 2): 6, (1, 2): -12}
    # (4.8) with 30/T³: 18 Θ1×Θ3 − (3/2) Θ2 × (44 Θ3 − 3 Θ1) − 30 (Θ1 − 6 Θ2 + 12 Θ3) × Θ4
    assert anti(CONING["invariant"][1]) == {(0, 1): F(-9, 2), (0, 2): 18, (0, 3): -30,
                                            (1, 2): -66, (1, 3): 180, (2, 3): -360}


def test_miller_coefficients_null_the_coning_series():
    """X, Y of (2.10) chosen to cancel the two lowest orders of the coning error [9]."""
    s13 = coning_series({(0, 2): F(1)}, "sub", 3, exact_part=False)
    s_y = coning_series({(0, 1): F(1), (1, 2): F(1)}, "sub", 3, exact_part=False)
    true = coning_series({}, "sub", 3)
    true = [-c for c in true]  # the exact correction's series
    # X s13 + Y s_y = true at orders x^2 and x^4 (first two non-zero)
    a, b, c, d = s13[2], s_y[2], s13[4], s_y[4]
    det = a * d - b * c
    X = (true[2] * d - b * true[4]) / det
    Y = (a * true[4] - c * true[2]) / det
    assert (X, Y) == (F(9, 20), F(27, 40))


def test_sculling_coefficients():
    # (2.4): ½ ΔΘ × ΔV
    assert SCULLING["traditional1"][1] == [[F(1, 2)]]
    # (2.3) with 2/3: ½(ΔΘ1+ΔΘ2)×(ΔV1+ΔV2) + (2/3)(ΔΘ1×ΔV2 − ΔΘ2×ΔV1)
    assert SCULLING["traditional2"][1] == [[F(1, 2), F(1, 2) + F(2, 3)], [F(1, 2) - F(2, 3), F(1, 2)]]
    # (3.6): ½ Θ¹×V¹ − (Θ¹×V² − Θ²×V¹)/T
    assert SCULLING["smoothing"][1] == [[F(1, 2), -1], [1, 0]]
    # (4.4): Θ¹×V¹ + 6(Θ² − (2/3)Θ¹)×V² − 12(Θ² − ½Θ¹)×V³
    assert SCULLING["invariant_accel1"][1] == [[1, -4, 6], [0, 6, -12]]
    # (4.5): Θ¹ × (V¹ − V²/T)
    assert SCULLING["invariant_accel0"][1] == [[1, -1]]
    # (4.6): −6 Θ² × (V² − (2/3)V¹) + 12 Θ³ × (V² − ½V¹)
    assert SCULLING["invariant_rate1"][1] == [[0, 0], [4, -6], [-6, 12]]
    # (4.7): Θ² × V¹ / T
    assert SCULLING["invariant_rate0"][1] == [[0], [1]]


def test_displacement_twins_coefficients():
    """Our δS_s formulas (5.4) as written in the kernel's comments."""
    assert DISPLACEMENT["traditional1"] == [[F(1, 6)]]
    assert DISPLACEMENT["smoothing"] == [[F(1, 15), F(-3, 10)], [F(1, 5), F(3, 5)]]
    assert DISPLACEMENT["invariant_accel1"] == [[0, 1, -8, 18], [0, 0, 12, -36]]
    assert DISPLACEMENT["invariant_accel0"] == [[0, 1, -2]]
    assert DISPLACEMENT["invariant_rate1"] == [[0, 0], [0, 0], [4, -6], [-12, 24]]
    assert DISPLACEMENT["invariant_rate0"] == [[0], [0], [1]]


# --------------------------------------------------------------------------------------
# The kernels implement exactly these forms (probed on unit vectors, any T)
# --------------------------------------------------------------------------------------

EX, EY = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])


def _T_power(form, i, j, extra=0):
    """Coefficient of input rows i, j scales as T^(−i−j) for multiple integrals."""
    return extra - (i + j) if form == "multiple" else extra


@pytest.mark.parametrize("T", [1.0, 0.37])
@pytest.mark.parametrize("name", list(CONING))
def test_coning_kernel_matches_derivation(name, T):
    form, K = CONING[name]
    info = sd.get_algorithm("coning", name)
    assert info.form == form and info.m_dtheta == len(K)
    for (i, j), coef in anti(K).items():
        inc = np.zeros((len(K), 3))
        inc[i], inc[j] = EX, EY
        got = sd.coning_correction(name, inc, T)
        expect = float(coef) * T ** _T_power(form, i, j)
        np.testing.assert_allclose(got, [0, 0, expect], rtol=1e-14, atol=1e-14 * abs(expect))


def test_miller_kernel():
    inc = np.zeros((3, 3))
    for (i, j), coef in {(0, 1): 27 / 40, (0, 2): 9 / 20, (1, 2): 27 / 40}.items():
        inc[:] = 0
        inc[i], inc[j] = EX, EY
        np.testing.assert_allclose(sd.coning_correction("traditional3_miller", inc, 0.1), [0, 0, coef], rtol=1e-15)
    assert np.all(sd.coning_correction("one_sample", np.ones((4, 1, 3)), 0.1) == 0.0)


def _probe(function, name, K, T, form, extra=0):
    for i in range(len(K)):
        for j in range(len(K[0])):
            th, v = np.zeros((len(K), 3)), np.zeros((len(K[0]), 3))
            th[i], v[j] = EX, EY
            expect = float(K[i][j]) * T ** _T_power(form, i, j, extra)
            np.testing.assert_allclose(function(name, th, v, T), [0, 0, expect], rtol=1e-14,
                                       atol=1e-14 * max(abs(expect), 1e-300), err_msg=f"{name} {i} {j}")


@pytest.mark.parametrize("T", [1.0, 0.37])
@pytest.mark.parametrize("name", list(SCULLING))
def test_sculling_kernel_matches_derivation(name, T):
    form, K = SCULLING[name]
    info = sd.get_algorithm("sculling", name)
    assert (info.form, info.m_dtheta, info.m_dv) == (form, len(K), len(K[0]))
    _probe(sd.sculling_correction, name, K, T, form)


@pytest.mark.parametrize("T", [1.0, 0.37])
@pytest.mark.parametrize("name", list(DISPLACEMENT))
def test_displacement_kernel_matches_derivation(name, T):
    K = DISPLACEMENT[name]
    info = sd.get_algorithm("displacement", name)
    assert (info.m_dtheta, info.m_dv) == (len(K), len(K[0]))
    _probe(sd.position_correction, name, K, T, "multiple", extra=1)


def _reference(K, th, v, T, form, extra=0):
    """Plain NumPy: Σ_ij K_ij T^p (th_i × v_j) over all intervals."""
    out = np.zeros((th.shape[0], 3))
    for i in range(len(K)):
        for j in range(len(K[0])):
            if K[i][j]:
                out += float(K[i][j]) * T ** _T_power(form, i, j, extra) * np.cross(th[:, i], v[:, j])
    return out


def test_kernels_against_plain_reference_on_random_input():
    rng = np.random.default_rng(5)
    T = 0.013
    th = rng.normal(size=(500, 4, 3)) * T ** np.arange(4)[:, None]
    v = rng.normal(size=(500, 4, 3)) * T ** np.arange(4)[:, None]

    def close(got, ref):  # cancellation between terms: tolerance on the scale of the result
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-13 * np.abs(ref).max())

    for name, (form, K) in CONING.items():
        x = th[:, :len(K)]
        close(sd.coning_correction(name, x, T), _reference(K, x, x, T, form))
    for name, (form, K) in SCULLING.items():
        a, b = th[:, :len(K)], v[:, :len(K[0])]
        close(sd.sculling_correction(name, a, b, T), _reference(K, a, b, T, form))
    for name, K in DISPLACEMENT.items():
        close(sd.position_correction(name, th, v, T), _reference(K, th, v, T, "multiple", 1))
    # rotation vector (1.11): total increment plus the correction
    np.testing.assert_allclose(sd.rotation_vector("smoothing", th, T), th[:, 0] + sd.coning_correction("smoothing", th, T))
    sub = th[:, :3]
    np.testing.assert_allclose(sd.rotation_vector("traditional3", sub, T),
                               sub.sum(axis=1) + sd.coning_correction("traditional3", sub, T))


# --------------------------------------------------------------------------------------
# Error formulas: exact series for the test motions and general-motion local errors
# --------------------------------------------------------------------------------------


def _series_of_inputs(form, m):
    """Inputs for e^{ixτ} as power series in x (real part, imaginary part), T = 1."""
    L = sub_functional(m, D + 2) if form == "sub" else multiple_functional(m, D + 2)
    out = []
    for row in L:
        re, im = [F(0)] * (D + 1), [F(0)] * (D + 1)
        for p in range(D + 1):  # i^p x^p
            (re if p % 2 == 0 else im)[p] += row[p] * (-1 if p % 4 in (2, 3) else 1)
        out.append((re, im))
    return out


def _mul(a, b):
    out = [F(0)] * (D + 1)
    for i, x in enumerate(a):
        if x:
            for j in range(D + 1 - i):
                out[i + j] += x * b[j]
    return out


def _one_minus_sinc():
    """1 − sin x / x."""
    s = [F(0)] * (D + 1)
    for n in range(2, D + 1, 2):
        s[n] = -F((-1) ** (n // 2), math.factorial(n + 1))
    return s


def coning_series(anti_coefs, form, m, exact_part=True):
    """(computed − exact) δΘ_c along the cone axis, over (α²ω_c/2)·T, as a series in x = ω_c T.

    Inputs carry the rotating rate iΩ sinα e^{iΩt}; (y_i × y_j)_z = Ω² sin²α Im(conj Y_i Y_j);
    the exact correction is ½ sin²α (x − sin x).
    """
    Y = _series_of_inputs(form, m)
    acc = [F(0)] * (D + 1)
    for (i, j), c in anti_coefs.items():
        (ar, ai), (br, bi) = Y[i], Y[j]
        im = [p - q for p, q in zip(_mul(ar, bi), _mul(ai, br))]
        acc = [s + c * t for s, t in zip(acc, im)]
    e = [F(0)] + [2 * c for c in acc[:-1]]  # × 2x (the Ω² over Ω·α²/2 normalisation)
    if exact_part:
        e = [p - q for p, q in zip(e, _one_minus_sinc())]
    return e


def sculling_series(K, form, m_w, m_a):
    """(computed − exact) mean δV_s along z, over (θ₀a₀/2)·T, as a series in x = ω₀T.

    ω_x = θ₀Ω Re e^{iΩt}, a_y = a₀ Re(−i e^{iΩt}); the phase mean of y_i,x y_j,y is
    ½ θ₀ a₀ Ω Re(i Y_i conj Y_j); the exact mean correction is (θ₀a₀/2)(1 − sin x/x) T.
    """
    Yw, Ya = _series_of_inputs(form, m_w), _series_of_inputs(form, m_a)
    acc = [F(0)] * (D + 1)
    for i in range(len(K)):
        for j in range(len(K[0])):
            if K[i][j]:
                (ar, ai), (br, bi) = Yw[i], Ya[j]
                re = [p - q for p, q in zip(_mul(ar, bi), _mul(ai, br))]  # Re(i a conj b)
                acc = [s + K[i][j] * t for s, t in zip(acc, re)]
    e = [F(0)] + acc[:-1]
    return [p - q for p, q in zip(e, _one_minus_sinc())]


def _leading(series):
    k = next(i for i, c in enumerate(series) if c != 0)
    return k, series[k]


# (order in x, coefficient): signs are computed − exact along the exact correction
CONING_DRIFT = {
    "one_sample": (2, F(-1, 6)),
    "two_sample": (4, F(-1, 480)),
    "traditional3": (4, F(1, 3240)),   # (2.12)
    "smoothing": (6, F(-1, 50400)),    # (3.11)
    "invariant": (6, F(-1, 100800)),   # (4.14)
}
SCULLING_ERROR = {
    "traditional1": (2, F(-1, 6)),        # (2.7)
    "traditional2": (4, F(-3, 1440)),     # (2.6)
    "smoothing": (4, F(-4, 1440)),        # (3.10)
    "invariant_accel1": (4, F(-1, 720)),  # (4.11)
    "invariant_rate1": (4, F(-1, 720)),   # (4.11)
    "invariant_accel0": (2, F(-1, 12)),   # (4.12)
    "invariant_rate0": (2, F(-1, 12)),    # (4.12)
}


@pytest.mark.parametrize("name", list(CONING_DRIFT))
def test_coning_drift_formulas_exact(name):
    form, K = CONING[name]
    assert _leading(coning_series(anti(K), form, len(K))) == CONING_DRIFT[name]
    assert sd.get_algorithm("coning", name).error_term == CONING_DRIFT[name]


def test_miller_coning_drift_exact():
    """(2.13): (α²ω_c/2)(ω_cT)⁶/102060 for X = 9/20, Y = 27/40."""
    coefs = {(0, 1): F(27, 40), (0, 2): F(9, 20), (1, 2): F(27, 40)}
    assert _leading(coning_series(coefs, "sub", 3)) == (6, F(-1, 102060))
    assert sd.get_algorithm("coning", "traditional3_miller").error_term == (6, F(-1, 102060))


@pytest.mark.parametrize("name", list(SCULLING_ERROR))
def test_sculling_error_formulas_exact(name):
    form, K = SCULLING[name]
    assert _leading(sculling_series(K, form, len(K), len(K[0]))) == SCULLING_ERROR[name]
    assert sd.get_algorithm("sculling", name).error_term == SCULLING_ERROR[name]


def _local_error(K, L_w, L_a, coning, weight=integral_weight):
    """Leading general-motion error: coefficients of c_p × c_q (c = A, B, C, ...)."""
    n = len(L_w[0])
    M = [[sum(L_w[i][p] * K[i][j] * L_a[j][q] for i in range(len(K)) for j in range(len(K[0])))
          - weight(p, q) * (F(1, 2) if coning else 1) for q in range(n)] for p in range(n)]
    terms = {}
    for p in range(6):
        for q in range(6):
            if coning and q <= p:
                continue
            c = M[p][q] - M[q][p] if coning else M[p][q]
            if c:
                terms.setdefault(p + q + 2, {})["ABCDEF"[p] + "ABCDEF"[q]] = c
    order = min(terms)
    return order, terms[order]


def test_general_motion_local_errors():
    """(2.5), (2.11), (3.8), (3.9), (4.9), (4.10), (4.13) and Miller's, as corrected
    (computed − exact; the paper prints (2.11), (3.9), (4.13) with the opposite sign)."""
    sub2, sub3 = sub_functional(2), sub_functional(3)
    mul = multiple_functional(4)
    # (2.11): T⁵/6480 A×D (no B×C term for the polynomial coefficients)
    assert _local_error(CONING["traditional3"][1], sub3, sub3, True) == (5, {"AD": F(-1, 6480)})
    # Miller: −T⁵/6480 (A×D + B×C), not T⁴/120 A×C as printed
    miller = [[0, F(27, 40), F(9, 20)], [0, 0, F(27, 40)], [0, 0, 0]]
    assert _local_error(miller, sub3, sub3, True) == (5, {"AD": F(-1, 6480), "BC": F(-1, 6480)})
    # (3.9) T⁷/100800 C×D and (4.13) T⁷/201600 C×D
    assert _local_error(CONING["smoothing"][1], mul[:3], mul[:3], True) == (7, {"CD": F(-1, 100800)})
    assert _local_error(CONING["invariant"][1], mul, mul, True) == (7, {"CD": F(-1, 201600)})
    # (2.5) for (2.3) with 2/3: T⁵/720 [C×B − B×C + ¼ D×A − ¼ A×D]
    assert _local_error(SCULLING["traditional2"][1], sub2, sub2, False) == (
        5, {"AD": F(-1, 2880), "BC": F(-1, 720), "CB": F(1, 720), "DA": F(1, 2880)})
    # (3.8): T⁵/720 [C×B − B×C]
    assert _local_error(SCULLING["smoothing"][1], mul[:2], mul[:2], False) == (5, {"BC": F(-1, 720), "CB": F(1, 720)})
    # (4.9): T⁵/720 C×B (printed 1/1440); (4.10): −T⁵/720 B×C (printed +1/1440)
    assert _local_error(SCULLING["invariant_accel1"][1], mul[:2], mul[:3], False) == (5, {"CB": F(1, 720)})
    assert _local_error(SCULLING["invariant_rate1"][1], mul[:3], mul[:2], False) == (5, {"BC": F(-1, 720)})


def test_displacement_twins_are_exact_for_their_models():
    """Each δS_s twin has no error below the order its model allows (T³ is δS_s's own
    leading order: the constant-model twins err at T⁴, the linear ones at T⁵)."""
    mul = multiple_functional(4)
    orders = {name: _local_error(K, mul[:len(K)], mul[:len(K[0])], False, displacement_weight)[0] + 1
              for name, K in DISPLACEMENT.items()}
    assert orders == {"traditional1": 4, "smoothing": 5, "invariant_accel1": 5, "invariant_accel0": 4,
                      "invariant_rate1": 5, "invariant_rate0": 5}


# --------------------------------------------------------------------------------------
# The jitted kernels on exact inputs reproduce the drift formulas (double precision)
# --------------------------------------------------------------------------------------


def _inputs(signal, info, t0, T, m):
    if info.form == "sub":
        return signal.sub_increments(t0, T, m)
    return signal.multiple_integrals(t0, T, max(m, 1))


@pytest.mark.parametrize("x", [0.1, 0.4])
def test_kernels_reproduce_coning_drift(x):
    motion = ConingMotion(half_angle_rad=0.02, rate_rad_s=2 * np.pi * 7.0)
    T = x / motion.rate_rad_s
    t0 = np.arange(6) * 0.731 * T
    scale = motion.error_scale
    formulas = dict(CONING_DRIFT, traditional3_miller=(6, F(-1, 102060)))
    for name, (order, coef) in formulas.items():
        info = sd.get_algorithm("coning", name)
        inc = _inputs(motion.omega_b, info, t0, T, info.m_dtheta)
        drift = (sd.coning_correction(name, inc, T)[:, 2] - motion.coning_integral_z(T)) / T
        np.testing.assert_allclose(drift / (scale * float(coef) * x**order), 1.0, atol=0.02, err_msg=name)


@pytest.mark.parametrize("x", [0.1, 0.4])
def test_kernels_reproduce_sculling_error(x):
    motion = ScullingMotion(angle_amplitude_rad=0.01, accel_amplitude_mps2=2.0, rate_rad_s=2 * np.pi * 5.0)
    T = x / motion.rate_rad_s
    period = 2 * np.pi / motion.rate_rad_s
    t0 = np.arange(8) * period / 8  # 8 equally spaced phases: the exact phase mean
    scale = motion.error_scale
    for name, (order, coef) in SCULLING_ERROR.items():
        info = sd.get_algorithm("sculling", name)
        th = _inputs(motion.omega_b, info, t0, T, info.m_dtheta)
        dv = _inputs(motion.specific_force_b, info, t0, T, info.m_dv)
        err = (sd.sculling_correction(name, th, dv, T)[:, 2].mean() - motion.sculling_integral_z_mean(T)) / T
        np.testing.assert_allclose(err / (scale * float(coef) * x**order), 1.0, atol=0.02, err_msg=name)


def test_invariant_algorithms_are_exact_for_any_other_factor():
    """(4.4), (4.5) are exact for any acceleration when the rate fits their model, (4.6),
    (4.7) for any rate when the acceleration does; (4.8) for a quadratic rate; likewise the
    δS_s twins. The exact integrals are by 64-point Gauss-Legendre quadrature."""
    from biso_cosim.strapdown.motions import HarmonicSignal

    T = 0.05
    nodes, weights = np.polynomial.legendre.leggauss(64)
    tau, w = 0.5 * T * (nodes + 1), 0.5 * T * weights
    wild = HarmonicSignal.of((0.3, -0.2, 0.5), [((1.0, 2j, -0.5), 97.0), ((0.2j, -0.7, 1.1), 233.0)])

    def poly(coefs):  # ω(τ) = Σ c_p τ^p / p!, its multiple integrals and running integral
        c = np.asarray(coefs, dtype=float)
        val = sum(c[p] * tau[:, None] ** p / math.factorial(p) for p in range(len(c)))
        run = sum(c[p] * tau[:, None] ** (p + 1) / math.factorial(p + 1) for p in range(len(c)))
        mi = np.array([sum(c[p] * T ** (p + r) / math.factorial(p + r) for p in range(len(c))) for r in range(1, 5)])
        return val, run, mi[None]

    rng = np.random.default_rng(3)
    lin = rng.normal(size=(2, 3)) * np.array([[1.0], [30.0]])  # linear model, large slope
    quad = rng.normal(size=(3, 3)) * np.array([[1.0], [30.0], [900.0]])
    # running integral of the wild signal from 0: ΔV¹ over [0, τ]
    wild_val = wild(tau)
    wild_run = np.array([wild.multiple_integrals([0.0], t, 1)[0, 0] for t in tau])
    wild_mi = wild.multiple_integrals([0.0], T, 4)

    def exact(alpha, a, displacement=False):
        f = np.cross(alpha, a) * (T - tau[:, None] if displacement else 1.0)
        return (w[:, None] * f).sum(axis=0)

    w_val, w_run, w_mi = poly(lin)
    for name in ("invariant_accel1",):
        np.testing.assert_allclose(sd.sculling_correction(name, w_mi, wild_mi, T)[0], exact(w_run, wild_val), rtol=1e-11)
        np.testing.assert_allclose(sd.position_correction(name, w_mi, wild_mi, T)[0],
                                   exact(w_run, wild_val, True), rtol=1e-10)
    a_val, _, a_mi = poly(lin)
    np.testing.assert_allclose(sd.sculling_correction("invariant_rate1", wild_mi, a_mi, T)[0],
                               exact(wild_run, a_val), rtol=1e-11)
    np.testing.assert_allclose(sd.position_correction("invariant_rate1", wild_mi, a_mi, T)[0],
                               exact(wild_run, a_val, True), rtol=1e-10)
    c_val, c_run, c_mi = poly(lin[:1])
    np.testing.assert_allclose(sd.sculling_correction("invariant_accel0", c_mi, wild_mi, T)[0], exact(c_run, wild_val), rtol=1e-11)
    np.testing.assert_allclose(sd.position_correction("invariant_accel0", c_mi, wild_mi, T)[0],
                               exact(c_run, wild_val, True), rtol=1e-10)
    np.testing.assert_allclose(sd.sculling_correction("invariant_rate0", wild_mi, c_mi, T)[0], exact(wild_run, c_val), rtol=1e-11)
    np.testing.assert_allclose(sd.position_correction("invariant_rate0", wild_mi, c_mi, T)[0],
                               exact(wild_run, c_val, True), rtol=1e-10)
    q_val, q_run, q_mi = poly(quad)
    for name in ("smoothing", "invariant"):
        np.testing.assert_allclose(sd.coning_correction(name, q_mi, T)[0], 0.5 * exact(q_run, q_val), rtol=1e-10)


# --------------------------------------------------------------------------------------
# Registry and bad input
# --------------------------------------------------------------------------------------


def test_registry_lists_every_name_of_the_issue():
    names = {q: [a.name for a in sd.list_algorithms(q)] for q in ("coning", "sculling", "displacement")}
    assert {"traditional3", "traditional3_miller", "smoothing", "invariant", "two_sample"} <= set(names["coning"])
    assert names["sculling"] == ["traditional1", "traditional2", "smoothing", "invariant_accel1",
                                 "invariant_accel0", "invariant_rate1", "invariant_rate0"]
    assert len(sd.list_algorithms()) == sum(len(v) for v in names.values())
    for a in sd.list_algorithms():
        assert a.input_description and a.equation


def test_bad_input_is_refused_with_clear_errors():
    inc = np.zeros((4, 3, 3))
    with pytest.raises(ValueError, match=r"unknown coning algorithm 'bogus'; known: one_sample, two_sample"):
        sd.coning_correction("bogus", inc, 0.1)
    with pytest.raises(ValueError, match="unknown sculling algorithm.*invariant_rate0"):
        sd.sculling_correction("invariant", inc, inc, 0.1)
    with pytest.raises(ValueError, match=r"multiple integrals ΔΘ¹..ΔΘ\^4 per interval \(m >= 4\), got m = 3"):
        sd.coning_correction("invariant", inc, 0.1)
    with pytest.raises(ValueError, match="exactly m = 2 sub-interval increments ΔΘ per interval, got m = 3"):
        sd.coning_correction("two_sample", inc, 0.1)
    with pytest.raises(ValueError, match=r"dv .*ΔV¹..ΔV\^3 .*got m = 2"):
        sd.sculling_correction("invariant_accel1", inc, inc[:, :2], 0.1)
    for bad_T in (0.0, -0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="T must be finite and > 0"):
            sd.coning_correction("smoothing", inc, bad_T)
    with pytest.raises(TypeError, match="T must be a real number"):
        sd.coning_correction("smoothing", inc, "0.1")
    with pytest.raises(TypeError, match="coning algorithm must be a name"):
        sd.coning_correction(3, inc, 0.1)
    with pytest.raises(ValueError, match=r"increments must have shape \(N, m, 3\)"):
        sd.coning_correction("smoothing", np.zeros((4, 3, 2)), 0.1)
    bad = inc.copy()
    bad[2, 1, 0] = np.nan
    with pytest.raises(ValueError, match="increments contains non-finite values \\(first in interval 2\\)"):
        sd.coning_correction("smoothing", bad, 0.1)
    with pytest.raises(ValueError, match="same intervals"):
        sd.sculling_correction("smoothing", inc, inc[:3], 0.1)
    with pytest.raises(TypeError, match="real numeric array"):
        sd.coning_correction("smoothing", inc.astype(complex), 0.1)


def test_single_interval_and_empty_batches():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3, 4, 3))
    np.testing.assert_array_equal(sd.coning_correction("invariant", x[1], 0.2), sd.coning_correction("invariant", x, 0.2)[1])
    assert sd.sculling_correction("smoothing", x[:0], x[:0], 0.2).shape == (0, 3)


def test_attitude_step_kernel_signature():
    """The kernel offered to estimators: q_wb(k+1) = q_wb(k) ∘ exp(ΔΘ + δΘ_c)."""
    from biso_cosim import frames

    rng = np.random.default_rng(2)
    q0 = frames.quat_normalize(rng.normal(size=4))
    inc = rng.normal(size=(4, 3)) * 0.01
    for name in ("one_sample", "traditional3", "invariant"):
        info = sd.get_algorithm("coning", name)
        rows = inc[:info.m_dtheta]
        q1 = np.array(_kernels._attitude_step(q0[0], q0[1], q0[2], q0[3], rows, 0.01, info.id))
        expect = frames.quat_multiply(q0, frames.quat_from_rotvec(sd.rotation_vector(name, rows, 0.01)))
        np.testing.assert_allclose(q1, expect, atol=1e-15)
