"""``biso-cosim estimate`` on a run's log repeats the GNSS-aided estimators and the
coning-step (Litmanovich increments) estimators bit for bit: the log holds the receiver's
fixes on the rows where they arrive and the gyro increments a ``gyro_step`` integrates;
a log that is cut, or disagrees with its summary, is refused naming what disagrees."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from biso_cosim.cli import main as cli_main
from biso_cosim.logs import GNSS_COLUMNS, increment_columns, read_gnss_fixes

ESTIMATORS = ("gnss_kalman", "gnss_complementary", "biso:gyro_step=two_sample", "inv=poisson:gyro_step=invariant",
              "biso_plus")


@pytest.fixture(scope="module")
def gnss_run(tmp_path_factory):
    """6 s of the figure eight (30 fixes at 5 Hz; the car drives off at 1 s) with both
    GNSS-aided filters, BISO on two sub-interval increments, the Poisson integration on the
    invariant coning algorithm (four multiple integrals), and biso_plus (wheel odometry)."""
    out = tmp_path_factory.mktemp("gnss_run") / "figure8"
    argv = ["run", "--route", "figure8", "--duration", "6", "--seed", "3", "--out", str(out), "--no-progress"]
    for spec in ESTIMATORS:
        argv += ["--estimator", spec]
    assert cli_main(argv) == 0
    return out


def _summary(run):
    return json.loads((run / "summary.json").read_text())


def test_estimate_repeats_gnss_aided_and_coning_step_estimators_bit_for_bit(gnss_run, tmp_path, capsys):
    capsys.readouterr()
    again = tmp_path / "again.csv"
    assert cli_main(["estimate", str(gnss_run / "log.csv"), "--out", str(again)]) == 0
    printed = capsys.readouterr().out
    assert "skipped" not in printed and "fall-back" not in printed
    assert printed.count("30 GNSS fixes from the log") == 2
    assert "gyro increments (sub, 2 rows) from the log" in printed
    assert "gyro increments (multiple, 4 rows) from the log" in printed
    logged = pd.read_csv(gnss_run / "log.csv")
    repeated = pd.read_csv(again)
    summary = _summary(gnss_run)
    assert set(summary["estimators"]) == {"gnss_kalman", "gnss_complementary", "biso_twosample", "inv", "biso_plus",
                                          "poisson"}
    for key in summary["estimators"]:
        for col in [f"{key}_q{c}" for c in "wxyz"] + [f"{key}_flags"]:
            np.testing.assert_array_equal(repeated[col].to_numpy(), logged[col].to_numpy(), err_msg=col)
    # the GNSS fixes did aid them: flagged updates, and the estimate differs from the unaided one
    for key in ("gnss_kalman", "gnss_complementary"):
        assert summary["estimators"][key]["flagged_samples"] > 0
    unaided = tmp_path / "unaided.csv"
    bare = tmp_path / "bare"
    bare.mkdir()
    logged.drop(columns=list(GNSS_COLUMNS)).to_csv(bare / "log.csv", index=False)
    capsys.readouterr()
    declination = summary["estimator_inputs"]["gnss_kalman"]["params"]["declination_rad"]
    assert cli_main(["estimate", str(bare / "log.csv"), "--out", str(unaided), "--method", "gnss_kalman",
                     "--param", f"declination_rad={declination!r}"]) == 0
    assert "carries no GNSS fixes" in capsys.readouterr().out
    assert not np.array_equal(pd.read_csv(unaided)["gnss_kalman_qx"], logged["gnss_kalman_qx"])
    # one estimator by name takes the run's inputs too
    one = tmp_path / "one.csv"
    assert cli_main(["estimate", str(gnss_run / "log.csv"), "--out", str(one), "--method", "gnss_complementary"]) == 0
    np.testing.assert_array_equal(pd.read_csv(one)["gnss_complementary_qz"], logged["gnss_complementary_qz"])


def test_the_log_holds_each_fix_on_the_row_where_it_arrives(gnss_run):
    log = pd.read_csv(gnss_run / "log.csv")
    summary = _summary(gnss_run)
    fixes = read_gnss_fixes(gnss_run / "log.csv")
    has_fix = log["gnss_t_s"].notna().to_numpy()
    assert len(fixes) == has_fix.sum() == summary["estimator_inputs"]["gnss_kalman"]["gnss_fixes"]
    assert summary["gnss"]["fixes"] >= len(fixes)  # those arriving after the last sample were never used
    # every cell of a fix is filled on its row, and none elsewhere
    assert log.loc[has_fix, list(GNSS_COLUMNS)].notna().all().all()
    assert log.loc[~has_fix, list(GNSS_COLUMNS)].isna().all().all()
    rows = np.flatnonzero(has_fix)
    t = log["t_s"].to_numpy()
    # the first sample at or after the arrival (t_s is written to 0.1 ms)
    assert np.all(t[rows] >= np.round(fixes.t_arrival_s, 4) - 1e-9)
    assert np.all(t[rows - 1] < fixes.t_arrival_s)
    # 5 Hz epochs of validity; arrival = validity + the consumer receiver's latency
    np.testing.assert_allclose(np.diff(fixes.t_s), 0.2, atol=1e-12)
    latency = fixes.t_arrival_s - fixes.t_s
    np.testing.assert_allclose(latency, latency[0], atol=1e-12)
    assert fixes.valid.all() and np.isfinite(fixes.vel_w).all()
    # the fix's velocity is the IMU's at the time of validity, within the receiver's noise
    pos = log[["pos_e_m", "pos_n_m", "pos_u_m"]].to_numpy()
    vel_truth = np.gradient(pos, t, axis=0)[np.searchsorted(t, fixes.t_s - 1e-9)]
    assert np.max(np.abs(fixes.vel_w - vel_truth)) < 0.3
    assert np.max(np.linalg.norm(vel_truth, axis=1)) > 2.0  # the car drives
    # the estimators' record names the columns
    assert summary["estimator_inputs"]["gnss_kalman"]["columns"]["gnss"] == list(GNSS_COLUMNS)


def test_the_logged_increments_are_the_sensors_own(gnss_run):
    """The sub-interval increments of each sample interval add up to the first multiple
    integral ΔΘ¹ (both are sums of the same high-rate samples: ImuSamples); ΔΘ¹ over T = 5 ms
    is the mean rate, near the gyro's DLPF-filtered reading on this slow motion."""
    log = pd.read_csv(gnss_run / "log.csv")
    fed = _summary(gnss_run)["estimator_inputs"]
    sub, multiple = increment_columns("sub", 2), increment_columns("multiple", 4)
    assert fed["biso_twosample"]["columns"]["dtheta_b"] == list(sub)
    assert fed["inv"]["columns"]["dtheta_b"] == list(multiple)
    assert multiple[3:6] == ("dtheta2_x_rad_s", "dtheta2_y_rad_s", "dtheta2_z_rad_s") and multiple[-1] == "dtheta4_z_rad_s3"
    d_sub = log[list(sub)].to_numpy().reshape(-1, 2, 3)
    d1 = log[list(multiple[:3])].to_numpy()
    np.testing.assert_allclose(d_sub.sum(axis=1), d1, rtol=0, atol=1e-15)
    gyro = log[["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"]].to_numpy()
    assert np.max(np.abs(d1 / 0.005 - gyro)) < 0.02
    # ΔΘ² = ∫∫ω: about ΔΘ¹·T/2 for a slowly varying rate (the noise inside the interval aside)
    d2 = log[list(multiple[3:6])].to_numpy()
    assert np.max(np.abs(d2 - d1 * 0.0025)) < 0.25 * np.max(np.abs(d2))


