"""Routes: the library that ships with the package, and route files of the user's own.

``load_route("loop600")`` loads a library route by name; ``load_route("my/route.toml")``
loads a file (format in :mod:`biso_cosim.routes.route`). ``route_names()`` lists the library.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path as FilePath

from biso_cosim.routes.limits import CarLimits, car_limits
from biso_cosim.routes.route import (DrivingLimits, Route, RouteWarning, Site, Stop, Waypoint, parse_route,
                                    read_route_file)

__all__ = ["Route", "Waypoint", "DrivingLimits", "Site", "Stop", "RouteWarning", "CarLimits", "car_limits",
           "load_route", "route_names", "parse_route", "read_route_file", "library_table"]

_LIBRARY = resources.files("biso_cosim.routes").joinpath("library")


def route_names() -> list[str]:
    """Names of the routes in the library, sorted."""
    return sorted(p.name[:-5] for p in _LIBRARY.iterdir() if p.name.endswith(".toml"))


def load_route(name_or_path: str | FilePath | Route) -> Route:
    """A library route by name, or a route file by path (anything ending in .toml)."""
    if isinstance(name_or_path, Route):
        return name_or_path
    text = str(name_or_path)
    if text.endswith(".toml") or "/" in text or "\\" in text:
        path = FilePath(text)
        if path.is_dir():
            raise ValueError(f"route file {text!r} is a directory; expected a .toml file")
        if not path.is_file():
            raise FileNotFoundError(f"route file {text!r} does not exist")
        return read_route_file(path)
    names = route_names()
    if text not in names:
        raise ValueError(f"unknown route {text!r}; known routes: {', '.join(names)} (or give a path to a .toml file)")
    with resources.as_file(_LIBRARY.joinpath(f"{text}.toml")) as path:
        return read_route_file(path)


def library_table() -> str:
    """The route library as a Markdown table (the one in docs/routes.md is this)."""
    rows = ["| route | what it is | excites | length | duration |", "|---|---|---|---|---|"]
    for name in route_names():
        r = load_route(name)
        s = r.summary()
        rows.append(f"| `{name}` | {r.description} | {r.excites} | {s['length_m']:.0f} m | "
                    f"{s['nominal_duration_s']:.0f} s |")
    return "\n".join(rows)
