"""The period survey report of one object: trend, table, and each pass's periodogram and folded curve.

Built from the period results stored by `rsodb periods` (`rsodb.campaign.period_survey`) and the
passes themselves (to draw the periodograms and folded light curves):

1. a summary and the spin-up/down trend (`rsodb.periods.trend`);
2. period against date with 1-sigma error bars, coloured by verdict, and the trend line;
3. a table of every pass (period, error, verdict, cycles, false-alarm probability, S/N,
   sidereal range, reason);
4. per pass: the light curve with the fitted model, the Lomb-Scargle periodogram with the
   peak and the chosen period marked, and the curve folded on the chosen period.

Use `build_period_report(archive, norad)` from Python or
``rsodb report periods --archive DIR --object N --out FILE.html``.
"""

from __future__ import annotations

import math

import numpy as np

from rsodb.campaign.period_survey import load_period_results
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.trend import trend_from_results
from rsodb.plotting import file_pyplot, magnitude_label
from rsodb.report.html import Document, Heading, Paragraph, Raw, Table, anchor, figure_from_matplotlib

__all__ = [
    "build_period_report",
    "trend_figure",
    "pass_figure",
]

_VERDICT_STYLE = {
    "confident": {"color": "C0", "marker": "o"},
    "ambiguous harmonic": {"color": "C1", "marker": "s"},
    "too short": {"color": "0.6", "marker": "^"},
    "no signal": {"color": "0.6", "marker": "x"},
}


def trend_figure(results, trend=None):
    """Period against date with error bars, by verdict, and the trend line; returns the figure."""
    plt = file_pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    for verdict, style in _VERDICT_STYLE.items():
        chosen = [
            r for r in results if r.verdict == verdict and math.isfinite(r.best_period_s) and r.epoch_utc is not None
        ]
        if not chosen or verdict in ("too short", "no signal"):
            continue
        dates = np.array([r.epoch_utc for r in chosen], dtype="datetime64[ns]").astype("datetime64[ms]").astype(object)
        ax.errorbar(
            dates,
            [r.best_period_s for r in chosen],
            yerr=[r.uncertainty_s for r in chosen],
            ls="none",
            capsize=3,
            label=f"{verdict} ({len(chosen)})",
            **style,
        )
        bounds = [(r.epoch_utc, *sorted(r.sidereal_bounds_s)) for r in chosen if r.synodic is not None]
        if bounds:
            t = np.array([b[0] for b in bounds], dtype="datetime64[ms]").astype(object)
            ax.vlines(t, [b[1] for b in bounds], [b[2] for b in bounds], color=style["color"], alpha=0.25, lw=6)
    if trend is not None:
        times = np.array([r.epoch_utc for r in results if r.epoch_utc is not None], dtype="datetime64[ns]")
        grid = times.min() + (times.max() - times.min()) * np.linspace(-0.02, 1.02, 50)
        ax.plot(
            grid.astype("datetime64[ms]").astype(object),
            trend.period_s(grid),
            color="C3",
            lw=1.2,
            label=f"trend {trend.slope_s_per_yr:+.3g} +- {trend.slope_err_s_per_yr:.2g} s/yr",
        )
    dated = np.array([r.epoch_utc for r in results if r.epoch_utc is not None], dtype="datetime64[ns]")
    if dated.size and dated.max() - dated.min() < np.timedelta64(2, "D"):
        # One night: matplotlib would span years around it; show a fortnight.
        middle = dated.min() + (dated.max() - dated.min()) / 2
        ax.set_xlim(*(middle + np.array([-7, 7]) * np.timedelta64(1, "D")).astype("datetime64[ms]").astype(object))
    ax.set_ylabel("synodic period [s]")
    ax.set_xlabel("date (UTC)")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="small")
    fig.autofmt_xdate()
    return fig


