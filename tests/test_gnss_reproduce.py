"""``reproduce ibrahim2020`` in its quick form: the report, the results and their physics."""

import json

import pytest

from biso_cosim.reproduce import ibrahim2020


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("ibrahim2020")
    return out, ibrahim2020.run(out, quick=True)


def test_writes_the_report_results_and_figures(quick):
    out, results = quick
    assert json.loads((out / "results.json").read_text())["routes"].keys() == set(ibrahim2020.ROUTES)
    report = (out / "report.md").read_text()
    for needle in ("loop600", "banked_oval", "paper, KF", "0.269", "Consistency", "Outage", "Against the paper"):
        assert needle in report
    for name in ibrahim2020.ROUTES:
        assert (out / f"{name}_errors.png").stat().st_size > 10_000
        assert (out / f"{name}_outage.png").stat().st_size > 10_000


def test_gnss_aiding_keeps_the_tilt_where_the_accelerometer_alone_cannot(quick):
    _, results = quick
    oval = results["routes"]["banked_oval"]["stats"]
    for key in ("gnss_complementary", "gnss_kalman"):
        for angle in ("roll", "pitch"):
            assert oval[key][angle]["sigma_deg"] < 0.4
            assert oval[key][angle]["sigma_deg"] < oval["biso"][angle]["sigma_deg"] / 3
    # an ideal receiver changes little: the window's velocity noise nearly cancels
    assert oval["gnss_kalman, ideal GNSS"]["roll"]["sigma_deg"] > 0.5 * oval["gnss_kalman"]["roll"]["sigma_deg"]


def test_consistency_and_outage_figures(quick):
    _, results = quick
    for name in ibrahim2020.ROUTES:
        r = results["routes"][name]
        c = r["consistency"]
        assert c["updates"] >= 40 and 0.5 < c["nis_mean"] < 4.0 and c["above_chi2_p99"] < 0.05
        o = r["outage"]
        assert o["lost_s"][1] - o["lost_s"][0] > 10.0
        coast = o["gnss_kalman/coast"]
        assert max(coast["max_abs_during_deg"]["roll"], coast["max_abs_during_deg"]["pitch"]) < 1.0
        assert coast["unaided_s"] > 5.0


def test_docs_tables_are_in_sync_with_the_parameter_records():
    import re
    from pathlib import Path

    from biso_cosim.estimators.gnss_aided import docs_tables

    page = (Path(__file__).parent.parent / "docs" / "gnss.md").read_text()
    for name, table in docs_tables().items():
        found = re.search(rf"<!-- table:{name} -->\n(.*?)\n<!-- /table -->", page, flags=re.S)
        assert found and found.group(1) == table, f"docs/gnss.md table {name!r} is stale: regenerate it"
