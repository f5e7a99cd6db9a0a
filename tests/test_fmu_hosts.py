"""The FMUs in FMI hosts other than FMPy (issue 20): the project's C master (no Python in the
host, no environment variable), under valgrind over a whole route with two instances, reset
and state save/restore; libcosim (Open Simulation Platform, libcosimpy); and FMPy and
libcosim from a virtual environment without biso_cosim. Each bad input an error status and a
log line."""

from __future__ import annotations

import importlib.metadata as metadata
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")

from _plugin_reference import OUTPUTS, plugin_reference  # noqa: E402

from biso_cosim.estimators import estimate_attitude  # noqa: E402
from biso_cosim.fmu.build import built_fmus  # noqa: E402
from biso_cosim.fmu.host import FmuInstance  # noqa: E402
from biso_cosim.fmu.native.compiler import CompilerNotFound, find_compiler  # noqa: E402
from biso_cosim.fmu.variables import AXES, QUAT  # noqa: E402
from biso_cosim.motions import make_motion  # noqa: E402

try:
    find_compiler()
except CompilerNotFound:
    pytest.skip("no C compiler", allow_module_level=True)

VERSIONS = ["fmi2", "fmi3"]
EST_OUT = [f"estimate.q_wb.{c}" for c in QUAT]
GYRO, ACCEL, MAG = [0.05, -0.02, 0.4], [0.3, -0.2, 9.75], [4.0, 18.0, -44.0]
HELD = {f"{head}.{c}": x for head, row in (("gyro_s", GYRO), ("accel_s", ACCEL), ("mag_s", MAG))
        for c, x in zip("xyz", row)}


@pytest.fixture(scope="module")
def fmus():
    return built_fmus(("BisoEstimator", "BisoImuPlugin"))


@pytest.fixture(scope="module")
def master(tmp_path_factory):
    from biso_cosim.fmu.demos.native import compile_master

    return compile_master(tmp_path_factory.mktemp("master"), extra=("-g",))


def _truth_rows(motion) -> dict[str, np.ndarray]:
    rows = {}
    for head, a in (("omega_b", motion.omega_b), ("specific_force_b", motion.specific_force_b)):
        rows.update({f"{head}.{c}": a[:, k] for k, c in enumerate(AXES)})
    rows.update({f"q_wb.{c}": motion.q_wb[:, k] for k, c in enumerate(QUAT)})
    return rows


# ---------------------------------------------------------------------------- C master


@pytest.mark.parametrize("version", VERSIONS)
def test_c_master_runs_both_native_fmus_like_python(fmus, master, tmp_path, version):
    from biso_cosim.fmu.demos.native import run_native

    n = 120
    run = run_native(master, fmus[f"BisoEstimator-{version}"], 0.005, n, workdir=tmp_path / "est",
                     start={"estimator": "dcm_pi", "dcm_pi.kp_rp": 2.0}, inputs=HELD, outputs=EST_OUT)
    assert run.returncode == 0, run.log
    assert np.allclose(run.rows[:, 0], 0.005 * np.arange(1, n + 1))
    ref = estimate_attitude(*(np.tile(x, (n, 1)) for x in (GYRO, ACCEL, MAG)), 200.0, method="dcm_pi", kp_rp=2.0)
    assert np.array_equal(run.rows[:, 1:], ref)
    motion = make_motion("tumble", duration_s=0.4, fs_hz=1000.0)
    run = run_native(master, fmus[f"BisoImuPlugin-{version}"], 0.001, len(motion.t_s), workdir=tmp_path / "plug",
                     start={"estimator": "biso_plus"}, input_rows=_truth_rows(motion),
                     outputs=[o for o in OUTPUTS if o.startswith(("gyro_b", "accel_b", "estimate.q", "error"))])
    assert run.returncode == 0, run.log
    ref = plugin_reference(0.001, motion.omega_b, motion.specific_force_b, motion.q_wb, estimator="biso_plus")
    cols = [OUTPUTS.index(o) for o in OUTPUTS if o.startswith(("gyro_b", "accel_b", "estimate.q", "error"))]
    assert np.max(np.abs(run.rows[:, 1:] - ref[:, cols])) <= 1e-12  # readings and estimate exact, errors 1e-12
    assert np.array_equal(run.rows[:, 1:-4], ref[:, cols[:-4]])


