"""Recordings for ``biso-cosim score``: BROAD's HDF5 files, .npz with BROAD's keys and run-log
CSVs read into the same record (tests/data/07_…_excerpt.npz, BROAD, CC BY 4.0)."""

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from biso_cosim.logs import SENSOR_COLUMNS
from biso_cosim.score.readers import (BROAD_RATE_HZ, broad_groups, find_recordings, read_broad_hdf5, read_npz,
                                      read_recording, read_run_log)

EXCERPT = Path(__file__).parent / "data" / "07_undisturbed_fast_rotation_B_excerpt.npz"


def _excerpt():
    with np.load(EXCERPT) as d:
        return {k: d[k] for k in d.files}


def write_hdf5(path, data, *, rate_as="dataset", column_major=False):
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w") as f:
        for key in ("imu_gyr", "imu_acc", "imu_mag", "opt_quat"):
            f.create_dataset(key, data=data[key].T if column_major else data[key])
        f.create_dataset("opt_pos", data=np.zeros((len(data["imu_gyr"]), 3)))
        f.create_dataset("movement", data=data["movement"].astype(np.uint8))
        if rate_as == "dataset":
            f.create_dataset("sampling_rate", data=BROAD_RATE_HZ)
        else:
            f.attrs["sampling_rate"] = BROAD_RATE_HZ
    return path


def write_log_csv(path, data, declination_deg=0.0):
    """A run-log CSV (the columns of biso_cosim.logs) from the excerpt, numbers written exactly."""
    n = len(data["imu_gyr"])
    names = ["t_s", "true_qw", "true_qx", "true_qy", "true_qz"]
    cols = [np.arange(n) / BROAD_RATE_HZ] + [data["opt_quat"][:, i] for i in range(4)]
    for key, src in (("gyro", "imu_gyr"), ("accel", "imu_acc"), ("mag", "imu_mag")):
        names += list(SENSOR_COLUMNS[key])
        cols += [data[src][:, i] for i in range(3)]
    names += ["imu_flags", "declination_deg"]
    cols += [np.zeros(n), np.full(n, declination_deg)]
    np.savetxt(path, np.column_stack([np.asarray(c, np.float64) for c in cols]), fmt="%.17g", delimiter=",",
               header=",".join(names), comments="")
    return path


def test_the_npz_excerpt_reads_with_broads_rate_groups_and_movement():
    rec = read_npz(EXCERPT)
    d = _excerpt()
    assert rec.name == "07_undisturbed_fast_rotation_B_excerpt" and rec.format == "npz"
    assert rec.fs_hz == 2000.0 / 7.0 and len(rec) == 6858
    assert rec.groups == ("all_trials", "undisturbed", "rotation", "fast", "no_breaks")
    np.testing.assert_array_equal(rec.gyro_b, d["imu_gyr"].astype(np.float64))
    np.testing.assert_array_equal(rec.q_ref, d["opt_quat"].astype(np.float64))
    assert rec.gyro_b.dtype == np.float64 and rec.gyro_b.flags.c_contiguous
    # 8.5 s at rest, then the scored fast rotation
    assert not rec.movement[: int(8.4 * rec.fs_hz)].any() and rec.movement[int(8.6 * rec.fs_hz):].all()
    # at rest the accelerometer reads g and the magnetometer the Earth's field (Berlin, ~50 µT)
    still = slice(0, int(8 * rec.fs_hz))
    assert np.linalg.norm(rec.accel_b[still], axis=1).mean() == pytest.approx(9.81, abs=0.1)
    assert 35 < np.linalg.norm(rec.mag_b[still], axis=1).mean() < 65


@pytest.mark.parametrize("rate_as,column_major", [("dataset", False), ("attribute", True)])
def test_a_broad_hdf5_file_reads_the_same_samples_as_the_npz(tmp_path, rate_as, column_major):
    d = _excerpt()
    path = write_hdf5(tmp_path / "07_undisturbed_fast_rotation_B_excerpt.hdf5", d, rate_as=rate_as,
                      column_major=column_major)
    a, b = read_broad_hdf5(path), read_npz(EXCERPT)
    assert a.format == "broad-hdf5" and a.fs_hz == b.fs_hz and a.groups == b.groups
    for key in ("gyro_b", "accel_b", "mag_b", "q_ref", "movement"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))


