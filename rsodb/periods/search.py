"""Spin period of one pass: Lomb-Scargle, harmonic candidates, and an honest verdict.

A plain periodogram peaks at the harmonic with the most power. A rotating satellite with two or
four similar faces puts most power at 2, 3 or 4 times the rotation frequency: on the TOPEX pass
of 2024-07-30 the one-term Lomb-Scargle peak is 2.37 s while the light curve repeats every
9.48 s. `find_period` therefore treats the peak only as a starting point:

1. **Periodogram.** astropy's one-term Lomb-Scargle of the curve with a cubic removed, on the
   grid of `rsodb.periods.power.frequency_grid`; its false-alarm probability (Baluev 2008).
2. **Candidates.** P/2 .. 4P of the peak period P, the peak of the harmonic sum
   ``sum_{h<=4} power(h f)``, then twice and half the leading candidates.
3. **Scores.** Each candidate is a Fourier series plus a Legendre trend in time, fitted jointly
   (`rsodb.periods.harmonic`); the trend may be no more flexible than the candidate's cycles in
   the pass allow (`trend_degree_limit`), and the BIC chooses the harmonic count and the trend's
   degree together. Residuals correlated from sample to sample are handled by generalised least
   squares: the magnitudes are prewhitened for AR(1) noise and every candidate scored again.
4. **The reported period** is the best candidate that repeats at least twice in the pass;
   slower ones (one cycle spanning most of the pass fits any smooth change) only say whether
   the pass is too short.
5. **Verdict** (`rsodb.periods.verdicts`): no signal, single glint, too short, non-periodic,
   aliased, ambiguous harmonic or confident, with one sentence saying why.
6. **Synodic and sidereal.** With the pass geometry, the phase-angle-bisector correction of
   `rsodb.periods.synodic` gives the sidereal period for either sense of rotation.

The narrative, thresholds and their calibration: docs/periods.md. Results are `PeriodResult`
objects, stored in the archive with `to_hdf5` and read with `PeriodResult.from_hdf5`;
`result.prior_interval_s()` gives the interval of a fit's spin-period prior.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.stats import chi2

from rsodb.periods import dispersion
from rsodb.periods.glints import find_flashes
from rsodb.periods.harmonic import (
    HarmonicFit,
    SeriesData,
    bic,
    fit_harmonics,
    max_harmonics,
    nested_rss,
    polish_frequency,
    scan_frequency,
    trend_degree_limit,
)
from rsodb.periods.noise import (
    point_to_point_noise_mag,
    residual_amplitude_mag,
    white_amplitude_mag,
)
from rsodb.periods.power import power_spectrum
from rsodb.periods.result import (
    Candidate,
    PeriodResult,
    PeriodSettings,
)
from rsodb.periods.synodic import SynodicCorrection
from rsodb.periods.verdicts import Evidence, judge

if TYPE_CHECKING:
    from rsodb.periods.lightcurve import LightCurve

# The result, its settings and candidates live in rsodb.periods.result (reading stored results
# needs no search); they are imported here for the search and for older imports.
__all__ = ["find_period", "PeriodSettings", "PeriodResult"]

# Fewer samples than this cannot fit a trend and a few harmonics with any redundancy.
MIN_POINTS = 20
# Shorter candidates spanning more samples than this cannot fake a longer period by aliasing
# (their harmonics above the Nyquist frequency, k > 12, carry no measurable power).
ALIAS_MAX_SAMPLES = 25
# A period is seen to repeat only if the pass holds two of its cycles; slower candidates fit any
# smooth change and are not reported as the period.
REPEAT_CYCLES = 2.0
# AR(1) coefficients: at most this (a random walk has no white part left to fit), and changes
# smaller than this do not repeat the prewhitening.
RHO_MAX = 0.98
RHO_STEP = 0.05
# Gaps of at least this fraction of the pass are checked for cycle-count aliases.
GAP_MIN_FRACTION = 0.05
# A harmonic rival is judged in each half of the pass when it has this many cycles there.
HALF_CYCLES = 1.5


# -- the search ------------------------------------------------------------------------------
@dataclass
class _Problem:
    """Arrays and constants shared by the evaluation of every candidate of one curve."""

    raw: SeriesData  # magnitudes as given, with a trend of the settings' degree (fitted jointly)
    y_detrended: np.ndarray  # for the dispersion scores
    duration_s: float
    cadence_s: float
    nyquist_hz: float
    ceiling_hz: float
    peak_hz: float
    settings: PeriodSettings
    pdm_bin_s: float
    scored: list = field(default_factory=list)
    pdm_within: dict = field(default_factory=dict)  # period_s -> (within SS, occupied bins)
    rho: float = 0.0  # AR(1) coefficient the data are prewhitened with (0: white)
    data: SeriesData | None = None  # what candidates are scored on: `raw` or raw prewhitened
    views: dict = field(default_factory=dict)  # trend degree -> `data` with that trend

    def __post_init__(self):
        if self.data is None:
            self.data = self.raw

    def view(self, degree: int) -> SeriesData:
        """The scored data with a trend of `degree`."""
        if degree not in self.views:
            self.views[degree] = self.data.with_trend_degree(degree)
        return self.views[degree]

    def trend_cap(self, frequency_hz: float) -> int:
        """Highest trend degree a candidate at `frequency_hz` allows (`trend_degree_limit`)."""
        return trend_degree_limit(frequency_hz * self.duration_s, self.raw.n_points, self.settings.trend_degree)

    def prewhiten(self, rho: float) -> None:
        """Score from now on the data prewhitened for AR(1) noise of coefficient `rho`."""
        self.rho = rho
        self.data = self.raw.prewhitened(rho, self.cadence_s) if rho > 0 else self.raw
        self.views = {}

    def criterion(self, rss, n_harmonics, degree: int):
        """BIC of harmonic counts `n_harmonics` with RSS `rss` and a trend of `degree`."""
        return bic(rss, self.data.n_points, n_harmonics, degree)

    def cycles(self, scored: _Scored) -> float:
        return scored.frequency_hz * self.duration_s

    def leader(self, repeating: bool = True) -> _Scored | None:
        """Lowest BIC (among candidates repeating at least twice, when any do)."""
        pool = [s for s in self.scored if not s.degenerate]
        if repeating:
            pool = [s for s in pool if self.cycles(s) >= REPEAT_CYCLES] or pool
        return min(pool, key=lambda s: s.bic) if pool else None

    def same(self, f_a: float, f_b: float) -> bool:
        """Two frequencies name the same candidate (closer than a quarter of a resolution element)."""
        return abs(f_a - f_b) < 0.25 / self.duration_s

    def known(self, frequency_hz: float) -> bool:
        return any(self.same(frequency_hz, s.frequency_hz) or self.same(frequency_hz, s.start_hz) for s in self.scored)


@dataclass
class _Scored:
    label: str
    start_hz: float
    fit: HarmonicFit | None  # on the problem's current data
    k_max: int
    trend_degree: int
    bic: float  # the criterion used for ranking
    rss_curve: np.ndarray  # nested RSS for 0..k harmonics with `trend_degree`, near the candidate's frequency
    refined: bool = False
    scan_hz: float = math.nan  # where the scan put it
    degenerate: bool = False  # its trend and harmonics cancel: a periodic part wider than the data

    @property
    def frequency_hz(self) -> float:
        return self.scan_hz if self.fit is None else self.fit.frequency_hz


def _finish(problem: _Problem, scored: _Scored) -> None:
    """Fit a candidate left at its scan (for its period error and the ranking table)."""
    if scored.fit is None:
        k = _choose(problem, scored.rss_curve, scored.trend_degree)
        scored.fit = fit_harmonics(problem.view(scored.trend_degree), scored.scan_hz, k)


def _admissible(problem: _Problem, frequency_hz: float) -> bool:
    """A candidate needs one full cycle in the pass and its fundamental under the harmonic ceiling."""
    return (
        frequency_hz * problem.duration_s >= 1.0
        and frequency_hz <= problem.nyquist_hz
        and frequency_hz <= problem.ceiling_hz
    )


def _choose(problem: _Problem, rss_curve: np.ndarray, degree: int) -> int:
    """Harmonic count with the lowest criterion, from nested RSS for 0..k harmonics."""
    return int(np.argmin(problem.criterion(rss_curve[1:], np.arange(1, len(rss_curve)), degree))) + 1


def _scan(problem: _Problem, frequency_hz: float, label: str) -> _Scored | None:
    """First look at a candidate: its frequency located with the low harmonics only.

    The scanned model keeps the harmonics up to ~3x the Lomb-Scargle peak frequency - the same
    frequency content for every candidate, so the models of P and 2P stay nested and the
    scan's BIC already ranks them fairly. The trend is the most flexible the candidate allows.
    """
    s = problem.settings
    if not _admissible(problem, frequency_hz):
        return None
    degree = problem.trend_cap(frequency_hz)
    data = problem.view(degree)
    k_max = max_harmonics(frequency_hz, problem.ceiling_hz, data.n_points, degree, s.max_harmonics)
    k_scan = min(int(math.ceil(3 * problem.peak_hz / frequency_hz)), k_max)
    # The start inherits the error of the Lomb-Scargle peak (up to ~0.15 / T), divided by the
    # multiple: a candidate at f_peak / 4 is known four times better in frequency.
    half_width = 0.3 / problem.duration_s * min(1.0, frequency_hz / problem.peak_hz)
    f, curve = scan_frequency(data, frequency_hz, k_scan, half_width)
    k = _choose(problem, curve, degree)
    # The fit itself waits until it is needed (`_finish`): most scanned candidates get refined.
    return _Scored(
        label, frequency_hz, None, k_max, degree, float(problem.criterion(curve[k], k, degree)), curve, scan_hz=f
    )


def _refine(problem: _Problem, scored: _Scored) -> None:
    """Polish a candidate with all its harmonics; the BIC picks their number and the trend's degree."""
    cap = problem.trend_cap(scored.frequency_hz)
    data = problem.view(cap)
    # Harmonics above the scanned ones are worth trying only if the scan's BIC wanted (nearly)
    # all of the scanned ones: a smooth curve whose BIC stopped early will not want more.
    k_scan = len(scored.rss_curve) - 1
    wanted = _choose(problem, scored.rss_curve, scored.trend_degree)
    k_cap = scored.k_max if wanted >= 0.75 * k_scan else k_scan
    curve = nested_rss(data, scored.frequency_hz, k_cap)
    k = _choose(problem, curve, cap)
    f = polish_frequency(data, scored.frequency_hz, k)
    curve = nested_rss(data, f, k_cap)
    k_new = _choose(problem, curve, cap)
    if k_new != k:
        # A refined frequency keeps high harmonics coherent, so the BIC may then want more of them.
        k = k_new
        f = polish_frequency(data, f, k)
    # The trend's degree is chosen with the harmonic count: every degree up to the cap.
    curves = nested_rss(data, f, k_cap, trend_degrees=range(cap + 1))
    best = None
    for degree, curve in enumerate(curves):
        criterion = problem.criterion(curve[1:], np.arange(1, k_cap + 1), degree)
        k_d = int(np.argmin(criterion)) + 1
        if best is None or criterion[k_d - 1] < best[0]:
            best = (float(criterion[k_d - 1]), degree, k_d, curve)
    _, degree, k, curve = best
    scored.fit = fit_harmonics(problem.view(degree), f, k)
    scored.trend_degree = degree
    scored.bic = float(problem.criterion(scored.fit.rss, k, degree))
    scored.rss_curve = curve
    scored.refined = True


