"""The virtual GNSS receiver: timing and latency, the noise model's statistics, outages,
geodetic output, streaming = batch bit for bit, bad input."""

import dataclasses
import math

import numpy as np
import pytest

from biso_cosim.sensors.gnss import (
    CONSUMER,
    IDEAL,
    GnssFixes,
    GnssProfile,
    GnssReceiver,
    TimeOutage,
    ZoneOutage,
    gnss_profile_table,
)

F_IN = 1000.0


def _track(seconds, f_in=F_IN):
    """A smooth analytic track: position and its exact derivative."""
    t = np.arange(int(round(seconds * f_in))) / f_in
    pos = np.stack([12.0 * t + 3.0 * np.sin(0.4 * t), 40.0 * np.sin(0.1 * t), 0.5 * np.cos(0.3 * t)], axis=1)
    vel = np.stack([12.0 + 1.2 * np.cos(0.4 * t), 4.0 * np.cos(0.1 * t), -0.15 * np.sin(0.3 * t)], axis=1)
    return t, pos, vel


def _profile(**changes):
    return dataclasses.replace(IDEAL, name="test", **changes)


def test_ideal_fixes_are_the_truth_at_the_epochs_and_latency_delays_delivery():
    t, pos, vel = _track(4.0)
    fixes = GnssReceiver("ideal", rate_hz=5.0).simulate(pos, vel)
    np.testing.assert_allclose(fixes.t_s, np.arange(20) / 5.0)
    np.testing.assert_array_equal(fixes.t_arrival_s, fixes.t_s)
    assert fixes.valid.all()
    i = np.round(fixes.t_s * F_IN).astype(int)
    np.testing.assert_array_equal(fixes.pos_w, pos[i])
    np.testing.assert_array_equal(fixes.vel_w, vel[i])
    # epochs between input samples: linear interpolation of the truth
    rx = GnssReceiver("ideal", rate_hz=3.0, input_rate_hz=F_IN)
    f3 = rx.simulate(pos, vel)
    np.testing.assert_allclose(f3.t_s, np.arange(12) / 3.0)
    for a in range(3):
        np.testing.assert_allclose(f3.vel_w[:, a], np.interp(f3.t_s, t, vel[:, a]), rtol=0, atol=1e-12)
    # latency: same fixes, delivered 0.25 s later, the last one not yet
    late = GnssReceiver(_profile(latency_s=0.25), rate_hz=5.0).simulate(pos, vel)
    np.testing.assert_allclose(late.t_arrival_s - late.t_s, 0.25)
    assert len(late) == np.count_nonzero(fixes.t_s + 0.25 <= t[-1] + 1e-12)
    np.testing.assert_array_equal(late.vel_w, fixes.vel_w[:len(late)])


def test_a_call_returns_the_fixes_delivered_during_its_input_span():
    t, pos, vel = _track(2.0)
    rx = GnssReceiver(_profile(latency_s=0.0175), rate_hz=10.0)
    first = rx.simulate(pos[:20], vel[:20])  # samples 0..19 ms: epoch 0 arrives at 17.5 ms, delivered at 18 ms
    assert len(first) == 1 and first.t_s[0] == 0.0
    second = rx.simulate(pos[20:118], vel[20:118])  # up to 117 ms: epoch 0.1 s arrives at 117.5 ms: not yet
    assert len(second) == 0
    third = rx.simulate(pos[118:119], vel[118:119])
    assert len(third) == 1 and third.t_s[0] == pytest.approx(0.1)
    assert rx.time_s == pytest.approx(0.119)


