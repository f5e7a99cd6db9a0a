"""The FMUs in FMI hosts other than FMPy: a native C master (no Python in the host) and
libcosim (Open Simulation Platform's C++ engine, from PyPI as libcosimpy)."""

from __future__ import annotations

import shutil
import sysconfig

import numpy as np
import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

from biso_cosim.estimators import estimate_attitude
from biso_cosim.fmu.build import built_fmus
from biso_cosim.fmu.host import FmuInstance
from biso_cosim.fmu.variables import variables_of


@pytest.mark.skipif(not (shutil.which("cc") or shutil.which("gcc")), reason="no C compiler")
@pytest.mark.skipif(not sysconfig.get_config_var("Py_ENABLE_SHARED"), reason="this Python has no libpython.so")
def test_native_c_master_runs_the_estimator_fmu(tmp_path):
    from biso_cosim.fmu.demos.native import compile_master, python_environment, run_native

    env = python_environment()
    assert env["LD_PRELOAD"].endswith(".so") and env["PYTHONPATH"]
    master = compile_master(tmp_path)
    gyro, accel, mag = [0.05, -0.02, 0.4], [0.3, -0.2, 9.75], [4.0, 18.0, -44.0]
    inputs = {f"{head}.{c}": x for head, row in (("gyro_s", gyro), ("accel_s", accel), ("mag_s", mag))
              for c, x in zip("xyz", row)}
    n = 120
    rows, log = run_native(master, built_fmus()["BisoEstimator"], 0.005, n, workdir=tmp_path,
                           start={"estimator": "dcm_pi", "dcm_pi.kp_rp": 2.0, "use_speed": False},
                           inputs=inputs, outputs=[f"estimate.q_wb.{c}" for c in "wxyz"])
    assert rows.shape == (n, 5)
    assert np.allclose(rows[:, 0], 0.005 * np.arange(1, n + 1))
    ref = estimate_attitude(*(np.tile(x, (n, 1)) for x in (gyro, accel, mag)), 200.0, method="dcm_pi", kp_rp=2.0)
    assert np.max(np.abs(rows[:, 1:] - ref)) <= 1e-12
    # a refused step reaches the native host as fmi2Discard (2) with the logged reason
    with pytest.raises(RuntimeError, match=r"failed \(2\).*not finite"):
        run_native(master, built_fmus()["BisoEstimator"], 0.005, 3, workdir=tmp_path / "nan",
                   inputs={"gyro_s.x": float("nan")}, outputs=["estimate.q_wb.w"])


def test_libcosim_connects_vehicle_and_plugin_like_fmpy():
    pytest.importorskip("libcosimpy")
    from biso_cosim.fmu.demos.libcosim import run_connected
    from biso_cosim.fmu.demos.master import CONNECTIONS

    paths = built_fmus()
    record = ("estimate.q_wb.w", "estimate.q_wb.z", "gyro_b.z", "accel_b.x", "new_samples")
    rec = run_connected(paths["BisoVehicle"], paths["BisoImuPlugin"], duration_s=1.0, record=record)
    n = len(rec["plugin.gyro_b.z"])
    assert n == 50 and rec["plugin.new_samples"].sum() > 150
    # the same exchange in FMPy: libcosim gives the plug-in, at each step, the vehicle's
    # outputs from the end of the previous step (its start values at the first)
    start = {v.name: v.start for v in variables_of("BisoVehicle")}
    inputs = {o: start[o] for o in CONNECTIONS}
    out = []
    vehicle = FmuInstance(paths["BisoVehicle"], "vehicle", start_values={"route": "figure8"})
    plugin = FmuInstance(paths["BisoImuPlugin"], "plugin")
    try:
        for _ in range(n):
            plugin.set({CONNECTIONS[o]: x for o, x in inputs.items()})
            assert vehicle.step(0.02) and plugin.step(0.02)
            inputs = dict(zip(CONNECTIONS, vehicle.get(list(CONNECTIONS))))
            out.append([inputs["truth.q_wb.w"], *plugin.get(list(record))])
    finally:
        vehicle.close()
        plugin.close()
    out = np.array(out, dtype=float)
    assert np.array_equal(out[:, 0], rec["vehicle.truth.q_wb.w"])
    for i, name in enumerate(record):
        assert np.array_equal(out[:, i + 1], rec[f"plugin.{name}"]), name
