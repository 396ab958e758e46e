"""The index page of the main job's reports: one sortable row per pass and links to every report."""

from __future__ import annotations

import html
import math

from rsodb.fit.conventions import comparable_convention, fit_conventions
from rsodb.fit.result import FitResult
from rsodb.periods.result import PeriodResult
from rsodb.report.html import Document, Link, Paragraph, Raw, Table, anchor
from rsodb.report.spin_state import axis_text, convention_interval, interval
from rsodb.report.trust import assess

__all__ = ["build_index"]

COLUMNS = (
    "pass",
    "object",
    "band",
    "start UTC",
    "period search (s, synodic)",
    "period verdict",
    "spin period, fitted (s)",
    "light-curve period, fitted (s)",
    "spin axis",
    "trust",
    "why",
)


def build_index(archive, written, fit_name: str | None, missing=None) -> Document:
    """The index page: links to every report and one table row per pass (period search, fitted
    spin state, trust level, and the reason wherever a value is missing).

    Parameters
    ----------
    archive : Archive
    written : list of (kind, norad, path)
        The reports written, linked by file name.
    fit_name : str or None
        The stored fit shown in the table (None: no fits were run).
    missing : mapping of str to (str, str), optional
        Why a pass has no value: pass id -> (column, reason), column ``"periods"`` or ``"fits"``.
    """
    missing = dict(missing or {})
    rows = archive.summaries()
    names = {row.norad: row.name for row in rows}
    pages = {(kind, norad): path.name for kind, norad, path in written}
    items = "".join(
        f'<li><a href="{html.escape(path.name)}">{html.escape(names.get(norad, str(norad)))} '
        f"(NORAD {norad}): {kind}</a></li>"
        for kind, norad, path in written
    )
    table, classes = [], []
    for row in rows:
        period = _stored(archive, row.pass_id, "periods", "default", PeriodResult.from_hdf5)
        fit = _stored(archive, row.pass_id, "fits", fit_name, FitResult.from_hdf5) if fit_name else None
        why = []
        column, reason = missing.get(row.pass_id, ("", ""))
        if period is None:
            period_cell, verdict = "-", "-"
            why.append(
                f"no period: {reason}" if column == "periods" else "no period search stored (run 'rsodb periods')"
            )
        else:
            verdict = period.verdict
            if math.isfinite(period.best_period_s):
                period_cell = f"{period.best_period_s:.4f} +- {period.uncertainty_s:.4f}"
            else:
                period_cell = "-"
                why.append(f"no period: {period.reason}")
        if fit_name is None:
            no_fit = "no fits run (the main job ran with --no-fit)"
        elif column == "fits":
            no_fit = f"not fitted: {reason}"
        else:
            no_fit = f"no fit named {fit_name!r} (run 'rsodb fit')"
        trust = assess(fit, period, missing=no_fit)
        spin = curve = axis = "-"
        if fit is not None:
            if "spin_period_s" in fit.names:
                j = fit.names.index("spin_period_s")
                spin = interval(fit.median[j], fit.p16[j], fit.p84[j], digits=6)
            elif "spin_period_s" in fit.space.fixed:
                spin = f"{fit.space.fixed['spin_period_s']:.6g} (fixed)"
            curve = convention_interval(fit, comparable_convention(fit_conventions(fit)))
            axis = axis_text(fit)
        why.extend(trust.reasons)
        page = pages.get(("fits", row.norad)) or pages.get(("periods", row.norad))
        pass_cell = Link(row.pass_id, f"{page}#{anchor('Pass ' + row.pass_id)}") if page else row.pass_id
        start = str(row.start_utc)[:19].replace("T", " ")
        table.append(
            (
                pass_cell,
                f"{names[row.norad]} ({row.norad})",
                row.band,
                start,
                period_cell,
                verdict,
                spin,
                curve,
                axis,
                trust.level,
                "; ".join(why) or "-",
            )
        )
        classes.append(f"trust-{trust.level}")
    doc = Document("rsodb reports").add(
        Paragraph(f"Archive {archive.path.resolve()}: {len(rows)} passes of {len(names)} object(s)."),
        Raw(f"<ul>{items}</ul>"),
        Table(COLUMNS, tuple(table), numeric=frozenset({4, 6, 7}), sortable=True, row_classes=tuple(classes)),
        Paragraph(
            "Click a column's header to sort by it. The period search gives the light curve's apparent "
            "(synodic) period; the fitted spin period is the attitude model's parameter, and the fitted "
            "light-curve period is the period at which the fitted model's light curve repeats, to compare "
            "with the period search. Trust: high when the chain converged, the model fits the data and "
            "agrees with a confident period search; medium when one of those is in doubt; low when the chain "
            "has not converged or the model misses the data; none when there is no fit. A short fit is a "
            "first look: rerun 'rsodb fit' or 'rsodb campaign' with the standard configuration before quoting "
            "a result.",
            "meta",
        ),
    )
    return doc


def _stored(archive, pass_id: str, kind: str, name: str, reader):
    """A stored result, or None when the pass has none of that name."""
    if name not in archive.result_names(pass_id, kind):
        return None
    return archive.load_result(pass_id, kind, name, reader)
