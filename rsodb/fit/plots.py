"""Figures of a fit: corner plot, observed vs synthetic light curve with residuals, traces.

Each function returns a ``matplotlib.figure.Figure`` (built without pyplot, so it is safe in
worker processes and threads) and saves it when given a path.

>>> from rsodb.fit.plots import lightcurve_figure    # doctest: +SKIP
>>> lightcurve_figure(result, "fit.png")              # doctest: +SKIP
"""

from __future__ import annotations

import logging
from pathlib import Path
import textwrap

import numpy as np

from rsodb.fit.conventions import azimuth_elevation, comparable_convention
from rsodb.fit.likelihood import NormalisedLikelihood
from rsodb.fit.sampler import read_chain

__all__ = [
    "corner_figure",
    "lightcurve_figure",
    "folded_figure",
    "fold_worth",
    "prediction_figure",
    "glint_map_figure",
    "trace_figure",
    "save_all",
]

# A pass of at least this many light-curve cycles also gets the folded figure: the whole-pass
# plot cannot show the shape of one cycle when dozens are side by side.
FOLD_MIN_CYCLES = 8


def _figure(width_in: float, height_in: float, layout: str | None = "constrained"):
    # matplotlib loads in about a second; only drawing needs it.
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), layout=layout)


def _saved(figure, path, dpi: int = 110):
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(path, dpi=dpi)
    return figure


def corner_figure(result, path=None, truths=None):
    """Corner plot of the stored posterior samples (the ``corner`` package).

    Parameters
    ----------
    result : FitResult
    path : str or Path, optional
        Where to save the figure.
    truths : mapping of str to float, optional
        True values to mark (injection tests).
    """
    # corner (and matplotlib under it) loads in about a second; only drawing needs it.
    import corner

    ndim = len(result.names)
    # No layout engine: corner places its panels itself (subplots_adjust), which a constrained
    # layout would refuse with a warning.
    figure = _figure(1.5 * ndim + 1, 1.5 * ndim + 1, layout=None)
    marks = None if truths is None else [truths.get(n) for n in result.names]
    quiet = _WithoutContourWarnings()
    logging.getLogger().addFilter(quiet)
    try:
        _corner(corner, result, figure, marks)
    finally:
        logging.getLogger().removeFilter(quiet)
    figure.suptitle(f"{result.pass_id}: posterior of fit {result.name!r}", fontsize=10)
    return _saved(figure, path, dpi=80)


class _WithoutContourWarnings(logging.Filter):
    """Drops corner's root-logger warning for a panel whose draws are too concentrated for
    contours (a clump of a short chain): the panel shows the draws anyway, and the warning
    would be printed once per panel per fit."""

    def filter(self, record) -> bool:
        return "Too few points to create valid contours" not in record.getMessage()


def _corner(corner, result, figure, marks) -> None:
    corner.corner(
        np.asarray(result.samples),
        fig=figure,
        labels=list(result.space.labels),
        quantiles=[0.16, 0.5, 0.84],
        show_titles=True,
        title_fmt=".4g",
        truths=marks,
        title_kwargs={"fontsize": 9},
        label_kwargs={"fontsize": 9},
        # Three ticks and labels set off from them: more overlap at 1.5 inches a panel.
        max_n_ticks=3,
        labelpad=0.2,
    )
    for axis in figure.axes:
        axis.tick_params(labelsize=7)


