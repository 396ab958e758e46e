"""``rsodb pipeline DATA_DIR --archive DIR --out REPORTS_DIR``: the main job, end to end.

The job itself is `rsodb.pipeline.run_pipeline`; this module parses the arguments and prints
where the reports are.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import sys

import rsodb
from rsodb.cli.archive_options import add_archive_option, archive_location, fail, workers_of

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb pipeline data_samples --archive archive --out reports
  rsodb pipeline /data/observations --archive archive --out reports --fit-config fit.toml
  rsodb pipeline data_samples --archive archive --out reports --no-fit

Every step can be rerun: files already in the archive are skipped, periods are recomputed,
and passes that already have the fit (same --fit-name) are skipped. The short fit is a first
look (few walkers and steps; it says when its chain has not converged); run 'rsodb fit' or
'rsodb campaign' with the full settings for results to publish.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "pipeline",
        help="ingest a directory, find periods, fit every pass, write the reports",
        description="The whole workflow on a directory of observation files: ingest into the archive, spin "
        "period of every pass, a short MCMC spin-state fit of every pass on a Dask LocalCluster, "
        "and HTML reports (periods and fits per object, and an index).",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("data_dir", metavar="DATA_DIR", help="directory (or file) of observation files")
    add_archive_option(parser)
    parser.add_argument("--out", required=True, metavar="REPORTS_DIR", help="where the HTML reports go")
    parser.add_argument("--fit-config", metavar="FIT.toml", help="fit configuration instead of the short first look")
    parser.add_argument("--fit-name", help="stored fit name (default: 'quick', or the configuration's)")
    parser.add_argument("--workers", type=int, metavar="N", help="parallel workers (default: one per core)")
    parser.add_argument("--no-fit", action="store_true", help="ingest, periods and period reports only")
    parser.add_argument("--json", action="store_true", help="print a JSON summary instead of text")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    quiet = args.quiet or args.json
    try:
        workers = workers_of(args)
        config = rsodb.fit.FitConfig.from_toml(args.fit_config) if args.fit_config else None
        summary = rsodb.pipeline.run_pipeline(
            args.data_dir,
            archive_location(args)[0],
            args.out,
            fit_config=config,
            fit_name=args.fit_name,
            workers=workers,
            fit=not args.no_fit,
            progress=not quiet,
            log=(lambda line: print(line, file=sys.stderr)) if args.json else print,
        )
    except (ValueError, TypeError, OSError, LookupError) as error:
        return fail("pipeline", error)
    if args.json:
        print(json.dumps(summary, indent=1, default=str))
    else:
        print(f"done in {summary['elapsed_s']:.0f} s. Reports in {Path(args.out).resolve()}:")
        for path in summary["reports"]:
            print(f"  {Path(path).resolve()}")
        print(f"open {Path(summary['index']).resolve()} to start")
    return 0
