"""Spin periods of light curves: detrending, periodograms, harmonic models, dispersion tests,
the period search with its verdicts, flashes, synodic-to-sidereal correction and spin trends.

>>> from rsodb.periods import LightCurve, find_period                        # doctest: +SKIP
>>> find_period(LightCurve.from_pass(observed_pass)).best_period_s           # doctest: +SKIP

See docs/periods.md.
"""

import lazy_loader

# Loaded on first use: reading stored results (rsodb.periods.result) must not pay for the
# search's astropy and scipy.
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "analysis": ["analyse_pass"],
        "lightcurve": ["FoldedLightCurve", "LightCurve"],
        "periodogram": ["Periodogram", "periodogram"],
        "power": ["PowerSpectrum", "power_spectrum"],
        "result": ["DEFAULT_RESULT_NAME", "VERDICTS", "Candidate", "PeriodResult", "PeriodSettings"],
        "search": ["find_period"],
        "synodic": ["SynodicCorrection"],
        "trend": ["Epoch", "PeriodTrend", "SpinTrend", "fit_period_trend", "trend_from_results"],
    },
)
