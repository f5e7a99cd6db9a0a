"""The system C compiler: found once, called with the flags that keep the C model's
arithmetic the Python model's (C99, no contraction into fused multiply-adds, no fast math)."""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
from pathlib import Path
from typing import Sequence

__all__ = ["CompilerNotFound", "find_compiler", "compile_shared", "compile_objects", "link_shared", "compile_program",
           "CFLAGS"]

CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math", "-Wall", "-Wextra")
"""The flags of every native build. ``-ffp-contract=off``: numba does not fuse a product and
a sum into one rounding, so the C code must not either (bit for bit)."""

_INSTALL_HINT = ("install one: Debian/Ubuntu `apt-get install gcc`, Fedora `dnf install gcc`, macOS "
                 "`xcode-select --install`, or set CC to a C99 compiler")


class CompilerNotFound(RuntimeError):
    """No C compiler on this machine (the message says what to install)."""


@functools.cache
def find_compiler() -> str:
    """The C compiler: ``$CC`` if set, else the first of cc, gcc, clang on the PATH."""
    cc = os.environ.get("CC")
    if cc:
        path = shutil.which(cc.split()[0])
        if path is None:
            raise CompilerNotFound(f"CC={cc!r} is not an executable on the PATH; {_INSTALL_HINT}")
        return cc
    for name in ("cc", "gcc", "clang"):
        path = shutil.which(name)
        if path:
            return path
    raise CompilerNotFound(f"building the native FMUs needs a C compiler and none was found (cc, gcc, clang); "
                           f"{_INSTALL_HINT}")


def _run(args: list[str]) -> None:
    done = subprocess.run(args, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"C compilation failed ({' '.join(args)}):\n{done.stderr[-4000:]}")


def compile_shared(sources: Sequence[Path], out: Path, include_dirs: Sequence[Path] = (),
                   defines: Sequence[str] = (), hidden: bool = True) -> Path:
    """A shared library from C sources (``-fvisibility=hidden``: only the symbols the sources
    mark exported are visible, as an FMU's binary must)."""
    args = [*find_compiler().split(), *CFLAGS, "-fPIC", "-shared"]
    if hidden:
        args.append("-fvisibility=hidden")
    args += [f"-I{d}" for d in include_dirs] + [f"-D{d}" for d in defines]
    args += [str(s) for s in sources] + ["-o", str(out), "-lm"]
    _run(args)
    return out


def compile_objects(sources: Sequence[Path], out_dir: Path, include_dirs: Sequence[Path] = (),
                    hidden: bool = True, extra: Sequence[str] = ()) -> list[Path]:
    """Object files (position independent) of C sources, one per source, in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    objects = [out_dir / (Path(s).stem + ".o") for s in sources]
    for src, obj in zip(sources, objects):
        args = [*find_compiler().split(), *CFLAGS, "-fPIC", *(["-fvisibility=hidden"] if hidden else []),
                *(f"-I{d}" for d in include_dirs), *extra, "-c", str(src), "-o", str(obj)]
        _run(args)
    return objects


def link_shared(objects: Sequence[Path], out: Path, libraries: Sequence[str] = ("m",),
                extra: Sequence[str] = ()) -> Path:
    """A shared library from object files, linked against ``libraries`` (libm only by default)."""
    _run([*find_compiler().split(), "-shared", *(str(o) for o in objects), "-o", str(out),
          *(f"-l{lib}" for lib in libraries), *extra])
    return out


def compile_program(sources: Sequence[Path], out: Path, include_dirs: Sequence[Path] = (),
                    libraries: Sequence[str] = ("m",), extra: Sequence[str] = ()) -> Path:
    """An executable from C sources."""
    args = [*find_compiler().split(), *CFLAGS, *extra, *(f"-I{d}" for d in include_dirs), *(str(s) for s in sources),
            "-o", str(out), *(f"-l{lib}" for lib in libraries)]
    _run(args)
    return out
