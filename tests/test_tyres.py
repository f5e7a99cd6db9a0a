"""The Magic Formula tyres (biso_cosim/vehicle/tyres.py, the C plugin vehicle/native/tyres.c):
the tyre curve against its analytic properties, the plugin in MuJoCo's step (a parked car
stays parked, one mj_step(m, d, n) equals n calls, loads from the contacts), bad input and a
non-finite force refused loudly, and the handling on a steady circle."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from biso_cosim.vehicle.model import build_model, car_spec, vehicle_parameters
from biso_cosim.vehicle.terrain import Terrain
from biso_cosim.vehicle.tyres import (BRAKES, STEER, SURFACES, TYRES, WHEEL_GEOMS, ChassisParams, TyreParams,
                                      load_plugin, magic_formula, surface_friction, tyre_states)

G = 9.80665
P = TYRES


def mu_y(fz):
    return (P.pdy1 + P.pdy2 * (fz - P.fz0_n) / P.fz0_n)


def cornering_stiffness(fz):
    """K_yα = p_Ky1·F_z0·sin(2 atan(F_z/(p_Ky2·F_z0))) (Pacejka 2012, §4.3), N/rad."""
    return P.pky1 * P.fz0_n * math.sin(2.0 * math.atan(fz / (P.pky2 * P.fz0_n)))


def peak(f):
    """The largest value of f on [0, 1.5]: a grid, then a bounded search around its best point."""
    from scipy.optimize import minimize_scalar

    grid = np.linspace(0.0, 1.5, 1501)
    best = grid[int(np.argmax([f(x) for x in grid]))]
    found = minimize_scalar(lambda x: -f(x), bounds=(max(best - 0.002, 0.0), best + 0.002), method="bounded",
                            options={"xatol": 1e-12})
    return -found.fun


@pytest.mark.parametrize("fz", [1500.0, 4000.0, 6500.0])
@pytest.mark.parametrize("scale", [1.0, SURFACES["wet"], SURFACES["snow"]])
def test_peak_forces_are_mu_times_load(fz, scale):
    """D = λ_μ·μ·F_z: the peak of each pure-slip curve (the sine reaches 1 since C > 1)."""
    fy = peak(lambda s: -magic_formula(fz, 0.0, s, friction_scale=scale)[1])
    fx = peak(lambda k: magic_formula(fz, k, 0.0, friction_scale=scale)[0])
    dfz = (fz - P.fz0_n) / P.fz0_n
    assert fy == pytest.approx(scale * mu_y(fz) * fz, rel=1e-6)
    assert fx == pytest.approx(scale * (P.pdx1 + P.pdx2 * dfz) * fz, rel=1e-6)


@pytest.mark.parametrize("fz", [1500.0, 2550.0, 3825.0, 6500.0])
def test_slip_stiffnesses_at_zero_slip_are_bcd(fz):
    """dF_y/dα at α = 0 is B·C·D = K_yα, dF_x/dκ at κ = 0 is K_xκ = F_z(p_Kx1 + p_Kx2 dfz)e^(p_Kx3 dfz)."""
    h = 1e-6
    ky = -(magic_formula(fz, 0.0, h)[1] - magic_formula(fz, 0.0, -h)[1]) / (2 * h)
    kx = (magic_formula(fz, h, 0.0)[0] - magic_formula(fz, -h, 0.0)[0]) / (2 * h)
    dfz = (fz - P.fz0_n) / P.fz0_n
    assert ky == pytest.approx(cornering_stiffness(fz), rel=1e-6)
    assert kx == pytest.approx(fz * (P.pkx1 + P.pkx2 * dfz) * math.exp(P.pkx3 * dfz), rel=1e-6)
    # the lateral force opposes the lateral slip, the longitudinal one follows the slip ratio
    assert magic_formula(fz, 0.0, 0.05)[1] < 0.0 < magic_formula(fz, 0.05, 0.0)[0]


def test_combined_slip_reduces_each_force_by_its_weighting_function():
    """F_y(κ, α) = G_yκ·F_y0(α) with G_yκ = cos(r_Cy1 atan(B_yκ κ)), B_yκ = r_By1 cos(atan(r_By2 α)),
    and the same for F_x: each force falls as the other slip grows, and is odd in its own slip."""
    fz, alpha = 4000.0, math.radians(4.0)
    pure_y = magic_formula(fz, 0.0, math.tan(alpha))[1]
    pure_x = magic_formula(fz, 0.1, 0.0)[0]
    previous = abs(pure_y)
    for kappa in (0.02, 0.05, 0.1, 0.2, 0.5):
        fx, fy = magic_formula(fz, kappa, math.tan(alpha))
        g_yk = math.cos(P.rcy1 * math.atan(P.rby1 * math.cos(math.atan(P.rby2 * alpha)) * kappa))
        assert fy == pytest.approx(g_yk * pure_y, rel=1e-12)
        assert abs(fy) < previous
        previous = abs(fy)
    fx, _ = magic_formula(fz, 0.1, math.tan(alpha))
    g_xa = math.cos(P.rcx1 * math.atan(P.rbx1 * math.cos(math.atan(P.rbx2 * 0.1)) * alpha))
    assert fx == pytest.approx(g_xa * pure_x, rel=1e-12) and fx < pure_x
    assert magic_formula(fz, -0.1, -0.2) == pytest.approx(tuple(-f for f in magic_formula(fz, 0.1, 0.2)), rel=1e-15)
    assert magic_formula(0.0, 0.1, 0.1) == (0.0, 0.0)


def test_cornering_stiffness_grows_less_than_the_load():
    """Load sensitivity: K_yα/F_z falls with the load (the source of the tyres' understeer)."""
    loads = np.array([1500.0, 2550.0, 3825.0, 5000.0, 6500.0])
    per_newton = [cornering_stiffness(f) / f for f in loads]
    assert all(b < a for a, b in zip(per_newton, per_newton[1:]))
    assert [mu_y(f) for f in loads] == sorted((mu_y(f) for f in loads), reverse=True)


def test_loads_beyond_the_range_of_validity_count_as_its_top():
    """F_z,max (MF-Tyre's FZMAX): a larger load gives the forces at F_z,max, a smaller one its own."""
    slips = (0.05, math.tan(math.radians(3.0)))
    at_top = magic_formula(P.fzmax_n, *slips)
    assert magic_formula(5.0 * P.fzmax_n, *slips) == at_top
    assert magic_formula(7e6, *slips) == at_top
    assert magic_formula(0.9 * P.fzmax_n, *slips) != at_top
    lower = replace(TYRES, fzmax_n=6000.0)
    assert magic_formula(8000.0, *slips, params=lower) == magic_formula(6000.0, *slips, params=lower)
    with pytest.raises(ValueError, match=r"TyreParams\.fzmax_n must be above fz0_n \(4000 N\)"):
        replace(TYRES, fzmax_n=3000.0).check()


def test_parameters_out_of_range_are_refused_naming_them():
    for name, bad in (("pdx1", 0.0), ("pky1", -14.95), ("sigma_y_m", 5.0), ("fz0_n", float("nan"))):
        with pytest.raises(ValueError, match=rf"TyreParams\.{name} must be in \["):
            replace(TYRES, **{name: bad}).check()
    with pytest.raises(ValueError, match="surface must be one of dry, wet"):
        surface_friction("mud")
    with pytest.raises(ValueError, match=r"surface friction scale must be in \(0, 1.5\]"):
        surface_friction(2.0)
    with pytest.raises(ValueError, match="tyres must be 'coulomb' or 'magic_formula'"):
        build_model(Terrain(()), tyres="brush")
    with pytest.raises(ValueError, match="apply to tyres='magic_formula' only"):
        build_model(Terrain(()), tyres="coulomb", surface="wet")
    assert TyreParams.table().count("\n") == len(TyreParams.__dataclass_fields__) + 1


def test_a_non_finite_tyre_force_stops_the_run_naming_time_and_wheel():
    """A model file whose tyre parameters slipped past the range check (here μ_x = 0, written
    into the plugin's config directly): the first force is 0·sin(NaN), and the step stops."""
    spec = car_spec()
    load_plugin()
    for name in WHEEL_GEOMS:
        spec.geom(name).condim = 1
    spec.activate_plugin("biso.tyres")
    instance = spec.add_plugin(name="tyres", plugin_name="biso.tyres")
    instance.config = {**TYRES.config(), "pdx1": "0", "pdx2": "0", "wheels": " ".join(WHEEL_GEOMS),
                       "brakes": " ".join(BRAKES), "steer": STEER}
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0])
    model = spec.compile()
    data = mujoco.MjData(model)
    with pytest.raises(mujoco.FatalError, match=r"tyre force of wheel fl_tyre is not finite at t = 0\.00\d+ s"):
        mujoco.mj_step(model, data, 100)


