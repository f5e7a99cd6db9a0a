"""What a rendered frame shows besides the model: the road along the route and a sky.

The road is drawn into the scene of each frame (``mujoco.mjv_initGeom`` on the scene's
free geoms), not added to the model, so the physics and the model stay as they are: a
dark asphalt strip of ``ROAD_WIDTH_M`` along the route's centre line at the terrain's
height, with white edge lines and a dashed centre line. Where the model draws no geometry
(depth at the far plane: MuJoCo's background is black without a skybox texture), the frame
gets a sky, a vertical gradient from a pale horizon to blue. The interactive viewer
(``render_mode="human"``), whose pixels cannot be painted, gets the same road and a sky of
geometry in its scene (``decorate_scene``): a wall of boxes in the gradient's colours
around the route, under a lid.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from biso_cosim.routes import Route

__all__ = ["ROAD_WIDTH_M", "SKY_EMISSION", "road_geoms", "sky_geoms", "add_geoms", "decorate_scene", "paint_sky"]

ROAD_WIDTH_M = 7.0
"""Width of the drawn road, m (two lanes of 3.5 m)."""

_ASPHALT = np.array([0.18, 0.18, 0.19, 1.0], dtype=np.float32)
_PAINT = np.array([0.92, 0.92, 0.88, 1.0], dtype=np.float32)
_SEGMENT_M = 2.0  # length of one road box, m
_DASH_M, _GAP_M = 3.0, 6.0  # centre-line dashes and gaps, m
_LINE_M = 0.12  # width of the painted lines, m
_LIFT_M = (0.03, 0.04)  # height of the asphalt's and the paint's top above the terrain, m (no z-fighting)
_SKY_TOP = np.array([70, 120, 190], dtype=np.float64)
_SKY_HORIZON = np.array([200, 215, 230], dtype=np.float64)
_SKY_PANELS, _SKY_BANDS = 48, 6  # the sky's wall: panels around the route, bands of colour up it
_SKY_MARGIN_M = 300.0  # the wall's distance beyond the farthest point of the route, m
_SKY_ELEVATION = 0.6  # the wall's height over its radius (tan of the angle the camera sees it up to)
SKY_EMISSION = 0.5
"""Emission of the sky's boxes: their colour shows with little shading from the lights."""


def _boxes(route: Route, start: np.ndarray, length_m: float, offset_m: float, width_m: float, lift_m: float,
           rgba: np.ndarray) -> list[tuple]:
    """Boxes of length ``length_m`` along the path from arc lengths ``start``, their centres
    ``offset_m`` left of the centre line: (size, pos, mat, rgba) each."""
    path = route.path
    s = np.clip(start + 0.5 * length_m, 0.0, path.length_m)
    x = np.interp(s, path.s_m, path.x_m)
    y = np.interp(s, path.s_m, path.y_m)
    heading = np.interp(s, path.s_m, np.unwrap(path.heading_rad))
    x, y = x - offset_m * np.sin(heading), y + offset_m * np.cos(heading)
    z = np.asarray(route.terrain.height(x, y), dtype=np.float64) + lift_m
    out = []
    for xi, yi, zi, h in zip(x.tolist(), y.tolist(), z.tolist(), heading.tolist()):
        c, sn = math.cos(h), math.sin(h)
        mat = np.array([c, -sn, 0.0, sn, c, 0.0, 0.0, 0.0, 1.0])
        out.append((np.array([0.5 * length_m + 0.05, 0.5 * width_m, 0.01]), np.array([xi, yi, zi - 0.01]), mat, rgba))
    return out


def road_geoms(route: Route) -> list[tuple]:
    """The boxes of the road along ``route``: asphalt, edge lines, centre dashes."""
    length = route.path.length_m
    segments = np.arange(0.0, length, _SEGMENT_M)
    geoms = _boxes(route, segments, _SEGMENT_M, 0.0, ROAD_WIDTH_M, _LIFT_M[0], _ASPHALT)
    edge = 0.5 * ROAD_WIDTH_M - 0.3
    for side in (-edge, edge):
        geoms += _boxes(route, segments, _SEGMENT_M, side, _LINE_M, _LIFT_M[1], _PAINT)
    geoms += _boxes(route, np.arange(0.0, length - _DASH_M, _DASH_M + _GAP_M), _DASH_M, 0.0, _LINE_M, _LIFT_M[1],
                    _PAINT)
    return geoms


