"""What a period search finds and how it is stored: `PeriodSettings`, `Candidate`, `PeriodResult`.

Kept apart from the search itself (`rsodb.periods.search`, which needs astropy and scipy) so that
reading stored results, as `rsodb periods` does for passes searched before, costs no more than
numpy: see docs/periods.md.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
import math
from typing import TYPE_CHECKING

import numpy as np

from rsodb.periods.harmonic import HarmonicFit, TimeAxis
from rsodb.periods.synodic import SynodicCorrection
from rsodb.periods.verdicts import PERIOD_VERDICTS, VERDICTS
from rsodb.storage import attr_plain, attr_text, finite_or_none

if TYPE_CHECKING:
    from rsodb.periods.lightcurve import LightCurve

__all__ = [
    "PeriodSettings",
    "PeriodResult",
    "Candidate",
    "VERDICTS",
    "METHOD",
    "SCHEMA",
    "READABLE_SCHEMAS",
    "DEFAULT_RESULT_NAME",
]

METHOD = "lombscargle+harmonic-gls-bic+pdm"
SCHEMA = "rsodb.periods/2"
# Results stored before the verdicts of issue 18 (no trend degree per candidate) are still read.
READABLE_SCHEMAS = ("rsodb.periods/1", SCHEMA)
DEFAULT_RESULT_NAME = "default"


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
    trend_degree : int
        Degree of the trend fitted with it (chosen with the harmonic count, see
        `rsodb.periods.harmonic.trend_degree_limit`).
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
    trend_degree: int = 3


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
        ("trend_degree", "i4"),
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
        All candidates tried, the reported one first (the best that repeats at least twice in
        the pass), then by BIC.
    false_alarm_probability : float
        Of the one-term Lomb-Scargle peak (astropy, Baluev method).
    peak_period_s : float
        The Lomb-Scargle peak period (before disambiguation).
    signal_to_noise : float
        Amplitude of the strongest harmonic over the mean residual amplitude around it (never
        below what white noise of the curve's own errors gives).
    amplitude_mag : float
        Peak-to-peak range of the periodic model (never wider than the magnitudes span).
    n_cycles : float
        Pass duration over the best period.
    n_points : int
    duration_s : float
    model : HarmonicFit or None
        The best Fourier model (trend included), None without a period.
    synodic : SynodicCorrection or None
        The phase-angle-bisector correction; None without geometry.
    synodic_note : str
        Why `synodic` is missing, if it is; or where its geometry came from when not from
        orbital elements ("geometry: track fitted to the file's Az/El/range columns ...").
    settings : PeriodSettings
    method : str
    epoch_utc : numpy.datetime64 or None
        UTC of the curve's ``t_s = 0`` (start of the pass).
    norad : int or None
    band, pass_id, label : str
    residual_rho : float
        AR(1) coefficient the magnitudes were prewhitened with (0: white residuals).
    explained_fraction : float
        Share of the brightness variation beyond the noise (about the trend) that the model
        explains.
    noise_mag : float
        Point-to-point noise of the magnitudes (`rsodb.periods.noise.point_to_point_noise_mag`).
    n_flashes : int
        Flashes found (`rsodb.periods.glints`); -1 when not looked for.
    input_sha256 : str
        What the result was found from (the stored pass's content, the settings, the geometry
        switch and the method; `rsodb.campaign.period_survey`): a survey reuses a stored result
        whose inputs are unchanged. Empty when not known.
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
    residual_rho: float = math.nan
    explained_fraction: float = math.nan
    noise_mag: float = math.nan
    n_flashes: int = -1
    input_sha256: str = ""

    # -- views -----------------------------------------------------------------------------
    @property
    def best_period(self):
        """The synodic period as an astropy Quantity (seconds)."""
        import astropy.units as u  # heavy: reading stored results needs numpy only

        return self.best_period_s * u.s

    @property
    def has_period(self) -> bool:
        """True when the verdict names a period ("confident" or "ambiguous harmonic")."""
        return self.verdict in PERIOD_VERDICTS

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
                "give the spin-period prior yourself, or pass force=True (on the command line: rsodb fit --force)"
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
            "residual_rho": finite_or_none(self.residual_rho),
            "explained_fraction": finite_or_none(self.explained_fraction),
            "noise_mag": finite_or_none(self.noise_mag),
            "n_flashes": self.n_flashes,
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
            "residual_rho",
            "explained_fraction",
            "noise_mag",
        ):
            attrs[name] = float(getattr(self, name))
        attrs["n_points"] = int(self.n_points)
        attrs["n_flashes"] = int(self.n_flashes)
        for name in ("verdict", "reason", "synodic_note", "band", "pass_id", "label"):
            attrs[name] = str(getattr(self, name))
        attrs["norad"] = -1 if self.norad is None else int(self.norad)
        if self.input_sha256:
            attrs["input_sha256"] = self.input_sha256
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
        if schema not in READABLE_SCHEMAS:
            raise ValueError(f"HDF5 group {group.name!r} holds {schema or 'no schema'!r}, not a {SCHEMA} period result")
        table = group["candidates"][()]
        candidates = tuple(
            Candidate(
                **{
                    name: (row[name].decode() if name == "label" else row[name].item())
                    for name in _CANDIDATE_DTYPE.names
                    if name in table.dtype.names
                }
            )
            for row in table
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
            residual_rho=float(attrs.get("residual_rho", math.nan)),
            explained_fraction=float(attrs.get("explained_fraction", math.nan)),
            noise_mag=float(attrs.get("noise_mag", math.nan)),
            n_flashes=int(attrs.get("n_flashes", -1)),
            input_sha256=attr_text(attrs.get("input_sha256", "")),
        )
