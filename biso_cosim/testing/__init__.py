"""Scripted driving-route tests: drive a route with an estimator, assert its attitude errors.

A test reads like the requirement it checks::

    from biso_cosim.testing import drive

    def test_my_estimator_holds_tilt_on_hills():
        run = drive("hill_climb", estimator=MyEstimator(), seed=0)
        run.assert_max_error(roll=1.0, pitch=1.0)          # degrees, over the whole drive

``estimator`` is a library name (``"biso"``), a ``(name, params)`` pair, or your own object
with ``update(gyro_b, accel_b, mag_b)`` returning the (k, 4) ``q_wb`` of the k samples it was
given (see :class:`biso_cosim.cosim.CoSimulation`). A run whose car left the route, rolled
over, got stuck or did not finish fails with :class:`RouteRunFailed` and the reason. A
failing assertion says which angle,
when it first went over, for how long in all, and the largest error with where on the
route it happened.

Runs of library estimators are cached for the session (the 16 most recent), keyed by
everything that makes a run (the route's content, the estimator, its parameters and label,
the seed, the duration, the sensor options and a profile file's content), so a suite that
drives the same route several times simulates it once, and a changed route or profile file
is a different key: nothing stale comes back. Cached results are read-only. Runs with your
own estimator objects are never cached (they hold state).

With pytest, the plugin (registered automatically) offers the fixture ``drive_route`` (this
``drive``) and the marker ``biso_route``::

    @pytest.mark.biso_route("hill_climb", estimator="biso", seed=0, duration_s=60)
    def test_hill(route_run):
        route_run.assert_rms_error(roll=0.5)
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from biso_cosim.metrics import ANGLES

__all__ = ["drive", "DriveResult", "AttitudeErrorExceeded", "RouteRunFailed", "clear_cache"]

_ALL = (*ANGLES, "total")
_CACHE: "OrderedDict[tuple, Any]" = OrderedDict()
_CACHE_SIZE = 16


class AttitudeErrorExceeded(AssertionError):
    """An attitude error went over its bound; the message says where and by how much."""


class RouteRunFailed(AssertionError):
    """The run itself failed (``biso_cosim.runstatus``): its errors mean nothing. ``status``
    is the :class:`~biso_cosim.runstatus.RunStatus`."""

    def __init__(self, message: str, status: Any = None):
        super().__init__(message)
        self.status = status


def clear_cache() -> None:
    """Forget the cached runs."""
    _CACHE.clear()


def _cache_key(route, estimator, seed, duration_s, label, options) -> tuple | None:
    if isinstance(estimator, str):
        est = (estimator, ())
    elif (isinstance(estimator, tuple) and len(estimator) == 2 and isinstance(estimator[0], str)
          and isinstance(estimator[1], Mapping)):
        est = (estimator[0], tuple(sorted((k, repr(v)) for k, v in estimator[1].items())))
    else:
        return None  # a user's object: never cached
    try:
        hash(route)
    except TypeError:
        return None
    from biso_cosim.cosim import _profile_content

    profile = _profile_content(options.get("sensor_profile"))
    return route, est, seed, duration_s, label, profile, tuple(sorted((k, repr(v)) for k, v in options.items()))


def _read_only(run: Any) -> Any:
    """Mark a cached run's arrays read-only: tests share it."""
    for value in vars(run).values():
        arrays = [value] if isinstance(value, np.ndarray) else (
            [v for v in vars(value).values() if isinstance(v, np.ndarray)] if hasattr(value, "__dict__") else [])
        if hasattr(value, "packed"):
            arrays.append(value.packed)
        for array in arrays:
            array.flags.writeable = False
    return run


def drive(route: Any, estimator: Any = "biso", *, seed: int = 0, duration_s: float | None = None,
          label: str | None = None, allow_failed: bool = False, **options: Any) -> "DriveResult":
    """Drive ``route`` (name, file or Route) with ``estimator`` in the loop; see the module doc.

    ``options`` go to :class:`biso_cosim.cosim.CoSimulation` (``sensor_profile``,
    ``registers``, ``mounting``, ``gyro_calibration_s``, ``control_rate_hz``, ...).
    A run that failed (the car left the route, rolled over, got stuck, or did not finish in
    a duration long enough to: ``biso_cosim.runstatus``) raises :class:`RouteRunFailed`
    with the reason, unless ``allow_failed``; a shorter ``duration_s`` is a part of the
    route, not a failure.
    """
    from biso_cosim.runstatus import judge_run

    from biso_cosim.cosim import CoSimulation, EstimatorSpec
    from biso_cosim.routes import load_route

    route = load_route(route)
    key = _cache_key(route, estimator, seed, duration_s, label, options)
    if key is not None and key in _CACHE:
        _CACHE.move_to_end(key)
        run = _CACHE[key]
    else:
        if isinstance(estimator, tuple):
            spec = EstimatorSpec(estimator[0], dict(estimator[1]), label=label or "")
        elif isinstance(estimator, str):
            spec = EstimatorSpec(estimator, label=label or "")
        else:
            spec = estimator
        run = CoSimulation(route, duration_s=duration_s, seed=seed, estimators=[spec], **options).run()
        if key is not None:
            _CACHE[key] = _read_only(run)
            while len(_CACHE) > _CACHE_SIZE:
                _CACHE.popitem(last=False)
    result = DriveResult(run, next(iter(run.estimates)))
    status = judge_run(run)
    if status.failed and not allow_failed:
        raise RouteRunFailed(f"{result._name()}: {status.status}: {status.reason}", status)
    return result


