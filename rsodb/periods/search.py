"""Spin period of one pass: Lomb-Scargle, harmonic candidates, and an honest verdict.

A plain periodogram peaks at the harmonic with the most power. A rotating satellite with two or
four similar faces puts most power at 2, 3 or 4 times the rotation frequency: on the TOPEX pass
of 2024-07-30 the one-term Lomb-Scargle peak is 2.37 s while the light curve repeats every
9.48 s. `find_period` therefore treats the peak only as a starting point:

1. **Trend and weights.** Magnitudes (range-normalised by the reduction) are fitted with the
   pass trend modelled as a degree-3 Legendre polynomial in time (see `rsodb.periods.lightcurve`),
   weights ``1 / (err^2 + 0.01^2)``.
2. **Periodogram.** astropy's one-term Lomb-Scargle of the detrended curve on the grid of
   `rsodb.periods.periodogram.frequency_grid` (5 points per 1/T, up to the Nyquist frequency of the
   cadence); its false-alarm probability (Baluev 2008) is astropy's.
3. **Candidates.** P/2, P, 2P, 3P and 4P of the peak period P, and of the peak of the harmonic
   sum ``S(f) = sum_{h<=4} power(h f)`` (which lands on the fundamental of a glint curve
   whose power is spread over many harmonics); then twice and half the leading candidate until
   both neighbours of the leader have been tried.
4. **Scores.** Each candidate's frequency is refined by least squares, and it is scored by a
   Fourier series plus the trend (`rsodb.periods.harmonic`) with the harmonic count chosen by the BIC.
   The highest harmonic allowed is the same frequency for every candidate (12 times the peak
   frequency, at most the Nyquist frequency), so the model of 2P contains the model of P and
   the BIC decides whether the odd harmonics of 2P - the difference between the two halves of
   its cycle - are real. A phase-dispersion (PDM) step model with bins of fixed width in time
   is scored the same way as a shape-free second opinion; string length is reported too.
5. **Uncertainty.** From the covariance of the best model linearised in the frequency, scaled
   by the residual scatter and inflated for residual correlation (AR(1)); validated by
   injection (tests/test_periods_injection.py, docs/periods.md).
6. **Verdict**, in this order:

   * ``"no signal"``: the Lomb-Scargle false-alarm probability exceeds 1e-3, or the strongest
     harmonic is less than 4 times the mean residual amplitude spectrum around its frequency
     (the S/N >= 4 criterion of Breger et al. 1993, A&A 271, 482), which rejects slow
     non-repeating variations that white-noise statistics call significant;
   * ``"too short"``: the best period fits fewer than 3 times into the pass;
   * ``"ambiguous harmonic"``: another candidate is within 10 of the best BIC (Kass & Raftery
     1995 call a difference above 10 very strong evidence), or PDM prefers another candidate;
   * ``"confident"`` otherwise.

7. **Synodic and sidereal.** The measured period is synodic; with the pass geometry the
   phase-angle-bisector correction of `rsodb.periods.synodic` gives the sidereal period for either
   sense of rotation.

Results are `PeriodResult` objects, stored in the archive with `to_hdf5` and read with
`PeriodResult.from_hdf5`; `result.prior_interval_s()` gives the interval of a fit's spin-period prior.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
import math
from typing import TYPE_CHECKING

import astropy.units as u
import numpy as np

from rsodb.periods import dispersion
from rsodb.periods.harmonic import (
    HarmonicFit,
    SeriesData,
    TimeAxis,
    bic,
    fit_harmonics,
    max_harmonics,
    nested_rss,
    polish_frequency,
    powers,
    scan_frequency,
)
from rsodb.periods.power import power_spectrum
from rsodb.periods.synodic import SynodicCorrection
from rsodb.storage import attr_plain, attr_text, finite_or_none

if TYPE_CHECKING:
    from rsodb.periods.lightcurve import LightCurve

__all__ = [
    "find_period",
    "PeriodSettings",
    "PeriodResult",
    "Candidate",
    "VERDICTS",
    "METHOD",
    "SCHEMA",
    "DEFAULT_RESULT_NAME",
]

VERDICTS = ("confident", "ambiguous harmonic", "too short", "no signal")
METHOD = "lombscargle+harmonic-bic+pdm"
SCHEMA = "rsodb.periods/1"
DEFAULT_RESULT_NAME = "default"
# Fewer samples than this cannot fit a trend and a few harmonics with any redundancy.
MIN_POINTS = 20
# Significance at which phase dispersion must confirm a period over a shorter one dividing it.
PDM_P_VALUE = 1e-3
# Shorter candidates spanning more samples than this cannot fake a longer period by aliasing
# (their harmonics above the Nyquist frequency, k > 12, carry no measurable power).
ALIAS_MAX_SAMPLES = 25


@dataclass(frozen=True)
class PeriodSettings:
    """Settings of the period search; stored with every result.

    Attributes
    ----------
    oversampling : float
        Frequency-grid points per 1/T.
    trend_degree : int
        Degree of the Legendre trend in time fitted with every model.
    error_floor_mag : float
        Added in quadrature to the magnitude errors for the weights.
    multiples : tuple of float
        Candidate periods as multiples of each base peak period.
    harmonic_sum_terms : int
        Terms of the harmonic-sum base peak (0 or 1 disables it).
    harmonic_ceiling : float
        Highest harmonic frequency allowed in the fits, in units of the peak frequency
        (also capped at the Nyquist frequency).
    max_harmonics : int
        Cap on the harmonic count of any model.
    min_cycles : float
        Fewest cycles in the pass for a period to be more than "too short".
    fap_threshold : float
        Largest false-alarm probability of the Lomb-Scargle peak that counts as a signal.
    snr_threshold : float
        Smallest S/N (amplitude of the strongest harmonic over the residual amplitude spectrum
        around it) that counts as a repeating signal.
    bic_margin : float
        BIC difference to every other candidate needed for "confident".
    refine_margin : float
        Candidates whose scan (low harmonics only) is more than this behind the scan's leader
        in BIC are not polished further; they are reported with their scan scores.
    pdm_bins : int
        PDM bins per Lomb-Scargle peak period (bins have this fixed width in time for all
        candidates, so multiples of the period get proportionally more).
    minimum_period_s, maximum_period_s : float or None
        Search range (defaults: twice the cadence, the pass duration).
    """

    oversampling: float = 5.0
    trend_degree: int = 3
    error_floor_mag: float = 0.01
    multiples: tuple[float, ...] = (0.5, 1.0, 2.0, 3.0, 4.0)
    harmonic_sum_terms: int = 4
    harmonic_ceiling: float = 12.0
    max_harmonics: int = 64
    min_cycles: float = 3.0
    fap_threshold: float = 1e-3
    snr_threshold: float = 4.0
    bic_margin: float = 10.0
    refine_margin: float = 100.0
    pdm_bins: int = 8
    minimum_period_s: float | None = None
    maximum_period_s: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "multiples", tuple(float(m) for m in self.multiples))
        positive = (
            "oversampling",
            "error_floor_mag",
            "harmonic_ceiling",
            "min_cycles",
            "fap_threshold",
            "snr_threshold",
            "bic_margin",
            "refine_margin",
        )
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"period setting {name}={value!r} must be a positive number")
        for name, low, high in (
            ("trend_degree", 0, 10),
            ("harmonic_sum_terms", 0, 16),
            ("max_harmonics", 1, 200),
            ("pdm_bins", 2, 100),
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or not low <= value <= high:
                raise ValueError(f"period setting {name}={value!r} must be a whole number from {low} to {high}")
        if not self.multiples or any(not (math.isfinite(m) and m > 0) for m in self.multiples):
            raise ValueError(
                f"period setting multiples={self.multiples!r} must be positive numbers, e.g. (0.5, 1, 2, 3, 4)"
            )
        for name in ("minimum_period_s", "maximum_period_s"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"period setting {name}={value!r} must be a positive number of seconds or None")

    def replace(self, **changes) -> PeriodSettings:
        """A copy with some settings changed (validated)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise TypeError(
                f"unknown period setting(s) {', '.join(sorted(unknown))}; "
                f"known: {', '.join(f.name for f in fields(self))}"
            )
        return replace(self, **changes)

    def to_dict(self) -> dict:
        record = asdict(self)
        record["multiples"] = list(self.multiples)
        return record

    @classmethod
    def from_dict(cls, record) -> PeriodSettings:
        known = {f.name for f in fields(cls)}
        values = {key: value for key, value in dict(record).items() if key in known}
        if "multiples" in values:
            values["multiples"] = tuple(np.atleast_1d(values["multiples"]).tolist())
        for key in ("trend_degree", "harmonic_sum_terms", "max_harmonics", "pdm_bins"):
            if key in values:
                values[key] = int(values[key])
        for key in ("minimum_period_s", "maximum_period_s"):
            if key in values and values[key] is not None and not math.isfinite(float(values[key])):
                values[key] = None
        return cls(**values)


