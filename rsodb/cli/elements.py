"""``rsodb elements add FILE [--archive DIR]``: orbital elements for passes already stored."""

from __future__ import annotations

import argparse
import json

from rsodb.cli.archive_options import (
    add_archive_option,
    add_max_age_option,
    fail,
    max_age_days,
    open_archive,
    read_catalogue,
)

__all__ = ["register", "run_add"]

EXAMPLE = """\
example:
  rsodb elements add tles.txt --archive archive
  rsodb elements add celestrak_omm.json --archive archive --norad 51511 --max-age-days 45

FILE is a TLE file (2- or 3-line sets) or OMM records in JSON (a list, as CelesTrak and
Space-Track give them). Each stored pass without elements gets the set of its object whose epoch
is nearest the pass, unless that set is more than --max-age-days (default 30) away; the
catalogue's name, hash, the set's line and epoch and its age are stored with the pass. Elements
from a file's own header are never replaced; with --replace, elements an earlier catalogue gave
are replaced where this one has a nearer set. Each object file is replaced atomically.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "elements",
        help="add orbital elements (TLE or OMM catalogue) to stored passes",
        description="Manage the orbital elements of stored passes.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    add = actions.add_parser(
        "add",
        help="give passes without elements the nearest set of a catalogue",
        description="Give stored passes without orbital elements the nearest set of a TLE/OMM catalogue.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add.add_argument("catalogue", metavar="FILE", help="TLE file or OMM JSON")
    add_archive_option(add)
    add.add_argument("--norad", type=int, help="only this object")
    add_max_age_option(add)
    add.add_argument("--replace", action="store_true", help="also replace elements an earlier catalogue gave")
    add.add_argument("--json", action="store_true", help="print the report as JSON")
    add.set_defaults(func=run_add)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)


def run_add(args: argparse.Namespace) -> int:
    try:
        catalogue = read_catalogue(args.catalogue, "the catalogue")
        archive = open_archive(args)
        report = archive.add_elements(
            catalogue,
            max_age_days=max_age_days(args),
            norad=args.norad,
            replace_catalogue=args.replace,
        )
    except (ValueError, OSError, TimeoutError) as error:
        return fail("elements add", error)
    print(json.dumps(report.to_dict(), indent=1) if args.json else report.summary())
    return 0 if report.ok else 1
