"""``rsodb pipeline DATA_DIR --archive DIR --out REPORTS_DIR``: the main job, end to end.

Ingest every observation file under DATA_DIR, find every pass's spin period, run a short
spin-state fit of every pass (Dask LocalCluster), and write the period and fit reports of every
object plus an index page; then print where the reports are.
"""
from __future__ import annotations

import argparse
import html
import json
from pathlib import Path
import sys
import time

from rsodb.cli.archive_options import fail

__all__ = ["register", "run", "QUICK_FIT", "run_pipeline"]

EXAMPLE = """\
examples:
  rsodb pipeline data_samples --archive archive --out reports
  rsodb pipeline /data/observations --archive archive --out reports --fit-config fit.toml
  rsodb pipeline data_samples --archive archive --out reports --no-fit

Every step can be rerun: files already in the archive are skipped, periods are recomputed,
and passes that already have the fit (same --fit-name) are skipped. The short fit is a first
look (few walkers and steps; it says when its chain has not converged); run 'rsodb fit' or
'rsodb campaign' with the full settings for results to publish.
"""

# A first look that keeps the bundled samples within a few minutes on two cores: at most 40
# samples per pass, no exposure sub-samples, a small global search and a short chain. The
# fit's cost is set by the shape's cached renderer (~0.3 ms per direction pair for TOPEX,
# ~0.65 ms for COSMOS 2502 on this machine), times samples, times evaluations.
QUICK_FIT = {
    "name": "quick",
    "model": {"n_sub": 1},
    "data": {"max_points": 40},
    "sampler": {"n_walkers": 12, "n_steps": 80, "search_popsize": 8, "search_maxiter": 10, "search_points": 30,
                "seed": 0},
}


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "pipeline", help="ingest a directory, find periods, fit every pass, write the reports",
        description="The whole workflow on a directory of observation files: ingest into the archive, spin "
                    "period of every pass, a short MCMC spin-state fit of every pass on a Dask LocalCluster, "
                    "and HTML reports (periods and fits per object, and an index).",
        epilog=EXAMPLE, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("data_dir", metavar="DATA_DIR", help="directory (or file) of observation files")
    parser.add_argument("--archive", required=True, metavar="DIR", help="archive directory (created when missing)")
    parser.add_argument("--out", required=True, metavar="REPORTS_DIR", help="where the HTML reports go")
    parser.add_argument("--fit-config", metavar="FIT.toml", help="fit configuration instead of the short first look")
    parser.add_argument("--fit-name", help="stored fit name (default: 'quick', or the configuration's)")
    parser.add_argument("--workers", type=int, metavar="N", help="parallel workers (default: one per core)")
    parser.add_argument("--no-fit", action="store_true", help="ingest, periods and period reports only")
    parser.add_argument("--json", action="store_true", help="print a JSON summary instead of text")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)