def _score(problem: _Problem, frequency_hz: float, label: str) -> _Scored | None:
    """Scan and refine one candidate."""
    scored = _scan(problem, frequency_hz, label)
    if scored is not None:
        _refine(problem, scored)
    return scored


def _rescore(problem: _Problem, scored: _Scored) -> None:
    """Score a candidate again on the problem's (newly prewhitened) data where it stands.

    Only its criterion is recomputed (its frequency barely moves with the weighting); the
    candidates that can still lead are polished again by `_refine_near_leader`.
    """
    scored.scan_hz = scored.frequency_hz
    scored.rss_curve = nested_rss(problem.view(scored.trend_degree), scored.scan_hz, len(scored.rss_curve) - 1)
    k = _choose(problem, scored.rss_curve, scored.trend_degree)
    scored.fit = None
    scored.refined = False
    scored.bic = float(problem.criterion(scored.rss_curve[k], k, scored.trend_degree))


def _meet_neighbours(problem: _Problem) -> None:
    """Score twice and half the leading candidates until both have been tried."""
    for _ in range(6):
        leaders = {id(s): s for s in (problem.leader(), problem.leader(repeating=False)) if s is not None}
        added = False
        for leader in leaders.values():
            for factor, tag in ((0.5, "x2"), (2.0, "x0.5")):
                f = leader.frequency_hz * factor
                if not problem.known(f):
                    scored = _score(problem, f, f"{leader.label}{tag}")
                    if scored is not None:
                        problem.scored.append(scored)
                        added = True
        if not added:
            return


