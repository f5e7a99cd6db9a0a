"""pytest plugin of biso_cosim (registered through the ``pytest11`` entry point).

* fixture ``drive_route``: :func:`biso_cosim.testing.drive` (session-cached runs);
* marker ``biso_route(route, estimator="biso", seed=0, duration_s=None, **options)`` with the
  fixture ``route_run``: the :class:`~biso_cosim.testing.DriveResult` of that drive; a run
  that failed (left the route, rolled over, got stuck, did not finish) fails the test with
  the reason.

Importing this module imports nothing heavy: MuJoCo and the kernels load on the first drive.
"""

from __future__ import annotations

import pytest


def pytest_configure(config) -> None:
    config.addinivalue_line(
        "markers",
        "biso_route(route, estimator='biso', seed=0, duration_s=None, **options): drive a route "
        "for the route_run fixture (biso_cosim)",
    )


@pytest.fixture
def drive_route():
    """``drive(route, estimator, seed=..., duration_s=..., **options)`` → DriveResult."""
    from biso_cosim.testing import drive

    return drive


@pytest.fixture
def route_run(request):
    """The drive described by the test's ``biso_route`` marker."""
    marker = request.node.get_closest_marker("biso_route")
    if marker is None or not marker.args:
        raise pytest.UsageError("route_run needs @pytest.mark.biso_route(route, ...) on the test")
    from biso_cosim.testing import RouteRunFailed, drive

    try:
        return drive(*marker.args, **marker.kwargs)
    except RouteRunFailed as exc:  # the test fails (not errors) with the reason
        pytest.fail(str(exc), pytrace=False)
