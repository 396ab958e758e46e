"""The model ladder: fit one pass with shapes and attitude families of growing detail, score each
rung on the part of the pass its fit did not see, and choose the simplest rung within a stated
margin of the best.

Each rung is an ordinary fit (`rsodb.fit`) stored as ``<ladder>.<shape>-<attitude>`` and fitted
on the first ``train_fraction`` of the pass (``[data] start_s``/``duration_s``); every fit
already keeps its best-fit model over the whole pass, so the held-out residuals cost nothing
more. The fits run as one Dask campaign (`rsodb.campaign.fit_campaign.run_campaigns`), so a
ladder of many passes runs on a scheduler address too. docs/real_passes.md explains the choice
and its margin.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
import functools
import math
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from raycast.geometry.pass_geometry import orbit_problem
from rsodb.campaign.fit_campaign import run_campaigns
from rsodb.fit.config import PERIODS_PRIOR, FitConfig, read_toml
from rsodb.fit.conventions import comparable_convention
from rsodb.fit.model import ATTITUDES
from rsodb.fit.prediction import predict_fit
from rsodb.fit.result import FitResult
from rsodb.fit.runner import fit_pass, load_periods
from rsodb.fit.selection import usable_samples
from rsodb.fit.shapes import SHAPES

__all__ = [
    "Rung",
    "RungScore",
    "LadderSettings",
    "LadderPlan",
    "LadderResult",
    "run_ladder",
    "score_ladder",
    "choose_rung",
    "median_rms",
    "NaiveForecast",
    "seasonal_naive",
    "naive_forecast",
]

# Detail of a shape and an attitude family, for ordering rungs of equal parameter count.
SHAPE_RANK = MappingProxyType({"ellipsoid": 0, "lopsided": 0, "box": 1, "box_panels": 2})
MESH_RANK = 3
ATTITUDE_RANK = MappingProxyType({"inertial": 0, "inertial_tilted": 1, "precessing": 2, "torque_free": 3})
# Shapes that look the same after half a turn about their spin axis: their light curve repeats
# twice per spin, so their spin period is twice the light curve's.
HALF_TURN_SYMMETRIC = frozenset({"ellipsoid", "box"})
# [model] keys a rung sets itself (its shape, a built-in model, and its attitude family).
RUNG_OWN_MODEL_KEYS = ("shape", "attitude", "mesh", "materials", "articulations")
# The start of the status of a rung whose model gives no light on some held-out samples.
DARK_STATUS = "model dark at"
# Fewest bootstrap blocks in the held-out part (blocks are shortened to keep this many).
MIN_BLOCKS = 10


@dataclass(frozen=True)
class Rung:
    """One model of the ladder: a shape (a `rsodb.fit.shapes.SHAPES` name) and an attitude family.

    ``parameters`` overlay the base configuration's (e.g. a wider spin-period prior, or a model's
    surface parameters freed with ``{}``); ``sampler`` overlays its sampler settings (e.g. a longer
    ``time_limit_s`` for a rung with more parameters); ``model`` its ``[model]`` settings other
    than the shape (e.g. ``n_sub = 1``, which replaces the base's ``sub_tolerance_mag``).
    """

    shape: str
    attitude: str
    parameters: Mapping[str, Any] = field(default_factory=dict)
    sampler: Mapping[str, Any] = field(default_factory=dict)
    model: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ValueError(f"ladder rung shape={self.shape!r} is not one of {', '.join(SHAPES)}")
        if self.attitude not in ATTITUDES:
            raise ValueError(f"ladder rung attitude={self.attitude!r} is not one of {', '.join(ATTITUDES)}")
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))
        object.__setattr__(self, "sampler", MappingProxyType(dict(self.sampler)))
        own = sorted(set(self.model) & set(RUNG_OWN_MODEL_KEYS))
        if own:
            raise ValueError(
                f"ladder rung {self.name}: model = {{...}} may not set {', '.join(own)} "
                "(a rung's shape and attitude are its own keys)"
            )
        object.__setattr__(self, "model", MappingProxyType(dict(self.model)))

    @classmethod
    def from_dict(cls, record: Mapping) -> Rung:
        unknown = sorted(set(record) - {"shape", "attitude", "parameters", "sampler", "model"})
        if unknown or "shape" not in record or "attitude" not in record:
            raise ValueError(
                f"a ladder rung needs shape and attitude (optional parameters, sampler, model); got {dict(record)!r}"
            )
        return cls(
            record["shape"],
            record["attitude"],
            dict(record.get("parameters", {})),
            dict(record.get("sampler", {})),
            dict(record.get("model", {})),
        )

    @property
    def name(self) -> str:
        return f"{self.shape}-{self.attitude}"

    def config(self, base: FitConfig, ladder: str, duration_s: float) -> FitConfig:
        """The rung's fit: `base` with this shape and attitude, fitted on ``[0, duration_s]``."""
        parameters = dict(base.parameters)
        period = parameters.get("spin_period_s", dict(PERIODS_PRIOR))
        if isinstance(period, Mapping) and "from" in period and self.shape in HALF_TURN_SYMMETRIC:
            period = dict(period, multiple=2.0 * float(period.get("multiple", 1.0)))
        parameters["spin_period_s"] = period
        parameters.update(self.parameters)
        record = base.to_dict()
        record.update(name=f"{ladder}.{self.name}", parameters=parameters)
        overlay = dict(self.model)
        if overlay.get("n_sub"):
            overlay.setdefault("sub_tolerance_mag", 0.0)  # a fixed count replaces the measured one
        record["model"] = dict(
            record["model"],
            shape=self.shape,
            attitude=self.attitude,
            mesh="",
            materials="",
            articulations=[],
            **overlay,
        )
        record["data"] = dict(record["data"], start_s=0.0, duration_s=float(duration_s))
        # emcee's stretch move needs more than twice as many walkers as free parameters (+ jitter).
        attitude = ATTITUDES[self.attitude].parameters
        shape_free = [n for n, spec in parameters.items() if isinstance(spec, Mapping) and n not in attitude]
        walkers = 2 * (len(attitude) + len(set(shape_free) | {"jitter_mag"})) + 2
        sampler = dict(record["sampler"], **self.sampler)
        record["sampler"] = dict(sampler, n_walkers=max(int(sampler["n_walkers"]), walkers))
        return FitConfig.from_dict(record)


@dataclass(frozen=True)
class LadderSettings:
    """How a ladder is fitted and chosen.

    Attributes
    ----------
    name : str
        Prefix of the stored fits (``<name>.<shape>-<attitude>``).
    rungs : tuple of Rung
    train_fraction : float
        The fits see the first this fraction of the pass; the rest is held out.
    margin_floor_mag : float
        The smallest margin (mag): held-out RMS differences below it are not told apart.
    bootstrap : int
        Block-bootstrap resamples behind the standard error of each rung's held-out RMS
        difference from the best.
    seed : int
    """

    name: str = "ladder"
    rungs: tuple = ()
    train_fraction: float = 0.7
    margin_floor_mag: float = 0.02
    bootstrap: int = 500
    seed: int = 0

    def __post_init__(self):
        rungs = tuple(r if isinstance(r, Rung) else Rung.from_dict(r) for r in self.rungs)
        names = [r.name for r in rungs]
        if len(set(names)) != len(names):
            raise ValueError(f"ladder rungs {names} repeat a shape-attitude pair; give each once")
        object.__setattr__(self, "rungs", rungs)
        if not (0.2 <= self.train_fraction <= 0.95):
            raise ValueError(f"[ladder] train_fraction={self.train_fraction!r} must be within 0.2..0.95")
        if not (0 <= self.margin_floor_mag < 1):
            raise ValueError(f"[ladder] margin_floor_mag={self.margin_floor_mag!r} must be within 0..1 mag")
        if not (isinstance(self.bootstrap, int) and self.bootstrap >= 50):
            raise ValueError(f"[ladder] bootstrap={self.bootstrap!r} must be a whole number >= 50")


@dataclass(frozen=True)
class LadderPlan:
    """A ladder campaign: settings, the base fit and per-object additions.

    ``objects`` maps a NORAD number to ``{"rungs": [...], "parameters": {...}}``: rungs added
    to the ladder of that object's passes (e.g. its own model) and parameters overlaid on all
    its rungs (e.g. a forced period prior).
    """

    settings: LadderSettings = field(default_factory=LadderSettings)
    base: FitConfig = field(default_factory=FitConfig)
    objects: Mapping[int, Mapping] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, record: Mapping) -> LadderPlan:
        unknown = sorted(set(record) - {"ladder", "fit", "objects"})
        if unknown:
            raise ValueError(f"ladder configuration has unknown sections {unknown}; allowed: ladder, fit, objects")
        ladder = dict(record.get("ladder", {}))
        allowed = LadderSettings.__dataclass_fields__
        if sorted(set(ladder) - set(allowed)):
            raise ValueError(
                f"[ladder] has unknown keys {sorted(set(ladder) - set(allowed))}; allowed: {', '.join(allowed)}"
            )
        objects = {}
        for norad, extra in dict(record.get("objects", {})).items():
            if not str(norad).isdigit() or not isinstance(extra, Mapping) or set(extra) - {"rungs", "parameters"}:
                raise ValueError(
                    f"[objects.{norad}] must be a NORAD number with rungs and/or parameters; got {extra!r}"
                )
            for rung in extra.get("rungs", ()):
                Rung.from_dict(rung)
            objects[int(norad)] = {
                "rungs": list(extra.get("rungs", ())),
                "parameters": dict(extra.get("parameters", {})),
            }
        return cls(LadderSettings(**ladder), FitConfig.from_dict(record.get("fit", {})), objects)

    @classmethod
    def from_toml(cls, path: str | Path) -> LadderPlan:
        path = Path(path)
        record = read_toml(path, "ladder configuration")
        try:
            return cls.from_dict(record)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: {error}") from None

    def rungs_for(self, norad: int) -> tuple[Rung, ...]:
        """The ladder of one object: the common rungs, then its own."""
        return self.settings.rungs + tuple(Rung.from_dict(r) for r in self.objects.get(norad, {}).get("rungs", ()))

    def base_for(self, norad: int) -> FitConfig:
        """The base fit of one object (its parameters overlaid)."""
        extra = self.objects.get(norad, {}).get("parameters", {})
        return self.base.replace(parameters=dict(self.base.parameters, **extra)) if extra else self.base

    def configs(self, observed) -> list[tuple[Rung, FitConfig]]:
        """(rung, fit configuration) of every rung of a stored pass."""
        usable = usable_samples(observed)
        t_s = observed.t_s[usable]
        if t_s.size < 20:
            raise ValueError(f"pass {observed.pass_id} has {t_s.size} usable samples; a ladder needs at least 20")
        duration_s = float(t_s[0] + self.settings.train_fraction * (t_s[-1] - t_s[0]))
        base = self.base_for(observed.norad)
        return [(rung, rung.config(base, self.settings.name, duration_s)) for rung in self.rungs_for(observed.norad)]


