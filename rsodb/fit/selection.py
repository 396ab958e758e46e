"""Which samples of a pass a fit compares with its model, and the check that they do not strobe.

A fit reads the usable samples (valid, finite, unsaturated unless asked) of its *window*
(``[data] start_s``, ``duration_s``; the whole pass by default). When ``max_points`` asks for
fewer, `select_samples` never takes every k-th sample, which strobes a periodic light curve
(50 samples spread over a 464 s pass are 9.47 s apart, within 0.1% of TOPEX's light-curve
period, and show a smooth ramp instead of 0-8 mag swings). It reduces the samples by

1. **binning** consecutive samples, where a bin turns the body by at most ``bin_turn_deg``
   at the fastest spin the prior allows: the bin's flux-mean magnitude is compared with the
   model integrated over the bin's span (its exposure), so nothing is lost but resolution the
   light curve does not have;
2. then **contiguous windows**: as many as keep each window at least one cycle of the slowest
   candidate period long, spread evenly over the fitted window (the long baseline pins the
   period), each holding every (binned) sample it spans.

`phase_coverage` then measures how the kept samples cover the spin phase for every candidate
period of the prior (a grid fine enough that the phase at the window's end moves by less than
half a phase bin between neighbours): the largest gap of empty phase bins, in cycles.
`select_samples` refuses a selection whose gap exceeds `MAX_PHASE_GAP` where the window's own
samples cover the phase well, and says how to fix it; where the window itself covers the
phase poorly (a pass shorter than the period, or sparser than it), the fit runs and carries
a warning.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = [
    "Selection",
    "PhaseCoverage",
    "select_samples",
    "phase_coverage",
    "usable_samples",
    "window_samples",
    "MAX_PHASE_GAP",
    "PHASE_BINS",
]

# Phase bins of the coverage measure (18 deg each).
PHASE_BINS = 20
# Largest gap in spin phase (cycles) a selection may leave where its window covers the phase.
MAX_PHASE_GAP = 0.25
# The light curve's period differs from the spin period by the precession and the moving
# Sun-observer geometry (1-3% in the published fits): candidates extend this far beyond the prior.
CANDIDATE_MARGIN = 0.03
# Candidate periods checked at most (a very wide prior on a long pass is checked more coarsely).
MAX_CANDIDATES = 20_000
# A gap in the time stamps longer than this many cadences ends a run of consecutive samples.
_RUN_BREAK = 1.5


def usable_samples(observed, keep_saturated: bool = False) -> np.ndarray:
    """(n,) bool: valid samples with finite magnitudes and errors (unsaturated unless asked)."""
    keep = observed.valid & np.isfinite(observed.best_mag) & np.isfinite(observed.mag_err)
    return keep if keep_saturated else keep & ~observed.saturated


def window_samples(observed, data) -> np.ndarray:
    """(n,) bool: the usable samples inside the fitted window of `data` (a `DataConfig`)."""
    t_s = observed.t_s
    keep = usable_samples(observed, data.keep_saturated) & (t_s >= data.start_s)
    if data.duration_s > 0:
        keep &= t_s <= data.start_s + data.duration_s
    return keep


@dataclass(frozen=True)
class PhaseCoverage:
    """How two sets of times cover the spin phase over a grid of candidate periods.

    Attributes
    ----------
    periods_s : (k,) float
        Candidate periods.
    gap_cycles : (k,) float
        Largest run of empty phase bins of the kept samples, in cycles (0 = every bin hit).
    window_gap_cycles : (k,) float
        The same for every usable sample of the window.
    """

    periods_s: np.ndarray
    gap_cycles: np.ndarray
    window_gap_cycles: np.ndarray

    @property
    def worst(self) -> int:
        """Index of the candidate where the kept samples lose most against the window."""
        return int(np.argmax(self.gap_cycles - self.window_gap_cycles))

    @property
    def max_gap_cycles(self) -> float:
        return float(self.gap_cycles[self.worst]) if self.periods_s.size else 0.0

    @property
    def poor(self) -> bool:
        """The kept samples leave a gap over `MAX_PHASE_GAP` where the window has none as large."""
        if not self.periods_s.size:
            return False
        i = self.worst
        return bool(
            self.gap_cycles[i] > MAX_PHASE_GAP and self.gap_cycles[i] > self.window_gap_cycles[i] + 2.0 / PHASE_BINS
        )

    @property
    def window_poor(self) -> bool:
        """The window's own samples leave a gap over `MAX_PHASE_GAP` at some candidate period."""
        return bool(self.periods_s.size and np.max(self.window_gap_cycles) > MAX_PHASE_GAP)

    def summary(self) -> str:
        if not self.periods_s.size:
            return "no candidate period to check"
        i = self.worst
        return (
            f"largest spin-phase gap {self.gap_cycles[i]:.2f} cycle at P = {self.periods_s[i]:.5g} s "
            f"(every sample of the window: {self.window_gap_cycles[i]:.2f}), over {self.periods_s.size} "
            f"candidate periods {self.periods_s[0]:.5g}-{self.periods_s[-1]:.5g} s"
        )


