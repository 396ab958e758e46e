"""The index page of the main job's reports: one row per pass and links to every report."""

from __future__ import annotations

import html

from rsodb.fit.result import FitResult
from rsodb.periods.search import PeriodResult
from rsodb.report.html import Document, Paragraph, Raw, Table

__all__ = ["build_index"]


def build_index(archive, written, fit_name: str | None, missing=None) -> Document:
    """The index page: links to every report and one table row per pass (period and fitted spin period).

    Parameters
    ----------
    archive : Archive
    written : list of (kind, norad, path)
        The reports written, linked by file name.
    fit_name : str or None
        The stored fit shown in the table (None: no fit column values).
    missing : dict of str to (str, str), optional
        Why a pass has no value: pass id -> (column, reason), column ``"periods"`` or
        ``"fits"``; the reason is shown in place of the value.
    """
    missing = missing or {}

    rows = archive.summaries()
    names = {row.norad: row.name for row in rows}
    items = "".join(
        f'<li><a href="{html.escape(path.name)}">{html.escape(names.get(norad, str(norad)))} '
        f"(NORAD {norad}): {kind}</a></li>"
        for kind, norad, path in written
    )
    table = []
    for row in rows:
        column, reason = missing.get(row.pass_id, ("", ""))
        period = f"none: {reason}" if column == "periods" else "-"
        fit = f"not fitted: {reason}" if column == "fits" else "-"
        if "default" in archive.result_names(row.pass_id, "periods"):
            result = archive.load_result(row.pass_id, "periods", "default", PeriodResult.from_hdf5)
            period = f"{result.best_period_s:.4f} +- {result.uncertainty_s:.4f} ({result.verdict})"
        rms = converged = "-"
        if fit_name and fit_name in archive.result_names(row.pass_id, "fits"):
            record = archive.load_result(row.pass_id, "fits", fit_name, FitResult.from_hdf5).to_dict()
            spin = record["parameters"].get("spin_period_s")
            fit = (
                f"{spin['median']:.4f} -{spin['median'] - spin['p16']:.4f} +{spin['p84'] - spin['median']:.4f}"
                if spin
                else "fixed"
            )
            rms, converged = f"{record['residual_rms_mag']:.3f}", "yes" if record["converged"] else "no"
        start = str(row.start_utc)[:19].replace("T", " ")
        table.append((row.pass_id, f"{names[row.norad]} ({row.norad})", row.band, start, period, fit, rms, converged))
    doc = Document("rsodb reports").add(
        Paragraph(f"Archive {archive.path.resolve()}: {len(rows)} passes of {len(names)} object(s)."),
        Raw(f"<ul>{items}</ul>"),
        Table(
            (
                "pass",
                "object",
                "band",
                "start UTC",
                "period search (s, synodic)",
                f"fit {fit_name!r}: spin period (s)" if fit_name else "spin period fit",
                "residual RMS (mag)",
                "converged",
            ),
            tuple(table),
            numeric=frozenset({6}),
        ),
        Paragraph(
            "The period search gives the light curve's apparent (synodic) period; the fit gives the spin "
            "period of the attitude model, which differs from it by the precession and the moving "
            "Sun-observer geometry. A short fit is a first look: rerun 'rsodb fit' or 'rsodb campaign' "
            "with the full settings before quoting a result.",
            "meta",
        ),
    )
    return doc