@dataclass(frozen=True)
class RungScore:
    """One rung's fit and scores (NaN where the fit is missing or failed; `status` says why)."""

    rung: str
    shape: str
    attitude: str
    fit_name: str
    status: str = "ok"
    n_parameters: int = 0
    train_rms_mag: float = math.nan
    heldout_rms_mag: float = math.nan
    heldout_se_mag: float = math.nan
    n_train: int = 0
    n_heldout: int = 0
    reduced_chi2: float = math.nan
    converged: bool = False
    verdict: str = ""
    light_curve_period_s: float = math.nan
    elapsed_s: float = math.nan
    median_train_rms_mag: float = math.nan
    median_heldout_rms_mag: float = math.nan

    @property
    def ok(self) -> bool:
        return self.status == "ok" and math.isfinite(self.heldout_rms_mag)

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class NaiveForecast:
    """The held-out samples predicted with no model: each is the training window's last sample at
    the same phase of the light-curve period (:func:`seasonal_naive`).

    A yardstick for the rungs' held-out RMS, not a rung: it has no spin state. A rung that
    predicts the rest of the pass worse than this has not caught how the light curve changes with
    the geometry, however well it fits its training window.

    Attributes
    ----------
    period_s : float
        The lag: the stored light-curve period, or twice it where that forecasts the end of the
        training window better (a period search can find half the period of a body whose two
        halves differ).
    heldout_rms_mag : float
        RMS of observed minus forecast over the rungs' held-out samples.
    se_mag : float
        Moving-block bootstrap standard error of the best rung's held-out RMS minus this one's (the
        rungs' blocks and resamples); NaN when no rung scored.
    n_heldout : int
    """

    period_s: float
    heldout_rms_mag: float
    se_mag: float = math.nan
    n_heldout: int = 0

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class LadderResult:
    """The ladder of one pass: every rung's scores and the chosen rung.

    Attributes
    ----------
    pass_id, name : str
    scores : tuple of RungScore
        Simplest first (fewest free parameters, then the less detailed shape and attitude).
    chosen : str
        The simplest rung whose held-out RMS is within the margin of the best ("" when none scored).
    best : str
        The rung with the lowest held-out RMS.
    margin_floor_mag : float
    train_end_utc : str
        End of the training window; later samples are held out.
    naive : NaiveForecast or None
        The no-model yardstick on the same held-out samples (None when no rung has a fit).
    """

    pass_id: str
    name: str
    scores: tuple
    chosen: str
    best: str
    margin_floor_mag: float
    train_end_utc: str = ""
    naive: NaiveForecast | None = None

    def score(self, rung: str) -> RungScore:
        return next(s for s in self.scores if s.rung == rung)

    def margin_mag(self, score: RungScore) -> float:
        """The margin a rung is allowed: the floor, or its bootstrap standard error if larger."""
        se = score.heldout_se_mag if math.isfinite(score.heldout_se_mag) else 0.0
        return max(self.margin_floor_mag, se)

    def table(self) -> str:
        """The ladder as a text table, simplest rung first."""
        rows = [
            f"ladder {self.name!r} of {self.pass_id}: trained up to {self.train_end_utc} UTC, held out after",
            f"{'rung':<24} {'npar':>4} {'train':>7} {'held-out':>8} {'+-se':>6} {'n_held':>6} "
            f"{'P_pg (s)':>9} {'conv':>5} {'median: train':>13} {'held-out':>8}  status",
        ]
        for s in self.scores:
            mark = " <- chosen" if s.rung == self.chosen else (" (best)" if s.rung == self.best else "")
            rows.append(
                f"{s.rung:<24} {s.n_parameters:>4} {s.train_rms_mag:7.3f} {s.heldout_rms_mag:8.3f} "
                f"{s.heldout_se_mag:6.3f} {s.n_heldout:>6} {s.light_curve_period_s:9.4f} "
                f"{'yes' if s.converged else 'no':>5} {s.median_train_rms_mag:13.3f} {s.median_heldout_rms_mag:8.3f}  "
                f"{s.status}{mark}"
            )
        if self.naive is not None:
            rows.append(self.naive_text())
        rows.append(
            f"RMS in mag of the best-fit sample (median: of the posterior median, when replayed); chosen = simplest rung with held-out RMS within max({self.margin_floor_mag:.3f} mag, "
            "its bootstrap standard error) of the best; P_pg: the period search on the rung's model curve (the "
            "periodogram convention, comparable with the stored period; the light-curve one for fits stored before it)"
        )
        return "\n".join(rows)

    def naive_text(self) -> str:
        """One line on the no-model yardstick and how the best rung compares with it."""
        naive = self.naive
        text = (
            f"no model (each held-out sample = the last training sample at its phase of {naive.period_s:.4f} s): "
            f"held-out RMS {naive.heldout_rms_mag:.3f} mag"
        )
        if not self.best:
            return text
        difference = self.score(self.best).heldout_rms_mag - naive.heldout_rms_mag
        if not math.isfinite(difference):
            return text
        word = "better" if difference < 0 else "worse"
        return f"{text}; the best rung predicts {abs(difference):.3f} mag {word} (+-{naive.se_mag:.3f})"

    def to_dict(self) -> dict:
        return {
            "pass_id": self.pass_id,
            "name": self.name,
            "chosen": self.chosen,
            "best": self.best,
            "margin_floor_mag": self.margin_floor_mag,
            "train_end_utc": self.train_end_utc,
            "scores": [s.to_dict() for s in self.scores],
            "naive": None if self.naive is None else self.naive.to_dict(),
        }