def _draw_pass(top, bottom, samples, curve, jitter_mag: float, model_label: str, mag_label: str) -> None:
    """Observed samples of a pass (a `PassCurve`-like object), the model curve and band, the
    fitted window shaded, and every sample's residual."""
    start = samples.time_utc[0]
    t = (samples.time_utc - start) / np.timedelta64(1, "s")
    window, fitted = samples.in_window, samples.fitted
    edges = t[window][[0, -1]]
    for axis in (top, bottom):
        axis.axvspan(*edges, color="C2", alpha=0.08, lw=0, label="fitted window" if axis is top else None)
    inside = window & fitted
    top.errorbar(
        t[inside],
        samples.mag_obs[inside],
        samples.mag_err[inside],
        fmt=".",
        ms=3,
        color="0.2",
        elinewidth=0.4,
        label="observed, fitted",
    )
    hollow = window & ~fitted
    if hollow.any():
        top.plot(
            t[hollow],
            samples.mag_obs[hollow],
            "o",
            ms=2.5,
            mfc="none",
            mec="0.35",
            mew=0.5,
            label="observed, in the window, not in the likelihood",
        )
    if (~window).any():
        top.plot(t[~window], samples.mag_obs[~window], ".", ms=2, color="0.7", label="observed, outside the window")
    if curve is not None:
        ct = (curve.time_utc - start) / np.timedelta64(1, "s")
        if curve.mag_band.size:
            low, high = curve.band(0.025, 0.975)
            top.fill_between(ct, low, high, color="C3", alpha=0.15, lw=0, label="model, 95% of posterior draws")
            low, high = curve.band(0.16, 0.84)
            top.fill_between(ct, low, high, color="C3", alpha=0.3, lw=0, label="model, 68%")
        top.plot(ct, curve.mag_best, "-", lw=0.8, color="C3", label=model_label)
    else:
        top.plot(t, samples.mag_model, "-", lw=1.0, color="C3", label=f"{model_label}, at the samples")
    top.invert_yaxis()
    top.set_ylabel(mag_label)
    top.legend(loc="best", fontsize=7)
    sigma = np.hypot(samples.mag_err, jitter_mag)
    bottom.axhline(0.0, color="0.5", lw=0.8)
    bottom.fill_between(t, -sigma, sigma, color="C0", alpha=0.2, lw=0)
    # Said in the title rather than a legend box, which would hide residuals.
    bottom.set_title("residuals of every sample; shaded: 1 sigma (quoted errors + jitter)", fontsize=8, loc="left")
    bottom.plot(t, samples.mag_obs - samples.mag_model, ".", ms=2, color="0.2")
    bottom.invert_yaxis()
    bottom.set_ylabel("obs - model [mag]")
    bottom.set_xlabel(f"seconds since {str(start)[:23]} UTC")


def lightcurve_figure(result, path=None, mag_label: str = "magnitude"):
    """The whole pass: observed magnitudes, the model as a continuous curve with its posterior
    band, the fitted window shaded, and the residuals of every sample.

    Samples the likelihood saw are filled, other samples of the window hollow, samples outside
    the window grey. The model curve is the stored fine-step curve (`FitResult.curve`), not the
    model at the samples joined by lines, so a curve that swings between samples shows it.
    `mag_label` names the magnitudes (`rsodb.plotting.magnitude_label` of the pass).
    """
    figure = _figure(11, 6.5)
    top, bottom = figure.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    if result.likelihood == "normalised":
        window = result.in_window
        t = result.t_s[window]
        observed, model, _ = NormalisedLikelihood(result.mag_obs[window], result.mag_err[window]).compared(
            result.mag_model[window]
        )
        top.plot(t, observed, ".", ms=3, color="0.3", label="observed (normalised)")
        top.plot(t, model, "-", lw=1.2, color="C3", label="best fit (normalised)")
        top.set_ylabel("normalised brightness")
        top.legend(loc="best", fontsize=8)
        bottom.plot(t, observed - model, ".", ms=3, color="0.2")
        bottom.set_ylabel("obs - model")
        bottom.set_xlabel(f"seconds since {str(result.time_utc[0])[:23]} UTC")
    else:
        _draw_pass(
            top,
            bottom,
            result,
            result.curve,
            result.jitter_mag,
            f"best fit (offset {result.offset_mag:+.2f} mag)",
            mag_label,
        )
    top.set_title(
        f"{result.pass_id}  fit {result.name!r}: residual RMS {result.residual_rms_mag:.3f} mag over all "
        f"{result.n_window} samples of the window, reduced chi2 {result.reduced_chi2:.2f}",
        fontsize=10,
    )
    return _saved(figure, path)