def _refine_near_leader(problem: _Problem) -> None:
    """Polish the candidates near the leader (only they can win once refined)."""
    leader = problem.leader(repeating=False)
    for scored in problem.scored:
        if not scored.refined and leader is not None and scored.bic - leader.bic < problem.settings.refine_margin:
            _refine(problem, scored)


def _raw_fit(problem: _Problem, scored: _Scored) -> HarmonicFit:
    """The candidate's model of the magnitudes as given (for amplitudes, residuals and plots).

    Its frequency and frequency error are those of the candidate's fit on the scored data
    (generalised least squares when prewhitened); the coefficients are ordinary least squares
    on the raw magnitudes at that frequency, with the candidate's harmonics and trend.
    """
    _finish(problem, scored)
    fit = scored.fit
    raw = fit_harmonics(problem.raw.with_trend_degree(scored.trend_degree), fit.frequency_hz, fit.n_harmonics)
    return replace(raw, frequency_err_hz=fit.frequency_err_hz, inflation=fit.inflation)


def _whiten(problem: _Problem) -> None:
    """Generalised least squares for AR(1) residuals: prewhiten, score again, twice at most.

    Correlated residuals (red noise, or a light-curve shape that drifts during the pass) make
    every extra harmonic look significant to a white-noise criterion, and multiples of the period
    - or one slow cycle spanning the pass - fit them best. The lag-1 correlation of the leading
    candidate's raw residuals sets the AR(1) filter; every candidate is then scored on
    the filtered magnitudes (`SeriesData.prewhitened`).
    """
    for _ in range(2):
        leader = problem.leader(repeating=False)
        if leader is None:
            return
        rho = min(max(_raw_fit(problem, leader).residual_lag1, 0.0), RHO_MAX)
        if abs(rho - problem.rho) < RHO_STEP:
            return
        problem.prewhiten(rho)
        for scored in problem.scored:
            _rescore(problem, scored)
        _refine_near_leader(problem)
        _meet_neighbours(problem)


