"""Coning, sculling and displacement corrections of Litmanovich (2002), batch over intervals.

The registry below is the single description of every algorithm (name, equation, input
form, rows needed, error on the test motion); :func:`list_algorithms` returns it, and the
docs table, the CLI help and the reproduction report are drawn from it.

Input forms (docs/design.md §7 notation):

* ``"sub"``: the m sub-interval increments ΔΘ_1..ΔΘ_m (ΔV_1..ΔV_m) of equal length T/m,
  ordinary gyro/accelerometer outputs; the array must have exactly the m the algorithm
  takes (m = 1: the increment over the whole interval).
* ``"multiple"``: the multiple integrals ΔΘ¹..ΔΘ^m (ΔV¹..) over T, eq. (1.14), row r−1
  holding the r-fold integral (units rad·s^(r−1), m/s·s^(r−1)); at least the rows the
  algorithm uses, extra rows (e.g. the four a virtual MPU-9250 delivers) are ignored.

Error formulas are for the paper's test motions: coning of half-angle α at ω_c (drift ε
along the cone axis) and sculling of amplitudes θ₀, a₀ at ω₀ (mean acceleration error ΔW),
leading term in ω·T, as corrected in docs/design.md §7 and re-derived in the tests. The paper
prints magnitudes; our sign is that of (computed − exact) along the exact correction, so a
negative error means the algorithm under-compensates coning or sculling.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from biso_cosim.strapdown import _kernels as K

__all__ = [
    "AlgorithmInfo",
    "list_algorithms",
    "get_algorithm",
    "coning_correction",
    "sculling_correction",
    "position_correction",
    "rotation_vector",
]

QUANTITIES = ("coning", "sculling", "displacement")


@dataclass(frozen=True)
class AlgorithmInfo:
    """One algorithm of the registry.

    ``m_dtheta`` / ``m_dv``: rows of ΔΘ / ΔV per interval, exactly for the ``"sub"`` form,
    at least for the ``"multiple"`` form (0: not used). ``error_term`` (n, c): the leading
    error on the paper's test motion, ε = (α²ω_c/2)·c·(ω_cT)^n for coning, ΔW =
    (θ₀a₀/2)·c·(ω₀T)^n for sculling (None for the δS_s twins); ``error_equation`` the
    paper's number for it. ``correction``: how our formula differs from the printed one.
    """

    name: str
    quantity: str
    id: int
    equation: str
    form: str
    m_dtheta: int
    m_dv: int
    model: str
    error_term: tuple[int, Fraction] | None = None
    error_equation: str = ""
    correction: str = ""

    @property
    def error(self) -> str | None:
        """The leading error as a formula, e.g. ``ε = −(α²ω_c/2)(ω_cT)⁶/100800 (4.14)``."""
        if self.error_term is None:
            return None
        n, c = self.error_term
        sign = "−" if c < 0 else ""
        power = str(n).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))
        frac = f"/{abs(c.denominator)}" if abs(c.numerator) == 1 else f"·{abs(c)}"
        if self.quantity == "coning":
            text = f"ε = {sign}(α²ω_c/2)(ω_cT){power}{frac}"
        else:
            text = f"ΔW = {sign}(θ₀a₀/2)(ω₀T){power}{frac}"
        return f"{text} {self.error_equation}".rstrip()

    @property
    def input_description(self) -> str:
        """The input form in words, e.g. for CLI help and error messages."""
        def rows(m: int, symbol: str) -> str:
            if self.form == "sub":
                return f"{m} sub-interval increment{'s' if m > 1 else ''} {symbol}"
            return f"multiple integrals {symbol}¹..{symbol}^{m} (m ≥ {m})"

        parts = [rows(self.m_dtheta, "ΔΘ")]
        if self.m_dv:
            parts.append(rows(self.m_dv, "ΔV"))
        return "; ".join(parts)


def _coning(name, id_, equation, form, m, model, error_term, error_equation="", correction=""):
    return AlgorithmInfo(name, "coning", id_, equation, form, m, 0, model, error_term, error_equation, correction)


def _sculling(name, id_, equation, form, m_dtheta, m_dv, model, error_term, error_equation, correction=""):
    return AlgorithmInfo(name, "sculling", id_, equation, form, m_dtheta, m_dv, model, error_term,
                         error_equation, correction)


def _twin(name, id_, m_dtheta, m_dv, model):
    return AlgorithmInfo(name, "displacement", id_, "(5.4), ours", "multiple", m_dtheta, m_dv, model)


_CONING = (
    _coning("one_sample", K.CONING_ONE_SAMPLE, "(1.11) with δΘ_c = 0", "sub", 1,
            "constant rate, no coning correction (baseline)", (2, Fraction(-1, 6))),
    _coning("two_sample", K.CONING_TWO_SAMPLE, "classic (Miller 1983)", "sub", 2,
            "linear rate, 2 samples: (2/3) ΔΘ1 × ΔΘ2", (4, Fraction(-1, 480))),
    _coning("traditional3", K.CONING_TRADITIONAL3, "(2.10)", "sub", 3,
            "quadratic rate, 3 samples, X = 33/80, Y = 57/80", (4, Fraction(1, 3240)), "(2.12)"),
    _coning("traditional3_miller", K.CONING_TRADITIONAL3_MILLER, "(2.10)", "sub", 3,
            "3 samples optimised for coning, X = 9/20, Y = 27/40", (6, Fraction(-1, 102060)), "(2.13)",
            "general-motion error −T⁵/6480 (A×D + B×C), not the printed T⁴/120 (A×C)"),
    _coning("smoothing", K.CONING_SMOOTHING, "(3.7)", "multiple", 3,
            "quadratic rate fitted to ΔΘ¹..ΔΘ³ (3.4)", (6, Fraction(-1, 50400)), "(3.11)"),
    _coning("invariant", K.CONING_INVARIANT, "(4.8)", "multiple", 4,
            "quadratic rate at the interval end in the quadrature (4.3)", (6, Fraction(-1, 100800)), "(4.14)",
            "last term (30/T³)(…) × ΔΘ⁴, printed 30/T²; (4.3) needs a factor ½"),
)

_SCULLING = (
    _sculling("traditional1", K.SCULLING_TRADITIONAL1, "(2.4)", "sub", 1, 1,
              "constant rate and acceleration", (2, Fraction(-1, 6)), "(2.7)"),
    _sculling("traditional2", K.SCULLING_TRADITIONAL2, "(2.3)", "sub", 2, 2,
              "linear rate and acceleration, 2 samples", (4, Fraction(-3, 1440)), "(2.6)",
              "coefficient 2/3, printed 1/3"),
    _sculling("smoothing", K.SCULLING_SMOOTHING, "(3.6)", "multiple", 2, 2,
              "linear rate and acceleration fitted by (3.5)", (4, Fraction(-4, 1440)), "(3.10)"),
    _sculling("invariant_accel1", K.SCULLING_INVARIANT_ACCEL1, "(4.4)", "multiple", 2, 3,
              "acceleration-invariant, linear rate", (4, Fraction(-1, 720)), "(4.11)",
              "local error T⁵/720 C_ω×B_a (4.9), printed T⁵/1440"),
    _sculling("invariant_accel0", K.SCULLING_INVARIANT_ACCEL0, "(4.5)", "multiple", 1, 2,
              "acceleration-invariant, constant rate", (2, Fraction(-1, 12)), "(4.12)"),
    _sculling("invariant_rate1", K.SCULLING_INVARIANT_RATE1, "(4.6)", "multiple", 3, 2,
              "rate-invariant, linear acceleration", (4, Fraction(-1, 720)), "(4.11)",
              "local error −T⁵/720 B_ω×C_a (4.10), printed +T⁵/1440"),
    _sculling("invariant_rate0", K.SCULLING_INVARIANT_RATE0, "(4.7)", "multiple", 2, 1,
              "rate-invariant, constant acceleration", (2, Fraction(-1, 12)), "(4.12)"),
)

# δS_s twins of the sculling algorithms (ours: the paper names the approach, §5, but prints
# no formula). m_dv counts what δS_s uses; (5.2) itself needs ΔV² in any case.
_DISPLACEMENT = (
    _twin("traditional1", K.SCULLING_TRADITIONAL1, 1, 1, "constant rate and acceleration: (T/6) ΔΘ¹ × ΔV¹"),
    _twin("smoothing", K.SCULLING_SMOOTHING, 2, 2, "linear rate and acceleration fitted by (3.5)"),
    _twin("invariant_accel1", K.SCULLING_INVARIANT_ACCEL1, 2, 4, "acceleration-invariant, linear rate"),
    _twin("invariant_accel0", K.SCULLING_INVARIANT_ACCEL0, 1, 3, "acceleration-invariant, constant rate"),
    _twin("invariant_rate1", K.SCULLING_INVARIANT_RATE1, 4, 2, "rate-invariant, linear acceleration"),
    _twin("invariant_rate0", K.SCULLING_INVARIANT_RATE0, 3, 1, "rate-invariant, constant acceleration"),
)

_REGISTRY = {
    "coning": {a.name: a for a in _CONING},
    "sculling": {a.name: a for a in _SCULLING},
    "displacement": {a.name: a for a in _DISPLACEMENT},
}


def list_algorithms(quantity: str | None = None) -> tuple[AlgorithmInfo, ...]:
    """The available algorithms, optionally of one ``quantity`` ("coning", "sculling",
    "displacement"), with their equation, input form and rows needed."""
    if quantity is None:
        return _CONING + _SCULLING + _DISPLACEMENT
    return tuple(_registry(quantity).values())


def get_algorithm(quantity: str, name: str) -> AlgorithmInfo:
    """The registry entry of ``name``; an unknown name is a ``ValueError`` listing the known ones."""
    table = _registry(quantity)
    if not isinstance(name, str):
        raise TypeError(f"{quantity} algorithm must be a name (str), got {type(name).__name__}")
    if name not in table:
        raise ValueError(f"unknown {quantity} algorithm {name!r}; known: {', '.join(table)}")
    return table[name]


def _registry(quantity: str) -> dict[str, AlgorithmInfo]:
    if quantity not in _REGISTRY:
        raise ValueError(f"quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    return _REGISTRY[quantity]


# --------------------------------------------------------------------------------------
# Validation shared with the navigator
# --------------------------------------------------------------------------------------


def check_interval(T, name: str = "T") -> float:
    """``T`` as a float; it must be a finite real number > 0 (seconds)."""
    if isinstance(T, bool) or not isinstance(T, numbers.Real):
        raise TypeError(f"{name} must be a real number of seconds, got {type(T).__name__}")
    value = float(T)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be finite and > 0 s, got {value!r}")
    return value


def as_increments(array, name: str) -> tuple[np.ndarray, bool]:
    """``array`` as a C-contiguous float64 (N, m, 3) array and whether it was one (m, 3)
    interval; non-numeric, wrongly shaped or non-finite input is refused."""
    a = np.asarray(array)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be a real numeric array, got dtype {a.dtype}")
    single = a.ndim == 2
    if a.ndim not in (2, 3) or a.shape[-1] != 3 or a.shape[-2] < 1:
        raise ValueError(f"{name} must have shape (N, m, 3) or (m, 3) with m >= 1, got {a.shape}")
    a = np.ascontiguousarray(a.reshape((-1,) + a.shape[-2:]), dtype=np.float64)
    if not np.isfinite(a.reshape(-1)).all():  # fast path first; locate only on failure
        first = int(np.argmin(np.isfinite(a).all(axis=(1, 2))))
        raise ValueError(f"{name} contains non-finite values (first in interval {first})")
    return a, single


def check_rows(info: AlgorithmInfo, name: str, m: int, needed: int, symbol: str) -> None:
    """Refuse an increment array whose m does not fit the algorithm, saying what it needs."""
    if info.form == "sub" and m != needed:
        raise ValueError(
            f"{name} for {info.quantity} algorithm {info.name!r} must hold exactly m = {needed} "
            f"sub-interval increment{'s' if needed > 1 else ''} {symbol} per interval, got m = {m}"
        )
    if info.form == "multiple" and m < needed:
        raise ValueError(
            f"{name} for {info.quantity} algorithm {info.name!r} must hold the multiple integrals "
            f"{symbol}¹..{symbol}^{needed} per interval (m >= {needed}), got m = {m}"
        )


def _pair(info: AlgorithmInfo, dtheta, dv) -> tuple[np.ndarray, np.ndarray, bool]:
    th, single_th = as_increments(dtheta, "dtheta")
    v, single_v = as_increments(dv, "dv")
    if single_th != single_v or th.shape[0] != v.shape[0]:
        raise ValueError(f"dtheta and dv must cover the same intervals, got shapes "
                         f"{np.shape(dtheta)} and {np.shape(dv)}")
    check_rows(info, "dtheta", th.shape[1], info.m_dtheta, "ΔΘ")
    check_rows(info, "dv", v.shape[1], info.m_dv, "ΔV")
    return th, v, single_th


# --------------------------------------------------------------------------------------
# Public batch functions
# --------------------------------------------------------------------------------------


def coning_correction(algorithm: str, increments, T: float) -> np.ndarray:
    """Coning correction δΘ_c (rad) of each interval, eq. (1.12), shape (N, 3).

    Parameters
    ----------
    algorithm:
        ``one_sample``, ``two_sample``, ``traditional3`` (2.10), ``traditional3_miller``
        (2.10), ``smoothing`` (3.7) or ``invariant`` (4.8); see :func:`list_algorithms`.
    increments:
        (N, m, 3) gyro increments of each interval in the algorithm's input form: m
        sub-interval increments ΔΘ_j (rad) for the traditional algorithms, the multiple
        integrals ΔΘ¹..ΔΘ^m (rad·s^(r−1)) for ``smoothing`` (m ≥ 3) and ``invariant``
        (m ≥ 4). One interval may be given as (m, 3); the result is then (3,).
    T:
        The update interval in s (> 0).

    Raises ``ValueError`` for an unknown name (listing the known ones), an m that does not
    fit the algorithm (saying the m it needs), non-finite increments or T <= 0.
    """
    info = get_algorithm("coning", algorithm)
    T = check_interval(T)
    inc, single = as_increments(increments, "increments")
    check_rows(info, "increments", inc.shape[1], info.m_dtheta, "ΔΘ")
    out = np.empty((inc.shape[0], 3))
    K._batch_coning(info.id, inc, T, out)
    return out[0] if single else out


def rotation_vector(algorithm: str, increments, T: float) -> np.ndarray:
    """Rotation vector Φ = ΔΘ + δΘ_c of each interval, eq. (1.11), shape (N, 3).

    Arguments as :func:`coning_correction`; ΔΘ is the sum of the sub-interval increments,
    or ΔΘ¹ for the multiple-integral algorithms.
    """
    info = get_algorithm("coning", algorithm)
    inc, single = as_increments(increments, "increments")
    total = inc[:, 0, :] if info.form == "multiple" else inc.sum(axis=1)
    out = total + coning_correction(algorithm, inc, T)
    return out[0] if single else out


def sculling_correction(algorithm: str, dtheta, dv, T: float) -> np.ndarray:
    """Sculling correction δV_s (m/s) of each interval, eq. (1.8), shape (N, 3).

    Parameters
    ----------
    algorithm:
        ``traditional1`` (2.4), ``traditional2`` (2.3), ``smoothing`` (3.6),
        ``invariant_accel1`` (4.4), ``invariant_accel0`` (4.5), ``invariant_rate1`` (4.6),
        ``invariant_rate0`` (4.7); see :func:`list_algorithms` for the rows each needs.
    dtheta, dv:
        (N, m, 3) gyro and accelerometer increments of the same N intervals in the
        algorithm's input form (sub-interval increments for ``traditional*``, multiple
        integrals otherwise; the two m may differ). (m, 3) for a single interval.
    T:
        The update interval in s (> 0).

    Raises ``ValueError`` as :func:`coning_correction`, and when dtheta and dv cover
    different numbers of intervals.
    """
    info = get_algorithm("sculling", algorithm)
    T = check_interval(T)
    th, v, single = _pair(info, dtheta, dv)
    out = np.empty((th.shape[0], 3))
    K._batch_sculling(info.id, th, v, T, out)
    return out[0] if single else out


def position_correction(algorithm: str, dtheta, dv, T: float) -> np.ndarray:
    """Displacement correction δS_s (m) of each interval, eq. (5.4), shape (N, 3).

    δS_s = ∫∫ ΔΘ(t_k, τ) × a(τ) dτ dt completes the exact position update (5.2):
    S(k+1) = S(k) + V(k) T + C(k)[ΔV² + δS_s] (+ g T²/2 in a gravity field). The paper
    prints no algorithm for it; ours are the twins of the sculling algorithms of the same
    name (same models, same derivation), taking multiple integrals: ``traditional1``,
    ``smoothing``, ``invariant_accel1`` (ΔV¹..ΔV⁴), ``invariant_accel0``, ``invariant_rate1``
    (ΔΘ¹..ΔΘ⁴), ``invariant_rate0``. Arguments and errors as :func:`sculling_correction`.
    """
    info = get_algorithm("displacement", algorithm)
    T = check_interval(T)
    th, v, single = _pair(info, dtheta, dv)
    out = np.empty((th.shape[0], 3))
    K._batch_displacement(info.id, th, v, T, out)
    return out[0] if single else out
