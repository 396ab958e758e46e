"""Atmospheric refraction as PyEphem (libastro) computes it.

The observation files' Az/El columns were written by PyEphem, whose altitudes include
refraction at the observer's pressure and temperature (PyEphem's defaults: 1010 mbar, 15 C).
To compare with them we use the same model, from libastro's ``refract.c``:

* for apparent altitudes a >= 15.5 deg the refraction is
  ``R = 7.888888e-5 * P / ((273 + T) * tan a)`` radians;
* for a < 14.5 deg, ``R = P (0.1594 + 0.0196 a + 2e-5 a^2) / ((273 + T)(1 + 0.505 a + 0.0845 a^2))``
  degrees (a in degrees; no refraction where this turns negative, below about -8 deg);
* between 14.5 and 15.5 deg the two are blended linearly in a.

These give the true altitude from the apparent one (``true = apparent - R(apparent)``);
PyEphem inverts that numerically (secant method, to 0.1 arcsec) to get the apparent altitude
of a computed (true) position; `apparent_elevation_deg` does the same, vectorised, by Newton's
method to 1e-9 deg.

Examples
--------
>>> from raycast.geometry.refraction import apparent_elevation_deg, true_elevation_deg
>>> float(apparent_elevation_deg(45.0).round(5))
45.01584
>>> float(true_elevation_deg(apparent_elevation_deg(10.0)).round(9))
10.0
"""

from __future__ import annotations

import numpy as np

__all__ = ["PRESSURE_MBAR", "TEMPERATURE_C", "apparent_elevation_deg", "true_elevation_deg"]

PRESSURE_MBAR = 1010.0  # PyEphem's default Observer.pressure
TEMPERATURE_C = 15.0  # PyEphem's default Observer.temp
_LOW_DEG, _HIGH_DEG = 14.5, 15.5
_TOLERANCE_DEG = 1e-9
_MAX_ITERATIONS = 50


def true_elevation_deg(
    apparent_deg, pressure_mbar: float = PRESSURE_MBAR, temperature_c: float = TEMPERATURE_C
) -> np.ndarray:
    """Remove refraction: the geometric elevation of an apparent (refracted) one.

    Parameters
    ----------
    apparent_deg : (...) float
        Apparent elevation, degrees.
    pressure_mbar, temperature_c : float
        Air pressure and temperature at the observer (PyEphem defaults 1010 mbar, 15 C).

    Returns
    -------
    (...) float
        Geometric elevation, degrees.
    """
    a = np.asarray(apparent_deg, dtype=float)
    return a - _refraction_deg(a, pressure_mbar, temperature_c)[0]


def apparent_elevation_deg(
    true_deg, pressure_mbar: float = PRESSURE_MBAR, temperature_c: float = TEMPERATURE_C
) -> np.ndarray:
    """Add refraction: the apparent elevation of a geometric one.

    Solves ``true_elevation_deg(a) = true_deg`` for a by Newton's method from
    ``a = true + R(true)``; three or four steps reach 1e-9 deg above the horizon.

    Parameters
    ----------
    true_deg : (...) float
        Geometric elevation, degrees.
    pressure_mbar, temperature_c : float
        Air pressure and temperature at the observer (PyEphem defaults 1010 mbar, 15 C).

    Returns
    -------
    (...) float
        Apparent elevation, degrees (equal to the input where the model gives no refraction).
    """
    t = np.asarray(true_deg, dtype=float)
    a = (t + _refraction_deg(t, pressure_mbar, temperature_c)[0]).ravel()
    flat_t = t.ravel()
    todo = np.arange(a.size)
    for _ in range(_MAX_ITERATIONS):
        refraction, slope = _refraction_deg(a[todo], pressure_mbar, temperature_c)
        step = (a[todo] - refraction - flat_t[todo]) / (1.0 - slope)
        a[todo] -= step
        todo = todo[np.abs(step) > _TOLERANCE_DEG]
        if todo.size == 0:
            break
    return a.reshape(t.shape)


def _refraction_deg(apparent_deg: np.ndarray, pressure_mbar: float, temperature_c: float):
    """Refraction R(a) = apparent - true and dR/da at apparent elevation a (libastro), degrees."""
    a = apparent_deg
    kelvin = 273.0 + temperature_c
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        radians = np.radians(a)
        scale = np.degrees(7.888888e-5 * pressure_mbar / kelvin)
        high = scale / np.tan(radians)
        d_high = -scale * (np.pi / 180.0) / np.sin(radians) ** 2
        top = ((2e-5 * a + 1.96e-2) * a + 1.594e-1) * pressure_mbar
        bottom = kelvin * ((8.45e-2 * a + 5.05e-1) * a + 1.0)
        low = top / bottom
        d_low = ((4e-5 * a + 1.96e-2) * pressure_mbar * bottom - top * kelvin * (1.69e-1 * a + 5.05e-1)) / bottom**2
        # libastro leaves negative altitudes alone where the low-altitude formula goes negative.
        flat = (a < 0.0) & (low < 0.0)
        low = np.where(flat, 0.0, low)
        d_low = np.where(flat, 0.0, d_low)
        blend = np.minimum(np.maximum((a - _LOW_DEG) / (_HIGH_DEG - _LOW_DEG), 0.0), 1.0)
        refraction = np.where(blend <= 0.0, low, np.where(blend >= 1.0, high, low + (high - low) * blend))
        slope = np.where(
            blend <= 0.0,
            d_low,
            np.where(blend >= 1.0, d_high, d_low + (d_high - d_low) * blend + (high - low) / (_HIGH_DEG - _LOW_DEG)),
        )
    return refraction, slope