def settled(tyres="magic_formula", steps=3000):
    model, _ = build_model(Terrain(()), tyres=tyres)
    data = mujoco.MjData(model)
    data.ctrl[[model.actuator(f"brake_{w}").id for w in ("fl", "fr", "rl", "rr")]] = 1.0
    mujoco.mj_step(model, data, steps)
    return model, data


def test_the_loads_are_mujocos_contact_forces_and_carry_the_weight():
    model, data = settled()
    s = tyre_states(model, data)
    p = vehicle_parameters(model)
    assert s["in_contact"].tolist() == [1.0] * 4
    assert s["load_n"].sum() == pytest.approx(p["total_mass_kg"] * G, rel=1e-3)
    # the front axle's share of the static load: where the whole car's centre of mass lies
    # between the axles (the unsprung masses included)
    chassis = model.body("chassis").id
    com_x = data.subtree_com[chassis][0] - data.xpos[chassis][0]
    rear_x = float(model.body("rl_corner").pos[0])
    front_share = s["load_n"][:2].sum() / s["load_n"].sum()
    assert front_share == pytest.approx((com_x - rear_x) / p["wheelbase_m"], abs=2e-3)
    # the contacts carry no friction of MuJoCo's (condim 1): the plugin's forces are all there is
    assert all(model.geom(name).condim == 1 for name in WHEEL_GEOMS)
    # the Python view of the plugin state has the C layout
    from biso_cosim.vehicle.tyres import STATE_STRIDE, _ctypes_library

    assert _ctypes_library().biso_tyres_state_stride() == STATE_STRIDE and model.npluginstate == 4 * STATE_STRIDE


