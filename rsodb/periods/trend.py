"""Spin-up or spin-down: a straight line through an object's periods against time.

``P(t) = P_ref + slope (t - t_ref)`` by weighted least squares, the slope in seconds per
Julian year (365.25 d) and the reference time the weighted mean epoch (where intercept and
slope are uncorrelated). Each period's weight is ``1 / (sigma^2 + delta^2)``:

* ``sigma`` the pass's statistical error;
* ``delta`` the largest synodic-to-sidereal correction of the pass (`rsodb.periods.synodic`) when its
  geometry is known: the periods are synodic and the sense of rotation is unknown, so the
  correction is treated as an error rather than applied.

When the scatter about the line exceeds these errors (reduced chi-square above 1, as it does
whenever passes differ by more than their formal errors), the slope error is scaled by the
Birge ratio ``sqrt(chi2 / dof)``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = ["PeriodTrend", "fit_period_trend", "trend_from_results", "SECONDS_PER_YEAR"]

SECONDS_PER_YEAR = 365.25 * 86400.0


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
    chi2_reduced : float
        NaN with two points.
    birge_ratio : float
        Factor applied to the errors (1 when chi2_reduced <= 1 or undefined).
    """

    slope_s_per_yr: float
    slope_err_s_per_yr: float
    period_at_reference_s: float
    period_at_reference_err_s: float
    reference_utc: np.datetime64
    n_points: int
    chi2_reduced: float
    birge_ratio: float

    def period_s(self, time_utc) -> np.ndarray:
        """The line at UTC times (datetime64)."""
        years = (np.asarray(time_utc, dtype="datetime64[ns]") - self.reference_utc) / np.timedelta64(1, "s")
        return self.period_at_reference_s + self.slope_s_per_yr * years / SECONDS_PER_YEAR

    def summary(self) -> str:
        sense = "spinning up" if self.slope_s_per_yr < 0 else "spinning down"
        return (
            f"dP/dt = {self.slope_s_per_yr:+.4g} +- {self.slope_err_s_per_yr:.2g} s/yr ({sense}) from "
            f"{self.n_points} passes; P = {self.period_at_reference_s:.4f} +- "
            f"{self.period_at_reference_err_s:.4f} s at {str(self.reference_utc)[:10]}"
        )


def fit_period_trend(time_utc, period_s, period_err_s) -> PeriodTrend:
    """Weighted straight line through periods against time.

    Parameters
    ----------
    time_utc : (n,) datetime64
    period_s, period_err_s : (n,) float
        Periods and their 1-sigma errors (> 0).

    Returns
    -------
    PeriodTrend

    Raises
    ------
    ValueError
        With fewer than two distinct times or non-positive errors.

    Examples
    --------
    >>> t = np.array(["2020-01-01", "2021-01-01", "2022-01-01"], dtype="datetime64[ns]")
    >>> trend = fit_period_trend(t, [10.0, 9.9, 9.8], [0.01, 0.01, 0.01])
    >>> round(trend.slope_s_per_yr, 3)
    -0.1
    """
    times = np.asarray(time_utc, dtype="datetime64[ns]")
    period_s = np.asarray(period_s, dtype=float)
    sigma = np.asarray(period_err_s, dtype=float)
    if not (times.shape == period_s.shape == sigma.shape) or times.ndim != 1:
        raise ValueError("time_utc, period_s and period_err_s must be 1-D arrays of one length")
    if len(np.unique(times)) < 2:
        raise ValueError(f"a period trend needs passes at two or more times, got {len(np.unique(times))}")
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        raise ValueError("period_err_s must be positive and finite; drop passes without an error")
    weight = 1.0 / sigma**2
    seconds = (times - times.min()) / np.timedelta64(1, "s")
    reference_s = float(np.sum(weight * seconds) / np.sum(weight))
    x = (seconds - reference_s) / SECONDS_PER_YEAR
    sxx = float(np.sum(weight * x * x))
    intercept = float(np.sum(weight * period_s) / np.sum(weight))
    slope = float(np.sum(weight * x * (period_s - intercept)) / sxx)
    residual = period_s - intercept - slope * x
    dof = len(period_s) - 2
    chi2_reduced = float(np.sum(weight * residual**2) / dof) if dof > 0 else math.nan
    birge = math.sqrt(chi2_reduced) if dof > 0 and chi2_reduced > 1 else 1.0
    reference = times.min() + np.timedelta64(int(round(reference_s * 1e9)), "ns")
    return PeriodTrend(
        slope_s_per_yr=slope,
        slope_err_s_per_yr=birge / math.sqrt(sxx),
        period_at_reference_s=intercept,
        period_at_reference_err_s=birge / math.sqrt(float(np.sum(weight))),
        reference_utc=reference,
        n_points=len(period_s),
        chi2_reduced=chi2_reduced,
        birge_ratio=birge,
    )


def trend_from_results(results, verdicts=("confident",)) -> PeriodTrend | None:
    """The trend of the period results whose verdict is in `verdicts` (None with fewer than two times).

    The error of each period is combined with its largest synodic correction (module notes).
    """
    chosen = [
        r
        for r in results
        if r.verdict in verdicts and r.epoch_utc is not None and math.isfinite(r.best_period_s) and r.uncertainty_s > 0
    ]
    if len({r.epoch_utc for r in chosen}) < 2:
        return None
    sigma = [math.hypot(r.uncertainty_s, r.synodic.max_correction_s if r.synodic is not None else 0.0) for r in chosen]
    # Start of the pass plus half its duration: the time the period describes.
    times = [r.epoch_utc + np.timedelta64(int(r.duration_s * 5e8), "ns") for r in chosen]
    return fit_period_trend(np.array(times, dtype="datetime64[ns]"), [r.best_period_s for r in chosen], sigma)
