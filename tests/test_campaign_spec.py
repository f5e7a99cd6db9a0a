"""Campaign specs: grids and random samples expand as documented, run identities are stable,
and every bad input is one line naming the field, before any run (no cluster needed)."""

import math
import re

import pytest

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from biso_cosim.campaign import SpecError, load_spec, parse_spec  # noqa: E402
from biso_cosim.cli import main as cli_main  # noqa: E402

BASE = {"routes": ["figure8"], "duration_s": 2, "estimators": [{"name": "biso"}]}


def test_grid_random_and_sensor_lists_expand(tmp_path):
    spec = parse_spec(BASE | {
        "parts": 3, "first_seed": 10,
        "sensors": [{"profile": "mpu9250", "registers": [{"dlpf_cfg": 2}, {"dlpf_cfg": 4}]}, {}],
        "estimators": [{"name": "biso", "grid": {"cutoff_hz": [2.0, 5.0], "norm_gain": [1.0, 0.5]}},
                       {"name": "biso_plus", "label": "bp", "random": {
                           "samples": 4, "seed": 7, "params": {"k_tilt": [5.0, 20.0], "tau_acc_s": {"log": [1.0, 10.0]},
                                                               "accel_gate": {"choice": [2.0, 3.0]}}}}]})
    assert [s.label for s in spec.sensors] == ["mpu9250[dlpf_cfg=2]", "mpu9250[dlpf_cfg=4]", "mpu9250_calibrated"]
    labels = [e.label for e in spec.estimators]
    assert labels[:4] == ["biso[cutoff_hz=2.0,norm_gain=1.0]", "biso[cutoff_hz=2.0,norm_gain=0.5]",
                          "biso[cutoff_hz=5.0,norm_gain=1.0]",
                          "biso[cutoff_hz=5.0,norm_gain=0.5]"]
    assert labels[4:] == ["bp#0", "bp#1", "bp#2", "bp#3"]
    drawn = [dict(e.params) for e in spec.estimators[4:]]
    assert all(5.0 <= d["k_tilt"] <= 20.0 and 1.0 <= d["tau_acc_s"] <= 10.0 and d["accel_gate"] in (2.0, 3.0)
               for d in drawn)
    assert len({d["k_tilt"] for d in drawn}) == 4
    # the same seed draws the same sets; another seed others
    again = parse_spec(BASE | {"estimators": [{"name": "biso_plus", "random": {
        "samples": 4, "seed": 7, "params": {"k_tilt": [5.0, 20.0], "tau_acc_s": {"log": [1.0, 10.0]},
                                            "accel_gate": {"choice": [2.0, 3.0]}}}}]})
    assert [dict(e.params) for e in again.estimators] == drawn
    runs = spec.runs()
    assert len(runs) == 1 * 3 * 3 and [r.seed for r in runs[:3]] == [10, 11, 12]
    assert len({r.run_id for r in runs}) == len(runs)
    # a run's identity depends on what makes its result: the same after a re-parse, another with other estimators
    table = BASE | {"parts": 2}
    ids = [r.run_id for r in parse_spec(table).runs()]
    assert ids == [r.run_id for r in parse_spec(dict(table)).runs()] and len(set(ids)) == 2
    assert not set(ids) & {r.run_id for r in parse_spec(table | {"estimators": [{"name": "poisson"}]}).runs()}


def test_defaults_route_files_and_profile_files(tmp_path):
    (tmp_path / "routes").mkdir()
    from importlib import resources

    text = resources.files("biso_cosim.routes").joinpath("library/slalom.toml").read_text()
    (tmp_path / "routes" / "mine.toml").write_text(text)
    (tmp_path / "quiet.toml").write_text('base = "mpu9250_calibrated"\nname = "quiet"\n[gyro]\nnoise_density = 0.005\n')
    spec_file = tmp_path / "c.toml"
    spec_file.write_text('routes = ["routes/mine.toml", "figure8"]\n[[sensors]]\nprofile = "quiet.toml"\n'
                         '[[estimators]]\nname = "poisson"\n')
    spec = load_spec(spec_file)
    assert spec.name == "c" and spec.parts == 1 and spec.keep == "summaries"
    mine, figure8 = spec.routes
    assert mine.text == text and mine.load().name == "slalom"
    assert figure8.text is None and figure8.duration_s == math.ceil(figure8.load().nominal_duration_s + 10.0)
    profile = spec.sensors[0].load_profile()
    assert profile.name == "quiet"


