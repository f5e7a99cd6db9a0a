"""Output files and directories: checked before any work, every file written whole or not at all.

The package's one helper for outputs (the CLI's commands, route files, campaign stores).
``check_output_dir`` refuses, in one line naming the option, an output directory that is an
existing file, holds or is one of the command's inputs, or cannot be written in (probed).
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

__all__ = ["check_output_file", "check_output_dir", "atomic_output", "write_text_atomic"]


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
    _probe(ancestor, option, out)
    return out


def _probe(directory: Path, option: str, shown: Path) -> None:
    try:  # the one sure test (permissions, read-only file systems, special directories)
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=directory)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"{option} {str(shown)!r}: cannot write in {str(directory)!r} "
                         f"({exc.strerror or exc})") from None


def check_output_dir(path: str | Path, *, option: str = "--out", inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a Path if it is, or can be made as, a directory to write files in, else
    ValueError naming ``option``. Nothing is created (the writers make it). An input given
    as the directory, or lying in it under a name the command writes, is the caller's to
    refuse with ``check_output_file`` on each output file."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option} {str(out)!r} is an existing file; expected a directory")
    for given in inputs:
        source = Path(given)
        if _same_file(out, source) or out.resolve() == source.resolve():
            raise ValueError(f"{option} {str(out)!r} is the input {str(source)!r}; give another directory")
    ancestor = out
    while not ancestor.exists():  # directories still to be made
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValueError(f"{option} {str(out)!r}: {str(ancestor)!r} is a file, not a directory")
    _probe(ancestor, option, out)
    return out


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` whole or not at all (``atomic_output``)."""
    with atomic_output(path) as temporary:
        temporary.write_text(text)
    return Path(path)


@contextmanager
def atomic_output(path: str | Path, *, keep_suffix: bool = True) -> Iterator[Path]:
    """A temporary file beside ``path`` (its parent directories made) to write to; renamed over
    ``path`` when the block ends, removed if it raises. The temporary name ends in the
    output's suffix (for writers that choose the format by it), or with ``keep_suffix=False``
    in ``.tmp`` (for directories whose readers glob the suffix)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    suffix = f".tmp{out.suffix}" if keep_suffix else f"{out.suffix}.tmp"
    fd, name = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=suffix, dir=out.parent)
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
