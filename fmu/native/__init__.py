"""The native (C99) FMU path: C sources of the estimators and the MPU-9250, built into FMUs
that need no Python.

The estimators' library lives in ``include/biso_estimators.h`` and ``src/estimators/``;
its constants and parameter tables are generated from the Python estimators
(``python -m biso_cosim.fmu.native.gen``).
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