@pytest.mark.parametrize("version", VERSIONS)
def test_c_master_bad_inputs_are_errors_with_a_log_line(fmus, master, tmp_path, version):
    from biso_cosim.fmu.demos.native import run_native

    est, plug = fmus[f"BisoEstimator-{version}"], fmus[f"BisoImuPlugin-{version}"]
    cases = [
        (est, 0.005, {"fs_hz": -1.0}, {}, "fs_hz not set: allowed"),                         # setter
        (est, 0.005, {"estimator": "nope"}, {}, "estimator not set: must be one of"),
        (est, 0.005, {"biso.pattern": 20}, {}, "biso.pattern"),
        (est, 0.005, {"use_speed": True}, {}, "ExitInitializationMode: invalid parameters: use_speed"),
        (est, 0.003, {}, {}, "allowed steps: n * 0.005"),                                      # step size
        (plug, 0.001, {"sensor.registers.a_dlpf_cfg": 9}, {}, "registers.a_dlpf_cfg must be one of 0..7"),
        (plug, 0.001, {"sensor.profile": "nope"}, {}, "sensor.profile not set"),
        (plug, 0.0003, {}, {}, "allowed steps"),
        (plug, 0.001, {}, {"omega_b.x": float("nan")}, "omega_b.x = nan"),                     # truth
        (plug, 0.001, {}, {"q_wb.w": 0.5}, "q_wb must be a unit quaternion"),
    ]
    for k, (fmu, step, start, held, words) in enumerate(cases):
        run = run_native(master, fmu, step, 3, start=start, inputs=held, outputs=EST_OUT, workdir=tmp_path / str(k))
        assert run.returncode == 3, (start, held, run.returncode, run.log)
        assert words in run.log and "status 3 logStatusError" in run.log, (words, run.log)


def _route_truth() -> dict[str, np.ndarray]:
    """A whole library route (slalom, 54 s) driven by the MuJoCo car, recorded at the 200 Hz
    sensor samples: the truth a host's vehicle model would feed."""
    from biso_cosim.cosim import CoSimulation

    result = CoSimulation("slalom", seed=0, estimators=["biso"]).run()
    t = result.truth
    rows = {f"omega_b.{c}": t.omega_b[:, k] for k, c in enumerate(AXES)}
    rows.update({f"specific_force_b.{c}": t.specific_force_b[:, k] for k, c in enumerate(AXES)})
    rows.update({f"q_wb.{c}": t.q_wb[:, k] for k, c in enumerate(QUAT)})
    rows.update({f"pos_w.{c}": t.pos_w[:, k] for k, c in enumerate(AXES)})
    rows.update({f"vel_w.{c}": t.vel_w[:, k] for k, c in enumerate(AXES)})
    return rows, result


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
def test_valgrind_two_instances_whole_route_reset_state_and_free(fmus, master, tmp_path):
    """valgrind --error-exitcode=1 --leak-check=full on the C master: two instances of each
    native FMU through a whole route (plug-in: the recorded truth; estimator: the recorded
    sensor samples), state saved, serialized, restored and replayed, reset and run again,
    freed; every replay equal bit for bit (the master checks) and nothing reported."""
    from biso_cosim.fmu.demos.native import run_native

    truth, result = _route_truth()
    n = len(truth["q_wb.w"])
    samples = {f"{head}.{c}": a[:, k] for head, a in (("gyro_s", result.imu.gyro_b), ("accel_s", result.imu.accel_b),
                                                       ("mag_s", result.imu.mag_b)) for k, c in enumerate(AXES)}
    valgrind = ["valgrind", "--error-exitcode=1", "--leak-check=full", "--errors-for-leak-kinds=all", "-q"]
    for version in VERSIONS:
        for name, rows, step, start in (("BisoImuPlugin", truth, 0.005, {"estimator": "biso_plus", "use_velocity": True}),
                                        ("BisoEstimator", samples, 0.005, {"estimator": "biso_plus"})):
            run = run_native(master, fmus[f"{name}-{version}"], step, n, start=start, input_rows=rows,
                             outputs=EST_OUT + ["estimate.heading"], prefix=valgrind, timeout=1800,
                             options=["--instances", "2", "--check-state", "--quiet"],
                             workdir=tmp_path / f"{name}-{version}")
            assert run.returncode == 0, (name, version, run.log[-3000:])
            assert "==" not in run.log, run.log[-3000:]  # valgrind's report lines


