"""The FMUs' build, CLI and docs, and the Python-based BisoVehicle.fmu (pythonfmu): built and
validated, run in FMPy and compared with the co-simulation it wraps; external driver, FMU
state, refusals. The native FMUs are tested in test_native_fmu.py and test_fmu_hosts.py."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

from biso_cosim.fmu.build import built_fmus, validate_fmu  # noqa: E402
from biso_cosim.fmu.host import FmuInstance  # noqa: E402
from biso_cosim.fmu.variables import QUAT, variables_of  # noqa: E402

EST_OUT = [f"estimate.q_wb.{c}" for c in QUAT]


@pytest.fixture(scope="module")
def fmus():
    return built_fmus(("BisoVehicle",))


def test_vehicle_builds_valid_and_says_it_needs_python(fmus):
    import xml.etree.ElementTree as ET

    path = fmus["BisoVehicle"]
    assert validate_fmu(path) == []
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
        names = z.namelist()
        doc = z.read("documentation/index.html").decode()
    assert "documentation/index.html" in names and "resources/biso_cosim_fmu.json" in names
    assert "Python-based" in doc and "Python" in root.get("description")
    units = {u.get("name") for u in root.iter("Unit")}
    used = {t.get("unit") for sv in root.iter("ScalarVariable") for t in sv if t.get("unit")}
    assert used and used <= units
    cs = root.find("CoSimulation").attrib
    assert cs["canGetAndSetFMUstate"] == "true" and cs["canBeInstantiatedOnlyOncePerProcess"] == "false"
    outputs = [sv for sv in root.iter("ScalarVariable") if sv.get("causality") == "output"]
    assert outputs and all(sv.get("initial") == "exact" and sv[0].get("start") is not None for sv in outputs)
    assert all(t.get("start") != "NaN" for sv in root.iter("ScalarVariable") for t in sv)


# ----------------------------------------------------------------------------- vehicle


VEHICLE_OUT = ["sample_time", "new_samples", "gyro_b.x", "accel_b.y", "mag_b.z", "raw.gyro.z",
               *(f"truth.q_wb.{c}" for c in QUAT), "truth.pos_w.x", "truth.speed", *EST_OUT, "error.heading"]


def test_vehicle_fmu_equals_the_cosimulation_run(fmus):
    from biso_cosim.cosim import CoSimulation

    duration = 2.0
    with FmuInstance(fmus["BisoVehicle"], "car", start_values={"route": "figure8", "estimator": "biso"},
                     stop_time=duration) as fmu:
        rows = []
        for _ in range(50):
            assert fmu.step(0.02), fmu.log
            rows.append(fmu.get(VEHICLE_OUT))
        assert fmu.step(0.06)  # three control periods at once
        rows.append(fmu.get(VEHICLE_OUT))
        assert not fmu.step(0.03) and "control" in fmu.errors()[-1]
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


def test_vehicle_fmu_external_driver_and_refusals(fmus):
    from biso_cosim.cosim import CoSimulation
    from biso_cosim.vehicle.driver import DriverCommand

    start = {"route": "figure8", "external_driver": True, "estimator": "poisson"}
    with FmuInstance(fmus["BisoVehicle"], "driven", start_values=start) as fmu:
        speeds = []
        for i in range(40):
            fmu.set({"drive": 0.4, "brake": 0.0, "steer": 0.1})
            assert fmu.step(0.02)
            speeds.append(fmu.get(["truth.speed", "estimate.q_wb.z"]))
        fmu.set({"drive": 2.0})
        assert not fmu.step(0.02) and "drive must be in [-1, 1]" in fmu.errors()[-1]
        fmu.set({"drive": 0.4})
        assert fmu.step(0.02)  # still usable
        # go back in time: the same inputs give the same outputs, bit for bit
        state = fmu.fmu.getFMUstate()
        blob = fmu.fmu.serializeFMUstate(state)
        first = [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)]
        fmu.fmu.setFMUstate(fmu.fmu.deSerializeFMUstate(blob))
        fmu.time -= 10 * 0.02
        assert [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)] == first
        fmu.fmu.freeFMUstate(state)
    sim = CoSimulation("figure8", seed=0, estimators=["poisson"])
    for _ in range(40):
        samples, truth, out = sim.step(DriverCommand(0.1, 0.4, 0.0))
    assert speeds[-1][0] == truth.speed_mps[-1] > 0.2
    assert speeds[-1][1] == out["poisson"].q_wb[-1, 3]


def test_vehicle_invalid_route_is_refused(fmus):
    with FmuInstance(fmus["BisoVehicle"], "nowhere", start_values={"route": "no_such_route"}) as fmu:
        assert not fmu.step(0.02)
        assert "invalid parameters" in fmu.errors()[-1] and "no_such_route" in fmu.errors()[-1]


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

    stale = tmp_path / "BisoVehicle.fmu"
    with zipfile.ZipFile(fmus["BisoVehicle"]) as src, zipfile.ZipFile(stale, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item.endswith("biso_cosim_fmu.json"):
                data = json.dumps({**json.loads(data), "version": "0.0.1", "fingerprint": "0" * 16}).encode()
            dst.writestr(item, data)
    with pytest.raises(RuntimeError, match="rebuild it with `biso-cosim fmu build`"):
        FmuInstance(stale, "stale")


def test_docs_tables_are_generated_from_the_variables():
    from pathlib import Path

    from biso_cosim.fmu.variables import fill_docs

    doc = Path(__file__).resolve().parents[1] / "docs" / "fmu.md"
    text = doc.read_text("utf-8")
    assert fill_docs(text) == text, "docs/fmu.md is stale: biso-cosim fmu docs docs/fmu.md"