@dataclass(frozen=True)
class Candidate:
    """One trial period and its scores.

    Attributes
    ----------
    period_s, uncertainty_s : float
        Refined period and its 1-sigma error.
    label : str
        How it was proposed: a multiple of the Lomb-Scargle peak (``"4P"``), of the harmonic-sum
        peak (``"2H"``), or of the leading candidate (``"x2"``, ``"x0.5"``).
    n_harmonics : int
        Harmonics chosen by the BIC.
    bic : float
        BIC of the Fourier model (lower is better).
    delta_bic : float
        ``bic`` minus the best candidate's.
    pdm_theta, pdm_bic : float
        Stellingwerf's theta and the BIC of the binned model.
    string_length : float
    n_cycles : float
        Pass duration over the period.
    """

    period_s: float
    uncertainty_s: float
    label: str
    n_harmonics: int
    bic: float
    delta_bic: float
    pdm_theta: float
    pdm_bic: float
    string_length: float
    n_cycles: float


_CANDIDATE_DTYPE = np.dtype(
    [
        ("period_s", "f8"),
        ("uncertainty_s", "f8"),
        ("label", "S16"),
        ("n_harmonics", "i4"),
        ("bic", "f8"),
        ("delta_bic", "f8"),
        ("pdm_theta", "f8"),
        ("pdm_bic", "f8"),
        ("string_length", "f8"),
        ("n_cycles", "f8"),
    ]
)


