"""The ``--archive DIR`` option, the Dask options and error reporting shared by the commands.

Without ``--archive`` a command uses ``$RSODB_ARCHIVE`` when it is set, else ``./archive``.
"""

from __future__ import annotations

import argparse
import os
import sys

import ingest
import rsodb

__all__ = [
    "add_archive_option",
    "add_max_age_option",
    "add_dask_options",
    "workers_of",
    "max_age_days",
    "read_catalogue",
    "open_archive",
    "archive_location",
    "fail",
    "ARCHIVE_ENV",
    "DEFAULT_ARCHIVE",
]

ARCHIVE_ENV = "RSODB_ARCHIVE"
DEFAULT_ARCHIVE = "archive"


def add_dask_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--scheduler ADDRESS`` and ``--workers N``, the Dask cluster of a campaign of fits."""
    parser.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address (default: a LocalCluster)")
    parser.add_argument("--workers", type=int, metavar="N", help="LocalCluster workers (default: one per core)")


def workers_of(args: argparse.Namespace) -> int | None:
    """``--workers``, checked: None (one per core) or a count of at least 1."""
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers {args.workers} must be at least 1")
    return args.workers


def add_archive_option(parser: argparse.ArgumentParser) -> None:
    """Add the ``--archive DIR`` option (default: ``$RSODB_ARCHIVE``, else ``./archive``)."""
    parser.add_argument(
        "--archive",
        default=None,
        metavar="DIR",
        help=f"archive directory (default: ${ARCHIVE_ENV} if set, else ./{DEFAULT_ARCHIVE}; "
        "created by 'rsodb ingest' when missing)",
    )


def add_max_age_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--max-age-days D``: the oldest element set a catalogue may give a pass."""
    parser.add_argument(
        "--max-age-days",
        type=float,
        default=None,
        metavar="D",
        help="oldest element set given to a pass, days between its epoch and the pass (default: 30)",
    )


def max_age_days(args: argparse.Namespace) -> float:
    """``--max-age-days``, or the library's default (`ingest.elements.DEFAULT_MAX_AGE_DAYS`)."""
    return ingest.DEFAULT_MAX_AGE_DAYS if args.max_age_days is None else args.max_age_days


def read_catalogue(path: str, what: str):
    """The element catalogue in `path` (`ingest.ElementCatalogue`); a file that cannot be read is a
    one-line error naming `what` gave it (an option or argument) and the file."""
    try:
        return ingest.ElementCatalogue.from_file(path)
    except OSError as exc:
        raise ValueError(f"{what} {path}: cannot read the element catalogue ({exc.strerror or exc})") from None


def archive_location(args: argparse.Namespace) -> tuple[str, str]:
    """The archive directory the command uses, and where that choice came from."""
    if getattr(args, "archive", None):
        return args.archive, "--archive"
    if os.environ.get(ARCHIVE_ENV):
        return os.environ[ARCHIVE_ENV], f"${ARCHIVE_ENV}"
    return DEFAULT_ARCHIVE, "the default"


def open_archive(args: argparse.Namespace, create: bool = False):
    """Open the archive (``args.archive`` is set to the directory used).

    Raises
    ------
    ValueError
        One sentence when it is not usable; a missing default archive says how to choose one.
    """
    path, source = archive_location(args)
    args.archive = path
    try:
        return rsodb.Archive(path, create=create)
    except ValueError as error:
        if source == "--archive":
            raise
        raise ValueError(
            f"{error} (the archive directory {path!r} comes from {source}; give --archive DIR or set {ARCHIVE_ENV})"
        ) from None


def fail(command: str, error: Exception, status: int = 2) -> int:
    """Print ``rsodb COMMAND: error: MESSAGE`` on stderr and return `status`."""
    message = error.args[0] if isinstance(error, LookupError) and error.args else str(error)
    print(f"rsodb {command}: error: {message}", file=sys.stderr)
    return status
