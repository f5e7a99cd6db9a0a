"""Whether a run drove its route: a run's status, judged from its truth.

A run whose car left the road, rolled over, stood still where it should drive, or did not
reach the finish in the time it had produces error tables that mean nothing. ``judge_run``
tells, from the run's own truth and the driver's log, which of these happened first:

| status | when | bound |
|---|---|---|
| ``diverged`` | the physics could not go on (``PhysicsDiverged``: MuJoCo found the state unstable and would have reset it, or a tyre force was not finite); the run ended there | |
| ``rolled_over`` | the body's z axis tilts from the vertical by more than ``ROLLOVER_TILT_DEG`` | 60° |
| ``left_route`` | the driver's cross-track distance exceeds ``CROSS_TRACK_BOUND_M`` | 5 m |
| ``stuck`` | after the start-up wait and before the finish, the driver's progress along the route grows by less than ``STUCK_PROGRESS_M`` in ``stuck_window_s(route)`` | 1 m in max(20 s, longest stop + 10 s) |
| ``incomplete`` | none of these, but the route was not completed although the run lasted its nominal duration + ``FINISH_MARGIN_S`` | 10 s |
| ``partial`` | not completed, in a run shorter than that (the caller asked for a part of the route): not a failure | |
| ``completed`` | the finish was reached | |

The bounds: the static rollover threshold of a compact car (half track over centre of mass
height, 0.75 m / 0.55 m) is 54°, so a car tilted past 60° has fallen over, while no road of
the route library or of an imported track is steeper than the car's climbable grade (33 %,
18°) or banked by more than 20°. The scripted driver keeps within 0.5 m of the route on
every library route (``biso-cosim routes check``); 5 m is beyond a lane and its shoulder.
A route's stops (traffic lights, cusps) are shorter than the stuck window by construction.

``biso-cosim run`` prints the status first, writes it with its reason into summary.json and
exits with ``EXIT_RUN_FAILED`` for a failed run (unless ``--allow-incomplete``); a run
stopped by Ctrl-C has the status ``interrupted`` and exits with ``EXIT_INTERRUPTED``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["RunStatus", "judge_run", "interrupted", "stuck_window_s", "CROSS_TRACK_BOUND_M", "ROLLOVER_TILT_DEG",
           "STUCK_PROGRESS_M", "STUCK_MIN_WINDOW_S", "FINISH_MARGIN_S", "FAILED", "EXIT_RUN_FAILED",
           "EXIT_INTERRUPTED"]

CROSS_TRACK_BOUND_M = 5.0
"""Largest cross-track distance of a run that stays on its route (the driver keeps within 0.5 m)."""

ROLLOVER_TILT_DEG = 60.0
"""Tilt of the body's z axis from the vertical beyond which the car has rolled over (static
rollover threshold of the class: atan(0.75 / 0.55) = 54°)."""

STUCK_PROGRESS_M = 1.0
"""Least progress along the route in a stuck window of a car that still drives."""

STUCK_MIN_WINDOW_S = 20.0
"""Shortest stuck window; a route with a longer stop gets that stop + 10 s."""

FINISH_MARGIN_S = 10.0
"""A run that lasted the route's nominal duration and this much more should have finished
(the default duration of ``biso-cosim run`` is the nominal duration + 10 s)."""

FAILED = ("diverged", "rolled_over", "left_route", "stuck", "incomplete")
"""The statuses of a failed run."""

EXIT_RUN_FAILED = 3
"""Exit code of ``biso-cosim run`` for a failed run (a status in ``FAILED``)."""

EXIT_INTERRUPTED = 130
"""Exit code of a run stopped by Ctrl-C (128 + SIGINT, the shell's convention)."""


@dataclass(frozen=True)
class RunStatus:
    """A run's status (``completed``, ``partial``, one of ``FAILED``, or ``interrupted``),
    the reason in words, and the time it happened (None when it is the run's end)."""

    status: str
    reason: str
    t_s: float | None = None

    @property
    def failed(self) -> bool:
        return self.status in FAILED

    def as_dict(self) -> dict:
        return {"status": self.status, "status_reason": self.reason}


def stuck_window_s(route) -> float:
    """The time a car on ``route`` may stand outside its stops: max(20 s, longest stop + 10 s)."""
    dwells = [s.dwell_s for s in route.stops[:-1]]  # the last is the finish (dwell ∞)
    return max(STUCK_MIN_WINDOW_S, max(dwells, default=0.0) + 10.0)


def _period_times(result) -> np.ndarray:
    """Time at the start of each logged control period (the driver's log)."""
    n = result.progress_m.shape[0]
    return result.log_start_s + np.arange(n) * (result.duration_s - result.log_start_s) / max(n, 1)


def _rollover(result) -> RunStatus | None:
    q = result.truth.q_wb
    up = 1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2)  # z component of the body's z axis in ENU
    tilt = np.degrees(np.arccos(np.clip(up, -1.0, 1.0)))
    over = np.flatnonzero(tilt > ROLLOVER_TILT_DEG)
    if not over.size:
        return None
    i = int(over[0])
    t = float(result.t_s[i])
    return RunStatus("rolled_over", f"the car rolled over at t = {t:.2f} s (tilt {tilt[i]:.1f}° from the vertical, "
                                    f"bound {ROLLOVER_TILT_DEG:g}°)", t)


