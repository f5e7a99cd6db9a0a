"""Strapdown navigator on gyro and accelerometer increments (Litmanovich 2002, §1 and §5).

Per update interval T, from the state at t_k (attitude q_wb(k), velocity V(k), position S(k)):

* attitude: rotation vector Φ = ΔΘ + δΘ_c (1.11), ``q_wb(k+1) = q_wb(k) ∘ exp(Φ)``;
* velocity: ``V(k+1) = V(k) + C(k)[ΔV + δV_s] + g T`` (1.3), (1.6);
* position: ``S(k+1) = S(k) + V(k) T`` (rectangle, 5.1), ``+ ½(V(k) + V(k+1)) T``
  (trapezoid), or the exact form ``S(k) + V(k) T + C(k)[ΔV² + δS_s] + g T²/2`` (5.2)
  with δS_s (5.4) (printed with V̇(k) for V(k), docs/design.md §7).

Frames: world w is ENU and treated as inertial (flat, non-rotating Earth: right for the
MuJoCo world; the Earth rate, 15 °/h, is below the MPU-9250's gyro noise); b is the frame
of the increments (the vehicle body frame x forward, y left, z up, when the sensor's
mounting has been applied). ``q_wb`` maps b to w. ΔV are increments of specific force (an
accelerometer at rest reads +g up); gravity ``gravity_w`` defaults to (0, 0, −9.80665) m/s².
The velocity and position updates are those of the paper: first order in the rotation
within one interval (C(t) ≈ C(k)(I + [ΔΘ(t_k, t)×])), which is what (1.6) and (5.3)-(5.4)
assume.

Streaming: :meth:`StrapdownNavigator.update` takes one chunk of intervals and continues
where the previous call stopped; the whole state is readable and restorable
(:meth:`~StrapdownNavigator.get_state`, :meth:`~StrapdownNavigator.set_state`). One call on
all intervals (:func:`navigate`) and any split into chunks give identical results, bit for
bit, since both run the same per-interval kernel on the same state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from biso_cosim.strapdown import _kernels as K
from biso_cosim.strapdown.algorithms import (
    AlgorithmInfo,
    as_increments,
    check_interval,
    get_algorithm,
)
from biso_cosim.units import G0

__all__ = ["NavigatorParams", "NavigatorState", "NavigatorOutput", "StrapdownNavigator", "navigate"]

POSITION_METHODS = {"rectangle": K.POSITION_RECTANGLE, "trapezoid": K.POSITION_TRAPEZOID, "exact": K.POSITION_EXACT}
INPUT_FORMS = ("sub", "multiple")


def _doc(symbol: str, unit: str, doc: str, source: str = "") -> dict:
    """Field metadata: the one description of a parameter (docs table, CLI help, FMU)."""
    return {"symbol": symbol, "unit": unit, "doc": doc, "source": source}


@dataclass(frozen=True)
class NavigatorParams:
    """Settings of a :class:`StrapdownNavigator` (checked on construction)."""

    interval_s: float = field(metadata=_doc(
        "T", "s", "update interval: one row of dtheta / dv per interval", "Litmanovich (2002) §1"))
    coning: str = field(default="invariant", metadata=_doc(
        "", "", "coning algorithm for δΘ_c (list_algorithms('coning'))", "(1.11), (1.12)"))
    sculling: str = field(default="invariant_rate1", metadata=_doc(
        "", "", "sculling algorithm for δV_s, and its δS_s twin for exact position", "(1.6), (1.8), (5.4)"))
    position: str = field(default="exact", metadata=_doc(
        "", "", "position update: 'rectangle' (5.1), 'trapezoid', 'exact' (5.2)", "(5.1), (5.2)"))
    input_form: str | None = field(default=None, metadata=_doc(
        "", "", "'sub' (sub-interval increments) or 'multiple' (multiple integrals); "
        "None: the form the algorithms take ('sub' when all are one-sample)", "(1.14)"))
    gravity_w: tuple[float, float, float] = field(default=(0.0, 0.0, -G0), metadata=_doc(
        "g", "m/s²", "gravity in the world frame (ENU), constant", "units.G0"))

    def __post_init__(self) -> None:
        object.__setattr__(self, "interval_s", check_interval(self.interval_s, "interval_s"))
        g = np.asarray(self.gravity_w, dtype=np.float64) if not isinstance(self.gravity_w, str) else None
        if g is None or g.shape != (3,) or not np.isfinite(g).all():
            raise ValueError(f"gravity_w must be 3 finite numbers in m/s² (ENU), got {self.gravity_w!r}")
        object.__setattr__(self, "gravity_w", tuple(float(x) for x in g))
        if self.position not in POSITION_METHODS:
            raise ValueError(f"unknown position method {self.position!r}; known: {', '.join(POSITION_METHODS)}")
        if self.input_form is not None and self.input_form not in INPUT_FORMS:
            raise ValueError(f"input_form must be 'sub', 'multiple' or None, got {self.input_form!r}")
        _setup(self)  # refuses names and combinations that cannot work together


@dataclass(frozen=True)
class _Setup:
    """Derived from the parameters once: kernel ids, input form, rows each array needs
    (``rows_*``: exact count for the 'sub' form, None = any; minimum for 'multiple')."""

    coning: AlgorithmInfo
    sculling: AlgorithmInfo
    position_id: int
    multiple: bool
    rows_dtheta: int | None
    rows_dv: int | None
    gravity_w: np.ndarray


def _one_sample(info: AlgorithmInfo) -> bool:
    return info.form == "sub" and info.m_dtheta == 1


def _setup(params: NavigatorParams) -> _Setup:
    coning = get_algorithm("coning", params.coning)
    sculling = get_algorithm("sculling", params.sculling)
    exact = params.position == "exact"
    form = params.input_form
    if form is None:
        needs_multiple = exact or coning.form == "multiple" or sculling.form == "multiple"
        form = "multiple" if needs_multiple else "sub"
    if form == "multiple":
        for info in (coning, sculling):
            if info.form == "sub" and not _one_sample(info):
                raise ValueError(
                    f"{info.quantity} algorithm {info.name!r} takes sub-interval increments, but the "
                    f"navigator's input is multiple integrals (input_form={params.input_form!r}, "
                    f"position={params.position!r}); choose a one-sample, smoothing or invariant algorithm")
        twin = get_algorithm("displacement", sculling.name) if exact else None
        rows_dtheta = max(coning.m_dtheta, sculling.m_dtheta, twin.m_dtheta if twin else 1)
        rows_dv = max(sculling.m_dv, twin.m_dv if twin else 1, 2 if exact else 1)
    else:
        if exact:
            raise ValueError("position='exact' (5.2) needs ΔV², i.e. input_form='multiple'")
        for info in (coning, sculling):
            if info.form == "multiple":
                raise ValueError(f"{info.quantity} algorithm {info.name!r} takes multiple integrals, "
                                 "but input_form='sub'")
        sub_m = {info.m_dtheta for info in (coning, sculling) if not _one_sample(info)}
        if len(sub_m) > 1:
            raise ValueError(f"coning algorithm {coning.name!r} and sculling algorithm {sculling.name!r} "
                             f"take different numbers of sub-interval increments ({sorted(sub_m)})")
        rows_dtheta = sub_m.pop() if sub_m else None
        rows_dv = None if _one_sample(sculling) else sculling.m_dv
    return _Setup(coning, sculling, POSITION_METHODS[params.position], form == "multiple",
                  rows_dtheta, rows_dv, np.array(params.gravity_w))


@dataclass(frozen=True, eq=False)
class NavigatorState:
    """The whole state of a navigator after ``steps`` intervals from ``t0_s``.

    ``q_wb`` (4,) unit quaternion (w, x, y, z); ``v_w`` (3,) velocity in m/s and ``p_w``
    (3,) position in m, world frame (ENU). The time is ``t0_s + steps * interval_s``,
    kept as a count so that chunked and single calls agree bit for bit.
    """

    q_wb: np.ndarray
    v_w: np.ndarray
    p_w: np.ndarray
    t0_s: float = 0.0
    steps: int = 0

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, NavigatorState) and self.t0_s == other.t0_s and self.steps == other.steps
                and all(np.array_equal(getattr(self, n), getattr(other, n)) for n in ("q_wb", "v_w", "p_w")))

    __hash__ = None


@dataclass(frozen=True)
class NavigatorOutput:
    """The navigation solution at the end of each interval of one ``update`` call.

    ``t_s`` (k,) s; ``q_wb`` (k, 4); ``v_w`` (k, 3) m/s; ``p_w`` (k, 3) m (world ENU).
    """

    t_s: np.ndarray
    q_wb: np.ndarray
    v_w: np.ndarray
    p_w: np.ndarray


def _vector(name: str, value, size: int) -> np.ndarray:
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be {size} real numbers, got {value!r}") from None
    if a.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite, got {a}")
    return a


def _check_state(state: NavigatorState) -> NavigatorState:
    if not isinstance(state, NavigatorState):
        raise TypeError(f"state must be a NavigatorState, got {type(state).__name__}")
    q = _vector("state.q_wb", state.q_wb, 4)
    norm = float(np.linalg.norm(q))
    if norm == 0.0:
        raise ValueError("state.q_wb must be non-zero")
    t0 = float(state.t0_s)
    if not math.isfinite(t0):
        raise ValueError(f"state.t0_s must be finite, got {state.t0_s!r}")
    if isinstance(state.steps, bool) or not isinstance(state.steps, (int, np.integer)) or state.steps < 0:
        raise ValueError(f"state.steps must be an integer >= 0, got {state.steps!r}")
    return NavigatorState(q / norm, _vector("state.v_w", state.v_w, 3), _vector("state.p_w", state.p_w, 3),
                          t0, int(state.steps))


class StrapdownNavigator:
    """Dead-reckoning navigator on increments, streaming (see the module docstring).

    Parameters
    ----------
    params:
        :class:`NavigatorParams` (interval, algorithms, position method, gravity).
    q_wb, v_w, p_w, t_s:
        Initial attitude (w, x, y, z), velocity (m/s, ENU), position (m, ENU) and time (s) at
        the start of the first interval, e.g. the true state when used as a reference
        dead-reckoning navigator in the co-simulation.

    Input policy: every ``update`` is checked whole before anything is integrated; a
    wrong shape, an m that does not fit the algorithms, or a non-finite value is refused
    with a ``ValueError`` and the navigator keeps its state, ready for the next call.
    """

    def __init__(self, params: NavigatorParams, *, q_wb=(1.0, 0.0, 0.0, 0.0), v_w=(0.0, 0.0, 0.0),
                 p_w=(0.0, 0.0, 0.0), t_s: float = 0.0):
        if not isinstance(params, NavigatorParams):
            raise TypeError(f"params must be a NavigatorParams, got {type(params).__name__}")
        self._params = params
        self._setup = _setup(params)
        self._state = _check_state(NavigatorState(q_wb, v_w, p_w, t_s, 0))

    @property
    def params(self) -> NavigatorParams:
        return self._params

    @property
    def t_s(self) -> float:
        """Time at the end of the last interval integrated (s)."""
        return self._state.t0_s + self._state.steps * self._params.interval_s

    @property
    def input_form(self) -> str:
        """'sub' or 'multiple': what ``update`` expects in dtheta and dv."""
        return "multiple" if self._setup.multiple else "sub"

    def get_state(self) -> NavigatorState:
        """A copy of the whole state."""
        s = self._state
        return NavigatorState(s.q_wb.copy(), s.v_w.copy(), s.p_w.copy(), s.t0_s, s.steps)

    def set_state(self, state: NavigatorState) -> None:
        """Restore a state from :meth:`get_state` (or build one, e.g. from the truth)."""
        self._state = _check_state(state)

    def update(self, dtheta, dv) -> NavigatorOutput:
        """Integrate k intervals; ``dtheta``, ``dv`` (k, m, 3) in the navigator's input form.

        'sub': the sub-interval increments ΔΘ_j (rad) and ΔV_j (m/s) of each interval, m as
        the algorithms take (any m for one-sample algorithms, which use the sums);
        'multiple': the multiple integrals ΔΘ^r, ΔV^r of each interval, r = 1..m, at least
        the rows the algorithms need (``invariant`` coning and exact position with
        ``invariant_rate1`` need 4 of ΔΘ; ``invariant_accel1`` needs 4 of ΔV).
        """
        setup = self._setup
        th, single_th = as_increments(dtheta, "dtheta")
        v, single_v = as_increments(dv, "dv")
        if single_th or single_v:
            raise ValueError(f"dtheta and dv must have shape (k, m, 3), got {np.shape(dtheta)} and {np.shape(dv)}")
        if th.shape[0] != v.shape[0]:
            raise ValueError(f"dtheta and dv must cover the same intervals, got {th.shape[0]} and {v.shape[0]}")
        self._check_rows(th.shape[1], v.shape[1])

        k = th.shape[0]
        s = self._state
        q, vel, pos = s.q_wb.copy(), s.v_w.copy(), s.p_w.copy()
        out_q, out_v, out_p = np.empty((k, 4)), np.empty((k, 3)), np.empty((k, 3))
        T = self._params.interval_s
        K._navigate(q, vel, pos, th, v, T, setup.gravity_w, setup.coning.id, setup.sculling.id,
                    setup.position_id, setup.multiple, out_q, out_v, out_p)
        t = s.t0_s + (s.steps + 1 + np.arange(k)) * T
        self._state = NavigatorState(q, vel, pos, s.t0_s, s.steps + k)
        return NavigatorOutput(t, out_q, out_v, out_p)

    def _check_rows(self, m_theta: int, m_v: int) -> None:
        setup, p = self._setup, self._params
        for name, m, needed, symbol in (("dtheta", m_theta, setup.rows_dtheta, "ΔΘ"),
                                        ("dv", m_v, setup.rows_dv, "ΔV")):
            if needed is None or (m == needed if not setup.multiple else m >= needed):
                continue
            what = (f"the multiple integrals {symbol}¹..{symbol}^{needed} (m >= {needed})" if setup.multiple
                    else f"exactly m = {needed} sub-interval increments {symbol}_j")
            raise ValueError(f"{name} must hold {what} per interval for coning={p.coning!r}, "
                             f"sculling={p.sculling!r}, position={p.position!r}; got m = {m}")


def navigate(params: NavigatorParams, dtheta, dv, *, q_wb=(1.0, 0.0, 0.0, 0.0), v_w=(0.0, 0.0, 0.0),
             p_w=(0.0, 0.0, 0.0), t_s: float = 0.0) -> NavigatorOutput:
    """Batch navigation: a fresh :class:`StrapdownNavigator` given all intervals at once."""
    return StrapdownNavigator(params, q_wb=q_wb, v_w=v_w, p_w=p_w, t_s=t_s).update(dtheta, dv)