@dataclass(frozen=True, eq=False)
class PeriodResult:
    """The period of one pass with everything needed to judge and reuse it.

    Attributes
    ----------
    best_period_s : float
        The synodic (apparent) period; NaN when no candidate could be fitted.
    uncertainty_s : float
        Its 1-sigma error.
    verdict : str
        One of `VERDICTS`.
    reason : str
        One sentence explaining the verdict.
    candidates : tuple of Candidate
        All candidates tried, best first.
    false_alarm_probability : float
        Of the one-term Lomb-Scargle peak (astropy, Baluev method).
    peak_period_s : float
        The Lomb-Scargle peak period (before disambiguation).
    signal_to_noise : float
        Amplitude of the strongest harmonic over the mean residual amplitude around it.
    amplitude_mag : float
        Peak-to-peak range of the periodic model.
    n_cycles : float
        Pass duration over the best period.
    n_points : int
    duration_s : float
    model : HarmonicFit or None
        The best Fourier model (trend included), None without a period.
    synodic : SynodicCorrection or None
        The phase-angle-bisector correction; None without geometry.
    synodic_note : str
        Why `synodic` is missing, if it is.
    settings : PeriodSettings
    method : str
    epoch_utc : numpy.datetime64 or None
        UTC of the curve's ``t_s = 0`` (start of the pass).
    norad : int or None
    band, pass_id, label : str
    """

    best_period_s: float
    uncertainty_s: float
    verdict: str
    reason: str
    candidates: tuple[Candidate, ...]
    false_alarm_probability: float
    peak_period_s: float
    signal_to_noise: float
    amplitude_mag: float
    n_cycles: float
    n_points: int
    duration_s: float
    model: HarmonicFit | None
    synodic: SynodicCorrection | None
    synodic_note: str
    settings: PeriodSettings
    method: str = METHOD
    epoch_utc: np.datetime64 | None = None
    norad: int | None = None
    band: str = ""
    pass_id: str = ""
    label: str = ""

    # -- views -----------------------------------------------------------------------------
    @property
    def best_period(self):
        """The synodic period as an astropy Quantity (seconds)."""
        return self.best_period_s * u.s

    @property
    def has_period(self) -> bool:
        """True when the verdict names a period ("confident" or "ambiguous harmonic")."""
        return self.verdict in ("confident", "ambiguous harmonic")

    @property
    def sidereal_bounds_s(self) -> tuple[float, float]:
        """(shorter, longer) sidereal periods for the two senses of rotation; NaN without geometry."""
        if self.synodic is None:
            return (math.nan, math.nan)
        return (self.synodic.sidereal_prograde_s, self.synodic.sidereal_retrograde_s)

    def prior_interval_s(
        self, width_frac: float = 0.01, frame: str = "sidereal", *, force: bool = False
    ) -> tuple[float, float]:
        """(low, high) of the uniform spin-period prior of a fit, seconds.

        Parameters
        ----------
        width_frac : float
            Half-width as a fraction of the period (default 1%); widened to 3 sigma when the
            period's error is larger.
        frame : {"sidereal", "synodic"}
            ``"synodic"``: ``P (1 +- width_frac)``. ``"sidereal"`` (the fit's spin period is
            inertial): the same interval widened on each side by the phase-angle-bisector
            correction, so both senses of rotation are inside; equal to the synodic interval
            when no geometry was available.
        force : bool
            Give a prior even when the verdict is "too short" or "no signal".

        Raises
        ------
        ValueError
            For a verdict without a period (unless `force`), or a bad width or frame.
        """
        if not (isinstance(width_frac, (int, float)) and 0 < width_frac < 0.5):
            raise ValueError(f"width_frac={width_frac!r} must be a fraction between 0 and 0.5, e.g. 0.01 for +-1%")
        if frame not in ("sidereal", "synodic"):
            raise ValueError(f"frame={frame!r} must be 'sidereal' or 'synodic'")
        if not math.isfinite(self.best_period_s) or (not self.has_period and not force):
            raise ValueError(
                f"pass {self.pass_id or self.label!r} has verdict {self.verdict!r} ({self.reason}); "
                "give the spin-period prior yourself or pass force=True"
            )
        # Never narrower than +-3 sigma: a period measured over few cycles may be less precise
        # than the requested fraction.
        half = max(width_frac * self.best_period_s, 3.0 * self.uncertainty_s)
        low, high = self.best_period_s - half, self.best_period_s + half
        if frame == "sidereal" and self.synodic is not None:
            shorter, longer = self.sidereal_bounds_s
            low -= self.best_period_s - shorter
            high += longer - self.best_period_s
        return low, high

    def folded(self, lightcurve: LightCurve):
        """`lightcurve` folded on the best period with phase 0 at the pass middle."""
        epoch = self.model.axis.t_mid_s if self.model is not None else 0.0
        return lightcurve.fold(self.best_period_s, epoch_s=epoch)

    def summary(self) -> str:
        """One line: period, error, verdict."""
        period = (
            "no period"
            if not math.isfinite(self.best_period_s)
            else f"P = {self.best_period_s:.4f} +- {self.uncertainty_s:.4f} s"
        )
        return f"{self.pass_id or self.label}: {period} ({self.verdict}; {self.reason})"

    def __repr__(self) -> str:
        return f"PeriodResult({self.summary()})"

    # -- conversion ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-ready summary (candidates, settings, synodic correction included)."""
        return {
            "pass_id": self.pass_id,
            "norad": self.norad,
            "band": self.band,
            "label": self.label,
            "epoch_utc": None if self.epoch_utc is None else np.datetime_as_string(self.epoch_utc, unit="ms") + "Z",
            "best_period_s": finite_or_none(self.best_period_s),
            "uncertainty_s": finite_or_none(self.uncertainty_s),
            "verdict": self.verdict,
            "reason": self.reason,
            "false_alarm_probability": finite_or_none(self.false_alarm_probability),
            "peak_period_s": finite_or_none(self.peak_period_s),
            "signal_to_noise": finite_or_none(self.signal_to_noise),
            "amplitude_mag": finite_or_none(self.amplitude_mag),
            "n_cycles": finite_or_none(self.n_cycles),
            "n_points": self.n_points,
            "duration_s": finite_or_none(self.duration_s),
            "candidates": [
                {k: (finite_or_none(v) if isinstance(v, float) else v) for k, v in asdict(c).items()}
                for c in self.candidates
            ],
            "synodic": None
            if self.synodic is None
            else {k: finite_or_none(v) for k, v in self.synodic.to_dict().items()},
            "synodic_note": self.synodic_note,
            "method": self.method,
            "settings": self.settings.to_dict(),
        }

    def to_hdf5(self, group) -> None:
        """Write into an h5py group (attributes, a candidates table, model and settings subgroups)."""
        attrs = group.attrs
        attrs["schema"] = SCHEMA
        attrs["method"] = self.method
        for name in (
            "best_period_s",
            "uncertainty_s",
            "false_alarm_probability",
            "peak_period_s",
            "signal_to_noise",
            "amplitude_mag",
            "n_cycles",
            "duration_s",
        ):
            attrs[name] = float(getattr(self, name))
        attrs["n_points"] = int(self.n_points)
        for name in ("verdict", "reason", "synodic_note", "band", "pass_id", "label"):
            attrs[name] = str(getattr(self, name))
        attrs["norad"] = -1 if self.norad is None else int(self.norad)
        attrs["epoch_utc"] = "" if self.epoch_utc is None else str(np.datetime_as_string(self.epoch_utc, unit="ns"))
        table = np.array(
            [
                tuple(getattr(c, f) if f != "label" else c.label.encode() for f in _CANDIDATE_DTYPE.names)
                for c in self.candidates
            ],
            dtype=_CANDIDATE_DTYPE,
        )
        group.create_dataset("candidates", data=table)
        settings = group.create_group("settings")
        for key, value in self.settings.to_dict().items():
            if value is not None:
                settings.attrs[key] = value
        if self.model is not None:
            model = group.create_group("model")
            model.create_dataset("coefficients", data=self.model.coefficients)
            for name in ("frequency_hz", "frequency_err_hz", "rss", "bic", "residual_lag1", "inflation"):
                model.attrs[name] = float(getattr(self.model, name))
            for name in ("n_harmonics", "trend_degree", "n_points"):
                model.attrs[name] = int(getattr(self.model, name))
            model.attrs["t_mid_s"] = self.model.axis.t_mid_s
            model.attrs["half_span_s"] = self.model.axis.half_span_s
        if self.synodic is not None:
            synodic = group.create_group("synodic")
            for key, value in self.synodic.to_dict().items():
                synodic.attrs[key] = float(value)

    @classmethod
    def from_hdf5(cls, group) -> PeriodResult:
        """Read what `to_hdf5` wrote."""
        attrs = group.attrs
        schema = attr_text(attrs.get("schema", ""))
        if schema != SCHEMA:
            raise ValueError(f"HDF5 group {group.name!r} holds {schema or 'no schema'!r}, not a {SCHEMA} period result")
        candidates = tuple(
            Candidate(
                **{
                    name: (row[name].decode() if name == "label" else row[name].item())
                    for name in _CANDIDATE_DTYPE.names
                }
            )
            for row in group["candidates"][()]
        )
        model = None
        if "model" in group:
            m = group["model"].attrs
            model = HarmonicFit(
                frequency_hz=float(m["frequency_hz"]),
                frequency_err_hz=float(m["frequency_err_hz"]),
                n_harmonics=int(m["n_harmonics"]),
                trend_degree=int(m["trend_degree"]),
                axis=TimeAxis(float(m["t_mid_s"]), float(m["half_span_s"])),
                coefficients=group["model"]["coefficients"][()],
                rss=float(m["rss"]),
                n_points=int(m["n_points"]),
                bic=float(m["bic"]),
                residual_lag1=float(m["residual_lag1"]),
                inflation=float(m["inflation"]),
            )
        synodic = None
        if "synodic" in group:
            synodic = SynodicCorrection(**{k: float(v) for k, v in group["synodic"].attrs.items()})
        settings = PeriodSettings.from_dict({k: attr_plain(v) for k, v in group["settings"].attrs.items()})
        epoch = attr_text(attrs["epoch_utc"])
        norad = int(attrs["norad"])
        return cls(
            best_period_s=float(attrs["best_period_s"]),
            uncertainty_s=float(attrs["uncertainty_s"]),
            verdict=attr_text(attrs["verdict"]),
            reason=attr_text(attrs["reason"]),
            candidates=candidates,
            false_alarm_probability=float(attrs["false_alarm_probability"]),
            peak_period_s=float(attrs["peak_period_s"]),
            signal_to_noise=float(attrs["signal_to_noise"]),
            amplitude_mag=float(attrs["amplitude_mag"]),
            n_cycles=float(attrs["n_cycles"]),
            n_points=int(attrs["n_points"]),
            duration_s=float(attrs["duration_s"]),
            model=model,
            synodic=synodic,
            synodic_note=attr_text(attrs["synodic_note"]),
            settings=settings,
            method=attr_text(attrs["method"]),
            epoch_utc=np.datetime64(epoch, "ns") if epoch else None,
            norad=None if norad < 0 else norad,
            band=attr_text(attrs["band"]),
            pass_id=attr_text(attrs["pass_id"]),
            label=attr_text(attrs["label"]),
        )


