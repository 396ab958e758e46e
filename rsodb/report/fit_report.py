"""The report of one object's fits: spin period and parameters against date, a table of every
pass with its trust level, and per pass the spin state with intervals, the verdicts in words,
the observed curve with the posterior band and residuals, corner and trace plots, and the
period search's periodogram and folded curve."""

from __future__ import annotations

import math

import numpy as np

from rsodb.campaign.period_survey import load_period_results
from rsodb.fit.plots import corner_figure, fold_worth, folded_figure, lightcurve_figure, trace_figure
from rsodb.fit.result import FitResult
from rsodb.periods.lightcurve import LightCurve
from rsodb.plotting import magnitude_label
from rsodb.report.html import Document, Heading, Paragraph, Raw, Table, anchor, figure_from_matplotlib
from rsodb.report.period_report import pass_figure
from rsodb.report.spin_state import axis_text, spin_state_rows
from rsodb.report.trust import assess

__all__ = [
    "build_campaign_report",
    "folded_blocks",
    "load_fits",
    "parameters_figure",
    "period_figure",
]


def load_fits(archive, norad: int, name: str = "default", band: str | None = None) -> list:
    """The stored `FitResult` of every pass of an object that has a fit called `name`, by date."""
    results = []
    for row in archive.summaries(norad, band):
        if name in archive.result_names(row.pass_id, "fits"):
            results.append(archive.load_result(row.pass_id, "fits", name, FitResult.from_hdf5))
    return results


def _date_axis(axis) -> None:
    """Concise date labels (one night of passes reads as times, a season as dates)."""
    # matplotlib loads in about a second; only drawing needs it.
    import matplotlib.dates as mdates

    locator = mdates.AutoDateLocator()
    axis.xaxis.set_major_locator(locator)
    axis.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))


def _dates(results):
    return np.array([r.time_utc[0] for r in results], dtype="datetime64[ns]").astype("datetime64[ms]").astype(object)


def parameters_figure(results):
    """Median and 16/84 percentiles of every free parameter against the pass date."""
    # matplotlib loads in about a second; only drawing needs it.
    from matplotlib.figure import Figure

    names = sorted(
        {n for r in results for n in r.names}, key=lambda n: min(r.names.index(n) for r in results if n in r.names)
    )
    figure = Figure(figsize=(9, 1.9 * len(names) + 0.6), layout="constrained")
    axes = np.atleast_1d(figure.subplots(len(names), 1, sharex=True))
    for axis, name in zip(axes, names):
        chosen = [r for r in results if name in r.names]
        i = [r.names.index(name) for r in chosen]
        median = np.array([r.median[j] for r, j in zip(chosen, i)])
        low = median - np.array([r.p16[j] for r, j in zip(chosen, i)])
        high = np.array([r.p84[j] for r, j in zip(chosen, i)]) - median
        colours = ["C0" if r.converged else "C3" for r in chosen]
        for date, m, lo, hi, colour in zip(_dates(chosen), median, low, high, colours):
            axis.errorbar([date], [m], yerr=[[lo], [hi]], fmt="o", ms=4, color=colour, capsize=2)
        axis.set_ylabel(chosen[0].space.labels[i[0]], fontsize=8)
        axis.grid(alpha=0.3)
    axes[0].set_title("Posterior median with 16/84 percentiles per pass (red: chain not converged)", fontsize=9)
    axes[-1].set_xlabel("pass date (UTC)")
    _date_axis(axes[-1])
    return figure


def period_figure(results, periods):
    """Fitted spin period beside the periodogram's period (and its multiples) per pass."""
    # matplotlib loads in about a second; only drawing needs it.
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 4), layout="constrained")
    axis = figure.subplots()
    fitted = [r for r in results if "spin_period_s" in r.names]
    for r, date in zip(fitted, _dates(fitted)):
        j = r.names.index("spin_period_s")
        axis.errorbar(
            [date],
            [r.median[j]],
            yerr=[[r.median[j] - r.p16[j]], [r.p84[j] - r.median[j]]],
            fmt="o",
            color="C0" if r.converged else "C3",
            ms=5,
            capsize=2,
        )
    shown = [p for p in periods if math.isfinite(p.best_period_s) and p.epoch_utc is not None]
    # 4x the periodogram period only when some fit is up there: otherwise it squeezes the axis.
    fit_max = max((r.p84[r.names.index("spin_period_s")] for r in fitted), default=0.0)
    multiples = (2, 4) if any(fit_max > 3 * p.best_period_s for p in shown) else (2,)
    for p in shown:
        date = np.datetime64(p.epoch_utc, "ms").astype(object)
        axis.errorbar([date], [p.best_period_s], yerr=[p.uncertainty_s], fmt="s", mfc="none", color="C2", ms=6)
        for multiple in multiples:
            axis.plot([date], [multiple * p.best_period_s], "x", color="0.6", ms=5)
    axis.plot([], [], "o", color="C0", label="MCMC fit, median and 16/84 (converged)")
    axis.plot([], [], "o", color="C3", label="MCMC fit, chain not converged")
    axis.plot([], [], "s", mfc="none", color="C2", label="periodogram (synodic), 1 sigma")
    axis.plot([], [], "x", color="0.6", label=" and ".join(f"{m}x" for m in multiples) + " the periodogram period")
    axis.set_ylabel("spin period [s]")
    axis.set_xlabel("pass date (UTC)")
    _date_axis(axis)
    axis.legend(fontsize=8, loc="best")
    axis.grid(alpha=0.3)
    return figure


