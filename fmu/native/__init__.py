"""The native (C99) FMUs: C sources of the virtual MPU-9250, the estimators and the FMI
shells, the data generated for them from the Python package, and their build.

``include/`` holds the public headers (the sensor ``biso_sensor.h``, the Earth field
``biso_field.h``, the estimators' ``biso_estimators.h`` and the FMI 2.0 / 3.0 headers);
``src/sensor`` the virtual MPU-9250, its random generators and the WMM; ``src/estimators``
the estimators' library; ``src/fmi`` the FMU models and their FMI 2.0 and FMI 3.0 shells.
Every constant the C code shares with the Python model is generated at build time from the
Python package (``constants.py`` for the sensor, ``gen.py`` for the estimators,
``model_description.py`` for the variables), never written twice.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["NATIVE_DIR", "INCLUDE_DIR", "C_FLAGS", "estimator_sources", "estimator_headers"]

NATIVE_DIR = Path(__file__).resolve().parent
INCLUDE_DIR = NATIVE_DIR / "include"

C_FLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math")
"""Compiler flags of the same numbers as numba: no fused multiply-add, IEEE semantics."""


def estimator_sources() -> list[Path]:
    """The C files of the estimators' library (compile them all, with ``-I INCLUDE_DIR``)."""
    return sorted((NATIVE_DIR / "src" / "estimators").glob("*.c"))


def estimator_headers() -> list[Path]:
    """The headers the estimators' sources include (public ones in INCLUDE_DIR)."""
    return sorted(INCLUDE_DIR.glob("biso_estimators*.h")) + sorted((NATIVE_DIR / "src" / "estimators").glob("*.h"))