def pass_figure(result, lightcurve):
    """Three panels for one pass: light curve with model, periodogram, folded curve."""
    plt = file_pyplot()
    fig = plt.figure(figsize=(12, 6.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, height_ratios=(1, 1.1))
    ax_curve = fig.add_subplot(grid[0, :])
    ax_power = fig.add_subplot(grid[1, 0])
    ax_fold = fig.add_subplot(grid[1, 1])
    lightcurve.plot(ax_curve, s=2)
    ax_curve.set_title("")
    model = result.model
    if model is not None:
        t = np.linspace(lightcurve.t_s[0], lightcurve.t_s[-1], max(2000, 20 * int(result.n_cycles or 1)))
        ax_curve.plot(t, model.model_mag(t), color="C3", lw=0.7, alpha=0.8, label="model")
        ax_curve.plot(t, model.trend_mag(t), color="C1", lw=1.2, label="trend")
        ax_curve.legend(fontsize="small", loc="upper right")
    settings = result.settings
    periodogram = lightcurve.detrend(settings.trend_degree, settings.error_floor_mag).periodogram(
        oversampling=settings.oversampling,
        minimum_period_s=settings.minimum_period_s,
        maximum_period_s=settings.maximum_period_s,
        error_floor_mag=settings.error_floor_mag,
    )
    periodogram.plot(ax_power)
    if math.isfinite(result.peak_period_s):
        ax_power.axvline(result.peak_period_s, color="0.5", lw=0.8, ls=":", label=f"peak {result.peak_period_s:.4g} s")
    if math.isfinite(result.best_period_s):
        ax_power.axvline(
            result.best_period_s, color="C3", lw=0.9, ls="--", label=f"chosen {result.best_period_s:.4g} s"
        )
    ax_power.legend(fontsize="small")
    if model is not None:
        detrended = lightcurve.mag - model.trend_mag(lightcurve.t_s)
        folded = lightcurve.replace(mag=detrended).fold(result.best_period_s, epoch_s=model.axis.t_mid_s)
        phase = np.linspace(0, 1, 400)
        folded.plot(ax_fold, model=(phase, model.phase_curve_mag(phase)), s=2)
        ax_fold.set_ylabel(magnitude_label(lightcurve.band, lightcurve.mag_convention, detrended=True))
        ax_fold.set_title("")
    else:
        ax_fold.text(0.5, 0.5, "no period", ha="center", va="center", transform=ax_fold.transAxes)
        ax_fold.set_axis_off()
    return fig


def _fmt(value, spec: str) -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, spec)


def _table(results, rows_by_id) -> Table:
    columns = (
        "start UTC",
        "pass",
        "band",
        "site",
        "points",
        "duration s",
        "period s",
        "+- s",
        "verdict",
        "cycles",
        "FAP",
        "S/N",
        "sidereal range s",
        "reason",
    )
    rows = []
    for r in results:
        row = rows_by_id.get(r.pass_id)
        sidereal = "-" if r.synodic is None else "{:.4f} .. {:.4f}".format(*sorted(r.sidereal_bounds_s))
        rows.append(
            (
                str(np.datetime_as_string(r.epoch_utc, unit="s")).replace("T", " ") if r.epoch_utc is not None else "-",
                r.pass_id,
                r.band,
                row.site if row is not None else "-",
                str(r.n_points),
                _fmt(r.duration_s, ".1f"),
                _fmt(r.best_period_s, ".4f"),
                _fmt(r.uncertainty_s, ".4f"),
                r.verdict,
                _fmt(r.n_cycles, ".1f"),
                _fmt(r.false_alarm_probability, ".2g"),
                _fmt(r.signal_to_noise, ".1f"),
                sidereal,
                r.reason,
            )
        )
    return Table(columns, tuple(rows), numeric=frozenset({4, 5, 6, 7, 9, 10, 11}))


