"""Named unit constants. SI inside the package; degrees, g and °/s only at the edges."""

from __future__ import annotations

import math

DEG = math.pi / 180.0
"""One degree in radians: ``angle_rad = angle_deg * DEG``."""

G0 = 9.80665
"""Standard gravity in m/s² (the 'g' of datasheet units such as LSB/g and µg/√Hz)."""

MICRO_G = 1e-6 * G0
"""One µg in m/s²."""

MILLI_G = 1e-3 * G0
"""One mg in m/s²."""

DEG_PER_S = DEG
"""One °/s in rad/s."""

DEG_PER_H = DEG / 3600.0
"""One °/h in rad/s."""

GAUSS = 100.0
"""One gauss in µT (the package's unit of magnetic flux density)."""
