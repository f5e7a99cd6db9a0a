"""``biso-cosim reproduce``: reproduce a source paper's claims into a report."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from biso_cosim.reproduce import PAPERS

    p = sub.add_parser(
        "reproduce",
        help="reproduce a paper's claims: report.md, figures, results.json",
        description="Reproduce the claims of a source paper. Papers: "
                    + "; ".join(f"{k}: {v}" for k, v in PAPERS.items()),
    )
    p.add_argument("paper", choices=sorted(PAPERS), help="which paper")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--quick", action="store_true", help="fewer points and shorter runs (a smoke test)")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from biso_cosim.reproduce import run

    run(args.paper, args.out, quick=args.quick)
    print(f"wrote {args.out}/report.md and {args.out}/results.json")
    return 0
