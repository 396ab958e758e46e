"""Power spectra of a light curve on a frequency grid: one entry point, a table of methods.

``power_spectrum(lc, method="lombscargle")`` evaluates power on a frequency grid set by the
curve's cadence and duration (`frequency_grid`):

* lowest frequency ``1 / maximum_period_s`` (default: one cycle in the pass, ``1 / T``);
* highest ``1 / minimum_period_s`` (default: the Nyquist frequency of the median cadence,
  ``1 / (2 dt)``);
* spacing ``1 / (oversampling T)`` with ``oversampling = 5`` by default, i.e. five samples
  across each peak of width ``~1 / T`` (VanderPlas 2018, ApJS 236, 16, recommends 5-10;
  5 is astropy's ``samples_per_peak`` default) for Lomb-Scargle, whose peaks are ``~1 / T``
  wide; 20 for PDM and string length, whose minima narrow with every harmonic the curve has
  (a glint's minimum is many times narrower). The period search refines every candidate off
  the grid, so a denser Lomb-Scargle grid buys it nothing.

Methods (`PERIODOGRAM_METHODS`):

* ``"lombscargle"``: astropy's `LombScargle` on the curve with its trend removed, weighted by
  ``1 / (err^2 + floor^2)``; ``nterms=1`` uses the fast O(N log N) method, more terms the
  (slow) multi-term chi^2 method, whose highest harmonic is kept under the Nyquist frequency.
* ``"pdm"``: ``1 - theta`` of phase dispersion minimisation with 10 bins.
* ``"string_length"``: ``1 - L / L_max`` of Dworetsky's string length.

A plain power spectrum peaks at whatever harmonic carries the most power, which for a rotating
satellite is often not the rotation; `rsodb.periods.periodogram.Periodogram` adds the full
search (harmonic disambiguation) on top of this module.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import TYPE_CHECKING

from astropy.timeseries import LombScargle
import numpy as np

from rsodb.periods.dispersion import pdm, string_length
from rsodb.periods.harmonic import DEFAULT_ERROR_FLOOR_MAG
from rsodb.plotting import axes_or_new

if TYPE_CHECKING:
    from rsodb.periods.lightcurve import LightCurve

__all__ = [
    "PowerSpectrum",
    "power_spectrum",
    "frequency_grid",
    "PERIODOGRAM_METHODS",
    "DEFAULT_OVERSAMPLING",
    "METHOD_OVERSAMPLING",
]

DEFAULT_OVERSAMPLING = 5.0
# Grid points per 1/T by method when none is given (see the module notes).
METHOD_OVERSAMPLING = {"lombscargle": 5.0, "pdm": 20.0, "string_length": 20.0}


def frequency_grid(
    t_s,
    oversampling: float = DEFAULT_OVERSAMPLING,
    minimum_period_s: float | None = None,
    maximum_period_s: float | None = None,
) -> np.ndarray:
    """Regular frequency grid from the cadence and duration of the samples.

    Parameters
    ----------
    t_s : (n,) float
        Times, seconds, increasing.
    oversampling : float
        Grid points per ``1 / T`` (T the duration).
    minimum_period_s, maximum_period_s : float, optional
        Period range; defaults ``2 dt`` (Nyquist of the median cadence dt) and ``T``.

    Returns
    -------
    (m,) float
        Frequencies in Hz, increasing.
    """
    t_s = np.asarray(t_s, dtype=float)
    duration = float(t_s[-1] - t_s[0])
    cadence = float(np.median(np.diff(t_s)))
    f_min = 1.0 / (maximum_period_s or duration)
    f_max = 1.0 / (minimum_period_s or 2.0 * cadence)
    if not (oversampling > 0 and math.isfinite(oversampling)):
        raise ValueError(f"oversampling={oversampling!r} must be a positive number of grid points per 1/T")
    if not f_max > f_min:
        raise ValueError(
            f"the period range [{1 / f_max:g}, {1 / f_min:g}] s is empty; the shortest period must be "
            f"below the longest (the pass lasts {duration:g} s at a {cadence:g} s cadence)"
        )
    step = 1.0 / (oversampling * duration)
    return f_min + step * np.arange(int(math.floor((f_max - f_min) / step)) + 1)


def _lombscargle(lc: LightCurve, frequency_hz: np.ndarray, weight: np.ndarray, nterms: int) -> np.ndarray:
    ls = LombScargle(lc.t_s, lc.mag, 1.0 / np.sqrt(weight), nterms=nterms)
    if nterms == 1:
        return ls.power(frequency_hz, method="fast", assume_regular_frequency=True)
    return ls.power(frequency_hz, method="fastchi2", assume_regular_frequency=True)


def _pdm_power(lc: LightCurve, frequency_hz: np.ndarray, weight: np.ndarray, nterms: int) -> np.ndarray:
    return 1.0 - _chunked(lambda periods: pdm(lc.t_s, lc.mag, periods, 10), 1.0 / frequency_hz, len(lc))


def _string_length_power(lc: LightCurve, frequency_hz: np.ndarray, weight: np.ndarray, nterms: int) -> np.ndarray:
    lengths = _chunked(lambda periods: string_length(lc.t_s, lc.mag, periods), 1.0 / frequency_hz, len(lc))
    return 1.0 - lengths / lengths.max()


def _chunked(function, periods: np.ndarray, n: int) -> np.ndarray:
    """Evaluate `function` on slices of `periods` so that (m, n) work arrays stay ~50 MB."""
    size = max(1, 2_000_000 // max(n, 1))
    return np.concatenate([function(periods[i : i + size]) for i in range(0, len(periods), size)])


PERIODOGRAM_METHODS = {
    "lombscargle": _lombscargle,
    "pdm": _pdm_power,
    "string_length": _string_length_power,
}


@dataclass(frozen=True, eq=False)
class PowerSpectrum:
    """Power against frequency for one light curve.

    Attributes
    ----------
    frequency_hz, power : (m,) float
    method : str
        Key of `PERIODOGRAM_METHODS`.
    nterms : int
        Fourier terms (Lomb-Scargle only).
    lightcurve : LightCurve
        The (detrended) curve the power was computed from.
    settings : dict
        Grid and weighting settings (oversampling, period range, error floor).
    """

    frequency_hz: np.ndarray
    power: np.ndarray
    method: str
    nterms: int
    lightcurve: LightCurve
    settings: dict = field(default_factory=dict)

    @property
    def period_s(self) -> np.ndarray:
        """(m,) periods of the grid, seconds."""
        return 1.0 / self.frequency_hz

    @property
    def peak_frequency_hz(self) -> float:
        """Frequency of the highest power, refined by a parabola through the peak's grid points."""
        i = int(np.argmax(self.power))
        if 0 < i < len(self.power) - 1:
            left, mid, right = self.power[i - 1 : i + 2]
            curvature = left - 2 * mid + right
            if curvature < 0:
                shift = 0.5 * (left - right) / curvature
                return float(self.frequency_hz[i] + shift * (self.frequency_hz[1] - self.frequency_hz[0]))
        return float(self.frequency_hz[i])

    @property
    def peak_period_s(self) -> float:
        """Period of the highest peak, seconds (not disambiguated: often a harmonic)."""
        return 1.0 / self.peak_frequency_hz

    def false_alarm_probability(self, method: str = "baluev") -> float:
        """astropy's false-alarm probability of the highest peak (Lomb-Scargle, one term only).

        The probability that white noise alone gives a peak this high anywhere on the grid;
        ``method`` is passed to `LombScargle.false_alarm_probability` (``"baluev"``: the
        Baluev 2008 upper bound, fast; ``"bootstrap"`` is slow).
        """
        if self.method != "lombscargle" or self.nterms != 1:
            raise ValueError(
                f"a false-alarm probability needs a one-term Lomb-Scargle periodogram, this one is "
                f"{self.method!r} with nterms={self.nterms}; compute lc.periodogram() first"
            )

        weight = self.lightcurve.weights(self.settings.get("error_floor_mag", DEFAULT_ERROR_FLOOR_MAG))
        ls = LombScargle(self.lightcurve.t_s, self.lightcurve.mag, 1.0 / np.sqrt(weight))
        return float(
            ls.false_alarm_probability(
                float(np.max(self.power)),
                method=method,
                minimum_frequency=float(self.frequency_hz[0]),
                maximum_frequency=float(self.frequency_hz[-1]),
            )
        )

    def plot(self, ax=None, mark_period_s=None, **style):
        """Power against period (log axis); returns the matplotlib axes."""
        ax = axes_or_new(ax)
        ax.plot(self.period_s, self.power, color=style.pop("color", "k"), lw=style.pop("lw", 0.7), **style)
        ax.set_xscale("log")
        ax.set_xlabel("period [s]")
        ax.set_ylabel(f"{self.method} power" + (f" ({self.nterms} terms)" if self.method == "lombscargle" else ""))
        for period in np.atleast_1d(mark_period_s) if mark_period_s is not None else ():
            ax.axvline(period, color="C3", lw=0.8, ls="--")
        return ax

    def to_pandas(self):
        """DataFrame with ``frequency_hz``, ``period_s`` and ``power``."""
        # pandas costs about half a second to import; only this conversion needs it.
        import pandas as pd

        return pd.DataFrame({"frequency_hz": self.frequency_hz, "period_s": self.period_s, "power": self.power})