def build_period_report(
    archive,
    norad: int,
    *,
    name: str = "default",
    band: str | None = None,
    trend_verdicts=("confident",),
    pass_figures: bool = True,
) -> Document:
    """The report of one object's stored period results.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    norad : int
    name : str
        Name of the stored period results.
    band : str, optional
        Only this band.
    trend_verdicts : tuple of str
        Verdicts whose periods enter the trend (default: confident only).
    pass_figures : bool
        Draw the per-pass figures (the slow part of a long survey).

    Returns
    -------
    rsodb.report.html.Document

    Raises
    ------
    ValueError
        When the object has no stored period results.
    """
    rows = archive.catalog(norad, band)
    results = load_period_results(archive, norad, name, band)
    if not results:
        raise ValueError(
            f"object {norad} has no period results named {name!r} in {str(archive.path)!r} "
            f"({len(rows)} passes stored); run 'rsodb periods --archive {archive.path} --object {norad}' first"
        )
    rows_by_id = {row.pass_id: row for row in rows}
    object_name = rows[0].name if rows else str(norad)
    trend = trend_from_results(results, trend_verdicts)
    counts = {v: sum(r.verdict == v for r in results) for v in _VERDICT_STYLE}
    missing = len(rows) - len(results)

    doc = Document(f"Spin periods of {object_name} (NORAD {norad})")
    summary = (
        f"{len(results)} pass{'es' if len(results) != 1 else ''} analysed from {str(results[0].epoch_utc)[:10]} to "
        f"{str(results[-1].epoch_utc)[:10]}: " + ", ".join(f"{n} {v}" for v, n in counts.items() if n) + "."
    )
    if missing:
        summary += f" {missing} stored pass(es) have no result named {name!r} yet."
    doc = doc.add(Paragraph(summary), Raw("<p>Contents:</p>"))
    sections = ["Trend", "Passes", "Method"] + ([f"Pass {r.pass_id}" for r in results] if pass_figures else [])
    doc = doc.add(Raw("<ul>" + "".join(f'<li><a href="#{anchor(s)}">{s}</a></li>' for s in sections) + "</ul>"))

    doc = doc.add(Heading("Trend"))
    if trend is None:
        doc = doc.add(Paragraph(f"No trend: fewer than two passes with verdict {' or '.join(trend_verdicts)}."))
    else:
        doc = doc.add(
            Paragraph(
                trend.summary()
                + (
                    f"; reduced chi-square {trend.chi2_reduced:.2g}, errors scaled by {trend.birge_ratio:.2g}"
                    if math.isfinite(trend.chi2_reduced)
                    else "; two passes: no scatter estimate"
                )
            )
        )
    doc = doc.add(
        figure_from_matplotlib(
            trend_figure(results, trend),
            "Synodic period of each pass with its 1-sigma error; shaded bars: the sidereal period for either sense "
            "of rotation (phase-angle-bisector correction); line: weighted straight-line trend.",
        )
    )

    doc = doc.add(Heading("Passes"), _table(results, rows_by_id))
    settings = results[0].settings
    doc = doc.add(
        Heading("Method"),
        Paragraph(
            f"Method {results[0].method}: one-term Lomb-Scargle of the detrended magnitudes (Legendre trend of degree "
            f"{settings.trend_degree}, error floor {settings.error_floor_mag} mag) on a grid with {settings.oversampling:g} "
            f"points per 1/T; candidates {', '.join(f'{m:g}P' for m in settings.multiples)} of the peak and the "
            f"harmonic-sum peak, each refined and scored by a Fourier series with the harmonic count chosen by BIC; "
            f"verdict thresholds: FAP <= {settings.fap_threshold:g}, S/N >= {settings.snr_threshold:g}, at least "
            f"{settings.min_cycles:g} cycles, BIC margin {settings.bic_margin:g}, and phase dispersion confirming the "
            f"period over its sub-multiples. Periods are synodic; see docs/periods.md."
        ),
    )

    if pass_figures:
        for result in results:
            doc = doc.add(Heading(f"Pass {result.pass_id}", level=2), Paragraph(result.summary(), css_class="meta"))
            try:
                lightcurve = LightCurve.from_pass(archive.get(result.pass_id))
            except (LookupError, ValueError) as error:
                doc = doc.add(Paragraph(f"pass data unavailable: {error}"))
                continue
            doc = doc.add(
                figure_from_matplotlib(
                    pass_figure(result, lightcurve),
                    "Top: magnitudes with the fitted model (red) and trend (orange). Left: Lomb-Scargle power, "
                    "peak (dotted) and chosen period (dashed). Right: folded on the chosen period, trend removed, "
                    "coloured by cycle, with the Fourier model.",
                )
            )
    return doc
