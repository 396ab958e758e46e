"""How finely a fit integrates each exposure: as finely as its model's light curve needs.

The geometry's default (`raycast.geometry.pass_geometry.choose_n_sub`) turns the body at most
2 deg per exposure sub-sample at the prior's fastest spin, whatever the model: safe, and on a
1 s exposure of a 5 s spinner 39 renders per sample. A smooth convex body needs far fewer (its
light curve is a few low harmonics); a flat glossy panel needs many (its glint lasts a few
degrees of turn). `sub_samples_needed` asks the model itself: it doubles the sub-samples from
one until the model's magnitudes, at a few prior draws, move by less than a tolerance.
"""

from __future__ import annotations

from collections.abc import Callable
import math

import numpy as np

__all__ = ["sub_samples_needed", "magnitude_change", "SUB_SAMPLE_DRAWS"]

# Prior draws at which the curves are compared: enough that one draw which turns a glint toward
# the observer is among them, few enough that the measurement costs a fraction of a fit.
SUB_SAMPLE_DRAWS = 8


def magnitude_change(before: np.ndarray, after: np.ndarray) -> float:
    """RMS change (mag) from `before` to `after`, (draws, samples) magnitudes each, once each
    draw's mean change is removed (a fit's offset absorbs it); samples dark in either are left
    out, and a draw with fewer than two lit samples counts as unchanged.
    """
    squares, count = 0.0, 0
    for old, new in zip(np.atleast_2d(before), np.atleast_2d(after), strict=True):
        with np.errstate(invalid="ignore"):  # a sample dark in both: inf - inf
            change = new - old
        change = change[np.isfinite(change)]
        if change.size < 2:
            continue
        change = change - change.mean()
        squares += float(np.sum(change**2))
        count += change.size
    return math.sqrt(squares / count) if count else 0.0


def sub_samples_needed(curves_at: Callable[[int], np.ndarray], limit: int, tolerance_mag: float) -> tuple[int, float]:
    """The fewest exposure sub-samples whose curves change by at most `tolerance_mag` when doubled.

    Parameters
    ----------
    curves_at : callable
        ``curves_at(k) -> (draws, samples)`` model magnitudes with `k` sub-samples per exposure.
    limit : int
        The most sub-samples ever used (the 2 deg rule's count): returned when no fewer will do.
    tolerance_mag : float
        RMS change (`magnitude_change`) below which doubling is not worth its cost.

    Returns
    -------
    (k, change) : (int, float)
        The sub-samples chosen, and the RMS change measured from `k` to the next count (0 when
        `k` is `limit`).

    Examples
    --------
    >>> import numpy as np
    >>> curve = lambda k: np.array([[0.0, 1.0 / k**2, 0.0, -1.0 / k**2]])  # error falls as 1/k^2
    >>> count, change = sub_samples_needed(curve, 64, 0.05)
    >>> count, round(change, 4)
    (4, 0.0331)
    """
    if limit < 1 or not tolerance_mag > 0:
        raise ValueError(f"sub_samples_needed: limit {limit!r} must be >= 1 and tolerance {tolerance_mag!r} > 0")
    count, curves = 1, curves_at(1)
    while count < limit:
        finer = min(2 * count, limit)
        finer_curves = curves_at(finer)
        change = magnitude_change(curves, finer_curves)
        if change <= tolerance_mag:
            return count, change
        count, curves = finer, finer_curves
    return count, 0.0