def _candidate_periods(bounds_s: tuple[float, float], span_s: float) -> np.ndarray:
    low = bounds_s[0] * (1 - CANDIDATE_MARGIN)
    high = bounds_s[1] * (1 + CANDIDATE_MARGIN)
    if span_s <= 0:
        return np.array([low, high])
    # d(t/P) = t dP / P**2: neighbours move the phase at the end of the span by half a bin.
    step_frac = low / (span_s * 2.0 * PHASE_BINS)
    count = int(min(MAX_CANDIDATES, max(2, math.ceil(math.log(high / low) / math.log1p(step_frac)) + 1)))
    return np.geomspace(low, high, count)


def _largest_gaps(t_s: np.ndarray, periods_s: np.ndarray) -> np.ndarray:
    """(k,) largest circular run of empty phase bins, in cycles, of times `t_s` at each period."""
    gaps = np.empty(periods_s.size)
    chunk = max(1, 4_000_000 // max(t_s.size, 1))
    for begin in range(0, periods_s.size, chunk):
        periods = periods_s[begin : begin + chunk]
        bins = np.floor(np.mod(t_s[None, :] / periods[:, None], 1.0) * PHASE_BINS).astype(np.int64)
        bins = np.minimum(bins, PHASE_BINS - 1) + PHASE_BINS * np.arange(periods.size)[:, None]
        hit = np.bincount(bins.ravel(), minlength=periods.size * PHASE_BINS).reshape(periods.size, PHASE_BINS) > 0
        empty = np.concatenate([~hit, ~hit], axis=1)
        run = np.zeros(periods.size, dtype=np.int64)
        longest = np.zeros(periods.size, dtype=np.int64)
        for column in empty.T:
            run = np.where(column, run + 1, 0)
            longest = np.maximum(longest, run)
        gaps[begin : begin + chunk] = np.minimum(longest, PHASE_BINS) / PHASE_BINS
    return gaps


def phase_coverage(kept_t_s, window_t_s, period_bounds_s: tuple[float, float]) -> PhaseCoverage:
    """Phase coverage of the kept samples and of the whole window over the candidate periods.

    Parameters
    ----------
    kept_t_s : (m,) float
        Times of the samples the likelihood sees (every member of a bin), seconds.
    window_t_s : (n,) float
        Times of every usable sample of the window, seconds.
    period_bounds_s : (low, high)
        The spin-period prior's support; candidates extend `CANDIDATE_MARGIN` beyond it.
    """
    kept_t_s, window_t_s = np.asarray(kept_t_s, dtype=float), np.asarray(window_t_s, dtype=float)
    span = float(np.ptp(window_t_s)) if window_t_s.size else 0.0
    periods = _candidate_periods(period_bounds_s, span)
    return PhaseCoverage(periods, _largest_gaps(kept_t_s, periods), _largest_gaps(window_t_s, periods))


@dataclass(frozen=True, eq=False)
class Selection:
    """The samples of one fit.

    Attributes
    ----------
    window : (n,) bool
        Usable samples inside the fitted window: residuals and their RMS cover all of them.
    groups : (m, b) int
        Pass indices of each sample the likelihood sees: b consecutive samples per bin
        (b = 1: the samples themselves).
    description : str
        What was kept, in words.
    coverage : PhaseCoverage
    """

    window: np.ndarray
    groups: np.ndarray
    description: str
    coverage: PhaseCoverage

    @property
    def kept(self) -> np.ndarray:
        """(n,) bool: the samples inside the likelihood's bins."""
        kept = np.zeros(self.window.size, dtype=bool)
        kept[self.groups.ravel()] = True
        return kept

    @property
    def bin_size(self) -> int:
        return int(self.groups.shape[1])

    @property
    def n(self) -> int:
        """Samples the likelihood sees (bins)."""
        return int(self.groups.shape[0])

    def time_utc(self, observed) -> np.ndarray:
        """(m,) mid-time of each bin (the samples' own times when b = 1)."""
        times = observed.time_utc[self.groups]
        return times[:, 0] + (times[:, -1] - times[:, 0]) // 2

    def exposure_s(self, observed) -> float:
        """The time each bin integrates: its span plus one exposure (the exposure when b = 1)."""
        if self.bin_size == 1:
            return float(observed.exposure_s)
        t_s = observed.t_s[self.groups]
        return float(np.median(t_s[:, -1] - t_s[:, 0])) + float(observed.exposure_s)

    def magnitudes(
        self, observed, mag_err_floor: float = 0.0, point_model: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """(mag (m,), mag_err (m,)) of each bin: the magnitude of the mean flux and its error.

        ``point_model``: the model is compared at each bin's mid-time only, not integrated over
        the bin (the global search's coarse posterior). Where the light curve bends within a
        bin (a glint, a sharp edge) its value at the mid-time differs from the bin's mean, so the
        error also holds that difference as the bin's own samples show it (the mean's magnitude
        against the middle sample's, beyond their noise): without it, one glint smeared over a
        bin outweighs every other bin and the true state scores far below wrong ones. A straight
        ramp adds nothing (its middle is its mean).
        """
        mag = observed.best_mag[self.groups]
        err = np.maximum(observed.mag_err[self.groups], mag_err_floor)
        if self.bin_size == 1:
            return mag[:, 0], err[:, 0]
        flux = 10.0 ** (-0.4 * (mag - mag[:, :1]))
        mean = flux.mean(axis=1)
        flux_err = flux * err * (0.4 * math.log(10.0))
        bin_err = np.sqrt(np.sum(flux_err**2, axis=1)) / self.bin_size / mean / (0.4 * math.log(10.0))
        mean_mag = mag[:, 0] - 2.5 * np.log10(mean)
        if point_model:
            # The middle sample (odd bins) or the mean of the two middle ones (even bins).
            middle = sorted({(self.bin_size - 1) // 2, self.bin_size // 2})
            mid_mag = mag[:, middle].mean(axis=1)
            mid_var = np.sum(err[:, middle] ** 2, axis=1) / len(middle) ** 2
            beyond_noise = (mean_mag - mid_mag) ** 2 - mid_var - bin_err**2
            bin_err = np.sqrt(bin_err**2 + np.maximum(beyond_noise, 0.0))
        return mean_mag, bin_err


def _runs(t_s: np.ndarray) -> list[np.ndarray]:
    """Positions of `t_s` split into runs of consecutive samples (no gap over 1.5 cadences)."""
    if t_s.size < 2:
        return [np.arange(t_s.size)]
    step = np.diff(t_s)
    cadence = float(np.median(step))
    breaks = np.flatnonzero(step > _RUN_BREAK * cadence) + 1
    return np.split(np.arange(t_s.size), breaks)


def _binned(index: np.ndarray, t_s: np.ndarray, size: int) -> np.ndarray:
    """(m, size) bins of `size` consecutive samples within each run; a run's remainder is left out."""
    rows = []
    for run in _runs(t_s[index]):
        whole = run.size // size * size
        if whole:
            rows.append(index[run[:whole]].reshape(-1, size))
    return np.concatenate(rows) if rows else np.zeros((0, size), dtype=np.int64)


def select_samples(observed, data, period_bounds_s: tuple[float, float], pass_id: str = "") -> Selection:
    """The samples of `observed` a fit under `data` (a `DataConfig`) compares with its model.

    Parameters
    ----------
    observed : Pass
    data : DataConfig
        Window, ``max_points``, ``bin_turn_deg``, ``windows``.
    period_bounds_s : (low, high)
        Support of the spin-period prior (the candidate periods).
    pass_id : str
        For messages.

    Raises
    ------
    ValueError
        When fewer than 10 samples are usable, or the kept samples cover the spin phase poorly
        where the window's samples do not (the message says how to fix it).
    """
    label = pass_id or getattr(observed, "pass_id", "") or observed.source_name
    window = window_samples(observed, data)
    index = np.flatnonzero(window)
    if index.size < 10:
        raise ValueError(
            f"pass {label}: only {index.size} usable samples in the chosen window; a fit needs at least 10 "
            "(check [data] start_s/duration_s, or keep_saturated)"
        )
    t_s = observed.t_s
    low, high = float(period_bounds_s[0]), float(period_bounds_s[1])
    groups = index[:, None]
    parts = [f"{index.size} samples of the window"]
    if data.max_points and index.size > data.max_points:
        cadence = float(np.median(np.diff(t_s[index])))
        turn_per_sample = 360.0 * cadence / low
        largest = max(1, int(data.bin_turn_deg // turn_per_sample)) if turn_per_sample > 0 else 1
        size = min(largest, math.ceil(index.size / data.max_points))
        if size > 1:
            groups = _binned(index, t_s, size)
            parts = [f"{index.size} samples of the window in {groups.shape[0]} bins of {size}"]
        if groups.shape[0] > data.max_points:
            step = cadence * groups.shape[1]
            per_cycle = math.ceil(high / step)
            count = data.windows or max(1, data.max_points // per_cycle)
            length = data.max_points // count
            starts = (
                [(groups.shape[0] - length) // 2]
                if count == 1
                else np.linspace(0, groups.shape[0] - length, count).round().astype(int)
            )
            groups = np.concatenate([groups[s : s + length] for s in starts])
            seconds = length * step
            parts.append(
                f"{count} contiguous window(s) of {length} {'bins' if groups.shape[1] > 1 else 'samples'} "
                f"({seconds:.4g} s, {seconds / high:.2g} cycles of the slowest candidate period) spread over it"
            )
    coverage = phase_coverage(t_s[groups.ravel()], t_s[index], (low, high))
    if coverage.poor:
        i = coverage.worst
        raise ValueError(
            f"pass {label}: the {groups.size} kept samples cover the spin phase poorly at P = "
            f"{coverage.periods_s[i]:.5g} s (a gap of {coverage.gap_cycles[i]:.2f} cycle, against "
            f"{coverage.window_gap_cycles[i]:.2f} with every sample of the window); fit every sample "
            "([data] max_points = 0), or allow more points or fewer [data] windows so that each window "
            "spans a whole cycle"
        )
    return Selection(window, groups, "; ".join(parts), coverage)