def fold_period_s(result) -> float | None:
    """The period to fold a fit's pass at: its period as the period search sees it, else its
    light-curve period (posterior medians, `rsodb.fit.conventions.comparable_convention`), else
    the fitted spin period; None when the fit has none."""
    conventions = dict(result.spin_periods).get("conventions", {})
    name = comparable_convention(conventions)
    if name is not None:
        return float(conventions[name]["median"])
    if "spin_period_s" in result.names:
        return float(result.values("median")["spin_period_s"])
    return None


def fold_worth(result) -> float | None:
    """The fold period when the fitted window spans at least `FOLD_MIN_CYCLES` of it, else None."""
    period_s = fold_period_s(result)
    window = result.t_s[result.in_window]
    if period_s and window.size and (window[-1] - window[0]) >= FOLD_MIN_CYCLES * period_s:
        return period_s
    return None


def folded_figure(
    result,
    path=None,
    period_s: float | None = None,
    windows: int = 6,
    mag_label: str = "magnitude",
    whole_pass: bool = False,
):
    """Observed and model folded at one period in consecutive stretches of the pass.

    Each panel holds every sample of one stretch (the likelihood's filled, the rest of the
    fitted window hollow, with `whole_pass` the samples after or before the window in blue) and
    the stored model curve of that stretch, one line per cycle, so that how the light curve and
    the misfit change over the pass can be read at a glance. The phase is counted from the
    pass's first sample. Returns None when no period is known (`fold_period_s`).
    """
    period_s = period_s or fold_period_s(result)
    if not period_s or not np.isfinite(period_s) or period_s <= 0:
        return None
    window = result.in_window
    shown = np.isfinite(result.mag_obs) if whole_pass else window
    start = result.time_utc[0]
    t = result.t_s
    edges = np.linspace(t[shown][0], t[shown][-1], windows + 1)
    columns = min(3, windows)
    rows = -(-windows // columns)
    figure = _figure(4.2 * columns, 3.2 * rows)
    axes = np.atleast_1d(figure.subplots(rows, columns, sharex=True, sharey=True)).ravel()
    curve = result.curve
    ct = None if curve is None else (curve.time_utc - start) / np.timedelta64(1, "s")
    phase = (t / period_s) % 1.0
    for k, axis in enumerate(axes):
        if k >= windows:
            axis.set_visible(False)
            continue
        low, high = edges[k], edges[k + 1]
        inside = shown & (t >= low) & ((t < high) | (k == windows - 1))
        fitted = inside & result.fitted
        outside = inside & ~window
        if ct is not None:
            stretch = (ct >= low) & (ct <= high)
            cycle = np.floor(ct[stretch] / period_s)
            model_phase = (ct[stretch] / period_s) % 1.0
            mag = curve.mag_best[stretch]
            # One line per cycle: break where the phase wraps.
            for c in np.unique(cycle):
                one = cycle == c
                axis.plot(model_phase[one], mag[one], "-", lw=0.6, color="C3", alpha=0.6)
        axis.plot(phase[fitted], result.mag_obs[fitted], ".", ms=2.5, color="0.15")
        hollow = inside & window & ~fitted
        axis.plot(phase[hollow], result.mag_obs[hollow], "o", ms=2, mfc="none", mec="0.4", mew=0.4)
        if outside.any():
            axis.plot(phase[outside], result.mag_obs[outside], ".", ms=2.5, color="C0")
        residual = result.mag_obs[inside] - result.mag_model[inside]
        rms = float(np.sqrt(np.nanmean(residual**2))) if residual.size else float("nan")
        held = " (outside the fit)" if outside.any() and not (inside & window).any() else ""
        axis.set_title(f"{low:.0f}-{high:.0f} s{held}: RMS {rms:.2f} mag", fontsize=9)
        if k % columns == 0:
            axis.set_ylabel(mag_label)
        if k >= windows - columns:
            axis.set_xlabel(f"phase at {period_s:.5g} s")
    axes[0].invert_yaxis()
    figure.suptitle(
        f"{result.pass_id} fit {result.name!r}, folded\nobserved black (hollow: not in the likelihood"
        + ("; blue: outside the fitted window" if whole_pass else "")
        + "), best fit red (one line per cycle)",
        fontsize=10,
    )
    return _saved(figure, path)


def prediction_figure(prediction, path=None, mag_label: str = "magnitude"):
    """A stored fit replayed (`rsodb.fit.prediction.FitPrediction`): the posterior median over the
    whole pass with the band of its posterior draws, and every sample's residual."""
    result = prediction.result
    figure = _figure(11, 6.5)
    top, bottom = figure.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    _draw_pass(top, bottom, prediction.samples, prediction.curve, result.jitter_mag, "posterior median", mag_label)
    top.set_title(
        f"{result.pass_id}  fit {result.name!r} replayed: posterior median and {prediction.draws} draws; "
        f"residual RMS {prediction.residual_rms_mag:.3f} mag over the window",
        fontsize=10,
    )
    return _saved(figure, path)


def _surface_directions(scene, values, axis, cell_deg: float = 0.5):
    """{material: (azimuth, elevation, area m^2)} of the scene's surfaces at the fit's values,
    area summed over cells of `cell_deg` in direction (a dish's hundreds of facets, a box's few)."""
    posed = scene.with_parameters(**{k: values[k] for k in scene.parameters if k in values}).posed()
    area = posed.areas_m2
    azimuth, elevation = azimuth_elevation(posed.face_normals, axis)
    cells = {}
    for index, name in enumerate(scene.material_names):
        mine = (posed.material_index == index) & (area > 0)
        if not mine.any():
            continue
        keys = np.stack([np.round(azimuth[mine] / cell_deg), np.round(elevation[mine] / cell_deg)], axis=1)
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        total = np.bincount(inverse.ravel(), weights=area[mine])
        cells[name] = ((unique[:, 0] * cell_deg) % 360.0, unique[:, 1] * cell_deg, total)
    return cells


def glint_map_figure(prediction, path=None, min_area_m2: float = 0.05):
    """Where in the body frame the model misses: every sample's residual at the direction of the
    Sun-observer bisector, over the directions the model's surfaces face.

    A flat, smooth surface glints when the bisector (in body coordinates) crosses its normal,
    so a patch of samples much brighter than the model (blue) at one azimuth and elevation asks
    for a smooth surface facing there, and a red patch for less light there. Azimuth and
    elevation are about the median state's spin axis in the body frame (`conventions.
    azimuth_elevation`); the hollow markers are the model's surface normals (area summed over
    half-degree cells, cells under `min_area_m2` left out), one colour per material.

    Parameters
    ----------
    prediction : rsodb.fit.prediction.FitPrediction
    path : str or Path, optional
    min_area_m2 : float
    """
    result, samples = prediction.result, prediction.samples
    bisector, spin = prediction.bisector_body()
    azimuth, elevation = azimuth_elevation(bisector, spin)
    residual = samples.mag_obs - samples.mag_model
    usable = np.isfinite(residual)
    if not usable.any():
        raise ValueError(f"{result.pass_id}: no sample with both an observed and a model magnitude to map")
    limit = float(max(0.5, np.percentile(np.abs(residual[usable]), 98)))
    low = max(-90.0, float(elevation[usable].min()) - 10.0)
    high = min(90.0, float(elevation[usable].max()) + 10.0)
    figure = _figure(11, 5.2)
    axis = figure.subplots()
    order = np.argsort(np.abs(np.where(usable, residual, 0.0)))
    order = order[usable[order]]
    dots = axis.scatter(
        azimuth[order], elevation[order], c=residual[order], cmap="coolwarm", vmin=-limit, vmax=limit, s=7, lw=0
    )
    figure.colorbar(dots, ax=axis, label="observed - model (mag); blue: brighter than the model")
    scene = prediction.scene
    if scene is not None:
        for k, (name, (az, el, area)) in enumerate(_surface_directions(scene, prediction.values, spin).items()):
            shown = (area >= min_area_m2) & (el >= low) & (el <= high)
            if shown.any():
                axis.scatter(
                    az[shown],
                    el[shown],
                    s=12.0 + 30.0 * np.sqrt(area[shown]),
                    facecolors="none",
                    edgecolors=f"C{(k + 2) % 10}",
                    lw=1.0,
                    label=f"{name} normals",
                )
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=7, loc="upper right", framealpha=0.8)
    axis.set_xlim(0.0, 360.0)
    axis.set_ylim(low, high)
    axis.set_xticks(np.arange(0, 361, 45))
    axis.set_xlabel("azimuth of the Sun-observer bisector about the spin axis, body frame (deg)")
    axis.set_ylabel("its elevation toward the spin axis (deg)")
    axis.set_title(
        f"{result.pass_id} fit {result.name!r}\nresiduals at the Sun-observer bisector's body direction; "
        f"spin axis (body) [{spin[0]:.2f}, {spin[1]:.2f}, {spin[2]:.2f}]",
        fontsize=10,
    )
    return _saved(figure, path)