def sky_geoms(route: Route, far_m: float) -> list[tuple]:
    """The sky of a viewer that draws only geometry (MuJoCo's interactive viewer, whose
    pixels ``paint_sky`` cannot reach): a wall of thin boxes on a circle around the route,
    ``_SKY_MARGIN_M`` beyond its farthest point (closer when the camera's far plane
    ``far_m`` would cut it off), in bands of ``paint_sky``'s gradient from the horizon's
    colour at the bottom to the top's, and a lid of the top's colour. Drawn with full
    emission (``add_geoms``), so that the lights do not shade it."""
    path = route.path
    cx, cy = 0.5 * (path.x_m.min() + path.x_m.max()), 0.5 * (path.y_m.min() + path.y_m.max())
    reach = float(np.max(np.hypot(path.x_m - cx, path.y_m - cy)))
    # (a camera on the route sees the far side of the wall at reach + radius, the lid's corner farther)
    radius = max(min(reach + _SKY_MARGIN_M, (0.9 * far_m - reach) / (1.0 + _SKY_ELEVATION)), reach + 10.0)
    height = _SKY_ELEVATION * radius
    base = float(np.min(route.terrain.height(path.x_m, path.y_m))) - 0.1 * height
    half_width = radius * math.tan(math.pi / _SKY_PANELS) + 1.0  # (panels overlap at their ends)
    band = height / _SKY_BANDS
    geoms = []
    for i in range(_SKY_PANELS):
        angle = 2.0 * math.pi * i / _SKY_PANELS
        c, sn = math.cos(angle), math.sin(angle)
        # the box's x axis points to the centre, y along the wall
        mat = np.array([-c, sn, 0.0, -sn, -c, 0.0, 0.0, 0.0, 1.0])
        for j in range(_SKY_BANDS):
            t = (j + 0.5) / _SKY_BANDS
            rgba = np.append((_SKY_HORIZON * (1.0 - t) + _SKY_TOP * t) / 255.0, 1.0).astype(np.float32)
            pos = np.array([cx + radius * c, cy + radius * sn, base + (j + 0.5) * band])
            geoms.append((np.array([1.0, half_width, 0.5 * band + 0.5]), pos, mat, rgba))
    lid = np.append(_SKY_TOP / 255.0, 1.0).astype(np.float32)
    geoms.append((np.array([radius, radius, 1.0]), np.array([cx, cy, base + height + 1.0]), np.eye(3).ravel(), lid))
    return geoms


def add_geoms(scene: mujoco.MjvScene, geoms: list[tuple], emission: float = 0.0) -> None:
    """Append boxes to the scene of a frame (as many as it has room for), with ``emission``
    (0: lit as the model's geoms, 1: their own colour whatever the light)."""
    box = mujoco.mjtGeom.mjGEOM_BOX
    for size, pos, mat, rgba in geoms:
        if scene.ngeom >= scene.maxgeom:
            return
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(geom, box, size, pos, mat, rgba)
        geom.emission = emission
        scene.ngeom += 1


def decorate_scene(scene: mujoco.MjvScene, route: Route, model: mujoco.MjModel) -> None:
    """Append to ``scene`` the road along ``route`` and the sky around it: what the
    interactive viewer (``render_mode="human"``) draws besides ``model``, in its ``user_scn``.
    The sky keeps within the model's far clipping plane."""
    add_geoms(scene, road_geoms(route))
    add_geoms(scene, sky_geoms(route, float(model.vis.map.zfar * model.stat.extent)), emission=SKY_EMISSION)


def paint_sky(pixels: np.ndarray, depth: np.ndarray) -> None:
    """Give the background (depth 1: nothing drawn) a sky gradient, rows top to bottom."""
    background = depth >= 1.0
    if not background.any():
        return
    rows = pixels.shape[0]
    t = (np.arange(rows) / max(rows - 1, 1))[:, None]
    gradient = (_SKY_TOP * (1.0 - t) + _SKY_HORIZON * t).astype(np.uint8)  # (rows, 3)
    sky = np.broadcast_to(gradient[:, None, :], pixels.shape)
    pixels[background] = sky[background]