def test_a_parked_car_stays_parked():
    """Brakes on, flat ground: the tyres' deflection states hold the car (no creep, no jitter)."""
    model, data = settled()
    start = data.qpos[:3].copy()
    mujoco.mj_step(model, data, 10_000)  # 10 s
    assert np.linalg.norm(data.qpos[:2] - start[:2]) < 1e-4
    assert np.max(np.abs(data.qvel[:6])) < 1e-4


def test_one_mj_step_call_of_n_steps_equals_n_calls_bit_for_bit():
    """The tyre states live in MuJoCo's plugin state (part of mjSTATE_INTEGRATION): a chunked
    step and single steps give the same state; so do mj_getState/mj_setState round trips."""
    model, a = settled(steps=500)
    b = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, a, state, spec)
    mujoco.mj_setState(model, b, state, spec)
    for d in (a, b):
        d.ctrl[:] = 0.0
        d.ctrl[model.actuator("drive").id] = 800.0
        d.ctrl[model.actuator("steer").id] = 0.2
    mujoco.mj_step(model, a, 700)
    for _ in range(700):
        mujoco.mj_step(model, b)
    sa, sb = np.empty_like(state), np.empty_like(state)
    mujoco.mj_getState(model, a, sa, spec)
    mujoco.mj_getState(model, b, sb, spec)
    np.testing.assert_array_equal(sa, sb)
    assert np.any(tyre_states(model, a)["fx_n"][2:] > 100.0)  # driving: the rear tyres push


def test_the_default_tyres_are_the_magic_formula_and_coulomb_is_car_xml():
    """Without the option the car drives on the plugin's tyres (the tyre geoms carry the normal
    load only, condim 1); ``tyres="coulomb"`` is the Coulomb car of car.xml (no plugin, condim 3)."""
    model, _ = build_model(Terrain(()))
    assert model.nplugin == 1 and all(model.geom(name).condim == 1 for name in WHEEL_GEOMS)
    model, _ = build_model(Terrain(()), tyres="coulomb")
    assert model.nplugin == 0 and all(model.geom(name).condim == 3 for name in WHEEL_GEOMS)
    assert all(model.geom(name).condim == car_spec().compile().geom(name).condim for name in WHEEL_GEOMS)


