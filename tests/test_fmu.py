"""The FMUs' build, CLI and docs, and the Python-based BisoVehicle FMUs (our C shell embedding
CPython, FMI 2.0 and 3.0): built and validated, run in FMPy and in the C master (a native host
that starts Python itself) and compared with the co-simulation they wrap; external driver,
FMU state, refusals as fmi2Error / fmi3Error with a logged reason, repeated runs that exit
cleanly. The native FMUs are tested in test_native_fmu.py and test_fmu_hosts.py."""

from __future__ import annotations

import subprocess
import sys
import zipfile

import numpy as np
import pytest

pytest.importorskip("fmpy")

from biso_cosim.fmu.build import built_fmus, validate_fmu  # noqa: E402
from biso_cosim.fmu.host import FmuCallError, FmuInstance  # noqa: E402
from biso_cosim.fmu.variables import QUAT  # noqa: E402

EST_OUT = [f"estimate.q_wb.{c}" for c in QUAT]
VERSIONS = ("fmi2", "fmi3")


@pytest.fixture(scope="module")
def fmus():
    return built_fmus(("BisoVehicle",))


@pytest.mark.parametrize("version", VERSIONS)
def test_vehicle_builds_valid_and_says_it_needs_python(fmus, version):
    import xml.etree.ElementTree as ET

    path = fmus[f"BisoVehicle-{version}"]
    assert validate_fmu(path) == []
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
        names = z.namelist()
        doc = z.read("documentation/index.html").decode()
        config = z.read("resources/python.txt").decode()
    assert {"documentation/index.html", "resources/biso_cosim_fmu.json", "resources/python.txt"} <= set(names)
    assert "Python-based" in doc and "Python" in root.get("description")
    assert f"version={sys.version_info.major}.{sys.version_info.minor}." in config and "path=" in config
    assert not any("pythonfmu" in n for n in names)
    units = {u.get("name") for u in root.iter("Unit")}
    variables = [node for node in root.find("ModelVariables")]
    typed = [t for sv in variables for t in sv] if version == "fmi2" else variables
    used = {t.get("unit") for t in typed if t.get("unit")}
    assert used and used <= units
    cs = root.find("CoSimulation").attrib
    state = "canGetAndSetFMUstate" if version == "fmi2" else "canGetAndSetFMUState"
    assert cs[state] == "true" and cs["canBeInstantiatedOnlyOncePerProcess"] == "false"
    assert cs["canHandleVariableCommunicationStepSize"] == "true"
    outputs = [v for v in variables if v.get("causality") == "output"]
    assert outputs and all(v.get("initial") == "exact" for v in outputs)
    assert all(t.get("start") != "NaN" for t in typed)


# ----------------------------------------------------------------------------- vehicle


VEHICLE_OUT = ["sample_time", "new_samples", "gyro_b.x", "accel_b.y", "mag_b.z", "raw.gyro.z",
               *(f"truth.q_wb.{c}" for c in QUAT), "truth.pos_w.x", "truth.speed", *EST_OUT, "error.heading"]


def test_vehicle_fmu_equals_the_cosimulation_run(fmus):
    from biso_cosim.cosim import CoSimulation

    duration = 2.0
    with FmuInstance(fmus["BisoVehicle-fmi2"], "car", start_values={"route": "figure8", "estimator": "biso"},
                     stop_time=duration) as fmu:
        rows = []
        for _ in range(50):
            assert fmu.step(0.02), fmu.log
            rows.append(fmu.get(VEHICLE_OUT))
        assert fmu.step(0.06)  # three control periods at once
        rows.append(fmu.get(VEHICLE_OUT))
        # not a whole number of control periods: fmi2Error with the allowed steps, nothing computed
        assert not fmu.step(0.03)
        assert "allowed steps: n * 0.02 s" in fmu.errors()[-1] and fmu.get(VEHICLE_OUT) == rows[-1]
        assert fmu.get(["route_finished"]) == [False]
    rows = np.array(rows)
    col = {n: rows[:, k] for k, n in enumerate(VEHICLE_OUT)}
    result = CoSimulation("figure8", duration_s=duration + 0.06, seed=0, estimators=["biso"]).run()
    last = np.r_[np.arange(3, 200, 4), 211]  # the latest sample of each step (4 per control period)
    assert np.array_equal(col["sample_time"], result.t_s[last])
    assert np.array_equal(col["new_samples"], np.r_[np.full(50, 4), 12])
    assert np.array_equal(col["gyro_b.x"], result.imu.gyro_b[last, 0])
    assert np.array_equal(col["raw.gyro.z"], result.imu.raw.words[last, 6])
    assert np.array_equal(np.stack([col[f"truth.q_wb.{c}"] for c in QUAT], 1), result.truth.q_wb[last])
    assert np.array_equal(col["truth.speed"], result.truth.speed_mps[last])
    q = np.stack([col[n] for n in EST_OUT], axis=1)
    assert np.max(np.abs(q - result.estimates["biso"][0][last])) <= 1e-12
    assert np.allclose(col["error.heading"], np.radians(result.errors("biso")["heading"][last]), atol=1e-9)


