"""Injection and recovery: synthetic light curves of known period, and how often the search finds it.

`synthetic_lightcurve` builds a pass-like curve: a periodic shape of known period, a slow
pass trend, white or AR(1) (red) noise, optional gaps. `SHAPES` are the cases a satellite
period search must survive:

* ``"sinusoid"``: one maximum per rotation (the easy case).
* ``"two_faced"``: two nearly equal halves per rotation - the dominant second harmonic with a
  weak fundamental of relative size `asymmetry` (0.1 = the halves differ by ~10% of the
  amplitude). Plain Lomb-Scargle finds half the period.
* ``"four_faced"``: a dominant fourth harmonic with weaker first to third ones, like TOPEX
  (whose one-term periodogram peaks at a quarter of the period).
* ``"glint"``: a flat light curve with one narrow specular flash per rotation (Gaussian in
  phase, 2% of a cycle wide), the amplitude being the flash height in magnitudes. Its power is
  spread over many harmonics.

`recover` runs `rsodb.periods.find_period` on a batch of such curves (in a process pool when
asked) and tabulates truth against result. A period counts as *recovered* when the verdict
names a period and the default +-1% fit prior built from it contains the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from rsodb.periods.lightcurve import LightCurve
from rsodb.periods.search import find_period
from rsodb.pool import imap_in_pool

__all__ = ["SHAPES", "Injection", "synthetic_lightcurve", "shape_mag", "recover", "RECOVERY_TOLERANCE"]

# Recovered = inside the +-1% prior a fit would start from.
RECOVERY_TOLERANCE = 0.01
# Midpoint sub-samples per exposure (a 2%-wide glint at 2 s spans ~1 sub-sample of 0.2 s / 16).
_EXPOSURE_SUBSAMPLES = 16


def _sinusoid(phase, asymmetry):
    return 0.5 * np.cos(2 * np.pi * phase)


def _two_faced(phase, asymmetry):
    # Normalised so that the peak-to-peak range is ~1 for small asymmetry.
    return 0.5 * np.cos(4 * np.pi * phase) + 0.5 * asymmetry * np.cos(2 * np.pi * phase + 0.7)


def _four_faced(phase, asymmetry):
    return 0.5 * (
        np.cos(8 * np.pi * phase)
        + 0.6 * asymmetry * np.cos(2 * np.pi * phase + 0.3)
        + 0.4 * asymmetry * np.cos(4 * np.pi * phase + 1.1)
        + 0.3 * asymmetry * np.cos(6 * np.pi * phase + 2.0)
    )


def _glint(phase, asymmetry):
    distance = np.abs(np.mod(phase + 0.5, 1.0) - 0.5)  # cycles from the flash
    return -np.exp(-0.5 * (distance / 0.02) ** 2)  # brighter = more negative magnitude


SHAPES = {"sinusoid": _sinusoid, "two_faced": _two_faced, "four_faced": _four_faced, "glint": _glint}


def shape_mag(shape: str, phase, asymmetry: float = 0.2) -> np.ndarray:
    """Magnitude variation of a shape (peak-to-peak ~1) at rotation phases `phase` (cycles)."""
    if shape not in SHAPES:
        raise ValueError(f"shape={shape!r} is not one of {', '.join(SHAPES)}")
    return SHAPES[shape](np.asarray(phase, dtype=float), asymmetry)


@dataclass(frozen=True)
class Injection:
    """The truth behind one synthetic curve.

    Attributes
    ----------
    shape : str
    period_s, amplitude_mag, noise_mag : float
    n_points : int
    cadence_s : float
    gap_fraction : float
        Fraction of the pass removed in gaps.
    red_noise_rho : float
        Lag-1 correlation of the AR(1) noise (0 = white).
    asymmetry : float
    seed : int
    """

    shape: str
    period_s: float
    amplitude_mag: float
    noise_mag: float
    n_points: int = 2500
    cadence_s: float = 0.2
    gap_fraction: float = 0.0
    red_noise_rho: float = 0.0
    asymmetry: float = 0.2
    trend_mag: float = 0.5
    seed: int = 0

    @property
    def n_cycles(self) -> float:
        """Rotations in the pass (gaps included in the duration)."""
        return self.n_points * self.cadence_s / self.period_s


def synthetic_lightcurve(injection: Injection) -> LightCurve:
    """The light curve of an `Injection` (its `seed` makes it reproducible).

    The pass lasts ``n_points * cadence_s``; samples are regular and integrate the flux over
    an exposure equal to the cadence (16 midpoint sub-samples), then gaps remove
    `gap_fraction` of the pass in two blocks at random places, one in each half. The trend is a parabola of
    `trend_mag` across the pass (a phase-angle brightening); `mag_err` is the white noise level.

    Returns
    -------
    LightCurve
    """
    if injection.shape not in SHAPES:
        raise ValueError(f"shape={injection.shape!r} is not one of {', '.join(SHAPES)}")
    if not 0 <= injection.gap_fraction < 0.9:
        raise ValueError(f"gap_fraction={injection.gap_fraction!r} must be in [0, 0.9)")
    if not 0 <= injection.red_noise_rho < 1:
        raise ValueError(f"red_noise_rho={injection.red_noise_rho!r} must be in [0, 1)")
    rng = np.random.default_rng(injection.seed)
    n = injection.n_points
    t = np.arange(n) * injection.cadence_s
    duration = t[-1]
    phase0 = rng.random()
    x = t / duration - 0.5
    # Each sample integrates the flux over its exposure (= the cadence), as a camera does: a
    # glint narrower than the cadence, sampled at points, would alias into a false period.
    offsets = injection.cadence_s * ((np.arange(_EXPOSURE_SUBSAMPLES) + 0.5) / _EXPOSURE_SUBSAMPLES - 0.5)
    phase = (t[:, None] + offsets[None, :]) / injection.period_s + phase0
    periodic = injection.amplitude_mag * shape_mag(injection.shape, phase, injection.asymmetry)
    periodic = -2.5 * np.log10(np.mean(10 ** (-0.4 * periodic), axis=1))
    mag = 6.0 + periodic + injection.trend_mag * (4 * x * x - 1 / 3) + 0.3 * injection.trend_mag * x
    white = rng.normal(0.0, injection.noise_mag, n)
    rho = injection.red_noise_rho
    if rho > 0:
        # AR(1) with the same marginal variance: e_i = rho e_{i-1} + sqrt(1 - rho^2) u_i.
        from scipy.signal import lfilter

        white = lfilter([math.sqrt(1 - rho * rho)], [1.0, -rho], white)
    mag = mag + white
    keep = np.ones(n, bool)
    if injection.gap_fraction > 0:
        # One gap in each half of the pass, so they never overlap; the ends stay observed.
        gap = int(round(injection.gap_fraction * n / 2))
        half = n // 2
        for lo in (1, half):
            start = lo + int(rng.integers(0, max(half - gap - 1, 1)))
            keep[start : start + gap] = False
        keep[[0, -1]] = True
    label = (
        f"{injection.shape} P={injection.period_s:g}s A={injection.amplitude_mag:g} "
        f"noise={injection.noise_mag:g} seed={injection.seed}"
    )
    return LightCurve.from_arrays(
        t[keep], mag[keep], np.full(keep.sum(), injection.noise_mag), exposure_s=injection.cadence_s, label=label
    )


def _run_one(injection: Injection) -> dict:
    result = find_period(synthetic_lightcurve(injection))
    error = (result.best_period_s - injection.period_s) / injection.period_s
    recovered = result.has_period and abs(error) < RECOVERY_TOLERANCE
    return {
        "shape": injection.shape,
        "period_s": injection.period_s,
        "amplitude_mag": injection.amplitude_mag,
        "noise_mag": injection.noise_mag,
        "gap_fraction": injection.gap_fraction,
        "red_noise_rho": injection.red_noise_rho,
        "asymmetry": injection.asymmetry,
        "seed": injection.seed,
        "n_cycles": injection.n_cycles,
        "found_period_s": result.best_period_s,
        "uncertainty_s": result.uncertainty_s,
        "relative_error": error,
        "pull": (result.best_period_s - injection.period_s) / result.uncertainty_s
        if result.uncertainty_s > 0
        else math.nan,
        "verdict": result.verdict,
        "recovered": bool(recovered),
        "confident_wrong": result.verdict == "confident" and not abs(error) < RECOVERY_TOLERANCE,
        # A confident period at P/2, P/3 or P/4: the cycle's parts alike within the noise.
        "confident_subharmonic": result.verdict == "confident"
        and _is_submultiple(result.best_period_s, injection.period_s),
    }


def _is_submultiple(found_s: float, true_s: float) -> bool:
    ratio = true_s / found_s
    return round(ratio) in (2, 3, 4) and abs(ratio - round(ratio)) < RECOVERY_TOLERANCE * ratio


def recover(injections, processes: int = 1, progress: bool = False):
    """Run the period search on each injection.

    Parameters
    ----------
    injections : iterable of Injection
    processes : int
        Worker processes (1 = in this process).
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    pandas.DataFrame
        One row per injection: the truth, the found period, its error and pull, the verdict,
        ``recovered``, ``confident_wrong`` (a confident verdict outside +-1%) and
        ``confident_subharmonic`` (the confidently wrong ones at P/2, P/3 or P/4: a cycle whose
        parts look alike within the noise).
    """
    # pandas costs about half a second to import; only this conversion needs it.
    import pandas as pd

    injections = list(injections)
    rows = list(
        imap_in_pool(
            _run_one, injections, processes=processes, progress=progress, description="injections", ordered=True
        )
    )
    return pd.DataFrame(rows)
