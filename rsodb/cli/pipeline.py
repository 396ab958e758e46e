"""``rsodb pipeline DATA_DIR --archive DIR --out REPORTS_DIR``: the main job, end to end.

Ingest every observation file under DATA_DIR, find every pass's spin period, run a short
spin-state fit of every pass (Dask LocalClusters), and write the period and fit reports of every
object plus an index page; then print where the reports are.

The short fits run one campaign per model, because each known model spins about its own body
axis (`QUICK_SPIN_AXES`); the campaigns share one LocalCluster.
"""
from __future__ import annotations

import argparse
import html
import json
from pathlib import Path
import sys
import time
from types import MappingProxyType

from rsodb.cli.archive_options import fail

__all__ = ["register", "run", "QUICK_FIT", "QUICK_SPIN_AXES", "run_pipeline"]

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

# A first look that keeps the bundled samples within a few minutes on two cores: at most 50
# samples per pass, no exposure sub-samples, a global search on 40 samples whose final
# population seeds the walkers (spread over the good modes), differential-evolution moves that
# let walkers jump between modes, and a short chain: ~3500 evaluations of the forward model per
# pass, each costing the shape's cached renderer (~0.1-0.3 ms per direction pair on this
# machine) times the samples. On the bundled samples it lands near the TOPEX truths; COSMOS
# 2502's glint-dominated curves sometimes need the full fit (30 generations and 80 steps found
# every truth but took twice as long).
QUICK_FIT = {
    "name": "quick",
    "model": {"n_sub": 1},
    "data": {"max_points": 50},
    "sampler": {"n_walkers": 12, "n_steps": 60, "init": "population", "moves": "de", "search_popsize": 12,
                "search_maxiter": 20, "search_points": 40, "seed": 0},
}
# The body axis each known model spins about in the published fits (TOPEX about its long axis,
# COSMOS 2502 end over end); other shapes keep the configuration's default ("z").
QUICK_SPIN_AXES = MappingProxyType({"topex": "z", "cosmos2502": "x"})


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

    rows = archive.catalog()
    norads = sorted({row.norad for row in rows})
    if fit and rows:
        outcomes = _fit_all(archive, rows, fit_config, fit_name, workers, progress)
        for outcome in outcomes:
            log(outcome.summary())
            for pass_id, error in outcome.failed:
                log(f"  {pass_id}: fit failed: {error}")
        fit_name = outcomes[0].name
        summary["fits"] = [outcome.to_dict() for outcome in outcomes]

    written = []
    for norad in norads:
        try:
            report_path = out_dir / f"{norad}_periods.html"
            written.append(("periods", norad, build_period_report(archive, norad).write(report_path)))
        except ValueError as error:
            log(f"object {norad}: no period report ({error})")
        if fit and rows:
            try:
                written.append(("fits", norad, build_campaign_report(archive, norad, name=fit_name)
                                .write(out_dir / f"{norad}_fits.html")))
            except ValueError as error:
                log(f"object {norad}: no fit report ({error})")
    index = _write_index(out_dir, archive, written, fit_name if fit and rows else None)
    summary["reports"] = [str(path) for _, _, path in written]
    summary["index"] = str(index)
    summary["elapsed_s"] = time.perf_counter() - started
    return summary


def quick_fit_configs(norads) -> dict:
    """The short first-look fit of each object: `QUICK_FIT` with the object's model's spin axis.

    Parameters
    ----------
    norads : iterable of int

    Returns
    -------
    dict of int to FitConfig
    """
    from rsodb.fit.config import FitConfig
    from rsodb.fit.shapes import shape_for_norad

    configs = {}
    for norad in norads:
        axis = QUICK_SPIN_AXES.get(shape_for_norad(norad))
        record = {**QUICK_FIT, "model": {**QUICK_FIT["model"], **({"spin_axis": axis} if axis else {})}}
        configs[norad] = FitConfig.from_dict(record)
    return configs


def _fit_all(archive, rows, fit_config, fit_name, workers, progress) -> list:
    """Fit every pass: one campaign per distinct configuration (per model for the quick fit), the
    campaigns side by side through one client of one LocalCluster, so no worker idles while another
    object's passes wait."""
    from rsodb.campaign import run_campaigns

    if fit_config is not None:
        configs = {row.norad: fit_config for row in rows}
    else:
        configs = quick_fit_configs({row.norad for row in rows})
    groups: dict = {}
    for row in rows:
        config = configs[row.norad]
        config = config.replace(name=fit_name) if fit_name else config
        groups.setdefault(json.dumps(config.to_dict(), sort_keys=True), (config, []))[1].append(row.pass_id)
    return run_campaigns(archive, [groups[key] for key in sorted(groups)], n_workers=workers, progress=progress)


def _write_index(out_dir: Path, archive, written, fit_name: str | None) -> Path:
    """index.html: links to every report and one table row per pass (period and fitted spin period)."""
    from rsodb.fit.result import FitResult
    from rsodb.periods import PeriodResult
    from rsodb.report.html import Document, Paragraph, Raw, Table

    rows = archive.catalog()
    names = {row.norad: row.name for row in rows}
    items = "".join(f'<li><a href="{html.escape(path.name)}">{html.escape(names.get(norad, str(norad)))} '
                    f'(NORAD {norad}): {kind}</a></li>' for kind, norad, path in written)
    table = []
    for row in rows:
        period = fit = "-"
        if "default" in archive.result_names(row.pass_id, "periods"):
            result = archive.load_result(row.pass_id, "periods", "default", PeriodResult.from_hdf5)
            period = f"{result.best_period_s:.4f} +- {result.uncertainty_s:.4f} ({result.verdict})"
        rms = converged = "-"
        if fit_name and fit_name in archive.result_names(row.pass_id, "fits"):
            record = archive.load_result(row.pass_id, "fits", fit_name, FitResult.from_hdf5).to_dict()
            spin = record["parameters"].get("spin_period_s")
            fit = (f"{spin['median']:.4f} -{spin['median'] - spin['p16']:.4f} +{spin['p84'] - spin['median']:.4f}"
                   if spin else "fixed")
            rms, converged = f"{record['residual_rms_mag']:.3f}", "yes" if record["converged"] else "no"
        start = str(row.start_utc)[:19].replace("T", " ")
        table.append((row.pass_id, f"{names[row.norad]} ({row.norad})", row.band, start, period, fit, rms, converged))
    doc = Document("rsodb reports").add(
        Paragraph(f"Archive {archive.path.resolve()}: {len(rows)} passes of {len(names)} object(s)."),
        Raw(f"<ul>{items}</ul>"),
        Table(("pass", "object", "band", "start UTC", "period search (s, synodic)",
               f"fit {fit_name!r}: spin period (s)" if fit_name else "spin period fit", "residual RMS (mag)",
               "converged"), tuple(table), numeric=frozenset({6})),
        Paragraph("The period search gives the light curve's apparent (synodic) period; the fit gives the spin "
                  "period of the attitude model, which differs from it by the precession and the moving "
                  "Sun-observer geometry. A short fit is a first look: rerun 'rsodb fit' or 'rsodb campaign' "
                  "with the full settings before quoting a result.", "meta"))
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
