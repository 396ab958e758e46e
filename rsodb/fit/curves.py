"""The fitted model over the whole pass: every sample's residual and a continuous curve with a band.

A fit compares its model with the samples `rsodb.fit.selection` keeps (all of them, or bins and
contiguous windows); what it reports covers more:

* `PassCurve`: every usable sample of the pass with the best fit's magnitude (the marginalised
  offset applied) and two flags, ``in_window`` (inside the fitted window: residuals and their RMS
  cover all of these) and ``fitted`` (inside a bin the likelihood saw);
* `ModelCurve`: the model at fine time steps (`POINTS_PER_CYCLE` per cycle of the fastest spin
  the prior allows, never coarser than the cadence) from the first to the last sample of the
  pass, exposure-integrated like the observations: the best fit and quantiles over posterior
  draws, each draw with its own marginalised offset. Plots draw this curve, not the model at the
  kept samples joined by lines (which hides strobing).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from raycast.geometry.pass_geometry import PassGeometry, orbit_of
from rsodb.fit.likelihood import flux_error_of, jitter_of
from rsodb.fit.selection import usable_samples

__all__ = ["PassCurve", "ModelCurve", "BAND_LEVELS", "pass_curves", "geometry_at", "fine_times"]

BAND_LEVELS = (0.025, 0.16, 0.5, 0.84, 0.975)
POINTS_PER_CYCLE = 40
MAX_CURVE_POINTS = 20_000


def _readonly(value, dtype=float):
    array = np.array(value, dtype=dtype)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class PassCurve:
    """Observed samples of the pass with the best-fit model.

    Attributes
    ----------
    time_utc : (n,) datetime64[ns]
    mag_obs, mag_err : (n,) float
    mag_model : (n,) float
        Best fit, the marginalised offset applied.
    in_window : (n,) bool
        Inside the fitted window.
    fitted : (n,) bool
        Seen by the likelihood (itself or inside a bin).
    """

    time_utc: np.ndarray
    mag_obs: np.ndarray
    mag_err: np.ndarray
    mag_model: np.ndarray
    in_window: np.ndarray
    fitted: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "time_utc", _readonly(self.time_utc, "datetime64[ns]"))
        for name in ("mag_obs", "mag_err", "mag_model"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        for name in ("in_window", "fitted"):
            object.__setattr__(self, name, _readonly(getattr(self, name), bool))


@dataclass(frozen=True, eq=False)
class ModelCurve:
    """The model at fine time steps over the pass.

    Attributes
    ----------
    time_utc : (k,) datetime64[ns]
    mag_best : (k,) float
        Best fit, offset applied.
    levels : (q,) float
        Quantile levels of `mag_band` (`BAND_LEVELS`).
    mag_band : (q, k) float
        Quantiles of the model over posterior draws (empty when no draws were taken).
    """

    time_utc: np.ndarray
    mag_best: np.ndarray
    levels: np.ndarray
    mag_band: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "time_utc", _readonly(self.time_utc, "datetime64[ns]"))
        for name in ("mag_best", "levels", "mag_band"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))

    def band(self, level_low: float, level_high: float) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) quantile curves at two of `levels`."""
        levels = list(np.round(self.levels, 6))
        return self.mag_band[levels.index(round(level_low, 6))], self.mag_band[levels.index(round(level_high, 6))]


def geometry_at(observed, time_utc, exposure_s: float, n_sub: int | None, spin_period_s: float | None):
    """`PassGeometry` of a pass's object and site at any times, with any exposure.

    The orbit is the pass's elements, or else a track fitted to its own Az/El/range columns
    (`raycast.geometry.orbit_of`), which covers only the observed span.
    """
    return PassGeometry.compute(
        orbit_of(observed),
        observed.site,
        np.asarray(time_utc, dtype="datetime64[ns]"),
        float(exposure_s),
        n_sub=n_sub,
        spin_period_s=spin_period_s,
    )


def fine_times(observed, fastest_period_s: float) -> np.ndarray:
    """(k,) times from the pass's first to its last sample, `POINTS_PER_CYCLE` per fastest cycle."""
    start, end = observed.time_utc[0], observed.time_utc[-1]
    span_s = float((end - start) / np.timedelta64(1, "s"))
    cadence = float(np.median(np.diff(observed.t_s))) if len(observed) > 1 else span_s
    step = min(cadence, fastest_period_s / POINTS_PER_CYCLE) if math.isfinite(fastest_period_s) else cadence
    count = int(min(MAX_CURVE_POINTS, max(2, math.ceil(span_s / max(step, 1e-6)) + 1)))
    offsets = np.round(np.linspace(0.0, span_s, count) * 1e9).astype("int64").astype("timedelta64[ns]")
    return start + offsets


def pass_curves(posterior, observed, selection, best_theta, draws, *, n_sub: int | None, fastest_period_s: float):
    """(PassCurve, ModelCurve) of a fit.

    Parameters
    ----------
    posterior : Posterior
        The fitted posterior (its model on the kept samples, its likelihood).
    observed : Pass
    selection : rsodb.fit.selection.Selection
    best_theta : (ndim,) float
    draws : (d, ndim) float
        Posterior draws for the band (d may be 0).
    n_sub : int or None
        Exposure sub-samples of the pass-wide curves (None: chosen from the exposure and period).
    fastest_period_s : float
        The shortest spin period of the prior (sets the fine step and the sub-sampling).
    """
    space, model, likelihood = posterior.space, posterior.model, posterior.likelihood

    def aligned(theta, on_model):
        values = space.values(theta)
        offset = likelihood.offset_mag(model.magnitudes(values), jitter_of(values), flux_error_of(values))
        return on_model.magnitudes(values) + offset

    # Saturated samples outside the window are drawn too; they are never fitted.
    usable = np.flatnonzero(selection.window | usable_samples(observed, keep_saturated=True))
    samples_model = model.on(
        geometry_at(observed, observed.time_utc[usable], observed.exposure_s, n_sub, fastest_period_s)
    )
    kept = selection.kept
    pass_curve = PassCurve(
        observed.time_utc[usable],
        observed.best_mag[usable],
        observed.mag_err[usable],
        aligned(best_theta, samples_model),
        selection.window[usable],
        kept[usable],
    )
    fine = fine_times(observed, fastest_period_s)
    fine_model = model.on(geometry_at(observed, fine, observed.exposure_s, n_sub, fastest_period_s))
    with np.errstate(divide="ignore", invalid="ignore"):
        best = aligned(best_theta, fine_model)
        curves = np.array([aligned(theta, fine_model) for theta in np.asarray(draws)]).reshape(-1, fine.size)
    band = np.quantile(curves, BAND_LEVELS, axis=0) if len(curves) else np.zeros((0, fine.size))
    return pass_curve, ModelCurve(fine, best, np.array(BAND_LEVELS if len(curves) else ()), band)