def _left_route(result) -> RunStatus | None:
    xt = np.abs(np.asarray(result.cross_track_m, dtype=np.float64))
    off = np.flatnonzero(~(xt <= CROSS_TRACK_BOUND_M))  # NaN counts as off the route
    if not off.size:
        return None
    i = int(off[0])
    t = float(_period_times(result)[i])
    s = float(result.progress_m[i])
    return RunStatus("left_route", f"the car left the route at t = {t:.2f} s, about {s:.0f} m along it "
                                   f"(cross-track {xt[i]:.1f} m, bound {CROSS_TRACK_BOUND_M:g} m)", t)


def _stuck(result) -> RunStatus | None:
    progress = np.asarray(result.progress_m, dtype=np.float64)
    times = _period_times(result)
    if progress.shape[0] < 2:
        return None
    dt = (times[-1] - times[0]) / (progress.shape[0] - 1)
    window_s = stuck_window_s(result.route)
    w = int(math.ceil(window_s / dt)) + 1
    end = result.finished_at_s if result.finished_at_s is not None else math.inf
    driving = np.flatnonzero((times >= result.route.driving.start_wait_s) & (times <= end))
    if driving.shape[0] < w:
        return None
    segment = progress[driving[0]:driving[-1] + 1]
    views = np.lib.stride_tricks.sliding_window_view(segment, w)
    span = views.max(axis=1) - views.min(axis=1)
    still = np.flatnonzero(span < STUCK_PROGRESS_M)
    if not still.size:
        return None
    i = int(driving[0] + still[0])
    t = float(times[i])
    return RunStatus("stuck", f"the car got stuck at t = {t:.2f} s, about {progress[i]:.0f} m along the route "
                              f"(less than {STUCK_PROGRESS_M:g} m of progress in {window_s:g} s)", t)


def _diverged(result) -> RunStatus | None:
    if result.diverged is None:
        return None
    t, reason = result.diverged
    return RunStatus("diverged", f"{reason}; the run stopped there", t)


def judge_run(result) -> RunStatus:
    """The status of a :class:`biso_cosim.cosim.RunResult` (see the module doc): the earliest
    failure, else whether the route was completed."""
    events = [e for e in (_diverged(result), _rollover(result), _left_route(result), _stuck(result)) if e is not None]
    if events:
        return min(events, key=lambda e: e.t_s)
    route = result.route
    if result.completed:
        return RunStatus("completed", f"route completed at t = {result.finished_at_s:.1f} s"
                         if result.finished_at_s is not None else "route completed")
    nominal = route.nominal_duration_s
    if result.duration_s >= nominal + FINISH_MARGIN_S - 1e-9:
        return RunStatus("incomplete", f"the route was not completed in {result.duration_s:.0f} s (nominal duration "
                                       f"{nominal:.0f} s; {result.progress_m[-1]:.0f} of {route.path.length_m:.0f} m "
                                       "driven)")
    return RunStatus("partial", f"the run ended at {result.duration_s:g} s, before the route's nominal duration of "
                                f"{nominal:.0f} s (not a failure)")


def interrupted(result) -> RunStatus:
    """The status of a run stopped by Ctrl-C after ``result.duration_s`` simulated seconds."""
    return RunStatus("interrupted", f"interrupted at t = {result.duration_s:.2f} s", result.duration_s)
