"""``rsodb campaign --archive DIR --object N``: fit every pass of an object in parallel on Dask."""

from __future__ import annotations

import argparse
import json

import rsodb
from rsodb.cli.archive_options import add_archive_option, add_dask_options, fail, open_archive, workers_of
from rsodb.cli.fit import add_fit_options, config_from_args

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb campaign --archive archive --object 22076
  rsodb campaign --archive archive --object 22076 --config configs/short.toml --report topex_fits.html
  rsodb campaign --archive archive --object 40358 --model cosmos.obj --materials cosmos.materials.json --spin-axis x
  rsodb campaign --archive archive --passes 22076-20240730T212240 22076-20240802T203011
  rsodb campaign --archive /shared/archive --object 22076 --scheduler tcp://head-node:8786

By default the passes are fitted on a Dask LocalCluster with one single-threaded worker per
core. With --scheduler the tasks go to a running Dask cluster; the archive directory must then
be visible to every worker at the same path. Passes that already have a fit of this name are
skipped, so a rerun only does what is left; --restart refits them all. A mesh's shape cache is
built by the first task and read by the others from the archive (shapes/).
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "campaign",
        help="fit every pass of an object in parallel on Dask and report the fits",
        description="Fit many passes on Dask distributed (a LocalCluster by default, or --scheduler ADDRESS); "
        "each fit is stored in the archive as it finishes; an HTML report shows the parameters "
        "against date and the fitted spin period beside the periodogram periods.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_archive_option(parser)
    parser.add_argument("--object", type=int, metavar="NORAD", help="fit every pass of this object")
    parser.add_argument("--passes", nargs="+", metavar="PASS", help="fit only these passes (ids or prefixes)")
    parser.add_argument("--band", help="only passes in this band")
    add_fit_options(parser)
    add_dask_options(parser)
    parser.add_argument("--restart", action="store_true", help="refit passes that already have this fit")
    parser.add_argument("--report", metavar="FILE.html", help="write the campaign report here when done")
    parser.add_argument("--json", action="store_true", help="print the outcome as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        config = config_from_args(args)
        workers = workers_of(args)
        outcome = rsodb.campaign.run_campaign(
            archive,
            args.object,
            pass_ids=args.passes,
            band=args.band,
            config=config,
            scheduler=args.scheduler,
            n_workers=workers,
            restart=args.restart,
            progress=not (args.quiet or args.json),
        )
        report_path = None
        if args.report:
            norads = sorted({archive.get(p).norad for p in (args.passes or [])}) if args.passes else [args.object]
            report_path = rsodb.report.build_campaign_report(archive, norads[0], name=config.name).write(args.report)
    except (ValueError, TypeError, OSError, LookupError) as error:
        return fail("campaign", error)
    if args.json:
        print(json.dumps(dict(outcome.to_dict(), report=str(report_path) if report_path else None), indent=1))
    else:
        for record in outcome.fitted:
            period = record["parameters"].get("spin_period_s")
            text = (
                f"P = {period['median']:.4f} (-{period['median'] - period['p16']:.4f} +{period['p84'] - period['median']:.4f}) s"
                if period
                else ""
            )
            print(f"{record['pass_id']:40s} {text:36s} {'converged' if record['converged'] else 'NOT converged'}")
        for pass_id, error in outcome.failed:
            print(f"{pass_id:40s} not fitted: {error}")
        print(outcome.summary())
        if report_path:
            print(f"wrote {report_path}")
    return 0 if outcome.ok else 1
