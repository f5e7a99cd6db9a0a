"""Where the C sources of the native FMUs are, and the generated files that join them."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

__all__ = ["NATIVE", "INCLUDE", "SENSOR_DIR", "SENSOR_SOURCES", "write_sensor_data"]

NATIVE = Path(__file__).resolve().parent
INCLUDE = NATIVE / "include"
SENSOR_DIR = NATIVE / "src" / "sensor"
SENSOR_SOURCES = (SENSOR_DIR / "rng.c", SENSOR_DIR / "mpu9250.c", SENSOR_DIR / "wmm.c")


def write_sensor_data(folder: Path, extra_profiles: Sequence = ()) -> Path:
    """Write the generated ``biso_sensor_data.c`` into ``folder``."""
    from biso_cosim.fmu.native.constants import sensor_data_c

    path = Path(folder) / "biso_sensor_data.c"
    path.write_text(sensor_data_c(extra_profiles), "utf-8")
    return path
