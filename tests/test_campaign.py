"""Campaigns on a real Dask LocalCluster of two worker processes: the rows equal the same runs
made one by one with run_route; resume, Ctrl-C, a killed worker and a failing run lose no
finished row; the CLI on an existing cluster by its scheduler's address."""

import dataclasses
import math
import os
import signal
from importlib import resources

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from biso_cosim.campaign import (CampaignInterrupted, dask_client, load_campaign, load_spec, parse_spec,  # noqa: E402
                                 run_campaign)
from biso_cosim.campaign.store import ResultStore  # noqa: E402
from biso_cosim.cli import main as cli_main  # noqa: E402
from biso_cosim.cosim import EstimatorSpec, run_route  # noqa: E402

ANGLES = ("roll", "pitch", "heading", "total")


@pytest.fixture(scope="module")
def client():
    with dask_client(workers=2) as c:
        yield c


def _small(tmp_path, parts=2, **extra):
    """Two routes (one from a file), two sensor set-ups, four estimators; runs of 2 s."""
    route_file = tmp_path / "my_slalom.toml"
    route_file.write_text(resources.files("biso_cosim.routes").joinpath("library/slalom.toml").read_text())
    data = {"name": "small", "routes": ["figure8", "my_slalom.toml"], "duration_s": 2.0, "parts": parts,
            "sensors": [{}, {"profile": "mpu9250", "registers": {"dlpf_cfg": 2}, "gyro_calibration_s": 0.5}],
            "estimators": [{"name": "biso_plus"}, {"name": "biso", "grid": {"cutoff_hz": [2.0, 5.0]}},
                           {"name": "poisson"}]} | extra
    return parse_spec(data, source="small.toml", base_dir=tmp_path)


def test_campaign_rows_equal_runs_made_one_by_one(tmp_path, client):
    spec = _small(tmp_path)
    table = run_campaign(spec, client, out=tmp_path / "out")
    assert len(table) == 2 * 2 * 2 * 4 and table["run_id"].nunique() == 8
    assert (table["status"] == "partial").all() and table["error"].isna().all()  # short runs: parts of routes
    # every task loaded the numba kernels warm: no compilation inside a task
    assert (table["numba_compilations"] == 0).all()
    sensors = {"mpu9250_calibrated": {},
               "mpu9250[dlpf_cfg=2]": dict(sensor_profile="mpu9250", registers={"dlpf_cfg": 2}, gyro_calibration_s=0.5)}
    estimators = [EstimatorSpec("biso_plus"), EstimatorSpec("biso", {"cutoff_hz": 2.0}, label="biso[cutoff_hz=2.0]"),
                  EstimatorSpec("biso", {"cutoff_hz": 5.0}, label="biso[cutoff_hz=5.0]"), EstimatorSpec("poisson")]
    for (route, sensor, seed), rows in table.groupby(["route", "sensor", "seed"], sort=False):
        where = str(tmp_path / route) if route.endswith(".toml") else route
        summary = run_route(where, duration_s=2.0, seed=int(seed), estimators=estimators, **sensors[sensor]).summary()
        for _, row in rows.iterrows():
            entry = summary["estimators"][row["estimator"]]
            for angle in ANGLES:
                for figure, value in entry["errors"][angle].items():
                    assert row[f"{angle}_{figure}"] == value, (route, sensor, seed, row["estimator"], angle, figure)
            assert row["flagged_samples"] == entry["flagged_samples"]
            assert row["samples"] == summary["samples"] and row["completed_route"] == summary["completed_route"]
            assert row["cross_track_rms_m"] == summary["cross_track_rms_m"]
            assert row["sensor_output_rate_hz"] == summary["sensor"]["output_rate_hz"]
            assert row["route_length_m"] == summary["route"]["length_m"]
    # the stored dataset is the returned table
    pd.testing.assert_frame_equal(load_campaign(tmp_path / "out"), table)


