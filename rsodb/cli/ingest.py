"""``rsodb ingest PATH... [--archive DIR]``: store observation files in an archive."""

from __future__ import annotations

import argparse
import json
import sys

import rsodb
from rsodb.cli.archive_options import (
    add_archive_option,
    add_max_age_option,
    fail,
    max_age_days,
    open_archive,
    read_catalogue,
)

__all__ = ["register", "run"]

EXAMPLE = """\
example:
  rsodb ingest ~/observations/2025-01 night.phV --archive archive
  rsodb ingest 51511_250130_1719.phc --tle tles.txt --archive archive
  rsodb ingest other_tool.csv --archive archive

Directories are walked recursively for *.ph<letter> files (ccd_phot .phV/.phR/..., photometer
.phc); files named explicitly are read whatever their name, CSV light curves included (rsodb's
own export, or a table of time_utc, mag, mag_err under '# object', '# band', '# exposure_s' and
'# site' lines: see docs/formats.md). A file already in the archive (same SHA-256) is skipped; a
file whose rows are all in a stored pass is recorded as a duplicate source; a changed file for a
stored pass becomes a new version of it. Damaged rows are set aside and listed as warnings
(FILE:LINE: REASON); a file is refused only when more than 10% of its rows are damaged, and a bad
file does not stop the others. --tle gives passes whose files carry no orbital elements the set
of their object nearest the pass (refused beyond --max-age-days, default 30).
Exit status: 0 when every file was ingested or already present, 1 when any failed, 2 when the
archive could not be used.
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
        "--tle",
        metavar="FILE",
        help="TLE file or OMM JSON: orbital elements for passes whose files carry none",
    )
    add_max_age_option(parser)
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="reader processes (default: one per CPU for large batches; 0: none; at most the CPU count)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        workers = _workers(args.workers)
        catalogue = read_catalogue(args.tle, "--tle") if args.tle else None
        archive = open_archive(args, create=True)
        report = archive.ingest(
            args.paths,
            progress=not args.no_progress,
            workers=workers,
            elements=catalogue,
            max_age_days=max_age_days(args),
        )
    except (ValueError, OSError, TimeoutError) as error:
        return fail("ingest", error)
    print(json.dumps(report.to_dict(), indent=1) if args.json else report.summary())
    return 0 if report.ok else 1


def _workers(requested: int | None) -> int | None:
    """The reader processes to use: more than one per usable core and one are not started (a note
    says so)."""
    if requested is None:
        return None
    if requested < 0:
        raise ValueError(f"--workers {requested} must be 0 or more (0 reads in this process)")
    limit = rsodb.pool.ingest_readers()
    if requested > limit:
        print(
            f"rsodb ingest: note: --workers {requested} is more than the {limit - 1} usable CPUs can use; "
            f"using {limit}",
            file=sys.stderr,
        )
        return limit
    return requested
