"""The C estimators (fmu/native, the FMU path) against the numba estimators (the Python path).

The C library is compiled with the system C compiler into a temporary directory and called
through ctypes (``biso_cosim.fmu.native.binding``). Every output, flag, bias estimate and
state value must equal the Python estimator's bit for bit where the arithmetic is the same;
only BISO's general mode (pattern 13: a 4×4 matrix exponential whose products numba hands
to BLAS) may differ by rounding, at most 1e-12 in attitude. Inputs: samples and wheel speed of
a shipped route, the analytic test motions, NaN/zero/saturated samples and sensor flags;
tunable changes in mid-run, reset, and states moved between C and Python.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from biso_cosim.estimators import State, describe_estimator, estimator_inputs, make_estimator
from biso_cosim.estimators import flags as fl
from biso_cosim.fmu.native import gen
from biso_cosim.fmu.native.binding import CompilerNotFound, NativeEstimator, NativeLibrary, compile_estimators
from biso_cosim.motions import make_motion, motion_names

KINDS = gen.NATIVE_KINDS
FS = 200.0


@pytest.fixture(scope="module")
def lib(tmp_path_factory) -> NativeLibrary:
    try:
        path = compile_estimators(tmp_path_factory.mktemp("native_estimators"))
    except CompilerNotFound as exc:
        pytest.skip(f"no C compiler: {exc}")
    return NativeLibrary(path)


@pytest.fixture(scope="module")
def route():
    """Samples, sensor flags and wheel speed of 12 s of figure8 (the co-simulation's MPU-9250)."""
    from biso_cosim.cosim import run_route

    run = run_route("figure8", duration_s=12.0, seed=4, estimators=["poisson"])
    assert len(run.truth) == len(run.imu.gyro_b) > 2000
    return {"gyro_b": run.imu.gyro_b, "accel_b": run.imu.accel_b, "mag_b": run.imu.mag_b,
            "imu_flags": run.imu.flags.astype(np.int64), "speed_mps": run.truth.speed_mps.copy()}


def _noisy_motion(name: str, duration_s: float = 4.0, seed: int = 0) -> dict[str, np.ndarray]:
    m = make_motion(name, duration_s, FS, seed=seed)
    rng = np.random.default_rng(seed)
    n = m.t_s.size
    bias = np.array([0.01, -0.02, 0.015])
    out = {"gyro_b": m.omega_b + bias + rng.normal(0.0, 0.005, (n, 3)),
           "accel_b": m.specific_force_b + rng.normal(0.0, 0.05, (n, 3)),
           "mag_b": m.mag_b + rng.normal(0.0, 0.4, (n, 3))}
    if "speed_mps" in m.info:
        out["speed_mps"] = np.asarray(m.info["speed_mps"], dtype=np.float64)
    return out


def _inputs_for(kind: str, samples: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The optional inputs among ``samples`` that ``kind`` takes."""
    return {k: v for k, v in samples.items() if k in estimator_inputs(kind)}


def _run_both(py, c, samples: dict[str, np.ndarray], kind: str):
    extra = _inputs_for(kind, samples)
    a = py.update(samples["gyro_b"], samples["accel_b"], samples["mag_b"], **extra)
    b = c.update(samples["gyro_b"], samples["accel_b"], samples["mag_b"], **extra)
    return a, b


def _assert_same(a, b, *, exact: bool = True, what: str = "") -> None:
    """Two Estimates equal: bit for bit, or within 1e-12 (attitude) with the same flags."""
    assert np.array_equal(a.flags, b.flags), f"{what}: flags differ at {np.nonzero(a.flags != b.flags)[0][:5]}"
    assert np.all(np.isfinite(b.q_wb)), f"{what}: the C output has non-finite values"
    if exact:
        bad = np.nonzero(np.any(a.q_wb != b.q_wb, axis=1))[0]
        assert bad.size == 0, (f"{what}: q_wb differs from sample {bad[0]} on "
                               f"(max |Δ| {np.abs(a.q_wb - b.q_wb).max():.3g})")
    else:
        err = np.abs(a.q_wb - b.q_wb).max()
        assert err <= 1e-12, f"{what}: q_wb differs by {err:.3g} > 1e-12"
    if a.gyro_bias_b is not None:
        if exact:
            assert np.array_equal(a.gyro_bias_b, b.gyro_bias_b), f"{what}: gyro_bias_b differs"
        else:
            np.testing.assert_allclose(b.gyro_bias_b, a.gyro_bias_b, rtol=0, atol=1e-12)


def _assert_same_state(py, c, *, exact: bool = True, what: str = "") -> None:
    s_py, s_c = py.get_state().values, c.get_state()
    if exact:
        same = (s_py == s_c) | (np.isnan(s_py) & np.isnan(s_c))
        assert same.all(), f"{what}: state differs at {np.nonzero(~same)[0]}"
    else:
        np.testing.assert_allclose(s_c, s_py, rtol=0, atol=1e-12, err_msg=what)


# --------------------------------------------------------------------------------------
# one source of the constants
# --------------------------------------------------------------------------------------


def test_generated_files_are_current():
    assert gen.main(["--check"]) == 0, "run python -m biso_cosim.fmu.native.gen"


def _py_value(row: dict, choices) -> list[float]:
    d = row["default"]
    if isinstance(d, tuple):
        return [float(x) for x in d]
    if d is None:
        return [math.nan]
    if isinstance(d, str):
        return [float(choices.index(d))]
    return [float(d)]


@pytest.mark.parametrize("kind", KINDS)
def test_tables_are_the_python_records(lib, kind):
    """Names, defaults, documentation and sizes of the compiled tables are the Python ones."""
    k = lib.kind(kind)
    table = lib.params(k)
    skip = gen.PYTHON_ONLY.get(gen.family_of(kind), ())
    rows = [r for r in describe_estimator(kind)["params"] if r["name"] not in skip]
    by_field: dict[str, list] = {}
    for p in table:
        by_field.setdefault(p.field, []).append(p)
    assert list(by_field) == [r["name"] for r in rows]
    for r in rows:
        entries = by_field[r["name"]]
        defaults = _py_value(r, entries[0].choices)
        assert np.array_equal([p.default for p in entries], defaults, equal_nan=True), r["name"]
        for p in entries:
            assert (p.doc, p.symbol, p.unit, p.source) == (r["doc"], r["symbol"], r["unit"], r["source"])
            assert p.tunable
            assert p.optional == (r["default"] is None)
    est = make_estimator(kind, FS)
    assert lib.lib.biso_est_kind_summary(k).decode() == describe_estimator(kind)["summary"]
    assert lib.lib.biso_est_state_size(k) == est.get_state().values.size
    assert lib.lib.biso_est_coef_size(k) == est.coefficients.size
    assert bool(lib.lib.biso_est_estimates_bias(k)) == est.estimates_bias
    bits = {"imu_flags": 1, "speed_mps": 2, "velocity_enu_mps": 4}
    assert lib.lib.biso_est_inputs(k) == sum(bits[n] for n in estimator_inputs(kind) if n in bits)


def _python_accepts(kind: str, params: dict) -> bool:
    try:
        make_estimator(kind, FS, **params)
    except (ValueError, TypeError):
        return False
    return True


def _c_accepts(lib, kind: str, params: dict) -> tuple[bool, str]:
    try:
        NativeEstimator(lib, kind, FS, **params)
    except ValueError as exc:
        return False, str(exc)
    return True, ""


# parameters another must accompany for a bound to be testable on its own
_CONTEXT = {("biso", "k"): {"k_p": 0.0}}


def _candidates(p) -> list[float]:
    """Values at and just beyond each bound of a parameter's declared range (an open bound
    itself and a value just inside it too); far out and infinite where unbounded (far:
    1e3, where no Python estimator overflows, see test_overflowing_values_are_refused)."""
    out = []
    for bound, outward, is_open in ((p.min, -math.inf, p.min_open), (p.max, math.inf, False)):
        if math.isfinite(bound):
            out += [math.nextafter(bound, outward), bound]
            if is_open:  # a value inside (the next double, 5e-324, overflows a division)
                out.append(bound + max(1e-6, 1e-6 * abs(bound)))
        else:
            out += [math.copysign(1e3, outward), outward]
    return out + [math.nan]


@pytest.mark.parametrize("kind", KINDS)
def test_ranges_are_those_the_python_estimators_check(lib, kind):
    """Each bound of gen.RANGES: accepted by both, the next double beyond refused by both
    (the C message names the variable and its range); NaN is None where that is allowed."""
    k = lib.kind(kind)
    defaults = {r["name"]: r["default"] for r in describe_estimator(kind)["params"]}
    for i, p in enumerate(lib.params(k)):
        if p.type not in ("REAL", "INTEGER"):
            continue
        for value in _candidates(p):
            params = dict(_CONTEXT.get((kind, p.field), {}))
            if "[" in p.name:
                vec = list(defaults[p.field])
                vec[int(p.name[-2]) - 1] = value
                params[p.field] = tuple(vec)
            else:
                params[p.field] = None if (math.isnan(value) and p.optional) else value
            py_ok = _python_accepts(kind, params)
            c_ok, message = _c_accepts(lib, kind, params)
            assert py_ok == c_ok, f"{kind}.{p.name} = {value!r}: Python {'accepts' if py_ok else 'refuses'}, " \
                                  f"C {'accepts' if c_ok else 'refuses'} ({message})"
            alone = lib.check_param(k, i, value)
            if not c_ok and alone is not None:
                assert alone.startswith(f"{kind}.{p.name} must be"), alone
            if c_ok:
                np.testing.assert_array_equal(NativeEstimator(lib, kind, FS, **params).coefficients,
                                              make_estimator(kind, FS, **params).coefficients)


_PARAM_SETS = {
    "biso": [{}, {"k": 10.0, "k_p": 3.0}, {"cutoff_hz": 2.5}, {"cutoff_hz": 1.0, "reading": "L"},
             {"reading": "L"}, {"reference": "euler", "declination_rad": 0.2}, {"renormalize": True},
             {"norm_gain": 0.0}, {"norm_gain": 7.0}, {"latitude_rad": 0.9, "altitude_m": 300.0},
             {"latitude_rad": -0.3, "k": 5.0, "k_p": 0.0}, {"k": 0.0, "k_p": 0.0},
             {"gyro_range_rad_s": 4.0, "accel_range_mps2": 15.0}, {"declination_rad": -0.4}],
    "positional": [{}, {"k": 3.0}, {"k": 0.0}, {"reference": "euler"}, {"latitude_rad": 0.5}],
    "poisson": [{}, {"norm_gain": 0.0}, {"renormalize": True}, {"latitude_rad": 1.0}],
    "dcm_pi": [{}, {"kp_rp": 2.0, "ki_rp": 0.1, "kp_yaw": 0.5, "ki_yaw": 0.01}, {"declination_rad": 0.3},
               {"integral_limit_rad_s": 0.0, "gravity_mps2": 9.7}, {"accel_range_mps2": 12.0}],
    "biso_plus": [{}, {"k_p": 2.0}, {"k_tilt": 3.0, "k_heading": 0.2, "tau_acc_s": 0.0},
                  {"field_norm_ut": 49.0, "dip_rad": 1.2}, {"estimate_mag_offset": False},
                  {"declination_rad": 0.15, "speed_point_b_m": (-1.2, 0.1, -0.3)},
                  {"mag_offset_interval_s": 0.0, "mag_dip_tol_rad": 4.0, "bias_heading_factor": 0.0},
                  {"tau_speed_s": 0.0, "rest_time_s": 0.0, "gyro_range_rad_s": 3.0},
                  {"tilt_lp_order": 1, "accel_gate_free": 2.0, "mag_time_skew_s": 0.02},
                  {"accel_gate_free": 0.01, "mag_time_skew_s": 0.01, "mag_disturbance_gain": 0.0,
                   "tau_mag_disturbance_s": 0.0, "mag_heading_noise_ut": 4.0},
                  {"rear_slip_gradient_rad_per_g": 0.08, "speed_slip_accel_mps2": 2.0, "speed_slip_hold_s": 0.2,
                   "speed_point_b_m": (-1.2, 0.0, 0.0)},
                  {"linear_accel_mps2": 2.0, "linear_hold_s": 0.3, "speed_point_b_m": (-1.2, 0.0, 0.0)},
                  {"mag_offset_bias_sigma_rad_s": 0.05, "mag_offset_interval_s": 0.02,
                   "mag_offset_test_angle_rad": 0.5}],
}
_GENERAL = {"biso": [{"pattern": 13}, {"pattern": 13, "k": 20.0, "k_p": 6.0, "latitude_rad": 0.8}]}


@pytest.mark.parametrize("kind", KINDS)
def test_coefficients_are_the_python_coefficients(lib, kind):
    for params in _PARAM_SETS[kind] + _GENERAL.get(kind, []):
        for fs in (FS, 1000.0, 7.5):
            c = NativeEstimator(lib, kind, fs, **params).coefficients
            np.testing.assert_array_equal(c, make_estimator(kind, fs, **params).coefficients,
                                          err_msg=f"{kind} {params} at {fs} Hz")


# --------------------------------------------------------------------------------------
# same numbers
# --------------------------------------------------------------------------------------


def _cases(kind):
    return [(p, True) for p in _PARAM_SETS[kind]] + [(p, False) for p in _GENERAL.get(kind, [])]


@pytest.mark.parametrize("kind", KINDS)
def test_route_samples(lib, route, kind):
    """12 s of figure8 with its sensor flags and the vehicle's speed: every output equal."""
    for params, exact in _cases(kind):
        py, c = make_estimator(kind, FS, **params), NativeEstimator(lib, kind, FS, **params)
        a, b = _run_both(py, c, route, kind)
        _assert_same(a, b, exact=exact, what=f"{kind} {params}")
        _assert_same_state(py, c, exact=exact, what=f"{kind} {params}")
        assert not (b.flags & fl.UNINITIALIZED).any()


@pytest.mark.parametrize("motion", motion_names())
def test_motions(lib, motion):
    """Every test motion (tumbling through ±90° pitch, coning, a magnet, a circle with its
    speed), with noise and a gyro bias, through every estimator."""
    samples = _noisy_motion(motion, seed=3)
    for kind in KINDS:
        for params, exact in _cases(kind)[:3] + _cases(kind)[-2:]:
            py, c = make_estimator(kind, FS, **params), NativeEstimator(lib, kind, FS, **params)
            a, b = _run_both(py, c, samples, kind)
            _assert_same(a, b, exact=exact, what=f"{motion} {kind} {params}")
            _assert_same_state(py, c, exact=exact, what=f"{motion} {kind} {params}")


def test_wheel_slip_and_sideslip(lib):
    """biso_plus on a circle whose wheel speed spins up and drops back every 2 s (a wheel off
    the road), with the rear axle's sideslip modelled: the slip path and the lateral
    velocity taken, every output and the state equal."""
    m = make_motion("circle", 12.0, FS, imu_ahead_m=1.2)
    rng = np.random.default_rng(7)
    n = m.t_s.size
    speed = np.asarray(m.info["speed_mps"], dtype=np.float64).copy()
    phase = np.arange(n) % 400
    speed[phase < 30] += 0.1 * phase[phase < 30]
    speed[rng.integers(0, n, 10)] = np.nan
    samples = {"gyro_b": m.omega_b + 0.002 * rng.normal(size=(n, 3)),
               "accel_b": m.specific_force_b + 0.05 * rng.normal(size=(n, 3)),
               "mag_b": m.mag_b + 0.3 * rng.normal(size=(n, 3)), "speed_mps": speed}
    params = {"rear_slip_gradient_rad_per_g": 0.08, "speed_point_b_m": (-1.2, 0.0, 0.0)}
    py, c = make_estimator("biso_plus", FS, **params), NativeEstimator(lib, "biso_plus", FS, **params)
    a, b = _run_both(py, c, samples, "biso_plus")
    _assert_same(a, b, what="circle with wheel slip")
    _assert_same_state(py, c, what="circle with wheel slip")
    assert (a.flags & fl.ACCEL_GATED).any()


def test_slides_beyond_the_linear_range(lib):
    """biso_plus on a circle (3.3 m/s² of lateral specific force) that slides for 0.5 s in
    every 2 s (8.3 m/s²), beyond its tyres' linear range a_l = 5 m/s²: the guard taken and
    released, every output and the state equal."""
    m = make_motion("circle", 12.0, FS, imu_ahead_m=1.2)
    rng = np.random.default_rng(8)
    n = m.t_s.size
    accel = m.specific_force_b + 0.05 * rng.normal(size=(n, 3))
    phase = np.arange(n) % 400
    accel[(phase >= 150) & (phase < 250), 1] += 5.0
    samples = {"gyro_b": m.omega_b + 0.002 * rng.normal(size=(n, 3)), "accel_b": accel,
               "mag_b": m.mag_b + 0.3 * rng.normal(size=(n, 3)),
               "speed_mps": np.asarray(m.info["speed_mps"], dtype=np.float64)}
    params = {"rear_slip_gradient_rad_per_g": 0.08, "speed_point_b_m": (-1.2, 0.0, 0.0), "linear_accel_mps2": 5.0,
              "linear_hold_s": 0.3}
    py, c = make_estimator("biso_plus", FS, **params), NativeEstimator(lib, "biso_plus", FS, **params)
    a, b = _run_both(py, c, samples, "biso_plus")
    _assert_same(a, b, what="circle with slides")
    _assert_same_state(py, c, what="circle with slides")
    gated = (a.flags & fl.ACCEL_GATED) != 0
    assert gated[phase == 200].all() and not gated[phase == 100].any()


def _bad_samples(seed: int = 5) -> dict[str, np.ndarray]:
    """A shaking motion whose samples go bad in every way the input policy knows, the
    first ones included: NaN/inf/huge gyro, NaN/inf/zero/huge/saturated accelerometer,
    NaN/zero/huge field or along f, sensor flags of every kind, unknown speed."""
    s = _noisy_motion("shake", 3.0, seed=seed)
    s["speed_mps"] = np.full(len(s["gyro_b"]), 2.0)
    rng = np.random.default_rng(seed)
    n = len(s["gyro_b"])
    g, a, m, v = s["gyro_b"], s["accel_b"], s["mag_b"], s["speed_mps"]
    flags = np.zeros(n, dtype=np.int64)
    a[0:3] = np.nan  # no attitude for the first samples
    g[1] = np.inf
    m[3:6] = 0.0
    for i in rng.choice(np.arange(10, n), size=n // 4, replace=False):
        case = i % 14
        if case == 0:
            g[i, rng.integers(3)] = np.nan
        elif case == 1:
            g[i] = [2e4, 0.0, 0.0]
        elif case == 2:
            a[i, rng.integers(3)] = np.inf
        elif case == 3:
            a[i] = 0.0
        elif case == 4:
            a[i] = [1e7, 0.0, 0.0]
        elif case == 5:
            m[i, rng.integers(3)] = np.nan
        elif case == 6:
            m[i] = 0.0
        elif case == 7:
            m[i] = a[i] * 3.0  # along f: no heading in it
        elif case == 8:
            m[i] = [2e7, 0.0, 0.0]
        elif case == 9:
            a[i, 0] = 40.0  # beyond the declared accelerometer range
        elif case == 10:
            g[i, 2] = -6.0  # beyond the declared gyro range
        elif case == 11:
            v[i] = np.nan
        else:
            flags[i] = rng.integers(1, 32)
    s["imu_flags"] = flags
    return s


@pytest.mark.parametrize("kind", KINDS)
def test_bad_samples_are_flagged_as_in_python(lib, kind):
    samples = _bad_samples()
    for params, exact in _cases(kind):
        for ranges in ({}, {"gyro_range_rad_s": 5.0, "accel_range_mps2": 30.0}):
            p = {**params, **ranges}
            py, c = make_estimator(kind, FS, **p), NativeEstimator(lib, kind, FS, **p)
            a, b = _run_both(py, c, samples, kind)
            _assert_same(a, b, exact=exact, what=f"{kind} {p}")
            _assert_same_state(py, c, exact=exact, what=f"{kind} {p}")
            assert (b.flags[:3] & fl.UNINITIALIZED).all() and np.array_equal(b.q_wb[0], [1.0, 0.0, 0.0, 0.0])
            for bit in (fl.GYRO_INVALID, fl.ACCEL_INVALID, fl.MAG_INVALID, fl.SATURATED):
                assert (b.flags & bit).any(), f"{kind}: no sample flagged {fl.NAMES[bit]}"


@pytest.mark.parametrize("kind", KINDS)
def test_all_bad_samples_never_give_nan(lib, kind):
    """Nothing valid at all, then only a gyro: the identity, then gyro propagation, no NaN."""
    n = 50
    nan3 = np.full((n, 3), np.nan)
    c, py = NativeEstimator(lib, kind, FS), make_estimator(kind, FS)
    for gyro, accel, mag in ((nan3, nan3, nan3), (np.full((n, 3), 0.3), np.zeros((n, 3)), nan3)):
        a = py.update(gyro, accel, mag)
        b = c.update(gyro, accel, mag)
        _assert_same(a, b, what=kind)
    c.reset(q0=(1.0, 1.0, -1.0, 1.0))
    py.reset(q0=(1.0, 1.0, -1.0, 1.0))
    _assert_same(py.update(nan3, nan3, nan3), c.update(nan3, nan3, nan3), what=f"{kind} after q0")
    _assert_same_state(py, c, what=kind)


# --------------------------------------------------------------------------------------
# tuning, reset, state
# --------------------------------------------------------------------------------------

_CHANGES = {
    "biso": [{"k": 10.0, "k_p": 2.0}, {"k": None, "k_p": None, "cutoff_hz": 3.0}, {"reading": "L"},
             {"reference": "euler"}, {"renormalize": True}, {"renormalize": False, "norm_gain": 0.0},
             {"declination_rad": 0.3}, {"latitude_rad": 0.7}, {"cutoff_hz": None, "k": 0.0, "k_p": 0.0},
             {"k": 44.4, "k_p": 25.64, "reading": "D"}],
    "positional": [{"k": 5.0}, {"reference": "euler"}, {"k": 0.0}, {"k": 60.0, "norm_gain": 3.0}],
    "poisson": [{"norm_gain": 0.0}, {"latitude_rad": -0.5}, {"renormalize": True}],
    "dcm_pi": [{"kp_rp": 3.0}, {"ki_yaw": 0.5, "declination_rad": -0.2}, {"integral_limit_rad_s": 0.01},
               {"gravity_mps2": 9.81}],
    "biso_plus": [{"k_tilt": 2.0}, {"k_heading": 0.5, "k_p": 1.0}, {"estimate_mag_offset": False},
                  {"field_norm_ut": 50.0, "dip_rad": 1.1}, {"field_norm_ut": None, "dip_rad": None},
                  {"declination_rad": 0.1, "speed_point_b_m": (-1.0, 0.0, 0.0)}, {"tau_acc_s": 0.5},
                  {"mag_offset_interval_s": 0.02, "bias_forgetting_s": 10.0},
                  {"tilt_lp_order": 1, "mag_disturbance_gain": 10.0}, {"tilt_lp_order": 2, "accel_gate_free": 1.0}],
}


@pytest.mark.parametrize("kind", KINDS)
def test_tuning_in_mid_run(lib, route, kind):
    """Tunable changes between samples act as set_params does: the state is kept (no jump),
    the coefficients are derived again; every output stays equal to Python's."""
    py, c = make_estimator(kind, FS), NativeEstimator(lib, kind, FS)
    changes = _CHANGES[kind] + [{"pattern": 13}] * (kind == "biso")
    bounds = np.linspace(0, len(route["gyro_b"]), len(changes) + 2).astype(int)
    exact = True
    for j, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        part = {k: v[lo:hi] for k, v in route.items()}
        a, b = _run_both(py, c, part, kind)
        _assert_same(a, b, exact=exact, what=f"{kind} segment {j}")
        if j < len(changes):
            before = c.get_state()
            py.set_params(**changes[j])
            c.set_params(**changes[j])
            assert np.array_equal(c.get_state(), before, equal_nan=True), "set_params changed the state"
            np.testing.assert_array_equal(c.coefficients, py.coefficients, err_msg=f"{kind} {changes[j]}")
            exact = exact and changes[j].get("pattern") != 13
    _assert_same_state(py, c, exact=exact, what=kind)


@pytest.mark.parametrize("kind", KINDS)
def test_invalid_changes_change_nothing(lib, kind):
    samples = _noisy_motion("rotation", 1.0)
    c = NativeEstimator(lib, kind, FS)
    c.update(samples["gyro_b"], samples["accel_b"], samples["mag_b"])
    coef, state = c.coefficients, c.get_state()
    first = next(p for p in c.table if p.type == "REAL" and math.isfinite(p.min))
    bad = {first.field: math.nextafter(first.min, -math.inf)}
    if "[" in first.name:
        pytest.fail("no scalar parameter to break")
    with pytest.raises(ValueError, match=rf"^{kind}\.{first.name} must be finite and"):
        c.set_params(**bad)
    assert np.array_equal(c.coefficients, coef, equal_nan=True) and np.array_equal(c.get_state(), state, equal_nan=True)
    with pytest.raises(ValueError):
        make_estimator(kind, FS).set_params(**bad)


def test_combinations_refused_as_in_python(lib):
    """BISO's checks across parameters: cutoff_hz with gains, k = 0 with a cross-link, and the
    frozen-rate stability of pattern 13 (Hurwitz here, eigenvalues in Python)."""
    with pytest.raises(ValueError, match=r"biso\.cutoff_hz or biso\.k"):
        NativeEstimator(lib, "biso", FS, cutoff_hz=2.0, k=3.0)
    with pytest.raises(ValueError, match=r"k = 0 with k_p"):
        NativeEstimator(lib, "biso", FS, k=0.0, k_p=2.0)
    verdicts = []
    for k in (0.0, 0.05, 0.5, 5.0, 44.4):
        for kp in (0.0, 1.0, 25.64):
            for rate in (0.0, 5.0, 40.0):
                params = {"pattern": 13, "k": k, "k_p": kp, "stability_rate_rad_s": rate}
                py_ok = _python_accepts("biso", params)
                c_ok, message = _c_accepts(lib, "biso", params)
                assert py_ok == c_ok, f"{params}: Python {py_ok}, C {c_ok} ({message})"
                verdicts.append(c_ok)
                if not c_ok and k > 0.0:
                    assert "unstable gains" in message and "stability_rate_rad_s" in message
    assert any(verdicts) and not all(verdicts)


@pytest.mark.parametrize("kind, params, names", [
    ("biso", {"norm_gain": 1e6}, "biso.norm_gain"),
    ("biso", {"cutoff_hz": 1e308}, "biso.cutoff_hz"),
    ("biso_plus", {"bias_sigma_init_rad_s": 1e200}, "biso_plus.bias_sigma_init_rad_s"),
    ("biso_plus", {"bias_sigma_motion_rad_s": 1e100}, "biso_plus.bias_sigma_motion_rad_s"),
    ("biso_plus", {"mag_offset_interval_s": 1e307}, "biso_plus.mag_offset_interval_s"),
    ("biso_plus", {"accel_gate": 1e-200, "gravity_mps2": 1e-200}, "biso_plus.gravity_mps2, biso_plus.accel_gate"),
])
def test_overflowing_values_are_refused(lib, kind, params, names):
    """Values within the declared ranges whose derived coefficients overflow: the Python
    estimator raises OverflowError or runs on infinities; C refuses them, naming them."""
    with pytest.raises(ValueError, match=rf"^{kind}: the values of (.*, )?{names}(, .*)? give a non-finite"):
        NativeEstimator(lib, kind, FS, **params)


def test_bad_construction_messages(lib):
    with pytest.raises(ValueError, match=r"^fs_hz must be finite and > 0, got 0"):
        NativeEstimator(lib, "biso", 0.0)
    with pytest.raises(ValueError, match=r"^fs_hz must be finite and > 0, got nan"):
        NativeEstimator(lib, "dcm_pi", math.nan)
    with pytest.raises(ValueError, match=r"^biso\.reference must be one of 0 'vector', 1 'euler', got -1"):
        NativeEstimator(lib, "biso", FS, reference="quaternion")
    with pytest.raises(ValueError, match=r"^biso\.pattern must be a whole number in \[12, 13\], got 12\.5"):
        NativeEstimator(lib, "biso", FS, pattern=12.5)
    with pytest.raises(ValueError, match=r"^biso_plus\.estimate_mag_offset must be 0 \(false\) or 1"):
        NativeEstimator(lib, "biso_plus", FS, estimate_mag_offset=2)
    with pytest.raises(ValueError, match=r"^biso\.latitude_rad must be finite and in \[-1\.5690509975429023, "
                                         r"1\.5690509975429023\], got 1\.6 \(or NaN: none\)"):
        NativeEstimator(lib, "biso", FS, latitude_rad=1.6)
    with pytest.raises(ValueError, match=r"^biso_plus\.speed_point_b_m\[2\] must be finite, got inf"):
        NativeEstimator(lib, "biso_plus", FS, speed_point_b_m=(0.0, math.inf, 0.0))
    with pytest.raises(ValueError, match=r"q0 must be finite and non-zero"):
        NativeEstimator(lib, "biso", FS).reset(q0=(0.0, 0.0, 0.0, 0.0))
    assert lib.lib.biso_est_kind(b"gnss_kalman") == -1 and lib.lib.biso_est_kind(b"biso_plus") == 4


@pytest.mark.parametrize("kind", KINDS)
def test_reset_and_initial_output(lib, route, kind):
    py, c = make_estimator(kind, FS), NativeEstimator(lib, kind, FS)
    q, flags, bias = c.peek()
    assert np.array_equal(q, [1.0, 0.0, 0.0, 0.0]) and flags == fl.UNINITIALIZED and not bias.any()
    half = len(route["gyro_b"]) // 2
    first = {k: v[:half] for k, v in route.items()}
    second = {k: v[half:] for k, v in route.items()}
    _run_both(py, c, first, kind)
    for q0 in (None, (1.0, -1.0, 1.0, 1.0), (0.9, 0.1, -0.3, 0.2)):
        py.reset(q0=q0)
        c.reset(q0=q0)
        # as_quaternion's norm is numpy's (a BLAS dot): the same to rounding
        exact = q0 is None or q0[0] == 1.0
        _assert_same_state(py, c, exact=exact, what=f"{kind} reset({q0})")
        q, flags, _ = c.peek()
        assert flags == (fl.UNINITIALIZED if q0 is None else 0)
        if q0 is not None:
            np.testing.assert_allclose(q, np.asarray(q0) / np.linalg.norm(q0), rtol=0, atol=1e-16)
        a, b = _run_both(py, c, second, kind)
        _assert_same(a, b, exact=exact, what=f"{kind} after reset({q0})")


@pytest.mark.parametrize("kind", KINDS)
def test_state_moves_between_c_and_python(lib, route, kind):
    """get/set state round trips, and a state taken in C continued in Python and back,
    give the run without interruption."""
    layout = make_estimator(kind, FS).state_layout
    n = len(route["gyro_b"])
    cuts = [0, n // 4, n // 2, 3 * n // 4, n]
    parts = [{k: v[a:b] for k, v in route.items()} for a, b in zip(cuts[:-1], cuts[1:])]
    ref = make_estimator(kind, FS)
    reference = [ref.update(p["gyro_b"], p["accel_b"], p["mag_b"], **_inputs_for(kind, p)) for p in parts]

    c = NativeEstimator(lib, kind, FS)
    out = [c.update(parts[0]["gyro_b"], parts[0]["accel_b"], parts[0]["mag_b"], **_inputs_for(kind, parts[0]))]
    c2 = NativeEstimator(lib, kind, FS)  # C → C
    c2.set_state(c.get_state())
    out.append(c2.update(parts[1]["gyro_b"], parts[1]["accel_b"], parts[1]["mag_b"], **_inputs_for(kind, parts[1])))
    py = make_estimator(kind, FS)  # C → Python
    py.set_state(State(kind, c2.get_state(), layout))
    out.append(py.update(parts[2]["gyro_b"], parts[2]["accel_b"], parts[2]["mag_b"], **_inputs_for(kind, parts[2])))
    c3 = NativeEstimator(lib, kind, FS)  # Python → C
    c3.set_state(py.get_state().values)
    out.append(c3.update(parts[3]["gyro_b"], parts[3]["accel_b"], parts[3]["mag_b"], **_inputs_for(kind, parts[3])))
    for j, (a, b) in enumerate(zip(reference, out)):
        _assert_same(a, b, what=f"{kind} part {j}")
    assert np.array_equal(c3.get_state(), ref.get_state().values, equal_nan=True)
    with pytest.raises(ValueError, match="state must have shape"):
        c3.set_state(np.zeros(3))


@pytest.mark.parametrize("kind", KINDS)
def test_one_sample_calls_are_the_batch(lib, route, kind):
    """biso_est_update sample by sample (the FMU's call) equals biso_est_run over a block."""
    c1, c2 = NativeEstimator(lib, kind, FS), NativeEstimator(lib, kind, FS)
    n = 600
    extra = _inputs_for(kind, {k: v[:n] for k, v in route.items()})
    batch = c1.update(route["gyro_b"][:n], route["accel_b"][:n], route["mag_b"][:n], **extra)
    for i in range(n):
        q, flags, bias = c2.update_one(route["gyro_b"][i], route["accel_b"][i], route["mag_b"][i],
                                       speed_mps=extra["speed_mps"][i] if "speed_mps" in extra else math.nan,
                                       imu_flags=int(extra["imu_flags"][i]) if "imu_flags" in extra else 0)
        assert np.array_equal(q, batch.q_wb[i]) and flags == batch.flags[i]
        if batch.gyro_bias_b is not None:
            assert np.array_equal(bias, batch.gyro_bias_b[i])
    assert np.array_equal(c1.get_state(), c2.get_state(), equal_nan=True)


def test_transport_rate_from_the_velocity_input(lib, route):
    """BISO with latitude and a velocity over the ground (transport rate), some of it NaN."""
    n = len(route["gyro_b"])
    heading = np.linspace(0.0, 6.0, n)
    vel = np.stack([route["speed_mps"] * np.cos(heading), route["speed_mps"] * np.sin(heading), np.zeros(n)], axis=1)
    vel[::97] = np.nan
    for kind, params, exact in (("biso", {"latitude_rad": 0.9}, True), ("poisson", {"latitude_rad": -1.2}, True),
                                ("biso", {"latitude_rad": 0.4, "pattern": 13}, False)):
        py, c = make_estimator(kind, FS, **params), NativeEstimator(lib, kind, FS, **params)
        a = py.update(route["gyro_b"], route["accel_b"], route["mag_b"], velocity_enu_mps=vel)
        b = c.update(route["gyro_b"], route["accel_b"], route["mag_b"], velocity_enu_mps=vel)
        _assert_same(a, b, exact=exact, what=f"{kind} {params}")
