"""The co-simulation loop: reproducibility, consistency of the chain, batch = streaming."""

import json
import math

import numpy as np
import pytest

from biso_cosim.cli import main as cli_main
from biso_cosim.cosim import CoSimulation, EstimatorSpec, run_route
from biso_cosim.estimators import estimate_attitude
from biso_cosim.frames import quat_conjugate, quat_rotate


@pytest.fixture(scope="module")
def figure8_run():
    """The whole figure eight (the car finishes at rest), BISO and the baseline."""
    return run_route("figure8", seed=3)


def test_same_seed_same_run_bit_for_bit():
    a = run_route("figure8", duration_s=8.0, seed=5)
    b = run_route("figure8", duration_s=8.0, seed=5)
    np.testing.assert_array_equal(a.imu.gyro_b, b.imu.gyro_b)
    np.testing.assert_array_equal(a.truth.packed, b.truth.packed)
    for key in a.estimates:
        np.testing.assert_array_equal(a.estimates[key][0], b.estimates[key][0])
    c = run_route("figure8", duration_s=8.0, seed=6)
    assert not np.array_equal(a.imu.gyro_b, c.imu.gyro_b)
    np.testing.assert_array_equal(a.truth.packed, c.truth.packed)  # the seed is the sensor's only


def test_reset_repeats_the_run():
    sim = CoSimulation("figure8", duration_s=6.0, seed=2)
    first = sim.run()
    sim.reset()
    second = sim.run()
    np.testing.assert_array_equal(first.estimates["biso"][0], second.estimates["biso"][0])
    np.testing.assert_array_equal(first.imu.accel_b, second.imu.accel_b)


def test_in_loop_streaming_equals_batch_estimation(figure8_run):
    run = figure8_run
    declination = math.radians(run.site["declination_deg"])
    for key in ("biso", "poisson"):
        batch = estimate_attitude(run.imu.gyro_b, run.imu.accel_b, run.imu.mag_b, run.sensor["output_rate_hz"],
                                  method=key, declination_rad=declination)
        np.testing.assert_array_equal(batch, run.estimates[key][0])


def test_truth_is_taken_at_the_sample_times(figure8_run):
    run = figure8_run
    np.testing.assert_array_equal(run.truth.t_s, run.imu.t_s)
    dt = 1.0 / run.sensor["output_rate_hz"]
    np.testing.assert_allclose(np.diff(run.t_s), dt, atol=1e-9)
    assert run.t_s[0] == 0.0
    np.testing.assert_allclose(np.linalg.norm(run.truth.q_wb, axis=1), 1.0, atol=1e-12)


def test_ideal_sensor_chain_is_consistent():
    """With an error-free sensor, uncorrected integration follows the truth, and the
    magnetometer reads the world field rotated into the sensor frame."""
    sim = CoSimulation("figure8", duration_s=20.0, seed=0, sensor_profile="ideal",
                       estimators=["poisson"], gyro_calibration_s=0.0)
    run = sim.run()
    err = run.errors("poisson")
    # the chip's low-pass filter delays the gyro by a few ms: small errors while turning
    assert np.max(err["total"]) < 0.5
    assert np.sqrt(np.mean(err["total"] ** 2)) < 0.1
    at_rest = run.t_s < 1.5  # standing still before driving off
    field_w = np.asarray(run.site["field_enu_ut"])
    expected = quat_rotate(quat_conjugate(run.truth.q_wb[at_rest]), np.broadcast_to(field_w, (at_rest.sum(), 3)))
    np.testing.assert_allclose(run.imu.mag_b[at_rest], expected, atol=0.2)  # 16-bit step 0.15 µT
    np.testing.assert_allclose(run.imu.accel_b[at_rest].mean(axis=0), [0, 0, 9.80665], atol=5e-3)