@pytest.fixture(scope="module")
def circle_points():
    from biso_cosim.vehicle.handling import steady_circle

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the route's lateral-acceleration cap: the runs hold their own speed
        return [steady_circle(v, radius_m=40.0, settle_s=6.0, window_s=4.0) for v in (6.0, 10.0, 14.0)]


def test_steady_circle_understeer_and_sideslip(circle_points):
    """ISO 4138 on a 40 m circle with the Magic Formula tyres: the steering grows beyond the
    Ackermann angle L/R with the lateral acceleration (understeer; the Coulomb car's gradient
    is 0), and the rear axle slides outward by 1-2.5° at 0.25-0.5 g (a real car's sideslip,
    which the Coulomb car lacks). The understeer gradient the tyres alone give (on the
    road-wheel angle) is about 0.5 °/g; the compliance steer adds c_δ·W_f (Gillespie 1992,
    ch. 6), the front axle's load W_f, to the steering command's: 2-4 °/g, the class's."""
    from biso_cosim.vehicle.handling import understeer_fit

    wheelbase = vehicle_parameters()["wheelbase_m"]
    assert all(p.steady for p in circle_points)
    fit = understeer_fit(circle_points, wheelbase, linear_limit_g=0.55, road_wheel=True)
    assert 0.3 < fit["understeer_gradient_deg_per_g"] < 1.0
    assert -6.0 < fit["sideslip_gradient_deg_per_g"] < -3.0
    rear = {round(p.target_speed_mps): p.sideslip_rear_axle_deg for p in circle_points}
    assert -1.5 < rear[10] < -0.8 and -3.0 < rear[14] < -2.0
    # the bicycle model's linear understeer gradient from the tyres' cornering stiffnesses
    # at the static loads (Gillespie 1992, ch. 6: K = W_f/C_αf − W_r/C_αr) bounds it from below
    p = vehicle_parameters()
    share_f = 1.0 - p["cg_behind_front_axle_m"] / p["wheelbase_m"]
    w_f, w_r = share_f * p["total_mass_kg"] * G / 2, (1 - share_f) * p["total_mass_kg"] * G / 2
    linear = math.degrees(w_f / cornering_stiffness(w_f) - w_r / cornering_stiffness(w_r))
    assert linear == pytest.approx(0.46, abs=0.02)
    assert fit["understeer_gradient_deg_per_g"] > linear
    # the steering command (ISO 4138's steering-wheel angle over the ratio): plus the
    # compliance steer c_δ·F_yf, with F_yf = W_f·a_y/g in a steady turn
    from biso_cosim.vehicle.handling import PUBLISHED
    from biso_cosim.vehicle.tyres import CHASSIS

    command = understeer_fit(circle_points, wheelbase, linear_limit_g=0.55)
    compliance = math.degrees(CHASSIS.compliance_steer_rad_per_n * 2 * w_f)
    assert command["understeer_gradient_deg_per_g"] - fit["understeer_gradient_deg_per_g"] == pytest.approx(
        compliance, rel=0.1)
    (lo, hi), _ = PUBLISHED["understeer_gradient_deg_per_g"]
    assert lo <= command["understeer_gradient_deg_per_g"] <= hi


def test_the_roll_gradient_is_the_cars_documented_value(circle_points):
    """The body rolls outward in proportion to the lateral acceleration, by the car's
    documented 4.5 °/g (springs and anti-roll bars, car.xml): the slip tyres change where
    the lateral force builds, not the roll stiffness that resists its moment."""
    from biso_cosim.vehicle.handling import PUBLISHED, understeer_fit

    fit = understeer_fit(circle_points, vehicle_parameters()["wheelbase_m"], linear_limit_g=0.55)
    (lo, hi), _ = PUBLISHED["roll_gradient_deg_per_g"]
    assert lo <= fit["roll_gradient_deg_per_g"] <= hi
    assert all(p.roll_deg > 0.0 for p in circle_points)  # outward: right side down in this left turn