def test_vehicle_fmi3_equals_fmi2(fmus):
    """The same slave behind both shells: the same outputs, bit for bit (FMI 3.0's time,
    value reference 0, reads as the communication point)."""
    out = {}
    for version in VERSIONS:
        with FmuInstance(fmus[f"BisoVehicle-{version}"], version, start_values={"route": "slalom"}) as fmu:
            out[version] = [fmu.step(0.04) and fmu.get(VEHICLE_OUT) for _ in range(10)]
            if version == "fmi3":
                assert fmu.fmu.getFloat64([0]) == [fmu.time]  # the last communication point
    assert out["fmi2"] == out["fmi3"] and all(out["fmi2"])


@pytest.mark.parametrize("version", VERSIONS)
def test_vehicle_fmu_external_driver_state_and_refusals(fmus, version):
    from biso_cosim.cosim import CoSimulation
    from biso_cosim.vehicle.driver import DriverCommand

    start = {"route": "figure8", "external_driver": True, "estimator": "poisson"}
    with FmuInstance(fmus[f"BisoVehicle-{version}"], "driven", start_values=start) as fmu:
        speeds = []
        for i in range(40):
            fmu.set({"drive": 0.4, "brake": 0.0, "steer": 0.1})
            assert fmu.step(0.02)
            speeds.append(fmu.get(["truth.speed", "estimate.q_wb.z"]))
        # refused by the setter (fmi2Error / fmi3Error), naming the input and its range; not stored
        for name, value, allowed in (("drive", 2.0, "allowed >= -1 and <= 1, got 2.0"),
                                     ("brake", -0.5, "allowed >= 0 and <= 1, got -0.5"),
                                     ("steer", float("nan"), "allowed any finite value, got nan"),
                                     ("poisson.norm_gain", -1.0, "allowed >= 0 1/s, got -1.0"),
                                     ("physics_rate_hz", 500.0, "a fixed parameter cannot change after "
                                                                "initialization (kept 1000.0)"),
                                     ("estimate.q_wb.w", 1.0, "it is an output")):
            with pytest.raises(FmuCallError, match="failed"):
                fmu.set({name: value})
            assert fmu.errors()[-1].endswith(f"{name} not set: {allowed}") or allowed in fmu.errors()[-1],                 fmu.errors()[-1]
        assert fmu.get(["drive", "brake", "poisson.norm_gain"]) == [0.4, 0.0, 1.0]
        assert fmu.step(0.02)  # still usable
        # go back in time: the same inputs give the same outputs, bit for bit
        state = fmu.get_state()
        blob = fmu.serialize(state)
        first = [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)]
        fmu.set_state(fmu.deserialize(blob))
        assert [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)] == first
        fmu.set_state(state)
        assert [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)] == first
        fmu.free_state(state)
    sim = CoSimulation("figure8", seed=0, estimators=["poisson"])
    for _ in range(40):
        samples, truth, out = sim.step(DriverCommand(0.1, 0.4, 0.0))
    assert speeds[-1][0] == truth.speed_mps[-1] > 0.2
    assert speeds[-1][1] == out["poisson"].q_wb[-1, 3]


