"""Flashes: short brightenings that stand out of a light curve (specular glints).

A light curve whose variation is mostly a few flashes repeats only as often as the flashes do:
one flash in a pass gives no period at all, two give a single interval. `find_flashes` finds
them against a robust baseline (a low-degree polynomial in time fitted with the bright samples
clipped), so the period search can say "single glint" instead of fitting a period to one
event. See docs/periods.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rsodb.periods.harmonic import TimeAxis

__all__ = ["Flashes", "find_flashes", "FLASH_SIGMA", "FLASH_SHARE", "FLASH_MAX_WIDTH"]

# A flash sample is this many noise sigma brighter than the baseline (a Gaussian false alarm
# is 3e-7 per sample: ~1e-3 per pass of 2500 samples).
FLASH_SIGMA = 5.0
# The flashes dominate a light curve when their samples carry this fraction of its variation.
FLASH_SHARE = 0.5
# Wider than this fraction of the pass, a brightening is a hump of the light curve, not a flash.
FLASH_MAX_WIDTH = 0.1


@dataclass(frozen=True, eq=False)
class Flashes:
    """The flashes of one light curve.

    Attributes
    ----------
    peak_t_s : (m,) float
        Time of each flash's brightest sample.
    height_mag : (m,) float
        How much brighter than the baseline that sample is (positive).
    width_s : (m,) float
        From the first to the last sample of the flash (plus one cadence).
    start_s, stop_s : (m,) float
        Times of the first and last sample of each flash.
    share : float
        Fraction of the light curve's variation about its baseline, beyond the noise, carried
        by the flash samples (0..1).
    """

    peak_t_s: np.ndarray
    height_mag: np.ndarray
    width_s: np.ndarray
    share: float
    start_s: np.ndarray
    stop_s: np.ndarray

    @property
    def count(self) -> int:
        return int(self.peak_t_s.shape[0])

    @property
    def dominant(self) -> bool:
        """True when the flashes carry most of the variation (`FLASH_SHARE`)."""
        return self.count > 0 and self.share >= FLASH_SHARE

    def outside(self, t_s) -> np.ndarray:
        """(n,) True for the times `t_s` outside every flash."""
        t_s = np.asarray(t_s, dtype=float)
        inside = (t_s[:, None] >= self.start_s[None, :]) & (t_s[:, None] <= self.stop_s[None, :])
        return ~inside.any(axis=1)

    def describe(self) -> str:
        """A few words: how many flashes, where, how bright."""
        if not self.count:
            return "no flash"
        where = ", ".join(f"{t:.1f} s" for t in self.peak_t_s[:4]) + (" ..." if self.count > 4 else "")
        return (
            f"{self.count} flash{'es' if self.count > 1 else ''} (at {where} from the first sample, up to "
            f"{self.height_mag.max():.2f} mag above the baseline, {100 * self.share:.0f}% of the variation)"
        )


def _baseline(t_s: np.ndarray, mag: np.ndarray, noise_mag: float, degree: int) -> np.ndarray:
    """Polynomial baseline fitted with the samples more than 3 sigma brighter than it left out."""
    axis = TimeAxis.from_times(t_s)
    basis = axis.trend_basis(t_s, degree)
    keep = np.ones(t_s.shape, bool)
    for _ in range(4):
        coefficients, *_ = np.linalg.lstsq(basis[keep], mag[keep], rcond=None)
        baseline = basis @ coefficients
        new = (mag - baseline) > -3.0 * noise_mag
        if new.sum() <= degree + 1 or np.array_equal(new, keep):
            break
        keep = new
    return baseline


def find_flashes(t_s, mag, noise_mag: float, cadence_s: float) -> Flashes:
    """Find the flashes of a light curve.

    Parameters
    ----------
    t_s, mag : (n,) float
        Times (s) and magnitudes.
    noise_mag : float
        White-noise level (e.g. `rsodb.periods.noise.point_to_point_noise_mag`).
    cadence_s : float
        Regular sample spacing (the width of a one-sample flash).

    Returns
    -------
    Flashes
        Runs of samples more than 2 noise sigma brighter than a cubic baseline (lower degree for
        short curves) that hold a sample `FLASH_SIGMA` sigma brighter, no wider than
        `FLASH_MAX_WIDTH` of the pass.
    """
    t_s, mag = np.asarray(t_s, dtype=float), np.asarray(mag, dtype=float)
    empty = Flashes(np.zeros(0), np.zeros(0), np.zeros(0), 0.0, np.zeros(0), np.zeros(0))
    if not (noise_mag > 0) or t_s.size < 10:
        return empty
    residual = mag - _baseline(t_s, mag, noise_mag, min(3, t_s.size // 10 - 1))
    brighter = -residual  # positive when brighter
    core = np.flatnonzero(brighter > FLASH_SIGMA * noise_mag)
    if not core.size:
        return empty
    duration = t_s[-1] - t_s[0]
    # Runs of samples more than 2 sigma brighter than the baseline that hold a core sample.
    elevated = np.concatenate([[False], brighter > 2.0 * noise_mag, [False]])
    edges = np.flatnonzero(np.diff(elevated.astype(np.int8)))
    starts, stops = edges[::2], edges[1::2] - 1  # inclusive sample indices
    holds_core = np.add.reduceat(np.isin(np.arange(t_s.size), core), starts) > 0 if starts.size else starts
    width = t_s[stops] - t_s[starts] + cadence_s
    chosen = holds_core & (width <= FLASH_MAX_WIDTH * duration)
    if not chosen.any():
        return empty
    starts, stops, width = starts[chosen], stops[chosen], width[chosen]
    run = np.repeat(np.arange(starts.size), stops - starts + 1)
    inside = np.concatenate([np.arange(a, b + 1) for a, b in zip(starts, stops)])
    order = np.lexsort((-brighter[inside], run))
    first = np.concatenate([[True], np.diff(run[order]) > 0])
    brightest = inside[order][first]
    peaks, heights = t_s[brightest], brighter[brightest]
    excess = residual**2 - noise_mag**2
    total = float(np.sum(np.maximum(excess, 0.0)))
    share = float(np.sum(np.maximum(excess[inside], 0.0)) / total) if total > 0 else 0.0
    return Flashes(peaks, heights, width, min(share, 1.0), t_s[starts], t_s[stops])
