"""The period survey report of one object: spin trend, table, and each pass's periodogram and folded curve.

Built from the period results stored by `rsodb periods` (`rsodb.campaign.period_survey`) and the
passes themselves (to draw the periodograms and folded light curves):

1. a summary, and the spin trend in words (`rsodb.periods.trend`: epochs, the minimum span,
   "spinning up/down" only at 2 sigma, otherwise "no significant trend" with the bound);
2. period against date (dated axis) with 1-sigma error bars, coloured by verdict, the epochs
   and the trend line through them;
3. a table of every pass (period, error, verdict, cycles, false-alarm probability, S/N,
   sidereal range, reason);
4. per pass: its candidates with their errors, the light curve with the fitted model, the
   Lomb-Scargle periodogram with the candidates marked, and the curve folded on the reported
   period; every axis is scaled to the data, never to a model.

Use `build_period_report(archive, norad)` from Python or
``rsodb report periods --archive DIR --object N --out FILE.html``.
"""

from __future__ import annotations

import math

import numpy as np

from rsodb.campaign.period_survey import load_period_results
from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.trend import DEFAULT_MIN_SPAN_DAYS, SIGNIFICANCE_SIGMA, trend_from_results
from rsodb.periods.verdicts import VERDICTS
from rsodb.plotting import file_pyplot, magnitude_label
from rsodb.report.html import Document, Heading, Paragraph, Raw, Table, anchor, figure_from_matplotlib

__all__ = [
    "build_period_report",
    "trend_figure",
    "pass_figure",
    "candidates_table",
]

_VERDICT_STYLE = {
    "confident": {"color": "C0", "marker": "o"},
    "ambiguous harmonic": {"color": "C1", "marker": "s"},
    "aliased": {"color": "C4", "marker": "D"},
    "non-periodic": {"color": "0.6", "marker": "v"},
    "single glint": {"color": "0.6", "marker": "*"},
    "too short": {"color": "0.6", "marker": "^"},
    "no signal": {"color": "0.6", "marker": "x"},
}
# Verdicts whose periods are drawn on the trend plot.
_DRAWN = ("confident", "ambiguous harmonic")


def _dates(times) -> list:
    """datetime64 values as Python datetimes, which matplotlib's date axis understands."""
    return list(np.asarray(times, dtype="datetime64[ms]").astype(object))


def _date_axis(ax, times) -> None:
    """A date axis over `times` (padded by 5%, at least an hour each side), labelled concisely."""
    # Deferred like pyplot itself: only drawing needs matplotlib.
    import matplotlib.dates as mdates

    times = np.asarray(times, dtype="datetime64[ns]")
    pad = max((times.max() - times.min()) * 0.05, np.timedelta64(1, "h"))
    ax.set_xlim(*_dates([times.min() - pad, times.max() + pad]))
    locator = mdates.AutoDateLocator(minticks=3, maxticks=8)
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))