def test_start_to_end_on_a_closed_route(figure8_run):
    run = figure8_run
    summary = run.summary()
    assert summary["completed_route"]
    truth = summary["truth_start_end_deg"]
    # the car parks where it started: tilt as at the start, heading within a few degrees
    assert abs(truth["roll"]) < 0.05 and abs(truth["pitch"]) < 0.05 and abs(truth["heading"]) < 5.0
    biso = summary["estimators"]["biso"]
    for angle in ("roll", "pitch", "heading"):
        assert biso["start_end_error_deg"][angle] == pytest.approx(biso["start_end_deg"][angle] - truth[angle])
    # BISO's correction holds the closure near the truth; errors are finite and recorded
    assert abs(biso["start_end_error_deg"]["roll"]) < 0.5 and abs(biso["start_end_error_deg"]["pitch"]) < 0.5
    json.dumps(summary, default=str)


def test_estimator_specs_and_bad_arguments():
    with pytest.raises(ValueError, match="unknown route 'nowhere'.*figure8"):
        CoSimulation("nowhere")
    with pytest.raises(ValueError, match="duration_s"):
        CoSimulation("figure8", duration_s=-1)
    with pytest.raises(ValueError, match="seed"):
        CoSimulation("figure8", seed=-3)
    with pytest.raises(ValueError, match="unknown estimator"):
        CoSimulation("figure8", duration_s=1, estimators=["nope"])
    with pytest.raises(ValueError, match="labels must be unique"):
        CoSimulation("figure8", duration_s=1, estimators=["biso", "biso"])
    sim = CoSimulation("figure8", duration_s=1.0, estimators=[
        "biso", EstimatorSpec("biso", {"cutoff_hz": 2.0}, label="biso_2hz")])
    assert set(sim.run().estimates) == {"biso", "biso_2hz"}


