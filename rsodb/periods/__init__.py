"""Spin periods of light curves: detrending, periodograms, harmonic models, dispersion tests,
the period search with its verdicts, flashes, synodic-to-sidereal correction and spin trends.

>>> from rsodb.periods import LightCurve, find_period                        # doctest: +SKIP
>>> find_period(LightCurve.from_pass(observed_pass)).best_period_s           # doctest: +SKIP

See docs/periods.md.
"""

from rsodb.periods.analysis import analyse_pass
from rsodb.periods.lightcurve import FoldedLightCurve, LightCurve
from rsodb.periods.periodogram import Periodogram, periodogram
from rsodb.periods.power import PowerSpectrum, power_spectrum
from rsodb.periods.search import (
    DEFAULT_RESULT_NAME,
    VERDICTS,
    Candidate,
    PeriodResult,
    PeriodSettings,
    find_period,
)
from rsodb.periods.synodic import SynodicCorrection
from rsodb.periods.trend import Epoch, PeriodTrend, SpinTrend, fit_period_trend, trend_from_results

__all__ = [
    "analyse_pass",
    "FoldedLightCurve",
    "LightCurve",
    "Periodogram",
    "periodogram",
    "PowerSpectrum",
    "power_spectrum",
    "DEFAULT_RESULT_NAME",
    "VERDICTS",
    "Candidate",
    "PeriodResult",
    "PeriodSettings",
    "find_period",
    "SynodicCorrection",
    "Epoch",
    "PeriodTrend",
    "SpinTrend",
    "fit_period_trend",
    "trend_from_results",
]
