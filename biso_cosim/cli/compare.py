"""``biso-cosim compare``: every estimator and its open peers on the same simulated MPU-9250 data."""

from __future__ import annotations

import argparse


def _csv(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def _ints(text: str) -> list[int]:
    try:
        return [int(t) for t in _csv(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds takes integers separated by commas, got {text!r}") from None


def register(sub: argparse._SubParsersAction) -> None:
    from biso_cosim.compare import DEFAULT_METHODS, DEFAULT_MOTIONS

    p = sub.add_parser(
        "compare",
        help="accuracy of biso, the baselines, biso_plus, VQF and imufusion on the same data",
        description=(
            "Drive the routes in the co-simulation and run the test motions through the virtual "
            "MPU-9250, once per seed; run every method on the same samples and print RMS (max) roll, "
            "pitch and heading errors per dataset. Writes OUT/results.json and OUT/table.md. VQF "
            "and imufusion need the optional extra 'compare' (pip install biso_cosim[compare])."
        ),
    )
    p.add_argument("--routes", type=_csv, default=None, metavar="A,B",
                   help="library routes (default: every shipped route; '' for none)")
    p.add_argument("--motions", type=_csv, default=list(DEFAULT_MOTIONS), metavar="A,B",
                   help=f"test motions (default {','.join(DEFAULT_MOTIONS)}; '' for none)")
    p.add_argument("--seeds", type=_ints, default=[0], metavar="0,1", help="sensor seeds (default 0)")
    p.add_argument("--methods", type=_csv, default=list(DEFAULT_METHODS), metavar="A,B",
                   help=f"methods (default all: {','.join(DEFAULT_METHODS)})")
    p.add_argument("--route-duration", type=float, default=None, metavar="S",
                   help="simulated seconds per route (default: the whole route)")
    p.add_argument("--motion-duration", type=float, default=None, metavar="S",
                   help="seconds per test motion (default: the motion's own)")
    p.add_argument("--out", default="out/compare", metavar="DIR",
                   help="output directory (default out/compare); results.json and table.md are rewritten as each "
                        "dataset finishes, so an interrupted comparison keeps the datasets done")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from biso_cosim.compare import compare, format_table, write
    from biso_cosim.output import check_output_dir, check_output_file
    from biso_cosim.routes import route_names

    out = check_output_dir(args.out)
    for name in ("results.json", "table.md"):
        check_output_file(out / name)
    routes = route_names() if args.routes is None else args.routes
    bar = tqdm(total=len(args.seeds) * (len(routes) + len(args.motions)), unit="dataset", desc="compare",
               disable=args.no_progress)

    def started(message: str) -> None:
        bar.set_postfix_str(message)

    def finished(result: dict) -> None:  # each dataset's rows written as it finishes
        write(result, out)
        bar.update(1)

    try:
        result = compare(routes, args.motions, args.seeds, args.methods,
                         route_duration_s=args.route_duration, motion_duration_s=args.motion_duration,
                         progress=started, on_dataset=finished)
    finally:
        bar.close()
    print(format_table(result))
    for method, why in result["config"]["skipped"].items():
        print(f"skipped {method}: {why}")
    paths = write(result, out)
    print(f"wrote {paths['json']} and {paths['table']}")
    return 0
