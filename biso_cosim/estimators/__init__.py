"""Attitude estimators: the faithful BISO of Aleshkin et al. (2024), its baselines, biso_plus
and the GNSS-aided filters of Ibrahim & Lukyanov (2020).

Conventions (the package's): samples in body axes (x forward, y left, z up), gyro in rad/s,
accelerometer = specific force in m/s² (+g up at rest), magnetometer in µT; every estimator
returns ``q_wb`` (w, x, y, z), Hamilton, body → ENU.

>>> est = make_estimator("biso", fs_hz=200.0)          # the paper's k = 44.4, k_p = 25.64
>>> out = est.update(gyro_b, accel_b, mag_b)           # (k, 3) each; call again to continue
>>> out.q_wb, out.flags                                # (k, 4), (k,) bitmask (see ``flags``)
>>> q = estimate_attitude(gyro, accel, mag, 200.0, method="biso", cutoff_hz=5.0)

Streaming: consecutive ``update`` calls continue one stream; any chunking gives the same
result as one call, bit for bit. ``get_state``/``set_state`` copy and restore the whole
state; ``set_params`` retunes without a jump; ``reset(q0=...)`` starts again.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from biso_cosim.estimators import flags
from biso_cosim.estimators._base import Estimate, Estimator, GyroIncrements, LoopArrays, State, param, param_markdown, param_table
from biso_cosim.estimators.biso import BisoEstimator, BisoParams
from biso_cosim.estimators.biso_plus import BisoPlusEstimator, BisoPlusParams
from biso_cosim.estimators.dcm_pi import DcmPiEstimator, DcmPiParams
from biso_cosim.estimators.gnss_aided import GnssComplementaryEstimator, GnssKalmanEstimator
from biso_cosim.estimators.reference import reference_attitude

__all__ = [
    "make_estimator",
    "estimator_names",
    "estimator_inputs",
    "estimator_vehicle_params",
    "estimate_attitude",
    "describe_estimator",
    "params_markdown",
    "reference_attitude",
    "Estimate",
    "Estimator",
    "LoopArrays",
    "GyroIncrements",
    "State",
    "param",
    "BisoParams",
    "BisoEstimator",
    "BisoPlusParams",
    "BisoPlusEstimator",
    "DcmPiParams",
    "DcmPiEstimator",
    "GnssComplementaryEstimator",
    "GnssKalmanEstimator",
    "flags",
]

# name → (class, parameters fixed by the name, one-line description)
_REGISTRY: dict[str, tuple[type, dict[str, Any], str]] = {
    "biso": (BisoEstimator, {},
             "faithful BISO: Poisson equation with cross-linked positional correction "
             "(Aleshkin et al. 2024, reading D)"),
    "positional": (BisoEstimator, {"k_p": 0.0, "cutoff_hz": None},
                   "baseline: positional correction without cross-links (k_p = 0)"),
    "poisson": (BisoEstimator, {"k": 0.0, "k_p": 0.0, "cutoff_hz": None},
                "baseline: uncorrected gyro integration, eq. (2) (accel + mag only initialise)"),
    "dcm_pi": (DcmPiEstimator, {},
               "baseline: DCM with PI drift correction (Premerlani & Bizard 2009, the paper's ref. [8])"),
    "biso_plus": (BisoPlusEstimator, {},
                  "BISO family for vehicles: gyro-bias estimation, acceleration compensation from "
                  "speed, gating, magnetic disturbance detection, unbiased cross-link"),
    "gnss_complementary": (GnssComplementaryEstimator, {},
                           "GNSS-aided attitude without a Kalman filter: tilt from GNSS acceleration, "
                           "magnetic heading (Ibrahim & Lukyanov 2020)"),
    "gnss_kalman": (GnssKalmanEstimator, {},
                    "GNSS-aided attitude, five-state Kalman filter: tilt errors and gyro drifts "
                    "(Ibrahim & Lukyanov 2020)"),
}


def estimator_names() -> tuple[str, ...]:
    """Names accepted by ``make_estimator`` and ``estimate_attitude``."""
    return tuple(_REGISTRY)


def _entry(name: str) -> tuple[type, dict[str, Any], str]:
    if not isinstance(name, str) or name not in _REGISTRY:
        raise ValueError(f"unknown estimator {name!r}; known: {', '.join(_REGISTRY)}")
    return _REGISTRY[name]


def estimator_inputs(name: str) -> tuple[str, ...]:
    """Optional per-sample inputs the estimator ``name`` takes besides gyro, accel and mag
    (e.g. ``("speed_mps",)``)."""
    return tuple(_entry(name)[0].inputs)


def estimator_vehicle_params(name: str) -> tuple[str, ...]:
    """Parameters of the estimator ``name`` that the vehicle it rides on gives when the user
    sets none (``Estimator.vehicle_params``, e.g. ``("speed_point_b_m",)``)."""
    cls, fixed, _ = _entry(name)
    return tuple(p for p in cls.vehicle_params if p not in fixed)


def describe_estimator(name: str) -> dict[str, Any]:
    """``{"name", "summary", "params": rows, "fixed": {...}}`` for docs and CLI help."""
    cls, fixed, summary = _entry(name)
    rows = [r for r in param_table(cls.Params) if r["name"] not in fixed]
    return {"name": name, "summary": summary, "params": rows, "fixed": dict(fixed)}


def make_estimator(name: str, fs_hz: float, **params: Any) -> Estimator:
    """A streaming estimator by name, at sample rate ``fs_hz`` (Hz), with its parameters.

    Unknown names raise ``ValueError`` listing the known ones; unknown or fixed parameter
    names raise ``TypeError``; invalid values (including unstable gains) ``ValueError``.
    """
    cls, fixed, _ = _entry(name)
    clash = sorted(set(params) & set(fixed))
    if clash:
        raise TypeError(f"{name!r} fixes {', '.join(f'{c}={fixed[c]!r}' for c in clash)}; "
                        f"use another estimator to change them")
    known = {r["name"] for r in param_table(cls.Params)}
    unknown = sorted(set(params) - known)
    if unknown:
        raise TypeError(f"{name!r} has no parameter(s) {unknown}; known: {sorted(known - set(fixed))}")
    return cls(fs_hz, cls.Params(**fixed, **params), method=name)


def estimate_attitude(gyro, accel=None, mag=None, fs=None, method: str = "biso", *, registers=None, asa=None,
                      mounting=None, q0=None, full_output: bool = False, **params_and_inputs: Any):
    """Attitude of every sample of a whole recording: ``q_wb`` (N, 4), body → ENU.

    Either SI arrays::

        estimate_attitude(gyro_b, accel_b, mag_b, fs, method="biso", **params)

    or a raw MPU-9250 register log (``sensors.RawSamples``, e.g. ``rawlog.read_raw_csv(path).raw``
    or ``RawSamples.from_bytes`` of a real chip)::

        estimate_attitude(raw, fs=200.0, method="biso_plus", registers={"gyro_fs_sel": 0,
                          "accel_fs_sel": 1}, asa=(176, 177, 165), mounting=q_body_chip)

    Parameters
    ----------
    gyro, accel, mag : (N, 3) arrays in body axes (x forward, y left, z up, right-handed):
        rad/s, m/s² (specific force, +g up at rest), µT. Or ``gyro`` is a ``RawSamples`` and
        ``accel``, ``mag`` are left out: the words are converted with ``registers`` (full
        scales, AK8963 resolution; default the sensor model's), ``asa`` (fuse-ROM bytes;
        default 128: none) and ``mounting`` (chip → body; default identity), the AK8963 axis
        mapping applied, and the sensor flags the words show (saturation, AK8963 overflow,
        no data yet) passed as ``imu_flags`` (``rawlog``).
    fs : sample rate in Hz (required).
    method : an estimator name (``estimator_names()``).
    q0 : optional initial attitude (w, x, y, z) at the first sample; default: from the
        first valid accelerometer + magnetometer sample.
    full_output : return the ``Estimate`` (q_wb, per-sample flags, gyro_bias_b) instead of q_wb.
    **params_and_inputs : the estimator's parameters (``describe_estimator(method)``) and its
        optional per-sample inputs (``estimator_inputs(method)``: ``imu_flags``,
        ``speed_mps``, ...), told apart by name.

    NaN/inf samples follow the estimator's documented policy (flags say what happened);
    the output has no NaN. Wrong shapes raise ``ValueError``; misplaced arguments ``TypeError``.
    """
    from biso_cosim.estimators.rawlog import raw_inputs
    from biso_cosim.sensors import RawSamples

    if fs is None:
        raise TypeError("estimate_attitude needs the sample rate fs (Hz)")
    cls = _entry(method)[0]
    inputs = {k: params_and_inputs.pop(k) for k in list(params_and_inputs) if k in cls.inputs}
    if isinstance(gyro, RawSamples):
        if accel is not None or mag is not None:
            raise TypeError("with a raw log (RawSamples) as first argument, leave accel and mag out")
        conv = raw_inputs(gyro, registers, asa, mounting)
        gyro, accel, mag = conv.gyro_b, conv.accel_b, conv.mag_b
        if "imu_flags" in cls.inputs:
            extra = inputs.get("imu_flags")
            inputs["imu_flags"] = conv.imu_flags if extra is None else conv.imu_flags | np.asarray(extra, dtype=np.int64)
    else:
        given = [name for name, v in (("registers", registers), ("asa", asa), ("mounting", mounting)) if v is not None]
        if given:
            raise TypeError(f"{', '.join(given)} apply to raw logs (RawSamples) only; SI arrays are in body axes")
        if accel is None or mag is None:
            raise TypeError("estimate_attitude needs gyro, accel and mag arrays (or a RawSamples raw log)")
    est = make_estimator(method, fs, **params_and_inputs)
    if q0 is not None:
        est.reset(q0=q0)
    out = est.update(gyro, accel, mag, **inputs)
    return out if full_output else out.q_wb


def params_markdown(name: str) -> str:
    """The parameter table of an estimator in Markdown (docs/estimators.md is generated from it)."""
    cls, fixed, _ = _entry(name)
    table = param_markdown(cls.Params)
    if not fixed:
        return table
    keep = [line for line in table.splitlines() if not any(line.startswith(f"| `{f}` ") for f in fixed)]
    return "\n".join(keep)