def _cell(value: float, fmt: str = ".4g") -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, fmt)


def _table(results, periods_by_id) -> Table:
    rows = []
    for r in results:
        p = periods_by_id.get(r.pass_id)
        spin = ""
        if "spin_period_s" in r.names:
            j = r.names.index("spin_period_s")
            spin = f"{r.median[j]:.4f} -{r.median[j] - r.p16[j]:.4f} +{r.p84[j] - r.median[j]:.4f}"
        periodogram = (
            "-"
            if p is None or not math.isfinite(p.best_period_s)
            else f"{p.best_period_s:.4f} +-{p.uncertainty_s:.4f} ({p.verdict})"
        )
        rows.append(
            (
                r.pass_id,
                str(r.time_utc[0])[:19],
                str(r.mag_obs.size),
                spin,
                periodogram,
                _cell(r.residual_rms_mag, ".3f"),
                _cell(r.residual_rms_by_sight()[1], ".3f"),
                _cell(r.reduced_chi2, ".2f"),
                _cell(r.jitter_mag, ".3f"),
                "yes" if r.converged else "no",
                axis_text(r),
                assess(r, p).text(),
            )
        )
    return Table(
        (
            "pass",
            "start UTC",
            "n",
            "spin period fit [s]",
            "periodogram [s]",
            "resid. RMS [mag]",
            "RMS between the fit's samples [mag]",
            "red. chi2",
            "jitter [mag]",
            "converged",
            "spin axis",
            "trust",
        ),
        tuple(rows),
        numeric=frozenset({2, 5, 6, 7, 8}),
        sortable=True,
    )


def build_campaign_report(
    archive,
    norad: int,
    *,
    name: str = "default",
    periods_name: str = "default",
    band: str | None = None,
    pass_figures: bool = True,
) -> Document:
    """The report of one object's stored fits.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    norad : int
    name : str
        Name of the stored fits.
    periods_name : str
        Name of the stored period results shown beside them.
    band : str, optional
    pass_figures : bool
        Add each pass's observed and best-fit light curve.

    Raises
    ------
    ValueError
        When the object has no stored fits of that name.
    """
    rows = archive.summaries(norad, band)
    results = load_fits(archive, norad, name, band)
    if not results:
        others = sorted({n for row in rows for n in archive.result_names(row.pass_id, "fits")})
        fix = (
            f"its fits are named {', '.join(map(repr, others))}: give --name {others[0]}"
            if others
            else f"run 'rsodb campaign --archive {archive.path} --object {norad}' first"
        )
        raise ValueError(
            f"object {norad} has no fits named {name!r} in {str(archive.path)!r} ({len(rows)} passes stored); {fix}"
        )
    periods = load_period_results(archive, norad, periods_name, band)
    periods_by_id = {p.pass_id: p for p in periods}
    object_name = rows[0].name if rows else str(norad)
    converged = sum(r.converged for r in results)
    misfits = sum(any(f.startswith("model misfit") for f in r.flags) for r in results)
    shapes = sorted({str(r.config.get("shape", "?")) for r in results})
    attitudes = sorted({str(r.config.get("model", {}).get("attitude", "?")) for r in results})

    doc = Document(f"Spin-state fits of {object_name} (NORAD {norad}), fit {name!r}")
    doc = doc.add(
        Paragraph(
            f"{len(results)} of {len(rows)} stored passes fitted ({str(results[0].time_utc[0])[:10]} to "
            f"{str(results[-1].time_utc[0])[:10]}); shape {', '.join(shapes)}, attitude model {', '.join(attitudes)}. "
            f"{converged} chain(s) converged by the autocorrelation criterion; {misfits} fit(s) flagged as a model "
            "misfit (residuals well above the quoted errors, absorbed by the jitter term)."
        )
    )
    sections = ["Spin period", "Parameters against date", "Passes", "Method"] + (
        [f"Pass {r.pass_id}" for r in results] if pass_figures else []
    )
    doc = doc.add(Raw("<ul>" + "".join(f'<li><a href="#{anchor(s)}">{s}</a></li>' for s in sections) + "</ul>"))
    doc = doc.add(
        Heading("Spin period"),
        figure_from_matplotlib(
            period_figure(results, periods),
            "Spin period of each pass from the MCMC fit (posterior median, 16/84 percentiles) and from the "
            "periodogram (synodic, 1 sigma). The light curve of a body with two similar halves repeats at half its "
            "spin period, so the fit may sit at 2x the periodogram's value; a precessing spin axis also shifts the "
            "light curve's period from the spin period by about cos(theta) P / P_pr.",
        ),
    )
    doc = doc.add(
        Heading("Parameters against date"),
        figure_from_matplotlib(parameters_figure(results), "Every free parameter of the fits against the pass date."),
    )
    doc = doc.add(Heading("Passes"), _table(results, periods_by_id))
    first = results[0]
    doc = doc.add(
        Heading("Method"),
        Paragraph(
            f"emcee ensemble sampler ({first.n_walkers} walkers x {first.n_steps} steps, first {first.discard} "
            f"dropped as burn-in), walkers started around the best point of a differential-evolution search; "
            f"likelihood {first.likelihood!r} with the observed errors, a fitted jitter term and the magnitude "
            "offset marginalised analytically; convergence when the kept chain is at least 50 autocorrelation "
            "times long with a healthy acceptance fraction. See docs/fitting.md."
        ),
    )
    if pass_figures:
        for r in results:
            doc = doc.add(*_pass_section(archive, r, periods_by_id.get(r.pass_id)))
    return doc