# -- the search ------------------------------------------------------------------------------
@dataclass
class _Problem:
    """Arrays and constants shared by the evaluation of every candidate of one curve."""

    data: SeriesData  # magnitudes as given (the trend is fitted jointly)
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
    n_effective: float | None = None  # AR(1) effective sample size, once estimated

    def criterion(self, rss, n_harmonics):
        """BIC of harmonic counts `n_harmonics` with RSS `rss` (effective sample size when known)."""
        return bic(rss, self.data.n_points, n_harmonics, self.settings.trend_degree, self.n_effective)

    def leader(self) -> _Scored | None:
        return min(self.scored, key=lambda s: s.bic) if self.scored else None

    def same(self, f_a: float, f_b: float) -> bool:
        """Two frequencies name the same candidate (closer than a quarter of a resolution element)."""
        return abs(f_a - f_b) < 0.25 / self.duration_s

    def known(self, frequency_hz: float) -> bool:
        return any(self.same(frequency_hz, s.frequency_hz) or self.same(frequency_hz, s.start_hz) for s in self.scored)


@dataclass
class _Scored:
    label: str
    start_hz: float
    fit: HarmonicFit
    k_max: int
    bic: float  # the criterion used for ranking (effective-sample BIC once known)
    rss_curve: np.ndarray  # nested RSS for 0..k harmonics near the candidate's frequency
    refined: bool = False
    scan_hz: float = math.nan  # where the scan put it

    @property
    def frequency_hz(self) -> float:
        return self.scan_hz if self.fit is None else self.fit.frequency_hz


