"""The attitude estimators ``score`` runs: ours, the open peers, and a user's own.

A method turns one :class:`~biso_cosim.score.readers.Recording` into ``q_wb`` (N, 4), sensor
axes → ENU, true north (the reference's north: magnetic for BROAD, true for a run log).

* **ours**: every name of ``biso_cosim.estimators.estimator_names()`` with its parameters
  (``biso_plus:tau_acc_s=2``; docs/estimators.md), made for the recording's sample rate and
  given its declination; no speed or GNSS input, the attitude from gyro, accelerometer and
  magnetometer alone.
* **peers** (extra ``score`` or ``compare``): ``vqf`` (``vqf.VQF.updateBatch``, the causal
  filter; parameters are VQF's, e.g. ``vqf:tauAcc=2``), ``vqf_offline`` (``vqf.offlineVQF``,
  which looks ahead: not comparable with a real-time filter) and ``imufusion`` (x-io Fusion
  with the settings of ``biso-cosim compare``: gain 0.5, rejection 10°/10°, recovery 5 s,
  gyro offset corrector; parameters ``gain``, ``acceleration_rejection``,
  ``magnetic_rejection``, ``recovery_trigger_period_s``, ``gyroscope_range`` override them).
  Peers are referenced to magnetic north and turned to true north by the declination.
* **a user's own**: ``module.Factory`` (a dotted import path; the current folder is searched
  first), called per recording as ``Factory(fs_hz, **params)``; what it returns has the
  estimator API of the loop (:class:`biso_cosim.cosim.CoSimulation`): ``update(gyro_b,
  accel_b, mag_b)`` returning the (k, 4) ``q_wb`` or an object with ``q_wb``. From Python, the
  factory itself, or an instance (its ``reset()`` is called before each recording).
"""

from __future__ import annotations

import importlib
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from biso_cosim.estimators import estimator_names, make_estimator
from biso_cosim.frames import quat_from_euler, quat_multiply

__all__ = ["Method", "PEERS", "method_names", "make_method", "peer_available"]

PEERS = ("vqf", "vqf_offline", "imufusion")

_IMUFUSION_DEFAULTS = {"gain": 0.5, "acceleration_rejection": 10.0, "magnetic_rejection": 10.0,
                       "recovery_trigger_period_s": 5.0, "gyroscope_range": 2000.0}


def method_names() -> tuple[str, ...]:
    """Registry names and peers (a user's ``module.Factory`` comes on top)."""
    return tuple(estimator_names()) + PEERS


def peer_available(name: str) -> bool:
    module = "vqf" if name.startswith("vqf") else name
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def _magnetic_to_true(q_mag: np.ndarray, declination_rad: float) -> np.ndarray:
    """Attitude relative to magnetic north → true north (the world turned by −D about Up)."""
    if declination_rad == 0.0:
        return q_mag
    qz = quat_from_euler(0.0, 0.0, -declination_rad)
    return quat_multiply(np.broadcast_to(qz, q_mag.shape).copy(), q_mag)


def _c64(*arrays: np.ndarray) -> list[np.ndarray]:
    return [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]


def _run_ours(name: str, params: dict, rec) -> np.ndarray:
    est = make_estimator(name, rec.fs_hz, **{"declination_rad": rec.declination_rad, **params})
    return est.update(rec.gyro_b, rec.accel_b, rec.mag_b).q_wb


def _run_vqf(params: dict, rec) -> np.ndarray:
    import vqf

    est = vqf.VQF(1.0 / rec.fs_hz, **params)
    out = est.updateBatch(*_c64(rec.gyro_b, rec.accel_b, rec.mag_b))
    return _magnetic_to_true(out["quat9D"], rec.declination_rad)


def _run_vqf_offline(params: dict, rec) -> np.ndarray:
    import vqf

    out = vqf.offlineVQF(*_c64(rec.gyro_b, rec.accel_b, rec.mag_b), 1.0 / rec.fs_hz, dict(params) or None)
    return _magnetic_to_true(out["quat9D"], rec.declination_rad)


def _run_imufusion(params: dict, rec) -> np.ndarray:
    import imufusion

    p = {**_IMUFUSION_DEFAULTS, **params}
    fs = rec.fs_hz
    settings = imufusion.AhrsSettings()
    settings.convention = imufusion.CONVENTION_ENU
    settings.gain = float(p["gain"])
    settings.gyroscope_range = float(p["gyroscope_range"])
    settings.acceleration_rejection = float(p["acceleration_rejection"])
    settings.magnetic_rejection = float(p["magnetic_rejection"])
    settings.rejection_timeout = int(p["recovery_trigger_period_s"] * fs)
    settings.sample_rate = fs
    ahrs = imufusion.Ahrs()
    ahrs.set_settings(settings)
    ahrs.set_sample_period(1.0 / fs)
    bias_settings = imufusion.BiasSettings()
    bias_settings.sample_rate = fs
    offset = imufusion.Bias()
    offset.set_settings(bias_settings)
    gyro_deg = np.degrees(rec.gyro_b)
    accel_g = rec.accel_b / 9.80665
    mag = np.ascontiguousarray(rec.mag_b, dtype=np.float64)
    out = np.empty((len(rec), 4))
    update, get_q, correct = ahrs.update, ahrs.get_quaternion, offset.update
    for i in range(len(rec)):  # imufusion's Python API has no batch call
        update(correct(gyro_deg[i]), accel_g[i], mag[i])
        out[i] = get_q()
    return _magnetic_to_true(out, rec.declination_rad)