def test_any_chunking_is_bit_identical_and_reset_repeats():
    t, pos, vel = _track(30.0)
    outages = (TimeOutage(5.0, 8.0), ZoneOutage((200.0, 10.0), (240.0, 30.0), 6.0))
    rx = GnssReceiver("consumer", seed=3, rate_hz=5.0, outages=outages)
    whole = rx.simulate(pos, vel)
    rx.reset()
    rng = np.random.default_rng(0)
    parts, i = [], 0
    while i < len(t):
        n = int(rng.integers(0, 700))
        parts.append(rx.simulate(pos[i:i + n], vel[i:i + n]))
        i += n
    joined = GnssFixes.concatenate(parts)
    for name in ("t_s", "t_arrival_s", "pos_w", "vel_w", "lat_deg", "lon_deg", "alt_m", "valid"):
        np.testing.assert_array_equal(getattr(joined, name), getattr(whole, name), err_msg=name)
    rx.reset(seed=4)
    other = rx.simulate(pos, vel)
    assert not np.allclose(other.pos_w[other.valid], whole.pos_w[whole.valid])
    # get/set state continues exactly
    rx.reset(seed=3)
    rx.simulate(pos[:10000], vel[:10000])
    snap = rx.get_state()
    rest = rx.simulate(pos[10000:], vel[10000:])
    rx2 = GnssReceiver("consumer", seed=99, rate_hz=5.0, outages=outages)
    rx2.set_state(snap)
    again = rx2.simulate(pos[10000:], vel[10000:])
    np.testing.assert_array_equal(again.vel_w, rest.vel_w)


def test_white_noise_statistics():
    n_fix = 20000
    rate = 10.0
    pos = np.zeros((int(n_fix / rate * 20), 3))
    rx = GnssReceiver(_profile(pos_white_m=(2.0, 3.0), vel_white_mps=(0.05, 0.08)), seed=1, rate_hz=rate,
                      input_rate_hz=20.0)
    f = rx.simulate(pos, pos)
    assert len(f) == n_fix
    tol = 4.0 / math.sqrt(2 * n_fix)  # 4σ of a sample standard deviation
    np.testing.assert_allclose(f.pos_w.std(axis=0) / [2.0, 2.0, 3.0], 1.0, atol=tol)
    np.testing.assert_allclose(f.vel_w.std(axis=0) / [0.05, 0.05, 0.08], 1.0, atol=tol)
    np.testing.assert_allclose(f.vel_w.mean(axis=0) / [0.05, 0.05, 0.08], 0.0, atol=4.0 / math.sqrt(n_fix))
    # independent from fix to fix and between axes
    lag1 = np.mean(f.vel_w[1:] * f.vel_w[:-1], axis=0) / f.vel_w.var(axis=0)
    np.testing.assert_allclose(lag1, 0.0, atol=4.0 / math.sqrt(n_fix))
    assert abs(np.corrcoef(f.pos_w[:, 0], f.pos_w[:, 1])[0, 1]) < 4.0 / math.sqrt(n_fix)


def test_gauss_markov_errors_are_stationary_with_the_right_correlation():
    rate, tau, n_fix = 5.0, 2.0, 40000
    rx = GnssReceiver(_profile(vel_gm_mps=(0.1, 0.2), vel_gm_tau_s=tau), seed=2, rate_hz=rate, input_rate_hz=10.0)
    z = np.zeros((int(n_fix / rate * 10), 3))
    v = rx.simulate(z, z).vel_w
    phi = math.exp(-1.0 / (rate * tau))
    # effective sample size of an AR(1) series: n (1 − φ²)/(1 + φ²) for the variance
    n_eff = n_fix * (1 - phi ** 2) / (1 + phi ** 2)
    np.testing.assert_allclose(v.std(axis=0) / [0.1, 0.1, 0.2], 1.0, atol=4.0 / math.sqrt(2 * n_eff))
    for lag in (1, 5, 20):
        r = np.mean(v[lag:] * v[:-lag], axis=0) / np.mean(v * v, axis=0)
        np.testing.assert_allclose(r, phi ** lag, atol=0.05)
    # stationary from the first fix: the first epochs of many seeds have the stationary σ
    first = np.array([GnssReceiver(_profile(vel_gm_mps=(0.1, 0.2), vel_gm_tau_s=tau), seed=s, rate_hz=rate,
                                   input_rate_hz=10.0).simulate(z[:1], z[:1]).vel_w[0] for s in range(1000)])
    np.testing.assert_allclose(first.std(axis=0) / [0.1, 0.1, 0.2], 1.0, atol=4.0 / math.sqrt(2000))