def _cut_dir(tmp_path, gnss_run, name, text):
    where = tmp_path / name
    where.mkdir()
    (where / "log.csv").write_text(text)
    (where / "summary.json").write_text((gnss_run / "summary.json").read_text())
    return where / "log.csv"


def test_a_cut_or_inconsistent_log_is_refused(gnss_run, tmp_path, capsys):
    lines = (gnss_run / "log.csv").read_text().splitlines(keepends=True)
    header = lines[0].rstrip("\n").split(",")
    fix_lines = [i for i, line in enumerate(lines[1:], start=1)
                 if line.split(",")[header.index("gnss_t_s")] != ""]
    samples = _summary(gnss_run)["samples"]

    def refused(log, *extra):
        capsys.readouterr()
        assert cli_main(["estimate", str(log), "--out", str(log.with_name("e.csv")), *extra]) == 2
        assert not log.with_name("e.csv").exists()
        return capsys.readouterr().err

    cut = _cut_dir(tmp_path, gnss_run, "cut", "".join(lines[:fix_lines[10]]))
    assert f"has {fix_lines[10] - 1} rows, but" in refused(cut) and f"logged {samples} samples" in refused(cut)
    # a fix blanked out: the rows agree, the fixes do not
    blank = list(lines)
    cells = blank[fix_lines[3]].rstrip("\n").split(",")
    for name in GNSS_COLUMNS:
        cells[header.index(name)] = ""
    blank[fix_lines[3]] = ",".join(cells) + "\n"
    err = refused(_cut_dir(tmp_path, gnss_run, "blank", "".join(blank)))
    assert "holds 29 GNSS fixes, but" in err and "fed gnss_kalman 30" in err
    # half a fix
    half = list(lines)
    cells = half[fix_lines[5]].rstrip("\n").split(",")
    cells[header.index("gnss_vel_n_mps")] = ""
    half[fix_lines[5]] = ",".join(cells) + "\n"
    err = refused(_cut_dir(tmp_path, gnss_run, "half", "".join(half)))
    assert f"line {fix_lines[5] + 1}: a GNSS fix needs a number in each of" in err
    # the fix columns gone while the summary says the run was fed from them
    log = pd.read_csv(gnss_run / "log.csv")
    gone = tmp_path / "gone"
    gone.mkdir()
    log.drop(columns=list(GNSS_COLUMNS)).to_csv(gone / "log.csv", index=False)
    (gone / "summary.json").write_text((gnss_run / "summary.json").read_text())
    err = refused(gone / "log.csv")
    assert "says gnss_kalman was fed GNSS fixes from the columns gnss_t_s" in err
    # the increments gone
    nodt = tmp_path / "nodt"
    nodt.mkdir()
    log.drop(columns=list(increment_columns("sub", 2))).to_csv(nodt / "log.csv", index=False)
    (nodt / "summary.json").write_text((gnss_run / "summary.json").read_text())
    err = refused(nodt / "log.csv")
    assert "biso_twosample (biso) integrates the gyro increments of its gyro_step, columns dtheta_sub1_x_rad" in err
    # by name without a summary: the increments of the step's form, or a one-line refusal
    err = refused(nodt / "log.csv", "--no-summary", "--method", "biso", "--param", "gyro_step=two_sample")
    assert "columns dtheta_sub1_x_rad, dtheta_sub1_y_rad" in err and "which the log does not have" in err


def test_docs_logs_names_every_column_a_run_writes(gnss_run):
    """docs/logs.md lists each column of the log (the estimators' own by their pattern)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "logs.md").read_text()
    header = (gnss_run / "log.csv").read_text().split("\n", 1)[0].split(",")
    labels = _summary(gnss_run)["estimators"]
    for name in header:
        if any(name.startswith(f"{key}_") for key in labels):
            continue  # <est>_qw ... <est>_flags
        if name.startswith("dtheta"):
            continue  # by pattern, below
        assert f"`{name}`" in text, name
    for name in ("dtheta1_x_rad", "dtheta2_x_rad_s", "dtheta3_x_rad_s2", "dtheta4_x_rad_s3", "dtheta_sub1_x_rad"):
        assert name in text and name in increment_columns("multiple", 4) + increment_columns("sub", 1)