def trace_figure(result, chain=None, path=None):
    """Every walker's trace per parameter, burn-in shaded.

    Parameters
    ----------
    result : FitResult
    chain : (n_steps, n_walkers, ndim) array, optional
        Default: read from ``result.chain_path``.
    path : str or Path, optional
    """
    if chain is None:
        if not Path(result.chain_path).exists():
            raise FileNotFoundError(
                f"the chain file {result.chain_path} of fit {result.name!r} is gone; "
                "traces need it (rerun the fit to recreate it)"
            )
        chain = read_chain(result.chain_path)[0]
    ndim = chain.shape[2]
    figure = _figure(9, 1.6 * ndim + 0.8)
    axes = np.atleast_1d(figure.subplots(ndim, 1, sharex=True))
    # At most ~300 steps drawn per walker: a longer trace looks the same at this width and
    # its antialiased lines would make a PNG of several MB.
    stride = max(1, chain.shape[0] // 300)
    steps = np.arange(chain.shape[0])[::stride]
    for i, axis in enumerate(axes):
        axis.plot(steps, chain[::stride, :, i], lw=0.5, alpha=0.5, color="k", antialiased=False)
        axis.axvspan(0, result.discard, color="C1", alpha=0.12, lw=0)
        axis.set_ylabel(result.space.labels[i], fontsize=8)
    # Wrapped to the figure's width: a verdict of one long line would be cut at the edge.
    verdict = textwrap.fill(result.verdict.split(". ")[0], 110)
    axes[0].set_title(
        f"{result.pass_id}: walker traces (burn-in of {result.discard} steps shaded)\n{verdict}", fontsize=9
    )
    axes[-1].set_xlabel("step")
    return _saved(figure, path, dpi=90)


def save_all(result, directory, stem: str | None = None, truths=None) -> dict[str, Path]:
    """Save the figures as ``<stem>_corner.png``, ``_lightcurve.png``, ``_trace.png`` and, for a
    pass of at least `FOLD_MIN_CYCLES` cycles, ``_folded.png``."""
    directory = Path(directory)
    stem = stem or f"{result.pass_id}_{result.name}"
    paths = {
        "corner": directory / f"{stem}_corner.png",
        "lightcurve": directory / f"{stem}_lightcurve.png",
        "trace": directory / f"{stem}_trace.png",
    }
    corner_figure(result, paths["corner"], truths)
    lightcurve_figure(result, paths["lightcurve"])
    period_s = fold_worth(result)
    if period_s:
        paths["folded"] = directory / f"{stem}_folded.png"
        folded_figure(result, paths["folded"], period_s)
    if Path(result.chain_path).exists():
        trace_figure(result, path=paths["trace"])
    else:
        del paths["trace"]
    return paths
