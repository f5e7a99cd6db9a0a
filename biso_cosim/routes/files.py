"""Output files of the route tools: checked before any work, written whole or not at all.

``check_output_file`` refuses, in one line naming the option, an output that could not be
written or would destroy something: an existing directory, one of the command's inputs, a
read-only file, or a place where no file can be made (tried with a probe file, which also
catches read-only file systems). ``atomic_output`` gives a temporary
name in the same directory to write to and renames it over the output only when the writing
succeeded (``os.replace`` is atomic on one file system), so that a reader never sees half a
file and an interrupted write leaves the old file as it was.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["check_output_file", "atomic_output"]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output_file(path: str | Path, *, option: str = "--out", suffixes: tuple[str, ...] = (),
                      inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a Path if a file can be written there, else ValueError naming ``option``."""
    out = Path(path)
    if out.is_dir():
        raise ValueError(f"{option} {str(out)!r} is a directory; expected a file name")
    for given in inputs:
        source = Path(given)
        if _same_file(out, source) or out.resolve() == source.resolve():
            raise ValueError(f"{option} {str(out)!r} is the input {str(source)!r}; give another file name "
                             "(the input is never overwritten)")
    if suffixes and out.suffix.lower() not in suffixes:
        raise ValueError(f"{option} {str(out)!r}: expected a {' or '.join(suffixes)} file")
    if out.exists() and not os.access(out, os.W_OK):
        raise ValueError(f"{option} {str(out)!r} exists and is read-only")
    parent = out.parent if str(out.parent) else Path(".")
    ancestor = parent
    while not ancestor.exists():  # directories still to be made
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValueError(f"{option} {str(out)!r}: {str(ancestor)!r} is a file, not a directory")
    try:  # the one sure test (permissions, read-only file systems, special directories)
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=ancestor)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"{option} {str(out)!r}: cannot write in {str(ancestor)!r} "
                         f"({exc.strerror or exc})") from None
    return out


@contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """A temporary file beside ``path`` (its parent directories made) to write to; renamed over
    ``path`` when the block ends, removed if it raises."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=f".tmp{out.suffix}", dir=out.parent)
    os.close(fd)
    temporary = Path(name)
    try:
        yield temporary
        # the permissions a plain open() would give (mkstemp makes the file private)
        if out.exists():
            mode = out.stat().st_mode & 0o777
        else:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask
        os.chmod(temporary, mode)
        os.replace(temporary, out)
    finally:
        temporary.unlink(missing_ok=True)
