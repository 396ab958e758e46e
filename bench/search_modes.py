"""Does the fit's global search find the true mode? Both searches on the Cycles-rendered passes.

    python bench/search_modes.py                       # passes 0-5: evolution 8x30 and 15x50, multi-start
    python bench/search_modes.py --passes 0 1 --evolution 8x30 --no-record

The passes are those of ``python bench/fit_coverage.py --cycles`` (Blender Cycles renders of the
published workflow's COSMOS 2502 mesh; rendered there, read here). Each search runs alone, as a
fit's start does, on the fit's coarse search posterior (120 samples of the 600, no exposure
sub-samples): differential evolution (``init = "search"``) with the population and generations
the coverage run uses, and the multi-start search (``init = "multistart"``) with its defaults. The
figure of merit is the log posterior of the point the search returns against that of the true
state (its best jitter): a search "reached the true mode" when it ended within ``--margin`` of
the truth (the wrong modes the searches end in lie hundreds below; a local optimum of the true
mode a few tens below, which the sampler then climbs).
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
import json
import multiprocessing
from pathlib import Path
import sys
import time

import numpy as np

sys.path[:] = [entry for entry in sys.path if Path(entry or ".").resolve() != Path(__file__).resolve().parent]
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.record import command, figure, record, today  # noqa: E402

JITTERS = (0.005, 0.01, 0.02, 0.03, 0.05, 0.1)


def _search(task) -> dict:
    """One search on one pass: what it found against the truth."""
    from bench import fit_coverage
    from rsodb.fit import sampler
    from rsodb.fit.config import FitConfig
    from rsodb.fit.runner import FitProblem
    from rsodb.fit.shape_store import ShapeStore

    directory, record_, method, options = task
    args = argparse.Namespace(**options, init=method)
    if method != "multistart":  # "search PxG": differential evolution, population P per parameter, G generations
        popsize, maxiter = method.split()[1].split("x")
        args.search_popsize, args.search_maxiter = int(popsize), int(maxiter)
        args.init = "search"
    config = FitConfig.from_dict(fit_coverage.cycles_config(record_["axis"], args))
    problem = FitProblem.build(
        fit_coverage.load_cycles_pass(Path(directory), record_),
        config,
        store=ShapeStore(str(Path(directory) / "shapes")),
    )
    names = problem.posterior.space.names
    coarse = problem.search_posterior
    truth = max(
        float(coarse(np.array([record_["truth"][name] if name != "jitter_mag" else jitter for name in names])))
        for jitter in JITTERS
    )
    evaluator = sampler._Evaluator(problem.posterior, coarse)
    rng = np.random.default_rng(int(record_["index"]))
    started = time.process_time()
    if args.init == "multistart":
        best, cost, evaluations, _ = sampler._search_multistart(problem.posterior, config.sampler, rng, evaluator)
    else:
        result, best, cost, polish = sampler._search(problem.posterior, config.sampler, rng, evaluator)
        evaluations = int(result.nfev) + polish
    values = dict(zip(names, best.tolist()))
    return {
        "pass": int(record_["index"]),
        "axis": record_["axis"],
        "method": method,
        "ln_p_found": float(-cost),
        "ln_p_truth": truth,
        "evaluations": int(evaluations),
        "cpu_s": time.process_time() - started,
        "found": values,
        "truth": {name: float(record_["truth"][name]) for name in names if name in record_["truth"]},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--passes", type=int, nargs="+", default=list(range(6)))
    parser.add_argument(
        "--evolution",
        nargs="*",
        default=["8x30", "15x50"],
        help="differential-evolution budgets, POPSIZExGENERATIONS (8x30: the coverage run's; 15x50: more evaluations than the multi-start); none: the multi-start alone",
    )
    parser.add_argument("--no-multistart", action="store_true")
    parser.add_argument("--passes-dir", default=str(Path.home() / ".cache" / "rsodb" / "cycles_passes"))
    parser.add_argument("--search-starts", type=int, default=8192)
    parser.add_argument("--search-polish", type=int, default=16)
    parser.add_argument("--margin", type=float, default=50.0, help="ln p below the truth's still in its mode")
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--no-record", action="store_true")
    args = parser.parse_args(argv)

    directory = Path(args.passes_dir)
    truths = directory / "truths.json"
    if not truths.exists():
        print(f"no Cycles passes in {directory}: render them with python bench/fit_coverage.py --cycles --render-only")
        return 1
    records = {int(item["index"]): item for item in json.loads(truths.read_text())}
    missing = [index for index in args.passes if index not in records]
    if missing:
        print(f"passes {missing} are not rendered in {directory}")
        return 1
    options = {
        "walkers": 16,
        "steps": 400,
        "until_converged": False,
        "time_limit_s": 0.0,
        "max_points": 0,
        "search_popsize": 8,  # (each evolution budget sets its own; the multi-start does not use them)
        "search_maxiter": 30,
        "search_starts": args.search_starts,
        "search_polish": args.search_polish,
    }
    methods = [f"search {budget}" for budget in args.evolution] + ([] if args.no_multistart else ["multistart"])
    tasks = [(str(directory), records[index], method, options) for index in args.passes for method in methods]
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(args.processes, mp_context=context) as pool:
        rows = []
        for row in pool.map(_search, tasks):
            row["reached"] = row["ln_p_found"] >= row["ln_p_truth"] - args.margin
            rows.append(row)
            print(
                f"pass {row['pass']} ({row['axis']}) {row['method']:15s} ln p {row['ln_p_found']:8.1f} "
                f"(truth {row['ln_p_truth']:7.1f}) {'true mode' if row['reached'] else 'WRONG MODE'}, "
                f"{row['evaluations']} evaluations, {row['cpu_s']:.0f} s CPU",
                flush=True,
            )
    labels = {
        method: "multi-start" if method == "multistart" else f"evolution {method.split()[1]}" for method in methods
    }
    summary = {method: [row for row in rows if row["method"] == method] for method in methods}
    lines = [
        f"| {row['pass']} | {row['axis']} | {labels[row['method']]} | {row['ln_p_found']:.1f} | {row['ln_p_truth']:.1f} | "
        f"{'yes' if row['reached'] else 'no'} | {row['evaluations']} | {row['cpu_s']:.0f} | "
        f"{row['found']['spin_period_s']:.2f} ({row['truth']['spin_period_s']:.2f}) | "
        f"{row['found']['precession_period_s']:.0f} ({row['truth']['precession_period_s']:.0f}) | "
        f"{row['found']['precession_angle_deg']:.1f} ({row['truth']['precession_angle_deg']:.1f}) |"
        for row in rows
    ]
    totals = {
        method: (sum(row["reached"] for row in items), len(items), float(np.median([r["evaluations"] for r in items])))
        for method, items in summary.items()
    }
    for method, (reached, count, evaluations) in totals.items():
        print(f"{labels[method]}: true mode on {reached} of {count} passes, median {evaluations:.0f} evaluations")
    if args.no_record:
        return 0
    section = f"""
