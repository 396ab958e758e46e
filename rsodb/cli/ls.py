"""``rsodb ls --archive DIR``: one line per stored pass."""

from __future__ import annotations

import argparse
import json

import numpy as np

from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "format_table"]

EXAMPLE = """\
example:
  rsodb ls --archive archive --norad 22076
  rsodb ls --archive archive --json | python -m json.tool
"""

COLUMNS = ("PASS ID", "NORAD", "NAME", "SITE", "BAND", "START UTC", "DURATION S", "POINTS")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "ls",
        help="list the passes of an archive",
        description="List stored passes, oldest first: id, object, site, band, start, duration, points.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_archive_option(parser)
    parser.add_argument("--norad", type=int, help="only this object")
    parser.add_argument("--band", help="only this band, e.g. V")
    parser.add_argument("--site", help="only this site (name, case-insensitive)")
    parser.add_argument("--all-versions", action="store_true", help="also list versions superseded by a changed file")
    parser.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    parser.set_defaults(func=run)


def format_table(rows: list[tuple[str, ...]]) -> str:
    """Left-aligned text columns under `COLUMNS` (numbers right-aligned)."""
    table = [COLUMNS, *rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(COLUMNS))]
    numeric = {1, 6, 7}
    return "\n".join(
        "  ".join(
            cell.rjust(width) if i in numeric else cell.ljust(width) for i, (cell, width) in enumerate(zip(row, widths))
        ).rstrip()
        for row in table
    )


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        rows = archive.catalog(args.norad, args.band, args.site, all_versions=args.all_versions)
    except (ValueError, OSError) as error:
        return fail("ls", error)
    if args.json:
        print(json.dumps([row.to_dict() for row in rows], indent=1, ensure_ascii=False))
        return 0
    if not rows:
        print(
            f"no passes in {args.archive}" + (" matching the filters" if args.norad or args.band or args.site else "")
        )
        return 0
    print(
        format_table(
            [
                (
                    row.pass_id,
                    str(row.norad),
                    row.name,
                    row.site,
                    row.band,
                    np.datetime_as_string(row.start_utc, unit="s").replace("T", " "),
                    f"{row.duration_s:.1f}",
                    str(row.n_points),
                )
                for row in rows
            ]
        )
    )
    return 0
