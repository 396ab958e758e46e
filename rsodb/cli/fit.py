"""``rsodb fit PASS --archive DIR``: fit the spin state of one pass by MCMC and store the posterior."""

from __future__ import annotations

import argparse
import json

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb fit 22076-20240730T212240 --archive archive
  rsodb fit 22076-20240730T212240 --archive archive --config fit.toml --plots figures/
  rsodb fit 22076-20240730T212240 --archive archive --steps 200 --processes 2 --json

The spin-period prior comes from the pass's stored period ('rsodb periods' first), +-1%
by default. The chain is written as the sampler runs: a fit that is stopped (Ctrl-C, kill -9)
continues where it stopped when the same command is run again; --restart discards it.
A fit configuration (TOML) sets the model, data window, priors and sampler; see docs/fitting.md.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "fit",
        help="fit the spin state of one pass (emcee) and store the posterior",
        description="Fit a spin-state model (shape + attitude) to one stored pass with emcee: global search, "
        "resumable chain, posterior median and 16/84 percentiles, best-fit light curve and "
        "diagnostics written back to the archive.",
        epilog=EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("pass_id", metavar="PASS", help="pass id (a unique prefix is enough; see 'rsodb ls')")
    add_archive_option(parser)
    parser.add_argument("--config", metavar="FIT.toml", help="fit configuration (default: the standard fit)")
    parser.add_argument("--name", help="stored fit name (default: the configuration's, 'default')")
    parser.add_argument("--steps", type=int, metavar="N", help="MCMC steps per walker (overrides the configuration)")
    parser.add_argument("--walkers", type=int, metavar="N", help="number of walkers (overrides the configuration)")
    parser.add_argument("--processes", type=int, metavar="N", help="worker processes (0 = one per core)")
    parser.add_argument("--seed", type=int, metavar="N", help="random seed (overrides the configuration)")
    parser.add_argument("--restart", action="store_true", help="discard a stored chain of this fit and start again")
    parser.add_argument("--plots", metavar="DIR", help="also write corner, light-curve and trace PNGs here")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)


def config_from_args(args: argparse.Namespace):
    """The `FitConfig` of a config file plus command-line overrides."""
    config = rsodb.FitConfig.from_toml(args.config) if args.config else rsodb.FitConfig()
    sampler = {
        key: value
        for key, value in (
            ("n_steps", args.steps),
            ("n_walkers", args.walkers),
            ("processes", args.processes),
            ("seed", args.seed),
        )
        if value is not None
    }
    changes = {"sampler": sampler} if sampler else {}
    if args.name:
        changes["name"] = args.name
    return config.replace(**changes) if changes else config


def run(args: argparse.Namespace) -> int:
    try:
        archive = open_archive(args)
        config = config_from_args(args)
        result = rsodb.fit_pass(
            archive, args.pass_id, config, restart=args.restart, progress=not (args.quiet or args.json)
        )
        paths = {}
        if args.plots:
            paths = rsodb.fit.save_all(result, args.plots)
    except (ValueError, TypeError, OSError, LookupError, RuntimeError) as error:
        return fail("fit", error)
    if args.json:
        print(json.dumps(dict(result.to_dict(), plots={k: str(v) for k, v in paths.items()}), indent=1))
    else:
        print(
            f"fit {result.name!r} of {result.pass_id}: {result.mag_obs.size} samples, "
            f"{result.n_walkers} walkers x {result.n_steps} steps in {result.elapsed_s:.0f} s"
        )
        print(result.table())
        for kind, path in paths.items():
            print(f"wrote {kind} plot {path}")
    return 0