def test_vehicle_tunable_change_acts_like_set_params(fmus):
    from biso_cosim.cosim import CoSimulation

    with FmuInstance(fmus["BisoVehicle-fmi2"], "tuned", start_values={"route": "figure8"}) as fmu:
        got = []
        for i in range(30):
            if i == 15:
                # one setter call per type, applied at its end: the flag alone (k = 0) is unstable
                with pytest.raises(FmuCallError, match="not asymptotically stable"):
                    fmu.set({"biso.has_k": True})
                assert fmu.get(["biso.has_k"]) == [False]  # kept
                fmu.set({"biso.k": 2.5})  # used once the flag says so
                fmu.set({"biso.has_k": True})
            assert fmu.step(0.02)
            got.append(fmu.get(EST_OUT))
    sim = CoSimulation("figure8", seed=0, estimators=["biso"])
    want = []
    for i in range(30):
        if i == 15:
            sim.estimators["biso"].set_params(k=2.5)
        _, _, out = sim.step()
        want.append(out["biso"].q_wb[-1].tolist())
    assert got == want


@pytest.mark.parametrize("start, message", [
    ({"route": "no_such_route"}, "invalid parameters: unknown route 'no_such_route'"),
    ({"physics_rate_hz": 1000.0, "control_rate_hz": 300.0}, "invalid parameters"),
])
def test_vehicle_invalid_parameters_are_refused_at_exit_initialization(fmus, start, message):
    for version in VERSIONS:
        with pytest.raises(FmuCallError, match="exitInitializationMode failed") as info:
            FmuInstance(fmus[f"BisoVehicle-{version}"], "nowhere", start_values=start)
        assert message in info.value.messages[-1], info.value.messages


def test_vehicle_invalid_parameter_is_refused_by_the_setter(fmus):
    for version in VERSIONS:
        with pytest.raises(FmuCallError, match="set Real failed") as info:
            FmuInstance(fmus[f"BisoVehicle-{version}"], "slow", start_values={"physics_rate_hz": 0.0})
        assert info.value.messages[-1].endswith("physics_rate_hz not set: allowed > 0 Hz, got 0.0")
        with pytest.raises(FmuCallError, match="set String failed") as info:
            FmuInstance(fmus[f"BisoVehicle-{version}"], "which", start_values={"estimator": "kalman"})
        assert "estimator not set: allowed one of biso, positional, poisson, dcm_pi, biso_plus" in \
            info.value.messages[-1]


_REPEAT = """
import sys
from biso_cosim.fmu.host import FmuInstance
with FmuInstance(sys.argv[1], "car", start_values={"route": "figure8"}) as fmu:
    for _ in range(10):
        assert fmu.step(0.02)
    second = FmuInstance(sys.argv[1], "other", start_values={"route": "slalom"})
    assert second.step(0.02)
    second.close()
print("done")
"""


def test_vehicle_fmu_runs_repeatedly_and_the_host_exits_cleanly(fmus, tmp_path):
    """Ten FMPy processes, each with two instances instantiated, stepped and freed (FreeInstance
    and the library's unloading): every one exits with 0. pythonfmu's wrapper aborted at exit
    here in 2-6 runs of 10 ("corrupted double-linked list", rc 134)."""
    script = tmp_path / "repeat.py"
    script.write_text(_REPEAT)
    codes = []
    for k in range(10):
        path = fmus[f"BisoVehicle-{VERSIONS[k % 2]}"]
        done = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True, timeout=600)
        codes.append(done.returncode)
        assert done.returncode == 0 and "done" in done.stdout, (k, done.returncode, done.stderr[-2000:])
    assert codes == [0] * 10


def test_vehicle_runs_in_the_c_master_which_starts_python(fmus, tmp_path):
    """A native host (the C master, an empty environment): the shell starts the Python that
    built the FMU (resources/python.txt) and runs the co-simulation; state save/restore and
    Reset replay bit for bit; every refusal is status 3 (error) with the logged reason."""
    from biso_cosim.fmu.demos.native import compile_master, run_native

    master = compile_master(tmp_path)
    outputs = ["sample_time", *EST_OUT, "truth.speed"]
    with FmuInstance(fmus["BisoVehicle-fmi2"], "ref", start_values={"route": "slalom"}) as fmu:
        ref = [fmu.step(0.02) and fmu.get(outputs) for _ in range(20)]
    for version in VERSIONS:
        fmu = fmus[f"BisoVehicle-{version}"]
        run = run_native(master, fmu, 0.02, 20, start={"route": "slalom"}, outputs=outputs,
                         options=["--check-state"], workdir=tmp_path / version, timeout=900)
        assert run.returncode == 0, run.log[-3000:]
        assert np.array_equal(run.rows[:, 1:], np.array(ref)), version
        for start, step, message in (
                ({"physics_rate_hz": -1.0}, 0.02, "physics_rate_hz not set: allowed > 0 Hz, got -1.0"),
                ({"route": "nowhere"}, 0.02, "ExitInitializationMode: invalid parameters: unknown route 'nowhere'"),
                ({"route": "slalom"}, 0.03, "allowed steps: n * 0.02 s")):
            bad = run_native(master, fmu, step, 3, start=start, workdir=tmp_path / f"{version}-bad", timeout=900)
            assert bad.returncode == 3 and "status 3 logStatusError" in bad.log and message in bad.log, bad.log


