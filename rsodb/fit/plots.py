"""Figures of a fit: corner plot, observed vs synthetic light curve with residuals, traces.

Each function returns a ``matplotlib.figure.Figure`` (built without pyplot, so it is safe in
worker processes and threads) and saves it when given a path.

>>> from rsodb.fit.plots import lightcurve_figure    # doctest: +SKIP
>>> lightcurve_figure(result, "fit.png")              # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rsodb.fit.likelihood import NormalisedLikelihood
from rsodb.fit.sampler import read_chain

__all__ = ["corner_figure", "lightcurve_figure", "trace_figure", "save_all"]


def _figure(width_in: float, height_in: float):
    # matplotlib loads in about a second; only drawing needs it.
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), layout="constrained")


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
    figure = _figure(1.5 * ndim + 1, 1.5 * ndim + 1)
    marks = None if truths is None else [truths.get(n) for n in result.names]
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
    )
    figure.suptitle(f"{result.pass_id}: posterior of fit {result.name!r}", fontsize=10)
    return _saved(figure, path, dpi=80)


def lightcurve_figure(result, path=None):
    """Observed magnitudes with errors, the best-fit synthetic curve, and the residuals."""
    figure = _figure(10, 6)
    top, bottom = figure.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    t = result.t_s
    if result.likelihood == "normalised":
        observed, model, _ = NormalisedLikelihood(result.mag_obs, result.mag_err).compared(result.mag_model)
        top.plot(t, observed, ".", ms=3, color="0.3", label="observed (normalised)")
        top.plot(t, model, "-", lw=1.2, color="C3", label="best fit (normalised)")
        top.set_ylabel("normalised brightness")
        residual, sigma = observed - model, None
    else:
        top.errorbar(t, result.mag_obs, result.mag_err, fmt=".", ms=3, color="0.3", elinewidth=0.5, label="observed")
        top.plot(t, result.mag_model, "-", lw=1.2, color="C3", label=f"best fit (offset {result.offset_mag:+.2f} mag)")
        top.invert_yaxis()
        top.set_ylabel("magnitude")
        residual, sigma = result.residuals_mag, np.hypot(result.mag_err, result.jitter_mag)
    top.legend(loc="best", fontsize=8)
    top.set_title(
        f"{result.pass_id}  fit {result.name!r}: residual RMS {result.residual_rms_mag:.3f} mag, "
        f"reduced chi2 {result.reduced_chi2:.2f}",
        fontsize=10,
    )
    bottom.axhline(0.0, color="0.5", lw=0.8)
    if sigma is not None:
        bottom.fill_between(t, -sigma, sigma, color="C0", alpha=0.2, lw=0)
        # Said in the title rather than a legend box, which would hide residuals.
        bottom.set_title("residuals; shaded: 1 sigma (quoted errors + jitter)", fontsize=8, loc="left")
    bottom.plot(t, residual, ".", ms=3, color="0.2")
    bottom.invert_yaxis()
    bottom.set_ylabel("obs - model [mag]" if sigma is not None else "obs - model")
    bottom.set_xlabel(f"seconds since {str(result.time_utc[0])[:23]} UTC")
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
    axes[0].set_title(
        f"{result.pass_id}: walker traces (burn-in of {result.discard} steps shaded)\n{result.verdict.split('. ')[0]}",
        fontsize=9,
    )
    axes[-1].set_xlabel("step")
    return _saved(figure, path, dpi=90)


def save_all(result, directory, stem: str | None = None, truths=None) -> dict[str, Path]:
    """Save the three figures as ``<stem>_corner.png``, ``_lightcurve.png``, ``_trace.png``."""
    directory = Path(directory)
    stem = stem or f"{result.pass_id}_{result.name}"
    paths = {
        "corner": directory / f"{stem}_corner.png",
        "lightcurve": directory / f"{stem}_lightcurve.png",
        "trace": directory / f"{stem}_trace.png",
    }
    corner_figure(result, paths["corner"], truths)
    lightcurve_figure(result, paths["lightcurve"])
    if Path(result.chain_path).exists():
        trace_figure(result, path=paths["trace"])
    else:
        del paths["trace"]
    return paths
