"""``rsodb ls [--archive DIR]``: one line per stored pass, streamed from the catalog index."""

from __future__ import annotations

import argparse
import itertools
import json
import sys

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run", "format_row", "COLUMNS"]

EXAMPLE = """\
example:
  rsodb ls --archive archive --norad 22076
  rsodb ls --archive archive --periods --period-min 5 --period-max 20 --verdict confident
  rsodb ls --archive archive --band V --since 2025-01-01 --json | python -m json.tool

Survey filters (--period-min, --period-max, --verdict) use the period results stored by
'rsodb periods' under --periods-name (default 'default'); passes without one are left out when
a period filter is given. Objects whose files are damaged are named on stderr (exit status 1);
their passes are not listed until 'rsodb check --repair' moves the files aside.
"""

COLUMNS = ("PASS ID", "NORAD", "NAME", "SITE", "BAND", "START UTC", "DURATION S", "POINTS")
PERIOD_COLUMNS = ("PERIOD S", "+-", "VERDICT")
_NUMERIC = {"NORAD", "DURATION S", "POINTS", "PERIOD S", "+-"}
# Rows read before the column widths are fixed; later rows stream through with those widths.
_WIDTH_SAMPLE = 1000


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "ls",
        help="list the passes of an archive (with survey filters)",
        description="List stored passes, oldest first: id, object, site, band, start, duration, points "
        "(and with --periods the stored spin period and its verdict).",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_archive_option(parser)
    parser.add_argument("--norad", type=int, help="only this object")
    parser.add_argument("--band", help="only this band, e.g. V")
    parser.add_argument("--site", help="only this site (name, case-insensitive)")
    parser.add_argument(
        "--since", metavar="UTC", help="only passes starting at or after this time (2025-01-30[T17:00])"
    )
    parser.add_argument("--until", metavar="UTC", help="only passes starting before this time")
    parser.add_argument("--period-min", type=float, metavar="S", help="only passes whose stored period is >= S seconds")
    parser.add_argument("--period-max", type=float, metavar="S", help="only passes whose stored period is <= S seconds")
    parser.add_argument("--verdict", help="only passes whose stored period has this verdict (e.g. confident)")
    parser.add_argument("--periods", action="store_true", help="show the stored period, its error and verdict")
    parser.add_argument(
        "--periods-name",
        default="default",
        metavar="NAME",
        help="period result to show and filter on (default: %(default)s)",
    )
    parser.add_argument("--all-versions", action="store_true", help="also list versions superseded by a changed file")
    parser.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    parser.set_defaults(func=run)


def _cells(row, with_periods: bool) -> tuple[str, ...]:
    start = rsodb.archive.utc_text(row.start_utc, "s").replace("T", " ")
    cells = (
        row.pass_id,
        str(row.norad),
        row.name,
        row.site,
        row.band,
        start,
        f"{row.duration_s:.1f}",
        str(row.n_points),
    )
    if with_periods:
        cells += (
            "-" if row.period_s is None else f"{row.period_s:.4f}",
            "-" if row.period_err_s is None else f"{row.period_err_s:.4f}",
            row.verdict or "-",
        )
    return cells


def format_row(cells: tuple[str, ...], widths: list[int], header: tuple[str, ...]) -> str:
    """One table line: text left-aligned, numbers right-aligned, in `widths`."""
    return "  ".join(
        cell.rjust(width) if name in _NUMERIC else cell.ljust(width) for cell, width, name in zip(cells, widths, header)
    ).rstrip()


def run(args: argparse.Namespace) -> int:
    periods = args.periods or args.period_min is not None or args.period_max is not None or args.verdict is not None
    try:
        archive = open_archive(args)
        rows = archive.iter_summaries(
            args.norad,
            args.band,
            args.site,
            all_versions=args.all_versions,
            since=args.since,
            until=args.until,
            period_min=args.period_min,
            period_max=args.period_max,
            verdict=args.verdict,
            periods_name=args.periods_name,
        )
        damaged = archive.damaged(args.norad)
    except (ValueError, TypeError, OSError) as error:
        return fail("ls", error)
    count = _print_json(rows) if args.json else _print_table(rows, periods)
    if not count and not args.json:
        filtered = any(
            value is not None
            for value in (args.norad, args.band, args.site, args.since, args.until, args.period_min, args.period_max)
        )
        print(f"no passes in {args.archive}" + (" matching the filters" if filtered or args.verdict else ""))
    for item in damaged:
        print(
            f"rsodb ls: warning: {item.path} is damaged ({item.reason}); its passes are not listed. "
            f"Run 'rsodb check --archive {args.archive} --repair'",
            file=sys.stderr,
        )
    return 1 if damaged else 0


def _print_table(rows, with_periods: bool) -> int:
    header = COLUMNS + (PERIOD_COLUMNS if with_periods else ())
    first = [_cells(row, with_periods) for row in itertools.islice(rows, _WIDTH_SAMPLE)]
    if not first:
        return 0
    widths = [max(len(cells[i]) for cells in [header, *first]) for i in range(len(header))]
    print(format_row(header, widths, header))
    for cells in first:
        print(format_row(cells, widths, header))
    count = len(first)
    for row in rows:
        print(format_row(_cells(row, with_periods), widths, header))
        count += 1
    return count


def _print_json(rows) -> int:
    """A JSON list written one pass at a time, so the first pass appears at once."""
    count = 0
    sys.stdout.write("[")
    for row in rows:
        sys.stdout.write(("," if count else "") + "\n " + json.dumps(row.to_dict(), ensure_ascii=False))
        count += 1
    sys.stdout.write("\n]\n" if count else "]\n")
    return count
