"""Multiple-integral strapdown algorithms of Litmanovich (2002).

Yu. A. Litmanovich, "Determination of the parameters of angular and translational motion
of a rigid body from inertial information in the form of increments of multiple integrals
of the measured quantities" (2002): coning (δΘ_c), sculling (δV_s) and position algorithms
in three families, traditional (polynomial models fitted to sub-interval increments),
"smoothing" (the same models fitted to the multiple integrals ΔΘ^r, ΔV^r) and "invariant"
(quadratures that expand only one factor of the integrand), and the exact position update
(5.2).

Notation, once for the package: T the update interval (s); ΔΘ_j, ΔV_j the m ordinary
sub-interval increments (rad, m/s); ΔΘ^r, ΔV^r the r-fold iterated integrals of body rate
and specific force over T (eq. (1.14); ΔΘ¹ = ΔΘ; units rad·s^(r−1), m/s·s^(r−1)). Increment
arrays are (N, m, 3): N intervals, m rows (sub-intervals, or orders r = 1..m), body axes.
The formulas are frame-free vector formulas; the navigator uses the package conventions
(world ENU, ``q_wb`` Hamilton scalar-first, body x forward y left z up).

Printed formulas that are wrong and what we use instead are in docs/design.md §7 and in each
kernel's comment; ``list_algorithms()`` lists names, equations and input forms.

Public API:

* :func:`coning_correction`, :func:`sculling_correction`, :func:`position_correction`,
  :func:`rotation_vector`: batch corrections per interval;
* :func:`list_algorithms`, :func:`get_algorithm`: the registry;
* :class:`StrapdownNavigator` (streaming), :func:`navigate` (batch), with
  :class:`NavigatorParams`, :class:`NavigatorState`, :class:`NavigatorOutput`;
* :mod:`biso_cosim.strapdown.motions`: analytic coning, sculling and harmonic test signals
  with exact multiple integrals.

For use inside other numba kernels (e.g. as an estimator's gyro step):
``biso_cosim.strapdown._kernels._attitude_step(qw, qx, qy, qz, increments, T, coning_id)``
returns the next q_wb as a 4-tuple; ``get_algorithm("coning", name).id`` gives the id.
"""

from biso_cosim.strapdown.algorithms import (
    AlgorithmInfo,
    coning_correction,
    get_algorithm,
    list_algorithms,
    position_correction,
    rotation_vector,
    sculling_correction,
)
from biso_cosim.strapdown.navigator import (
    NavigatorOutput,
    NavigatorParams,
    NavigatorState,
    StrapdownNavigator,
    navigate,
)

__all__ = [
    "AlgorithmInfo",
    "coning_correction",
    "sculling_correction",
    "position_correction",
    "rotation_vector",
    "list_algorithms",
    "get_algorithm",
    "StrapdownNavigator",
    "NavigatorParams",
    "NavigatorState",
    "NavigatorOutput",
    "navigate",
]
