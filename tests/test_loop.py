"""The co-simulation's one period pipeline (``biso_cosim.loop``): an estimator joins it by
declaring its kernel and arrays in its own module (here a user's, defined in this file),
and every registered estimator gives the same numbers on the fast path as on the general
path (``CoSimulation.fast_path = False``), bit for bit."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest

from biso_cosim._numba import jit
from biso_cosim.cosim import CoSimulation, EstimatorSpec
from biso_cosim.estimators import Estimator, LoopArrays, estimator_names, param
from biso_cosim.loop import PeriodWork


# ---- a user's own estimator: gyro integration on the unit sphere, eq. (2) of Aleshkin 2024
@dataclass(frozen=True)
class GyroOnlyParams:
    rate_scale: float = param(1.0, symbol="s", unit="1", doc="scale applied to the gyro readings")


@jit
def _gyro_only_batch(coef, state, gyro, q_out, flags_out):
    """q ← q ⊗ exp(½ s ω h), the exact rotation of a rate held over the interval."""
    h, s = coef[0], coef[1]
    w, x, y, z = state[0], state[1], state[2], state[3]
    for i in range(gyro.shape[0]):
        gx, gy, gz = s * gyro[i, 0] * h, s * gyro[i, 1] * h, s * gyro[i, 2] * h
        angle = math.sqrt(gx * gx + gy * gy + gz * gz)
        c = math.cos(0.5 * angle)
        f = 0.5 if angle == 0.0 else math.sin(0.5 * angle) / angle
        dw, dx, dy, dz = c, f * gx, f * gy, f * gz
        w, x, y, z = (w * dw - x * dx - y * dy - z * dz, w * dx + x * dw + y * dz - z * dy,
                      w * dy - x * dz + y * dw + z * dx, w * dz + x * dy - y * dx + z * dw)
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = w, x, y, z
        flags_out[i] = 0
    state[0], state[1], state[2], state[3] = w, x, y, z


@jit
def _gyro_only_loop(arrays, samples):
    k = samples.gyro_b.shape[0]
    _gyro_only_batch(arrays.coef, arrays.state, samples.gyro_b, arrays.q_wb[:k], arrays.flags[:k])


class GyroOnly(Estimator):
    method = "gyro_only"
    Params = GyroOnlyParams
    state_layout = (("q_wb", 4),)
    loop_kernel = _gyro_only_loop  # (loop_arrays: Estimator's LoopArrays of coef, state, outputs)

    def _coefficients(self, params, fs_hz):
        return np.array([1.0 / fs_hz, params.rate_scale])

    def _initial_state(self, q0):
        return np.array([1.0, 0.0, 0.0, 0.0]) if q0 is None else np.array(q0, dtype=float)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias):
        _gyro_only_batch(coef, state, gyro, q_out, flags)

    @property
    def initialized(self):
        return True


def _pair(**options):
    fast = CoSimulation("figure8", **options)
    general = CoSimulation("figure8", **options)
    general.fast_path = False
    return fast, general


def _assert_same_run(a, b):
    assert np.array_equal(a.imu.gyro_b, b.imu.gyro_b) and np.array_equal(a.truth.packed, b.truth.packed)
    assert list(a.estimates) == list(b.estimates)
    for key, (q, flags) in a.estimates.items():
        assert np.array_equal(q, b.estimates[key][0]) and np.array_equal(flags, b.estimates[key][1]), key
    assert (a.gnss is None) == (b.gnss is None)
    if a.gnss is not None:  # every field of the fixes, bit for bit (NaN where no fix)
        for f in dataclasses.fields(a.gnss):
            assert getattr(a.gnss, f.name).tobytes() == getattr(b.gnss, f.name).tobytes(), f.name


def _assert_same_estimate(a, b, key):
    """Two estimates (any ``Estimate`` record: GNSS-aided ones add σ and the updates) bit for bit."""
    assert type(a) is type(b), key
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert (x is None) == (y is None), (key, f.name)
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), (key, f.name)


def test_a_users_estimator_defined_here_joins_the_period_call():
    mine = GyroOnly(200.0, GyroOnlyParams(rate_scale=1.0))
    fast = CoSimulation("figure8", duration_s=3.0, seed=1, estimators=[mine, "biso"])
    q0 = fast.vehicle.current_truth().q_wb[0]  # (the sensor's first sample is at the first step)
    mine.reset(q0=q0)
    assert fast.loop_estimators == ("gyro_only", "biso")
    result = fast.run()
    twin = GyroOnly(200.0)
    twin.reset(q0=q0)
    general = CoSimulation("figure8", duration_s=3.0, seed=1, estimators=[twin, "biso"])
    general.fast_path = False
    _assert_same_run(result, general.run())
    # the stream in the loop is the estimator's own batch over the same samples
    again = GyroOnly(200.0)
    again.reset(q0=q0)
    np.testing.assert_array_equal(again.update(result.imu.gyro_b, result.imu.accel_b, result.imu.mag_b).q_wb,
                                  result.estimates["gyro_only"][0])
    # and, with no correction, it is the true attitude's integral: within the gyro's errors
    angle = 2 * np.arccos(np.clip(np.abs(np.sum(result.estimates["gyro_only"][0] * result.truth.q_wb, axis=1)), 0, 1))
    assert np.degrees(angle).max() < 1.0


# every registered estimator, and BISO's gyro steps: each coning algorithm (the multiple
# integrals of every order it takes, and the sub-interval increments), two at once with a
# navigator that has the sensor form more orders than they read
_GYRO_STEPS = [(EstimatorSpec("biso", {"gyro_step": step}, label=f"biso_{step}"),) for step in
               ("one_sample", "two_sample", "traditional3", "traditional3_miller", "smoothing", "invariant")]
_GYRO_STEPS.append((EstimatorSpec("poisson", {"gyro_step": "smoothing"}, label="poisson_smoothing"),
                    EstimatorSpec("positional", {"gyro_step": "two_sample"}, label="positional_two_sample")))


@pytest.mark.parametrize("specs", [(EstimatorSpec(name),) for name in estimator_names()] + _GYRO_STEPS,
                         ids=lambda specs: "+".join(s.key for s in specs))
def test_fast_path_equals_general_path_for_every_registered_estimator(specs):
    keys = tuple(s.key for s in specs)
    navigators = ("invariant",) if len(specs) > 1 else ()
    fast, general = _pair(duration_s=3.0, seed=5, estimators=list(specs), keep_log=True, navigators=navigators)
    assert fast.loop_estimators == keys  # (none falls out of the period call)
    for _ in range(60):
        a, b = fast.step(), general.step()
        assert np.array_equal(a[0].gyro_b, b[0].gyro_b) and np.array_equal(a[1].packed, b[1].packed)
        for key in keys:
            _assert_same_estimate(a[2][key], b[2][key], key)
    _assert_same_run(fast.run(), general.run())


def test_gyro_steps_in_the_call_read_the_period_samples_increments():
    """An estimator that declares gyro increments finds them in ``PeriodSamples`` (the
    sensor's, formed once per period), and the general path feeds ``update`` the same."""
    sim = CoSimulation("figure8", duration_s=1.0, seed=2, estimators=[
        EstimatorSpec("biso", {"gyro_step": "invariant"}, label="inv"),
        EstimatorSpec("biso", {"gyro_step": "two_sample"}, label="two")], keep_log=False)
    assert sim.estimators["inv"].gyro_increments == ("multiple", 4)
    assert sim.estimators["two"].gyro_increments == ("sub", 2)
    seen = np.zeros(2, dtype=np.int64)

    @jit
    def record(samples, q, arrays):
        arrays[0] = samples.dtheta_b.shape[1]
        arrays[1] = samples.dtheta_sub_b.shape[1]

    sim.attach(PeriodWork(record, seen))
    samples, _, _ = sim.step()
    assert tuple(seen) == (4, 2) and samples.dtheta.shape[1:] == (4, 3) and samples.dtheta_sub.shape[1:] == (2, 3)
    plain = CoSimulation("figure8", duration_s=1.0, seed=2, estimators=["biso"], keep_log=False)
    plain.attach(PeriodWork(record, seen))
    plain.step()
    assert tuple(seen) == (0, 0)  # nothing takes increments: the fields are empty


@pytest.mark.parametrize("name", ["gnss_complementary", "gnss_kalman"])
def test_gnss_aided_estimators_in_the_call_equal_update_over_a_route(name):
    """With the receiver and the filter in the period call (reused outputs, no log: the
    environments' way), every period's estimate (attitude, flags, drift, σ, the updates
    record) is the general path's, over a route long enough for fixes to be used and gated;
    and the run's fixes are the receiver's ``simulate`` over the same truth, geodetic
    position included (``pymap3d`` element by element, so one conversion in ``result()``
    gives the per-call numbers)."""
    options = dict(route="loop600", duration_s=40.0, seed=2, estimators=[name])
    fast = CoSimulation(keep_log=False, reuse_outputs=True, **options)
    general = CoSimulation(keep_log=False, **options)
    general.fast_path = False
    assert fast.loop_estimators == (name,)
    kinds = set()
    for _ in range(40 * 50):
        a, b = fast.step(), general.step()
        _assert_same_estimate(a[2][name], b[2][name], name)
        kinds.update(a[2][name].updates["kind"].tolist())
    assert {0, 2} <= kinds  # gnss updates and anchors were made
    result = CoSimulation(**(options | {"duration_s": 6.0})).run()
    import pymap3d

    site = result.route.site
    assert len(result.gnss) > 20 and result.gnss.valid.all()
    for i in range(len(result.gnss)):  # each fix converted alone: the same bits
        e, n, u = result.gnss.pos_w[i:i + 1].T
        want = pymap3d.enu2geodetic(e, n, u, site.lat_deg, site.lon_deg, site.alt_m)
        got = (result.gnss.lat_deg[i:i + 1], result.gnss.lon_deg[i:i + 1], result.gnss.alt_m[i:i + 1])
        assert all(g.tobytes() == w.tobytes() for g, w in zip(got, want)), i


def test_a_gnss_estimator_out_of_step_with_its_receiver_is_refused_on_either_path():
    """``update``'s refusal of fixes that do not continue the stream holds in the period
    call too: a state restored into the estimator alone (its last fix far ahead) raises the
    same error on both paths, and the estimator is left as it was."""
    from biso_cosim.estimators import State
    from biso_cosim.estimators import _gnss_kernels as K

    seen = []
    for fast_path in (True, False):
        sim = CoSimulation("figure8", duration_s=5.0, seed=1, estimators=["gnss_complementary"])
        sim.fast_path = fast_path
        for _ in range(20):
            sim.step()
        est = sim.estimators["gnss_complementary"]
        state = est.get_state()
        values = state.values.copy()
        values[K.S_LAST_FIX] = 1e6
        est.set_state(State(state.method, values, state.layout))
        steps = 0
        with pytest.raises(ValueError, match="must continue the stream"):
            while steps < 20:
                steps += 1
                sim.step()
        seen.append((steps, est.get_state().values))
    assert 1 <= seen[0][0] == seen[1][0] < 20  # refused at the first period with a fix
    assert seen[0][1][K.S_LAST_FIX] == 1e6 and seen[0][1].tobytes() == seen[1][1].tobytes()
