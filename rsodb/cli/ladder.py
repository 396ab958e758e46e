"""``rsodb ladder --archive DIR --config LADDER.toml``: fit a ladder of models to passes and choose."""

from __future__ import annotations

import argparse
import json

import rsodb
from rsodb.cli.archive_options import add_archive_option, add_dask_options, fail, open_archive, workers_of

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb ladder --archive archive --config configs/real_passes.toml --ingest ../shared/data/observations
  rsodb ladder --archive archive --config configs/real_passes.toml
  rsodb ladder --archive archive --config configs/real_passes.toml --object 22076 --report ladder.html
  rsodb ladder --archive archive --config configs/real_passes.toml --scheduler tcp://head-node:8786
  rsodb ladder --archive archive --config configs/real_passes.toml --score-only --json

Each rung (shape x attitude family) is fitted on the first part of each pass ([ladder]
train_fraction) and stored as the fit <ladder name>.<shape>-<attitude>; its held-out RMS is
measured on the rest. The simplest rung within the margin of the best held-out RMS is chosen
(docs/real_passes.md). Rungs already stored are not refitted (--restart refits them), so a
stopped ladder continues where it stopped. Without --passes or --object every pass is laddered.
--ingest first stores the given files (or directories) and finds the period of every pass
that has none, so one command goes from files to chosen models.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "ladder",
        help="fit a ladder of shapes and attitude families to passes; choose by held-out RMS",
        description="Fit every rung of a model ladder to the first part of each pass (a Dask campaign), score "
        "each rung by its RMS on the held-out rest, and choose the simplest rung within the margin of the best.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_archive_option(parser)
    parser.add_argument("--config", required=True, metavar="LADDER.toml", help="ladder configuration")
    parser.add_argument("--ingest", nargs="+", metavar="PATH", help="first ingest these files or directories")
    parser.add_argument("--object", type=int, metavar="NORAD", help="only the passes of this object")
    parser.add_argument("--passes", nargs="+", metavar="PASS", help="only these passes (ids or prefixes)")
    add_dask_options(parser)
    parser.add_argument("--in-process", action="store_true", help="fit here, one rung after another, without Dask")
    parser.add_argument("--restart", action="store_true", help="refit rungs that already have a stored fit")
    parser.add_argument("--score-only", action="store_true", help="fit nothing; score the stored rungs")
    parser.add_argument(
        "--median", action="store_true", help="also replay each rung at its posterior median (RMS columns)"
    )
    parser.add_argument(
        "--posterior",
        action="store_true",
        help="also print the chosen rung's posterior table (every period convention)",
    )
    parser.add_argument("--report", metavar="FILE.html", help="write the ladder report here when done")
    parser.add_argument("--json", action="store_true", help="print the ladders as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)


def _ingest(archive, paths, progress: bool) -> None:
    """Store the files and find the period of the objects whose passes have none."""
    report = archive.ingest(paths, progress=progress)
    if report.failed:
        raise ValueError(f"{len(report.failed)} file(s) failed to ingest; run 'rsodb ingest' on them for the reasons")
    missing = sorted(
        {row.norad for row in archive.summaries() if "default" not in archive.result_names(row.pass_id, "periods")}
    )
    for norad in missing:
        rsodb.campaign.survey_periods(archive, norad, progress=progress)


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args, create=bool(args.ingest))
        if args.ingest:
            _ingest(archive, args.ingest, progress=not (args.quiet or args.json))
        plan = rsodb.campaign.LadderPlan.from_toml(args.config)
        workers = workers_of(args)
        if args.passes:
            pass_ids = [archive.get(p).pass_id for p in args.passes]
        else:
            pass_ids = [row.pass_id for row in archive.summaries(args.object)]
        if not pass_ids:
            raise LookupError(f"the archive has no passes{f' of NORAD {args.object}' if args.object else ''}")
        if args.score_only:
            ladders = [rsodb.campaign.score_ladder(archive, p, plan, median=args.median) for p in pass_ids]
        else:
            ladders = rsodb.campaign.run_ladder(
                archive,
                pass_ids,
                plan,
                scheduler=args.scheduler,
                n_workers=workers,
                in_process=args.in_process,
                restart=args.restart,
                progress=not (args.quiet or args.json),
                median=args.median,
            )
        report_path = None
        if args.report:
            report_path = rsodb.report.build_ladder_report(archive, ladders).write(args.report)
    except (ValueError, TypeError, OSError, LookupError) as error:
        return fail("ladder", error)
    if args.json:
        print(
            json.dumps(
                {"ladders": [ladder.to_dict() for ladder in ladders], "report": report_path and str(report_path)},
                indent=1,
            )
        )
    else:
        for ladder in ladders:
            print(ladder.table() + "\n")
            if args.posterior and ladder.chosen:
                fit_name = ladder.score(ladder.chosen).fit_name
                result = archive.load_result(ladder.pass_id, "fits", fit_name, rsodb.FitResult.from_hdf5)
                print(f"posterior of the chosen rung ({fit_name}):\n{result.table()}\n")
        if report_path:
            print(f"wrote {report_path}")
    return 0
