"""Photometric reduction of the seed paper, as small vectorised functions.

The standard magnitude reduced to a range of 1000 km is

    m_st = A + m_inst - k X + m_r,
    m_inst = -2.5 log10(F / dt),      X = 1 / sin(el) = 1 / cos(z),      m_r = -5 log10(R / 1000 km),

with A the zero point and k > 0 the extinction coefficient of the site and band (F in counts
per exposure of dt seconds). ccd_phot before 2024-08-01 wrote ``+k X`` instead of ``-k X``.
Because every file obeys ``mag = A + m_inst + c X + m_r`` for some signed ``c``, a linear
regression of ``mag - m_inst - m_r`` on ``X`` recovers ``A`` and ``c`` to the rounding of the
printed magnitudes (~3e-4 mag RMS); ``c > 0`` is the sign error, and the corrected magnitude is
``mag - 2 c X`` (the same row with ``-c X``).

The plane-parallel airmass is what the files used; it is kept here on purpose (a refined
airmass would not reproduce the files' numbers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Reduction",
    "instrumental_mag",
    "airmass",
    "range_correction_mag",
    "standard_mag",
    "fit_reduction",
    "sign_corrected_mag",
    "fit_note",
    "REFERENCE_RANGE_KM",
    "LAW_RMS_LIMIT_MAG",
]

REFERENCE_RANGE_KM = 1000.0
# A file whose magnitudes follow the law leaves only the rounding of 3-decimal magnitudes:
# uniform on +-0.0005 mag, RMS 0.0003. Ten times that still means "follows the law".
LAW_RMS_LIMIT_MAG = 0.003
# The extinction term is called a sign error only when it is positive by this many standard errors.
_SIGNIFICANCE = 5.0


@dataclass(frozen=True)
class Reduction:
    """Photometric reduction recovered from a file by regression.

    The files obey ``mag = A + m_inst + c * X + m_r`` with ``m_inst = -2.5 log10(flux / dt)``,
    ``X = 1 / sin(el)`` and ``m_r = -5 log10(range_km / 1000)``. For a correct reduction
    ``c = -k`` (k > 0 the extinction coefficient); ccd_phot before 2024-08-01 wrote ``c = +k``.

    Attributes
    ----------
    zero_point_mag : float
        A, the zero point.
    extinction_term_mag : float
        c, the signed coefficient of airmass as found in the file.
    rms_mag : float
        RMS of the regression residuals (rounding of the file's magnitudes: ~3e-4 mag).
    n_points : int
        Rows used in the regression.
    sign_error : bool
        True when the file added the extinction term (c > 0).
    zero_point_err_mag, extinction_term_err_mag : float
        Standard errors of A and c from the regression (NaN when unknown).
    """

    zero_point_mag: float
    extinction_term_mag: float
    rms_mag: float
    n_points: int
    sign_error: bool
    zero_point_err_mag: float = float("nan")
    extinction_term_err_mag: float = float("nan")


def instrumental_mag(flux: np.ndarray, exposure_s: float | np.ndarray) -> np.ndarray:
    """m_inst = -2.5 log10(F / dt).

    Parameters
    ----------
    flux : (n,) float
        Background-subtracted counts per exposure; must be positive (NaN otherwise).
    exposure_s : float or (n,) float
        Exposure time, seconds.

    Returns
    -------
    (n,) float

    >>> float(instrumental_mag(np.array([1000.0]), 0.1)[0])
    -10.0
    """
    flux = np.asarray(flux, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(flux > 0, -2.5 * np.log10(flux / exposure_s), np.nan)


def airmass(el_deg: np.ndarray) -> np.ndarray:
    """Plane-parallel airmass X = 1 / sin(el) (NaN at or below the horizon).

    Parameters
    ----------
    el_deg : (n,) float
        Elevation in degrees (as written by the file, refraction included).

    Returns
    -------
    (n,) float

    >>> float(airmass(np.array([30.0]))[0])
    2.0000000000000004
    """
    sin_el = np.sin(np.radians(np.asarray(el_deg, dtype=float)))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sin_el > 0, 1.0 / sin_el, np.nan)


def range_correction_mag(range_km: np.ndarray) -> np.ndarray:
    """m_r = -5 log10(R / 1000 km): adding it reduces a magnitude to 1000 km range.

    Parameters
    ----------
    range_km : (n,) float
        Topocentric range in kilometres.

    Returns
    -------
    (n,) float

    >>> float(range_correction_mag(np.array([10000.0]))[0])
    -5.0
    """
    range_km = np.asarray(range_km, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(range_km > 0, -5.0 * np.log10(range_km / REFERENCE_RANGE_KM), np.nan)


def standard_mag(flux, exposure_s, el_deg, range_km, zero_point_mag: float, extinction_mag: float) -> np.ndarray:
    """m_st = A + m_inst - k X + m_r with the correct sign of the extinction term.

    Parameters
    ----------
    flux : (n,) float
        Counts per exposure.
    exposure_s : float
        Exposure time, seconds.
    el_deg, range_km : (n,) float
        Elevation (degrees) and range (km) of each sample.
    zero_point_mag : float
        A.
    extinction_mag : float
        k, magnitudes per airmass (positive).

    Returns
    -------
    (n,) float
    """
    return (
        zero_point_mag
        + instrumental_mag(flux, exposure_s)
        - extinction_mag * airmass(el_deg)
        + range_correction_mag(range_km)
    )


def fit_reduction(mag, flux, exposure_s, el_deg, range_km, valid=None) -> Reduction | None:
    """Recover A and the signed extinction term c from a file's own columns.

    Regresses ``y = mag - m_inst - m_r`` on ``X`` by ordinary least squares (the residuals are
    the uniform rounding of the printed magnitudes, the same for every row).

    Parameters
    ----------
    mag, flux, el_deg, range_km : (n,) float
        The file's columns.
    exposure_s : float
        Exposure time, seconds.
    valid : (n,) bool, optional
        Rows to use; rows with non-positive flux, elevation or range are dropped in any case.

    Returns
    -------
    Reduction or None
        None when fewer than 3 usable rows remain or the airmass does not vary enough
        (spread below 1e-3) to separate A from c.

    Notes
    -----
    ``sign_error`` is set when ``c`` is positive by more than five standard errors and the law
    holds (RMS below `LAW_RMS_LIMIT_MAG`); a file that does not follow the law is never
    "corrected".
    """
    x = airmass(el_deg)
    y = np.asarray(mag, dtype=float) - instrumental_mag(flux, exposure_s) - range_correction_mag(range_km)
    use = np.isfinite(x) & np.isfinite(y)
    if valid is not None:
        use &= np.asarray(valid, dtype=bool)
    x, y = x[use], y[use]
    if len(x) < 3 or np.ptp(x) < 1e-3:
        return None
    # Straight-line least squares in closed form (centred, so well conditioned).
    n = len(x)
    x_mean, y_mean = float(x.mean()), float(y.mean())
    dx = x - x_mean
    sxx = float(dx @ dx)
    term = float(dx @ (y - y_mean)) / sxx
    zero_point = y_mean - term * x_mean
    residual = y - (zero_point + term * x)
    variance = float(residual @ residual) / (n - 2) if n > 2 else np.nan
    term_err = float(np.sqrt(variance / sxx))
    zero_point_err = float(np.sqrt(variance * (1.0 / n + x_mean**2 / sxx)))
    rms = float(np.sqrt(np.mean(residual**2)))
    sign_error = bool(term > _SIGNIFICANCE * term_err and rms < LAW_RMS_LIMIT_MAG)
    return Reduction(
        zero_point_mag=zero_point,
        extinction_term_mag=term,
        rms_mag=rms,
        n_points=int(len(x)),
        sign_error=sign_error,
        zero_point_err_mag=zero_point_err,
        extinction_term_err_mag=term_err,
    )


def sign_corrected_mag(mag: np.ndarray, el_deg: np.ndarray, reduction: Reduction) -> np.ndarray:
    """The magnitudes with ``-c X`` instead of the file's ``+c X``: ``mag - 2 c X``.

    Parameters
    ----------
    mag, el_deg : (n,) float
    reduction : Reduction
        The file's fitted reduction (its ``extinction_term_mag`` is c).

    Returns
    -------
    (n,) float
    """
    return np.asarray(mag, dtype=float) - 2.0 * reduction.extinction_term_mag * airmass(el_deg)


def fit_note(reduction: Reduction | None) -> str | None:
    """A sentence for a pass's header when its reduction is missing or does not hold, else None."""
    if reduction is None:
        return "not fitted: fewer than 3 usable rows or no spread in airmass"
    if reduction.rms_mag >= LAW_RMS_LIMIT_MAG:
        return (
            f"the magnitudes do not follow the reduction law (RMS {reduction.rms_mag:.4f} mag, "
            f"more than {LAW_RMS_LIMIT_MAG} mag); no sign correction applied"
        )
    return None