# ---------------------------------------------------------------------------- libcosim


def _libcosim_run(path, step_s, n, start, rows=None, outputs=EST_OUT):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_step_size(step_size=int(round(step_s * 1e9)))
    i = ex.add_local_slave(CosimLocalSlave(fmu_path=str(path), instance_name="s"))
    refs = {v.name.decode(): v.reference for v in ex.slave_variables(i)}
    for name, value in start.items():
        setter = (ex.string_initial_value if isinstance(value, str) else ex.boolean_initial_value
                  if isinstance(value, bool) else ex.integer_initial_value if isinstance(value, int)
                  else ex.real_initial_value)
        assert setter(i, refs[name], value)
    observer = CosimObserver.create_last_value()
    ex.add_observer(observer=observer)
    out = []
    for k in range(n):
        if rows:
            for name, values in rows.items():
                ex.real_initial_value(i, refs[name], float(values[k])) if k == 0 else None
        if not ex.step():
            return np.array(out), False
        out.append(observer.last_real_values(i, [refs[o] for o in outputs]))
    return np.array(out), True


def test_libcosim_runs_the_native_fmi2_fmus(fmus):
    pytest.importorskip("libcosimpy")
    n = 100
    start = {"estimator": "biso_plus", **HELD}
    q, ok = _libcosim_run(fmus["BisoEstimator-fmi2"], 0.005, n, start)
    assert ok
    ref = estimate_attitude(*(np.tile(x, (n, 1)) for x in (GYRO, ACCEL, MAG)), 200.0, method="biso_plus")
    assert np.array_equal(q, ref)
    # a step that is not a whole number of sample periods: refused with the logged reason, no crash
    _, ok = _libcosim_run(fmus["BisoEstimator-fmi2"], 0.003, 3, {})
    assert not ok
    # the plug-in on constant truth (libcosim holds initial values of unconnected inputs)
    truth = {"omega_b.z": 0.3, "specific_force_b.z": 9.80665, "q_wb.w": 1.0}
    out, ok = _libcosim_run(fmus["BisoImuPlugin-fmi2"], 0.001, 200, truth, outputs=["gyro_b.z", *EST_OUT])
    assert ok
    ones = np.ones(200)
    ref = plugin_reference(0.001, np.c_[0 * ones, 0 * ones, 0.3 * ones], np.c_[0 * ones, 0 * ones, 9.80665 * ones],
                           np.c_[ones, 0 * ones, 0 * ones, 0 * ones])
    cols = [OUTPUTS.index(o) for o in ("gyro_b.z", *EST_OUT)]
    assert np.array_equal(out, ref[:, cols])


_LIBCOSIM_SCRIPT = """
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimSlave import CosimLocalSlave
log_output_level(CosimLogLevel.ERROR)
path, name, value, step = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
ex = CosimExecution.from_step_size(step_size=int(round(step * 1e9)))
i = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name='e'))
refs = {v.name.decode(): v.reference for v in ex.slave_variables(i)}
if name:
    setter = ex.string_initial_value if name == 'route' else ex.real_initial_value
    print('initial value', setter(i, refs[name], value if name == 'route' else float(value)), flush=True)
print('stepped', ex.step(), flush=True)
"""