def _harmonic_sum_peak(frequency_hz: np.ndarray, power: np.ndarray, terms: int) -> float | None:
    """Frequency maximising ``sum_{h=1..terms} power(h f)`` over the part of the grid where all terms exist."""
    f_top = frequency_hz[-1] / terms
    usable = frequency_hz <= f_top
    if usable.sum() < 3:
        return None
    f = frequency_hz[usable]
    total = sum(np.interp(h * f, frequency_hz, power) for h in range(1, terms + 1))
    return float(f[int(np.argmax(total))])


def _signal_to_noise(problem: _Problem, fit: HarmonicFit, residual: np.ndarray, error_mag: float) -> float:
    """Strongest harmonic's amplitude over the mean residual amplitude spectrum around it.

    The noise is the mean of ``(2 / n) |sum r exp(-2 pi i f t)|`` over 64 frequencies within
    ``max(f_k / 2, 25 / T)`` of the strongest harmonic ``f_k`` (clipped to [1/T, Nyquist]), on
    the residuals of the full model: a slow, non-repeating variation leaves a high residual
    spectrum there, a clean periodic signal a low one. It is never taken below what white noise
    of the light curve's own errors (`error_mag`) would give, so a noiseless curve does not get
    an unbounded S/N.
    """
    amplitudes = fit.harmonic_amplitudes_mag
    k = int(np.argmax(amplitudes)) + 1
    f_k = k * fit.frequency_hz
    half = max(0.5 * f_k, 25.0 / problem.duration_s)
    lo, hi = max(f_k - half, 1.0 / problem.duration_s), min(f_k + half, problem.nyquist_hz)
    noise = max(
        residual_amplitude_mag(problem.raw.t_s, residual, lo, hi),
        white_amplitude_mag(error_mag, problem.raw.n_points),
    )
    return float(amplitudes[k - 1] / noise) if noise > 0 else math.inf


def _no_result(lc: LightCurve, settings: PeriodSettings, verdict: str, reason: str, **values) -> PeriodResult:
    base = dict(
        best_period_s=math.nan,
        uncertainty_s=math.nan,
        verdict=verdict,
        reason=reason,
        candidates=(),
        false_alarm_probability=math.nan,
        peak_period_s=math.nan,
        signal_to_noise=math.nan,
        amplitude_mag=math.nan,
        n_cycles=math.nan,
        n_points=len(lc),
        duration_s=lc.duration_s,
        model=None,
        synodic=None,
        synodic_note="no period",
        settings=settings,
    )
    base.update(values)
    return PeriodResult(
        **base, epoch_utc=lc.epoch_utc, norad=lc.norad, band=lc.band, pass_id=lc.pass_id, label=lc.label
    )