def _finish(problem: _Problem, scored: _Scored) -> None:
    """Fit a candidate left at its scan (for its period error and the ranking table)."""
    if scored.fit is None:
        scored.fit = fit_harmonics(problem.data, scored.scan_hz, _choose(problem, scored.rss_curve))


def _admissible(problem: _Problem, frequency_hz: float) -> bool:
    """A candidate needs one full cycle in the pass and its fundamental under the harmonic ceiling."""
    return (
        frequency_hz * problem.duration_s >= 1.0
        and frequency_hz <= problem.nyquist_hz
        and frequency_hz <= problem.ceiling_hz
    )


def _choose(problem: _Problem, rss_curve: np.ndarray) -> int:
    """Harmonic count with the lowest criterion, from nested RSS for 0..k harmonics."""
    return int(np.argmin(problem.criterion(rss_curve[1:], np.arange(1, len(rss_curve))))) + 1


def _scan(problem: _Problem, frequency_hz: float, label: str) -> _Scored | None:
    """First look at a candidate: its frequency located with the low harmonics only.

    The scanned model keeps the harmonics up to ~3x the Lomb-Scargle peak frequency - the same
    frequency content for every candidate, so the models of P and 2P stay nested and the
    scan's BIC already ranks them fairly.
    """
    s, data = problem.settings, problem.data
    if not _admissible(problem, frequency_hz):
        return None
    k_max = max_harmonics(frequency_hz, problem.ceiling_hz, data.n_points, s.trend_degree, s.max_harmonics)
    k_scan = min(int(math.ceil(3 * problem.peak_hz / frequency_hz)), k_max)
    # The start inherits the error of the Lomb-Scargle peak (up to ~0.15 / T), divided by the
    # multiple: a candidate at f_peak / 4 is known four times better in frequency.
    half_width = 0.3 / problem.duration_s * min(1.0, frequency_hz / problem.peak_hz)
    f, curve = scan_frequency(data, frequency_hz, k_scan, half_width)
    k = _choose(problem, curve)
    # The fit itself waits until it is needed (`_finish`): most scanned candidates get refined.
    return _Scored(label, frequency_hz, None, k_max, float(problem.criterion(curve[k], k)), curve, scan_hz=f)


