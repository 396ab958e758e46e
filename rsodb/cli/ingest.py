"""``rsodb ingest PATH... --archive DIR``: store observation files in an archive."""

from __future__ import annotations

import argparse
import json

from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run"]

EXAMPLE = """\
example:
  rsodb ingest ~/observations/2025-01 night.phV --archive archive

Directories are walked recursively for *.ph<letter> files (ccd_phot .phV/.phR/..., photometer
.phc); files named explicitly are read whatever their name. A file already in the archive (same
SHA-256) is skipped; a changed file for a stored pass becomes a new version of it. A bad file is
reported as FILE:LINE: REASON and does not stop the others. Exit status: 0 when every file was
ingested or already present, 1 when any failed, 2 when the archive could not be used.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "ingest",
        help="store observation files (and directories of them) in an archive",
        description="Read observation files and store their passes in a crash-safe HDF5 archive.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("paths", nargs="+", metavar="PATH", help="observation files or directories")
    add_archive_option(parser)
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="reader processes (default: one per CPU for large batches; 0: none)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args, create=True)
        report = archive.ingest(args.paths, progress=not args.no_progress, workers=args.workers)
    except (ValueError, OSError, TimeoutError) as error:
        return fail("ingest", error)
    print(json.dumps(report.to_dict(), indent=1) if args.json else report.summary())
    return 0 if report.ok else 1