def _heldout_mask(time_utc: np.ndarray, in_window: np.ndarray, observed) -> np.ndarray:
    """(n,) bool over a curve's samples: usable (unsaturated) samples after the training window."""
    usable_times = observed.time_utc[usable_samples(observed)]
    after = time_utc > time_utc[in_window][-1]
    return after & np.isin(time_utc, usable_times)


def median_rms(archive, pass_id: str, fit_name: str, observed=None) -> tuple[float, float]:
    """(training, held-out) residual RMS of a stored fit's posterior median (`predict_fit`), mag."""
    observed = observed or archive.get(pass_id)
    curve = predict_fit(archive, observed.pass_id, fit_name, draws=1).samples
    residuals = curve.mag_obs - curve.mag_model
    heldout = _heldout_mask(curve.time_utc, curve.in_window, observed)
    return _rms(residuals[curve.in_window]), _rms(residuals[heldout])


def _block_indices(n: int, block: int, rng) -> np.ndarray:
    """Moving-block bootstrap: indices of ceil(n / block) random blocks of consecutive samples, cut to n."""
    block = int(min(max(block, 1), n))
    starts = rng.integers(0, n - block + 1, size=math.ceil(n / block))
    return (starts[:, None] + np.arange(block)).ravel()[:n]


def _bootstrap_picks(n: int, block: int, settings) -> tuple[np.ndarray, ...]:
    """``settings.bootstrap`` moving-block resamples of n held-out samples, seeded by
    ``settings.seed``: the same for every comparison of one ladder (a paired bootstrap), drawn
    once for the rungs and the no-model yardstick alike."""
    # At least MIN_BLOCKS blocks, or every resample is the same block and the error reads as zero.
    return _drawn_picks(int(n), max(1, min(int(block), n // MIN_BLOCKS)), int(settings.bootstrap), settings.seed)


# One draw kept: a ladder's rungs and its yardstick ask for it back to back (score_ladder), and a
# campaign of many passes would otherwise hold a few MB of resamples per pass for nothing.
@functools.lru_cache(maxsize=1)
def _drawn_picks(n: int, block: int, count: int, seed) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    picks = tuple(_block_indices(n, block, rng) for _ in range(count))
    for pick in picks:
        pick.flags.writeable = False  # shared by every caller of the cache
    return picks


def _paired_se(residuals: np.ndarray, reference: np.ndarray, picks) -> float:
    """Bootstrap standard error of RMS(residuals) - RMS(reference) over the resamples ``picks``."""
    return float(np.std([_rms(residuals[i]) - _rms(reference[i]) for i in picks], ddof=1))


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def seasonal_naive(t_s: np.ndarray, mag: np.ndarray, train: np.ndarray, at_s: np.ndarray, period_s: float):
    """Forecast magnitudes at times ``at_s`` (s, after the training samples) by the seasonal naive
    rule (R.J. Hyndman, G. Athanasopoulos, *Forecasting: Principles and Practice*, 3rd ed., 2021,
    section 5.2): each is the training curve at the time a whole number of periods earlier that
    falls within the training window's last period, interpolated linearly between its samples.

    Parameters
    ----------
    t_s, mag : (n,) float, sample times (s, increasing) and magnitudes.
    train : (n,) bool, the samples the forecast may use (the last one ends the training window).
    at_s : (k,) float, times to forecast, each after that end.
    period_s : float

    Returns
    -------
    (k,) float
    """
    t_train, m_train = t_s[train], mag[train]
    end = t_train[-1]
    lags = np.ceil((np.asarray(at_s, dtype=float) - end) / period_s)
    return np.interp(at_s - lags * period_s, t_train, m_train)


def naive_forecast(t_s, mag, train, heldout, period_s: float) -> tuple[float, np.ndarray]:
    """(period, residuals): :func:`seasonal_naive`'s residuals (observed minus forecast) on the
    ``heldout`` samples, with the lag chosen between ``period_s`` and twice it by which forecasts
    the training window's last four periods better from what precedes them (the held-out samples
    play no part in the choice). Training windows shorter than eight periods keep ``period_s``."""
    train = np.asarray(train, dtype=bool)
    t_train = t_s[train]
    lag = period_s
    cut = t_train[-1] - 4.0 * period_s
    if t_train[-1] - t_train[0] >= 8.0 * period_s:
        before, check = train & (t_s <= cut), train & (t_s > cut)
        errors = {
            candidate: _rms(mag[check] - seasonal_naive(t_s, mag, before, t_s[check], candidate))
            for candidate in (period_s, 2.0 * period_s)
        }
        lag = min(errors, key=errors.get)
    return lag, mag[heldout] - seasonal_naive(t_s, mag, train, t_s[heldout], lag)


def _naive_yardstick(result: FitResult, observed, period_s: float, best_residuals, block: int, settings):
    """:class:`NaiveForecast` on ``result``'s held-out samples (the rungs' own), with the bootstrap
    standard error of ``best_residuals``' RMS minus its own."""
    heldout = _heldout_mask(result.time_utc, result.in_window, observed)
    if not heldout.any() or not math.isfinite(period_s):
        return None
    times = np.asarray(result.time_utc, dtype="datetime64[ns]")
    t_s = (times - times[0]) / np.timedelta64(1, "s")
    period, residuals = naive_forecast(t_s, result.mag_obs, result.in_window, heldout, period_s)
    se = math.nan
    if best_residuals is not None and best_residuals.size == residuals.size:
        se = _paired_se(best_residuals, residuals, _bootstrap_picks(residuals.size, block, settings))
    return NaiveForecast(float(period), _rms(residuals), se, int(residuals.size))


def _score(rung: Rung, fit_name: str, result: FitResult, observed) -> tuple[RungScore, np.ndarray]:
    heldout = _heldout_mask(result.time_utc, result.in_window, observed)
    residuals = result.residuals_mag
    conventions = dict(result.spin_periods).get("conventions", {})
    # A body with flat faces only can turn every lit face away from the observer: no light where
    # the object was seen, an infinite residual. Such a rung predicts nothing there; say so.
    dark = int(np.count_nonzero(~np.isfinite(residuals[heldout])))
    status = "ok" if not dark else f"{DARK_STATUS} {dark} held-out samples"
    score = RungScore(
        rung.name,
        rung.shape,
        rung.attitude,
        fit_name,
        status if heldout.any() else "no held-out samples",
        len(result.names),
        _rms(residuals[result.in_window]),
        _rms(residuals[heldout]),
        math.nan,
        result.n_window,
        int(heldout.sum()),
        result.reduced_chi2,
        bool(result.converged),
        result.verdict,
        float(conventions.get(comparable_convention(conventions), {}).get("median", math.nan)),
        float(result.elapsed_s),
    )
    return score, residuals[heldout]


def _complexity(score: RungScore, order: int) -> tuple:
    # A rung without a fit counts its attitude's parameters and the jitter.
    count = score.n_parameters or len(ATTITUDES[score.attitude].parameters) + 1
    return (count, SHAPE_RANK.get(score.shape, MESH_RANK), ATTITUDE_RANK[score.attitude], order)


def score_ladder(
    archive, pass_id: str, plan: LadderPlan, failures: Mapping[str, str] | None = None, *, median: bool = False
) -> LadderResult:
    """Score the stored rungs of one pass and choose.

    The margin of a rung is ``max(margin_floor_mag, se)``, where ``se`` is the moving-block
    bootstrap standard error (blocks one stored light-curve period long, the same resampled
    samples for both) of the difference between its held-out RMS and the best rung's: a rung
    is kept when ``rms - rms_best <= margin``. The simplest kept rung is chosen.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    pass_id : str
    plan : LadderPlan
    failures : mapping of fit name to error text, optional
        Fits of this run that failed (shown as the rung's status).
    median : bool
        Also replay every scored rung at its posterior median (`predict_fit`) for the
        ``median_*_rms_mag`` columns (the choice stays on the stored best-fit curves).
    """
    observed = archive.get(pass_id)
    failures = dict(failures or {})
    stored = set(archive.result_names(observed.pass_id, "fits"))
    scores, residuals, train_end, first_result = [], {}, "", None
    for order, (rung, config) in enumerate(plan.configs(observed)):
        if config.name in failures:
            scores.append(
                (
                    RungScore(rung.name, rung.shape, rung.attitude, config.name, f"failed: {failures[config.name]}"),
                    order,
                )
            )
            continue
        if config.name not in stored:
            scores.append((RungScore(rung.name, rung.shape, rung.attitude, config.name, "not fitted"), order))
            continue
        result = archive.load_result(observed.pass_id, "fits", config.name, FitResult.from_hdf5)
        score, heldout = _score(rung, config.name, result, observed)
        if median and score.ok:
            train, held = median_rms(archive, observed.pass_id, config.name, observed)
            score = replace(score, median_train_rms_mag=train, median_heldout_rms_mag=held)
        train_end = str(result.window_utc[1])[:23]
        first_result = first_result or result
        scores.append((score, order))
        residuals[rung.name] = heldout
    scores = [s for s, _ in sorted(scores, key=lambda pair: _complexity(*pair))]
    periods = load_periods(archive, observed.pass_id)
    cadence = float(np.median(np.diff(observed.t_s))) if len(observed) > 1 else 1.0
    block = (
        round(periods.best_period_s / cadence) if periods is not None and math.isfinite(periods.best_period_s) else 1
    )
    scores, chosen, best = choose_rung(scores, residuals, block, plan.settings)
    naive = None
    if first_result is not None and periods is not None:
        naive = _naive_yardstick(
            first_result, observed, float(periods.best_period_s), residuals.get(best), block, plan.settings
        )
    return LadderResult(
        observed.pass_id, plan.settings.name, scores, chosen, best, plan.settings.margin_floor_mag, train_end, naive
    )


def choose_rung(
    scores: Sequence[RungScore], residuals: Mapping[str, np.ndarray], block: int, settings: LadderSettings
) -> tuple[tuple[RungScore, ...], str, str]:
    """Standard errors of the held-out differences and the choice.

    Parameters
    ----------
    scores : sequence of RungScore
        Simplest first.
    residuals : mapping of rung name to (n,) float
        Held-out residuals of every scored rung (the same samples for all).
    block : int
        Samples per bootstrap block (a light-curve period; shortened to keep `MIN_BLOCKS` blocks).
    settings : LadderSettings
        ``margin_floor_mag``, ``bootstrap``, ``seed``.

    Returns
    -------
    (scores with ``heldout_se_mag``, chosen rung, best rung); both names are "" when no rung scored.
    """
    scored = [s for s in scores if s.ok]
    if not scored:
        return tuple(scores), "", ""
    best = min(scored, key=lambda s: s.heldout_rms_mag)
    reference = residuals[best.rung]
    picks = _bootstrap_picks(reference.size, block, settings)
    with_se, chosen = [], ""
    for s in scores:
        if s.ok and s.rung != best.rung and residuals[s.rung].size == reference.size:
            s = replace(s, heldout_se_mag=_paired_se(residuals[s.rung], reference, picks))
        elif s.rung == best.rung:
            s = replace(s, heldout_se_mag=0.0)
        margin = max(settings.margin_floor_mag, s.heldout_se_mag if math.isfinite(s.heldout_se_mag) else 0.0)
        if not chosen and s.ok and s.heldout_rms_mag - best.heldout_rms_mag <= margin:
            chosen = s.rung
        with_se.append(s)
    return tuple(with_se), chosen, best.rung


def run_ladder(
    archive,
    pass_ids: Sequence[str],
    plan: LadderPlan | None = None,
    *,
    scheduler: str | None = None,
    n_workers: int | None = None,
    in_process: bool = False,
    restart: bool = False,
    progress: bool = True,
    median: bool = False,
) -> list[LadderResult]:
    """Fit every rung of every pass (one Dask campaign), store the fits, score and choose.

    Parameters
    ----------
    archive : rsodb.archive.Archive
    pass_ids : sequence of str
    plan : LadderPlan, optional
        Default: `LadderPlan()` (which has no rungs: give them).
    scheduler : str, optional
        Dask scheduler address; default a LocalCluster (`run_campaigns`).
    n_workers : int, optional
        LocalCluster workers.
    in_process : bool
        Fit here, one rung after another, without Dask (tests, debugging).
    restart : bool
        Refit rungs that already have a stored fit.
    progress : bool
    median : bool
        Also replay each rung at its posterior median (`score_ladder`).

    Returns
    -------
    list of LadderResult, in the order of `pass_ids`
    """
    plan = plan or LadderPlan()
    observed = [archive.get(p) for p in pass_ids]
    planned = [(o, config) for o in observed for _, config in plan.configs(o)]
    if not planned:
        raise ValueError("the ladder has no rungs; give [ladder] rungs (or [objects.NORAD] rungs) in its configuration")
    failures: dict[str, dict[str, str]] = {o.pass_id: {} for o in observed}
    groups = []
    # The geometry needs an orbit: the pass's elements, or a track fitted to its columns.
    orbits = {o.pass_id: orbit_problem(o) for o in observed}
    for o, config in planned:
        if orbits[o.pass_id]:
            failures[o.pass_id][config.name] = orbits[o.pass_id]
        else:
            groups.append((config, [o.pass_id]))
    if not groups:
        pass
    elif in_process:
        for config, (pass_id,) in groups:
            if not restart and config.name in archive.result_names(pass_id, "fits"):
                continue
            try:
                fit_pass(archive, pass_id, config, restart=restart, progress=progress)
            except (ValueError, RuntimeError, LookupError) as error:
                failures[pass_id][config.name] = f"{type(error).__name__}: {error}"
    else:
        outcomes = run_campaigns(
            archive, groups, scheduler=scheduler, n_workers=n_workers, restart=restart, progress=progress
        )
        for (config, _), outcome in zip(groups, outcomes):
            for pass_id, error in outcome.failed:
                failures[pass_id][config.name] = error
    return [score_ladder(archive, o.pass_id, plan, failures[o.pass_id], median=median) for o in observed]
