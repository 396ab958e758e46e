"""``rsodb report KIND ...``: write a self-contained HTML report of the archive's results."""

from __future__ import annotations

import argparse

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "REPORT_KINDS"]

EXAMPLE = """\
example:
  rsodb report periods --archive archive --object 22076 --out topex_periods.html

Run 'rsodb report KIND --help' for the options of one kind.
"""

PERIODS_EXAMPLE = """\
example:
  rsodb periods --archive archive --object 22076
  rsodb report periods --archive archive --object 22076 --out topex_periods.html
"""

CAMPAIGN_EXAMPLE = """\
example:
  rsodb report campaign --archive archive --object 22076 --out topex_fits.html

The fits come from 'rsodb fit' or 'rsodb campaign' (stored under --name, default 'default').
"""


def _common_arguments(parser) -> None:
    add_archive_option(parser)
    parser.add_argument("--object", type=int, required=True, metavar="NORAD", help="the object (NORAD number)")
    parser.add_argument("--out", required=True, metavar="FILE.html", help="HTML file to write")
    parser.add_argument("--band", help="only this band")


def _periods_arguments(parser) -> None:
    parser.add_argument("--name", default="default", help="stored period result name (default: %(default)s)")
    parser.add_argument(
        "--include-ambiguous", action="store_true", help="let 'ambiguous harmonic' periods enter the trend too"
    )
    parser.add_argument("--no-pass-figures", action="store_true", help="skip the per-pass figures")


def _campaign_arguments(parser) -> None:
    parser.add_argument("--name", default="default", help="stored fit name (default: %(default)s)")
    parser.add_argument("--periods-name", default="default", help="stored period results shown beside the fits")
    parser.add_argument("--no-pass-figures", action="store_true", help="skip the per-pass light curves")


def _periods_report(args):
    verdicts = ("confident", "ambiguous harmonic") if args.include_ambiguous else ("confident",)
    return rsodb.report.build_period_report(
        open_archive(args),
        args.object,
        name=args.name,
        band=args.band,
        trend_verdicts=verdicts,
        pass_figures=not args.no_pass_figures,
    )


def _campaign_report(args):
    return rsodb.report.build_campaign_report(
        open_archive(args),
        args.object,
        name=args.name,
        periods_name=args.periods_name,
        band=args.band,
        pass_figures=not args.no_pass_figures,
    )


# Kind -> (description, example, its options, the document it builds).
REPORT_KINDS = {
    "periods": (
        "period survey of one object: trend of the period with time, table, periodogram and folded curve per pass",
        PERIODS_EXAMPLE,
        _periods_arguments,
        _periods_report,
    ),
    "campaign": (
        "spin-state fits of one object: per pass the spin state with intervals and a trust level, the "
        "posterior band over the pass, corner, trace and periodogram; parameters against date",
        CAMPAIGN_EXAMPLE,
        _campaign_arguments,
        _campaign_report,
    ),
}


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "report",
        help="write an HTML report with embedded plots",
        description="Write a self-contained HTML report (plots embedded as PNG) of the archive's results.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    kinds = parser.add_subparsers(dest="kind", metavar="KIND")
    for kind, (description, example, add_arguments, build) in REPORT_KINDS.items():
        sub = kinds.add_parser(
            kind,
            help=description,
            description=description,
            epilog=example,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        _common_arguments(sub)
        add_arguments(sub)
        sub.set_defaults(func=run, report_builder=build)
    parser.set_defaults(func=lambda args: _missing_kind(parser))


def _missing_kind(parser) -> int:
    parser.print_help()
    return 2


def run(args: argparse.Namespace) -> int:
    try:
        document = args.report_builder(args)
        path = document.write(args.out)
    except (ValueError, TypeError, OSError, LookupError) as error:
        return fail(f"report {args.kind}", error)
    print(f"wrote {path}")
    return 0
