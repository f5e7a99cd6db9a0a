"""Tyres and road surface from a route file (``tyres``, ``surface``): parsed and checked by
biso_cosim.routes.route, taken by VehicleSim (so by ``biso-cosim run --route``) when it is
given none; the surface's friction reaches the model's ground and changes how the car brakes."""

from __future__ import annotations

import math
import tomllib
import warnings
from dataclasses import replace

import numpy as np
import pytest

from biso_cosim.routes import load_route, parse_route
from biso_cosim.vehicle.tyres import DEFAULT_TYRE_MODEL, SURFACES, TYRE_MODELS


def straight(**top) -> dict:
    """A straight open route of 400 m at 14 m/s, with the given top-level keys."""
    return {"name": "straight", "description": "a straight road", "closed": False,
            "waypoint": [{"x_m": 0.0, "y_m": 0.0, "speed_mps": 14.0}, {"x_m": 400.0, "y_m": 0.0}], **top}


def test_defaults_are_the_magic_formula_car_on_dry_asphalt():
    route = parse_route(straight())
    assert (route.tyres, route.surface) == ("magic_formula", "dry") == (DEFAULT_TYRE_MODEL, "dry")
    assert all((load_route(n).tyres, load_route(n).surface) == ("magic_formula", "dry")
               for n in ("figure8", "loop600", "rough_road"))
    # the earlier car stays selectable in the route file
    assert parse_route(straight(tyres="coulomb")).tyres == "coulomb"


@pytest.mark.parametrize("surface", [*SURFACES, 0.5, 1, 1.5])
def test_every_named_surface_and_scale_is_read(surface):
    route = parse_route(straight(tyres="magic_formula", surface=surface))
    assert route.tyres == "magic_formula" and route.surface == surface
    assert route.summary()["surface"] == surface


@pytest.mark.parametrize("top, message", [
    ({"tyres": "pacejka"}, "my.toml: tyres must be one of 'coulomb', 'magic_formula', got 'pacejka'"),
    ({"tyres": 1}, "my.toml: tyres must be one of 'coulomb', 'magic_formula', got 1"),
    ({"tyres": "magic_formula", "surface": "mud"},
     "my.toml: surface must be one of 'dry', 'wet', 'gravel', 'snow', 'ice' or a friction scale in (0, 1.5], "
     "got 'mud'"),
    ({"tyres": "magic_formula", "surface": 0.0}, "my.toml: surface must be one of"),
    ({"tyres": "magic_formula", "surface": 1.6}, "got 1.6"),
    ({"tyres": "magic_formula", "surface": float("nan")}, "got nan"),
    ({"tyres": "magic_formula", "surface": True}, "got True"),
    ({"tyres": "magic_formula", "surface": [1.0]}, "got [1.0]"),
    ({"tyres": "coulomb", "surface": "wet"}, "my.toml: surface = 'wet' needs tyres = \"magic_formula\""),
])
def test_bad_tyres_or_surface_is_one_line_naming_the_field(top, message):
    with pytest.raises(ValueError) as info:
        parse_route(straight(**top), source="my.toml")
    text = str(info.value)
    assert "\n" not in text and text.startswith("my.toml: ") and message in text


def test_the_route_file_format_is_documented():
    """The route module's docstring, the format's one reference, shows both keys with their
    defaults, and its TOML block parses with them."""
    import biso_cosim.routes.route as module

    doc = module.__doc__
    block = doc[doc.index("format = 1"):doc.index("The first waypoint")]
    data = tomllib.loads("\n".join(line[4:] for line in block.splitlines()))
    assert data["tyres"] == DEFAULT_TYRE_MODEL and data["surface"] == "dry"
    assert set(TYRE_MODELS) <= set(doc.replace('"', " ").split())


