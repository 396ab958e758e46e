"""The periodogram of a light curve with the full period search one call away.

A plain power spectrum (`rsodb.periods.power`) peaks at whatever harmonic carries the most
power, which for a rotating satellite is often not the rotation: `Periodogram.best_period`
therefore runs the search of `rsodb.periods.find_period` (harmonic disambiguation), while
`peak_period_s` is the raw peak.
"""

from __future__ import annotations

from dataclasses import fields
from functools import cached_property

import astropy.units as u

from rsodb.periods.power import PowerSpectrum, power_spectrum
from rsodb.periods.search import find_period

__all__ = ["Periodogram", "periodogram"]


class Periodogram(PowerSpectrum):
    """A `PowerSpectrum` whose curve's disambiguated period is one attribute away."""

    def find_period(self, geometry=None, settings=None, **overrides):
        """`rsodb.periods.find_period` on this periodogram's curve, reusing this power."""
        return find_period(self.lightcurve, geometry=geometry, settings=settings, periodogram_=self, **overrides)

    @cached_property
    def result(self):
        """The default `find_period` result (computed once)."""
        return self.find_period()

    @property
    def best_period(self):
        """The disambiguated period as an astropy Quantity in seconds (see `result` for the rest)."""
        return self.result.best_period_s * u.s


def periodogram(lc, method: str = "lombscargle", **options) -> Periodogram:
    """The `Periodogram` of a light curve; arguments as in `rsodb.periods.power.power_spectrum`."""
    spectrum = power_spectrum(lc, method, **options)
    return Periodogram(**{f.name: getattr(spectrum, f.name) for f in fields(spectrum)})
