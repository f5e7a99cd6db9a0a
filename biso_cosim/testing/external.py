"""Route tests of drives in another simulator: recorded truth in, the kit's assertions out.

The same three lines as a drive of the package's own car (``biso_cosim.testing.drive``)::

    from biso_cosim.testing import replay

    def test_my_estimator_on_my_simulators_roundabout():
        run = replay("drives/roundabout.npz", estimator="biso_plus", seed=0, frames=("NED", "FRD", "xyzw"))
        run.assert_max_error(roll=1.0, pitch=1.0, after_s=5.0)     # degrees

``replay`` runs the plug-in (``biso_cosim.plugin.ImuPlugin``) over a recording of the host
simulator's truth at its reference point, one row per physics tick (a dict of arrays or an
``.npz`` file): ``t_s`` (n,), ``q_wb`` (n, 4), ``omega_b`` (n, 3) and either
``specific_force_b`` or ``accel_w`` (n, 3); optionally ``p_w``, ``v_w``, ``alpha_b`` (n, 3)
and ``temperature_c`` (n,), all in the host's conventions (``frames``). A run recorded live
(the plug-in in the host's loop) is tested the same way with
``ExternalDrive.from_output(PluginOutput.concatenate(outputs))``.

``ExternalDrive`` is a ``DriveResult``: ``assert_max_error``, ``assert_rms_error`` and
``assert_closure`` (with ``start_end_windows``: when the vehicle stood still at the start and
at the end) fail with the same messages, "where" being the distance driven when positions
are known. A recording that cannot make a run (no samples, an estimate that is not finite,
a missing or malformed column) raises ValueError naming what is wrong.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from biso_cosim.frames import wrap_angle
from biso_cosim.metrics import ANGLES, attitude_angles_deg, error_stats, start_end_difference
from biso_cosim.testing import DriveResult

__all__ = ["replay", "ExternalDrive", "TRUTH_COLUMNS"]

TRUTH_COLUMNS = ("t_s", "q_wb", "omega_b", "specific_force_b", "accel_w", "p_w", "v_w", "alpha_b", "temperature_c")
"""The columns a recorded truth may hold (the arguments of ``ImuPlugin.step``)."""


def _load(truth: Any) -> dict[str, np.ndarray]:
    if isinstance(truth, (str, os.PathLike)):
        with np.load(os.fspath(truth)) as data:
            truth = {k: data[k] for k in data.files}
    if not isinstance(truth, Mapping):
        raise TypeError(f"truth must be a dict of arrays or an .npz file, got {type(truth).__name__}")
    unknown = sorted(set(truth) - set(TRUTH_COLUMNS))
    if unknown:
        raise ValueError(f"truth: unknown column(s) {unknown}; known: {', '.join(TRUTH_COLUMNS)}")
    for name in ("t_s", "q_wb", "omega_b"):
        if name not in truth:
            raise ValueError(f"truth needs the column {name!r}")
    return {k: np.asarray(v, dtype=np.float64) for k, v in truth.items()}


def _tick_s(t: np.ndarray) -> float:
    """The recording's tick: the median step of ``t_s``, snapped to 1/(a whole number of Hz)
    when it is one to 1 ppm (host clocks add 0.001 s to a float: the steps are not exact)."""
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"truth t_s must hold at least two ticks, got shape {t.shape}")
    step = float(np.median(np.diff(t)))
    if not step > 0.0:
        raise ValueError(f"truth t_s must increase, got a median step of {step!r} s")
    rate = round(1.0 / step)
    return 1.0 / rate if rate >= 1 and abs(1.0 / step - rate) <= 1e-6 * rate else step


def replay(truth: Any, estimator: Any = "biso_plus", *, seed: int = 0, tick_s: float | None = None,
           frames: Any = None, label: str | None = None, name: str = "external drive",
           start_end_windows: tuple[tuple[float, float], tuple[float, float]] | None = None,
           **plugin_options: Any) -> "ExternalDrive":
    """Run the plug-in with ``estimator`` over a recorded truth; see the module docstring.

    ``estimator``: a library name or a (name, params) pair; ``tick_s``: the host's tick
    (default: the median step of ``t_s``, as 1/(whole Hz) where it is one; every step must
    equal it); ``plugin_options``: the
    other arguments of ``ImuPlugin`` (``profile``, ``registers``, ``mounting``, ``site``,
    ``speed_from_velocity``, ...).
    """
    from biso_cosim.plugin import ImuPlugin

    columns = _load(truth)
    tick = _tick_s(columns["t_s"]) if tick_s is None else tick_s
    key = label or (estimator if isinstance(estimator, str) else estimator[0])
    plugin = ImuPlugin(tick_s=tick, frames=frames, seed=seed, estimators={key: estimator}, **plugin_options)
    step = {k: v for k, v in columns.items() if k not in ("t_s", "q_wb", "omega_b")}
    output = plugin.step(columns["t_s"], columns["q_wb"], columns["omega_b"], **step)
    return ExternalDrive.from_output(output, key, name=f"{name} (seed {seed})", truth_t_s=columns["t_s"],
                                     p_w=columns.get("p_w"), start_end_windows=start_end_windows)


@dataclass(frozen=True)
class ExternalDrive(DriveResult):
    """One estimator's drive in another simulator: ``run`` is the plug-in's ``PluginOutput``
    of the whole drive, ``key`` the estimator's label; the assertions of ``DriveResult``.

    ``distance_m``: (k,) distance driven at each sample (None without positions);
    ``start_end_windows``: host-time windows ((t0, t1), (t2, t3)) when the vehicle stood
    still at the start and at the end, for ``assert_closure``.
    """

    name: str = "external drive"
    distance_m: np.ndarray | None = field(default=None, repr=False)
    start_end_windows: tuple[tuple[float, float], tuple[float, float]] | None = None

    def __post_init__(self) -> None:
        if self.key not in self.run.estimates:
            raise ValueError(f"the run has no estimator {self.key!r}; it has {sorted(self.run.estimates)}")
        if len(self.run) == 0:
            raise ValueError(f"{self.name}: the drive latched no sensor sample (is the recording too short?)")
        q = self.run.estimates[self.key].estimate.q_wb
        if not np.all(np.isfinite(q)):
            first = int(np.argmax(~np.all(np.isfinite(q), axis=1)))
            raise ValueError(f"{self.name}: the estimate of {self.key} is not finite from t = {self.t_s[first]:.3f} s")

    @classmethod
    def from_output(cls, output: Any, key: str | None = None, *, name: str = "external drive",
                    truth_t_s: Any = None, p_w: Any = None,
                    start_end_windows: tuple[tuple[float, float], tuple[float, float]] | None = None) -> "ExternalDrive":
        """The drive of a ``PluginOutput`` (a live run: ``PluginOutput.concatenate`` of its
        calls); ``key`` the estimator (default the first); ``truth_t_s``/``p_w`` the host's
        tick times and positions (any world axes), for the distance in failure messages."""
        key = next(iter(output.estimates)) if key is None else key
        distance = None
        if p_w is not None:
            t = np.asarray(truth_t_s, dtype=np.float64)
            p = np.asarray(p_w, dtype=np.float64)
            if t.ndim != 1 or p.shape != (t.shape[0], 3):
                raise ValueError(f"truth_t_s (n,) and p_w (n, 3) must go together, got {t.shape} and {p.shape}")
            along = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))
            distance = np.interp(output.t_s, t, along)
        return cls(output, key, name=name, distance_m=distance, start_end_windows=start_end_windows)

    @property
    def t_s(self) -> np.ndarray:
        return self.run.t_s

    @property
    def errors(self) -> dict[str, np.ndarray]:
        """Per-sample errors in degrees: roll, pitch, heading (wrapped) and total."""
        return self.run.estimates[self.key].errors_deg

    @property
    def flags(self) -> np.ndarray:
        return self.run.estimates[self.key].flags

    @property
    def summary(self) -> dict:
        """Error statistics, flagged samples and (with ``start_end_windows``) the start-to-end
        figures, as in the co-simulation's run summary."""
        est = self.run.estimates[self.key]
        entry: dict[str, Any] = {"errors": error_stats(self.errors, self.t_s),
                                 "flagged_samples": int(np.count_nonzero(self.flags))}
        if self.start_end_windows is not None:
            truth = start_end_difference(self.t_s, attitude_angles_deg(est.q_true_wb), *self.start_end_windows)
            estimate = start_end_difference(self.t_s, attitude_angles_deg(est.estimate.q_wb), *self.start_end_windows)
            entry["start_end_deg"] = estimate
            entry["start_end_error_deg"] = {
                a: float(np.degrees(wrap_angle(np.radians(estimate[a] - truth[a])))) for a in ANGLES}
        return entry

    def _name(self) -> str:
        return f"{self.name} with {self.key}"

    def _where(self, index: int) -> str:
        t = float(self.t_s[index])
        if self.distance_m is None:
            return f"t = {t:.2f} s"
        return f"t = {t:.2f} s, about {float(self.distance_m[index]):.0f} m along the drive"

    def assert_completed(self, max_cross_track_m: float = 1.0) -> None:
        """An external drive has no route of ours to complete: refused (check your own
        simulator's progress)."""
        raise AssertionError(f"{self._name()}: assert_completed needs a route of biso_cosim; an external drive "
                             "has none")
