"""ImuPlugin's compiled call per tick (biso_cosim/plugin/_tick.py) against its general path
(``fast_path = False``: one Python call per stage): the same numbers, bit for bit, for
every estimator the plug-in runs, in any host convention, one tick or blocks per call,
across state restores and an estimator reset between calls."""

import numpy as np
import pytest

from biso_cosim.frames import quat_rotate
from biso_cosim.motions import make_motion
from biso_cosim.plugin import HostFrames, ImuPlugin, Mounting, PluginOutput

ESTIMATORS = {"plus": ("biso_plus", {}), "faithful": "biso", "positional": "positional", "poisson": "poisson",
              "dcm": "dcm_pi"}


def _same(a: PluginOutput, b: PluginOutput) -> None:
    assert np.array_equal(a.t_s, b.t_s)
    for name in ("t_s", "gyro_b", "accel_b", "mag_b", "temperature_c", "flags", "mag_fresh"):
        assert np.array_equal(getattr(a.samples, name), getattr(b.samples, name), equal_nan=True), name
    assert np.array_equal(a.raw.words, b.raw.words) and np.array_equal(a.raw.status, b.raw.status)
    assert np.array_equal(a.q_true_wb, b.q_true_wb)
    assert list(a.estimates) == list(b.estimates)
    for label, ea in a.estimates.items():
        eb = b.estimates[label]
        assert np.array_equal(ea.estimate.q_wb, eb.estimate.q_wb), label
        assert np.array_equal(ea.flags, eb.flags), label
        if ea.estimate.gyro_bias_b is None:
            assert eb.estimate.gyro_bias_b is None
        else:
            assert np.array_equal(ea.estimate.gyro_bias_b, eb.estimate.gyro_bias_b), label


def _truth(frames: HostFrames, h: float):
    """A tumbling motion written in ``frames`` (host conventions), with velocity, position,
    acceleration and a die temperature ramp."""
    motion = make_motion("tumble", duration_s=1.2, fs_hz=1.0 / h, seed=5)
    accel_enu = quat_rotate(motion.q_wb, motion.specific_force_b) - [0.0, 0.0, 9.80665]
    v_enu = np.cumsum(accel_enu, axis=0) * h
    q, omega = frames.attitude_from_package(motion.q_wb), frames.flu_to_body(motion.omega_b)
    world = frames.enu_to_world
    return dict(t_s=motion.t_s + 3.0, q_wb=q, omega_b=omega, accel_w=world(accel_enu),
                v_w=world(v_enu), p_w=world(np.cumsum(v_enu, axis=0) * h),
                temperature_c=30.0 + np.linspace(0.0, 5.0, len(motion)))


@pytest.mark.parametrize("frames", [HostFrames("ENU", "FLU", "wxyz"), HostFrames("NED", "FRD", "xyzw")])
def test_the_compiled_call_gives_the_general_paths_numbers_bit_for_bit(frames):
    h = 0.001
    truth = _truth(frames, h)
    n = truth["t_s"].shape[0]
    if frames.quaternion == "xyzw":  # (the host's quaternion rows reordered: one tick's q_wb is a strided view)
        assert not truth["q_wb"][0].flags.c_contiguous
    kwargs = dict(tick_s=h, frames=frames, profile="mpu9250", seed=4, estimators=ESTIMATORS, speed_from_velocity=True,
                  mounting=Mounting((0.3, -0.1, 0.2), (0.5, 0.5, 0.5, 0.5)))
    general = ImuPlugin(**kwargs)
    general.fast_path = False
    assert general.in_loop_estimators == ()
    reference = general.step(**truth)

    ticked = ImuPlugin(**kwargs)
    assert ticked.in_loop_estimators == tuple(ESTIMATORS)
    parts = [ticked.step(**{k: v[i] for k, v in truth.items()}) for i in range(n)]
    _same(reference, PluginOutput.concatenate(parts))  # kept outputs: no later call wrote over them
    latched = [p for p in parts if len(p)]
    assert not any(np.shares_memory(a.samples.gyro_b, b.samples.gyro_b) for a, b in zip(latched, latched[1:]))
    empty = [p for p in parts if not len(p)]  # nothing to write over: one object
    assert len(empty) > len(latched) and all(p is empty[0] for p in empty)

    blocks = ImuPlugin(**kwargs)
    cuts = np.unique(np.concatenate(([0, n], np.random.default_rng(0).integers(1, n, 40))))
    parts = [blocks.step(**{k: v[a:b] for k, v in truth.items()}) for a, b in zip(cuts[:-1], cuts[1:])]
    _same(reference, PluginOutput.concatenate(parts))
    assert len(reference) == 240 and ticked.ticks == blocks.ticks == n