def power_spectrum(
    lc: LightCurve,
    method: str = "lombscargle",
    *,
    nterms: int = 1,
    oversampling: float | None = None,
    minimum_period_s: float | None = None,
    maximum_period_s: float | None = None,
    error_floor_mag: float = DEFAULT_ERROR_FLOOR_MAG,
) -> PowerSpectrum:
    """Power of a light curve on the grid of `frequency_grid`.

    Parameters
    ----------
    lc : LightCurve
        A raw curve is detrended first (`LightCurve.detrend` with its defaults).
    method : str
        A key of `PERIODOGRAM_METHODS`.
    nterms : int
        Fourier terms for Lomb-Scargle (1 to 10); the grid then stops where the top term reaches
        the Nyquist frequency.
    oversampling : float, optional
        Grid points per 1/T (default by method: 5 for Lomb-Scargle, 20 for the dispersions).
    minimum_period_s, maximum_period_s : float, optional
    error_floor_mag : float

    Returns
    -------
    PowerSpectrum
    """
    if method not in PERIODOGRAM_METHODS:
        raise ValueError(f"method={method!r} is not one of {', '.join(PERIODOGRAM_METHODS)}")
    if not isinstance(nterms, (int, np.integer)) or not 1 <= nterms <= 10:
        raise ValueError(f"nterms={nterms!r} must be a whole number from 1 to 10")
    if oversampling is None:
        oversampling = METHOD_OVERSAMPLING[method]
    if lc.trend_mag is None:
        lc = lc.detrend()
    if minimum_period_s is None and nterms > 1:
        minimum_period_s = 2.0 * lc.cadence_s * nterms
    frequency_hz = frequency_grid(lc.t_s, oversampling, minimum_period_s, maximum_period_s)
    weight = lc.weights(error_floor_mag)
    power = PERIODOGRAM_METHODS[method](lc, frequency_hz, weight, int(nterms))
    settings = {
        "oversampling": float(oversampling),
        "minimum_period_s": minimum_period_s,
        "maximum_period_s": maximum_period_s,
        "error_floor_mag": float(error_floor_mag),
    }
    return PowerSpectrum(
        frequency_hz=frequency_hz,
        power=np.asarray(power, float),
        method=method,
        nterms=int(nterms),
        lightcurve=lc,
        settings=settings,
    )