def find_period(
    lightcurve: LightCurve, geometry=None, settings: PeriodSettings | None = None, *, periodogram_=None, **overrides
) -> PeriodResult:
    """Spin period of one light curve, disambiguated among harmonics, with a verdict.

    Parameters
    ----------
    lightcurve : LightCurve
        Raw or detrended; the trend is refitted jointly with every model anyway.
    geometry : raycast.geometry.PassGeometry, optional
        The pass geometry, for the synodic-to-sidereal correction.
    settings : PeriodSettings, optional
        Defaults to `PeriodSettings()`.
    periodogram_ : rsodb.periods.periodogram.Periodogram, optional
        A one-term Lomb-Scargle periodogram of this curve to reuse.
    **overrides
        Individual settings, e.g. ``min_cycles=2``.

    Returns
    -------
    PeriodResult

    Examples
    --------
    >>> from rsodb.periods import LightCurve
    >>> rng = np.random.default_rng(1)
    >>> t = np.arange(2000) * 0.2
    >>> two_faced = 0.5 * np.cos(4 * np.pi * t / 9.5) + 0.15 * np.cos(2 * np.pi * t / 9.5)
    >>> lc = LightCurve.from_arrays(t, 5 + two_faced + rng.normal(0, 0.02, t.size), np.full(t.size, 0.02))
    >>> result = find_period(lc)
    >>> round(result.best_period_s, 2), result.verdict
    (9.5, 'confident')
    """
    if not all(hasattr(lightcurve, name) for name in ("t_s", "mag", "mag_err", "detrend")):
        raise TypeError(
            f"find_period needs a rsodb.periods.LightCurve, got {type(lightcurve).__name__}; "
            "use LightCurve.from_pass(pass_) or LightCurve.from_arrays(t_s, mag, mag_err)"
        )
    settings = (settings or PeriodSettings()).replace(**overrides)
    lc = lightcurve
    if len(lc) < MIN_POINTS:
        return _no_result(lc, settings, "too short", f"only {len(lc)} usable samples (at least {MIN_POINTS} needed)")
    if np.ptp(lc.mag) == 0:
        return _no_result(lc, settings, "no signal", f"all {len(lc)} magnitudes are equal: the brightness is constant")
    degree = min(settings.trend_degree, trend_degree_limit(math.inf, len(lc), settings.trend_degree))
    detrended = (
        lc if lc.trend_mag is not None and lc.trend_degree == degree else lc.detrend(degree, settings.error_floor_mag)
    )
    if periodogram_ is None or periodogram_.method != "lombscargle" or periodogram_.nterms != 1:
        periodogram_ = power_spectrum(
            detrended,
            oversampling=settings.oversampling,
            minimum_period_s=settings.minimum_period_s,
            maximum_period_s=settings.maximum_period_s,
            error_floor_mag=settings.error_floor_mag,
        )
    f_peak = periodogram_.peak_frequency_hz
    fap = periodogram_.false_alarm_probability()
    duration = lc.duration_s
    nyquist = 0.5 / lc.cadence_s
    weight = lc.weights(settings.error_floor_mag)
    problem = _Problem(
        raw=SeriesData.from_arrays(lc.t_s, lc.mag, weight, degree),
        y_detrended=detrended.mag,
        duration_s=duration,
        cadence_s=lc.cadence_s,
        nyquist_hz=nyquist,
        ceiling_hz=min(nyquist, settings.harmonic_ceiling * f_peak),
        peak_hz=f_peak,
        settings=settings,
        pdm_bin_s=1.0 / (f_peak * settings.pdm_bins),
    )

    bases = [("P", f_peak)]
    if settings.harmonic_sum_terms > 1:
        f_sum = _harmonic_sum_peak(periodogram_.frequency_hz, periodogram_.power, settings.harmonic_sum_terms)
        if f_sum is not None and not problem.same(f_sum, f_peak):
            bases.append(("H", f_sum))
    # Multiples of the peak; the harmonic-sum peak enters alone (the leader's neighbours follow).
    for symbol, f_base in bases:
        for multiple in settings.multiples if symbol == "P" else (1.0,):
            f = f_base / multiple
            if not problem.known(f):
                scored = _scan(problem, f, _multiple_label(multiple, symbol))
                if scored is not None:
                    problem.scored.append(scored)
    _refine_near_leader(problem)
    _meet_neighbours(problem)
    _whiten(problem)
    if not problem.scored:
        return _no_result(
            lc,
            settings,
            "too short",
            f"no candidate period fits in the {duration:.0f} s pass at a {lc.cadence_s:g} s cadence",
            false_alarm_probability=fap,
            peak_period_s=1.0 / f_peak,
        )

    for scored in problem.scored:
        _finish(problem, scored)
    noise_mag = point_to_point_noise_mag(lc.t_s, lc.mag, lc.cadence_s)
    error_mag = float(np.sqrt(np.median(1.0 / weight)))
    best, model = _best_model(problem, noise_mag)
    candidates = _rank(problem, best)
    residual = lc.mag - model.model_mag(lc.t_s)
    snr = _signal_to_noise(problem, model, residual, error_mag)
    evidence, explained = _evidence(problem, lc, best, model, candidates, fap, snr, residual, noise_mag, weight)
    verdict, reason = judge(evidence, settings)

    synodic, note = None, "no pass geometry given"
    if geometry is not None:
        synodic, note = SynodicCorrection.from_geometry(model.period_s, geometry), ""
    return PeriodResult(
        best_period_s=model.period_s,
        uncertainty_s=model.period_err_s,
        verdict=verdict,
        reason=reason,
        candidates=candidates,
        false_alarm_probability=fap,
        peak_period_s=1.0 / f_peak,
        signal_to_noise=snr,
        amplitude_mag=model.peak_to_peak_mag,
        n_cycles=candidates[0].n_cycles,
        n_points=len(lc),
        duration_s=duration,
        model=model,
        synodic=synodic,
        synodic_note=note,
        settings=settings,
        epoch_utc=lc.epoch_utc,
        norad=lc.norad,
        band=lc.band,
        pass_id=lc.pass_id,
        label=lc.label,
        residual_rho=problem.rho,
        explained_fraction=explained,
        noise_mag=noise_mag,
        n_flashes=evidence.flashes.count,
    )


def _best_model(problem: _Problem, noise_mag: float) -> tuple[_Scored, HarmonicFit]:
    """The reported candidate and its raw model.

    The best candidate that repeats at least twice in the pass, unless a slower one beats it by
    the BIC margin (then the pass is too short for any period, and the slow one is the best
    description). A candidate whose trend and harmonics cancel each other (possible only when
    they nearly share a span) gets a periodic part swinging far beyond the magnitudes; it is
    marked degenerate and the next one leads.
    """
    span = float(np.ptp(problem.raw.y)) + 4.0 * (noise_mag if math.isfinite(noise_mag) else 0.0)
    while True:
        best, overall = problem.leader(), problem.leader(repeating=False)
        if overall.bic < best.bic - problem.settings.bic_margin:
            best = overall
        model = _raw_fit(problem, best)
        if model.peak_to_peak_mag <= span or all(s.degenerate or s is best for s in problem.scored):
            return best, model
        best.degenerate = True