def bicycle_step_response(mass, iz, a, b, c_f, c_r, v, times, steer, sigma, dt=1e-4):
    """The linear bicycle model (Gillespie 1992, ch. 6) with axle cornering stiffnesses c_f,
    c_r, each axle's force lagging its steady value c·α by the tyres' relaxation length sigma
    (Pacejka 2012, ch. 7: dF/dt = (v/σ)(c·α − F)), driven by the road-wheel angle ``steer``
    at ``times`` (linear in between); states lateral velocity, yaw rate, the two forces:
    (times, yaw rates), Euler at dt."""
    vy = r = f_f = f_r = 0.0
    t = np.arange(int(times[-1] / dt)) * dt
    angle = np.interp(t, times, steer)
    out = np.empty(t.shape)
    for k in range(t.shape[0]):
        delta = angle[k]
        alpha_f, alpha_r = delta - (vy + a * r) / v, -(vy - b * r) / v
        dvy = (f_f + f_r) / mass - v * r
        dr = (a * f_f - b * f_r) / iz
        f_f += dt * v / sigma * (c_f * alpha_f - f_f)
        f_r += dt * v / sigma * (c_r * alpha_r - f_r)
        vy += dt * dvy
        r += dt * dr
        out[k] = r
    return t, out


def test_step_steer_matches_the_linear_bicycle_model_of_the_tyres():
    """ISO 7401 step steer at 80 km/h, 4 m/s² (in the tyres' linear range): the MuJoCo car's
    yaw rate follows the linear bicycle model with the Magic Formula's cornering stiffnesses
    at the static loads, the relaxation length, the car's mass, yaw inertia and axle
    distances, driven by the car's own road-wheel angle (the steering servo lags the
    command): the time to 90 % of the steady yaw rate within 12 %, the steady yaw rate
    within 5 %, no overshoot."""
    from biso_cosim.vehicle.handling import step_steer_series

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = step_steer_series(understeer_deg_per_g=0.5)
    model = car_spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    chassis = model.body("chassis").id
    com = data.subtree_com[chassis]
    iz = 0.0  # yaw inertia of the whole car about its centre of mass
    for body in range(1, model.nbody):
        rot = data.ximat[body].reshape(3, 3)
        inertia = rot @ np.diag(model.body_inertia[body]) @ rot.T
        d = data.xipos[body] - com
        iz += inertia[2, 2] + model.body_mass[body] * (d[0] ** 2 + d[1] ** 2)
    front_x = data.xpos[model.body("fl_corner").id][0]
    rear_x = data.xpos[model.body("rl_corner").id][0]
    a, b = front_x - com[0], com[0] - rear_x
    mass = float(model.body_subtreemass[chassis])
    w_f, w_r = mass * G * b / (a + b) / 2, mass * G * a / (a + b) / 2
    speed = float(np.mean(run["speed_mps"]))
    t, r = bicycle_step_response(mass, iz, a, b, 2 * cornering_stiffness(w_f), 2 * cornering_stiffness(w_r),
                                 speed, run["t_s"], run["steer_rad"], TYRES.sigma_y_m)
    measured = np.interp(t, run["t_s"], run["yaw_rate_rad_s"])

    def t90(rates):
        return t[np.flatnonzero(rates >= 0.9 * np.mean(rates[t > t[-1] - 1.5]))[0]]

    # within 12 %: the reference has no roll, no load transfer, no suspension
    assert t90(measured) == pytest.approx(t90(r), rel=0.12)
    assert np.mean(measured[t > 4.0]) == pytest.approx(np.mean(r[t > 4.0]), rel=0.05)
    # the overshoot is the compliance steer's (the road-wheel angle gives way as the front
    # force builds: the model, driven by that angle, has it too)
    assert np.max(measured) == pytest.approx(np.max(r), rel=0.05)


def test_docs_vehicle_shows_the_tyre_parameters_in_force():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "vehicle.md").read_text()
    assert TyreParams.table() in text, "run: biso-cosim vehicle params --tyres, and paste it into docs/vehicle.md"


