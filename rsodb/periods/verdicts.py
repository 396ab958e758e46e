"""The verdict on a period search: what the evidence allows one to say, in one word and one sentence.

`find_period` gathers an `Evidence` record (false-alarm probability, the candidates and their
BIC, the explained fraction, flashes, aliases, split-half preferences...) and `judge` turns it
into one of `VERDICTS`, checked in this order:

1. ``"no signal"``: the brightness is constant within its errors, apart from the pass trend;
2. ``"single glint"``: one flash carries most of the variation; ``"too short"``: two do (one or
   two flashes put no peak in a periodogram, so this comes before the next check);
3. ``"no signal"``: the Lomb-Scargle peak could be noise (false-alarm probability above the
   threshold);
4. ``"too short"``: the best period fits fewer than `min_cycles` times in the pass (also when a
   variation slower than any repeating period fits best);
5. ``"no signal"`` or ``"non-periodic"``: the strongest harmonic is below S/N 4 against the
   residual around it (white residual: no signal; structured residual: non-periodic);
6. ``"non-periodic"``: the best period explains less than half of the variation beyond the
   noise, and the rest is not noise;
7. ``"aliased"``: the sampling can make the period up (cadence commensurate with a shorter
   candidate, fewer than 3 samples per cycle, a count of cycles across a gap that another
   count fits as well, or fewer than `MIN_CONFIDENT_CYCLES` cycles in the sampled stretches
   when the pass holds more across its gaps);
8. ``"ambiguous harmonic"``: a harmonically related candidate fits nearly as well, phase
   dispersion does not confirm the period, a half of the pass does not reject a harmonic rival
   by half the margin, or a rival fits nearly as well when the residuals' correlation is
   counted at every frequency, or the pass holds fewer than `MIN_CONFIDENT_CYCLES` cycles (twice
   the period could not be tested);
9. ``"confident"``.

Only "confident" and "ambiguous harmonic" name a period (`PERIOD_VERDICTS`). The thresholds and
their calibration are in docs/periods.md.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

__all__ = [
    "VERDICTS",
    "PERIOD_VERDICTS",
    "Evidence",
    "judge",
    "EXPLAINED_MIN",
    "MIN_SAMPLES_PER_CYCLE",
    "PDM_P_VALUE",
    "MIN_CONFIDENT_CYCLES",
]

VERDICTS = ("confident", "ambiguous harmonic", "aliased", "non-periodic", "single glint", "too short", "no signal")
PERIOD_VERDICTS = ("confident", "ambiguous harmonic")
# The best period must explain at least this fraction of the variation beyond the noise.
EXPLAINED_MIN = 0.5
# Fewer samples per cycle than this, and the frame rate's alias 1 / (1/dt - 1/P) is too close to tell.
MIN_SAMPLES_PER_CYCLE = 3.0
# Significance at which phase dispersion must confirm a period over a shorter one dividing it.
PDM_P_VALUE = 1e-3
# A confident period P must exclude 2P, which the search tests only when the pass holds two of
# its cycles: at least 4 cycles of P.
MIN_CONFIDENT_CYCLES = 4.0


@dataclass(frozen=True)
class Evidence:
    """What the verdict on one light curve is decided from (built by `find_period`).

    Attributes
    ----------
    duration_s, cadence_s : float
    false_alarm_probability, peak_period_s : float
        Of the one-term Lomb-Scargle peak.
    flat : tuple of (float, float) or None
        (chi-square gained by the best model over the trend alone, the gain noise would exceed
        with the false-alarm probability threshold) when the gain is below that, else None.
    signal_to_noise : float
    structured : bool
        The residual of the best model is significantly above the white noise.
    explained_fraction : float
        Share of the variation beyond the noise that the best model explains.
    best : Candidate
        The reported candidate (the best that repeats at least twice in the pass).
    candidates : tuple of Candidate
        All, best first.
    flashes : rsodb.periods.glints.Flashes
    covered_s : float
        Time the samples cover: the pass without its gaps (NaN: not measured).
    flashes_alone : bool
        Without the flash samples, the light curve has no significant Lomb-Scargle peak (the
        flashes are all there is).
    cadence_alias : Candidate or None
        A shorter candidate whose sampling makes `best` an artefact.
    gap_alias : tuple of (float, float, float) or None
        (period, BIC difference, gap) of a cycle-count alias across a gap fitting nearly as well.
    pdm_weakest : tuple of (Candidate, float) or None
        The shorter candidate dividing `best` with the largest PDM F-test p-value.
    halves : tuple of (Candidate, float, float) or None
        A harmonic rival and the BIC by which each half of the pass prefers `best` to it, when
        a half prefers the rival.
    conservative : tuple of (Candidate, float) or None
        The best rival and its BIC difference to `best` when the residuals' correlation is
        counted at every frequency (effective sample size), if within the margin.
    """

    duration_s: float
    cadence_s: float
    false_alarm_probability: float
    peak_period_s: float
    flat: tuple | None
    signal_to_noise: float
    structured: bool
    explained_fraction: float
    best: object
    candidates: tuple
    flashes: object
    cadence_alias: object | None
    gap_alias: tuple | None
    pdm_weakest: tuple | None
    halves: tuple | None
    conservative: tuple | None = None
    flashes_alone: bool = True
    covered_s: float = math.nan


def _period(candidate) -> str:
    error = candidate.uncertainty_s
    return f"{candidate.period_s:.4g} +- {error:.2g} s" if math.isfinite(error) else f"{candidate.period_s:.4g} s"


def _listing(candidates, count: int = 3) -> str:
    return "; ".join(f"{_period(c)} ({c.n_cycles:.1f} cycles)" for c in candidates[:count])


def judge(e: Evidence, settings) -> tuple[str, str]:
    """(verdict, reason) from the evidence, in the order of the module notes.

    Parameters
    ----------
    e : Evidence
    settings : rsodb.periods.search.PeriodSettings
        The thresholds (`fap_threshold`, `snr_threshold`, `min_cycles`, `bic_margin`).
    """
    s, best = settings, e.best
    if e.flat is not None:
        gain, limit = e.flat
        return "no signal", (
            f"the best model improves chi-square over the pass trend alone by {gain:.1f}, less than the "
            f"{limit:.1f} noise gives at p = {s.fap_threshold:g}: the brightness is constant within its errors"
        )
    if e.flashes.dominant and e.flashes.count == 1 and e.flashes_alone:
        return "single glint", (
            f"one flash carries the variation ({e.flashes.describe()}): a period needs it to repeat"
        )
    if e.flashes.dominant and e.flashes.count == 2 and e.flashes_alone:
        gap = abs(float(e.flashes.peak_t_s[1] - e.flashes.peak_t_s[0]))
        return "too short", (
            f"two flashes {gap:.4g} s apart carry the variation ({e.flashes.describe()}): one interval, "
            f"fewer than {s.min_cycles:g} cycles"
        )
    if not e.false_alarm_probability <= s.fap_threshold:
        return "no signal", (
            f"the highest Lomb-Scargle peak ({e.peak_period_s:.4g} s) has false-alarm probability "
            f"{e.false_alarm_probability:.2g}, above {s.fap_threshold:g}"
        )
    if best.n_cycles < s.min_cycles:
        return "too short", (
            f"the best period fits fewer than {s.min_cycles:g} times in the {e.duration_s:.0f} s pass; "
            f"candidates: {_listing(e.candidates)}"
        )
    if not e.signal_to_noise >= s.snr_threshold:
        if e.structured:
            return "non-periodic", (
                f"the strongest harmonic of {best.period_s:.4g} s is only {e.signal_to_noise:.1f} times the "
                f"residual around it (below {s.snr_threshold:g}) and the residual is not noise: the variation "
                "does not repeat"
            )
        return "no signal", (
            f"the strongest harmonic of {best.period_s:.4g} s is only {e.signal_to_noise:.1f} times the "
            f"noise around it (below {s.snr_threshold:g})"
        )
    if e.structured and e.explained_fraction < EXPLAINED_MIN:
        return "non-periodic", (
            f"the best period {best.period_s:.4g} s explains only {100 * e.explained_fraction:.0f}% of the "
            f"brightness variation beyond the noise (a period needs {100 * EXPLAINED_MIN:.0f}%): the light "
            "curve does not repeat (tumbling, or a shape that changes during the pass)"
        )
    if e.cadence_alias is not None:
        short = e.cadence_alias
        return "aliased", (
            f"{best.period_s:.4g} s may be an artefact of the sampling: {short.period_s:.4g} s "
            f"spans {short.period_s / e.cadence_s:.2f} samples, so its harmonics above the Nyquist "
            f"frequency alias onto those of {best.period_s:.4g} s"
        )
    samples = best.period_s / e.cadence_s
    if samples < MIN_SAMPLES_PER_CYCLE:
        alias = 1.0 / (1.0 / e.cadence_s - 1.0 / best.period_s)
        return "aliased", (
            f"{best.period_s:.4g} s spans only {samples:.2f} samples: the frame rate's alias {alias:.4g} s "
            "fits the samples as well"
        )
    if e.gap_alias is not None:
        period, delta, gap = e.gap_alias
        return "aliased", (
            f"{period:.5g} s, one cycle more or less across the {gap:.0f} s gap, fits nearly as well as "
            f"{best.period_s:.5g} s (BIC difference {delta:.1f} < {s.bic_margin:g})"
        )
    covered = e.covered_s / best.period_s
    if covered < MIN_CONFIDENT_CYCLES <= best.n_cycles:
        return "aliased", (
            f"the samples cover only {covered:.1f} cycles of {best.period_s:.5g} s; the other "
            f"{best.n_cycles - covered:.1f} of the {best.n_cycles:.1f} in the pass are counted across gaps, "
            "where a different count may fit as well"
        )
    # Any candidate counts, also one repeating less than twice (reported only when it wins clearly).
    rivals = [c for c in e.candidates[1:] if c.delta_bic < s.bic_margin]
    if rivals:
        return "ambiguous harmonic", (
            f"{_period(rivals[0])} fits nearly as well as {_period(best)} "
            f"(BIC difference {rivals[0].delta_bic:.1f} < {s.bic_margin:g})"
        )
    if e.pdm_weakest is not None and not e.pdm_weakest[1] < PDM_P_VALUE:
        shorter, p_value = e.pdm_weakest
        return "ambiguous harmonic", (
            f"the Fourier fits prefer {best.period_s:.4g} s but phase dispersion does not "
            f"confirm it over {shorter.period_s:.4g} s (F-test p = {p_value:.2g})"
        )
    if e.halves is not None:
        rival, first, second = e.halves
        which = "first" if first < second else "second"
        verb = "prefers" if min(first, second) < 0 else "does not clearly reject"
        return "ambiguous harmonic", (
            f"the {which} half of the pass {verb} {rival.period_s:.4g} s against {best.period_s:.4g} s "
            f"(BIC differences {first:.1f} and {second:.1f} in the two halves, each needs "
            f"{0.5 * s.bic_margin:g}): the choice does not hold through the pass"
        )
    if e.conservative is not None:
        rival, delta = e.conservative
        if rival.n_cycles < 2.0 and delta < 0:
            return "too short", (
                f"counting the residuals' correlation at every frequency, a variation slower than any "
                f"repeating period fits best ({_period(rival)}, {rival.n_cycles:.1f} cycles, BIC lower by "
                f"{-delta:.0f} than {_period(best)}): the pass is too short to tell"
            )
        return "ambiguous harmonic", (
            f"counting the residuals' correlation at every frequency, {_period(rival)} fits nearly as well as "
            f"{_period(best)} (BIC difference {delta:.1f} < {s.bic_margin:g})"
        )
    if best.n_cycles < MIN_CONFIDENT_CYCLES:
        return "ambiguous harmonic", (
            f"{_period(best)} fits {best.n_cycles:.1f} times in the pass, fewer than {MIN_CONFIDENT_CYCLES:g}: "
            "twice the period does not repeat twice, so a cycle whose halves differ cannot be excluded"
        )
    runner = e.candidates[1] if len(e.candidates) > 1 else None
    beaten = (
        f"beats {runner.period_s:.4g} s by a BIC difference of {runner.delta_bic:.0f}" if runner else "only candidate"
    )
    confirmed = (
        f", phase dispersion confirms it over {e.pdm_weakest[0].period_s:.4g} s (p = {e.pdm_weakest[1]:.1g})"
        if e.pdm_weakest is not None
        else ""
    )
    return "confident", f"{best.period_s:.4g} s {beaten}{confirmed}, S/N {e.signal_to_noise:.0f}"