def _evidence(problem, lc, best, model, candidates, fap, snr, residual, noise_mag, weight):
    """The `Evidence` of the verdict, and the fraction of the variation the best model explains."""
    s = problem.settings
    raw = problem.raw.with_trend_degree(best.trend_degree)
    sw = np.sqrt(weight)
    coefficients, *_ = np.linalg.lstsq(raw.trend * sw[:, None], lc.mag * sw, rcond=None)
    about_trend = lc.mag - raw.trend @ coefficients
    gain = float(np.sum(weight * about_trend**2) - np.sum(weight * residual**2))
    limit = float(chi2.isf(s.fap_threshold, 2 * model.n_harmonics + 1))
    explained, structured = _explained(problem, best)
    flashes = find_flashes(lc.t_s, lc.mag, noise_mag, problem.cadence_s)
    # Scored candidates in the order of `candidates` (the reported one first).
    by_scored = {candidates[i]: scored for i, scored in enumerate(_ranked(problem, best))}
    evidence = Evidence(
        duration_s=problem.duration_s,
        cadence_s=problem.cadence_s,
        false_alarm_probability=fap,
        peak_period_s=1.0 / problem.peak_hz,
        flat=(gain, limit) if gain < limit else None,
        signal_to_noise=snr,
        structured=structured,
        explained_fraction=explained,
        best=candidates[0],
        candidates=candidates,
        flashes=flashes,
        flashes_alone=_flashes_alone(lc, flashes, problem.settings),
        cadence_alias=_cadence_alias(problem, candidates[0], candidates),
        gap_alias=_gap_alias(problem, best),
        covered_s=_covered_s(problem),
        pdm_weakest=_pdm_weakest(problem, candidates),
        halves=_halves(problem, best, by_scored),
        conservative=_conservative_rival(problem, best, model, by_scored),
    )
    return evidence, explained


def _flashes_alone(lc: LightCurve, flashes, settings: PeriodSettings) -> bool:
    """True unless one or two dominant flashes leave a significant periodic signal behind them.

    Weak flashes repeating through the pass can show one of them above the noise; the rest of
    the curve then still has a Lomb-Scargle peak below the false-alarm threshold.
    """
    if not (flashes.dominant and flashes.count <= 2):
        return True
    rest = lc.select(flashes.outside(lc.t_s))
    if len(rest) < MIN_POINTS:
        return True
    spectrum = power_spectrum(rest.detrend(min(settings.trend_degree, 3)), error_floor_mag=settings.error_floor_mag)
    return not spectrum.false_alarm_probability() <= settings.fap_threshold


def _explained(problem: _Problem, best: _Scored) -> tuple[float, bool]:
    """Share of the variation beyond the noise that the best model explains, and whether the rest is noise.

    Judged on the scored magnitudes (prewhitened when the residuals were correlated), where
    red noise and slow drifts are whitened away: what remains unexplained there is structure at
    the time scales of the period that does not repeat. The noise is the point-to-point scatter
    of those magnitudes; the residual is structured when its variance exceeds the noise's by
    more than `max(25%, 8 / sqrt(n))` (the scatter of that estimate is ~2.5 / sqrt(n)).
    """
    data = problem.view(best.trend_degree)
    coefficients, *_ = np.linalg.lstsq(
        data.trend * np.sqrt(data.weight)[:, None], data.y * np.sqrt(data.weight), rcond=None
    )
    signal_var = float(np.var(data.y - data.trend @ coefficients))
    residual_var = float(np.var(data.y - best.fit.model_mag(data.t_s)))
    noise = point_to_point_noise_mag(data.t_s, data.y, problem.cadence_s)
    noise_var = noise**2 if math.isfinite(noise) else 0.0
    structured = residual_var > noise_var * (1.0 + max(0.25, 8.0 / math.sqrt(data.n_points)))
    excess = signal_var - noise_var
    return ((signal_var - residual_var) / excess if excess > 0 else math.nan), structured


def _multiple_label(multiple: float, symbol: str) -> str:
    if multiple == 1:
        return symbol
    if float(multiple).is_integer():
        return f"{int(multiple)}{symbol}"
    inverse = 1.0 / multiple
    if float(inverse).is_integer():
        return f"{symbol}/{int(inverse)}"
    return f"{multiple:g}{symbol}"


def _ranked(problem: _Problem, best: _Scored) -> list[_Scored]:
    """The scored candidates, the reported one first and the others by BIC."""
    return [best] + sorted((s for s in problem.scored if s is not best), key=lambda s: s.bic)


