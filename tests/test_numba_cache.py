"""The package's numba caches follow its sources (biso_cosim._numba.purge_stale_caches):
numba keys a cached kernel on its own file, so a kernel that inlines a kernel of another
file would keep the old code when only that file changes."""

import os
import subprocess
import sys
import textwrap

from biso_cosim._numba import purge_stale_caches

CALLER = """
from biso_cosim._numba import jit
from pkg.callee import gain

@jit
def twice_gain(x):
    return 2.0 * gain(x)
"""
CALLEE = """
from biso_cosim._numba import jit

@jit
def gain(x):
    return {factor} * x
"""
RUN = """
import sys
from biso_cosim._numba import purge_stale_caches
if sys.argv[1] == "purge":
    purge_stale_caches([sys.argv[2] + "/pkg"])
sys.path.insert(0, sys.argv[2])
from pkg.caller import twice_gain
print(twice_gain(1.0))
"""


def _write(root, factor):
    pkg = root / "pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    callee = pkg / "callee.py"
    callee.write_text(textwrap.dedent(CALLEE.format(factor=factor)))
    return callee


def _run(root, mode):
    out = subprocess.run([sys.executable, "-c", RUN, mode, str(root)], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def test_a_changed_callee_recompiles_its_callers(tmp_path):
    """numba alone runs the caller's cached code with the old callee inlined; after the
    purge the caller compiles again with the new one."""
    callee = _write(tmp_path, 3.0)
    assert _run(tmp_path, "plain") == 6.0  # compiled and cached
    callee.write_text(CALLEE.format(factor=5.0))
    st = callee.stat()
    os.utime(callee, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # a later edit, whatever the clock
    stale = _run(tmp_path, "plain")
    assert stale == 6.0  # numba's cache of caller.py: the old callee (the trap)
    assert _run(tmp_path, "purge") == 10.0


def test_caches_stay_while_the_sources_do(tmp_path):
    _write(tmp_path, 3.0)
    _run(tmp_path, "purge")  # no stamp yet: purged (nothing there), stamp written, then compiled
    caches = sorted((tmp_path / "pkg" / "__pycache__").glob("*.nb[ic]"))
    assert caches
    assert purge_stale_caches([tmp_path / "pkg"]) == 0
    assert sorted((tmp_path / "pkg" / "__pycache__").glob("*.nb[ic]")) == caches
    (tmp_path / "pkg" / "plain.py").write_text("X = 1\n")  # a module without kernels: caches kept
    assert purge_stale_caches([tmp_path / "pkg"]) == 0
    (tmp_path / "pkg" / "kernels.py").write_text("from biso_cosim._numba import jit\n")  # a new kernel module
    assert purge_stale_caches([tmp_path / "pkg"]) == len(caches)
    assert not list((tmp_path / "pkg" / "__pycache__").glob("*.nb[ic]"))
