"""The Litmanovich (2002) reproduction: files, the 2 % agreement with the drift formulas,
the pseudo-coning/sculling slopes, the least-squares check and the sensor section."""

import json
import math

import numpy as np
import pytest

from biso_cosim.reproduce import litmanovich2002 as repro


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("litmanovich2002")
    return out, repro.run(out, quick=True)


def test_files_and_json(quick_run):
    out, res = quick_run
    for name in ("report.md", "results.json", "fig1_pseudo_sculling_constant.png", "fig2_pseudo_sculling_linear.png",
                 "fig3_pseudo_coning.png", "drift_formulas.png"):
        assert (out / name).stat().st_size > 1000, name
    assert json.loads((out / "results.json").read_text())["checks"] == res["checks"]
    report = (out / "report.md").read_text()
    assert "contradicts the paper" in report and "(4.8)" in report


def test_drift_formulas_within_two_percent(quick_run):
    _, res = quick_run
    assert res["checks"]["coning_drift"]["within_2pct"]
    assert res["checks"]["sculling_error"]["within_2pct"]
    small = [r for r in res["coning_drift"] + res["sculling_error"] if r["x"] <= 0.1]
    assert all(abs(r["ratio"] - 1) < 1e-3 for r in small)
    # end to end at the smallest amplitude, as in section 1
    for r in res["coning_end_to_end"]:
        if r["half_angle_rad"] == 0.003:
            assert r["ratio"] == pytest.approx(1, abs=0.02), r
    for r in res["sculling_end_to_end"]:
        if r["angle_amplitude_rad"] == 1e-3:
            assert r["ratio"] == pytest.approx(1, abs=0.02), r
    # invariant sculling errors swing between ~0 and ~2× the mean over the interval phase
    for r in res["sculling_error"]:
        if r["algorithm"].startswith("invariant") and r["x"] == 0.3:
            assert r["phase_low_over_mean"] < 0.1 and r["phase_high_over_mean"] > 1.9


def test_pseudo_curves(quick_run):
    _, res = quick_run
    ps, pc = res["pseudo_sculling"], res["pseudo_coning"]
    # below the solution frequency the linear-model algorithms pass the rectification on
    for key in ("traditional2", "smoothing", "invariant_accel1", "invariant_rate1"):
        assert ps[key][0] > 0.9
    for key in ("traditional3", "smoothing", "invariant"):
        assert pc[key][0] > 0.95
    assert repro._slope(ps, "invariant_rate1") == pytest.approx(-2, abs=0.2)
    assert repro._slope(ps, "traditional1") == pytest.approx(-1, abs=0.2)
    assert repro._slope(pc, "invariant") == pytest.approx(-2, abs=0.2)
    assert repro._slope(pc, "smoothing") == pytest.approx(-1, abs=0.2)


def test_least_squares_claim():
    assert repro.least_squares_vs_multiple_integrals(100) == pytest.approx(0.0829, abs=5e-4)
    # the difference falls as 1/N towards (3.4)
    assert repro.least_squares_vs_multiple_integrals(4000) < 0.0025
    d1, d2 = repro.least_squares_vs_multiple_integrals(500), repro.least_squares_vs_multiple_integrals(1000)
    assert d1 / d2 == pytest.approx(2, rel=0.05)


def test_sensor_section(quick_run):
    _, res = quick_run
    sensor = res["mpu9250_end_to_end"]
    if not sensor["available"]:
        pytest.skip(sensor["missing"])
    for r in sensor["rows"]:
        # the sensor's own term is predicted by the polyline amplitude loss
        assert (r["measured"] - r["exact_input"]) / r["sensor_term"] == pytest.approx(1, abs=0.03), r
        assert r["exact_input"] / r["formula"] == pytest.approx(1, abs=0.02), r
        assert r["sensor_term"] == pytest.approx(-(r["x"] / r["internal_per_interval"]) ** 2 / 6, rel=0.01)


def test_deterministic():
    a = repro.pseudo_coning(("invariant",), [2.4], periods=2)
    b = repro.pseudo_coning(("invariant",), [2.4], periods=2)
    assert a == b and math.isfinite(a["invariant"][0])
    assert np.isfinite(repro.sculling_error_table((0.2,))[0]["ratio"])
