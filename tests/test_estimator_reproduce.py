"""The Aleshkin et al. (2024) reproduction (quick mode, without the 600 s drive), the
comparison on a test motion, and the docs' parameter tables in sync with the code."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from biso_cosim.estimators import estimator_names, params_markdown


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    from biso_cosim.reproduce import aleshkin2024

    out = tmp_path_factory.mktemp("aleshkin2024")
    return out, aleshkin2024.run(out, quick=True, loop600=False)


def test_reproduction_writes_its_files(report):
    out, r = report
    for name in ("report.md", "results.json", "fig1_frequency_response.png", "convergence_10rad_s.png"):
        assert (out / name).stat().st_size > 0
    assert json.loads((out / "results.json").read_text())["poles"] == json.loads(json.dumps(r["poles"]))


def test_poles_response_and_convergence(report):
    _, r = report
    p = r["poles"]
    assert p["natural_frequency_hz_reading_D"] == pytest.approx(10.0, rel=2e-3)
    assert p["damping_reading_D"] == pytest.approx(1 / math.sqrt(2), rel=2e-3)
    assert sorted(abs(b) for _, b in p["pattern13_readingD"]) == pytest.approx([25.64, 25.64, 44.41, 44.41], abs=0.01)
    fr_ = r["frequency_response"]
    assert fr_["cross-linked (12)"]["pitch"]["minus3db_hz"] == pytest.approx(12.7, rel=0.02)  # docs/design.md §5
    for c in fr_["discrete_check"]:
        assert c["simulated_abs"] == pytest.approx(c["analytic_abs"], rel=0.01)
        assert c["simulated_phase_deg"] == pytest.approx(c["analytic_phase_deg"], abs=1.0)
    rates = r["rates"]
    assert max(rates["pattern12_D"]["max_real_part"]) == pytest.approx(-44.4, abs=1e-6)
    np.testing.assert_allclose(rates["polynomial_at_w"]["corrected_11"], rates["polynomial_at_w"]["actual"], rtol=1e-9)
    for c in rates["convergence_at_10_rad_s"].values():
        assert c["decay_rate_1_per_s"] == pytest.approx(44.4, rel=0.02)


def test_noise_ratios_are_consistent(report):
    _, r = report
    for n in r["noise"]:
        # the filters reduce the accelerometer's noise; the gyro alone is quieter still
        assert n["without_cross_links"] < n["raw_lambda_k"]
        assert n["gyro_only_detrended"] < n["without_cross_links"]
        assert n["with_cross_links"] > n["without_cross_links"]
        assert n["cross_link_variance_factor_clean_mag"] < n["cross_link_variance_factor"]


def test_compare_on_a_motion():
    from biso_cosim.compare import compare, format_table

    res = compare(routes=(), motions=("magnet",), seeds=(0,), methods=("biso", "biso_plus", "poisson"),
                  motion_duration_s=12.0)
    rows = {r["method"]: r for r in res["rows"]}
    assert set(rows) == {"biso", "biso_plus", "poisson"}
    assert rows["biso_plus"]["errors"]["heading"]["rms_deg"] < rows["biso"]["errors"]["heading"]["rms_deg"]
    assert "| magnet | biso_plus |" in format_table(res)
    with pytest.raises(ValueError, match="vqf"):
        compare(routes=(), motions=("magnet",), methods=("vqff",))


def test_docs_parameter_tables_are_in_sync():
    text = (Path(__file__).resolve().parents[1] / "docs" / "estimators.md").read_text()
    for name in ("biso", "dcm_pi", "biso_plus"):
        block = re.search(rf"<!-- params:{name} -->\n(.*?)\n<!-- /params:{name} -->", text, re.S)
        assert block is not None and block.group(1) == params_markdown(name), name
    for name in estimator_names():
        assert f"`{name}`" in text