BAD = [
    ({"routes": ["figur8"]}, "routes[0]: unknown route 'figur8'"),
    ({"routes": ["nowhere/route.toml"]}, "routes[0]: route file"),
    ({"routes": []}, "routes: empty list"),
    ({"routes": [{"route": "figure8", "duration_s": -1}]}, "routes[0].duration_s: expected a positive number"),
    ({"parts": 0}, "parts: expected an integer >= 1"),
    ({"rutes": ["figure8"]}, "rutes: unknown key"),
    ({"keep": "everything"}, "keep: expected one of"),
    ({"sensors": [{"profile": "mpu9999"}]}, "sensors[0].profile: profile 'mpu9999'"),
    ({"sensors": [{"registers": {"dlpf_cfg": 9}}]}, "sensors[0].registers: registers.dlpf_cfg must be in [0, 7]"),
    ({"sensors": [{"registers": {"dlpf": 2}}]}, "sensors[0].registers: registers: unknown field(s) ['dlpf']"),
    ({"estimators": [{"name": "bisoo"}]}, "estimators[0]: bisoo: unknown estimator 'bisoo'"),
    ({"estimators": [{"name": "biso", "params": {"cutof_hz": 5}}]}, "estimators[0]: biso: 'biso' has no parameter"),
    ({"estimators": [{"name": "biso", "grid": {"cutoff_hz": []}}]},
     "estimators[0].grid.cutoff_hz: expected a non-empty"),
    ({"estimators": [{"name": "biso", "grid": {}}]}, "estimators[0].grid: expected a non-empty table"),
    ({"estimators": [{"name": "biso", "grid": {"cutoff_hz": [-1.0]}}]}, "estimators[0]: biso[cutoff_hz=-1.0]:"),
    ({"estimators": [{"name": "biso", "random": {"samples": 0, "params": {"k": [1, 2]}}}]},
     "estimators[0].random.samples: expected an integer >= 1"),
    ({"estimators": [{"name": "biso", "random": {"samples": 2, "params": {"k": [2, 1]}}}]},
     "estimators[0].random.params.k: expected [low, high]"),
    ({"estimators": [{"name": "biso"}, {"name": "biso"}]}, "estimators: label 'biso' used twice"),
    ({"statistics": {"baseline": "vqf"}}, "statistics.baseline: no estimator labelled 'vqf'"),
    ({"statistics": {"confidence": 95}}, "statistics.confidence: expected a level in (0, 1)"),
]


@pytest.mark.parametrize("change, message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_bad_spec_is_one_line_naming_the_field(change, message):
    with pytest.raises(SpecError) as info:
        parse_spec(BASE | change, source="c.toml")
    text = str(info.value)
    assert text.startswith("c.toml: ") and message in text, text
    assert "\n" not in text


def test_cli_refuses_bad_input_before_any_run(tmp_path, capsys):
    spec_file = tmp_path / "c.toml"
    spec_file.write_text('routes = ["figure8"]\nduration_s = 1\n[[estimators]]\nname = "biso"\ngrid = { k = [] }\n')
    out = tmp_path / "out"

    def error(*args):
        assert cli_main(["campaign", str(spec_file), "--out", str(out), *args]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("biso-cosim campaign: error: ")
        return err

    assert "estimators[0].grid.k: expected a non-empty list" in error()
    spec_file.write_text('routes = ["figure8"]\nduration_s = 1\n[[estimators]]\nname = "biso"\n')
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    out = blocker / "out"  # cannot be made
    assert "is not writable" in error()
    out = tmp_path / "out"
    assert "--scheduler 'tcp://127.0.0.1:9': no Dask scheduler answered within 1 s" in error(
        "--scheduler", "tcp://127.0.0.1:9", "--timeout", "1")
    assert not (out / "campaign.json").exists()  # nothing recorded: the campaign never started
    assert "--workers must be a positive integer" in error("--workers", "0")
    assert "does not exist" in error_for_missing_spec(tmp_path, capsys)


def error_for_missing_spec(tmp_path, capsys):
    assert cli_main(["campaign", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")]) == 2
    return capsys.readouterr().err


def test_docs_slurm_example_builds_its_job_script(capsys):
    """The SLURM example of docs/campaigns.md, as printed there (dask-jobqueue is optional)."""
    pytest.importorskip("dask_jobqueue")
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "docs" / "campaigns.md").read_text()
    block = re.search(r"<!-- slurm-example.*?-->\n```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {}
    try:
        exec(block, namespace)  # constructs the cluster (its scheduler; no job is submitted) and prints the script
    finally:
        if "cluster" in namespace:
            namespace["cluster"].close()
    script = capsys.readouterr().out
    for line in ("#SBATCH -p compute", "#SBATCH -A estimation", "#SBATCH --cpus-per-task=2", "#SBATCH --mem=8G",
                 "#SBATCH -t 04:00:00", "export NUMBA_CACHE_DIR=$HOME/biso/numba-cache"):
        assert line in script.splitlines(), line
    assert "distributed.cli.dask_worker" in script and "--nthreads 1" in script and "--nworkers 2" in script


def test_the_example_spec_is_valid():
    from pathlib import Path

    spec = load_spec(Path(__file__).resolve().parent.parent / "examples" / "campaign.toml")
    assert len(spec.runs()) == 4 * 16 and spec.statistics.baseline == "biso"
    assert [e.label for e in spec.estimators] == ["biso_plus", "biso", "biso_fc[cutoff_hz=1.0]",
                                                  "biso_fc[cutoff_hz=3.0]", "poisson"]