def test_a_run_log_csv_reads_the_same_samples_with_rate_from_t_s_and_declination(tmp_path):
    run = tmp_path / "my_run"
    run.mkdir()
    write_log_csv(run / "log.csv", _excerpt(), declination_deg=11.26)
    a, b = read_run_log(run / "log.csv"), read_npz(EXCERPT)
    assert a.name == "my_run" and a.format == "run-log" and a.groups == ("all_trials",)
    assert a.fs_hz == pytest.approx(b.fs_hz, rel=1e-12)
    assert a.declination_rad == pytest.approx(math.radians(11.26))
    assert a.movement.all()  # a run log is scored over every sample
    for key in ("gyro_b", "accel_b", "mag_b", "q_ref"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))


def test_a_log_without_t_s_takes_the_rate_from_summary_json(tmp_path):
    d = _excerpt()
    write_log_csv(tmp_path / "full.csv", d)
    lines = (tmp_path / "full.csv").read_text().splitlines()
    run = tmp_path / "run"
    run.mkdir()
    (run / "log.csv").write_text("\n".join(",".join(line.split(",")[1:]) for line in lines) + "\n")
    with pytest.raises(ValueError, match=r"no t_s column and no summary.json: give the sample rate \(--fs HZ\)"):
        read_run_log(run / "log.csv")
    (run / "summary.json").write_text(json.dumps({"sensor": {"output_rate_hz": 200.0}}))
    assert read_run_log(run / "log.csv").fs_hz == 200.0


def test_broad_groups_follow_broads_trials_json():
    assert broad_groups("05_undisturbed_slow_rotation_with_breaks_B") == (
        "all_trials", "undisturbed", "rotation", "slow", "with_breaks")
    assert broad_groups("21_undisturbed_fast_combined") == ("all_trials", "undisturbed", "combined", "fast", "no_breaks")
    assert broad_groups("27_disturbed_phone_vibration_B") == ("all_trials", "disturbed", "vibration")
    assert broad_groups("37_disturbed_office_A") == ("all_trials", "disturbed", "office_environment")
    assert broad_groups("my_walk") == ("all_trials",)


def test_find_recordings_takes_files_run_folders_and_trials_json_groups(tmp_path):
    shutil.copy(EXCERPT, tmp_path / "a.npz")
    (tmp_path / "notes.txt").write_text("not a recording")
    (tmp_path / "other.csv").write_text("x,y\n1,2\n")  # a CSV without the recording columns
    (tmp_path / "run1").mkdir()
    write_log_csv(tmp_path / "run1" / "log.csv", _excerpt())
    found = find_recordings(tmp_path)
    assert [p.name for p in found] == ["a.npz", "log.csv"]
    (tmp_path / "trials.json").write_text(json.dumps({"trials": {"a": {"groups": ["all_trials", "mine"]}}}))
    from biso_cosim.score.readers import read_folder

    recs = list(read_folder(tmp_path, fs_hz=50.0))  # the npz has no rate: 50 Hz; the log has t_s
    assert [r.fs_hz for r in recs] == [50.0, pytest.approx(BROAD_RATE_HZ)]
    assert recs[0].groups == ("all_trials", "mine")


def test_bad_recordings_name_the_file_and_what_was_expected(tmp_path):
    d = _excerpt()
    np.savez(tmp_path / "walk.npz", **d)  # not a BROAD name, no sampling_rate
    with pytest.raises(ValueError, match=r"walk.npz: no sampling_rate in the file; give the sample rate \(--fs HZ\)"):
        read_npz(tmp_path / "walk.npz")
    assert read_npz(tmp_path / "walk.npz", fs_hz=100.0).fs_hz == 100.0
    np.savez(tmp_path / "x.npz", imu_gyr=d["imu_gyr"], imu_acc=d["imu_acc"])
    with pytest.raises(ValueError, match="x.npz: missing imu_mag, opt_quat"):
        read_npz(tmp_path / "x.npz", fs_hz=100.0)
    np.savez(tmp_path / "y.npz", **{**d, "imu_acc": d["imu_acc"][:-1]}, sampling_rate=100.0)
    with pytest.raises(ValueError, match="y.npz: imu_acc has 6857 rows but imu_gyr has 6858"):
        read_npz(tmp_path / "y.npz")
    (tmp_path / "z.hdf5").write_text("not hdf5")
    pytest.importorskip("h5py")
    with pytest.raises(ValueError, match="z.hdf5: not a readable HDF5 file"):
        read_recording(tmp_path / "z.hdf5")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_recording(tmp_path / "missing.npz")