def test_vehicle_sim_takes_the_route_tyres_unless_given_its_own():
    from biso_cosim.vehicle.sim import VehicleSim

    route = parse_route(straight(tyres="magic_formula", surface="snow"))
    sim = VehicleSim(route)
    assert sim.tyres == "magic_formula" and sim.model.nplugin == 1
    assert sim.model.geom("ground").friction[0] == SURFACES["snow"]
    # an explicit model wins, with the route's surface only for the magic_formula tyres
    assert VehicleSim(route, tyres="coulomb").model.nplugin == 0
    wet = VehicleSim(route, surface="wet")
    assert wet.model.geom("ground").friction[0] == SURFACES["wet"]
    coulomb_route = parse_route(straight(tyres="coulomb"))
    assert VehicleSim(coulomb_route).model.nplugin == 0
    assert VehicleSim(coulomb_route, tyres="magic_formula").model.geom("ground").friction[0] == 1.0
    assert VehicleSim(parse_route(straight())).model.nplugin == 1  # the default


def brake_from(route, speed_mps: float = 14.0) -> float:
    """Stopping distance (m) of the car from ``speed_mps`` on the route's straight, with the
    route's tyres: driven up to speed, then all four brakes on full."""
    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.sim import VehicleSim

    sim = VehicleSim(route)
    for _ in range(50 * 40):
        sim.drive()
        sim.step()
        if sim.current_truth().speed_mps[0] >= speed_mps:
            break
    start = sim.current_truth().pos_w[0, :2].copy()
    for _ in range(50 * 20):
        sim.apply(DriverCommand(steer_rad=0.0, drive=0.0, brake=1.0))
        sim.step()
        if abs(sim.current_truth().speed_mps[0]) < 0.05:
            break
    return float(np.linalg.norm(sim.current_truth().pos_w[0, :2] - start))


def test_the_route_surface_changes_the_braking_as_its_friction_says():
    """A wet road (λ_μ = 0.7) brakes the car from 14 m/s in a longer distance than the dry one,
    a snowy one (0.25) in a much longer one; with the brakes locking or near it, the distance
    goes about as 1/μ (v²/(2μg)), and never below the friction's limit."""
    g = 9.80665
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dist = {s: brake_from(parse_route(straight(tyres="magic_formula", surface=s))) for s in ("dry", "snow")}
    mu_dry = 1.21 * 1.0  # p_Dx1 (the peak friction at the nominal load): the shortest distance there can be
    assert dist["dry"] > 14.0 ** 2 / (2 * mu_dry * g) * 0.95
    assert dist["snow"] > 14.0 ** 2 / (2 * mu_dry * SURFACES["snow"] * g) * 0.95
    assert dist["snow"] > 2.0 * dist["dry"]


def _rolling_stop(route, speed_mps: float = 14.0) -> float:
    """Stopping distance (m) with all four brakes on full from ``speed_mps``, the car put at
    that speed at the route's start (wheels rolling with it)."""
    import mujoco

    from biso_cosim.vehicle.driver import DriverCommand
    from biso_cosim.vehicle.sim import VehicleSim

    sim = VehicleSim(route)
    m, d = sim.model, sim.data
    d.qvel[0] = speed_mps
    for w in ("fl", "fr", "rl", "rr"):
        d.qvel[m.jnt_dofadr[m.joint(f"{w}_spin").id]] = speed_mps / sim.index.wheel_radius_m
    mujoco.mj_forward(m, d)
    x0 = float(d.qpos[0])
    for _ in range(50 * 20):
        sim.apply(DriverCommand(steer_rad=0.0, drive=0.0, brake=1.0))
        sim.step()
        if abs(d.qvel[0]) < 0.02:
            break
    return float(d.qpos[0]) - x0


def snow_patch(x0_m: float, x1_m: float, **extra) -> dict:
    return {"x0_m": x0_m, "y0_m": 0.0, "x1_m": x1_m, "y1_m": 0.0, "surface": "snow", **extra}


