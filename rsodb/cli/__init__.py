"""The `rsodb` command line: a thin dispatcher over the library.

Each sub-command lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func(args) -> int``.
Tests call ``main([...])`` directly.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

__all__ = ["main", "COMMAND_MODULES"]

# Order here is the order in `rsodb --help`.
COMMAND_MODULES = [
    "ingest",
    "ls",
    "show",
    "export",
    "check",
    "elements",
    "periods",
    "render",
    "report",
    "fit",
    "fit_joint",
    "campaign",
    "ladder",
    "pipeline",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rsodb",
        description="Light curves of resident space objects: archive, periods, rendering, spin fits.",
        epilog="Run 'rsodb COMMAND --help' for a command's options and an example.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in COMMAND_MODULES:
        importlib.import_module(f"rsodb.cli.{module_name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse `argv` (default: sys.argv[1:]) and run the command; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        status = int(args.func(args) or 0)
        sys.stdout.flush()
        return status
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output stopped early (``rsodb ls | head``): not an error of ours.
        # Point stdout at /dev/null so that the interpreter's final flush cannot fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a command that a closed pipe stopped


if __name__ == "__main__":
    sys.exit(main())
