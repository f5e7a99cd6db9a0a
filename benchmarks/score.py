"""Wall time of ``biso-cosim score`` on a folder of recordings, and the estimators' share.

In one process, after a warm-up pass (numba cache loads, matplotlib's import), three ways on
the same recordings:

* ``estimators``: the methods alone on recordings already in memory (the baseline: what
  scoring cannot avoid);
* ``score --no-plots``: ``biso_cosim.score.score`` reading the files, running the methods,
  computing BROAD's errors, writing ``score.json``;
* ``score``: the same with a plot per trial.

Prints wall and CPU seconds of each and the ratios to the baseline. On a machine shared with
other jobs the wall figures carry their load (the CPU figures much less): the load average
is printed with them. Issue 23's budget: ``score`` on the ten trials of shared/data/broad_dev
within 20 s on 2 cores after compilation.

    python benchmarks/score.py                                  # shared/data/broad_dev
    python benchmarks/score.py DIR --method biso_plus --method vqf
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from biso_cosim.score import score
from biso_cosim.score.readers import read_folder
from biso_cosim.score.run import as_methods, default_methods


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def shared_broad_dev() -> str:
    """shared/data/broad_dev beside the repository, or beside a parent of a work tree."""
    root = Path(__file__).resolve().parents[1]
    return next((str(p / "shared" / "data" / "broad_dev") for p in root.parents
                 if (p / "shared" / "data" / "broad_dev").is_dir()), "broad_dev")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", nargs="?", default=shared_broad_dev())
    ap.add_argument("--method", action="append", default=None)
    args = ap.parse_args()
    methods = default_methods() if args.method is None else as_methods(args.method)
    recordings = list(read_folder(args.dir))
    with tempfile.TemporaryDirectory() as tmp:
        score(recordings[0].path, methods, out=tmp)  # warm-up: cache loads, imports
        _, est_w, est_c = _timed(lambda: [m.run(r) for r in recordings for m in methods])
        _, np_w, np_c = _timed(lambda: score(args.dir, methods, out=tmp, plots=False))
        res, pl_w, pl_c = _timed(lambda: score(args.dir, methods, out=tmp, plots=True))
    load = os.getloadavg()
    print(f"{len(recordings)} recordings, {sum(len(r) for r in recordings)} samples; methods "
          f"{', '.join(m.label for m in methods)}; load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on "
          f"{os.cpu_count()} cores")
    print(f"{'':18} {'wall s':>7} {'CPU s':>7} {'wall / estimators':>18}")
    for name, w, c in (("estimators", est_w, est_c), ("score --no-plots", np_w, np_c), ("score", pl_w, pl_c)):
        print(f"{name:18} {w:7.2f} {c:7.2f} {w / est_w:18.2f}")
    per = ", ".join(f"{k} {v:.2f} s" for k, v in res["timing_s"]["per_method_s"].items())
    print(f"in score: estimators {res['timing_s']['estimators_s']:.2f} s ({per}), reading "
          f"{res['timing_s']['read_s']:.2f} s, plots {res['timing_s']['plots_s']:.2f} s; budget 20 s: "
          f"{'met' if pl_w <= 20 else 'NOT met'}")


if __name__ == "__main__":
    main()