def _refine(problem: _Problem, scored: _Scored) -> None:
    """Polish a scanned candidate with all its harmonics; the BIC picks their number."""
    data = problem.data
    # Harmonics above the scanned ones are worth trying only if the scan's BIC wanted (nearly)
    # all of the scanned ones: a smooth curve whose BIC stopped early will not want more.
    k_scan = len(scored.rss_curve) - 1
    k_cap = scored.k_max if _choose(problem, scored.rss_curve) >= 0.75 * k_scan else k_scan
    curve = nested_rss(data, scored.frequency_hz, k_cap)
    k = _choose(problem, curve)
    f = polish_frequency(data, scored.frequency_hz, k)
    curve = nested_rss(data, f, k_cap)
    k_new = _choose(problem, curve)
    if k_new != k:
        # A refined frequency keeps high harmonics coherent, so the BIC may then want more of them.
        k = k_new
        f = polish_frequency(data, f, k)
    scored.fit = fit_harmonics(data, f, k)
    scored.bic = float(problem.criterion(scored.fit.rss, k))
    scored.rss_curve = curve
    scored.refined = True


def _score(problem: _Problem, frequency_hz: float, label: str) -> _Scored | None:
    """Scan and refine one candidate."""
    scored = _scan(problem, frequency_hz, label)
    if scored is not None:
        _refine(problem, scored)
    return scored


def _rescore(problem: _Problem, scored: _Scored) -> None:
    """Choose the harmonic count again and recompute the criterion (after `n_effective` changed)."""
    k = _choose(problem, scored.rss_curve)
    if scored.fit is None:
        scored.bic = float(problem.criterion(scored.rss_curve[k], k))
        return
    if k != scored.fit.n_harmonics:
        scored.fit = fit_harmonics(problem.data, scored.fit.frequency_hz, k)
    scored.bic = float(problem.criterion(scored.fit.rss, k))


def _meet_neighbours(problem: _Problem) -> None:
    """Score twice and half the leading candidate until both have been tried."""
    for _ in range(6):
        leader = problem.leader()
        if leader is None:
            return
        added = False
        for factor, tag in ((0.5, "x2"), (2.0, "x0.5")):
            f = leader.frequency_hz * factor
            if not problem.known(f):
                scored = _score(problem, f, f"{leader.label}{tag}")
                if scored is not None:
                    problem.scored.append(scored)
                    added = True
        if not added:
            return


def _harmonic_sum_peak(frequency_hz: np.ndarray, power: np.ndarray, terms: int) -> float | None:
    """Frequency maximising ``sum_{h=1..terms} power(h f)`` over the part of the grid where all terms exist."""
    f_top = frequency_hz[-1] / terms
    usable = frequency_hz <= f_top
    if usable.sum() < 3:
        return None
    f = frequency_hz[usable]
    total = sum(np.interp(h * f, frequency_hz, power) for h in range(1, terms + 1))
    return float(f[int(np.argmax(total))])


