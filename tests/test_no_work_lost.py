"""No work lost: --out checked before any work, files written whole or not at all, Ctrl-C
writes what was simulated and exits 130, compare writes each dataset as it finishes,
estimate refuses a cut log; and estimate on a run's log repeats the run's estimates."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from biso_cosim.cli import main as cli_main
from biso_cosim.output import atomic_output, check_output_dir, write_text_atomic

CLI = [sys.executable, "-c", "import sys; from biso_cosim.cli import main; sys.exit(main())"]


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """A 4 s run of the figure eight with the default estimators (biso, biso_plus, poisson)."""
    out = tmp_path_factory.mktemp("run") / "figure8"
    assert cli_main(["run", "--route", "figure8", "--duration", "4", "--out", str(out), "--no-progress"]) == 0
    return out


# ---------------------------------------------------------------- estimate repeats the run
def test_estimate_on_a_runs_log_repeats_every_estimator_bit_for_bit(short_run, tmp_path, capsys):
    capsys.readouterr()
    est = tmp_path / "again.csv"
    assert cli_main(["estimate", str(short_run / "log.csv"), "--out", str(est)]) == 0
    printed = capsys.readouterr().out
    assert "speed from odometry_mps" in printed  # biso_plus was fed the run's wheel odometry
    logged = np.genfromtxt(short_run / "log.csv", delimiter=",", names=True)
    again = np.genfromtxt(est, delimiter=",", names=True)
    summary = json.loads((short_run / "summary.json").read_text())
    assert set(summary["estimators"]) == {"biso", "biso_plus", "poisson"}
    for key in summary["estimators"]:
        for c in "wxyz":
            np.testing.assert_array_equal(again[f"{key}_q{c}"], logged[f"{key}_q{c}"])
        np.testing.assert_array_equal(again[f"{key}_flags"], logged[f"{key}_flags"])
    # what the run fed biso_plus is in the summary: the lever arm to the rear axle, the declination
    fed = summary["estimator_inputs"]["biso_plus"]
    assert fed["columns"] == {"speed_mps": "odometry_mps", "imu_flags": "imu_flags"}
    assert len(fed["params"]["speed_point_b_m"]) == 3 and fed["params"]["speed_point_b_m"][0] < 0.0
    assert fed["params"]["declination_rad"] == pytest.approx(np.radians(summary["site"]["declination_deg"]))
    # one estimator by name takes the run's inputs too
    one = tmp_path / "one.csv"
    assert cli_main(["estimate", str(short_run / "log.csv"), "--out", str(one), "--method", "biso_plus"]) == 0
    np.testing.assert_array_equal(np.genfromtxt(one, delimiter=",", names=True)["biso_plus_qx"], logged["biso_plus_qx"])


def test_estimate_refuses_a_log_cut_short(short_run, tmp_path, capsys):
    cut_dir = tmp_path / "cut"
    cut_dir.mkdir()
    lines = (short_run / "log.csv").read_text().splitlines(keepends=True)
    (cut_dir / "log.csv").write_text("".join(lines[:300]))
    (cut_dir / "summary.json").write_text((short_run / "summary.json").read_text())
    capsys.readouterr()
    assert cli_main(["estimate", str(cut_dir / "log.csv"), "--out", str(tmp_path / "e.csv")]) == 2
    err = capsys.readouterr().err
    samples = json.loads((short_run / "summary.json").read_text())["samples"]
    assert f"has 299 rows, but {cut_dir / 'summary.json'} says the run logged {samples} samples" in err
    assert not (tmp_path / "e.csv").exists()


# ---------------------------------------------------------------- whole files
def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "log.csv"
    target.write_text("old\n")
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(target) as temporary:
            temporary.write_text("half a ")
            raise KeyboardInterrupt
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv"]
    write_text_atomic(target, "new\n")
    assert target.read_text() == "new\n" and sorted(p.name for p in tmp_path.iterdir()) == ["log.csv"]


def test_the_run_log_is_written_whole_or_not_at_all(short_run, tmp_path, monkeypatch):
    from biso_cosim import logs
    from biso_cosim.cosim import CoSimulation

    result = CoSimulation("figure8", duration_s=1.0, estimators=["poisson"]).run()
    real = np.savetxt

    def cut(path, table, **kw):  # Ctrl-C in the middle of the writing
        real(path, table[:10], **kw)
        raise KeyboardInterrupt

    monkeypatch.setattr(logs.np, "savetxt", cut)
    with pytest.raises(KeyboardInterrupt):
        logs.write_run_log(result, tmp_path / "log.csv")
    assert list(tmp_path.iterdir()) == []


def test_output_directory_checks(tmp_path):
    existing = tmp_path / "a_file"
    existing.write_text("x")
    with pytest.raises(ValueError, match="is an existing file; expected a directory"):
        check_output_dir(existing)
    with pytest.raises(ValueError, match="is a file, not a directory"):
        check_output_dir(existing / "sub")
    with pytest.raises(ValueError, match="cannot write in '/proc'"):
        check_output_dir("/proc/biso_out")
    assert check_output_dir(tmp_path / "new" / "dir") == tmp_path / "new" / "dir"
    assert not (tmp_path / "new").exists()  # nothing made by the check


# ---------------------------------------------------------------- Ctrl-C
def test_ctrl_c_stops_a_run_writes_what_was_simulated_and_exits_130(tmp_path):
    out = tmp_path / "run"
    err_file = tmp_path / "stderr.txt"
    with err_file.open("w") as err:
        proc = subprocess.Popen(CLI + ["run", "--route", "figure8", "--out", str(out)], stdout=subprocess.PIPE,
                                stderr=err, text=True, cwd=tmp_path)
        # wait until the progress bar has counted simulated seconds (the run is under way)
        while proc.poll() is None and not any(f" {n}/" in err_file.read_text() for n in range(3, 20)):
            time.sleep(0.2)
        assert proc.poll() is None, err_file.read_text()
        proc.send_signal(signal.SIGINT)
        stdout, _ = proc.communicate(timeout=300)
    stderr = err_file.read_text()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    assert stdout.splitlines()[0].startswith("RUN INTERRUPTED: interrupted at t = ")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert summary["status_reason"] == f"interrupted at t = {summary['duration_s']:.2f} s"
    assert 2.0 < summary["duration_s"] < 60.0
    rows = (out / "log.csv").read_text().count("\n") - 1
    assert rows == summary["samples"] == round(summary["duration_s"] * 200)
    assert (out / "attitude.png").stat().st_size > 10_000


# ---------------------------------------------------------------- compare
def test_compare_writes_each_dataset_as_it_finishes(tmp_path, monkeypatch):
    from biso_cosim import compare as compare_module

    seen = []

    def on_dataset(result):
        seen.append(len({(r["dataset"], r["seed"]) for r in result["rows"]}))

    result = compare_module.compare([], ["tumble", "shake"], [0], ["biso", "poisson"],
                                    motion_duration_s=3.0, on_dataset=on_dataset)
    assert seen == [1, 2] and len(result["rows"]) == 4
    # the CLI writes results.json after each: stop it in the second dataset, the first is on disk
    out = tmp_path / "cmp"
    real = compare_module.motion_dataset
    calls = []

    def second_interrupted(name, *args, **kwargs):
        calls.append(name)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(name, *args, **kwargs)

    monkeypatch.setattr(compare_module, "motion_dataset", second_interrupted)
    rc = cli_main(["compare", "--routes", "", "--motions", "tumble,shake", "--methods", "biso",
                   "--motion-duration", "3", "--out", str(out), "--no-progress"])
    assert rc == 130
    written = json.loads((out / "results.json").read_text())
    assert [r["dataset"] for r in written["rows"]] == ["tumble"]
