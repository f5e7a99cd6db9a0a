"""The first run says that the numba kernels are compiling (biso_cosim.compiling): numba's own
cache locator tells whether the run's kernels are in its cache."""

from __future__ import annotations

import os
import subprocess
import sys

from biso_cosim.cli import main as cli_main
from biso_cosim.compiling import FIRST_COMPILE_S, compile_notice, kernels_cached


def test_an_empty_cache_gives_the_notice_and_a_filled_one_none(tmp_path):
    code = "from biso_cosim.compiling import compile_notice; print(compile_notice())"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "empty"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.startswith("compiling the numba kernels: once, about") and f"{FIRST_COMPILE_S:.0f} s" in out
    # this process has run the kernels (or loads them from the cache): they are there now
    from biso_cosim.cosim import run_route

    run_route("figure8", duration_s=0.2, estimators=["biso"])
    assert kernels_cached() is True and compile_notice() is None


def test_run_prints_the_notice_before_the_run(tmp_path, capsys, monkeypatch):
    import biso_cosim.compiling as compiling

    monkeypatch.setattr(compiling, "kernels_cached", lambda: False)
    assert cli_main(["run", "--route", "figure8", "--duration", "0.5", "--out", str(tmp_path / "o"),
                     "--no-progress", "--no-log"]) == 0
    assert capsys.readouterr().err.startswith("compiling the numba kernels: once")