@dataclass(frozen=True)
class DriveResult:
    """One estimator's drive: errors, flags, figures, and assertions on them.

    ``run`` is the whole :class:`biso_cosim.cosim.RunResult` (truth, sensor samples, logs).
    """

    run: Any
    key: str

    @property
    def t_s(self) -> np.ndarray:
        return self.run.t_s

    @property
    def errors(self) -> dict[str, np.ndarray]:
        """Per-sample errors in degrees: roll, pitch, heading (wrapped) and total."""
        return self.run.errors(self.key)

    @property
    def flags(self) -> np.ndarray:
        return self.run.estimates[self.key][1]

    @property
    def summary(self) -> dict:
        """This estimator's entry of the run summary (RMS, max, start-to-end ...)."""
        return self.run.summary()["estimators"][self.key]

    def _name(self) -> str:
        return f"{self.run.route.name} with {self.key} (seed {self.run.seed})"

    def _where(self, index: int) -> str:
        """When, and where along the route (the driver's logged progress, so that laps and the
        branches of a figure eight are told apart)."""
        t = float(self.t_s[index])
        run = self.run
        n = run.progress_m.shape[0]
        # progress is measured at the start of each control period
        starts = run.log_start_s + np.arange(n) * (run.duration_s - run.log_start_s) / n
        s = float(np.interp(t, starts, run.progress_m))
        return f"t = {t:.2f} s, about {s:.0f} m along the route"

    @staticmethod
    def _bounds(given: dict[str, float | None]) -> dict[str, float]:
        out = {}
        for angle, bound in given.items():
            if bound is None:
                continue
            if not (isinstance(bound, (int, float)) and math.isfinite(bound) and bound > 0):
                raise ValueError(f"{angle}: the bound must be a positive number of degrees, got {bound!r}")
            out[angle] = float(bound)
        if not out:
            raise ValueError(f"give at least one bound: {', '.join(_ALL)}")
        return out

    def assert_max_error(self, roll: float | None = None, pitch: float | None = None,
                         heading: float | None = None, total: float | None = None, *,
                         after_s: float = 0.0) -> None:
        """Every |error| (degrees) stays within its bound from ``after_s`` on."""
        bounds = self._bounds({"roll": roll, "pitch": pitch, "heading": heading, "total": total})
        window = self.t_s >= after_s
        if not window.any():
            raise ValueError(f"after_s = {after_s} s leaves no samples (the drive lasted {self.t_s[-1]:.1f} s)")
        problems = []
        dt = float(np.median(np.diff(self.t_s))) if self.t_s.shape[0] > 1 else 0.0
        for angle, bound in bounds.items():
            err = np.abs(self.errors[angle])
            over = window & (err > bound)
            if over.any():
                first = int(np.argmax(over))
                worst = int(np.flatnonzero(window)[np.argmax(err[window])])
                problems.append(
                    f"{angle} error over {bound:g}° for {over.sum() * dt:.1f} s of {window.sum() * dt:.1f} s: "
                    f"first at {self._where(first)} ({err[first]:.2f}°); largest {err[worst]:.2f}° at "
                    f"{self._where(worst)}")
        if problems:
            raise AttitudeErrorExceeded(f"{self._name()}:\n  " + "\n  ".join(problems))

    def assert_rms_error(self, roll: float | None = None, pitch: float | None = None,
                         heading: float | None = None, total: float | None = None, *,
                         after_s: float = 0.0) -> None:
        """The RMS error (degrees) of each angle from ``after_s`` on is within its bound."""
        bounds = self._bounds({"roll": roll, "pitch": pitch, "heading": heading, "total": total})
        window = self.t_s >= after_s
        if not window.any():
            raise ValueError(f"after_s = {after_s} s leaves no samples (the drive lasted {self.t_s[-1]:.1f} s)")
        problems = []
        for angle, bound in bounds.items():
            rms = float(np.sqrt(np.mean(self.errors[angle][window] ** 2)))
            if not math.isfinite(rms):
                problems.append(f"{angle} RMS error is not a number (the estimate has NaN)")
                continue
            if rms > bound:
                problems.append(f"{angle} RMS error {rms:.3f}° is over {bound:g}° (from t = {after_s:g} s)")
        if problems:
            raise AttitudeErrorExceeded(f"{self._name()}:\n  " + "\n  ".join(problems))

    def assert_closure(self, roll: float | None = None, pitch: float | None = None,
                       heading: float | None = None) -> None:
        """On a closed route driven to its end: |(end − start of the estimate) − (end − start of
        the truth)| within the bounds (degrees); the paper's start-to-end test."""
        bounds = self._bounds({"roll": roll, "pitch": pitch, "heading": heading})
        entry = self.summary
        if "start_end_error_deg" not in entry:
            raise AssertionError(f"{self._name()}: no start-to-end figures: the route is open or was not "
                                 "driven to its end (give a longer duration_s)")
        problems = [f"{a} start-to-end error {entry['start_end_error_deg'][a]:+.3f}° is over ±{b:g}°"
                    for a, b in bounds.items() if abs(entry["start_end_error_deg"][a]) > b]
        if problems:
            raise AttitudeErrorExceeded(f"{self._name()}:\n  " + "\n  ".join(problems))

    def assert_completed(self, max_cross_track_m: float = 1.0) -> None:
        """The car reached the end of the route and the driver never strayed further than
        ``max_cross_track_m`` from it."""
        worst = float(np.max(np.abs(self.run.cross_track_m)))
        if not self.run.completed:
            raise AssertionError(f"{self._name()}: the route was not completed in {self.run.duration_s:.0f} s")
        if worst > max_cross_track_m:
            raise AssertionError(f"{self._name()}: the driver was {worst:.2f} m off the route "
                                 f"(bound {max_cross_track_m:g} m)")


# drives in another simulator (recorded truth through biso_cosim.plugin)
from biso_cosim.testing.external import ExternalDrive, replay  # noqa: E402

__all__ += ["replay", "ExternalDrive"]
