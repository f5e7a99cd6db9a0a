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
from biso_cosim.vehicle.tyres import SURFACES, TYRE_MODELS


def straight(**top) -> dict:
    """A straight open route of 400 m at 14 m/s, with the given top-level keys."""
    return {"name": "straight", "description": "a straight road", "closed": False,
            "waypoint": [{"x_m": 0.0, "y_m": 0.0, "speed_mps": 14.0}, {"x_m": 400.0, "y_m": 0.0}], **top}


def test_defaults_are_the_coulomb_car_on_dry_asphalt():
    route = parse_route(straight())
    assert (route.tyres, route.surface) == ("coulomb", "dry")
    assert all((load_route(n).tyres, load_route(n).surface) == ("coulomb", "dry")
               for n in ("figure8", "loop600", "rough_road"))


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
    ({"surface": "wet"}, "my.toml: surface = 'wet' needs tyres = \"magic_formula\""),
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
    assert data["tyres"] == "coulomb" and data["surface"] == "dry"
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
    coulomb_route = parse_route(straight())
    assert VehicleSim(coulomb_route).model.nplugin == 0
    assert VehicleSim(coulomb_route, tyres="magic_formula").model.geom("ground").friction[0] == 1.0


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
