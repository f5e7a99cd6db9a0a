"""An optional mount vibration spectrum: resonant modes of the sensor's mounting.

The vehicle's own vibration reaches the sensor through the physics (the truth arrays). A
flexible mount or bracket adds narrow-band motion the rigid-body model does not have;
`MountVibration` describes it as a sum of lightly damped modes, each a second-order
resonator driven by white noise, with a given RMS of specific force and angular rate per
body axis. The model adds it to the truth before the chip sees it, so it also reaches the
g-sensitivity and the nonlinearity (vibration rectification) and aliases through the
decimation, like on a real chip.

Discretisation at the step h: ``y_n = a1·y_{n-1} + a2·y_{n-2} + g·w_n``,
``a1 = 2r·cos(ω_d h)``, ``a2 = −r²``, ``r = exp(−ζ ω0 h)``, ``ω_d = ω0·√(1 − ζ²)``; the
stationary variance of the AR(2) with unit drive is (1 − a2)/((1 + a2)((1 − a2)² − a1²)),
so ``g`` = RMS / √variance.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

__all__ = ["VibrationMode", "MountVibration"]

MAX_MODES = 8


@dataclasses.dataclass(frozen=True)
class VibrationMode:
    """One mount resonance.

    Attributes:
        frequency_hz: natural frequency f0 (Hz), below the Nyquist frequency of the model's
            base rate.
        damping: damping ratio ζ in (0, 1).
        accel_rms: RMS specific force per body axis (m/s²), number or 3 values.
        gyro_rms: RMS angular rate per body axis (rad/s), number or 3 values.
    """

    frequency_hz: float
    damping: float = 0.05
    accel_rms: float | Sequence[float] = 0.0
    gyro_rms: float | Sequence[float] = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.frequency_hz) and self.frequency_hz > 0):
            raise ValueError(f"VibrationMode.frequency_hz must be positive, got {self.frequency_hz}")
        if not 0.0 < self.damping < 1.0:
            raise ValueError(f"VibrationMode.damping must be in (0, 1), got {self.damping}")
        for name in ("accel_rms", "gyro_rms"):
            v = np.broadcast_to(np.asarray(getattr(self, name), dtype=np.float64), (3,))
            if not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError(f"VibrationMode.{name} must be >= 0 (one number or 3), got {getattr(self, name)!r}")

    def coefficients(self, rate_hz: float) -> tuple[float, float, np.ndarray]:
        """(a1, a2, gains (6,) for accel xyz then gyro xyz) at ``rate_hz``."""
        if self.frequency_hz >= 0.5 * rate_hz:
            raise ValueError(f"vibration mode at {self.frequency_hz:g} Hz is above the Nyquist frequency of {rate_hz:g} Hz")
        h = 1.0 / rate_hz
        w0 = 2.0 * math.pi * self.frequency_hz
        r = math.exp(-self.damping * w0 * h)
        a1 = 2.0 * r * math.cos(w0 * math.sqrt(1.0 - self.damping**2) * h)
        a2 = -r * r
        var = (1.0 - a2) / ((1.0 + a2) * ((1.0 - a2) ** 2 - a1**2))
        rms = np.concatenate([np.broadcast_to(np.asarray(self.accel_rms, float), (3,)), np.broadcast_to(np.asarray(self.gyro_rms, float), (3,))])
        return a1, a2, rms / math.sqrt(var)


@dataclasses.dataclass(frozen=True)
class MountVibration:
    """A mount vibration spectrum: up to 8 `VibrationMode` s."""

    modes: Sequence[VibrationMode] = ()

    def __post_init__(self) -> None:
        if len(self.modes) > MAX_MODES:
            raise ValueError(f"MountVibration takes at most {MAX_MODES} modes, got {len(self.modes)}")
        for m in self.modes:
            if not isinstance(m, VibrationMode):
                raise TypeError(f"MountVibration.modes must be VibrationMode objects, got {type(m).__name__}")
