"""The Earth's shadow: what fraction of the Sun's disk a satellite sees.

The model is the conical shadow with umbra and penumbra (Montenbruck & Gill, *Satellite
Orbits*, 2000, section 3.4.2): seen from the satellite, the Sun is a uniform disk of angular
radius ``a = asin(R_sun / |sun - sat|)`` (0.267 deg at 1 au: a 0.53 deg disk) and the Earth a
disk of angular radius ``b = asin(R_earth / |sat|)``, their centres ``c`` apart. The visible
fraction is 1 when ``c >= a + b``, 0 when ``c <= b - a`` (umbra), and in between one minus the
overlap area of the two disks over the Sun's area, which falls monotonically through the
penumbra.

The Earth is the WGS84 ellipsoid, handled exactly for the shadow's edge by stretching the
Earth-fixed z axis by ``1 / (1 - f)`` (an affine map turns the ellipsoid into a sphere of the
equatorial radius and keeps straight rays straight). Left out: limb darkening of the Sun
(the penumbral profile is that of a uniform disk) and the atmosphere, whose refraction and
extinction dim the Sun a few seconds before the geometric penumbra starts.

Examples
--------
>>> import numpy as np
>>> from raycast.geometry.shadow import sunlit_fraction
>>> sun_km = np.array([1.496e8, 0.0, 0.0])
>>> sunlit_fraction(np.array([[7000.0, 0, 0], [-7000.0, 0, 0]]), sun_km).tolist()
[1.0, 0.0]
"""

from __future__ import annotations

import numpy as np

from ingest.site import WGS84_A_KM, WGS84_F

__all__ = ["SUN_RADIUS_KM", "sunlit_fraction", "disk_visible_fraction"]

SUN_RADIUS_KM = 695_700.0  # IAU 2015 Resolution B3 nominal solar radius


def sunlit_fraction(
    sat_km: np.ndarray, sun_km: np.ndarray, earth_radius_km: float = WGS84_A_KM, flattening: float = WGS84_F
) -> np.ndarray:
    """Fraction of the solar disk visible from the satellite, 0 (umbra) to 1 (full Sun).

    Parameters
    ----------
    sat_km : (..., 3) float
        Satellite position in an Earth-centred frame whose z axis is the Earth's polar axis
        (ITRS), km.
    sun_km : (..., 3) float
        Sun position in the same frame (broadcast against `sat_km`), km.
    earth_radius_km : float
        Equatorial radius of the Earth ellipsoid (WGS84 by default).
    flattening : float
        Flattening of the ellipsoid; 0 for a spherical Earth.

    Returns
    -------
    (...) float
        Visible fraction of the solar disk.
    """
    stretch = np.array([1.0, 1.0, 1.0 / (1.0 - flattening)])
    sat = np.asarray(sat_km, dtype=float) * stretch
    sun = np.asarray(sun_km, dtype=float) * stretch
    to_sun = sun - sat
    sun_distance = np.linalg.norm(to_sun, axis=-1)
    sat_distance = np.linalg.norm(sat, axis=-1)
    sun_radius = np.arcsin(np.minimum(SUN_RADIUS_KM / sun_distance, 1.0))
    earth_radius = np.arcsin(np.minimum(earth_radius_km / sat_distance, 1.0))
    cos_separation = -np.sum(sat * to_sun, axis=-1) / (sat_distance * sun_distance)
    separation = np.arccos(np.clip(cos_separation, -1.0, 1.0))
    return disk_visible_fraction(sun_radius, earth_radius, separation)


def disk_visible_fraction(sun_radius_rad, earth_radius_rad, separation_rad) -> np.ndarray:
    """Uncovered fraction of a disk of radius a behind a disk of radius b, centres c apart.

    Treats the two disks as flat circles of the given angular radii (exact in the small-angle
    limit for the Sun; for the large Earth disk the error is below 1e-3 of the Sun's radius).

    Parameters
    ----------
    sun_radius_rad, earth_radius_rad, separation_rad : (...) float
        a, b and c, radians (broadcast together).

    Returns
    -------
    (...) float
        1 - (overlap area) / (pi a^2), in [0, 1].
    """
    a, b, c = np.broadcast_arrays(
        np.asarray(sun_radius_rad, float), np.asarray(earth_radius_rad, float), np.asarray(separation_rad, float)
    )
    fraction = np.ones(a.shape)
    covered = c <= np.abs(b - a)  # one disk inside the other
    fraction[covered & (b >= a)] = 0.0
    annulus = covered & (b < a)
    fraction[annulus] = 1.0 - (b[annulus] / a[annulus]) ** 2
    partial = (c < a + b) & ~covered
    if np.any(partial):
        a, b, c = a[partial], b[partial], c[partial]
        x = (c * c + a * a - b * b) / (2.0 * c)
        y = np.sqrt(np.maximum(a * a - x * x, 0.0))
        overlap = (
            a * a * np.arccos(np.clip(x / a, -1.0, 1.0)) + b * b * np.arccos(np.clip((c - x) / b, -1.0, 1.0)) - c * y
        )
        fraction[partial] = np.clip(1.0 - overlap / (np.pi * a * a), 0.0, 1.0)
    return fraction
