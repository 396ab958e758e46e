"""``rsodb fit PASS --archive DIR``: fit the spin state of one pass by MCMC and store the posterior."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import rsodb
from rsodb.cli.archive_options import add_archive_option, fail, open_archive

__all__ = ["register", "run"]

EXAMPLE = """\
examples:
  rsodb fit 22076-20240730T212240 --archive archive
  rsodb fit 22076-20240730T212240 --archive archive --config configs/short.toml --plots figures/
  rsodb fit 22076-20240730T212240 --archive archive --steps 200 --processes 2 --json
  rsodb fit 40358-20240118T154343 --archive archive --model ../shared/data/models/cosmos2502_lotos.obj \\
      --materials ../shared/data/models/cosmos2502_lotos.materials.json --spin-axis x
  rsodb fit 22076-20240730T212240 --archive archive --until-converged --steps 3000 --time-limit-s 1800

The spin-period prior comes from the pass's stored period ('rsodb periods' first), +-1%
by default (--force uses a stored period whose verdict is too weak to trust). The chain is
written as the sampler runs: a fit that is stopped (Ctrl-C, kill -9) continues where it stopped
when the same command is run again; --restart discards it. --model takes a built-in model
name or any mesh file (OBJ, PLY, glTF), whose shape cache is built once and kept in the
archive (shapes/). A fit configuration (TOML) sets the model, data window, priors and
sampler; see docs/fitting.md.
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
    add_fit_options(parser)
    add_sampler_options(parser)
    parser.add_argument("--plots", metavar="DIR", help="also write corner, light-curve and trace PNGs here")
    parser.set_defaults(func=run)


def add_sampler_options(parser: argparse.ArgumentParser) -> None:
    """The options of one sampler run that `rsodb fit` and `rsodb fit-joint` share."""
    parser.add_argument("--walkers", type=int, metavar="N", help="number of walkers (overrides the configuration)")
    parser.add_argument("--processes", type=int, metavar="N", help="worker processes (0 = one per core)")
    parser.add_argument("--seed", type=int, metavar="N", help="random seed (overrides the configuration)")
    parser.add_argument("--until-converged", action="store_true", help="sample until converged (--steps caps it)")
    parser.add_argument(
        "--time-limit-s", type=float, metavar="S", help="stop sampling after S seconds (rerun continues)"
    )
    parser.add_argument("--restart", action="store_true", help="discard a stored chain of this fit and start again")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def add_fit_options(parser: argparse.ArgumentParser) -> None:
    """The options `rsodb fit` and `rsodb campaign` share: configuration, model and overrides."""
    parser.add_argument("--config", metavar="FIT.toml", help="fit configuration (default: the standard fit)")
    parser.add_argument("--name", help="stored fit name (default: the configuration's, 'default')")
    parser.add_argument(
        "--model",
        metavar="NAME|PATH",
        help="a built-in shape (topex, cosmos2502, ellipsoid, ...) or a mesh file (OBJ, PLY, glTF)",
    )
    parser.add_argument("--materials", metavar="JSON", help="materials JSON of the --model mesh")
    parser.add_argument(
        "--spin-axis", choices=("x", "y", "z"), help="body axis that spins (overrides the configuration)"
    )
    parser.add_argument("--steps", type=int, metavar="N", help="MCMC steps per walker (overrides the configuration)")
    parser.add_argument(
        "--force",
        action="store_true",
        help="take the spin-period prior from the stored period even when its verdict is too weak",
    )


def config_from_args(args: argparse.Namespace):
    """The `FitConfig` of a config file plus command-line overrides."""
    config = rsodb.FitConfig.from_toml(args.config) if args.config else rsodb.FitConfig()
    sampler = {
        key: value
        for key, value in (
            ("n_steps", args.steps),
            ("n_walkers", getattr(args, "walkers", None)),
            ("processes", getattr(args, "processes", None)),
            ("seed", getattr(args, "seed", None)),
            ("until_converged", True if getattr(args, "until_converged", False) else None),
            ("time_limit_s", getattr(args, "time_limit_s", None)),
        )
        if value is not None
    }
    changes = {"sampler": sampler} if sampler else {}
    if args.name:
        changes["name"] = args.name
    config = config.replace(**changes) if changes else config
    model = {}
    if args.model:
        if rsodb.fit.SHAPES.get(args.model) is not None or args.model == "auto":
            if args.materials:
                raise ValueError(
                    f"--materials {args.materials} goes with a mesh file, not the built-in model {args.model!r}"
                )
            model.update(shape=args.model, mesh="", materials="", articulations=())
        elif Path(args.model).is_file():
            materials = str(Path(args.materials).resolve()) if args.materials else ""
            model.update(shape="auto", mesh=str(Path(args.model).resolve()), materials=materials, articulations=())
        else:
            raise ValueError(
                f"--model {args.model!r} is neither a built-in shape ({', '.join(rsodb.fit.SHAPES)}) "
                "nor a mesh file; check the name or path"
            )
    elif args.materials:
        raise ValueError("--materials needs --model PATH (the mesh file it describes)")
    if args.spin_axis:
        model["spin_axis"] = args.spin_axis
    if model:
        config = config.with_model(**model)
    if args.force:
        spec = config.parameter_specs({}).get("spin_period_s")
        if not isinstance(spec, dict) or spec.get("from") != "periods":
            raise ValueError(
                "--force lets a weak stored period set the spin-period prior, but this fit gives its own prior"
            )
        config = config.replace(parameters={**config.parameters, "spin_period_s": {**spec, "force": True}})
    return config


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
