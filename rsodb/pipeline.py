"""The main job: ingest a directory, find every pass's period, fit every pass, write the reports.

The short fits run one campaign per model, because each known model spins about its own body
axis (`QUICK_SPIN_AXES`); the campaigns share one LocalCluster.
"""

from __future__ import annotations

import json
from pathlib import Path
import time
from types import MappingProxyType

from rsodb.archive import Archive
from rsodb.campaign.fit_campaign import run_campaigns
from rsodb.campaign.period_survey import survey_periods
from rsodb.fit.config import FitConfig
from rsodb.fit.shapes import shape_for_norad
from rsodb.report.fit_report import build_campaign_report
from rsodb.report.index_page import build_index
from rsodb.report.period_report import build_period_report

__all__ = ["run_pipeline", "quick_fit_configs", "QUICK_FIT", "QUICK_SPIN_AXES"]

# A first look that keeps the bundled samples within a few minutes on two cores. The likelihood
# sees at most 120 samples per pass, chosen without a stride (bins of consecutive samples where
# they turn the body little, then contiguous windows each a cycle long spread over the pass;
# rsodb.fit.selection), with no exposure sub-samples; a global search on 40 samples whose final
# population seeds the walkers (spread over the good modes), differential-evolution moves that
# let walkers jump between modes, and a short chain. Residuals, their RMS and the model curve
# still cover every sample of the pass. The quick fit says when its chain has not converged.
QUICK_FIT = {
    "name": "quick",
    "band_draws": 20,
    "model": {"n_sub": 1},
    "data": {"max_points": 120},
    "sampler": {
        "n_walkers": 12,
        "n_steps": 60,
        "init": "population",
        "moves": "de",
        "search_popsize": 12,
        "search_maxiter": 20,
        "search_points": 40,
        "seed": 0,
    },
}
# The body axis each known model spins about in the published fits (TOPEX about its long axis,
# COSMOS 2502 end over end); other shapes keep the configuration's default ("z").
QUICK_SPIN_AXES = MappingProxyType({"topex": "z", "cosmos2502": "x"})


def run_pipeline(
    data_dir,
    archive_dir,
    out_dir,
    *,
    fit_config=None,
    fit_name: str | None = None,
    workers: int | None = None,
    fit: bool = True,
    progress: bool = True,
    log=print,
) -> dict:
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
    log(
        f"periods: {len(survey.results)} pass(es), "
        + ", ".join(
            f"{sum(r.verdict == v for r in survey.results)} {v}" for v in sorted({r.verdict for r in survey.results})
        )
    )
    summary["periods"] = {r.pass_id: {"period_s": r.best_period_s, "verdict": r.verdict} for r in survey.results}

    missing = {pass_id: ("periods", error) for pass_id, error in survey.failures}  # shown in the index

    rows = archive.summaries()
    norads = sorted({row.norad for row in rows})
    if fit and rows:
        outcomes = _fit_all(archive, rows, fit_config, fit_name, workers, progress)
        for outcome in outcomes:
            log(outcome.summary())
            for pass_id, error in outcome.failed:
                log(f"  {pass_id}: not fitted: {error}")
                missing[pass_id] = ("fits", error)
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
                written.append(
                    (
                        "fits",
                        norad,
                        build_campaign_report(archive, norad, name=fit_name).write(out_dir / f"{norad}_fits.html"),
                    )
                )
            except ValueError as error:
                log(f"object {norad}: no fit report ({error})")
    index = build_index(archive, written, fit_name if fit and rows else None, missing).write(out_dir / "index.html")
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
