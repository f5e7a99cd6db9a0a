"""Runs that fail loudly (biso_cosim.runstatus): real short runs whose car rolls over, gets
stuck, leaves the route, or drives its route; the CLI's first line, summary.json's status,
the exit codes, and the route-test kit's RouteRunFailed."""

from __future__ import annotations

import dataclasses
import json
import math
import re
import warnings

import numpy as np
import pytest

from biso_cosim.cli import main as cli_main
from biso_cosim.cosim import CoSimulation
from biso_cosim.routes import RouteWarning, load_route
from biso_cosim.runstatus import (CROSS_TRACK_BOUND_M, EXIT_RUN_FAILED, ROLLOVER_TILT_DEG, STUCK_PROGRESS_M,
                                  judge_run, stuck_window_s)
from biso_cosim.testing import RouteRunFailed, drive

STRAIGHT = """format = 1
name = "{name}"
description = "{name}"
closed = false
[driving]
default_speed_mps = 10.0
[[waypoint]]
x_m = 0.0
y_m = 0.0
[[waypoint]]
x_m = {length}
y_m = 0.0
"""

# a 4 m ridge whose crest runs 1.2 m beside the road, from behind the start: the car is
# placed on its 63° flank at t = 0, its uphill wheels pressed into the flank (MuJoCo solves
# contact loads of 6e6 N there; the Magic Formula counts them as F_z,max), and lies over
FLANK = """[[terrain.feature]]
type = "ridge"
x0_m = -20.0
y0_m = 1.2
x1_m = 190.0
y1_m = 1.2
half_width_m = 2.0
height_m = 4.0
"""

# a 3 m ridge across the road, 1 m half-width: a wall (grade 4.7) the car drives into
WALL = """[[terrain.feature]]
type = "ridge"
x0_m = 60.0
y0_m = -10.0
x1_m = 60.0
y1_m = 10.0
half_width_m = 1.0
height_m = 3.0
"""


def _route_file(tmp_path, name, length=200.0, terrain="", top=""):
    path = tmp_path / f"{name}.toml"
    path.write_text(top + STRAIGHT.format(name=name, length=length) + terrain)
    return path


def _tilt_deg(q):
    return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1.0, 1.0)))


@pytest.fixture(scope="module")
def rolled(tmp_path_factory):
    path = _route_file(tmp_path_factory.mktemp("roll"), "flank", terrain=FLANK)
    sim = CoSimulation(path, duration_s=3.0, estimators=["poisson"])
    return path, sim.run(), sim


def test_the_slip_tyre_car_placed_on_a_steep_flank_stays_finite(rolled):
    """The magic_formula car pressed into the flank: MuJoCo never found the physics unstable
    (it would reset the state and the run go on from there), and each tyre's force stays
    within friction times F_z,max although its contact load is 6e6 N."""
    from biso_cosim.vehicle.tyres import TYRES, tyre_states

    _, result, sim = rolled
    assert sim.vehicle.tyres == "magic_formula"
    assert sim.vehicle.periods_with_warnings == 0
    assert np.all(np.isfinite(result.truth.q_wb)) and np.all(np.isfinite(result.imu.accel_b))
    states = tyre_states(sim.vehicle.model, sim.vehicle.data)
    assert states["load_n"].max() > 100 * TYRES.fzmax_n
    bound = max(TYRES.pdx1, TYRES.pdy1) * TYRES.fzmax_n
    assert np.all(np.hypot(states["fx_n"], states["fy_n"]) <= bound)


def test_a_car_on_a_steep_flank_rolls_over(rolled):
    _, result, _ = rolled
    status = judge_run(result)
    assert status.status == "rolled_over" and status.failed
    tilt = _tilt_deg(result.truth.q_wb)
    first = int(np.flatnonzero(tilt > ROLLOVER_TILT_DEG)[0])
    assert status.t_s == pytest.approx(result.t_s[first])
    assert f"t = {result.t_s[first]:.2f} s" in status.reason and "tilt" in status.reason


