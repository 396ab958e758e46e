"""``rsodb export PASS --archive DIR [--format csv|eossa]``: a pass as CSV or EOSSA FITS."""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

import ingest
import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "FORMATS"]

EXAMPLE = """\
example:
  rsodb export 22076-20240730T212240 --archive archive --format csv --out topex.csv
  rsodb export 22076-20240730T212240 --archive archive --format eossa --out topex.fits

csv: a '# key = value' header (object, band, exposure, site, conventions, elements) and one row
per sample: time_utc (ISO 8601, UTC mid-exposure), mag_file (as the file wrote it),
mag_corrected (only when the file had the extinction sign error: the magnitude to use), mag_err,
flux, flux_err, az_deg, el_deg, range_km, saturated, valid; written to standard output without
--out. 'rsodb ingest' reads it back (as a duplicate source of the pass it came from).
eossa: the SSA community's FITS photometry exchange format, v3.1.1; --out defaults to
PASS_ID.eossa.fits in the current directory.
"""

FORMATS = ("csv", "eossa")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write one pass as CSV or EOSSA FITS",
        description="Export one stored pass to a file other tools read.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("pass_id", metavar="PASS", help="pass id (or a unique prefix)")
    add_archive_option(parser)
    parser.add_argument("--format", default="csv", choices=FORMATS, help="output format (default: %(default)s)")
    parser.add_argument("--out", metavar="FILE", help="output file (csv: default standard output)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing output file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        stored = open_archive(args).get(args.pass_id)
        if args.format == "csv":
            notes = {"pass_id": stored.pass_id}
            if args.out is None:
                ingest.write_csv(stored, sys.stdout, notes)
                return 0
            out = _free_path(args.out, args.force)
            ingest.write_csv(stored, out, notes)
        else:
            out = _free_path(args.out or f"{stored.pass_id}.eossa.fits", args.force)
            rsodb.write_eossa(stored, out, overwrite=args.force)
    except (ValueError, LookupError, OSError) as error:
        return fail("export", error)
    print(f"wrote {out} ({len(stored)} samples of {stored.pass_id})", file=sys.stderr)
    return 0


def _free_path(out: str, force: bool) -> Path:
    path = Path(out)
    if path.exists() and not force:
        raise FileExistsError(f"{out} exists; choose another --out or add --force")
    return path
