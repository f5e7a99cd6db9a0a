"""NumPy's ziggurat tables, read from the static library NumPy ships in its wheel.

The turn-on errors of the virtual MPU-9250 are drawn with ``numpy.random.default_rng``
(PCG64 and NumPy's ziggurat normal, ``random_standard_normal``). The C model draws them
the same way, so it needs the same three tables (``ki_double``, ``wi_double``,
``fi_double``, 256 entries each). They are not exposed to Python, but the wheel ships the
compiled distributions as ``numpy/random/lib/libnpyrandom.a`` (for C code that links against
them); the tables are its read-only data. This module reads them from that archive (an ``ar``
archive of ELF objects, little-endian, 64-bit) at build time, so the FMU's C data is
NumPy's own numbers, never a copy typed by hand.
"""

from __future__ import annotations

import functools
import struct
from pathlib import Path

import numpy as np

__all__ = ["ziggurat_tables", "library_path"]

_NAMES = {"ki_double": "<u8", "wi_double": "<f8", "fi_double": "<f8"}
_COUNT = 256


def library_path() -> Path:
    """NumPy's ``libnpyrandom.a``."""
    path = Path(np.random.__file__).with_name("lib") / "libnpyrandom.a"
    if not path.is_file():
        raise RuntimeError(f"NumPy's static random library {path} is missing: the native FMUs need NumPy's "
                           "ziggurat tables from it (install numpy from its wheel: pip install numpy)")
    return path


def _members(data: bytes):
    """(name, bytes) of the members of a System V / GNU ``ar`` archive."""
    if not data.startswith(b"!<arch>\n"):
        raise RuntimeError("not an ar archive")
    pos, names = 8, b""
    while pos + 60 <= len(data):
        header = data[pos:pos + 60]
        name, size = header[:16].decode().strip(), int(header[48:58].decode().strip())
        body = data[pos + 60:pos + 60 + size]
        if name == "//":
            names = body
        elif name.startswith("/") and name[1:].isdigit():
            start = int(name[1:])
            yield names[start:names.index(b"/\n", start)].decode(), body
        elif name not in ("/", "/SYM64/"):
            yield name.rstrip("/"), body
        pos += 60 + size + (size & 1)


def _symbols(obj: bytes) -> dict[str, bytes]:
    """The bytes of the wanted data symbols of one ELF64 little-endian relocatable object."""
    if obj[:4] != b"\x7fELF" or obj[4] != 2 or obj[5] != 1:
        return {}
    shoff, = struct.unpack_from("<Q", obj, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", obj, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", obj, shoff + i * shentsize) for i in range(shnum)]
    found = {}
    for sh in sections:
        if sh[1] != 2:  # SHT_SYMTAB
            continue
        strtab = sections[sh[6]]
        for k in range(sh[5] // 24):
            st_name, _, _, st_shndx, st_value, st_size = struct.unpack_from("<IBBHQQ", obj, sh[4] + 24 * k)
            start = strtab[4] + st_name
            name = obj[start:obj.index(b"\0", start)].decode()
            if name in _NAMES and 0 < st_shndx < shnum:
                target = sections[st_shndx]
                offset = target[4] + st_value
                found[name] = obj[offset:offset + st_size]
    return found


@functools.cache
def ziggurat_tables() -> dict[str, np.ndarray]:
    """``{"ki_double": uint64 (256,), "wi_double": float64 (256,), "fi_double": float64 (256,)}``."""
    data = library_path().read_bytes()
    for _, body in _members(data):
        found = _symbols(body)
        if set(found) == set(_NAMES):
            out = {n: np.frombuffer(found[n], dtype=_NAMES[n]).copy() for n in _NAMES}
            if any(a.shape != (_COUNT,) for a in out.values()):
                break
            return out
    raise RuntimeError(f"could not read NumPy's ziggurat tables (ki_double, wi_double, fi_double) from "
                       f"{library_path()}: an ELF64 little-endian archive was expected")
