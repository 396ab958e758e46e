"""From reflected intensity per unit solar irradiance (I/E, m^2/sr) to magnitudes.

An unresolved object of intensity I (W/sr) at range R (m) delivers I / R^2 (W/m^2) to the
observer; with the Sun's irradiance E at the object, the object's magnitude is
``m = m_sun - 2.5 log10((I / E) / R^2)``. ``m_sun`` is the apparent magnitude of the Sun at
the object (1 au, which is the Sun-object distance for an Earth satellite within 1e-4 mag).

Solar magnitudes (Vega system)
------------------------------
=====  =======  ===============================================================================
band   m_sun    source
=====  =======  ===============================================================================
B      -26.13   Willmer 2018, ApJS 236, 47: M_B = 5.44, minus the 1 au distance modulus 31.572
V      -26.76   Willmer 2018, ApJS 236, 47: M_V = 4.81, minus 31.572
R      -27.11   V minus the solar colour (V-R)_C = 0.352 (Ramirez et al. 2012, ApJ 752, 5)
I      -27.46   V minus the solar colour (V-I)_C = 0.702 (Ramirez et al. 2012, ApJ 752, 5)
=====  =======  ===============================================================================
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "SOLAR_MAGNITUDES",
    "SOLAR_MAGNITUDE_SOURCES",
    "solar_magnitude",
    "magnitude",
    "intensity_from_magnitude",
    "REFERENCE_RANGE_KM",
]

SOLAR_MAGNITUDES = {"B": -26.13, "V": -26.76, "R": -27.11, "I": -27.46}
SOLAR_MAGNITUDE_SOURCES = {
    "B": "Willmer 2018, ApJS 236, 47 (M_B = 5.44 Vega, 1 au)",
    "V": "Willmer 2018, ApJS 236, 47 (M_V = 4.81 Vega, 1 au)",
    "R": "Willmer 2018 V with (V-R)_C = 0.352 from Ramirez et al. 2012, ApJ 752, 5",
    "I": "Willmer 2018 V with (V-I)_C = 0.702 from Ramirez et al. 2012, ApJ 752, 5",
}
# ccd_phot reduces magnitudes to this range (m_r = -5 log10(R / 1000 km)).
REFERENCE_RANGE_KM = 1000.0


def solar_magnitude(band: str) -> float:
    """Apparent magnitude of the Sun at 1 au in ``band`` (Vega system); see the module table."""
    key = str(band).strip().upper()
    if key not in SOLAR_MAGNITUDES:
        raise ValueError(
            f"band {band!r} has no solar magnitude; use one of {', '.join(SOLAR_MAGNITUDES)} or pass sun_mag explicitly"
        )
    return SOLAR_MAGNITUDES[key]


def magnitude(intensity_m2_sr, range_km, band: str = "V", sun_mag: float | None = None):
    """Magnitude of an object of intensity ``intensity_m2_sr`` (I/E) seen from ``range_km``.

    Parameters
    ----------
    intensity_m2_sr : (n,) float, reflected intensity per unit solar irradiance, m^2/sr.
    range_km : (n,) float or float, observer-object range in km.
    band : str, photometric band for the solar magnitude (ignored when ``sun_mag`` is given).
    sun_mag : float, optional, the Sun's apparent magnitude to use instead of the table.

    Returns
    -------
    (n,) float, magnitudes; +inf where the intensity is 0 (a dark or eclipsed frame).

    Examples
    --------
    A Lambertian 1 m^2 plate of albedo 0.5 seen face-on and lit face-on (I/E = 0.5/pi) at
    1000 km:

    >>> round(float(magnitude(0.5 / np.pi, 1000.0, "V")), 3)
    5.235
    """
    m_sun = solar_magnitude(band) if sun_mag is None else float(sun_mag)
    intensity = np.asarray(intensity_m2_sr, dtype=float)
    range_m = np.asarray(range_km, dtype=float) * 1e3
    if np.any(intensity < 0.0) or not np.all(np.isfinite(intensity)):
        raise ValueError("intensity_m2_sr must be finite and >= 0; check the renderer output")
    if np.any(~np.isfinite(range_m)) or np.any(range_m <= 0.0):
        raise ValueError("range_km must be finite and > 0; give the observer-object range in km")
    with np.errstate(divide="ignore"):
        return m_sun - 2.5 * np.log10(intensity / range_m**2)


def intensity_from_magnitude(mag, range_km, band: str = "V", sun_mag: float | None = None):
    """Inverse of :func:`magnitude`: I/E in m^2/sr from a magnitude at ``range_km``."""
    m_sun = solar_magnitude(band) if sun_mag is None else float(sun_mag)
    range_m = np.asarray(range_km, dtype=float) * 1e3
    return 10.0 ** (-0.4 * (np.asarray(mag, dtype=float) - m_sun)) * range_m**2
