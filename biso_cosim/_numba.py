"""The one place where numba flags are set for every kernel of the package.

``cache=True`` keeps compiled kernels between processes (the test suite and the CLI start
fast after the first run); ``fastmath`` stays off so that results are reproducible bit for
bit across runs and agree with the slow reference implementations in the tests.
"""

from __future__ import annotations

from numba import njit

__all__ = ["jit"]


def jit(function=None, **options):
    """``numba.njit`` with the project's flags; usable as ``@jit`` or ``@jit(...)``."""
    flags = {"cache": True, "nogil": True, "fastmath": False}
    flags.update(options)
    if function is None:
        return njit(**flags)
    return njit(**flags)(function)
