"""``biso-cosim score`` end to end on the BROAD excerpt in tests/data (CC BY 4.0): the same
scores from the three formats, the peers as in ``compare``, a user's estimator through the
loop's API, and one-line errors for bad input."""

import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from biso_cosim.cli import main
from biso_cosim.estimators import make_estimator
from biso_cosim.score import score
from biso_cosim.score.metrics import trial_rmse_deg
from biso_cosim.score.readers import read_npz
from test_score_readers import EXCERPT, _excerpt, write_hdf5, write_log_csv

NAME = "07_undisturbed_fast_rotation_B_excerpt"


@pytest.fixture
def folder(tmp_path):
    d = tmp_path / "trials"
    d.mkdir()
    shutil.copy(EXCERPT, d / EXCERPT.name)
    return d


def test_cli_prints_the_table_and_writes_json_and_a_plot(folder, tmp_path, capsys):
    pytest.importorskip("vqf")
    out = tmp_path / "out"
    code = main(["score", str(folder), "--method", "biso_plus", "--method", "vqf", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert NAME in printed and "all_trials" in printed and "estimators" in printed
    result = json.loads((out / "score.json").read_text())
    assert (out / f"{NAME}.png").stat().st_size > 10_000
    rec = read_npz(EXCERPT)
    import vqf

    q = vqf.VQF(1.0 / rec.fs_hz).updateBatch(rec.gyro_b, rec.accel_b, rec.mag_b)["quat9D"]
    expected = trial_rmse_deg(q, rec.q_ref, rec.movement)
    got = result["trials"][NAME]["methods"]["vqf"]
    for k in ("total", "heading", "inclination"):
        assert got[f"{k}_rmse_deg"] == expected[k]
    assert result["groups"]["fast"]["methods"]["vqf"]["total_rmse_deg"] == expected["total"]
    q = make_estimator("biso_plus", rec.fs_hz, declination_rad=0.0).update(rec.gyro_b, rec.accel_b, rec.mag_b).q_wb
    assert result["trials"][NAME]["methods"]["biso_plus"]["total_rmse_deg"] == trial_rmse_deg(
        q, rec.q_ref, rec.movement)["total"]
    # VQF on 15 s of BROAD's fast rotation: a couple of degrees, mostly heading (it converges
    # from the first sample; BROAD's own figures for whole trials are 1–4°)
    assert 0.5 < got["total_rmse_deg"] < 5.0 and got["inclination_rmse_deg"] < got["total_rmse_deg"]
    assert result["trials"][NAME]["scored_samples"] == int(rec.movement.sum())


def test_the_three_formats_score_the_same(folder, tmp_path):
    pytest.importorskip("h5py")
    d = _excerpt()
    (tmp_path / "h5").mkdir()
    write_hdf5(tmp_path / "h5" / f"{NAME}.hdf5", d)
    (tmp_path / "csv" / "run").mkdir(parents=True)
    write_log_csv(tmp_path / "csv" / "run" / "log.csv", d)
    results = [score(p, ["biso_plus"], plots=False) for p in (folder, tmp_path / "h5", tmp_path / "csv")]
    a, b, c = (next(iter(r["trials"].values()))["methods"]["biso_plus"] for r in results)
    assert a["total_rmse_deg"] == b["total_rmse_deg"]  # the same float32 samples
    # a run log is scored over every sample (it has no movement column), the excerpt over its movement part
    rec = read_npz(EXCERPT)
    q = make_estimator("biso_plus", rec.fs_hz).update(rec.gyro_b, rec.accel_b, rec.mag_b).q_wb
    assert c["total_rmse_deg"] == pytest.approx(trial_rmse_deg(q, rec.q_ref)["total"], rel=1e-9)


def test_peers_are_those_of_compare(folder):
    pytest.importorskip("vqf")
    pytest.importorskip("imufusion")
    from biso_cosim.compare import Dataset, run_method
    from biso_cosim.score.methods import make_method

    rec = read_npz(EXCERPT)
    d = Dataset(name="x", kind="motion", seed=0, fs_hz=rec.fs_hz, t_s=rec.t_s, gyro_b=rec.gyro_b, accel_b=rec.accel_b,
                mag_b=rec.mag_b, q_true=rec.q_ref, declination_rad=0.2, gyro_range_rad_s=math.radians(2000.0))
    import dataclasses

    rec_d = dataclasses.replace(rec, declination_rad=0.2)
    for name in ("vqf", "imufusion"):
        np.testing.assert_array_equal(make_method(name).run(rec_d), run_method(name, d))


class GyroOnly:
    """A user's estimator with the loop's API: update(gyro_b, accel_b, mag_b) → (k, 4) q_wb."""

    def __init__(self, fs_hz, **params):
        self.inner = make_estimator("poisson", fs_hz, **params)

    def update(self, gyro_b, accel_b, mag_b):
        return self.inner.update(gyro_b, accel_b, mag_b)  # an Estimate: its q_wb is taken


def test_a_users_estimator_by_module_path_and_from_python(folder, tmp_path, monkeypatch, capsys):
    (tmp_path / "my_filters.py").write_text(
        "from biso_cosim.estimators import make_estimator\n\n"
        "class Mine:\n"
        "    def __init__(self, fs_hz, **params):\n"
        "        self.inner = make_estimator('poisson', fs_hz, **params)\n"
        "    def update(self, gyro_b, accel_b, mag_b):\n"
        "        return self.inner.update(gyro_b, accel_b, mag_b).q_wb\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, "my_filters", raising=False)
    out = tmp_path / "out"
    assert main(["score", str(folder), "--method", "poisson", "--method", "mine=my_filters.Mine",
                 "--out", str(out), "--no-plots"]) == 0
    result = json.loads((out / "score.json").read_text())
    m = result["trials"][NAME]["methods"]
    assert m["mine"] == {**m["poisson"], "seconds": m["mine"]["seconds"]}
    assert not (out / f"{NAME}.png").exists()
    # from Python: the factory, or an instance (reset before each recording)
    from biso_cosim.cosim import EstimatorSpec

    instance = EstimatorSpec("mine", label="instance", instance=GyroOnly(2000.0 / 7.0))  # as run_route takes it
    r = score(folder, [GyroOnly, instance, "poisson"], plots=False)
    assert list(r["methods"]) == ["GyroOnly", "instance", "poisson"] and r["methods"]["instance"]["kind"] == "user"
    m = r["trials"][NAME]["methods"]
    assert m["GyroOnly"]["total_rmse_deg"] == m["instance"]["total_rmse_deg"] == m["poisson"]["total_rmse_deg"]


@pytest.mark.parametrize("argv,message", [
    (["score", "{missing}"], "DIR: '{missing}' does not exist"),
    (["score", "{empty}"], "DIR: no recordings found in '{empty}'"),
    (["score", "{folder}", "--method", "nope"], "--method: unknown method 'nope'; known: biso, "),
    (["score", "{folder}", "--method", "biso_plus:no_such=1"], "'biso_plus' has no parameter(s) ['no_such']"),
    (["score", "{folder}", "--method", "imufusion:speed=2"], "--method imufusion: no parameter(s) ['speed']"),
    (["score", "{folder}", "--method", "a=poisson", "--method", "a=biso"], "--method: labels must be unique"),
    (["score", "{folder}", "--method", "nomodule_here.Est"], "cannot import 'nomodule_here'"),
])
def test_bad_input_is_one_line_and_exit_code_2(folder, tmp_path, capsys, argv, message):
    (tmp_path / "empty").mkdir()
    paths = {"missing": tmp_path / "missing", "empty": tmp_path / "empty", "folder": folder}
    argv = [a.format(**paths) for a in argv] + ["--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("biso-cosim score: error: ")
    assert message.format(**paths) in err


def test_docs_name_every_method_and_format():
    from biso_cosim.score.methods import method_names

    text = (Path(__file__).resolve().parents[1] / "docs" / "score.md").read_text()
    missing = [n for n in method_names() if f"`{n}`" not in text]
    assert not missing, f"docs/score.md does not name {missing}"
    for key in ("imu_gyr", "imu_acc", "imu_mag", "opt_quat", "movement", "sampling_rate", "true_qw"):
        assert f"`{key}`" in text
