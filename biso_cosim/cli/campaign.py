"""``biso-cosim campaign``: a Monte Carlo campaign on a Dask cluster; statistics and report."""

from __future__ import annotations

import argparse
import sys

from biso_cosim.cli import UserError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "campaign",
        help="Monte Carlo campaign: routes × sensor parts × estimators on a Dask cluster",
        description=(
            "Run every route × sensor set-up × sensor part (seed) of SPEC as one co-simulation with all "
            "the campaign's estimators in the loop, as Dask tasks: on a local cluster of --workers "
            "processes (default: one per core) or on the cluster of --scheduler. Rows (one per run and "
            "estimator) go to OUT/results/ (Parquet) as runs finish; --resume skips those already there. "
            "Prints the error statistics and writes OUT/report.md with its figures. Needs the extra "
            "'campaign' (pip install 'biso_cosim[campaign]'); the spec format is in docs/campaigns.md."
        ),
    )
    p.add_argument("spec", metavar="SPEC.toml", help="the campaign's spec file")
    p.add_argument("--out", required=True, metavar="DIR", help="campaign directory (results, report)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="worker processes of the local Dask cluster (default: one per core)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="an existing Dask cluster's scheduler, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--resume", action="store_true", help="complete the campaign in DIR: skip its finished runs")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for --scheduler to answer (default 10)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=main)


def _import_campaign():
    try:
        import biso_cosim.campaign as campaign
        import biso_cosim.campaign.engine  # noqa: F401  (Dask distributed, pandas)
        import biso_cosim.campaign.store  # noqa: F401  (pyarrow)
    except ImportError as exc:
        raise UserError(f"needs the optional extra 'campaign' (pip install 'biso_cosim[campaign]'): "
                        f"{exc.name or exc} is not installed") from None
    return campaign


def main(args: argparse.Namespace) -> int:
    campaign = _import_campaign()
    from biso_cosim.campaign.report import format_comparisons, format_table, write_report
    from biso_cosim.campaign.store import ResultStore

    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be a positive integer, got {args.workers}")
    if not args.timeout > 0:
        raise UserError(f"--timeout must be a positive number of seconds, got {args.timeout}")
    spec = campaign.load_spec(args.spec)
    canonical = spec.canonical()
    ResultStore(args.out).check(canonical, args.resume)
    runs = spec.runs()
    print(f"campaign {spec.name!r}: {len(runs)} runs ({len(spec.routes)} routes × {len(spec.sensors)} sensor "
          f"set-ups × {spec.parts} parts), {len(spec.estimators)} estimators in the loop of each")
    try:
        with campaign.dask_client(workers=args.workers, scheduler=args.scheduler, timeout_s=args.timeout) as client:
            workers = len(client.scheduler_info(n_workers=-1)["workers"])
            print(f"Dask cluster: {'scheduler ' + args.scheduler if args.scheduler else 'local'}, {workers} workers")
            args.running = True  # from here on an exception is not an input problem (see cli.main)
            frame = campaign.run_campaign(spec, client, out=args.out, resume=args.resume,
                                          progress=not args.no_progress)
    except campaign.CampaignInterrupted as exc:
        print(f"biso-cosim campaign: {exc}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"biso-cosim campaign: interrupted; the runs that finished are in {args.out}, --resume completes "
              f"the campaign", file=sys.stderr)
        return 130
    attrs = frame.attrs
    if attrs["skipped"]:
        print(f"resumed: {attrs['skipped']} runs already in {args.out}, {attrs['ran']} run now")
    warm = attrs["warm_up"]
    if warm:
        print(f"numba: warm-up on {len(warm)} workers took "
              f"{', '.join(str(w['compilations']) for w in warm.values())} compilations "
              f"({max(w['seconds'] or 0.0 for w in warm.values()):.1f} s at most)", end="; ")
        compiled = frame.drop_duplicates("run_id")["numba_compilations"].fillna(0)
        print(f"{int(compiled.sum())} compilations in the campaign's {len(compiled)} tasks")
    stats = campaign.error_statistics(frame, spec.statistics.confidence, spec.statistics.resamples,
                                      spec.statistics.seed)
    paired = campaign.paired_comparisons(frame, spec.statistics.baseline, spec.statistics.confidence,
                                         spec.statistics.resamples, spec.statistics.seed)
    report = write_report(frame, stats, paired, args.out, canonical, wall_s=attrs["wall_s"])
    print(format_table(stats))
    comparisons = format_comparisons(paired)
    if comparisons:
        print(comparisons)
    runs_done = frame.drop_duplicates("run_id")
    counts = runs_done["status"].value_counts()
    print("runs: " + ", ".join(f"{n} {status}" for status, n in counts.items()) + f"; wrote {report}")
    failed = runs_done[runs_done["status"] == "failed"]
    if not failed.empty:
        first = failed.iloc[0]
        print(f"biso-cosim campaign: {len(failed)} of {len(runs_done)} runs failed; the first "
              f"({first['route']}, {first['sensor']}, seed {first['seed']}): {first['error']}", file=sys.stderr)
        return 1
    return 0