def _rank(problem: _Problem, best: _Scored) -> tuple[Candidate, ...]:
    """Every candidate, the reported one first and the others by BIC."""
    scored = _ranked(problem, best)
    periods = np.array([s.fit.period_s for s in scored])
    bins = np.maximum(2, np.round(periods / problem.pdm_bin_s)).astype(int)
    y = problem.y_detrended
    n = y.shape[0]
    within, occupied = dispersion.pdm_within(problem.raw.t_s, y, periods, bins)
    total = float(np.sum((y - y.mean()) ** 2))
    # Stellingwerf's theta and the binned model's BIC, as in rsodb.periods.dispersion.pdm / pdm_bic.
    with np.errstate(invalid="ignore", divide="ignore"):
        theta = (within / np.maximum(n - occupied, 1)) / (total / (n - 1))
    binned_bic = n * np.log(np.maximum(within, 1e-300) / n) + occupied * math.log(n)
    problem.pdm_within.update({float(p): (float(w), float(m)) for p, w, m in zip(periods, within, occupied)})
    strings = dispersion.string_length(problem.raw.t_s, y, periods)
    return tuple(
        Candidate(
            period_s=s.fit.period_s,
            uncertainty_s=s.fit.period_err_s,
            label=s.label,
            n_harmonics=s.fit.n_harmonics,
            bic=s.bic,
            delta_bic=s.bic - best.bic,
            pdm_theta=float(theta[i]),
            pdm_bic=float(binned_bic[i]),
            string_length=float(strings[i]),
            n_cycles=problem.duration_s / s.fit.period_s,
            trend_degree=s.trend_degree,
        )
        for i, s in enumerate(scored)
    )


def _pdm_weakest(problem: _Problem, candidates) -> tuple[Candidate, float] | None:
    """The shorter candidate dividing the best with the largest PDM F-test p-value.

    Phase dispersion, free of any shape assumption, must confirm that the best cycle is not a
    repeat of a shorter candidate that divides it (PDM cannot judge longer multiples: finer
    folds always disperse a little less).
    """
    best = candidates[0]
    n = problem.raw.n_points
    w_best, m_best = problem.pdm_within[best.period_s]
    weakest = None
    for c in candidates[1:]:
        ratio = best.period_s / c.period_s
        if ratio < 1.5 or abs(ratio - round(ratio)) > 0.02 * ratio:
            continue
        w_short, m_short = problem.pdm_within[c.period_s]
        p_value = dispersion.pdm_f_test(n, w_short, m_short, w_best, m_best)
        if weakest is None or not p_value <= weakest[1]:
            weakest = (c, p_value)
    return weakest


def _cadence_alias(problem: _Problem, best: Candidate, candidates) -> Candidate | None:
    """A shorter candidate P dividing the best period r P (r = 2..4) whose sampling makes r P spurious.

    With regular samples every ``dt``, harmonic k of ``1 / P`` above the Nyquist frequency
    appears at ``|1 / dt - k / P|``. When ``P / dt`` is within ``P / T`` (one resolution
    element) of ``m + j / r`` with ``j`` not a multiple of r, those aliases fall on harmonics of
    ``1 / (r P)`` that P itself lacks, and the sampled curve really repeats only every r P.
    Only periods spanning fewer than `ALIAS_MAX_SAMPLES` samples are considered, and only
    when the shorter candidate's own model needs harmonics up to half the Nyquist frequency:
    otherwise the harmonics that would alias (above the Nyquist frequency) carry no measurable
    power.
    """
    for c in candidates[1:]:
        ratio = best.period_s / c.period_s
        r = int(round(ratio))
        if not 2 <= r <= 4 or abs(ratio - r) > 0.02 * ratio or c.period_s / problem.cadence_s > ALIAS_MAX_SAMPLES:
            continue
        if c.n_harmonics / c.period_s < 0.5 * problem.nyquist_hz:
            continue
        samples = r * c.period_s / problem.cadence_s
        k = int(round(samples))
        if k % r and abs(samples - k) < r * c.period_s / problem.duration_s:
            return c
    return None


def _gap_alias(problem: _Problem, best: _Scored) -> tuple[float, float, float] | None:
    """A period with one cycle more or less across a gap that fits nearly as well as the best.

    Across a gap the count of cycles is known only as well as the period from the data on
    either side: ``f +- 1 / D`` (D between the centres of the data before and after the gap)
    fit the two sides alike when their own periods are not precise to a fraction of a
    cycle over D. The largest gap is checked when it lasts at least `GAP_MIN_FRACTION` of the
    pass and 10 cadences; each alias is polished with the best candidate's harmonics and trend.

    Returns
    -------
    (period_s, bic_difference, gap_s) of the closest alias within the BIC margin, or None.
    """
    t = problem.raw.t_s
    step = np.diff(t)
    large = np.flatnonzero(step >= max(GAP_MIN_FRACTION * problem.duration_s, 10 * problem.cadence_s))
    if not large.size:
        return None
    fit = best.fit
    data = problem.view(best.trend_degree)
    closest = None
    for i in large[np.argsort(step[large])[-1:]]:
        separation = float(np.mean(t[i + 1 :]) - np.mean(t[: i + 1]))
        for k in (-1, 1):
            f = fit.frequency_hz + k / separation
            if f * problem.duration_s < REPEAT_CYCLES or f > problem.ceiling_hz:
                continue
            f = polish_frequency(data, f, fit.n_harmonics)
            if problem.same(f, fit.frequency_hz):
                continue
            rss = nested_rss(data, f, fit.n_harmonics)[-1]
            delta = float(problem.criterion(rss, fit.n_harmonics, best.trend_degree)) - best.bic
            if delta < problem.settings.bic_margin and (closest is None or delta < closest[1]):
                closest = (1.0 / f, delta, float(step[i]))
    return closest