def test_cli_run_writes_summary_log_and_plot(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli_main(["run", "--route", "figure8", "--duration", "6", "--seed", "1", "--out", str(out),
                     "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "biso" in printed and "poisson" in printed and "RMS" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["estimators"]) == {"biso", "biso_plus", "poisson"}
    assert (out / "attitude.png").stat().st_size > 10_000
    header = (out / "log.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "t_s" and "biso_qw" in header and "gyro_x_rad_s" in header
    # re-estimating from the log reproduces the in-loop estimates (to the log's precision); the
    # declination comes from the log's own column
    est_out = tmp_path / "est.csv"
    capsys.readouterr()
    assert cli_main(["estimate", str(out / "log.csv"), "--out", str(est_out), "--method", "biso"]) == 0
    assert f"declination {summary['site']['declination_deg']:.2f}°" in capsys.readouterr().out
    logged = np.genfromtxt(out / "log.csv", delimiter=",", names=True)
    again = np.genfromtxt(est_out, delimiter=",", names=True)
    for c in "wxyz":
        np.testing.assert_allclose(again[f"biso_q{c}"], logged[f"biso_q{c}"], atol=2e-6)


def test_cli_errors_are_one_line_and_name_the_problem(tmp_path, capsys):
    assert cli_main(["run", "--route", "nowhere", "--out", str(tmp_path)]) == 2
    assert "known routes" in capsys.readouterr().err
    assert cli_main(["run", "--route", "figure8", "--duration", "-5", "--out", str(tmp_path)]) == 2
    assert "--duration" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,gyro_x_rad_s\n0,1\n")
    assert cli_main(["estimate", str(bad), "--out", str(tmp_path / "o.csv")]) == 2
    assert "missing column" in capsys.readouterr().err


def test_blocked_run_equals_stepping_period_by_period():
    blocked = CoSimulation("figure8", duration_s=5.0, seed=4)
    a = blocked.run(block_periods=7)
    stepped = CoSimulation("figure8", duration_s=5.0, seed=4)
    while not stepped.done:
        stepped.step()
    b = stepped.result()
    np.testing.assert_array_equal(a.truth.packed, b.truth.packed)
    np.testing.assert_array_equal(a.imu.mag_b, b.imu.mag_b)
    for key in a.estimates:
        np.testing.assert_array_equal(a.estimates[key][0], b.estimates[key][0])
    with pytest.raises(ValueError, match="block_periods"):
        blocked.run(block_periods=0)


def test_dead_reckoning_navigators_follow_the_truth_with_an_ideal_sensor():
    from biso_cosim.cosim import NAVIGATOR_PRESETS

    run = run_route("figure8", duration_s=30.0, seed=0, sensor_profile="ideal", estimators=["poisson"],
                    navigators=list(NAVIGATOR_PRESETS))
    errors = run.summary()["navigators"]
    assert set(errors) == set(NAVIGATOR_PRESETS)
    for key, e in errors.items():
        # 30 s of driving, no aiding: the chain sensor increments → navigator is consistent
        assert e["attitude_max_deg"] < 0.02, key
        assert e["horizontal_position_end_m"] < 0.1, key
    # the higher-order families beat the one-sample one on position
    assert errors["invariant"]["horizontal_position_end_m"] < errors["one_sample"]["horizontal_position_end_m"]
    # with the calibrated MPU-9250 the accelerometer residual dominates: metres, not millimetres
    real = run_route("figure8", duration_s=30.0, seed=0, estimators=["poisson"], navigators=["invariant"])
    assert real.summary()["navigators"]["invariant"]["horizontal_position_end_m"] > 1.0
    with pytest.raises(ValueError, match="unknown navigator 'kalman'"):
        CoSimulation("figure8", duration_s=1.0, navigators=["kalman"])


def test_whole_state_get_set_goes_back_in_time_exactly():
    import pickle

    sim = CoSimulation("figure8", duration_s=12.0, seed=2, estimators=["biso", "biso_plus"], navigators=["invariant"])
    for _ in range(150):  # 3 s
        sim.step()
    state = pickle.loads(pickle.dumps(sim.get_state()))
    for _ in range(200):
        sim.step()
    first = sim.result()
    sim.set_state(state)
    for _ in range(200):
        sim.step()
    second = sim.result()
    np.testing.assert_array_equal(first.truth.packed, second.truth.packed)
    np.testing.assert_array_equal(first.imu.gyro_b, second.imu.gyro_b)
    for key in first.estimates:
        np.testing.assert_array_equal(first.estimates[key][0], second.estimates[key][0])
    np.testing.assert_array_equal(first.navigation["invariant"]["p_w"], second.navigation["invariant"]["p_w"])
    # into a fresh instance of the same set-up: the same future, the log starts at the state
    other = CoSimulation("figure8", duration_s=12.0, seed=2, estimators=["biso", "biso_plus"], navigators=["invariant"])
    other.set_state(state)
    for _ in range(200):
        other.step()
    third = other.result()
    assert third.log_start_s == pytest.approx(3.0)
    np.testing.assert_array_equal(third.estimates["biso"][0], first.estimates["biso"][0][-third.t_s.shape[0]:])
    for other in (CoSimulation("figure8", duration_s=12.0, seed=2, estimators=["poisson"]),
                  CoSimulation("slalom", duration_s=12.0, seed=2, estimators=["biso", "biso_plus"],
                               navigators=["invariant"]),
                  CoSimulation("figure8", duration_s=12.0, seed=3, estimators=["biso", "biso_plus"],
                               navigators=["invariant"])):
        with pytest.raises(ValueError, match="another set-up"):
            other.set_state(state)


def test_set_state_never_mixes_histories_in_the_log():
    sim = CoSimulation("figure8", duration_s=12.0, seed=2, estimators=["poisson"])
    for _ in range(50):
        sim.step()
    s50 = sim.get_state()
    for _ in range(100):
        sim.step()
    s150 = sim.get_state()
    fresh = CoSimulation("figure8", duration_s=12.0, seed=2, estimators=["poisson"])
    fresh.set_state(s150)  # another instance: a new log from 3 s
    for _ in range(100):
        fresh.step()
    fresh.set_state(s50)  # earlier than that log: again a new log, from 1 s
    for _ in range(10):
        fresh.step()
    run = fresh.result()
    assert run.log_start_s == pytest.approx(1.0)
    assert np.all(np.diff(run.t_s) > 0) and run.t_s[0] == pytest.approx(1.0)  # the sample latched at 1 s


def test_an_interrupted_run_continues_in_step(monkeypatch):
    """A real SIGINT in the middle of a block of periods (while the progress bar draws after
    the 50th period, the first of the eighth block of seven): run() raises KeyboardInterrupt
    with the sensor and the estimators caught up with the physics, and a second run() goes on
    to the same samples as an uninterrupted run."""
    import signal

    import tqdm

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    draw = tqdm.tqdm.update

    def update_then_interrupt(bar, n=1):
        signal.raise_signal(signal.SIGINT)
        return draw(bar, n)

    sim = CoSimulation("figure8", duration_s=6.0, seed=0, estimators=["poisson"])
    try:
        monkeypatch.setattr(tqdm.tqdm, "update", update_then_interrupt)
        with pytest.raises(KeyboardInterrupt):
            sim.run(progress=True, block_periods=7)
        monkeypatch.setattr(tqdm.tqdm, "update", draw)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert sim.result().truth.t_s[-1] == pytest.approx(50 / 50.0, abs=0.02)  # the 50 periods it drove
    run = sim.run()
    np.testing.assert_allclose(run.truth.t_s, run.imu.t_s, atol=1e-12)
    reference = CoSimulation("figure8", duration_s=6.0, seed=0, estimators=["poisson"]).run()
    np.testing.assert_array_equal(run.imu.gyro_b, reference.imu.gyro_b)


def test_gnss_receiver_in_the_loop_loses_its_fix_in_the_underpass():
    sim = CoSimulation("loop600", duration_s=40.0, seed=0, gnss="consumer", estimators=["poisson"])
    run = sim.run()
    fixes = run.gnss
    np.testing.assert_allclose(np.diff(fixes.t_s), 0.2, atol=1e-9)  # 5 Hz
    under = ~fixes.valid
    assert under.any() and not under[:20].any()
    # invalid where the antenna was within 10 m of the underpass (x 200..250 m), or reacquiring after it
    truth_x = np.interp(fixes.t_s[under], run.t_s, run.truth.pos_w[:, 0])
    assert truth_x.min() > 189.0 and truth_x.max() < 270.0
    sim.reset()
    again = sim.run()
    np.testing.assert_array_equal(again.gnss.pos_w[~under], fixes.pos_w[~under])
    assert CoSimulation("figure8", duration_s=1.0).gnss_receiver is None  # "auto": nobody needs it


def test_agent_commands_are_checked_before_the_physics():
    from biso_cosim.vehicle.driver import DriverCommand

    sim = CoSimulation("figure8", duration_s=2.0, estimators=["poisson"])
    before = sim.get_state()
    with pytest.raises(ValueError, match=r"command.steer_rad must be a finite number"):
        sim.step(DriverCommand(float("nan"), 0.2, 0.0))
    with pytest.raises(ValueError, match=r"command.brake must be a finite number in \[0, 1\]"):
        sim.step(DriverCommand(0.0, 0.0, 2.0))
    with pytest.raises(TypeError, match="DriverCommand"):
        sim.step((0.0, 0.5, 0.0))
    np.testing.assert_array_equal(sim.get_state().physics, before.physics)  # nothing moved
    sim.step(DriverCommand(0.1, 0.3, 0.0))


def test_mujoco_sensor_rows_belong_to_the_start_of_their_step():
    import copy

    import mujoco

    sim = CoSimulation("figure8", duration_s=2.0, estimators=["poisson"])
    vehicle = sim.vehicle
    probe = copy.copy(vehicle.data)  # the IMU's position in the state before the step
    mujoco.mj_kinematics(vehicle.model, probe)
    before = probe.site_xpos[vehicle.index.imu_site].copy()
    truth = vehicle.step(1)
    np.testing.assert_array_equal(truth.pos_w[0], before)
    assert truth.t_s[0] == 0.0


def test_cli_input_errors_and_bugs_are_told_apart(tmp_path, capsys):
    from biso_cosim.logs import SENSOR_COLUMNS

    rows = [",".join(c for cols in SENSOR_COLUMNS.values() for c in cols)] + ["0,0,0,0,0,9.8,20,0,-40"] * 5
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    assert cli_main(["estimate", str(tmp_path / "in.csv"), "--out", str(tmp_path / "o.csv"), "--fs", "100",
                     "--param", "bogus=1"]) == 2
    assert "bogus" in capsys.readouterr().err


def test_cli_estimator_specs_carry_parameters_and_labels(tmp_path, capsys):
    from biso_cosim.cli import UserError, estimator_spec

    spec = estimator_spec("biso:k=(1.0,2.0,3.0,4.0),k_p=0,reference=euler")
    assert spec.name == "biso" and spec.params == {"k": (1.0, 2.0, 3.0, 4.0), "k_p": 0, "reference": "euler"}
    assert spec.key == "biso_1.02.03.04.0_0_euler"
    assert estimator_spec("inv=poisson:gyro_step=invariant").key == "inv"
    assert estimator_spec("biso_plus").params == {}
    for bad in ("biso:k", "biso:k=", "=biso", ":k=1"):
        with pytest.raises(UserError, match="--estimator"):
            estimator_spec(bad)
    out = tmp_path / "run"
    assert cli_main(["run", "--route", "figure8", "--duration", "2", "--out", str(out), "--no-progress", "--no-log",
                     "--estimator", "inv=poisson:gyro_step=invariant", "--estimator", "biso:cutoff_hz=5"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["estimators"]) == {"inv", "biso_5", "poisson"}
    assert cli_main(["run", "--route", "figure8", "--duration", "2", "--out", str(out),
                     "--estimator", "biso:nope=1"]) == 2
    assert "no parameter(s) ['nope']" in capsys.readouterr().err


def test_without_a_log_the_periods_are_the_same_and_memory_stays_constant():
    """keep_log=False (environments, FMUs): step() returns the same outputs bit for bit, the
    log stays empty, result() is refused with the reason and run() returns None."""
    logged = CoSimulation("figure8", duration_s=1.0, seed=3)
    bare = CoSimulation("figure8", duration_s=1.0, seed=3, keep_log=False)
    for _ in range(10):
        a, b = logged.step(), bare.step()
        np.testing.assert_array_equal(a[0].gyro_b, b[0].gyro_b)
        np.testing.assert_array_equal(a[1].packed, b[1].packed)
        for key in a[2]:
            np.testing.assert_array_equal(a[2][key].q_wb, b[2][key].q_wb)
    assert all(n == 0 for n in bare._log_lengths().values())
    with pytest.raises(RuntimeError, match="keep_log=False"):
        bare.result()
    assert bare.run() is None and bare.done
    state = logged.get_state()
    bare.reset()
    bare.set_state(state)  # states move between logged and unlogged co-simulations
    np.testing.assert_array_equal(logged.step()[0].accel_b, bare.step()[0].accel_b)
    with pytest.raises(TypeError, match="keep_log"):
        CoSimulation("figure8", duration_s=1.0, keep_log=1)


def test_sensor_inputs_kernel_equals_field_b_and_the_truth_columns():
    """The co-simulation's one kernel for the sensor's inputs (no local disturbances) gives
    the truth's rate and specific force and MagneticEnvironment.field_b, bit for bit, and
    reports a position that is not finite (field_b's refusal)."""
    from biso_cosim.loop import sensor_inputs as _sensor_inputs
    from biso_cosim.vehicle.sim import Truth

    sim = CoSimulation("figure8", duration_s=2.0, estimators=("poisson",))
    truth = Truth.concatenate([sim._drive() for _ in range(40)])
    omega, force, mag = np.empty((3, len(truth), 3))
    field = sim.magnetic.earth.field_enu_ut
    assert _sensor_inputs(truth.packed, field, omega, force, mag)
    assert np.array_equal(omega, truth.omega_b) and np.array_equal(force, truth.specific_force_b)
    assert np.array_equal(mag, sim.magnetic.field_b(truth.q_wb, truth.pos_w))
    bad = truth.packed.copy()
    bad[5, 12] = np.nan
    assert not _sensor_inputs(bad, field, omega, force, mag)


def _assert_same_samples(a, b):
    for name in ("t_s", "gyro_b", "accel_b", "mag_b", "mag_fresh", "temperature_c", "flags", "dtheta", "dv",
                 "dtheta_sub", "dv_sub"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name
    assert np.array_equal(a.raw.words, b.raw.words) and np.array_equal(a.raw.status, b.raw.status)


@pytest.mark.parametrize("options, in_loop", [
    ({}, ["biso", "biso_plus", "poisson"]),  # (poisson is BISO without correction)
    ({"estimators": ("biso", ("biso", {"cutoff_hz": 2.0}, "second"), "biso_plus", ("biso", {}, "third"), "dcm_pi")},
     ["biso", "second", "biso_plus", "third", "dcm_pi"]),
    ({"navigators": ("two_sample",), "gnss": "consumer",
      "estimators": ("biso", "biso_plus", ("biso", {"gyro_step": "two_sample"}, "biso_coning"), "gnss_kalman")},
     ["biso", "biso_plus", "biso_coning", "gnss_kalman"]),  # (the increments and the receiver's fixes: in the call)
    ({"sensor_profile": "mpu9250", "gyro_calibration_s": 1.0, "navigators": ("two_sample",), "gnss": "consumer",
      "estimators": ("biso", "biso_plus", ("biso", {"gyro_step": "two_sample"}, "biso_coning"), "gnss_kalman")}, []),
])
@pytest.mark.parametrize("reuse", [False, True])
def test_period_kernel_equals_the_general_path(options, in_loop, reuse):
    """step() senses a period by one call (truth packing, sensor inputs, MPU-9250, truth at
    the samples, and every estimator that declares a loop kernel): the same numbers, bit for
    bit, as the general path (``fast_path = False``); also when, as for the environments,
    every period's samples and estimates are written into the same arrays. A coning-algorithm
    gyro step (the sensor's increments, ``PeriodSamples.dtheta_sub_b``), the GNSS receiver and
    the GNSS-aided filters run in it; a gyro offset to remove first takes the general path."""
    opts = dict(options)
    estimators = opts.pop("estimators", ("biso", "biso_plus", "poisson"))
    specs = [e if isinstance(e, str) else EstimatorSpec(e[0], e[1], label=e[2]) for e in estimators]
    fused = CoSimulation("figure8", duration_s=4.0, seed=2, estimators=specs, keep_log=not reuse,
                         reuse_outputs=reuse, **opts)
    general = CoSimulation("figure8", duration_s=4.0, seed=2, estimators=specs, **opts)
    general.fast_path = False
    assert list(fused.loop_estimators) == in_loop and general.loop_estimators == ()
    previous = None
    while not fused.done:
        samples, truth, outputs = fused.step()
        want_samples, want_truth, want_outputs = general.step()
        _assert_same_samples(samples, want_samples)
        assert np.array_equal(truth.packed, want_truth.packed)
        assert list(outputs) == list(want_outputs)
        for key, out in outputs.items():
            want = want_outputs[key]
            assert np.array_equal(out.q_wb, want.q_wb) and np.array_equal(out.flags, want.flags), key
            assert (out.gyro_bias_b is None) == (want.gyro_bias_b is None), key
            assert out.gyro_bias_b is None or np.array_equal(out.gyro_bias_b, want.gyro_bias_b), key
        if previous is not None and in_loop and len(samples.t_s):  # views of the one set of arrays, or new ones
            assert np.shares_memory(samples.gyro_b, previous) == reuse
        previous = samples.gyro_b
    for key, est in fused.estimators.items():
        assert np.array_equal(est.get_state().values, general.estimators[key].get_state().values), key
    if not reuse:
        assert np.array_equal(fused.result().truth.packed, general.result().truth.packed)


def _step_both(fused, general, periods):
    """Step both co-simulations; each period's samples, truth and estimates the same."""
    for _ in range(periods):
        samples, truth, outputs = fused.step()
        want_samples, want_truth, want_outputs = general.step()
        _assert_same_samples(samples, want_samples)
        assert np.array_equal(truth.packed, want_truth.packed)
        for key, out in outputs.items():
            assert np.array_equal(out.q_wb, want_outputs[key].q_wb), key


@pytest.mark.parametrize("change", ["reset", "set_state", "gains", "pattern", "estimator_reset", "imu_state"])
def test_period_plan_gives_way_to_whatever_replaces_its_arrays(change):
    """The period call's arrays, gathered once for an environment's periods, are the
    sensor's and the estimators' own: a reset, a restored state, a parameter change or an
    estimator's reset between periods replaces them (their owners' ``arrays_version``
    counts up; BISO's change of equal gains writes them in place), and the periods after
    are still those of the general path, bit for bit."""
    options = dict(duration_s=3.0, seed=4, estimators=("biso", "biso_plus", "poisson"))
    fused = CoSimulation("figure8", keep_log=False, reuse_outputs=True, **options)
    general = CoSimulation("figure8", **options)
    general.fast_path = False
    _step_both(fused, general, 5)
    saved = [sim.get_state() for sim in (fused, general)]
    _step_both(fused, general, 5)

    def versions():
        return (fused.imu.arrays_version, *(est.arrays_version for est in fused.estimators.values()))

    before = versions()
    for sim, state in zip((fused, general), saved):
        if change == "reset":
            sim.reset()
        elif change == "set_state":
            sim.set_state(state)
        elif change == "gains":  # (in place)
            sim.estimators["biso"].set_params(cutoff_hz=1.5)
        elif change == "pattern":
            sim.estimators["biso"].set_params(pattern=13)
        elif change == "estimator_reset":
            sim.estimators["poisson"].reset(q0=(1.0, 0.0, 0.0, 0.0))
        else:  # the same state in new arrays
            sim.imu.set_state(sim.imu.get_state())
    assert (versions() == before) == (change == "gains")
    _step_both(fused, general, 5)


@pytest.mark.parametrize("case", ["warning", "long_period"])
@pytest.mark.parametrize("reuse", [False, True])
def test_step_reads_the_sensor_history_or_steps_again(tmp_path, monkeypatch, case, reuse):
    """step() leaves a period's rows in MuJoCo's sensor history for the period kernel; after
    a MuJoCo warning (here a non-finite control, which MuJoCo zeroes and goes on) the period is
    stepped again, and a period longer than the history is stepped through
    ``VehicleSim.step_rows``: either way the numbers of the general path, also from the
    arguments an environment's periods reuse."""
    from biso_cosim.cosim import CONTROLS_APPLIED

    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warnings to MUJOCO_LOG.TXT here
    rate = 4.0 if case == "long_period" else 50.0
    fused = CoSimulation("figure8", duration_s=2.0, seed=3, estimators=("biso_plus",), control_rate_hz=rate,
                         keep_log=not reuse, reuse_outputs=reuse)
    general = CoSimulation("figure8", duration_s=2.0, seed=3, estimators=("biso_plus",), control_rate_hz=rate)
    general.fast_path = False
    for period in range(6):
        command = None
        if case == "warning" and period == 3:
            for sim in (fused, general):  # the last period's controls, the steering not finite
                sim.vehicle.data.ctrl[sim.vehicle.index.steer] = np.nan
            command = CONTROLS_APPLIED
        samples, truth, outputs = fused.step(command)
        want_samples, want_truth, want_outputs = general.step(command)
        _assert_same_samples(samples, want_samples)
        assert np.array_equal(truth.packed, want_truth.packed)
        assert np.array_equal(outputs["biso_plus"].q_wb, want_outputs["biso_plus"].q_wb)
    assert fused.vehicle.periods_with_warnings == general.vehicle.periods_with_warnings == (case == "warning")


def test_a_state_mujoco_resets_stops_both_paths_at_the_same_step(tmp_path, monkeypatch):
    """A diverged state (MuJoCo would reset the data and go on): step() raises PhysicsDiverged
    at the same step on the period kernel's path and on the general one, and refuses to go on."""
    from biso_cosim.vehicle.sim import PhysicsDiverged

    monkeypatch.chdir(tmp_path)
    fused = CoSimulation("figure8", duration_s=2.0, seed=3, estimators=("biso_plus",))
    general = CoSimulation("figure8", duration_s=2.0, seed=3, estimators=("biso_plus",))
    general.fast_path = False
    times = []
    for sim in (fused, general):
        for _ in range(3):
            sim.step()
        sim.vehicle.data.qvel[0] = 1e11
        with pytest.raises(PhysicsDiverged, match=r"unstable at t = 0\.0600 s: MuJoCo found a non-finite or huge "
                                                  r"velocity \(dof 0\)") as caught:
            sim.step()
        times.append(caught.value.t_s)
        assert sim.diverged is caught.value
        with pytest.raises(RuntimeError, match="physics diverged"):
            sim.step()
    assert times[0] == times[1] == pytest.approx(0.06)


def test_wheel_odometry_is_the_front_wheels_times_cos_steering():
    from biso_cosim.vehicle._kernels import _wheel_odometry

    rows = np.random.default_rng(3).normal(size=(50, 23))
    expected = 0.5 * (rows[:, 18] + rows[:, 19]) * 0.3 * np.cos(rows[:, 22])
    out = np.empty(50)
    _wheel_odometry(rows, 0.3, out)
    np.testing.assert_allclose(out, expected, rtol=1e-15, atol=0)  # (NumPy's cos: ≤ 1 ulp)


@pytest.mark.parametrize(("column", "message"), [(1, "omega_b"), (12, "p_w must be finite")])
def test_period_kernel_refuses_bad_rows_as_the_general_path_does(column, message):
    """A non-finite rate or position in the physics rows (injected by the vehicle's public
    ``row_fault`` hook): the general path's error, and the sensor unchanged (the kernel
    refuses before it changes anything)."""
    sim = CoSimulation("figure8", duration_s=2.0, estimators=("poisson",))
    vehicle = sim.vehicle
    gather_column = int(vehicle.history_arrays.gather[column - 1])

    def poison(rows, first_step):
        rows[3, gather_column] = np.nan

    sim.step()
    before = sim.imu.get_state()
    vehicle.row_fault = poison
    with pytest.raises(ValueError, match=message):
        sim.step()
    after = sim.imu.get_state()
    assert all(np.array_equal(after[key], before[key]) for key in before)


def test_a_bad_velocity_is_the_receivers_error_on_either_path():
    """A non-finite velocity in the rows of a run with a GNSS receiver: the receiver's own
    error (``GnssReceiver.simulate``'s), with the sensor and the receiver in the same state
    after it on the fast path (which checks the rows before its chip) as on the general path."""
    from biso_cosim.vehicle._kernels import TRUTH_LAYOUT

    states = []
    for fast_path in (True, False):
        sim = CoSimulation("figure8", duration_s=2.0, estimators=("gnss_kalman",))
        sim.fast_path = fast_path
        column = int(sim.vehicle.history_arrays.gather[TRUTH_LAYOUT.vel_w - 1])  # (East)

        def poison(rows, first_step):
            rows[5, column] = np.inf

        for _ in range(3):
            sim.step()
        receiver = sim.gnss_receiver.get_state()
        sim.vehicle.row_fault = poison
        with pytest.raises(ValueError, match="vel_w must be finite"):
            sim.step()
        assert all(np.array_equal(v, receiver[key]) for key, v in sim.gnss_receiver.get_state().items())
        states.append(sim.imu.get_state())
    assert all(np.array_equal(states[0][key], states[1][key]) for key in states[0])