_PEER_RUN = {"vqf": _run_vqf, "vqf_offline": _run_vqf_offline, "imufusion": _run_imufusion}


def _as_q(out: Any, k: int, label: str) -> np.ndarray:
    q = out if isinstance(out, np.ndarray) else getattr(out, "q_wb", out)
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (k, 4):
        raise ValueError(f"method {label!r}: update() returned shape {q.shape}, expected ({k}, 4) q_wb")
    return q


@dataclass
class Method:
    """One method to score: ``run(recording) → q_wb``; ``kind`` is ours, peer or user."""

    label: str
    name: str
    kind: str
    params: dict = field(default_factory=dict)
    factory: Callable[..., Any] | None = None
    instance: Any = None

    def run(self, rec) -> np.ndarray:
        if self.kind == "ours":
            return _run_ours(self.name, self.params, rec)
        if self.kind == "peer":
            return _PEER_RUN[self.name](self.params, rec)
        est = self.instance
        if est is None:
            est = self.factory(rec.fs_hz, **self.params)
            if not callable(getattr(est, "update", None)):
                raise ValueError(f"method {self.label!r}: {self.name}(fs_hz) must return an estimator with "
                                 f"update(gyro_b, accel_b, mag_b), got {type(est).__name__}")
        elif callable(getattr(est, "reset", None)):
            est.reset()
        return _as_q(est.update(rec.gyro_b, rec.accel_b, rec.mag_b), len(rec), self.label)

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "params": {k: repr(v) if not isinstance(v, (int, float, str, bool))
                                                                 else v for k, v in self.params.items()}}


def _import_factory(path: str, label: str) -> Callable[..., Any]:
    module_name, _, attr = path.rpartition(".")
    cwd = os.getcwd()
    if cwd not in sys.path:
        sys.path.insert(0, cwd)
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"--method {label!r}: cannot import {module_name!r} ({exc})") from None
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise ValueError(f"--method {label!r}: {module_name!r} has no callable {attr!r}")
    return factory


def make_method(name: str, params: dict | None = None, label: str = "") -> Method:
    """A method by name (ours, a peer, or ``module.Factory``), its parameters checked now."""
    params = dict(params or {})
    label = label or name
    if name in estimator_names():
        make_estimator(name, 100.0, **params)  # unknown or bad parameters raise here, before any work
        return Method(label, name, "ours", params)
    if name in PEERS:
        if not peer_available(name):
            raise ValueError(f"--method {name}: the peer is not installed (pip install 'biso_cosim[score]')")
        if name == "imufusion":
            unknown = sorted(set(params) - set(_IMUFUSION_DEFAULTS))
            if unknown:
                raise ValueError(f"--method imufusion: no parameter(s) {unknown}; known: {sorted(_IMUFUSION_DEFAULTS)}")
        elif name == "vqf" and params:
            import vqf

            try:
                vqf.VQF(0.01, **params)
            except (TypeError, ValueError, AttributeError) as exc:
                raise ValueError(f"--method {label}: bad VQF parameter(s) {params} ({exc})") from None
        return Method(label, name, "peer", params)
    if "." in name and all(part.isidentifier() for part in name.split(".")):
        return Method(label, name, "user", params, factory=_import_factory(name, label))
    raise ValueError(f"--method: unknown method {name!r}; known: {', '.join(method_names())}, "
                     f"or your own as module.Factory")


def user_method(obj: Any, label: str | None = None, params: dict | None = None) -> Method:
    """A method from a user's estimator instance (``update`` method) or factory (``factory(fs_hz)``)."""
    if not isinstance(obj, type) and callable(getattr(obj, "update", None)):
        return Method(label or getattr(obj, "name", None) or type(obj).__name__, type(obj).__name__, "user",
                      dict(params or {}), instance=obj)
    if callable(obj):
        return Method(label or getattr(obj, "__name__", "user"), getattr(obj, "__name__", "user"), "user",
                      dict(params or {}), factory=obj)
    raise ValueError(f"methods: expected a name, an estimator with update(gyro_b, accel_b, mag_b) or a factory "
                     f"factory(fs_hz), got {obj!r}")