def _signal_to_noise(problem: _Problem, fit: HarmonicFit) -> float:
    """Strongest harmonic's amplitude over the mean residual amplitude spectrum around it.

    The noise is the mean of ``(2 / n) |sum r exp(-2 pi i f t)|`` over 64 frequencies within
    ``max(f_k / 2, 25 / T)`` of the strongest harmonic ``f_k`` (clipped to [1/T, Nyquist]), on
    the residuals of the full model: a slow, non-repeating variation leaves a high residual
    spectrum there, a clean periodic signal a low one.
    """
    data = problem.data
    residual = data.y - fit.model_mag(data.t_s)
    amplitudes = fit.harmonic_amplitudes_mag
    k = int(np.argmax(amplitudes)) + 1
    f_k = k * fit.frequency_hz
    half = max(0.5 * f_k, 25.0 / problem.duration_s)
    lo, hi = max(f_k - half, 1.0 / problem.duration_s), min(f_k + half, problem.nyquist_hz)
    n_trial = 64
    # exp(-2 pi i (lo + j df) t) = exp(-2 pi i lo t) * exp(-2 pi i df t)^j: one exp per sample.
    df = (hi - lo) / (n_trial - 1)
    start = np.exp(-2j * np.pi * lo * data.tc) * (residual - residual.mean())
    spectrum = np.abs(_spectrum(data.tc, start, df, n_trial))
    noise = float(np.mean(spectrum) * 2.0 / data.n_points)
    return float(amplitudes[k - 1] / noise) if noise > 0 else math.inf