def test_a_patch_of_snow_lengthens_the_braking_distance_by_its_share_of_the_stop():
    """Braking from 14 m/s on dry asphalt: about 9 m. A snow patch (λ_μ = 0.25) over the whole
    stop lengthens it to about 1/0.25 times (v²/(2μg), the ABS holding each surface's peak);
    one from 4 m on to in between (the car enters the snow at the speed left after the dry
    part: v² − 2·a_dry·d_dry); one beside the road changes nothing, bit for bit."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dry = _rolling_stop(parse_route(straight(tyres="magic_formula")))
        stops = {name: _rolling_stop(parse_route(straight(tyres="magic_formula", terrain={"surface": [patch]})))
                 for name, patch in (("all", snow_patch(-20.0, 200.0)), ("half", snow_patch(4.0, 200.0)),
                                     ("beside", snow_patch(-20.0, 200.0, y0_m=20.0, y1_m=20.0)))}
    assert stops["beside"] == dry
    assert stops["all"] == pytest.approx(dry / SURFACES["snow"], rel=0.1)  # v²/(2μg): μ scaled by λ_μ
    # the patch from x = 4 m: the front wheels (a wheelbase ahead of the rear axle, which
    # starts at x = 0) reach it after 4 − L m, the rear wheels after 4 m; from there on the
    # snow's deceleration: between the two, as if the whole car entered at either point
    from biso_cosim.vehicle.model import vehicle_parameters

    a_dry, a_snow = 14.0 ** 2 / (2 * dry), 14.0 ** 2 / (2 * stops["all"])
    entered = [4.0 - vehicle_parameters()["wheelbase_m"], 4.0]
    late, early = (d + (14.0 ** 2 - 2 * a_dry * d) / (2 * a_snow) for d in entered[::-1])
    assert dry < stops["half"] < stops["all"]
    assert late < stops["half"] < early


@pytest.mark.parametrize("patch, message", [
    ({"x0_m": 0.0, "y0_m": 0.0, "x1_m": 10.0, "y1_m": 0.0, "surface": "mud"},
     "my.toml: terrain.surface[0]: surface must be one of dry, wet, gravel, snow, ice or a friction scale in "
     "(0, 1.5], got 'mud'"),
    ({"x0_m": 0.0, "y0_m": 0.0, "x1_m": 10.0, "y1_m": 0.0, "surface": 2.0},
     "my.toml: terrain.surface[0]: surface friction scale must be in (0, 1.5], got 2.0"),
    ({"x0_m": 0.0, "y0_m": 0.0, "x1_m": 10.0, "y1_m": 0.0, "surface": "wet", "width_m": -1.0},
     "my.toml: terrain.surface[0]: surface: width_m must be a positive number, got -1.0"),
    ({"x0_m": 0.0, "y0_m": 0.0, "x1_m": 0.0, "y1_m": 0.0, "surface": "wet"},
     "my.toml: terrain.surface[0]: surface: the ends (x0_m, y0_m) and (x1_m, y1_m) must differ"),
    ({"x0_m": 0.0, "y0_m": 0.0, "x1_m": 10.0, "surface": "wet"}, "my.toml: terrain.surface[0]: missing field(s) ['y1_m']"),
    ({"x0_m": 0.0, "y0_m": 0.0, "x1_m": 10.0, "y1_m": 0.0, "surface": "wet", "mu": 1},
     "my.toml: terrain.surface[0]: unknown field(s) ['mu']"),
    ({"x0_m": "a", "y0_m": 0.0, "x1_m": 10.0, "y1_m": 0.0, "surface": "wet"},
     "my.toml: terrain.surface[0]: field 'x0_m' must be a number, got 'a'"),
])
def test_bad_surface_patches_are_one_line_naming_the_entry_and_field(patch, message):
    with pytest.raises(ValueError) as info:
        parse_route(straight(tyres="magic_formula", terrain={"surface": [patch]}), source="my.toml")
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


def test_surface_patches_need_the_magic_formula_tyres():
    with pytest.raises(ValueError) as info:
        parse_route(straight(tyres="coulomb", terrain={"surface": [snow_patch(0.0, 10.0)]}), source="my.toml")
    assert str(info.value) == ("my.toml: terrain.surface needs tyres = \"magic_formula\" (the coulomb tyres have "
                               "one friction everywhere)")