def test_resume_after_ctrl_c_runs_no_finished_run_again(tmp_path, client):
    spec = _small(tmp_path, parts=3)
    out = tmp_path / "out"
    first: list[str] = []

    def interrupt_after_two(rows):
        first.append(rows[0]["run_id"])
        if len(first) == 2:
            raise KeyboardInterrupt

    with pytest.raises(CampaignInterrupted, match="--resume completes"):
        run_campaign(spec, client, out=out, on_run=interrupt_after_two)
    stored = load_campaign(out)
    assert set(stored["run_id"]) == set(first)  # what finished is there; the runs in flight are not
    with pytest.raises(ValueError, match="--resume"):  # the same directory without --resume is refused
        run_campaign(spec, client, out=out)
    second: list[str] = []
    table = run_campaign(spec, client, out=out, resume=True, on_run=lambda rows: second.append(rows[0]["run_id"]))
    assert not set(first) & set(second)
    assert set(first) | set(second) == {run.run_id for run in spec.runs()}
    assert table.attrs["skipped"] == 2 and len(table) == 12 * 4
    before = stored.set_index(["run_id", "estimator"])
    after = table.set_index(["run_id", "estimator"]).loc[before.index]
    pd.testing.assert_frame_equal(after, before)  # the rows of the first session, untouched
    # a different spec is refused on resume, naming the field
    with pytest.raises(ValueError, match="'parts'"):
        run_campaign(_small(tmp_path, parts=4), client, out=out, resume=True)


def test_killed_worker_loses_no_finished_row(tmp_path, client):
    spec = _small(tmp_path, parts=1)
    out = tmp_path / "out"
    pids = client.run(os.getpid)
    killed: list[int] = []
    before: list[pd.DataFrame] = []

    def kill_a_worker(rows):
        if not killed:
            before.append(load_campaign(out))  # the rows finished so far
            victim = next(pid for address, pid in pids.items() if not rows[0]["worker"].endswith(f":{pid}"))
            os.kill(victim, signal.SIGKILL)  # the other worker, busy with its own run
            killed.append(victim)

    table = run_campaign(spec, client, out=out, on_run=kill_a_worker)
    assert killed and len(table) == 4 * 4 and table["run_id"].nunique() == 4
    assert (table["status"] != "failed").all()  # the lost run ran again on a live worker
    finished = before[0].set_index(["run_id", "estimator"])
    assert len(finished) >= 4  # one run's rows at least
    pd.testing.assert_frame_equal(table.set_index(["run_id", "estimator"]).loc[finished.index], finished)
    assert killed[0] not in client.run(os.getpid).values()  # the nanny started a new worker process
    # the same rows as a campaign nothing happened to (same runs, same numbers)
    clean = run_campaign(spec, client, out=tmp_path / "clean")
    figures = [c for c in table.columns if c.endswith(("_rms_deg", "_max_abs_deg", "_mean_deg"))]
    pd.testing.assert_frame_equal(table[["run_id", "estimator", *figures]], clean[["run_id", "estimator", *figures]])


def test_a_failing_run_is_a_row_and_the_campaign_goes_on(tmp_path, client):
    spec = _small(tmp_path, parts=1)
    bad = dataclasses.replace(spec.routes[1], text='name = "broken"\n')  # a route file that no longer parses
    spec = dataclasses.replace(spec, routes=(spec.routes[0], bad))
    table = run_campaign(spec, client, out=tmp_path / "out")
    failed = table[table["route"] == "my_slalom.toml"]
    assert len(failed) == 2 * 4 and (failed["status"] == "failed").all()
    assert failed["error"].str.startswith("ValueError: ").all()
    assert failed["error"].str.contains("missing required key").all()
    good = table[table["route"] == "figure8"]
    assert (good["status"] == "partial").all() and np.isfinite(good["heading_rms_deg"]).all()
    # resume runs the failed runs again (here they fail again) and keeps each (run, estimator) once
    again = run_campaign(spec, client, out=tmp_path / "out", resume=True)
    assert again.attrs["ran"] == 2 and len(again) == len(table)