def test_consumer_profile_numbers_and_sources():
    # 2.5 m CEP (u-blox M8) is 2.12 m per horizontal axis; 0.05 m/s (50 %) is 0.042 m/s per axis
    assert CONSUMER.pos_sigma_m[0] == pytest.approx(2.5 / 1.1774, rel=0.01)
    assert CONSUMER.vel_sigma_mps[0] == pytest.approx(0.05 / 1.1774, rel=0.01)
    rows = gnss_profile_table("consumer")
    assert {r["name"] for r in rows} == {"pos_white_m", "pos_gm_m", "pos_gm_tau_s", "vel_white_mps", "vel_gm_mps",
                                         "vel_gm_tau_s", "latency_s", "reacquisition_s"}
    assert all(r["source"] and r["unit"] and r["doc"] for r in rows)


def test_time_outage_and_reacquisition():
    t, pos, vel = _track(20.0)
    rx = GnssReceiver(_profile(reacquisition_s=1.0), rate_hz=5.0, outages=(TimeOutage(5.0, 8.0, label="tunnel"),))
    f = rx.simulate(pos, vel)
    lost = ~f.valid
    # blocked epochs 5.0 … 7.8, then 1 s of reacquisition after the last blocked epoch (7.8 → 8.8)
    np.testing.assert_allclose(f.t_s[lost], np.arange(25, 44) / 5.0)
    assert np.isnan(f.pos_w[lost]).all() and np.isnan(f.vel_w[lost]).all() and np.isnan(f.lat_deg[lost]).all()
    assert np.isfinite(f.pos_w[~lost]).all()


def test_zone_outage_follows_the_true_position():
    t, pos, vel = _track(30.0)
    zone = ZoneOutage((150.0, -100.0), (150.0, 100.0), 5.0, label="bridge")
    f = GnssReceiver("ideal", rate_hz=10.0, outages=(zone,)).simulate(pos, vel)
    i = np.round(f.t_s * F_IN).astype(int)
    inside = np.abs(pos[i, 0] - 150.0) <= 5.0  # the segment spans the track's y range
    np.testing.assert_array_equal(~f.valid, inside)
    assert inside.any()
    # the capsule: ends are round
    disc = ZoneOutage((0.0, 0.0), (0.0, 0.0), 1.0)
    np.testing.assert_array_equal(disc.contains([[0.7, 0.7], [0.71, 0.71], [0.0, -1.0]]), [True, False, True])
    seg = ZoneOutage((0.0, 0.0), (10.0, 0.0), 2.0)
    np.testing.assert_array_equal(seg.contains([[5.0, 1.99], [5.0, 2.01], [11.9, 0.0], [12.1, 0.0], [-1.0, 1.0]]),
                                  [True, False, True, False, True])


def test_geodetic_output_matches_the_local_enu_frame():
    import pymap3d

    from biso_cosim.routes import Site

    site = Site(lat_deg=-33.9, lon_deg=151.2, alt_m=40.0)
    t, pos, vel = _track(5.0)
    f = GnssReceiver("consumer", seed=0, site=site).simulate(pos, vel)
    e, n, u = pymap3d.geodetic2enu(f.lat_deg, f.lon_deg, f.alt_m, site.lat_deg, site.lon_deg, site.alt_m)
    np.testing.assert_allclose(np.stack([e, n, u], axis=1), f.pos_w, atol=1e-6)
    # 1 km north is about 1/111 of a degree of latitude
    g = GnssReceiver("ideal", site=site).simulate([[0.0, 1000.0, 0.0]], [[0.0, 0.0, 0.0]])
    assert g.lat_deg[0] - site.lat_deg == pytest.approx(1000.0 / 110_900.0, rel=0.01)