def _limits(values, margin: float = 0.08, floor: float = 0.0):
    """(low, high) of finite `values` widened by `margin` of their range (at least `floor`)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    low, high = float(values.min()), float(values.max())
    pad = max(margin * (high - low), floor)
    return low - pad, high + pad


def trend_figure(results, spin_trend=None):
    """Period against date with error bars, by verdict, the epochs and the trend line; returns the figure.

    Parameters
    ----------
    results : sequence of PeriodResult
    spin_trend : rsodb.periods.trend.SpinTrend, optional
    """
    plt = file_pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    shown = []
    for verdict, style in _VERDICT_STYLE.items():
        chosen = [
            r for r in results if r.verdict == verdict and math.isfinite(r.best_period_s) and r.epoch_utc is not None
        ]
        if not chosen or verdict not in _DRAWN:
            continue
        middles = [r.epoch_utc + np.timedelta64(int(r.duration_s * 5e8), "ns") for r in chosen]
        shown += [(t, r.best_period_s, r.uncertainty_s) for t, r in zip(middles, chosen)]
        ax.errorbar(
            _dates(middles),
            [r.best_period_s for r in chosen],
            yerr=[r.uncertainty_s for r in chosen],
            ls="none",
            capsize=3,
            label=f"{verdict} ({len(chosen)})",
            **style,
        )
        bounds = [(t, *sorted(r.sidereal_bounds_s)) for t, r in zip(middles, chosen) if r.synodic is not None]
        if bounds:
            ax.vlines(
                _dates([b[0] for b in bounds]),
                [b[1] for b in bounds],
                [b[2] for b in bounds],
                color=style["color"],
                alpha=0.25,
                lw=6,
            )
    epochs = spin_trend.epochs if spin_trend is not None else ()
    if len(epochs) > 0 and any(e.n_passes > 1 for e in epochs):
        ax.errorbar(
            _dates([e.time_utc for e in epochs]),
            [e.period_s for e in epochs],
            yerr=[e.period_err_s for e in epochs],
            ls="none",
            marker="_",
            ms=18,
            color="k",
            capsize=5,
            label="epoch (one night)",
        )
    trend = spin_trend.trend if spin_trend is not None else None
    if trend is not None:
        first, last = epochs[0].time_utc, epochs[-1].time_utc
        grid = first + (last - first) * np.linspace(0.0, 1.0, 50)
        line, error = trend.period_s(grid), trend.period_err_s(grid)
        ax.plot(_dates(grid), line, color="C3", lw=1.2, label=f"trend: {trend.sense}")
        ax.fill_between(_dates(grid), line - error, line + error, color="C3", alpha=0.15, lw=0)
    if shown:
        times = np.array([t for t, _, _ in shown], dtype="datetime64[ns]")
        _date_axis(ax, times)
        values = [p + s * e for _, p, e in shown for s in (-1, 1) if math.isfinite(e)] + [p for _, p, _ in shown]
        ax.set_ylim(*_limits(values, floor=1e-4))
    else:
        ax.text(0.5, 0.5, "no pass names a period", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel("synodic period [s]")
    ax.set_xlabel("date (UTC)")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="small")
    return fig


def candidates_table(result, count: int = 6) -> Table:
    """The first `count` candidates of a result with their errors, cycles and scores."""
    rows = []
    for c in result.candidates[:count]:
        rows.append(
            (
                c.label,
                _fmt(c.period_s, ".4f"),
                _fmt(c.uncertainty_s, ".2g"),
                _fmt(c.n_cycles, ".2f"),
                str(c.n_harmonics),
                str(c.trend_degree),
                _fmt(c.delta_bic, ".1f"),
            )
        )
    return Table(
        ("candidate", "period s", "+- s", "cycles", "harmonics", "trend degree", "BIC - reported"),
        tuple(rows),
        caption="Candidates, the reported one first (BIC differences above 10 are very strong evidence).",
        numeric=frozenset({1, 2, 3, 4, 5, 6}),
    )


def pass_figure(result, lightcurve):
    """Three panels for one pass: light curve with model, periodogram with candidates, folded curve.

    Every axis range comes from the data: a model that swings beyond them is clipped, not followed.
    """
    plt = file_pyplot()
    fig = plt.figure(figsize=(12, 6.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, height_ratios=(1, 1.1))
    ax_curve = fig.add_subplot(grid[0, :])
    ax_power = fig.add_subplot(grid[1, 0])
    ax_fold = fig.add_subplot(grid[1, 1])
    lightcurve.plot(ax_curve, s=2)
    ax_curve.set_title("")
    low, high = _limits(np.percentile(lightcurve.mag, [0.2, 99.8]), margin=0.15, floor=0.05)
    ax_curve.set_ylim(high, low)  # brighter up
    ax_curve.set_xlim(lightcurve.t_s[0], lightcurve.t_s[-1])
    model = result.model
    if model is not None:
        t = np.linspace(lightcurve.t_s[0], lightcurve.t_s[-1], max(2000, 20 * int(result.n_cycles or 1)))
        ax_curve.plot(t, model.model_mag(t), color="C3", lw=0.7, alpha=0.8, label="model")
        ax_curve.plot(t, model.trend_mag(t), color="C1", lw=1.2, label=f"trend (degree {model.trend_degree})")
        ax_curve.legend(fontsize="small", loc="upper right")
    settings = result.settings
    degree = model.trend_degree if model is not None else settings.trend_degree
    periodogram = lightcurve.detrend(degree, settings.error_floor_mag).periodogram(
        oversampling=settings.oversampling,
        minimum_period_s=settings.minimum_period_s,
        maximum_period_s=settings.maximum_period_s,
        error_floor_mag=settings.error_floor_mag,
    )
    periodogram.plot(ax_power)
    ax_power.set_xlim(periodogram.period_s.min(), periodogram.period_s.max())
    if math.isfinite(result.peak_period_s):
        ax_power.axvline(result.peak_period_s, color="0.5", lw=0.8, ls=":", label=f"peak {result.peak_period_s:.4g} s")
    for i, c in enumerate(result.candidates[:3]):
        if not (periodogram.period_s.min() <= c.period_s <= periodogram.period_s.max()):
            continue
        ax_power.axvspan(
            c.period_s - c.uncertainty_s, c.period_s + c.uncertainty_s, color=f"C{3 + i}", alpha=0.25, lw=0
        )
        ax_power.axvline(
            c.period_s,
            color=f"C{3 + i}",
            lw=0.9,
            ls="--",
            label=f"{'reported' if i == 0 else 'candidate'} {c.period_s:.4g} +- {c.uncertainty_s:.2g} s "
            f"({c.n_cycles:.1f} cycles)",
        )
    ax_power.legend(fontsize="small")
    if model is not None:
        detrended = lightcurve.mag - model.trend_mag(lightcurve.t_s)
        folded = lightcurve.replace(mag=detrended).fold(result.best_period_s, epoch_s=model.axis.t_mid_s)
        phase = np.linspace(0, 1, 400)
        folded.plot(ax_fold, model=(phase, model.phase_curve_mag(phase)), s=2)
        low, high = _limits(np.percentile(detrended, [0.2, 99.8]), margin=0.15, floor=0.05)
        ax_fold.set_ylim(high, low)
        ax_fold.set_ylabel(magnitude_label(lightcurve.band, lightcurve.mag_convention, detrended=True))
        ax_fold.set_title(f"{result.verdict}: folded on {result.best_period_s:.4g} s ({result.n_cycles:.1f} cycles)")
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
    min_span_days: float = DEFAULT_MIN_SPAN_DAYS,
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
    min_span_days : float
        Fewest days between the first and last epoch for a trend.

    Returns
    -------
    rsodb.report.html.Document

    Raises
    ------
    ValueError
        When the object has no stored period results.
    """
    rows = archive.summaries(norad, band)
    results = load_period_results(archive, norad, name, band)
    if not results:
        raise ValueError(
            f"object {norad} has no period results named {name!r} in {str(archive.path)!r} "
            f"({len(rows)} passes stored); run 'rsodb periods --archive {archive.path} --object {norad}' first"
        )
    rows_by_id = {row.pass_id: row for row in rows}
    object_name = rows[0].name if rows else str(norad)
    spin_trend = trend_from_results(results, trend_verdicts, min_span_days=min_span_days)
    counts = {v: sum(r.verdict == v for r in results) for v in VERDICTS}
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
    doc = doc.add(
        Paragraph(
            f"Spin trend from the passes with verdict {' or '.join(trend_verdicts)}: {spin_trend.summary()}. "
            f"Passes less than 12 h apart are one epoch (one spin state); a trend needs epochs at least "
            f"{min_span_days:g} days apart, and a spin-up or spin-down is claimed only {SIGNIFICANCE_SIGMA:g} "
            "standard errors from zero."
        )
    )
    doc = doc.add(
        figure_from_matplotlib(
            trend_figure(results, spin_trend),
            "Synodic period of each pass with its 1-sigma error, at the middle of the pass; shaded bars: the "
            "sidereal period for either sense of rotation (phase-angle-bisector correction); black bars: epochs "
            "(passes of one night merged); line and band: the weighted straight-line trend through the epochs "
            "and its 1-sigma error, drawn only where there are epochs.",
        )
    )

    doc = doc.add(Heading("Passes"), _table(results, rows_by_id))
    settings = results[0].settings
    doc = doc.add(
        Heading("Method"),
        Paragraph(
            f"Method {results[0].method}: one-term Lomb-Scargle of the detrended magnitudes on a grid with "
            f"{settings.oversampling:g} points per 1/T (error floor {settings.error_floor_mag} mag); candidates "
            f"{', '.join(f'{m:g}P' for m in settings.multiples)} of the peak and the harmonic-sum peak, each refined "
            f"and scored by a Fourier series plus a Legendre trend in time whose degree (at most "
            f"{settings.trend_degree}) is held to the candidate's cycles and chosen with the harmonic count by BIC, "
            "by generalised least squares when the residuals are correlated (AR(1)); the reported period is the "
            "best that repeats at least twice. Verdicts (no signal, single glint, too short, non-periodic, aliased, "
            f"ambiguous harmonic, confident) with FAP <= {settings.fap_threshold:g}, S/N >= "
            f"{settings.snr_threshold:g}, at least {settings.min_cycles:g} cycles, BIC margin {settings.bic_margin:g} "
            "(in the whole pass and half of it in each half), and phase dispersion confirming the period over its "
            "sub-multiples. Periods are synodic; see docs/periods.md."
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
            if result.candidates:
                doc = doc.add(candidates_table(result))
            doc = doc.add(
                figure_from_matplotlib(
                    pass_figure(result, lightcurve),
                    "Top: magnitudes with the fitted model (red) and trend (orange). Left: Lomb-Scargle power, "
                    "peak (dotted), the reported period and the next candidates (dashed, shaded over +-1 sigma). "
                    "Right: folded on the reported period, trend removed, coloured by cycle, with the Fourier "
                    "model. Axes are scaled to the data.",
                )
            )
    return doc