# ------------------------------------------------------------------------------------ CLI


def test_cli_builds_validates_and_lists(tmp_path, capsys):
    import argparse

    from biso_cosim.cli import fmu as cli_fmu

    parser = argparse.ArgumentParser()
    cli_fmu.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["fmu", "build", "--out", str(tmp_path), "--only", "BisoEstimator"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "BisoEstimator-fmi2.fmu: valid" in out and "BisoEstimator-fmi3.fmu: valid" in out
    bad = tmp_path / "broken.fmu"
    with zipfile.ZipFile(tmp_path / "BisoEstimator-fmi2.fmu") as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'initial="exact"', b"", 1)
            dst.writestr(item, data)
    args = parser.parse_args(["fmu", "validate", str(bad)])
    assert args.func(args) == 1
    assert "problem" in capsys.readouterr().out
    args = parser.parse_args(["fmu", "variables", "BisoVehicle", "--causality", "input"])
    assert args.func(args) == 0
    table = capsys.readouterr().out
    assert "`steer`" in table and "`route`" not in table


def test_fmu_built_for_other_variables_is_refused(fmus, tmp_path):
    import json

    stale = tmp_path / "BisoVehicle-fmi2.fmu"
    with zipfile.ZipFile(fmus["BisoVehicle-fmi2"]) as src, zipfile.ZipFile(stale, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item.endswith("biso_cosim_fmu.json"):
                data = json.dumps({**json.loads(data), "version": "0.0.1", "fingerprint": "0" * 16}).encode()
            dst.writestr(item, data)
    with pytest.raises(FmuCallError, match="rebuild it with `biso-cosim fmu build`"):
        FmuInstance(stale, "stale")


def test_docs_tables_are_generated_from_the_variables():
    from pathlib import Path

    from biso_cosim.fmu.variables import fill_docs

    doc = Path(__file__).resolve().parents[1] / "docs" / "fmu.md"
    text = doc.read_text("utf-8")
    assert fill_docs(text) == text, "docs/fmu.md is stale: biso-cosim fmu docs docs/fmu.md"


def _with_python_config(path, folder, edit):
    """A copy of an FMU whose resources/python.txt is ``edit(text)``."""
    out = folder / path.name
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            dst.writestr(item, edit(data.decode()).encode() if item == "resources/python.txt" else data)
    return out


def test_native_host_python_library_choice_and_its_errors(fmus, tmp_path):
    """In a native host the shell loads the libpython named in resources/python.txt, or the one
    BISO_COSIM_LIBPYTHON names; without one (a static-only Python built the FMU), or with a
    Python of another version, instantiation fails with the reason logged."""
    import os
    import re

    from biso_cosim.fmu.demos.native import compile_master, run_native
    from biso_cosim.fmu.native.python_shell import shared_libpython

    master = compile_master(tmp_path)
    path = fmus["BisoVehicle-fmi2"]
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin")}
    (tmp_path / "none").mkdir()
    no_library = _with_python_config(path, tmp_path / "none", lambda t: re.sub(r"libpython=.*", "libpython=", t))
    run = run_native(master, no_library, 0.02, 2, workdir=tmp_path / "w1", env=env)
    assert run.returncode != 0 and "has no shared library (built without --enable-shared)" in run.log, run.log
    run = run_native(master, no_library, 0.02, 2, workdir=tmp_path / "w2",
                     env={**env, "BISO_COSIM_LIBPYTHON": str(shared_libpython())})
    assert run.returncode == 0, run.log[-2000:]
    (tmp_path / "old").mkdir()
    other = _with_python_config(path, tmp_path / "old", lambda t: re.sub(r"version=.*", "version=2.7.", t))
    run = run_native(master, other, 0.02, 2, workdir=tmp_path / "w3", env=env)
    assert run.returncode != 0 and "this FMU was built for Python 2.7.; the Python in this process is 3." in run.log
