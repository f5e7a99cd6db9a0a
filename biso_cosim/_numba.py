"""The one place where numba flags are set for every kernel of the package.

``cache=True`` keeps compiled kernels between processes (the test suite and the CLI start
fast after the first run); ``fastmath`` stays off so that results are reproducible bit for
bit across runs and agree with the slow reference implementations in the tests.

numba keys a cached kernel on its own source file only: a kernel that calls (and inlines)
a kernel of another file keeps its old machine code when only that other file changes, as
after a ``git pull`` or a branch switch in a source tree, and runs the old physics without a
word. So on first import the package compares a fingerprint of its kernels' sources (path,
size, modification time of every file that imports this module) with the one its caches were
made with, and where they differ
deletes its numba cache files (``*.nbi``, ``*.nbc`` in its ``__pycache__`` folders) before
any kernel loads: the kernels compile again, once. An installed copy whose files do not
change keeps its caches.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from numba import njit

__all__ = ["jit", "source_roots", "purge_stale_caches"]

_STAMP = "numba_sources.stamp"


def jit(function=None, **options):
    """``numba.njit`` with the project's flags; usable as ``@jit`` or ``@jit(...)``."""
    flags = {"cache": True, "nogil": True, "fastmath": False}
    flags.update(options)
    if function is None:
        return njit(**flags)
    return njit(**flags)(function)


def source_roots() -> list[Path]:
    """The folders holding the package's kernels: the package, and in a source tree the
    ``envs`` and ``fmu`` folders beside it (``biso_cosim._source_tree``)."""
    package = Path(__file__).resolve().parent
    roots = [package]
    for sibling in ("envs", "fmu"):
        folder = package.parent / sibling
        if (folder / "__init__.py").is_file() and not (package / sibling).exists():
            roots.append(folder)
    return roots


def _fingerprint(roots: list[Path]) -> str:
    """Path, size and modification time of every source that defines kernels (imports this
    module): a kernel can inline only kernels, so an edit elsewhere keeps the caches."""
    digest = hashlib.sha256()
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            if "_numba import" not in path.read_text(encoding="utf-8", errors="replace"):
                continue
            st = path.stat()
            digest.update(f"{path.relative_to(root.parent)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return digest.hexdigest()


def purge_stale_caches(roots: list[Path] | None = None) -> int:
    """Delete the numba cache files under ``roots`` (default ``source_roots()``) if their
    sources changed since the caches were made; the number of files deleted. A folder that
    cannot be written is left as it is (numba then caches elsewhere, or not at all)."""
    roots = source_roots() if roots is None else [Path(r) for r in roots]
    stamp = roots[0] / "__pycache__" / _STAMP
    fingerprint = _fingerprint(roots)
    try:
        if stamp.read_text() == fingerprint:
            return 0
    except OSError:
        pass
    deleted = 0
    for root in roots:
        for cache in root.rglob("__pycache__"):
            for path in (*cache.glob("*.nbi"), *cache.glob("*.nbc")):
                try:
                    path.unlink()
                    deleted += 1
                except OSError:
                    pass
    try:
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_suffix(f".{os.getpid()}")
        tmp.write_text(fingerprint)
        tmp.replace(stamp)  # atomic: a process starting meanwhile reads the old stamp or the new
    except OSError:
        pass
    return deleted


purge_stale_caches()
