"""``rsodb fit-joint PASS PASS ... --archive DIR``: several passes of one object in one fit."""

from __future__ import annotations

import argparse
import json

from rsodb.cli.archive_options import add_archive_option, fail, open_archive
from rsodb.cli.fit import add_fit_options, add_sampler_options, config_from_args

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb fit-joint 51511-20250130T171941-V 51511-20250311 --archive archive \\
      --config configs/joint_cosmos2553.toml --plot figures/joint_cosmos2553.png
  rsodb fit-joint 22076-20240730T212240 22076-20240730T212740 --archive archive --no-trend --json

The passes share the spin pole (inertial attitude) or the cone angle and precession period
(precessing), and the shape's parameters; each pass has its own spin phase, precession phase,
jitter and magnitude offset; the spin period follows a linear trend from the first pass's
epoch (--no-trend: one period), and every pass's implied period must lie inside its own
stored-period prior. The chain is kept in the archive's joint/ directory: the same command
continues it; --restart discards it. See docs/fitting.md ("Joint fits").
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "fit-joint",
        help="fit several passes of one object under one spin state (shared pole, period trend)",
        description="Fit two or more stored passes of one object jointly: shared pole and shape, per-pass phases "
        "and jitter, a linear trend of the spin period across the passes.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "pass_ids", metavar="PASS", nargs="+", help="pass ids (unique prefixes); the first sets the epoch"
    )
    add_archive_option(parser)
    add_fit_options(parser)
    add_sampler_options(parser)
    parser.add_argument("--no-trend", action="store_true", help="one spin period for every pass (no linear trend)")
    parser.add_argument("--plot", metavar="FILE.png", help="also draw every pass with the joint best fit")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # The sampler and the renderer load in seconds; 'rsodb --help' must not wait for them.
    from rsodb.fit.joint import fit_joint, plot_joint

    try:
        if len(args.pass_ids) < 2:
            raise ValueError(f"a joint fit needs two or more passes, got {len(args.pass_ids)}; use 'rsodb fit' for one")
        archive = open_archive(args)
        config = config_from_args(args)
        result = fit_joint(
            archive,
            args.pass_ids,
            config,
            trend=not args.no_trend,
            restart=args.restart,
            progress=not (args.quiet or args.json),
        )
        plot = plot_joint(result, args.plot) if args.plot else None
    except (ValueError, TypeError, OSError, LookupError, RuntimeError) as error:
        return fail("fit-joint", error)
    if args.json:
        print(json.dumps(dict(result.to_dict(), plot=str(plot) if plot else None), indent=1))
    else:
        print(
            f"joint fit {config.name!r} of {len(result.pass_ids)} passes: {result.n_walkers} walkers x "
            f"{result.n_steps} steps in {result.elapsed_s:.0f} s"
            + (", spin period with a linear trend" if result.trend else ", one spin period")
        )
        print(result.table())
        if plot:
            print(f"wrote {plot}")
    return 0