def _covered_s(problem: _Problem) -> float:
    """Time the samples cover: the pass without its gaps (steps as long as `_gap_alias` checks)."""
    step = np.diff(problem.raw.t_s)
    gap = step >= max(GAP_MIN_FRACTION * problem.duration_s, 10 * problem.cadence_s)
    return float(np.sum(step[~gap]) + (np.count_nonzero(gap) + 1) * problem.cadence_s)


def _harmonic_ratio(period_a: float, period_b: float) -> int:
    """r when the longer period is r = 2..4 times the shorter within 2%, else 0."""
    ratio = max(period_a, period_b) / min(period_a, period_b)
    r = int(round(ratio))
    return r if 2 <= r <= 4 and abs(ratio - r) <= 0.02 * ratio else 0


def _halves(problem: _Problem, best: _Scored, by_candidate: dict) -> tuple[Candidate, float, float] | None:
    """A harmonic rival that one half of the pass, fitted alone, does not clearly reject.

    Each half of the scored magnitudes is fitted at the best's and at every harmonically
    related repeating rival's frequency, with their harmonic counts and a common trend no more
    flexible than the longer period allows in the half. A confident period must beat each rival
    in both halves by at least half the BIC margin: a copy of the pass truncated to either half
    must not come to a different choice, and a feature seen in one half only (a light curve
    whose halves differ early in the pass and look alike later) does not make a confident claim.

    Returns
    -------
    (rival, BIC difference in the first half, in the second) for the rival with the smallest
    difference below half the margin, or None when both halves prefer the best by that much.
    """
    data, settings = problem.data, problem.settings
    # Only rivals that repeat at least one and a half times in a half can be judged there.
    rivals = [
        (candidate, scored)
        for candidate, scored in by_candidate.items()
        if scored is not best
        and not scored.degenerate
        and problem.cycles(scored) >= HALF_CYCLES * 2
        and scored.bic - best.bic < settings.refine_margin
        and _harmonic_ratio(scored.fit.period_s, best.fit.period_s)
    ]
    if not rivals:
        return None
    mid = 0.5 * (data.t_s[0] + data.t_s[-1])
    deltas = {id(scored): [] for _, scored in rivals}
    for half in (data.t_s <= mid, data.t_s > mid):
        t = data.t_s[half]
        span = t[-1] - t[0] if t.size > 1 else 0.0
        full = SeriesData.from_arrays(t, data.y[half], data.weight[half], settings.trend_degree)

        def criterion(fit: HarmonicFit) -> float:
            # Each model with the trend its own period allows in the half, as in the full pass.
            degree = trend_degree_limit(fit.frequency_hz * span, full.n_points, settings.trend_degree)
            sub = full.with_trend_degree(min(degree, full.trend_degree))
            curve = nested_rss(sub, fit.frequency_hz, fit.n_harmonics)
            return float(bic(curve[-1], sub.n_points, fit.n_harmonics, sub.trend_degree))

        reference = criterion(best.fit)
        for _, scored in rivals:
            deltas[id(scored)].append(criterion(scored.fit) - reference)
    worst = None
    for candidate, scored in rivals:
        first, second = deltas[id(scored)]
        if min(first, second) < 0.5 * settings.bic_margin and (
            worst is None or min(first, second) < min(worst[1], worst[2])
        ):
            worst = (candidate, first, second)
    return worst


def _conservative_rival(problem: _Problem, best: _Scored, model: HarmonicFit, by_candidate: dict):
    """The best rival under the conservative treatment of correlated residuals, if within the margin.

    Generalised least squares trusts the AR(1) model of the residuals. Residual structure that
    AR(1) does not describe (a shape changing during the pass, slow non-repeating swings) can
    make it overconfident, so a confident period must also win when the correlation is counted
    as if it held at every frequency: the raw magnitudes' BIC with the effective sample size
    ``n (1 - rho) / (1 + rho)`` (Bayley & Hammersley 1946) of the best model's raw residuals,
    the harmonic count chosen again under it.

    Returns
    -------
    (Candidate, BIC difference to the best) or None.
    """
    rho = min(max(model.residual_lag1, 0.0), RHO_MAX)
    if rho <= RHO_STEP:
        return None
    n = problem.raw.n_points
    n_effective = n * (1 - rho) / (1 + rho)

    def criterion(scored: _Scored) -> float:
        fit = scored.fit
        curve = nested_rss(problem.raw.with_trend_degree(scored.trend_degree), fit.frequency_hz, fit.n_harmonics)
        values = bic(curve[1:], n, np.arange(1, fit.n_harmonics + 1), scored.trend_degree, n_effective)
        return float(np.min(values))

    reference = criterion(best)
    worst = None
    for candidate, scored in by_candidate.items():
        if scored is best or scored.degenerate:
            continue
        delta = criterion(scored) - reference
        if delta < problem.settings.bic_margin and (worst is None or delta < worst[1]):
            worst = (candidate, delta)
    return worst
