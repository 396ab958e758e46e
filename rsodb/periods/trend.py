"""Spin-up or spin-down: a straight line through an object's periods against time, epoch by epoch.

Passes of one night measure one spin state: they are merged into an *epoch* (passes less than
`EPOCH_GAP_HOURS` apart), whose period is their weighted mean. A trend is fitted only through
two or more epochs spanning at least `DEFAULT_MIN_SPAN_DAYS`; "spinning up" or "spinning down"
is claimed only when the slope differs from zero by `SIGNIFICANCE_SIGMA` standard errors,
otherwise the result is "no significant trend" with a bound on |dP/dt|. See docs/periods.md.

``P(t) = P_ref + slope (t - t_ref)`` by weighted least squares, the slope in seconds per Julian
year (365.25 d), the reference time the weighted mean epoch (where intercept and slope are
uncorrelated). Each pass's period error is ``sqrt(sigma^2 + delta^2)``: ``sigma`` its
statistical error, ``delta`` its largest synodic-to-sidereal correction (`rsodb.periods.synodic`)
when its geometry is known (the periods are synodic and the sense of rotation is unknown, so the
correction is an error rather than applied). Scatter beyond the errors (reduced chi-square above
1, within an epoch or about the line) scales the errors by the Birge ratio ``sqrt(chi2 / dof)``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = [
    "Epoch",
    "PeriodTrend",
    "SpinTrend",
    "group_epochs",
    "fit_period_trend",
    "trend_from_results",
    "SECONDS_PER_YEAR",
    "DEFAULT_MIN_SPAN_DAYS",
    "EPOCH_GAP_HOURS",
    "SIGNIFICANCE_SIGMA",
]

SECONDS_PER_YEAR = 365.25 * 86400.0
# Passes closer than this belong to one epoch (one night, one spin state).
EPOCH_GAP_HOURS = 12.0
# A trend needs its first and last epochs at least this far apart.
DEFAULT_MIN_SPAN_DAYS = 7.0
# A spin-up or spin-down is claimed only this many standard errors from zero.
SIGNIFICANCE_SIGMA = 2.0


def _weighted_mean(values: np.ndarray, sigma: np.ndarray) -> tuple[float, float, float]:
    """(mean, its error, Birge ratio) with errors scaled up when the scatter exceeds them."""
    weight = 1.0 / sigma**2
    mean = float(np.sum(weight * values) / np.sum(weight))
    error = 1.0 / math.sqrt(float(np.sum(weight)))
    birge = 1.0
    if values.size > 1:
        chi2_reduced = float(np.sum(weight * (values - mean) ** 2)) / (values.size - 1)
        birge = max(1.0, math.sqrt(chi2_reduced))
    return mean, error * birge, birge


@dataclass(frozen=True)
class Epoch:
    """The periods of one night merged.

    Attributes
    ----------
    time_utc : numpy.datetime64
        Weighted mean time of its passes.
    period_s, period_err_s : float
        Weighted mean period and its 1-sigma error (scaled by the Birge ratio when the passes
        disagree beyond their errors).
    n_passes : int
    pass_ids : tuple of str
    """

    time_utc: np.datetime64
    period_s: float
    period_err_s: float
    n_passes: int
    pass_ids: tuple[str, ...] = ()


def group_epochs(time_utc, period_s, period_err_s, pass_ids=None, gap_hours: float = EPOCH_GAP_HOURS):
    """Merge passes less than `gap_hours` apart into epochs.

    Parameters
    ----------
    time_utc : (n,) datetime64
    period_s, period_err_s : (n,) float
        Periods and their 1-sigma errors (> 0).
    pass_ids : (n,) str, optional
    gap_hours : float

    Returns
    -------
    tuple of Epoch
        In time order.
    """
    times = np.asarray(time_utc, dtype="datetime64[ns]")
    period_s = np.asarray(period_s, dtype=float)
    sigma = np.asarray(period_err_s, dtype=float)
    if not (times.shape == period_s.shape == sigma.shape) or times.ndim != 1:
        raise ValueError("time_utc, period_s and period_err_s must be 1-D arrays of one length")
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        raise ValueError("period_err_s must be positive and finite; drop passes without an error")
    ids = np.array(["" for _ in times] if pass_ids is None else list(pass_ids), dtype=object)
    order = np.argsort(times, kind="stable")
    times, period_s, sigma, ids = times[order], period_s[order], sigma[order], ids[order]
    gap = np.timedelta64(int(round(gap_hours * 3600e9)), "ns")
    starts = np.concatenate([[0], np.flatnonzero(np.diff(times) > gap) + 1, [times.size]])
    epochs = []
    for lo, hi in zip(starts[:-1], starts[1:]):
        mean, error, _ = _weighted_mean(period_s[lo:hi], sigma[lo:hi])
        weight = 1.0 / sigma[lo:hi] ** 2
        offset_s = (times[lo:hi] - times[lo]) / np.timedelta64(1, "s")
        centre = times[lo] + np.timedelta64(int(round(float(np.sum(weight * offset_s) / np.sum(weight)) * 1e9)), "ns")
        epochs.append(Epoch(centre, mean, error, int(hi - lo), tuple(str(i) for i in ids[lo:hi])))
    return tuple(epochs)


@dataclass(frozen=True)
class PeriodTrend:
    """A fitted period trend.

    Attributes
    ----------
    slope_s_per_yr, slope_err_s_per_yr : float
        dP/dt and its 1-sigma error (negative: spinning up).
    period_at_reference_s, period_at_reference_err_s : float
    reference_utc : numpy.datetime64
    n_points : int
        Epochs fitted.
    chi2_reduced : float
        About the line; NaN with two epochs.
    birge_ratio : float
        Factor applied to the errors (1 when chi2_reduced <= 1 or undefined).
    epochs : tuple of Epoch
    """

    slope_s_per_yr: float
    slope_err_s_per_yr: float
    period_at_reference_s: float
    period_at_reference_err_s: float
    reference_utc: np.datetime64
    n_points: int
    chi2_reduced: float
    birge_ratio: float
    epochs: tuple[Epoch, ...] = ()

    def period_s(self, time_utc) -> np.ndarray:
        """The line at UTC times (datetime64)."""
        seconds = (np.asarray(time_utc, dtype="datetime64[ns]") - self.reference_utc) / np.timedelta64(1, "s")
        return self.period_at_reference_s + self.slope_s_per_yr * seconds / SECONDS_PER_YEAR

    def period_err_s(self, time_utc) -> np.ndarray:
        """1-sigma error of the line at UTC times (intercept and slope are uncorrelated)."""
        years = (np.asarray(time_utc, dtype="datetime64[ns]") - self.reference_utc) / np.timedelta64(1, "s")
        years = years / SECONDS_PER_YEAR
        return np.hypot(self.period_at_reference_err_s, self.slope_err_s_per_yr * years)

    @property
    def span_days(self) -> float:
        """From the first to the last epoch."""
        if len(self.epochs) < 2:
            return math.nan
        return float((self.epochs[-1].time_utc - self.epochs[0].time_utc) / np.timedelta64(1, "D"))

    @property
    def significance(self) -> float:
        """|slope| in standard errors."""
        return abs(self.slope_s_per_yr) / self.slope_err_s_per_yr if self.slope_err_s_per_yr > 0 else math.inf

    @property
    def sense(self) -> str:
        """ "spinning up", "spinning down" (at `SIGNIFICANCE_SIGMA` or more) or "no significant trend"."""
        if self.significance < SIGNIFICANCE_SIGMA:
            return "no significant trend"
        return "spinning up" if self.slope_s_per_yr < 0 else "spinning down"

    @property
    def bound_s_per_yr(self) -> float:
        """Upper bound on |dP/dt| at `SIGNIFICANCE_SIGMA`: |slope| + that many standard errors."""
        return abs(self.slope_s_per_yr) + SIGNIFICANCE_SIGMA * self.slope_err_s_per_yr

    def summary(self) -> str:
        """One sentence: the claim (or its absence), the numbers, and what they rest on."""
        dates = ", ".join(str(e.time_utc)[:10] for e in self.epochs)
        basis = (
            f"{self.n_points} epochs ({dates}) spanning {self.span_days:.0f} days"
            if self.epochs
            else f"{self.n_points} epochs"
        )
        rate = f"dP/dt = {self.slope_s_per_yr:+.3g} +- {self.slope_err_s_per_yr:.2g} s/yr"
        if self.sense == "no significant trend":
            claim = (
                f"no significant trend: {rate} ({self.significance:.1f} sigma), |dP/dt| < "
                f"{self.bound_s_per_yr:.2g} s/yr ({SIGNIFICANCE_SIGMA:g} sigma)"
            )
        else:
            claim = f"{self.sense}: {rate} ({self.significance:.1f} sigma)"
        scatter = (
            f"; reduced chi-square {self.chi2_reduced:.2g}, errors scaled by {self.birge_ratio:.2g}"
            if math.isfinite(self.chi2_reduced)
            else "; two epochs: no scatter estimate"
        )
        return (
            f"{claim} from {basis}; P = {self.period_at_reference_s:.4f} +- {self.period_at_reference_err_s:.4f} s "
            f"at {str(self.reference_utc)[:10]}{scatter}"
        )


def fit_period_trend(
    time_utc,
    period_s,
    period_err_s,
    *,
    pass_ids=None,
    min_span_days: float = DEFAULT_MIN_SPAN_DAYS,
    epoch_gap_hours: float = EPOCH_GAP_HOURS,
) -> PeriodTrend:
    """Weighted straight line through the epochs of periods against time.

    Parameters
    ----------
    time_utc : (n,) datetime64
    period_s, period_err_s : (n,) float
        Periods and their 1-sigma errors (> 0).
    pass_ids : (n,) str, optional
    min_span_days : float
        Fewest days from the first to the last epoch.
    epoch_gap_hours : float
        Passes closer than this are one epoch.

    Returns
    -------
    PeriodTrend

    Raises
    ------
    ValueError
        With fewer than two epochs, epochs spanning less than `min_span_days`, or non-positive
        errors.

    Examples
    --------
    >>> t = np.array(["2020-01-01", "2021-01-01", "2022-01-01"], dtype="datetime64[ns]")
    >>> trend = fit_period_trend(t, [10.0, 9.9, 9.8], [0.01, 0.01, 0.01])
    >>> round(trend.slope_s_per_yr, 3), trend.sense
    (-0.1, 'spinning up')
    """
    epochs = group_epochs(time_utc, period_s, period_err_s, pass_ids, epoch_gap_hours)
    if len(epochs) < 2:
        raise ValueError(
            f"a period trend needs passes at two or more epochs (nights), got {len(epochs)}: passes less than "
            f"{epoch_gap_hours:g} h apart measure one spin state"
        )
    span_days = float((epochs[-1].time_utc - epochs[0].time_utc) / np.timedelta64(1, "D"))
    if not span_days >= min_span_days:
        raise ValueError(
            f"the epochs span {span_days:.2g} days, less than the {min_span_days:g} days a period trend needs; "
            "add passes further apart or lower min_span_days"
        )
    times = np.array([e.time_utc for e in epochs], dtype="datetime64[ns]")
    period = np.array([e.period_s for e in epochs])
    weight = 1.0 / np.array([e.period_err_s for e in epochs]) ** 2
    seconds = (times - times.min()) / np.timedelta64(1, "s")
    reference_s = float(np.sum(weight * seconds) / np.sum(weight))
    x = (seconds - reference_s) / SECONDS_PER_YEAR
    sxx = float(np.sum(weight * x * x))
    intercept = float(np.sum(weight * period) / np.sum(weight))
    slope = float(np.sum(weight * x * (period - intercept)) / sxx)
    residual = period - intercept - slope * x
    dof = len(epochs) - 2
    chi2_reduced = float(np.sum(weight * residual**2) / dof) if dof > 0 else math.nan
    birge = math.sqrt(chi2_reduced) if dof > 0 and chi2_reduced > 1 else 1.0
    reference = times.min() + np.timedelta64(int(round(reference_s * 1e9)), "ns")
    return PeriodTrend(
        slope_s_per_yr=slope,
        slope_err_s_per_yr=birge / math.sqrt(sxx),
        period_at_reference_s=intercept,
        period_at_reference_err_s=birge / math.sqrt(float(np.sum(weight))),
        reference_utc=reference,
        n_points=len(epochs),
        chi2_reduced=chi2_reduced,
        birge_ratio=birge,
        epochs=epochs,
    )


@dataclass(frozen=True)
class SpinTrend:
    """What an object's period results say about its spin trend, in numbers and in words.

    Attributes
    ----------
    trend : PeriodTrend or None
        None when no trend can be fitted (`note` says why).
    epochs : tuple of Epoch
        The epochs of the results used.
    note : str
        Why there is no trend (empty when there is one).
    verdicts : tuple of str
        The verdicts whose periods were used.
    min_span_days : float
    """

    trend: PeriodTrend | None
    epochs: tuple[Epoch, ...]
    note: str
    verdicts: tuple[str, ...]
    min_span_days: float

    def summary(self) -> str:
        """One sentence for a report."""
        return self.trend.summary() if self.trend is not None else self.note


def trend_from_results(
    results,
    verdicts=("confident",),
    *,
    min_span_days: float = DEFAULT_MIN_SPAN_DAYS,
    epoch_gap_hours: float = EPOCH_GAP_HOURS,
) -> SpinTrend:
    """The spin trend of period results whose verdict is in `verdicts`.

    The error of each period is combined with its largest synodic correction (module notes); the
    time a period describes is the middle of its pass.

    Returns
    -------
    SpinTrend
        With a `PeriodTrend`, or with the reason there is none.
    """
    verdicts = tuple(verdicts)
    chosen = [
        r
        for r in results
        if r.verdict in verdicts and r.epoch_utc is not None and math.isfinite(r.best_period_s) and r.uncertainty_s > 0
    ]
    which = " or ".join(repr(v) for v in verdicts)
    if not chosen:
        return SpinTrend(None, (), f"no trend: no pass has verdict {which}", verdicts, min_span_days)
    sigma = [math.hypot(r.uncertainty_s, r.synodic.max_correction_s if r.synodic is not None else 0.0) for r in chosen]
    times = np.array(
        [r.epoch_utc + np.timedelta64(int(r.duration_s * 5e8), "ns") for r in chosen], dtype="datetime64[ns]"
    )
    periods = [r.best_period_s for r in chosen]
    ids = [r.pass_id for r in chosen]
    epochs = group_epochs(times, periods, sigma, ids, epoch_gap_hours)
    passes = f"{len(chosen)} pass{'es' if len(chosen) != 1 else ''} with verdict {which}"
    if len(epochs) < 2:
        night = str(epochs[0].time_utc)[:10]
        return SpinTrend(
            None,
            epochs,
            f"no trend: the {passes} are from one night ({night}, one epoch); a trend needs epochs at least "
            f"{min_span_days:g} days apart",
            verdicts,
            min_span_days,
        )
    span_days = float((epochs[-1].time_utc - epochs[0].time_utc) / np.timedelta64(1, "D"))
    if span_days < min_span_days:
        return SpinTrend(
            None,
            epochs,
            f"no trend: the {len(epochs)} epochs of the {passes} span {span_days:.1f} days, less than the "
            f"{min_span_days:g} days a trend needs",
            verdicts,
            min_span_days,
        )
    trend = fit_period_trend(
        times, periods, sigma, pass_ids=ids, min_span_days=min_span_days, epoch_gap_hours=epoch_gap_hours
    )
    return SpinTrend(trend, epochs, "", verdicts, min_span_days)
