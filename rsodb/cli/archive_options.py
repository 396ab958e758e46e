"""The ``--archive DIR`` option and error reporting shared by the archive commands."""

from __future__ import annotations

import argparse
import sys

import rsodb

__all__ = ["add_archive_option", "open_archive", "fail"]


def add_archive_option(parser: argparse.ArgumentParser) -> None:
    """Add the required ``--archive DIR`` option."""
    parser.add_argument(
        "--archive", required=True, metavar="DIR", help="archive directory (created by 'rsodb ingest' when missing)"
    )


def open_archive(args: argparse.Namespace, create: bool = False):
    """Open ``args.archive`` (raises ValueError with a one-sentence message when it is not usable)."""
    return rsodb.Archive(args.archive, create=create)


def fail(command: str, error: Exception, status: int = 2) -> int:
    """Print ``rsodb COMMAND: error: MESSAGE`` on stderr and return `status`."""
    message = error.args[0] if isinstance(error, LookupError) and error.args else str(error)
    print(f"rsodb {command}: error: {message}", file=sys.stderr)
    return status
