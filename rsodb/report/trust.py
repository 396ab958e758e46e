"""How far to trust a pass's fitted spin state, in one word and the reasons behind it.

`assess` combines the fit's own diagnostics (chain convergence, misfit, warnings) with the
period search of the same pass (its verdict, and whether the fit's light-curve period agrees
with the periodogram's). The levels, best first: ``high``, ``medium``, ``low``, ``none``.

>>> assess(None, None, missing="no orbital elements").text()
'none: no orbital elements'
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import re

from rsodb.fit.result import MIN_AUTOCORR_LENGTHS

__all__ = ["Trust", "assess", "LEVELS", "AGREEMENT_SIGMA"]

LEVELS = ("high", "medium", "low", "none")
# The fit's light-curve period and the periodogram's agree when they differ by less than this
# many combined standard deviations.
AGREEMENT_SIGMA = 3.0


@dataclass(frozen=True)
class Trust:
    """A trust level (one of `LEVELS`) and the reasons that lowered it."""

    level: str
    reasons: tuple[str, ...] = ()

    @property
    def rank(self) -> int:
        """0 for ``high`` ... 3 for ``none`` (sorts best first)."""
        return LEVELS.index(self.level)

    def text(self) -> str:
        """The level and its reasons in one line."""
        return self.level + (": " + "; ".join(self.reasons) if self.reasons else "")


def _lower(level: str, to: str) -> str:
    return max(level, to, key=LEVELS.index)


def assess(fit, period=None, *, missing: str = "not fitted") -> Trust:
    """The trust level of a fit (`rsodb.fit.result.FitResult` or None) beside the period result
    of the same pass (`rsodb.periods.search.PeriodResult` or None).

    ``none`` when there is no fit (`missing` says why); ``low`` when the chain has not converged or
    the model misses the data; ``medium`` when the period search is not confident, the fit's
    light-curve period disagrees with the periodogram's, or the fit carries other warnings.
    """
    if fit is None:
        return Trust("none", (missing,))
    level, reasons = "high", []
    if not fit.converged:
        level = _lower(level, "low")
        reasons.append(_not_converged(fit.verdict))
    for flag in fit.flags:
        kind = flag.split(":")[0]
        if kind == "model misfit":
            level = _lower(level, "low")
            reasons.append(f"model misfit (reduced chi2 {fit.reduced_chi2:.1f})")
        else:
            level = _lower(level, "medium")
            reasons.append(kind)
    if period is None:
        level = _lower(level, "medium")
        reasons.append("no period search of the pass to compare with")
    elif period.verdict != "confident":
        level = _lower(level, "medium")
        reasons.append(f"period search {period.verdict!r}")
    disagreement = _period_disagreement(fit, period)
    if disagreement:
        level = _lower(level, "medium")
        reasons.append(disagreement)
    return Trust(level, tuple(reasons))


def _not_converged(verdict: str) -> str:
    """The convergence verdict's first problem, shortened for a table cell."""
    lengths = re.search(r"only ([\d.]+) autocorrelation times long", verdict)
    if lengths:
        return f"chain not converged ({lengths.group(1)} autocorrelation times, {MIN_AUTOCORR_LENGTHS} wanted)"
    # Long enough, but badly mixed (`assess_convergence`): its problems, not its length.
    mixing = re.search(r"autocorrelation times long \(tau = \d+ steps\), but (.+?): walkers", verdict)
    if mixing:
        return f"chain not converged ({mixing.group(1)})"
    first = verdict.split(". ")[0].split("; ")[0]
    return "chain not converged (" + first.removeprefix("not converged: ").rstrip(".") + ")"


def _period_disagreement(fit, period) -> str:
    """A reason when the fit's light-curve period misses the periodogram's, else ''."""
    conventions = dict(getattr(fit, "spin_periods", {}) or {}).get("conventions", {})
    curve = conventions.get("light_curve")
    if curve is None or period is None or not math.isfinite(period.best_period_s):
        return ""
    sigma_fit = 0.5 * (curve["p84"] - curve["p16"])
    sigma = math.hypot(sigma_fit, period.uncertainty_s if math.isfinite(period.uncertainty_s) else 0.0)
    if not sigma > 0.0:
        return ""
    pulls = {m: abs(curve["median"] - m * period.best_period_s) / sigma for m in (1.0, 2.0, 0.5)}
    if pulls[1.0] <= AGREEMENT_SIGMA:
        return ""
    closest = min(pulls, key=pulls.get)
    relation = f"{closest:g}x the periodogram's" if pulls[closest] <= AGREEMENT_SIGMA else "unlike the periodogram's"
    return (
        f"fitted light-curve period {curve['median']:.4f} s is {relation} "
        f"{period.best_period_s:.4f} +- {period.uncertainty_s:.4f} s"
    )
