"""``rsodb check [--archive DIR] [--repair]``: verify every object file and rebuild the index."""

from __future__ import annotations

import argparse
import json

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run"]

EXAMPLE = """\
example:
  rsodb check --archive archive
  rsodb check --archive archive --repair

Reads every object file: its tables (HDF5 Fletcher32 checksums), every pass (its SHA-256 of
samples, metadata and rows set aside) and every stored result (its SHA-256); rebuilds the catalog
index from the files. With --repair a damaged file is moved to DIR/damaged/ (nothing is edited in
place); restore it from a backup, or ingest its observation files again. Exit status: 0 when every
file is whole, 1 when any is damaged, 2 when the archive could not be used.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "check",
        help="verify every object file (checksums), move damaged ones aside, rebuild the index",
        description="Verify the archive's object files and rebuild its catalog index.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_archive_option(parser)
    parser.add_argument("--repair", action="store_true", help="move damaged object files to DIR/damaged/")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        report = rsodb.archive.check_archive(archive, repair=args.repair, progress=not args.no_progress)
    except (ValueError, OSError, TimeoutError) as error:
        return fail("check", error)
    print(json.dumps(report.to_dict(), indent=1) if args.json else report.summary())
    return 0 if report.ok else 1
