"""``rsodb periods --archive DIR``: the spin period of every pass, found in parallel and stored."""

from __future__ import annotations

import argparse
import math
import sys

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb periods --archive archive --object 22076
  rsodb periods --archive archive --json > periods.json
  rsodb periods --archive archive --object 22076 --min-cycles 2 --name relaxed

Each pass gets a period with a 1-sigma error and a verdict: confident, ambiguous harmonic,
aliased, non-periodic, single glint, too short (fewer than 3 cycles in the pass) or no signal
(docs/periods.md). Results are stored in the archive under --name and feed 'rsodb report
periods' and the spin-period prior of fits (confident and ambiguous harmonic only). A pass whose
result under --name was found from the same data, orbital elements and settings is not searched
again (its stored result is shown): after a night's ingest only the new passes are searched.
--force searches every pass.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "periods",
        help="find the spin period of every pass (in parallel) and store it",
        description="Lomb-Scargle, harmonic candidates (P/2 .. 4P) scored by Fourier-series BIC and phase "
        "dispersion, a verdict per pass, and the synodic-to-sidereal correction from the pass "
        "geometry. Results are stored in the archive.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_archive_option(parser)
    parser.add_argument("--object", type=int, metavar="NORAD", help="only this object (NORAD number)")
    parser.add_argument("--band", help="only this band, e.g. V")
    parser.add_argument("--json", action="store_true", help="print the results as JSON instead of a table")
    parser.add_argument(
        "--processes", type=int, metavar="N", help="worker processes (default: all cores, one per 8 passes at most)"
    )
    parser.add_argument("--name", default="default", help="stored result name (default: %(default)s)")
    parser.add_argument("--min-cycles", type=float, metavar="C", help="fewest cycles for a period (default 3)")
    parser.add_argument("--no-store", action="store_true", help="print only; leave the archive unchanged")
    parser.add_argument(
        "--no-geometry", action="store_true", help="skip the pass geometry (no sidereal period, faster)"
    )
    parser.add_argument(
        "--force", action="store_true", help="search passes whose stored result has the same inputs again"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


_COLUMNS = ("pass", "period s", "+- s", "cycles", "verdict", "sidereal s")
_FORMAT = "{:40s} {:>11s} {:>9s} {:>7s}  {:18s} {}"


def _header() -> str:
    return _FORMAT.format(*_COLUMNS).rstrip() + "\n" + "-" * 100


def _row(result) -> str:
    named = math.isfinite(result.best_period_s)
    sidereal = "-"
    if result.synodic is not None:
        low, high = sorted(result.sidereal_bounds_s)
        sidereal = f"{low:.4f}..{high:.4f}"
    return _FORMAT.format(
        result.pass_id,
        f"{result.best_period_s:.4f}" if named else "-",
        f"{result.uncertainty_s:.4f}" if named and math.isfinite(result.uncertainty_s) else "-",
        f"{result.n_cycles:.1f}" if math.isfinite(result.n_cycles) else "-",
        result.verdict,
        sidereal,
    )


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        settings = (
            rsodb.PeriodSettings() if args.min_cycles is None else rsodb.PeriodSettings(min_cycles=args.min_cycles)
        )
        if args.processes is not None and args.processes < 1:
            raise ValueError(f"--processes {args.processes} must be at least 1")
        survey = rsodb.survey_periods(
            archive,
            args.object,
            band=args.band,
            settings=settings,
            name=args.name,
            processes=args.processes,
            progress=not args.quiet and not args.json,
            store=not args.no_store,
            geometry=not args.no_geometry,
            force=args.force,
        )
        damaged = archive.damaged(args.object)
    except (ValueError, TypeError, OSError) as error:
        return fail("periods", error)
    if args.json:
        print(survey.to_json())
    else:
        if not survey.results and not survey.failures:
            print(f"no passes in {args.archive}" + (f" for object {args.object}" if args.object else ""))
        else:
            print(_header())
        for result in survey.results:
            print(_row(result))
        for pass_id, error in survey.failures:
            print(f"{pass_id:40s} failed: {error}")
        searched = len(survey.results) - len(survey.reused)
        if survey.stored_as and searched:
            print(f"stored {searched} result(s) as '{survey.stored_as}'")
        if survey.reused:
            print(
                f"{len(survey.reused)} pass(es) not searched again: their stored result '{args.name}' was found "
                "from the same data and settings (--force searches them)"
            )
    for item in damaged:
        print(
            f"rsodb periods: warning: {item.path} is damaged ({item.reason}); its passes were not searched. "
            f"Run 'rsodb check --archive {args.archive} --repair'",
            file=sys.stderr,
        )
    return 0 if survey.ok and not damaged else 1