def run_pipeline(data_dir, archive_dir, out_dir, *, fit_config=None, fit_name: str | None = None,
                 workers: int | None = None, fit: bool = True, progress: bool = True, log=print) -> dict:
    """Run the main job; returns a summary dict (what was done, where the reports are).

    Parameters
    ----------
    data_dir : path
        Observation files (searched recursively).
    archive_dir : path
        The archive (created when missing).
    out_dir : path
        Report directory.
    fit_config : FitConfig, optional
        The fit of every pass (default: `QUICK_FIT`, a short first look).
    fit_name : str, optional
        Overrides the fit's stored name.
    workers : int, optional
        Parallel workers for periods and fits (default: one per core).
    fit : bool
        Run the fits (False: ingest, periods and period reports only).
    progress : bool
        Progress bars.
    log : callable
        Receives one line per step.
    """
    from rsodb.archive import Archive
    from rsodb.campaign import run_campaign
    from rsodb.period_survey import survey_periods
    from rsodb.report.campaign import build_campaign_report
    from rsodb.report.periods import build_period_report

    started = time.perf_counter()
    out_dir = Path(out_dir)
    data_dir = Path(data_dir)
    if not data_dir.exists():
        raise ValueError(f"data directory {str(data_dir)!r} does not exist; give a directory of observation files")
    archive = Archive(archive_dir)
    summary: dict = {"archive": str(archive.path), "reports_dir": str(out_dir)}

    report = archive.ingest([data_dir], progress=progress)
    log(report.summary())
    summary["ingest"] = {"files": report.n_files, "ok": report.ok}
    survey = survey_periods(archive, processes=workers, progress=progress, store=True)
    log(f"periods: {len(survey.results)} pass(es), "
        + ", ".join(f"{sum(r.verdict == v for r in survey.results)} {v}"
                    for v in sorted({r.verdict for r in survey.results})))
    summary["periods"] = {r.pass_id: {"period_s": r.best_period_s, "verdict": r.verdict} for r in survey.results}

    norads = sorted({row.norad for row in archive.catalog()})
    if fit:
        from rsodb.fit.config import FitConfig

        config = fit_config if fit_config is not None else FitConfig.from_dict(QUICK_FIT)
        config = config.replace(name=fit_name) if fit_name else config
        outcome = run_campaign(archive, pass_ids=[row.pass_id for row in archive.catalog()], config=config,
                               n_workers=workers, progress=progress)
        log(outcome.summary())
        for pass_id, error in outcome.failed:
            log(f"  {pass_id}: fit failed: {error}")
        summary["fits"] = outcome.to_dict()

    written = []
    for norad in norads:
        try:
            written.append(("periods", norad, build_period_report(archive, norad).write(out_dir / f"{norad}_periods.html")))
        except ValueError as error:
            log(f"object {norad}: no period report ({error})")
        if fit:
            try:
                written.append(("fits", norad, build_campaign_report(archive, norad, name=config.name)
                                .write(out_dir / f"{norad}_fits.html")))
            except ValueError as error:
                log(f"object {norad}: no fit report ({error})")
    index = _write_index(out_dir, archive, written)
    summary["reports"] = [str(path) for _, _, path in written]
    summary["index"] = str(index)
    summary["elapsed_s"] = time.perf_counter() - started
    return summary


def _write_index(out_dir: Path, archive, written) -> Path:
    from rsodb.report.html import Document, Paragraph, Raw

    names = {row.norad: row.name for row in archive.catalog()}
    items = "".join(f'<li><a href="{html.escape(path.name)}">{html.escape(names.get(norad, str(norad)))} '
                    f'(NORAD {norad}): {kind}</a></li>' for kind, norad, path in written)
    doc = Document("rsodb reports").add(
        Paragraph(f"Archive {archive.path.resolve()}: {len(archive.catalog())} passes of {len(names)} object(s)."),
        Raw(f"<ul>{items}</ul>"))
    return doc.write(out_dir / "index.html")


def run(args: argparse.Namespace) -> int:
    from rsodb.fit.config import FitConfig

    quiet = args.quiet or args.json
    try:
        if args.workers is not None and args.workers < 1:
            raise ValueError(f"--workers {args.workers} must be at least 1")
        config = FitConfig.from_toml(args.fit_config) if args.fit_config else None
        summary = run_pipeline(args.data_dir, args.archive, args.out, fit_config=config, fit_name=args.fit_name,
                               workers=args.workers, fit=not args.no_fit, progress=not quiet,
                               log=(lambda line: print(line, file=sys.stderr)) if args.json else print)
    except (ValueError, TypeError, OSError, LookupError) as error:
        return fail("pipeline", error)
    if args.json:
        print(json.dumps(summary, indent=1, default=str))
    else:
        print(f"done in {summary['elapsed_s']:.0f} s. Reports in {Path(args.out).resolve()}:")
        for path in summary["reports"]:
            print(f"  {Path(path).resolve()}")
        print(f"open {Path(summary['index']).resolve()} to start")
    return 0