def test_restored_states_and_an_estimator_reset_between_calls_hold_on_the_compiled_call():
    """The compiled call runs on the sensor's and the estimators' own arrays; a restored
    state or a reset replaces them (``arrays_version``), and the next call runs on the new
    ones."""
    h = 0.001
    frames = HostFrames()
    truth = _truth(frames, h)
    one = lambda i: {k: v[i] for k, v in truth.items()}  # noqa: E731
    kwargs = dict(tick_s=h, seed=2, estimators=ESTIMATORS, speed_from_velocity=True)
    fast, general = ImuPlugin(**kwargs), ImuPlugin(**kwargs)
    general.fast_path = False
    outs = {id(fast): [], id(general): []}
    for plugin in (fast, general):
        for i in range(300):
            outs[id(plugin)].append(plugin.step(**one(i)))
        state = plugin.get_state()
        for i in range(300, 500):
            plugin.step(**one(i))
        plugin.set_state(state)  # back to tick 300
        for i in range(300, 700):
            outs[id(plugin)].append(plugin.step(**one(i)))
        plugin.estimators["faithful"].reset()  # a user's reset of one estimator
        outs[id(plugin)].append(plugin.step(**{k: v[700:900] for k, v in truth.items()}))
        for i in range(900, 1000):
            outs[id(plugin)].append(plugin.step(**one(i)))
    _same(PluginOutput.concatenate(outs[id(fast)]), PluginOutput.concatenate(outs[id(general)]))
    assert fast.ticks == general.ticks == 1000


def test_reused_outputs_hold_the_same_numbers_and_are_the_next_calls_buffers():
    """``reuse_outputs=True``: each output's arrays are views of the plug-in's buffers (the
    next call writes them again); copied at once, every call's output equals the general
    path's, one tick or blocks per call."""
    h = 0.001
    frames = HostFrames("NED", "FRD", "xyzw")
    truth = _truth(frames, h)
    n = truth["t_s"].shape[0]
    kwargs = dict(tick_s=h, frames=frames, seed=1, estimators=ESTIMATORS, speed_from_velocity=True,
                  mounting=Mounting((0.3, -0.1, 0.2)))
    general = ImuPlugin(**kwargs)
    general.fast_path = False
    reference = general.step(**truth)

    reused = ImuPlugin(**kwargs, reuse_outputs=True)
    outs = [reused.step(**{k: v[i] for k, v in truth.items()}) for i in range(n)]
    latched = [out for out in outs if len(out)]
    assert all(out is latched[0] for out in latched)  # one object per number of samples, written again
    assert np.array_equal(latched[0].gyro_b, reference.gyro_b[-1:])  # it holds the last call's sample

    reused.reset()
    parts = [reused.step(**{k: v[i] for k, v in truth.items()}).copy() for i in range(n)]
    _same(reference, PluginOutput.concatenate(parts))
    reused.reset()
    cuts = np.unique(np.concatenate(([0, n], np.random.default_rng(1).integers(1, n, 40))))
    parts = [reused.step(**{k: v[a:b] for k, v in truth.items()}).copy() for a, b in zip(cuts[:-1], cuts[1:])]
    _same(reference, PluginOutput.concatenate(parts))
    with pytest.raises(TypeError, match="reuse_outputs"):
        ImuPlugin(tick_s=h, reuse_outputs="yes")