def _pass_section(archive, fit, period) -> list:
    """The blocks of one pass: trust and verdicts in words, the spin-state table, the observed
    curve with the posterior band, corner and trace plots, and the period search's figure."""
    trust = assess(fit, period)
    blocks = [
        Heading(f"Pass {fit.pass_id}"),
        Paragraph(f"Trust: {trust.text()}.", css_class=f"trust-{trust.level}"),
        Paragraph(f"Convergence: {fit.verdict}"),
    ]
    blocks += [Paragraph(f"Warning: {flag}", css_class="meta") for flag in fit.flags]
    if fit.selection:
        blocks.append(Paragraph(f"Fitted: {fit.selection}.", css_class="meta"))
    blocks.append(
        Table(
            ("quantity", "median -/+ (16-84%)", "unit", "meaning"),
            tuple(spin_state_rows(fit)),
            caption=f"Spin state of fit {fit.name!r}"
            + (f" (phases at {fit.epoch_utc} UTC, the fitted window's mid-time)" if fit.epoch_utc else ""),
        )
    )
    try:
        stored = archive.get(fit.pass_id)
    except (LookupError, ValueError) as error:
        stored, unavailable = None, error
    mag_label = magnitude_label(stored.band, stored.mag_convention) if stored is not None else "magnitude"
    blocks.append(
        figure_from_matplotlib(
            lightcurve_figure(fit, mag_label=mag_label),
            "The whole pass: observed magnitudes, the model as a continuous curve with the band of its posterior "
            "draws, the fitted window shaded, and the residual of every sample.",
        )
    )
    blocks.extend(
        folded_blocks(
            fit,
            "The pass folded at {period} s in consecutive stretches: the shape of each cycle and where the model "
            "misses it, with each stretch's residual RMS.",
            mag_label=mag_label,
        )
    )
    blocks.append(
        figure_from_matplotlib(
            corner_figure(fit),
            "Posterior of the free parameters (stored draws): 16, 50 and 84% marked.",
            dpi=80,
        )
    )
    try:
        blocks.append(
            figure_from_matplotlib(
                trace_figure(fit), "Every walker's trace per parameter; the burn-in dropped is shaded.", dpi=80
            )
        )
    except (FileNotFoundError, OSError) as error:
        blocks.append(Paragraph(f"No trace plot: {error}", css_class="meta"))
    if period is None:
        blocks.append(Paragraph("No period search stored for this pass.", css_class="meta"))
        return blocks
    blocks.append(Paragraph(f"Period search: {period.summary()}", css_class="meta"))
    if stored is None:
        blocks.append(Paragraph(f"No periodogram: the pass's data are unavailable ({unavailable}).", css_class="meta"))
        return blocks
    blocks.append(
        figure_from_matplotlib(
            pass_figure(period, LightCurve.from_pass(stored)),
            "Period search of the same pass. Top: magnitudes with the Fourier model and trend. Left: Lomb-Scargle "
            "power with the peak and the chosen period. Right: folded on the chosen period, trend removed, "
            "coloured by cycle.",
        )
    )
    return blocks


def folded_blocks(fit, caption: str, mag_label: str = "magnitude", whole_pass: bool = False) -> list:
    """The folded figure of a fit (`rsodb.fit.plots.folded_figure`) as a report block, when its
    pass holds enough cycles for one (`fold_worth`); `caption` may name ``{period}``."""
    period_s = fold_worth(fit)
    if not period_s:
        return []
    figure = folded_figure(fit, period_s=period_s, mag_label=mag_label, whole_pass=whole_pass)
    return [figure_from_matplotlib(figure, caption.format(period=f"{period_s:.5g}"))]