@pytest.mark.parametrize("fmu, name, value, step, message", [
    ("BisoEstimator-fmi2", "fs_hz", "-1", 0.005, "fmi2SetReal: fs_hz not set: allowed >= 0, got -1"),
    ("BisoVehicle-fmi2", "physics_rate_hz", "-1", 0.02, "fmi2SetReal: physics_rate_hz not set: allowed > 0 Hz"),
    ("BisoVehicle-fmi2", "route", "nowhere", 0.02,
     "fmi2ExitInitializationMode: invalid parameters: unknown route 'nowhere'"),
])
def test_libcosim_ends_the_process_on_a_parameter_error(fmus, tmp_path, fmu, name, value, step, message):
    """libcosim (libcosimpy 0.0.6) does not report an error status from a setter or from
    ExitInitializationMode to its caller: the initial value is accepted (True), and at the
    first step libcosim throws cosim::error on its worker thread, which nothing catches
    (std::terminate, SIGABRT). What the FMU can do it does: the error status and the
    logged reason naming the variable reach libcosim's log and the exception's what()."""
    pytest.importorskip("libcosimpy")
    paths = {**fmus, **built_fmus(("BisoVehicle",))}
    script = tmp_path / "bad.py"
    script.write_text(_LIBCOSIM_SCRIPT)
    done = subprocess.run([sys.executable, str(script), str(paths[fmu]), name, value, str(step)],
                          capture_output=True, text=True, timeout=600)
    assert "initial value True" in done.stdout and "stepped" not in done.stdout, done.stdout
    assert done.returncode == -signal.SIGABRT, (done.returncode, done.stderr[-2000:])
    assert "terminate called after throwing an instance of 'cosim::error'" in done.stderr
    assert f"Model error: {message}" in done.stderr  # the exception's what()
    assert f"[FMI status=error, category=logStatusError] {message}" in done.stdout  # libcosim's log