def _spectrum(tc: np.ndarray, start: np.ndarray, df: float, n_trial: int) -> np.ndarray:
    """(n_trial,) ``sum start * exp(-2 pi i j df t)`` for j = 0..n_trial-1."""
    return powers(np.exp(-2j * np.pi * df * tc)[None, :], n_trial - 1)[0] @ start


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
    detrended = (
        lc
        if lc.trend_mag is not None and lc.trend_degree == settings.trend_degree
        else lc.detrend(settings.trend_degree, settings.error_floor_mag)
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
    problem = _Problem(
        data=SeriesData.from_arrays(lc.t_s, lc.mag, lc.weights(settings.error_floor_mag), settings.trend_degree),
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
    # Only candidates near the scan's leader can win once refined: polish those.
    leader = problem.leader()
    for scored in problem.scored:
        if leader is not None and scored.bic - leader.bic < settings.refine_margin:
            _refine(problem, scored)
    _meet_neighbours(problem)
    # Correlated residuals (red noise, or a shape that drifts during the pass) make every extra
    # harmonic look significant, and multiples of the period fit them best. Re-rank with the
    # AR(1) effective sample size of the leader's residuals (Bayley & Hammersley 1946).
    leader = problem.leader()
    if leader is not None:
        _finish(problem, leader)
    rho = 0.0 if leader is None else min(max(leader.fit.residual_lag1, 0.0), 0.98)
    if rho > 0.05:
        problem.n_effective = problem.data.n_points * (1 - rho) / (1 + rho)
        for scored in problem.scored:
            _rescore(problem, scored)
        _meet_neighbours(problem)
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
    candidates = _rank(problem)
    fit = problem.leader().fit
    best = candidates[0]
    snr = _signal_to_noise(problem, fit)
    verdict, reason = _verdict(problem, candidates, fap, snr, 1.0 / f_peak)

    synodic, note = None, "no pass geometry given"
    if geometry is not None:
        synodic, note = SynodicCorrection.from_geometry(fit.period_s, geometry), ""
    return PeriodResult(
        best_period_s=fit.period_s,
        uncertainty_s=fit.period_err_s,
        verdict=verdict,
        reason=reason,
        candidates=candidates,
        false_alarm_probability=fap,
        peak_period_s=1.0 / f_peak,
        signal_to_noise=snr,
        amplitude_mag=fit.peak_to_peak_mag,
        n_cycles=best.n_cycles,
        n_points=len(lc),
        duration_s=duration,
        model=fit,
        synodic=synodic,
        synodic_note=note,
        settings=settings,
        epoch_utc=lc.epoch_utc,
        norad=lc.norad,
        band=lc.band,
        pass_id=lc.pass_id,
        label=lc.label,
    )


def _multiple_label(multiple: float, symbol: str) -> str:
    if multiple == 1:
        return symbol
    if float(multiple).is_integer():
        return f"{int(multiple)}{symbol}"
    inverse = 1.0 / multiple
    if float(inverse).is_integer():
        return f"{symbol}/{int(inverse)}"
    return f"{multiple:g}{symbol}"


def _rank(problem: _Problem) -> tuple[Candidate, ...]:
    scored = sorted(problem.scored, key=lambda s: s.bic)
    periods = np.array([s.fit.period_s for s in scored])
    bins = np.maximum(2, np.round(periods / problem.pdm_bin_s)).astype(int)
    n = problem.data.n_points
    within, occupied = dispersion.pdm_within(problem.data.t_s, problem.y_detrended, periods, bins)
    total = float(np.sum((problem.y_detrended - problem.y_detrended.mean()) ** 2))
    # Stellingwerf's theta and the binned model's BIC, as in rsodb.periods.dispersion.pdm / pdm_bic.
    theta = (within / np.maximum(n - occupied, 1)) / (total / (n - 1))
    binned_bic = n * np.log(np.maximum(within, 1e-300) / n) + occupied * math.log(n)
    problem.pdm_within.update({float(p): (float(w), float(m)) for p, w, m in zip(periods, within, occupied)})
    strings = dispersion.string_length(problem.data.t_s, problem.y_detrended, periods)
    best_bic = scored[0].bic
    return tuple(
        Candidate(
            period_s=s.fit.period_s,
            uncertainty_s=s.fit.period_err_s,
            label=s.label,
            n_harmonics=s.fit.n_harmonics,
            bic=s.bic,
            delta_bic=s.bic - best_bic,
            pdm_theta=float(theta[i]),
            pdm_bic=float(binned_bic[i]),
            string_length=float(strings[i]),
            n_cycles=problem.duration_s / s.fit.period_s,
        )
        for i, s in enumerate(scored)
    )


def _verdict(
    problem: _Problem, candidates: tuple[Candidate, ...], fap: float, snr: float, peak_period_s: float
) -> tuple[str, str]:
    s = problem.settings
    best = candidates[0]
    if not fap <= s.fap_threshold:
        return "no signal", (
            f"the highest Lomb-Scargle peak ({peak_period_s:.4g} s) has false-alarm probability "
            f"{fap:.2g}, above {s.fap_threshold:g}"
        )
    if best.n_cycles < s.min_cycles:
        return "too short", (
            f"the best period {best.period_s:.4g} s fits only {best.n_cycles:.1f} times in the "
            f"{problem.duration_s:.0f} s pass (fewer than {s.min_cycles:g})"
        )
    if not snr >= s.snr_threshold:
        return "no signal", (
            f"the strongest harmonic of {best.period_s:.4g} s is only {snr:.1f} times the residual "
            f"noise around it (below {s.snr_threshold:g}): the variation does not repeat"
        )
    aliased = _cadence_alias(problem, best, candidates)
    if aliased is not None:
        return "ambiguous harmonic", (
            f"{best.period_s:.4g} s may be an artefact of the sampling: {aliased.period_s:.4g} s "
            f"spans {aliased.period_s / problem.cadence_s:.2f} samples, so its harmonics above "
            f"the Nyquist frequency alias onto those of {best.period_s:.4g} s"
        )
    rivals = [c for c in candidates[1:] if c.delta_bic < s.bic_margin]
    if rivals:
        return "ambiguous harmonic", (
            f"{rivals[0].period_s:.4g} s fits nearly as well as {best.period_s:.4g} s "
            f"(BIC difference {rivals[0].delta_bic:.1f} < {s.bic_margin:g})"
        )
    # Phase dispersion, free of any shape assumption, must confirm that the best cycle is not a
    # repeat of a shorter candidate that divides it (PDM cannot judge longer multiples: finer
    # folds always disperse a little less).
    n = problem.data.n_points
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
    if weakest is not None and not weakest[1] < PDM_P_VALUE:
        return "ambiguous harmonic", (
            f"the Fourier fits prefer {best.period_s:.4g} s but phase dispersion does not "
            f"confirm it over {weakest[0].period_s:.4g} s (F-test p = {weakest[1]:.2g})"
        )
    runner = candidates[1] if len(candidates) > 1 else None
    beaten = (
        f"beats {runner.period_s:.4g} s by a BIC difference of {runner.delta_bic:.0f}" if runner else "only candidate"
    )
    confirmed = (
        f", phase dispersion confirms it over {weakest[0].period_s:.4g} s (p = {weakest[1]:.1g})"
        if weakest is not None
        else ""
    )
    return "confident", f"{best.period_s:.4g} s {beaten}{confirmed}, S/N {snr:.0f}"


def _cadence_alias(problem: _Problem, best: Candidate, candidates) -> Candidate | None:
    """A shorter candidate P dividing the best period r P (r = 2..4) whose sampling makes r P spurious.

    With regular samples every ``dt``, harmonic k of ``1 / P`` above the Nyquist frequency
    appears at ``|1 / dt - k / P|``. When ``P / dt`` is within ``P / T`` (one resolution
    element) of ``m + j / r`` with ``j`` not a multiple of r, those aliases fall on harmonics of
    ``1 / (r P)`` that P itself lacks, and the sampled curve really repeats only every r P.
    Only periods spanning fewer than `ALIAS_MAX_SAMPLES` samples are considered: otherwise the
    harmonics that would alias (above ``P / (2 dt)``) carry no measurable power.
    """
    for c in candidates[1:]:
        ratio = best.period_s / c.period_s
        r = int(round(ratio))
        if not 2 <= r <= 4 or abs(ratio - r) > 0.02 * ratio or c.period_s / problem.cadence_s > ALIAS_MAX_SAMPLES:
            continue
        samples = r * c.period_s / problem.cadence_s
        k = int(round(samples))
        if k % r and abs(samples - k) < r * c.period_s / problem.duration_s:
            return c
    return None
