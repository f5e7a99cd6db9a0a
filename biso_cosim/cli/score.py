"""``biso-cosim score``: estimators on real recordings with a reference, BROAD's error measures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    from biso_cosim.score.run import DEFAULT_METHODS

    p = sub.add_parser(
        "score",
        help="score estimators on recordings with a reference (BROAD HDF5, .npz, run logs)",
        description=(
            "Run estimators on every recording of DIR and score them with BROAD's error measures "
            "(Laidig et al. 2021): total, heading and inclination RMSE over the movement samples, per "
            "trial and per group (the mean of the trials' RMSEs). Recordings: BROAD's HDF5 files "
            "(*.hdf5, needs h5py), .npz files with BROAD's keys, a run's log.csv (the truth is the "
            "reference). Writes OUT/score.json and a plot per trial. See docs/score.md."
        ),
    )
    p.add_argument("dir", metavar="DIR", help="folder of recordings (or one recording, or one run's folder)")
    p.add_argument("--method", action="append", default=None, metavar="[LABEL=]NAME[:P=V,...]",
                   help=f"estimator (repeatable; default {' '.join(DEFAULT_METHODS)}): one of ours "
                        "(biso_plus:tau_acc_s=2), vqf, vqf_offline, imufusion (VQF, imufusion need the "
                        "extra 'score'), or your own as module.Factory (called Factory(fs_hz, **params))")
    p.add_argument("--out", default="out/score", metavar="OUT", help="output folder (default out/score)")
    p.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sample rate of recordings that do not carry one (default: from the file)")
    p.add_argument("--no-plots", action="store_true", help="write no plot per trial")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from biso_cosim.score.report import format_table, format_timing
    from biso_cosim.score.run import as_methods, default_methods, score
    from biso_cosim.score.readers import find_recordings

    if not Path(args.dir).exists():
        raise FileNotFoundError(f"DIR: {args.dir!r} does not exist")
    if not find_recordings(args.dir):
        raise ValueError(f"DIR: no recordings found in {args.dir!r} (expected *.hdf5, *.h5, *.npz with BROAD's "
                         "keys, or a run's log.csv)")
    from biso_cosim.output import check_output_dir, check_output_file

    out = check_output_dir(args.out, inputs=[args.dir])  # before any work
    check_output_file(out / "score.json")
    methods = default_methods() if args.method is None else as_methods(args.method)
    result = score(args.dir, methods, out=args.out, fs_hz=args.fs, plots=not args.no_plots,
                   progress=lambda msg: print(f"  {msg}", file=sys.stderr))
    print(format_table(result))
    print(format_timing(result))
    print(f"wrote {Path(args.out) / 'score.json'}" + ("" if args.no_plots else " and a plot per trial"))
    return 0
