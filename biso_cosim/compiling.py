"""Whether the numba kernels are compiled already, so that the CLI can say so on a first run.

The kernels are compiled on their first call and kept in numba's cache (``cache=True``,
``biso_cosim._numba``); a process that finds them there loads them in a second or two, one
that does not spends ``FIRST_COMPILE_S`` compiling before the progress bar moves.
``kernels_cached`` asks numba's own cache locator for the index files of the main kernels
of a run: the vehicle's control period, the MPU-9250 and BISO.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["kernels_cached", "compile_notice", "FIRST_COMPILE_S"]

FIRST_COMPILE_S = 100.0
"""About how long the first ``biso-cosim run`` compiles its kernels on 2 cores (measured:
``NUMBA_CACHE_DIR=$(mktemp -d) biso-cosim run --route figure8 --duration 2 --no-progress``
took 110 s of wall time on 2 cores shared with other work (load 4); the issue's user saw
about 40 s on a machine to itself)."""


def kernels_cached() -> bool | None:
    """True if the period kernel is in numba's cache, False if not, None if numba's cache
    cannot be asked (a numba whose internals differ)."""
    from biso_cosim.estimators.biso import _biso_batch
    from biso_cosim.sensors._kernels import _simulate
    from biso_cosim.vehicle._kernels import _drive_period

    try:
        indexes = [Path(kernel._cache._cache_file._index_path) for kernel in (_drive_period, _simulate, _biso_batch)]
    except AttributeError:
        return None
    return all(index.is_file() for index in indexes)


def compile_notice() -> str | None:
    """The line to print before a run whose kernels will compile, or None."""
    if kernels_cached() is not False:
        return None
    return (f"compiling the numba kernels: once, about 40-{FIRST_COMPILE_S:.0f} s on 2 cores, before the progress bar "
            "moves (later runs load them from numba's cache)")