def test_cli_on_an_existing_cluster_writes_the_report(tmp_path, client, capsys):
    spec_file = tmp_path / "campaign.toml"
    spec_file.write_text('name = "cli"\nroutes = ["figure8"]\nduration_s = 2\nparts = 3\n'
                         '[[estimators]]\nname = "biso_plus"\n[[estimators]]\nname = "biso"\n'
                         '[statistics]\nbaseline = "biso"\nresamples = 200\n')
    out = tmp_path / "out"
    address = client.scheduler.address
    assert cli_main(["campaign", str(spec_file), "--out", str(out), "--scheduler", address, "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "3 runs" in printed and "0 compilations in the campaign's 3 tasks" in printed
    assert "biso_plus vs biso" in printed and "RMS error over runs" in printed
    for name in ("report.md", "cdf.png", "box.png", "statistics.csv", "paired.csv", "campaign.json"):
        assert (out / name).is_file(), name
    report = (out / "report.md").read_text()
    assert "### heading: RMS error" in report and "| `figure8` | `biso_plus` | 3 |" in report
    stats = pd.read_csv(out / "statistics.csv")
    table = load_campaign(out)
    rms = table[table["estimator"] == "biso"]["heading_rms_deg"]
    row = stats[(stats["estimator"] == "biso") & (stats["metric"] == "heading_rms_deg")].iloc[0]
    assert math.isclose(row["mean"], rms.mean(), rel_tol=1e-12) and row["max"] == rms.max()
    # resuming a finished campaign runs nothing and reports the same
    assert cli_main(["campaign", str(spec_file), "--out", str(out), "--scheduler", address, "--resume",
                     "--no-progress"]) == 0
    assert "3 runs already" in capsys.readouterr().out


def test_keep_logs_writes_each_runs_log(tmp_path, client):
    spec = load_spec_text(tmp_path, 'name = "logs"\nroutes = ["figure8"]\nduration_s = 1\nkeep = "logs"\n'
                                    '[[estimators]]\nname = "biso"\n')
    table = run_campaign(spec, client, out=tmp_path / "out")
    run_dir = tmp_path / "out" / "logs" / table["run_id"].iloc[0]
    log = pd.read_csv(run_dir / "log.csv")
    assert len(log) == table["samples"].iloc[0] and "biso_qw" in log
    assert (run_dir / "summary.json").is_file()
    assert ResultStore(tmp_path / "out").spec()["keep"] == "logs"


def load_spec_text(tmp_path, text):
    path = tmp_path / "spec.toml"
    path.write_text(text)
    return load_spec(path)


def test_estimate_repeats_a_campaign_runs_log_bit_for_bit(tmp_path, client, capsys):
    """A campaign's kept log is written as ``biso-cosim run`` writes it (logs.run_log_inputs):
    the wheel odometry, the gyro increments, the GNSS fixes and summary.json's
    estimator_inputs, so that estimate repeats every estimator of the run."""
    spec = load_spec_text(tmp_path, 'name = "again"\nroutes = ["figure8"]\nduration_s = 3\nkeep = "logs"\n'
                                    '[[estimators]]\nname = "biso_plus"\n'
                                    '[[estimators]]\nname = "gnss_complementary"\n'
                                    '[[estimators]]\nname = "biso"\nlabel = "coning"\nparams = { gyro_step = "two_sample" }\n')
    table = run_campaign(spec, client, out=tmp_path / "out")
    assert set(table["status"]) == {"partial"}
    run_dir = tmp_path / "out" / "logs" / table["run_id"].iloc[0]
    summary = __import__("json").loads((run_dir / "summary.json").read_text())
    fed = summary["estimator_inputs"]
    assert fed["biso_plus"]["columns"]["speed_mps"] == "odometry_mps"
    logged = pd.read_csv(run_dir / "log.csv")
    assert 10 <= fed["gnss_complementary"]["gnss_fixes"] == logged["gnss_t_s"].notna().sum() <= summary["gnss"]["fixes"]
    assert fed["coning"]["columns"]["dtheta_b"][0] == "dtheta_sub1_x_rad"
    capsys.readouterr()
    again = tmp_path / "again.csv"
    assert cli_main(["estimate", str(run_dir / "log.csv"), "--out", str(again)]) == 0
    assert "skipped" not in capsys.readouterr().out
    repeated = pd.read_csv(again)
    for key in ("biso_plus", "gnss_complementary", "coning"):
        for col in [f"{key}_q{c}" for c in "wxyz"] + [f"{key}_flags"]:
            np.testing.assert_array_equal(repeated[col].to_numpy(), logged[col].to_numpy(), err_msg=col)
    # the campaign's rows are unchanged by the log's record (estimator_inputs is the log's, not a column)
    assert not any(c.startswith("estimator_inputs") for c in table.columns)
