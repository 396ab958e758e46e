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

from rsodb.fit.conventions import comparable_convention, fit_conventions
from rsodb.fit.result import MIN_AUTOCORR_LENGTHS, chain_health

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
        reasons.append(_not_converged(fit))
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


def _not_converged(fit) -> str:
    """The chain's first problem (`rsodb.fit.result.chain_health`), short for a table cell."""
    check = chain_health(fit.n_steps - fit.discard, fit.autocorr_time, fit.acceptance_fraction)
    if check.too_short:
        return f"chain not converged ({check.lengths:.1f} autocorrelation times, {MIN_AUTOCORR_LENGTHS} wanted)"
    # Long enough, but badly mixed: its problems, not its length.
    if check.mixing_problems:
        return f"chain not converged ({'; '.join(check.mixing_problems)})"
    # Judged by another rule than today's (a fit stored before the rule changed): its own words.
    return "chain not converged (" + fit.verdict.split(". ")[0].removeprefix("not converged: ").rstrip(".") + ")"


def _period_disagreement(fit, period) -> str:
    """A reason when the fit's light-curve period misses the periodogram's, else ''."""
    conventions = fit_conventions(fit)
    curve = conventions.get(comparable_convention(conventions))
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