def test_libcosim_refused_step_returns_false_with_the_reason(tmp_path):
    pytest.importorskip("libcosimpy")
    script = tmp_path / "step.py"
    script.write_text(_LIBCOSIM_SCRIPT)
    done = subprocess.run([sys.executable, str(script), str(built_fmus(("BisoVehicle",))["BisoVehicle-fmi2"]), "", "",
                           "0.03"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "stepped False" in done.stdout, done.stderr[-2000:]
    assert "fmi2DoStep at t = 0.0 s refused (nothing computed)" in done.stdout  # libcosim's log
    assert "allowed steps: n * 0.02 s" in done.stdout


def test_libcosim_has_no_fmi3_and_says_so_in_its_last_error(fmus):
    """libcosim imports FMI 1.0 and 2.0 only: for an FMI 3.0 file CosimLocalSlave holds a NULL
    slave (libcosimpy does not check it: add_local_slave would crash the process) and
    libcosim's last error names the reason."""
    pytest.importorskip("libcosimpy")
    from libcosimpy._internal import get_last_error_message
    from libcosimpy.CosimSlave import CosimLocalSlave

    paths = {**fmus, **built_fmus(("BisoVehicle",))}
    for name in ("BisoEstimator-fmi3", "BisoImuPlugin-fmi3", "BisoVehicle-fmi3"):
        slave = CosimLocalSlave(fmu_path=str(paths[name]), instance_name="s")
        assert not slave.ptr()
        assert get_last_error_message() == f"Unsupported feature: Unsupported FMI version for FMU '{paths[name]}'"


def test_libcosim_connects_vehicle_and_native_plugin_like_fmpy():
    pytest.importorskip("libcosimpy")
    from biso_cosim.fmu.demos.libcosim import run_connected
    from biso_cosim.fmu.demos.master import CONNECTIONS
    from biso_cosim.fmu.variables import variables_of

    paths = {**built_fmus(("BisoEstimator", "BisoImuPlugin")), **built_fmus(("BisoVehicle",))}  # built once each
    record = ("estimate.q_wb.w", "estimate.q_wb.z", "gyro_b.z", "accel_b.x", "new_samples")
    rec = run_connected(paths["BisoVehicle-fmi2"], paths["BisoImuPlugin-fmi2"], duration_s=1.0, record=record)
    n = len(rec["plugin.gyro_b.z"])
    assert n == 50 and rec["plugin.new_samples"].sum() > 150
    # the same exchange in FMPy: libcosim gives the plug-in, at each step, the vehicle's
    # outputs from the end of the previous step (its start values at the first)
    start = {v.name: v.start for v in variables_of("BisoVehicle")}
    inputs = {o: start[o] for o in CONNECTIONS}
    out = []
    with FmuInstance(paths["BisoVehicle-fmi2"], "vehicle", start_values={"route": "figure8"}) as vehicle, \
            FmuInstance(paths["BisoImuPlugin-fmi2"], "plugin") as plugin:
        for _ in range(n):
            plugin.set({CONNECTIONS[o]: x for o, x in inputs.items()})
            assert vehicle.step(0.02) and plugin.step(0.02)
            inputs = dict(zip(CONNECTIONS, vehicle.get(list(CONNECTIONS))))
            out.append([inputs["truth.q_wb.w"], *plugin.get(list(record))])
    out = np.array(out, dtype=float)
    assert np.array_equal(out[:, 0], rec["vehicle.truth.q_wb.w"])
    for i, name in enumerate(record):
        assert np.array_equal(out[:, i + 1], rec[f"plugin.{name}"]), name


# ------------------------------------------------------- a Python without biso_cosim


def _distributions(*names: str) -> set[str]:
    """The installed distributions ``names`` need (their requirements, recursively)."""
    import re

    todo, seen = list(names), set()
    while todo:
        name = re.split(r"[ ;<>=!~\[(]", todo.pop())[0].lower().replace("_", "-")
        if name in seen:
            continue
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            continue
        seen.add(name)
        todo += [r for r in (dist.requires or []) if "extra ==" not in r]
    return seen


@pytest.fixture(scope="module")
def bare_python(tmp_path_factory):
    """A virtual environment holding FMPy and libcosimpy (and what they need), linked from this
    one's site-packages, without biso_cosim."""
    pytest.importorskip("libcosimpy")
    root = tmp_path_factory.mktemp("bare")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root / "venv")], check=True)
    site = next((root / "venv" / "lib").glob("python3*/site-packages"))
    for name in _distributions("fmpy", "libcosimpy"):
        dist = metadata.distribution(name)
        tops = {Path(str(f)).parts[0] for f in dist.files or [] if not str(f).startswith("..")}
        for top in tops:
            src = Path(dist.locate_file(top))
            if src.exists() and not (site / top).exists() and not top.startswith("__editable__"):
                (site / top).symlink_to(src)
    python = root / "venv" / "bin" / "python"
    probe = subprocess.run([str(python), "-c", "import biso_cosim"], capture_output=True, text=True, env={}, cwd=root)
    assert probe.returncode != 0 and "No module named 'biso_cosim'" in probe.stderr
    return python