def test_fixes_records():
    f = GnssFixes.from_arrays([1.0, 2.0], [[1, 0, 0], [0, 1, 0]])
    assert len(f) == 2 and f.valid.all() and np.isnan(f.pos_w).all()
    np.testing.assert_array_equal(f.t_arrival_s, f.t_s)
    assert len(GnssFixes.concatenate([f, GnssFixes.empty(), f[1:]])) == 3
    assert f[0].vel_w.shape == (1, 3)
    with pytest.raises(ValueError, match="vel_w"):
        GnssFixes.from_arrays([1.0, 2.0], [[1, 0, 0]])


def test_csv_round_trip(tmp_path):
    t, pos, vel = _track(3.0)
    f = GnssReceiver("consumer", seed=0, outages=(TimeOutage(1.0, 1.5),)).simulate(pos, vel)
    g = GnssFixes.read_csv(f.write_csv(tmp_path / "gnss.csv"))
    np.testing.assert_array_equal(g.valid, f.valid)
    np.testing.assert_allclose(g.vel_w, f.vel_w, atol=1e-4)
    np.testing.assert_allclose(g.t_arrival_s, f.t_arrival_s, atol=1e-6)
    np.testing.assert_allclose(g.lat_deg, f.lat_deg, atol=1e-9)
    (tmp_path / "min.csv").write_text("t_s,vel_e_mps,vel_n_mps,vel_u_mps\n0.0,1,2,3\n0.2,1,2,3\n")
    h = GnssFixes.read_csv(tmp_path / "min.csv")
    assert h.valid.all() and np.array_equal(h.t_arrival_s, h.t_s) and np.isnan(h.pos_w).all()
    (tmp_path / "bad.csv").write_text("t_s,speed\n0.0,1\n")
    with pytest.raises(ValueError, match="unknown GNSS column"):
        GnssFixes.read_csv(tmp_path / "bad.csv")


def test_bad_input_is_refused_and_changes_nothing():
    t, pos, vel = _track(1.0)
    rx = GnssReceiver("consumer", seed=0)
    rx.simulate(pos[:100], vel[:100])
    snap = rx.get_state()
    bad = pos[100:200].copy()
    bad[17, 1] = np.nan
    with pytest.raises(ValueError, match="pos_w must be finite: row 17"):
        rx.simulate(bad, vel[100:200])
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        rx.simulate(pos[100:200, :2], vel[100:200])
    with pytest.raises(ValueError, match="same number of rows"):
        rx.simulate(pos[100:200], vel[100:150])
    assert rx.time_s == pytest.approx(0.1)
    np.testing.assert_array_equal(rx.get_state()["state"], snap["state"])
    with pytest.raises(ValueError, match="rate_hz"):
        GnssReceiver(rate_hz=20.0)
    with pytest.raises(ValueError, match="unknown GNSS profile"):
        GnssReceiver("survey")
    with pytest.raises(TypeError, match="outages"):
        GnssReceiver(outages=((0.0, 1.0),))
    with pytest.raises(ValueError, match="end_s"):
        TimeOutage(3.0, 1.0)
    with pytest.raises(ValueError, match="half_width_m"):
        ZoneOutage((0, 0), (1, 1), 0.0)
    with pytest.raises(ValueError, match="latency_s"):
        dataclasses.replace(CONSUMER, latency_s=2.0)
    with pytest.raises(ValueError, match="vel_white_mps"):
        GnssProfile(name="x", description="", pos_white_m=(1, 1), pos_gm_m=(0, 0), pos_gm_tau_s=1.0,
                    vel_white_mps=(-1, 0), vel_gm_mps=(0, 0), vel_gm_tau_s=1.0, latency_s=0.0, reacquisition_s=0.0)
    with pytest.raises(TypeError, match="seed"):
        GnssReceiver(seed=1.5)
    with pytest.raises(TypeError, match="site"):
        GnssReceiver(site="Saratov")
    with pytest.raises(ValueError, match="get_state"):
        rx.set_state({"state": np.zeros(3), "rng": np.zeros(4, dtype=np.uint64)})