def _diverging(tmp_path, spoil):
    """A 4 s run on a straight road whose state ``spoil(sim)`` breaks after 1 s of driving."""
    sim = CoSimulation(_route_file(tmp_path, "straight"), duration_s=4.0, estimators=["poisson"])
    for _ in range(50):
        sim.step()
    spoil(sim)
    return sim, sim.run()


def _check_stopped_there(sim, result, reason):
    status = judge_run(result)
    assert status.status == "diverged" and status.failed
    assert re.search(reason, status.reason) and status.t_s == pytest.approx(1.0, abs=0.021)
    # the periods before are kept, whole and finite; the run refuses to go on from there
    assert 0.98 <= result.duration_s <= 1.0 and result.t_s[-1] < status.t_s
    assert np.all(np.isfinite(result.truth.q_wb)) and np.all(np.isfinite(result.estimates["poisson"][0]))
    with pytest.raises(RuntimeError, match="physics diverged .*reset\\(\\) it to run again"):
        sim.step()
    sim.reset()
    assert sim.diverged is None and np.all(np.isfinite(sim.step()[0].accel_b))


def test_a_state_mujoco_finds_unstable_stops_the_run_there(tmp_path, monkeypatch):
    """MuJoCo resets the data on a non-finite velocity and goes on; the run stops instead."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warnings to MUJOCO_LOG.TXT

    def spoil(sim):
        sim.vehicle.data.qvel[0] = np.nan

    sim, result = _diverging(tmp_path, spoil)
    _check_stopped_there(sim, result, r"^the physics became unstable at t = 1\.0000 s: MuJoCo found a non-finite or "
                                      r"huge velocity \(dof 0\) and reset the state; the run stopped there$")


def test_a_non_finite_tyre_force_stops_the_run_at_its_time_and_wheel(tmp_path):
    """The tyre plugin stops the step (mujoco.FatalError) on a non-finite force; the run ends there."""
    from biso_cosim.vehicle.tyres import STATE_STRIDE, tyre_states

    def spoil(sim):
        model, data = sim.vehicle.model, sim.vehicle.data
        adr = int(model.plugin_stateadr[0])
        assert tyre_states(model, data)["slip_ratio"][2] == data.plugin_state[adr + 2 * STATE_STRIDE]
        data.plugin_state[adr + 2 * STATE_STRIDE] = np.nan  # the slip ratio of wheel rl

    sim, result = _diverging(tmp_path, spoil)
    _check_stopped_there(sim, result, r"^the physics stopped at t = 1\.0000 s: biso\.tyres: the tyre force of wheel "
                                      r"rl_tyre is not finite at t = 1\.000000 s")


def test_a_car_that_drives_into_a_wall_is_stuck(tmp_path):
    path = _route_file(tmp_path, "wall", terrain=WALL)
    result = CoSimulation(path, estimators=["poisson"]).run()  # the default duration: nominal + 10 s
    status = judge_run(result)
    assert status.status == "stuck", status
    window = stuck_window_s(result.route)
    assert window == 20.0  # no stops on the route
    # the car stood before the wall: its progress over the window after t grew by less than 1 m
    n = result.progress_m.shape[0]
    times = result.log_start_s + np.arange(n) * result.duration_s / n
    inside = (times >= status.t_s) & (times <= status.t_s + window)
    assert np.ptp(result.progress_m[inside]) < STUCK_PROGRESS_M
    assert result.progress_m[inside][0] < 60.0  # before the crest
    assert not result.completed


def test_an_agent_that_steers_off_the_road_leaves_the_route():
    """The route loader caps impossible targets now (500 m/s becomes the car's top speed), so
    an agent's commands take the car off the road: full lock and throttle on the figure eight."""
    from biso_cosim.vehicle.driver import DriverCommand

    sim = CoSimulation("figure8", duration_s=20.0, estimators=["poisson"])
    lock = float(sim.vehicle.driver.max_steer_rad)
    while not sim.done:
        sim.step(DriverCommand(steer_rad=-lock, drive=0.6, brake=0.0))
    result = sim.result()
    status = judge_run(result)
    assert status.status == "left_route", status
    off = np.flatnonzero(np.abs(result.cross_track_m) > CROSS_TRACK_BOUND_M)
    assert off.size and f"cross-track {abs(result.cross_track_m[off[0]]):.1f} m" in status.reason


def test_impossible_routes_are_refused_or_capped_at_load(tmp_path):
    two = tmp_path / "two.toml"
    two.write_text('format = 1\nname = "two"\ndescription = "two"\nclosed = true\n'
                   "[[waypoint]]\nx_m = 0.0\ny_m = 0.0\n[[waypoint]]\nx_m = 50.0\ny_m = 0.0\n")
    with pytest.raises(ValueError, match=r"waypoint\[1\] turns by 180°"):
        load_route(two)
    fast = tmp_path / "fast.toml"
    fast.write_text(STRAIGHT.format(name="fast", length=300.0).replace("10.0", "500.0"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RouteWarning)
        route = load_route(fast)
    assert any("default_speed_mps = 500" in str(w.message) for w in caught)
    assert route.driving.default_speed_mps < 60.0


def test_completed_partial_and_incomplete(tmp_path):
    path = _route_file(tmp_path, "short", length=40.0)
    result = CoSimulation(path, estimators=["poisson"]).run()
    status = judge_run(result)
    assert status.status == "completed" and not status.failed
    # the same drive cut by a short duration is a part of the route, not a failure
    part = CoSimulation(path, duration_s=4.0, estimators=["poisson"]).run()
    assert judge_run(part).status == "partial" and not judge_run(part).failed
    # a run as long as the route needs that did not finish
    unfinished = dataclasses.replace(result, completed=False, finished_at_s=None)
    status = judge_run(unfinished)
    assert status.status == "incomplete" and status.failed
    assert f"not completed in {result.duration_s:.0f} s" in status.reason


def test_cli_says_a_failed_run_first_writes_its_status_and_exits_3(rolled, tmp_path, capsys):
    path, result, _ = rolled
    out = tmp_path / "run"
    rc = cli_main(["run", "--route", str(path), "--duration", "3", "--out", str(out), "--no-progress"])
    assert rc == EXIT_RUN_FAILED == 3
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("RUN FAILED: rolled_over: the car rolled over at t = ")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "rolled_over"
    assert summary["status_reason"] == judge_run(result).reason
    assert (out / "log.csv").is_file() and (out / "attitude.png").is_file()  # written all the same
    assert cli_main(["run", "--route", str(path), "--duration", "3", "--out", str(out), "--no-progress",
                     "--allow-incomplete", "--no-log"]) == 0
    assert "accepted: --allow-incomplete" in capsys.readouterr().out.splitlines()[0]


def test_cli_run_of_a_completed_route_exits_0(tmp_path, capsys):
    path = _route_file(tmp_path, "short", length=40.0)
    out = tmp_path / "run"
    assert cli_main(["run", "--route", str(path), "--out", str(out), "--no-progress", "--no-log"]) == 0
    assert capsys.readouterr().out.startswith("run completed: route completed at t = ")
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"


def test_the_route_test_kit_fails_a_failed_run_with_its_reason(rolled):
    path, result, _ = rolled
    with pytest.raises(RouteRunFailed, match="rolled_over: the car rolled over at t = ") as caught:
        drive(str(path), "poisson", duration_s=3.0)
    assert caught.value.status.status == "rolled_over"
    run = drive(str(path), "poisson", duration_s=3.0, allow_failed=True)
    assert math.isclose(run.run.duration_s, 3.0)