def test_native_fmus_run_in_a_python_without_biso_cosim(fmus, bare_python, tmp_path):
    """FMPy (both FMI versions) and libcosim (FMI 2.0) load and run every native FMU from a
    virtual environment without biso_cosim, with an empty environment."""
    script = tmp_path / "run.py"
    script.write_text(
        "import json, sys\n"
        "from fmpy import simulate_fmu\n"
        "from libcosimpy.CosimExecution import CosimExecution\n"
        "from libcosimpy.CosimObserver import CosimObserver\n"
        "from libcosimpy.CosimSlave import CosimLocalSlave\n"
        "paths, start = json.loads(sys.argv[1]), json.loads(sys.argv[2])\n"
        "out = {}\n"
        "for key, path in paths.items():\n"
        "    name = key.split('-')[0]\n"
        "    step = 0.005 if name == 'BisoEstimator' else 0.001\n"
        "    r = simulate_fmu(path, stop_time=0.5, step_size=step, start_values=start[name],\n"
        "                     output=['estimate.q_wb.w', 'estimate.q_wb.z'])\n"
        "    out['fmpy ' + key] = [r[-1][1], r[-1][2]]\n"
        "    if key.endswith('fmi2'):\n"
        "        ex = CosimExecution.from_step_size(step_size=int(round(step * 1e9)))\n"
        "        i = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name='s'))\n"
        "        refs = {v.name.decode(): v.reference for v in ex.slave_variables(i)}\n"
        "        for k, v in start[name].items():\n"
        "            (ex.string_initial_value if isinstance(v, str) else ex.real_initial_value)(i, refs[k], v)\n"
        "        obs = CosimObserver.create_last_value(); ex.add_observer(observer=obs)\n"
        "        for _ in range(int(round(0.5 / step))): assert ex.step()\n"
        "        out['libcosim ' + key] = obs.last_real_values(i, [refs['estimate.q_wb.w'], refs['estimate.q_wb.z']])\n"
        "print('RESULT ' + json.dumps(out))\n")
    start = {"BisoEstimator": {"estimator": "biso_plus", **HELD},
             "BisoImuPlugin": {"estimator": "biso_plus", "omega_b.z": 0.3, "specific_force_b.z": 9.80665}}
    paths = {k: str(v) for k, v in fmus.items()}
    done = subprocess.run([str(bare_python), str(script), json.dumps(paths), json.dumps(start)], capture_output=True,
                          text=True, env={"PATH": os.defpath}, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(next(line for line in done.stdout.splitlines() if line.startswith("RESULT "))[7:])
    assert len(out) == 6
    ref_est = estimate_attitude(*(np.tile(x, (100, 1)) for x in (GYRO, ACCEL, MAG)), 200.0, method="biso_plus")[-1]
    ones = np.ones(500)
    ref_plug = plugin_reference(0.001, np.c_[0 * ones, 0 * ones, 0.3 * ones], np.c_[0 * ones, 0 * ones, 9.80665 * ones],
                                np.c_[ones, 0 * ones, 0 * ones, 0 * ones], estimator="biso_plus")[-1]
    for key, value in out.items():
        want = ([ref_est[0], ref_est[3]] if "Estimator" in key
                else [ref_plug[OUTPUTS.index("estimate.q_wb.w")], ref_plug[OUTPUTS.index("estimate.q_wb.z")]])
        assert value == want, key


def test_vehicle_runs_in_a_python_without_biso_cosim(bare_python, tmp_path):
    """BisoVehicle in FMPy on a Python that cannot import biso_cosim (an empty environment):
    the shell adds the building environment's site-packages (resources/python.txt) and the
    run equals the one in this process; the process exits cleanly."""
    path = built_fmus(("BisoVehicle",))["BisoVehicle-fmi2"]
    outputs = ["truth.speed", "estimate.q_wb.w", "estimate.q_wb.z"]
    script = tmp_path / "vehicle.py"
    script.write_text(
        "import json, sys\n"
        "from fmpy import simulate_fmu\n"
        "r = simulate_fmu(sys.argv[1], stop_time=0.4, step_size=0.02, start_values={'route': 'slalom'},\n"
        f"                 output={outputs!r})\n"
        "print('RESULT ' + json.dumps([list(map(float, row)) for row in r]))\n")
    done = subprocess.run([str(bare_python), str(script), str(path)], capture_output=True, text=True,
                          env={"PATH": os.defpath}, timeout=900, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = json.loads(next(line for line in done.stdout.splitlines() if line.startswith("RESULT "))[7:])
    with FmuInstance(path, "here", start_values={"route": "slalom"}) as fmu:
        ref = [fmu.step(0.02) and fmu.get(outputs) for _ in range(20)]
    assert [row[1:] for row in rows[1:]] == ref
