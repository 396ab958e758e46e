"""``rsodb report KIND ...``: write a self-contained HTML report (kinds from `rsodb.report.REPORT_KINDS`)."""
from __future__ import annotations

import argparse

__all__ = ["register", "run"]

EXAMPLE = """\
example:
  rsodb report periods --archive archive --object 22076 --out topex_periods.html

Run 'rsodb report KIND --help' for the options of one kind.
"""


def register(subparsers) -> None:
    from rsodb.report import REPORT_KINDS, report_module

    parser = subparsers.add_parser(
        "report", help="write an HTML report with embedded plots",
        description="Write a self-contained HTML report (plots embedded as PNG) of the archive's results.",
        epilog=EXAMPLE, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    kinds = parser.add_subparsers(dest="kind", metavar="KIND")
    for kind in REPORT_KINDS:
        module = report_module(kind)
        sub = kinds.add_parser(kind, help=module.DESCRIPTION, description=module.DESCRIPTION,
                               epilog=module.EXAMPLE, formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(sub)
        sub.set_defaults(func=run, report_builder=module.build_from_args)
    parser.set_defaults(func=lambda args: _missing_kind(parser))


def _missing_kind(parser) -> int:
    parser.print_help()
    return 2


def run(args: argparse.Namespace) -> int:
    from rsodb.cli.archive_options import fail

    try:
        document = args.report_builder(args)
        path = document.write(args.out)
    except (ValueError, TypeError, OSError, LookupError) as error:
        return fail(f"report {args.kind}", error)
    print(f"wrote {path}")
    return 0
