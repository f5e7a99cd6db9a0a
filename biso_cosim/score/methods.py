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
import os
import sys
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from biso_cosim import peers
from biso_cosim.estimators import estimator_names, make_estimator

__all__ = ["Method", "PEERS", "method_names", "make_method", "peer_available"]

PEERS = ("vqf", "vqf_offline", "imufusion")

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


def _run_ours(name: str, params: dict, rec) -> np.ndarray:
    est = make_estimator(name, rec.fs_hz, **{"declination_rad": rec.declination_rad, **params})
    return est.update(rec.gyro_b, rec.accel_b, rec.mag_b).q_wb


def _peer(run: Callable[..., np.ndarray]) -> Callable[[dict, Any], np.ndarray]:
    def on_recording(params: dict, rec) -> np.ndarray:
        return run(rec.gyro_b, rec.accel_b, rec.mag_b, rec.fs_hz, rec.declination_rad, **params)
    return on_recording


_PEER_RUN = {name: _peer(getattr(peers, name)) for name in ("vqf", "vqf_offline", "imufusion")}


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
            unknown = sorted(set(params) - set(peers.IMUFUSION_DEFAULTS))
            if unknown:
                raise ValueError(f"--method imufusion: no parameter(s) {unknown}; known: {sorted(peers.IMUFUSION_DEFAULTS)}")
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