def test_the_plugin_builds_into_the_cache_and_without_a_compiler_says_so_in_one_line(tmp_path, monkeypatch):
    from biso_cosim.fmu.native.compiler import CompilerNotFound, find_compiler
    from biso_cosim.vehicle.tyres import plugin_library

    monkeypatch.setenv("BISO_COSIM_CACHE", str(tmp_path))
    built = plugin_library.__wrapped__()  # the cached function's body: a fresh build
    assert built.is_file() and built.parent.parent == tmp_path and built.name == "libbiso_tyres.so"
    assert plugin_library.__wrapped__() == built  # found in the cache the second time
    monkeypatch.setenv("BISO_COSIM_CACHE", str(tmp_path / "empty"))
    monkeypatch.setenv("CC", "no-such-compiler-anywhere")
    find_compiler.cache_clear()
    try:
        with pytest.raises(CompilerNotFound, match="the magic_formula tyres are a C plugin") as error:
            plugin_library.__wrapped__()
        assert "\n" not in str(error.value) and "install one" in str(error.value)
    finally:
        find_compiler.cache_clear()


def test_the_scripted_driver_follows_a_rough_road_on_the_slip_based_tyres():
    """rough_road (height-field terrain, wheels that leave the ground for moments): the tyres'
    contacts on the height fields carry the car, the driver keeps within 0.5 m of the path as
    on the Coulomb tyres, and gets as far."""
    from biso_cosim.routes import load_route
    from biso_cosim.vehicle.sim import VehicleSim

    route = load_route("rough_road")
    progress, rms = {}, {}
    for tyres in ("coulomb", "magic_formula"):
        sim = VehicleSim(route, tyres=tyres)
        cross = []
        for _ in range(40 * 50):  # 40 s
            sim.drive()
            sim.step()
            cross.append(sim.driver.state.cross_track_m)
        progress[tyres], rms[tyres] = sim.driver.state.s_m, float(np.sqrt(np.mean(np.square(cross))))
        if tyres == "magic_formula":
            assert np.all(np.isfinite(sim.data.plugin_state))
    assert rms["magic_formula"] < 0.5
    assert progress["magic_formula"] == pytest.approx(progress["coulomb"], rel=0.02)


def test_the_handling_command_refuses_bad_input_in_one_line(capsys, tmp_path):
    from biso_cosim.cli import main

    assert main(["vehicle", "handling", "--out", str(tmp_path), "--radius", "5"]) == 2
    assert capsys.readouterr().err.strip() == ("biso-cosim vehicle: error: --radius must be a number of metres in "
                                               "[20, 200], got 5")
    assert main(["vehicle", "params", "--tyres"]) == 0
    assert capsys.readouterr().out.strip() == TyreParams.table()
    assert main(["vehicle", "params", "--chassis"]) == 0
    assert capsys.readouterr().out.strip() == ChassisParams.table()
    # parameters set for the report: a value out of range, an unknown name, not a number
    for option, setting, message in (
            ("--chassis", "compliance_steer_rad_per_n=1e-3",
             "ChassisParams.compliance_steer_rad_per_n must be in [0, 3e-05] rad/N, got 0.001"),
            ("--tyre", "pdy1=nan", "TyreParams.pdy1 must be in [0.1, 2] -, got nan"),
            ("--chassis", "abs=1", "--chassis must be NAME=VALUE with NAME one of brake_torque_nm, "
                                   "brake_balance_front, brake_build_up_s, abs_slip_target, abs_gain_per_s, "
                                   "abs_speed_min_mps, "
                                   "compliance_steer_rad_per_n, got 'abs=1'"),
            ("--tyre", "pky1=stiff", "--tyre pky1 must be a number, got 'stiff'")):
        assert main(["vehicle", "handling", "--out", str(tmp_path), option, setting]) == 2
        assert capsys.readouterr().err.strip() == f"biso-cosim vehicle: error: {message}"


@pytest.mark.slow
def test_the_handling_report_writes_its_files(tmp_path):
    """``biso-cosim vehicle handling`` end to end (about a minute): the report, its JSON and plot."""
    import json

    from biso_cosim.vehicle.handling import PUBLISHED, handling_report

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = handling_report(tmp_path)
    assert {p.name for p in tmp_path.iterdir()} == {"handling.md", "handling.json", "handling_circle.png"}
    assert json.loads((tmp_path / "handling.json").read_text())["figures"] == result["figures"]
    text = (tmp_path / "handling.md").read_text()
    assert all(key in text for key in PUBLISHED)
    for key, ((lo, hi), _) in PUBLISHED.items():
        assert lo <= result["figures"][key] <= hi, key
    assert result["figures"]["progressive_limit"]
    assert result["step_cost"]["ratio"] > 0.0
