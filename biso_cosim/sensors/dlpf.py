"""Digital filters that reproduce the MPU-9250 DLPF table entries (bandwidth and delay).

The register map gives, for each DLPF setting, a -3 dB bandwidth and a delay. Subtracting
the delay of a first-order low-pass with that bandwidth from the table delay leaves a
nearly constant 2 ms (gyro) or 1.2 ms (accelerometer) at 1 kHz for every setting, which
points to a first-order low-pass behind a fixed pipeline delay. We build exactly that, at
the entry's internal rate ``fs``:

    H(z) = LP(z) · A(z) · z^-n

* ``LP(z) = (1 - a) / (1 - a z^-1)``: first-order low-pass whose |H| is 1/√2 exactly at the
  table bandwidth: ``a = (2 - c) - √((2 - c)² - 1)``, ``c = cos(2π f_bw / fs)``;
  its DC group delay is ``a / (1 - a)`` samples;
* ``A(z) = (d + z^-1) / (1 + d z^-1)``: first-order Thiran all-pass, DC group delay ``D``
  (``d = (1 - D) / (1 + D)``), magnitude 1 at every frequency;
* ``z^-n``: whole-sample delay;

with ``n + D`` the rest of the table delay (``D`` in [0.5, 1.5) where possible). So the
magnitude response is the low-pass alone (-3 dB exactly at the table bandwidth) and the
group delay at low frequency is exactly the table delay. Every gyro and accelerometer
entry leaves a positive rest (tested). The temperature sensor's table delays at 5 and 10 Hz
are below a first-order low-pass's, so for it only the bandwidth is matched (``n = 0``,
no all-pass) and entries at or above Nyquist pass unfiltered.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["FilterDesign", "design_dlpf", "frequency_response", "filter_reference"]


@dataclasses.dataclass(frozen=True)
class FilterDesign:
    """Coefficients of LP · all-pass · delay at the internal rate ``rate_hz``.

    ``lowpass_a = 0`` and ``allpass_d = 1`` with ``delay_samples = 0`` is the identity.
    """

    rate_hz: float
    lowpass_a: float
    allpass_d: float
    delay_samples: int
    bandwidth_hz: float
    delay_s: float

    @property
    def group_delay_s(self) -> float:
        """DC group delay of the design in seconds."""
        a, d = self.lowpass_a, self.allpass_d
        allpass_delay = (1.0 - d) / (1.0 + d)
        return (a / (1.0 - a) + allpass_delay + self.delay_samples) / self.rate_hz


IDENTITY = FilterDesign(1.0, 0.0, 1.0, 0, math.inf, 0.0)


def _lowpass_coefficient(bandwidth_hz: float, rate_hz: float) -> float:
    if bandwidth_hz >= 0.5 * rate_hz:
        return 0.0
    c = math.cos(2.0 * math.pi * bandwidth_hz / rate_hz)
    return (2.0 - c) - math.sqrt((2.0 - c) ** 2 - 1.0)


def design_dlpf(bandwidth_hz: float, delay_s: float, rate_hz: float, match_delay: bool = True) -> FilterDesign:
    """Design the filter of one DLPF table entry (see the module docstring).

    With ``match_delay=False`` only the bandwidth is matched (temperature sensor).
    Raises ValueError if the table delay is shorter than the low-pass's own delay.
    """
    a = _lowpass_coefficient(bandwidth_hz, rate_hz)
    if not match_delay:
        return FilterDesign(rate_hz, a, 1.0, 0, bandwidth_hz, delay_s)
    rest = delay_s * rate_hz - a / (1.0 - a)
    if rest < 0.0:
        raise ValueError(
            f"DLPF entry {bandwidth_hz} Hz / {delay_s * 1e3} ms at {rate_hz} Hz: the delay is shorter "
            "than a first-order low-pass's"
        )
    n = max(0, math.ceil(rest - 1.5))
    frac = rest - n
    d = (1.0 - frac) / (1.0 + frac)
    return FilterDesign(rate_hz, a, d, n, bandwidth_hz, delay_s)


def frequency_response(design: FilterDesign, f_hz) -> np.ndarray:
    """Complex response H(e^{jω}) of the design at frequencies ``f_hz``."""
    z1 = np.exp(-2j * np.pi * np.asarray(f_hz, dtype=np.float64) / design.rate_hz)
    a, d = design.lowpass_a, design.allpass_d
    return (1.0 - a) / (1.0 - a * z1) * (d + z1) / (1.0 + d * z1) * z1**design.delay_samples


def filter_reference(design: FilterDesign, x: np.ndarray) -> np.ndarray:
    """Slow plain-Python filtering of a 1-D signal, started in steady state at ``x[0]``.

    The twin of the numba kernel, for the tests.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.empty_like(x)
    lp = ap_x = ap_y = x[0]
    line = [x[0]] * design.delay_samples
    for i, v in enumerate(x):
        lp = design.lowpass_a * lp + (1.0 - design.lowpass_a) * v
        ap = design.allpass_d * lp + ap_x - design.allpass_d * ap_y
        ap_x, ap_y = lp, ap
        if line:
            line.append(ap)
            ap = line.pop(0)
        y[i] = ap
    return y
