"""biso_cosim: closed-loop tests of MEMS attitude estimation on a simulated vehicle.

A MuJoCo car drives scripted routes; its true motion feeds a virtual MPU-9250 (gyro,
accelerometer, AK8963 magnetometer); numba-jitted attitude estimators run in the loop.

Conventions (everywhere in the package; details in :mod:`biso_cosim.frames`):

* world frame ENU (x East, y North, z Up); vehicle body x forward, y left, z up (ISO 8855);
* quaternions Hamilton, scalar first (w, x, y, z); ``q_wb`` maps body vectors to world
  vectors, and every estimator returns ``q_wb``;
* roll, pitch, yaw: intrinsic z-y-x angles of ``q_wb`` (positive roll lowers the right side,
  positive pitch lowers the nose, yaw counter-clockwise from East); compass heading
  clockwise from North;
* SI units inside: rad, rad/s, m/s² (the accelerometer reads specific force, +g up at rest),
  µT, s; degrees only in printed summaries, plots and CSV columns named ``*_deg``.

Main entry points (imported on first use, so that ``import biso_cosim`` stays light)::

    from biso_cosim import run_route, estimate_attitude, load_route
    result = run_route("loop600", duration_s=600, seed=0)     # the co-simulation
    q_wb = estimate_attitude(gyro, accel, mag, 200.0, method="biso")
"""

from __future__ import annotations

import importlib

from biso_cosim import _source_tree

__version__ = "0.1.0"

# imported from the repository itself (python started in its root): envs/ and fmu/ beside
# the package are biso_cosim.envs and biso_cosim.fmu, as in an installed copy
_source_tree.install(__path__[0])

_LAZY = {
    "run_route": "biso_cosim.cosim",
    "CoSimulation": "biso_cosim.cosim",
    "RunResult": "biso_cosim.cosim",
    "EstimatorSpec": "biso_cosim.cosim",
    "estimate_attitude": "biso_cosim.estimators",
    "make_estimator": "biso_cosim.estimators",
    "estimator_names": "biso_cosim.estimators",
    "load_route": "biso_cosim.routes",
    "route_names": "biso_cosim.routes",
    "MPU9250": "biso_cosim.sensors",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'biso_cosim' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)

# Gymnasium ids biso_cosim/<Name>-v0, so that gym.make("biso_cosim:biso_cosim/<Name>-v0") works
# without a prior import. This imports Gymnasium (a dependency), never MuJoCo: the environment
# modules load when an environment is made.
import biso_cosim.envs  # noqa: E402,F401  (registers on import)
