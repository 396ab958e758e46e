"""A light curve ready for period analysis: times, magnitudes, errors, and what was done to them.

`LightCurve` is immutable; every operation returns a new object, so analyses chain::

    archive.passes(norad=22076)[0].detrend().periodogram().best_period
    lc.detrend().fold(9.4836).plot()

Which samples are used
----------------------
`LightCurve.from_pass` keeps the samples that are valid (no sentinel, finite) and not
saturated (a saturated frame clips the glints the period search relies on), and takes
`Pass.best_mag`: the magnitudes with the extinction sign error undone where the file had it.

The pass trend
--------------
ccd_phot magnitudes are already reduced to a range of 1000 km, so what remains slow over a
pass is the phase-angle dependence of the brightness (and, in files with the extinction sign
error left uncorrected, airmass): smooth, monotonic or single-humped over a few minutes.
`detrend` removes a low-degree Legendre polynomial in time (degree 3 by default) by weighted
least squares, for plots and periodograms. The period search does not depend on it: it fits the
trend jointly with every Fourier model, with a degree held to the candidate's cycles in the pass
(`rsodb.periods.harmonic.trend_degree_limit`: a trend may never imitate the candidate), so a
short pass gets a constant or a line, not a cubic that cancels a one-cycle model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math

import numpy as np

from rsodb.periods.harmonic import DEFAULT_ERROR_FLOOR_MAG, TimeAxis
from rsodb.periods.periodogram import periodogram
from rsodb.periods.search import find_period
from rsodb.plotting import axes_or_new, magnitude_label

__all__ = ["LightCurve", "FoldedLightCurve", "DEFAULT_TREND_DEGREE", "DEFAULT_ERROR_FLOOR_MAG"]

DEFAULT_TREND_DEGREE = 3


def _readonly(values, name: str, dtype=float) -> np.ndarray:
    array = np.array(values, dtype=dtype)
    if array.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array, got shape {array.shape}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class LightCurve:
    """Magnitudes of one object against time.

    Parameters
    ----------
    t_s : (n,) float
        Seconds since `epoch_utc`, strictly increasing.
    mag : (n,) float
        Magnitudes (after `detrend`: the residual about the trend).
    mag_err : (n,) float
        1-sigma errors, magnitudes; NaN where unknown (weights then use the error floor alone).
    epoch_utc : numpy.datetime64, optional
        UTC of ``t_s = 0`` (the first sample of the pass for `from_pass`).
    exposure_s : float
        Exposure of one sample, seconds (0 when unknown).
    label : str
        Human-readable name used in plots (object, band, date).
    norad : int, optional
    band : str
    pass_id : str
        The archive's id when the curve came from a stored pass.
    mag_convention : str
        What the magnitudes are (the pass's `mag_convention`, e.g. reduced to 1000 km); labels plots.
    trend_mag : (n,) float, optional
        What `detrend` removed; None while the curve is raw.
    trend_degree : int, optional
        Degree of that trend.
    """

    t_s: np.ndarray
    mag: np.ndarray
    mag_err: np.ndarray
    epoch_utc: np.datetime64 | None = None
    exposure_s: float = 0.0
    label: str = ""
    norad: int | None = None
    band: str = ""
    pass_id: str = ""
    mag_convention: str = ""
    trend_mag: np.ndarray | None = None
    trend_degree: int | None = None

    def __post_init__(self):
        t_s = _readonly(self.t_s, "t_s")
        mag = _readonly(self.mag, "mag")
        mag_err = _readonly(self.mag_err, "mag_err")
        n = t_s.shape[0]
        for name, array in (("mag", mag), ("mag_err", mag_err)):
            if array.shape[0] != n:
                raise ValueError(f"{name} has {array.shape[0]} samples but t_s has {n}; give arrays of one length")
        if n < 2:
            raise ValueError(f"a light curve needs at least 2 samples, got {n}; check the pass's valid flags")
        if not np.all(np.isfinite(t_s)) or np.any(np.diff(t_s) <= 0):
            raise ValueError("t_s must be finite and strictly increasing; sort the samples and drop duplicates")
        if not np.all(np.isfinite(mag)):
            raise ValueError(f"mag has {int(np.sum(~np.isfinite(mag)))} non-finite values; drop invalid samples first")
        if np.any(mag_err < 0):
            raise ValueError(f"mag_err has negative values (min {np.nanmin(mag_err):g}); give 1-sigma errors >= 0")
        object.__setattr__(self, "t_s", t_s)
        object.__setattr__(self, "mag", mag)
        object.__setattr__(self, "mag_err", mag_err)
        if self.trend_mag is not None:
            trend = _readonly(self.trend_mag, "trend_mag")
            if trend.shape[0] != n:
                raise ValueError(f"trend_mag has {trend.shape[0]} samples but t_s has {n}")
            object.__setattr__(self, "trend_mag", trend)
        if self.epoch_utc is not None:
            object.__setattr__(self, "epoch_utc", np.datetime64(self.epoch_utc, "ns"))
        if not (math.isfinite(self.exposure_s) and self.exposure_s >= 0):
            raise ValueError(f"exposure_s={self.exposure_s!r} must be a finite number of seconds >= 0")

    # -- construction ----------------------------------------------------------------------
    @classmethod
    def from_pass(cls, pass_, *, include_saturated: bool = False) -> LightCurve:
        """The usable samples of an `ingest.observation.Pass` (or a stored pass).

        Parameters
        ----------
        pass_ : Pass
        include_saturated : bool
            Keep frames flagged as saturated (default: drop them).

        Raises
        ------
        ValueError
            When fewer than two samples are valid and unsaturated.
        """
        mag = np.asarray(pass_.best_mag, dtype=float)
        keep = np.asarray(pass_.valid, bool) & np.isfinite(mag)
        if not include_saturated:
            keep &= ~np.asarray(pass_.saturated, bool)
        pass_id = str(getattr(pass_, "pass_id", "") or "")
        if keep.sum() < 2:
            raise ValueError(
                f"pass {pass_id or pass_.source_name!r} has {int(keep.sum())} valid unsaturated samples; "
                "a light curve needs at least 2 (try include_saturated=True)"
            )
        err = np.asarray(pass_.mag_err, dtype=float)[keep]
        err = np.where(np.isfinite(err) & (err >= 0), err, np.nan)
        day = np.datetime_as_string(pass_.start_utc, unit="m").replace("T", " ")
        return cls(
            t_s=pass_.t_s[keep],
            mag=mag[keep],
            mag_err=err,
            epoch_utc=pass_.start_utc,
            exposure_s=float(pass_.exposure_s),
            label=f"{pass_.name} ({pass_.norad}) {pass_.band} {day} UTC",
            norad=int(pass_.norad),
            band=str(pass_.band),
            pass_id=pass_id,
            mag_convention=str(getattr(pass_, "mag_convention", "") or ""),
        )

    @classmethod
    def from_arrays(cls, t_s, mag, mag_err=None, **metadata) -> LightCurve:
        """A light curve from plain arrays (astropy Quantities accepted for `t_s`, `mag_err`).

        Parameters
        ----------
        t_s : (n,) float or Quantity
            Times, seconds (any time unit when a Quantity).
        mag : (n,) float
        mag_err : (n,) float, optional
            Unknown (NaN) when omitted.
        **metadata
            Any other field of `LightCurve` (``epoch_utc``, ``label``, ...).
        """
        t_s = _strip_unit(t_s, "s")
        mag = np.asarray(mag, dtype=float)
        mag_err = np.full(mag.shape, np.nan) if mag_err is None else np.asarray(_strip_unit(mag_err, "mag"), float)
        return cls(t_s=t_s, mag=mag, mag_err=mag_err, **metadata)

    # -- views -----------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.t_s.shape[0]

    @property
    def duration_s(self) -> float:
        """Seconds from the first to the last sample."""
        return float(self.t_s[-1] - self.t_s[0])

    @property
    def cadence_s(self) -> float:
        """Median spacing of the samples, seconds."""
        return float(np.median(np.diff(self.t_s)))

    @property
    def time_utc(self) -> np.ndarray | None:
        """(n,) datetime64[ns] UTC of the samples, or None without an epoch."""
        if self.epoch_utc is None:
            return None
        return self.epoch_utc + np.round(self.t_s * 1e9).astype("timedelta64[ns]")

    def weights(self, error_floor_mag: float = DEFAULT_ERROR_FLOOR_MAG) -> np.ndarray:
        """(n,) least-squares weights ``1 / (mag_err^2 + floor^2)`` (unknown errors: the floor)."""
        err = np.where(np.isfinite(self.mag_err), self.mag_err, 0.0)
        return 1.0 / (err**2 + error_floor_mag**2)

    # -- operations ------------------------------------------------------------------------
    def detrend(
        self, degree: int = DEFAULT_TREND_DEGREE, error_floor_mag: float = DEFAULT_ERROR_FLOOR_MAG
    ) -> LightCurve:
        """Remove a weighted least-squares polynomial in time (see the module notes).

        Parameters
        ----------
        degree : int
            Polynomial degree, 0..10 (default 3).
        error_floor_mag : float
            Added in quadrature to the errors for the weights.

        Returns
        -------
        LightCurve
            Residual magnitudes (mean ~0); `trend_mag` accumulates what was removed.
        """
        if not isinstance(degree, (int, np.integer)) or isinstance(degree, bool) or not 0 <= degree <= 10:
            raise ValueError(f"degree={degree!r} must be a whole number from 0 to 10")
        if len(self) <= degree + 1:
            raise ValueError(f"a degree-{degree} trend needs more than {degree + 1} samples, the curve has {len(self)}")
        axis = TimeAxis.from_times(self.t_s)
        basis = axis.trend_basis(self.t_s, degree)
        sw = np.sqrt(self.weights(error_floor_mag))
        coefficients, *_ = np.linalg.lstsq(basis * sw[:, None], self.mag * sw, rcond=None)
        trend = basis @ coefficients
        previous = 0.0 if self.trend_mag is None else self.trend_mag
        return replace(self, mag=self.mag - trend, trend_mag=previous + trend, trend_degree=int(degree))

    def replace(self, **changes) -> LightCurve:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def select(self, mask) -> LightCurve:
        """The samples where `mask` (n,) is True."""
        mask = np.asarray(mask, bool)
        if mask.shape != self.t_s.shape:
            raise ValueError(f"mask has shape {mask.shape}, expected {self.t_s.shape}")
        trend = None if self.trend_mag is None else self.trend_mag[mask]
        return replace(self, t_s=self.t_s[mask], mag=self.mag[mask], mag_err=self.mag_err[mask], trend_mag=trend)

    def periodogram(
        self,
        method: str = "lombscargle",
        *,
        nterms: int = 1,
        oversampling: float | None = None,
        minimum_period_s: float | None = None,
        maximum_period_s: float | None = None,
        error_floor_mag: float = DEFAULT_ERROR_FLOOR_MAG,
    ):
        """Power against frequency; see `rsodb.periods.periodogram.periodogram` for the arguments."""
        return periodogram(
            self,
            method,
            nterms=nterms,
            oversampling=oversampling,
            minimum_period_s=minimum_period_s,
            maximum_period_s=maximum_period_s,
            error_floor_mag=error_floor_mag,
        )

    def find_period(self, geometry=None, settings=None, **overrides):
        """The disambiguated spin period: `rsodb.periods.find_period` on this curve."""
        return find_period(self, geometry=geometry, settings=settings, **overrides)

    def fold(self, period_s, epoch_s: float = 0.0) -> FoldedLightCurve:
        """Fold on a period.

        Parameters
        ----------
        period_s : float or Quantity
            Folding period.
        epoch_s : float
            Time of phase 0 on the curve's own axis.

        Returns
        -------
        FoldedLightCurve
        """
        period_s = float(_strip_unit(period_s, "s"))
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"period_s={period_s!r} must be a positive number of seconds")
        cycles = (self.t_s - epoch_s) / period_s
        return FoldedLightCurve(
            phase=np.mod(cycles, 1.0),
            mag=self.mag,
            mag_err=self.mag_err,
            cycle=np.floor(cycles).astype(int),
            period_s=period_s,
            epoch_s=float(epoch_s),
            label=self.label,
            mag_label=magnitude_label(self.band, self.mag_convention, self.trend_mag is not None),
        )

    def to_pandas(self):
        """DataFrame with ``t_s``, ``mag``, ``mag_err`` (and ``trend_mag``), indexed by UTC when known."""
        # pandas costs about half a second to import; only this conversion needs it.
        import pandas as pd

        columns = {"t_s": self.t_s, "mag": self.mag, "mag_err": self.mag_err}
        if self.trend_mag is not None:
            columns["trend_mag"] = self.trend_mag
        index = None if self.epoch_utc is None else pd.DatetimeIndex(self.time_utc, name="time_utc")
        frame = pd.DataFrame(columns, index=index)
        frame.attrs.update(label=self.label, norad=self.norad, band=self.band, pass_id=self.pass_id)
        return frame

    def plot(self, ax=None, **style):
        """Magnitude against time (brighter up); returns the matplotlib axes."""
        ax = axes_or_new(ax)
        options = {"s": 3, "color": "k", "lw": 0} | style
        ax.scatter(self.t_s, self.mag, **options)
        if not ax.yaxis_inverted():
            ax.invert_yaxis()
        ax.set_xlabel("time since first sample [s]")
        ax.set_ylabel(magnitude_label(self.band, self.mag_convention, self.trend_mag is not None))
        if self.label:
            ax.set_title(self.label, fontsize="medium")
        return ax

    def __repr__(self) -> str:
        state = f"detrended (degree {self.trend_degree})" if self.trend_mag is not None else "raw"
        return f"LightCurve({self.label or 'unnamed'!r}, n={len(self)}, duration_s={self.duration_s:.1f}, {state})"


@dataclass(frozen=True, eq=False)
class FoldedLightCurve:
    """A light curve folded on a period.

    Attributes
    ----------
    phase : (n,) float
        Phase in [0, 1).
    mag, mag_err : (n,) float
    cycle : (n,) int
        Cycle number of each sample (for colouring by time).
    period_s, epoch_s : float
    label : str
    mag_label : str
        The magnitude axis's label (band, range reduction).
    """

    phase: np.ndarray
    mag: np.ndarray
    mag_err: np.ndarray
    cycle: np.ndarray
    period_s: float
    epoch_s: float
    label: str = ""
    mag_label: str = "magnitude"

    def binned(self, n_bins: int = 50) -> tuple[np.ndarray, np.ndarray]:
        """Bin centres (n_bins,) and mean magnitude per bin (NaN where empty)."""
        index = np.minimum((self.phase * n_bins).astype(int), n_bins - 1)
        count = np.bincount(index, minlength=n_bins)
        total = np.bincount(index, weights=self.mag, minlength=n_bins)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, total / count, np.nan)
        return (np.arange(n_bins) + 0.5) / n_bins, mean

    def plot(self, ax=None, model=None, **style):
        """Magnitude against phase, coloured by cycle (with a colour bar); `model` is an optional
        (phase, mag) curve."""
        ax = axes_or_new(ax)
        options = {"s": 3, "c": self.cycle, "cmap": "viridis", "lw": 0} | style
        points = ax.scatter(self.phase, self.mag, **options)
        if "c" not in style and self.cycle.size and self.cycle.max() > self.cycle.min():
            ax.figure.colorbar(points, ax=ax, label="cycle (0: the one starting at the fold's epoch)", pad=0.01)
        if model is not None:
            phase, mag = model
            ax.plot(phase, mag, color="C3", lw=1.2)
        if not ax.yaxis_inverted():
            ax.invert_yaxis()
        ax.set_xlim(0, 1)
        ax.set_xlabel(f"phase (P = {self.period_s:.4f} s)")
        ax.set_ylabel(self.mag_label)
        if self.label:
            ax.set_title(self.label, fontsize="medium")
        return ax


def _strip_unit(value, unit: str):
    """Value in `unit` as a float array; astropy Quantities are converted, plain numbers pass."""
    if hasattr(value, "unit") and hasattr(value, "to_value"):
        return np.asarray(value.to_value(unit), dtype=float)
    return np.asarray(value, dtype=float)
