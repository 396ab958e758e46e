"""The ladder section of a report: every rung's training and held-out RMS side by side, and the
chosen rung's fit over the whole pass (training window shaded, held-out samples after it)."""

from __future__ import annotations

import math

import numpy as np

from rsodb.campaign.ladder import DARK_STATUS
from rsodb.fit.plots import lightcurve_figure
from rsodb.fit.result import FitResult
from rsodb.report.fit_report import folded_blocks
from rsodb.report.html import Document, Heading, Paragraph, Table, figure_from_matplotlib

__all__ = ["build_ladder_report", "ladder_section", "scores_figure", "scores_table"]


def _cell(value: float, spec: str = ".3f") -> str:
    return format(value, spec) if math.isfinite(value) else "-"


def scores_table(ladder) -> Table:
    """One row per rung, simplest first: parameters, training and held-out RMS, convergence."""
    rows = []
    for s in ladder.scores:
        role = "chosen" if s.rung == ladder.chosen else ("best held-out" if s.rung == ladder.best else "")
        rows.append(
            (
                s.rung,
                str(s.n_parameters or "-"),
                _cell(s.train_rms_mag),
                _cell(s.heldout_rms_mag),
                _cell(s.heldout_rms_mag - ladder.score(ladder.best).heldout_rms_mag) if ladder.best else "-",
                _cell(ladder.margin_mag(s)) if s.ok else "-",
                str(s.n_heldout),
                _cell(s.reduced_chi2, ".1f"),
                _cell(s.light_curve_period_s, ".4f"),
                "yes" if s.converged else "no",
                role or s.status,
            )
        )
    naive = ladder.naive
    if naive is not None:
        best = ladder.score(ladder.best).heldout_rms_mag if ladder.best else math.nan
        rows.append(
            (
                f"no model: the last training cycle repeated ({naive.period_s:.4f} s)",
                "0",
                "-",
                _cell(naive.heldout_rms_mag),
                _cell(naive.heldout_rms_mag - best),
                "-",
                str(naive.n_heldout),
                "-",
                "-",
                "-",
                "yardstick",
            )
        )
    return Table(
        (
            "rung",
            "free parameters",
            "training RMS (mag)",
            "held-out RMS (mag)",
            "minus best",
            "margin (mag)",
            "held-out samples",
            "reduced chi2",
            "period search on the model curve (s)",
            "converged",
            "",
        ),
        tuple(rows),
        caption=f"ladder {ladder.name!r} of {ladder.pass_id}: simplest rung first",
        numeric=frozenset(range(1, 10)),
    )


def scores_figure(ladder):
    """Training and held-out RMS of every rung as paired bars (held-out with the bootstrap standard
    error of its difference from the best); the margin floor above the best as a band."""
    # matplotlib loads in about a second; only drawing needs it.
    from matplotlib.figure import Figure

    scored = [s for s in ladder.scores if s.ok]
    figure = Figure(figsize=(max(5.0, 1.1 * len(ladder.scores) + 2), 3.6), layout="constrained")
    axis = figure.subplots()
    x = np.arange(len(ladder.scores))
    axis.bar(x - 0.2, [s.train_rms_mag for s in ladder.scores], 0.4, color="0.7", label="training window")
    colours = ["C3" if s.rung == ladder.chosen else "C0" for s in ladder.scores]
    errors = [s.heldout_se_mag if math.isfinite(s.heldout_se_mag) else 0.0 for s in ladder.scores]
    axis.bar(
        x + 0.2, [s.heldout_rms_mag for s in ladder.scores], 0.4, yerr=errors, color=colours, label="held out (+- SE)"
    )
    if scored and ladder.best:
        best = ladder.score(ladder.best).heldout_rms_mag
        axis.axhspan(best, best + ladder.margin_floor_mag, color="C2", alpha=0.25, label="best + margin floor")
    if ladder.naive is not None:
        axis.axhline(
            ladder.naive.heldout_rms_mag, color="k", ls="--", lw=1, label="held out, no model (last cycle repeated)"
        )
    for position, s in zip(x, ladder.scores):
        if s.status.startswith(DARK_STATUS):
            # No bar to draw: the model is dark where the object was seen (its status says where).
            axis.annotate("dark", (position + 0.2, 0.0), ha="center", va="bottom", fontsize=7, color="C3")
    axis.set_xticks(x, [s.rung for s in ladder.scores], rotation=25, ha="right", fontsize=8)
    axis.set_ylabel("residual RMS (mag)")
    axis.set_title(f"{ladder.pass_id}: chosen {ladder.chosen or 'none'} (red)", fontsize=9)
    axis.legend(fontsize=7, loc="best")
    return figure


def ladder_section(archive, ladder) -> list:
    """Report blocks for one pass's ladder: heading, scores table and figure, the chosen rung's curve."""
    blocks = [Heading(f"Model ladder: {ladder.pass_id}", 3), scores_table(ladder)]
    if ladder.naive is not None:
        blocks.append(
            Paragraph(
                "Yardstick: " + ladder.naive_text() + ". A rung that predicts worse than repeating the last "
                "training cycle has not caught how the light curve changes over the pass."
            )
        )
    blocks.append(figure_from_matplotlib(scores_figure(ladder), "training and held-out RMS of every rung"))
    if not ladder.chosen:
        blocks.append(Paragraph("No rung has a stored fit with held-out samples; nothing was chosen."))
        return blocks
    chosen = ladder.score(ladder.chosen)
    result = archive.load_result(ladder.pass_id, "fits", chosen.fit_name, FitResult.from_hdf5)
    blocks.append(
        Paragraph(
            f"Chosen: {chosen.rung} (fit {chosen.fit_name!r}), the simplest rung whose held-out RMS is within "
            f"its margin of the best ({ladder.best}). {result.verdict}."
        )
    )
    blocks.append(
        figure_from_matplotlib(
            lightcurve_figure(result),
            f"{chosen.rung} over the whole pass: fitted up to {ladder.train_end_utc} UTC (shaded), held out after",
        )
    )
    caption = (
        f"{chosen.rung}, observed and best fit folded at {{period}} s in consecutive stretches of the pass "
        "(the held-out samples in blue), each with its residual RMS"
    )
    blocks.extend(folded_blocks(result, caption, whole_pass=True))
    return blocks


def build_ladder_report(archive, ladders, title: str = "Model ladders") -> Document:
    """A document with one ladder section per pass."""
    document = Document(title).add(
        Paragraph(
            "Each rung is fitted on the first part of its pass and scored on the rest; the simplest rung "
            "within max(margin floor, bootstrap standard error) of the best held-out RMS is chosen "
            "(docs/real_passes.md)."
        )
    )
    for ladder in ladders:
        document = document.add(*ladder_section(archive, ladder))
    return document