## Global search on Cycles-rendered passes ({today()}, bench/search_modes.py)

Does the fit's start find the true mode? Each search alone, on the coarse search posterior (120 of
600 samples) of the Cycles-rendered COSMOS 2502 passes of `bench/fit_coverage.py --cycles`, with the
paper mesh's cached renderer; ln p of the point it returned against ln p at the true state (best
jitter); "true mode" = within {args.margin:g} of it (a search that ends above the truth is counted
there too: the forward model then misses the data, as on pass 4). Differential evolution ("evolution
PxG": population P per parameter, G generations; 8x30 is the coverage run's), L-BFGS-B polish. Multi-start: {args.search_starts} Sobol points of the priors, the best
{args.search_polish} refined by Nelder-Mead (400 evaluations each), L-BFGS-B polish.

| pass | axis | search | ln p found | ln p truth | true mode | evaluations | CPU s | P found (true), s | P_pr found (true), s | cone found (true), deg |
|---|---|---|---|---|---|---|---|---|---|---|
{chr(10).join(lines)}

{"; ".join(f"{labels[m]}: true mode on {r} of {c} passes (median {e:.0f} evaluations)" for m, (r, c, e) in totals.items())}.

Reproduce: `{command("search_modes.py", argv)}`.
"""
    figures = [
        figure(f"{labels[m]}: true mode found", f"{r} of {c} passes, median {e:.0f} evaluations")
        for m, (r, c, e) in totals.items()
    ]
    record("search_modes", command("search_modes.py", argv), figures, section, data=rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
